"""The kind of each evaluation's request, recorded with it: trajectory or ranging.

A stored request is read again as the model of its kind (:data:`service.jobs.kinds.REQUESTS`).
Evaluations made before this revision get theirs here, once, from their request: a ranging
request is the one that names its anchors.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-29
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

_EVALUATIONS = sa.table(
    "evaluations",
    sa.column("id", sa.String),
    sa.column("request", sa.JSON),
    sa.column("kind", sa.String),
)


def upgrade() -> None:
    """Add the column (trajectory by default), then mark the ranging evaluations.

    A database whose tables are ahead of its stamp (stamped back by hand, or restored over
    newer tables) keeps the column it has.
    """
    connection = op.get_bind()
    columns = {column["name"] for column in sa.inspect(connection).get_columns("evaluations")}
    if "kind" not in columns:
        with op.batch_alter_table("evaluations") as batch:
            batch.add_column(
                sa.Column("kind", sa.String(32), nullable=False, server_default="trajectory")
            )
    rows = connection.execute(sa.select(_EVALUATIONS.c.id, _EVALUATIONS.c.request)).all()
    ranging = [row.id for row in rows if isinstance(row.request, dict) and "anchors" in row.request]
    for evaluation_id in ranging:
        connection.execute(
            sa.update(_EVALUATIONS).where(_EVALUATIONS.c.id == evaluation_id).values(kind="ranging")
        )


def downgrade() -> None:
    """Drop the column (the kind is told from the request again)."""
    with op.batch_alter_table("evaluations") as batch:
        batch.drop_column("kind")
