"""A signing secret per schedule, for the HMAC signature on its webhook deliveries.

Existing schedules get a fresh secret here, so every delivery is signed from the upgrade on.
Nobody has seen those secrets: the owner of such a schedule learns its secret by rotating it
(``POST /api/v1/schedules/{id}/secret``), which shows the new one once.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-23
"""

from __future__ import annotations

import secrets

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

_SCHEDULES = sa.table(
    "schedules", sa.column("id", sa.String), sa.column("webhook_secret", sa.String)
)


def upgrade() -> None:
    """Add the column, give each existing schedule its own secret, then require one."""
    with op.batch_alter_table("schedules") as batch:
        batch.add_column(sa.Column("webhook_secret", sa.String(64), nullable=True))
    connection = op.get_bind()
    ids = connection.execute(sa.select(_SCHEDULES.c.id)).scalars().all()
    for schedule_id in ids:
        connection.execute(
            sa.update(_SCHEDULES)
            .where(_SCHEDULES.c.id == schedule_id)
            .values(webhook_secret=secrets.token_urlsafe(32))
        )
    with op.batch_alter_table("schedules") as batch:
        batch.alter_column("webhook_secret", existing_type=sa.String(64), nullable=False)


def downgrade() -> None:
    """Drop the column (deliveries are no longer signed)."""
    with op.batch_alter_table("schedules") as batch:
        batch.drop_column("webhook_secret")
