"""The one place that turns the queue's and the database's failures into typed errors.

Routes never write ``except Exception``: a call that reaches the queue (huey on SQLite or
Redis) or the metadata database (SQLAlchemy) runs inside :func:`converted`, which raises
:class:`~service.errors.ServiceUnavailableError` for an outage (a refused connection, a
locked or unreachable database) and lets everything else through, so a bug stays a bug (a
500 with an error id; in a job, :func:`service.tracking.tracked_job` records it as one).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Final, Literal

from sqlalchemy.exc import DisconnectionError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeoutError

from service.errors import (
    STORAGE_FULL_DETAIL,
    InsufficientStorageError,
    ServiceUnavailableError,
    is_storage_full,
)

try:  # Redis is the optional scale-out queue ("scale" extra)
    from redis.exceptions import RedisError
except ImportError:  # pragma: no cover  (installed with the scale extra)
    _REDIS_ERRORS: tuple[type[Exception], ...] = ()
else:
    _REDIS_ERRORS = (RedisError,)

__all__ = ["DATABASE_ERRORS", "QUEUE_ERRORS", "converted"]

DATABASE_ERRORS: Final[tuple[type[Exception], ...]] = (
    OperationalError,
    InterfaceError,
    DisconnectionError,
    PoolTimeoutError,
)
"""SQLAlchemy's errors of an unreachable or unusable database (not of a wrong query)."""

QUEUE_ERRORS: Final[tuple[type[Exception], ...]] = (
    *_REDIS_ERRORS,
    sqlite3.OperationalError,
    ConnectionError,
    TimeoutError,
)
"""The queue backends' errors of an unreachable queue (huey passes them through)."""

_WHAT: Final = {
    "queue": ("The job queue", QUEUE_ERRORS + DATABASE_ERRORS),
    "database": ("The metadata database", DATABASE_ERRORS),
}


@contextmanager
def converted(what: Literal["queue", "database"]) -> Iterator[None]:
    """Raise ServiceUnavailableError for an outage of the queue or the database.

    Raises:
        InsufficientStorageError: the backend could not write for a full disk (507: an
            administrator must free space; retrying alone does not help).
        ServiceUnavailableError: the backend cannot be reached; the message names it and
            the error's class, and asks to try again.
    """
    label, errors = _WHAT[what]
    try:
        yield
    except errors as err:
        if is_storage_full(err):
            raise InsufficientStorageError(STORAGE_FULL_DETAIL) from err
        msg = (
            f"{label} cannot be reached ({type(err).__name__}); try again in a minute "
            "(GET /readyz shows when it is back)."
        )
        raise ServiceUnavailableError(msg) from err
