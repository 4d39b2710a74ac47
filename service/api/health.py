"""Liveness and readiness probes (no API key needed)."""

from __future__ import annotations

import logging
import shutil

import anyio.to_thread
from fastapi import APIRouter
from sqlalchemy import text

from service.adapters import converted
from service.api.deps import RuntimeDep
from service.errors import InsufficientStorageError, ServiceUnavailableError
from service.preflight import format_bytes
from service.runtime import Runtime

__all__ = ["router"]

logger = logging.getLogger(__name__)
router = APIRouter(tags=["health"])


@router.get("/healthz")
def read_health() -> dict[str, str]:
    """The process is up."""
    return {"status": "ok"}


def _check_space(runtime: Runtime) -> None:
    """Refuse readiness while the data directory's free space is below its reserve."""
    reserve = runtime.settings.min_free_bytes
    if reserve <= 0:
        return
    free = shutil.disk_usage(runtime.store.root).free
    if free < reserve:
        msg = (
            f"The data directory has {format_bytes(free)} free, less than the "
            f"{format_bytes(reserve)} it keeps in reserve (LOCEVAL_MIN_FREE_BYTES), so writes "
            "are refused (507); delete old evaluations or datasets, set "
            "LOCEVAL_RETENTION_DAYS, or give the volume more space."
        )
        raise ServiceUnavailableError(msg)


def _check(runtime: Runtime) -> dict[str, str]:
    """Ask the database and the queue, and the free space; not ready is a 503."""
    try:
        try:
            with converted("database"), runtime.engine.connect() as connection:
                connection.execute(text("SELECT 1"))
            with converted("queue"):
                runtime.huey.pending_count()
        except InsufficientStorageError as err:  # not ready either: the probe answers 503
            raise ServiceUnavailableError(str(err)) from err
        _check_space(runtime)
    except ServiceUnavailableError as err:
        logger.warning("Readiness: %s", err)
        raise
    return {"status": "ready", "database": "ok", "queue": "ok"}


@router.get(
    "/readyz",
    responses={
        503: {"description": "database or queue unreachable, or less free space than the reserve"}
    },
)
async def read_readiness(runtime: RuntimeDep) -> dict[str, str]:
    """The database and the job queue answer, and the data directory has its free reserve."""
    return await anyio.to_thread.run_sync(_check, runtime)
