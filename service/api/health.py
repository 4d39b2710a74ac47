"""Liveness and readiness probes (no API key needed)."""

from __future__ import annotations

import logging

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


@router.get(
    "/healthz", responses={200: {"content": {"application/json": {"example": {"status": "ok"}}}}}
)
def read_health() -> dict[str, str]:
    """The process is up."""
    return {"status": "ok"}


def _check_space(runtime: Runtime) -> None:
    """Refuse readiness while the data directory's free space is below its reserve."""
    reserve = runtime.settings.min_free_bytes
    if reserve <= 0:
        return
    free = runtime.store.free_bytes()
    if free is not None and free < reserve:
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
        runtime.store.ping()
        _check_space(runtime)
    except ServiceUnavailableError as err:
        logger.warning("Readiness: %s", err)
        raise
    answer = {"status": "ready", "database": "ok", "queue": "ok"}
    if runtime.store.kind != "local":  # the data folder was checked at start; a bucket now
        answer["store"] = runtime.store.kind
    return answer


@router.get(
    "/readyz",
    responses={
        200: {
            "content": {
                "application/json": {
                    "example": {"status": "ready", "database": "ok", "queue": "ok"}
                }
            }
        },
        503: {
            "description": "database, queue or object store unreachable, or less free space "
            "than the reserve"
        },
    },
)
async def read_readiness(runtime: RuntimeDep) -> dict[str, str]:
    """The database, the job queue and the blob store answer; the disk has its reserve."""
    return await anyio.to_thread.run_sync(_check, runtime)
