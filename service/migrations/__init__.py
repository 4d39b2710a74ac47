"""Alembic migrations of the metadata database (applied by ``loceval serve`` on start)."""
