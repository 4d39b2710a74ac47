"""The one place that turns the queue's and the database's failures into typed errors.

Routes never write ``except Exception``: a call that reaches the queue (huey on SQLite or
Redis) or the metadata database (SQLAlchemy) runs inside :func:`converted`, which raises
:class:`~service.errors.ServiceUnavailableError` for an outage (a refused connection, a
locked or unreachable database) and lets everything else through, so a bug stays a bug (a
500 with an error id; in a job, :func:`service.jobs.tracking.tracked_job` records it as one).
"""

from __future__ import annotations

import logging
import sqlite3
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Final, Literal, TypeVar

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

__all__ = [
    "BACKOFF_FIRST_S",
    "BACKOFF_MAX_S",
    "DATABASE_ERRORS",
    "OUTAGE_ERRORS",
    "QUEUE_ERRORS",
    "converted",
    "persist",
    "unavailable",
]

logger = logging.getLogger(__name__)

BACKOFF_FIRST_S: Final = 0.25
BACKOFF_MAX_S: Final = 2.0
"""Retries of a write that met an outage: 0.25, 0.5, 1, 2, 2, ... s, so a database that
comes back is used again within 2 s."""

T = TypeVar("T")

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

OUTAGE_ERRORS: Final[tuple[type[Exception], ...]] = (*DATABASE_ERRORS, *_REDIS_ERRORS)
"""What a route may let through for the error handlers to answer 503 (not 500): the
database's and Redis's outages. (The builtin and sqlite3 errors of :data:`QUEUE_ERRORS` are
only outages where a queue call raised them, so routes convert those with :func:`converted`.)"""

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
    _, errors = _WHAT[what]
    try:
        yield
    except errors as err:
        if is_storage_full(err):
            raise InsufficientStorageError(STORAGE_FULL_DETAIL) from err
        raise unavailable(err, what) from err


def unavailable(
    err: Exception, what: Literal["queue", "database"] | None = None
) -> ServiceUnavailableError:
    """Return the 503 error of a backend's outage (``what`` by default: from the error's class)."""
    if what is None:
        what = "database" if isinstance(err, DATABASE_ERRORS) else "queue"
    label, _ = _WHAT[what]
    msg = (
        f"{label} cannot be reached ({type(err).__name__}); try again in a minute "
        "(GET /readyz shows when it is back)."
    )
    return ServiceUnavailableError(msg)


def persist(call: Callable[[], T], what: str, job_id: str, *, patience_s: float) -> T:
    """Return ``call()``, retried with backoff while the database is away, for ``patience_s``.

    Raises:
        OperationalError: (or another of ``DATABASE_ERRORS``) still failing after patience.
    """
    deadline = time.monotonic() + patience_s
    delay = BACKOFF_FIRST_S
    failures = 0
    while True:
        try:
            result = call()
        except DATABASE_ERRORS as err:
            failures += 1
            if failures == 1:
                logger.warning(
                    "%s of %s: the database cannot be reached (%s); retrying for up to %g s",
                    what,
                    job_id,
                    type(err).__name__,
                    patience_s,
                )
            if time.monotonic() + delay > deadline:
                raise
            time.sleep(delay)
            delay = min(delay * 2, BACKOFF_MAX_S)
        else:
            if failures:
                logger.warning("%s of %s done after %d retries", what, job_id, failures)
            return result
