"""Alembic environment: runs on the connection that :func:`service.db.migrate` passes in."""

from __future__ import annotations

from alembic import context

from service.db import Base

connection = context.config.attributes.get("connection")
if connection is None:  # pragma: no cover  (the alembic command line is not used)
    msg = "Run migrations through service.db.migrate() (loceval serve does it on start)."
    raise RuntimeError(msg)
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
