"""Liveness and readiness probes (no API key needed)."""

from __future__ import annotations

import logging

import anyio.to_thread
from fastapi import APIRouter
from sqlalchemy import text

from service.adapters import converted
from service.api.deps import RuntimeDep
from service.errors import ServiceUnavailableError
from service.runtime import Runtime

__all__ = ["router"]

logger = logging.getLogger(__name__)
router = APIRouter(tags=["health"])


@router.get("/healthz")
def read_health() -> dict[str, str]:
    """The process is up."""
    return {"status": "ok"}


def _check(runtime: Runtime) -> dict[str, str]:
    """Ask the database and the queue; an outage is a 503, anything else a bug (500)."""
    try:
        with converted("database"), runtime.engine.connect() as connection:
            connection.execute(text("SELECT 1"))
        with converted("queue"):
            runtime.huey.pending_count()
        runtime.store.ping()
    except ServiceUnavailableError as err:
        logger.warning("Readiness: %s", err)
        raise
    answer = {"status": "ready", "database": "ok", "queue": "ok"}
    if runtime.store.kind != "local":  # the data folder was checked at start; a bucket now
        answer["store"] = runtime.store.kind
    return answer


@router.get(
    "/readyz",
    responses={503: {"description": "database, queue or object store unreachable"}},
)
async def read_readiness(runtime: RuntimeDep) -> dict[str, str]:
    """The database, the job queue and the blob store answer."""
    return await anyio.to_thread.run_sync(_check, runtime)
