"""Start-up checks: the data directory and the database's migration level.

:func:`service.jobs.queue.create_runtime` runs both before anything else opens (so ``loceval
serve``, ``worker`` and ``keys`` and :func:`service.main.create_app` all pass through them),
and the app's start-up checks the data directory again. A check that fails raises
:class:`StartupError`, whose message says what is wrong and what to do; the command line
prints it and exits 1, without a traceback.

- The data directory must exist or be creatable, and be writable: a probe file is written and
  deleted. Low free space (below ``min_free_bytes``) is a warning, not a refusal: the service
  can still serve results and delete old ones, while uploads get 507 until space is freed.
- The database is brought to the newest migration when it is behind (the service has always
  migrated on start); a database at a migration this version does not know (a newer loceval
  upgraded it) is refused, since running old code on a newer schema would corrupt it.
"""

from __future__ import annotations

import logging
import shutil
import uuid
from pathlib import Path
from typing import Final

from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Engine

from loceval import __version__
from service import migrations
from service.db import migrate
from service.errors import StartupError
from service.settings import Settings

__all__ = ["StartupError", "check_data_dir", "format_bytes", "prepare_schema", "schema_heads"]

logger = logging.getLogger(__name__)

_MIGRATIONS: Final = Path(migrations.__file__).resolve().parent


def format_bytes(size: int) -> str:
    """Return a size for people: ``"512 bytes"``, ``"830 MB"``, ``"3.2 GB"`` (decimal units)."""
    if size < 10**6:
        return f"{size:,} bytes"
    if size < 10**9:
        return f"{size / 1e6:,.0f} MB"
    return f"{size / 1e9:,.1f} GB"


def _probe_write(folder: Path) -> None:
    """Write and delete a small file in ``folder`` (raises OSError when it cannot)."""
    probe = folder / f".loceval-probe-{uuid.uuid4().hex}"
    try:
        probe.write_bytes(b"loceval start-up probe\n")
    finally:
        probe.unlink(missing_ok=True)


def check_data_dir(settings: Settings) -> str | None:
    """Check that the data directory exists (or create it) and is writable.

    Returns:
        A warning when its free space is below ``settings.min_free_bytes``, else None.

    Raises:
        StartupError: the folder cannot be created or written to.
    """
    folder = settings.data_dir
    where = str(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        msg = (
            f"The data directory {where!r} does not exist and cannot be created "
            f"({err.strerror or err}); create it for the user running loceval, or set "
            "LOCEVAL_DATA_DIR to a folder that user may write."
        )
        raise StartupError(msg) from None
    try:
        _probe_write(folder)
    except OSError as err:
        msg = (
            f"The data directory {where!r} is not writable ({err.strerror or err}); give "
            "the user running loceval write access to it (and mount its volume read-write), "
            "or set LOCEVAL_DATA_DIR to a writable folder."
        )
        raise StartupError(msg) from None
    if settings.min_free_bytes <= 0:
        return None
    free = shutil.disk_usage(folder).free
    if free >= settings.min_free_bytes:
        return None
    return (
        f"The data directory {where!r} has {format_bytes(free)} free, less than the "
        f"{format_bytes(settings.min_free_bytes)} it keeps in reserve (LOCEVAL_MIN_FREE_BYTES): "
        "uploads are refused (507) until there is more; delete old evaluations or datasets, "
        "set LOCEVAL_RETENTION_DAYS, or give the volume more space."
    )


def schema_heads(engine: Engine) -> tuple[tuple[str, ...], str]:
    """Return the database's migration revisions and the newest one this code has."""
    script = ScriptDirectory(str(_MIGRATIONS))
    with engine.connect() as connection:
        current = tuple(MigrationContext.configure(connection).get_current_heads())
    head = script.get_current_head()
    if head is None:  # pragma: no cover  (the package ships its migrations)
        msg = "This installation has no database migrations; reinstall loceval."
        raise StartupError(msg)
    return current, head


def prepare_schema(engine: Engine, *, apply_migrations: bool = True) -> None:
    """Bring the database to this code's migration level, or refuse to start.

    Args:
        engine: the metadata database.
        apply_migrations: migrate a database that is behind (else refuse, saying so).

    Raises:
        StartupError: the database is at a migration this code does not know (a newer
            loceval upgraded it), or it is behind and ``apply_migrations`` is False.
    """
    current, head = schema_heads(engine)
    if current == (head,):
        return
    script = ScriptDirectory(str(_MIGRATIONS))
    known = {revision.revision for revision in script.walk_revisions()}
    unknown = [revision for revision in current if revision not in known]
    if unknown:
        msg = (
            f"The database is at migration {', '.join(unknown)}, which loceval {__version__} "
            f"does not know (its newest is {head}): a newer loceval has upgraded it. Run that "
            "newer loceval (upgrade this installation), or set LOCEVAL_DATABASE_URL to a "
            "database of this version; do not downgrade the database by hand."
        )
        raise StartupError(msg)
    was = ", ".join(current) or "empty"
    if not apply_migrations:
        msg = (
            f"The database is at migration {was}, older than this loceval's {head}; start "
            "`loceval serve` or `loceval worker` once, which migrates it on start."
        )
        raise StartupError(msg)
    migrate(engine)
    if current:
        logger.warning("Migrated the database from migration %s to %s", was, head)
