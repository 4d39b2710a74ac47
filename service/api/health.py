"""Liveness and readiness probes (no API key needed)."""

from __future__ import annotations

import logging

import anyio.to_thread
from fastapi import APIRouter
from sqlalchemy import text

from service.api.deps import RuntimeDep
from service.errors import ServiceUnavailableError
from service.jobs import Runtime

__all__ = ["router"]

logger = logging.getLogger(__name__)
router = APIRouter(tags=["health"])


@router.get("/healthz")
def read_health() -> dict[str, str]:
    """The process is up."""
    return {"status": "ok"}


def _check(runtime: Runtime) -> dict[str, str]:
    try:
        with runtime.engine.connect() as connection:
            connection.execute(text("SELECT 1"))
    except Exception as err:
        logger.warning("Readiness: database unreachable: %s", err)
        msg = f"The metadata database cannot be reached ({type(err).__name__})."
        raise ServiceUnavailableError(msg) from err
    try:
        runtime.huey.pending_count()
    except Exception as err:
        logger.warning("Readiness: queue unreachable: %s", err)
        msg = f"The job queue cannot be reached ({type(err).__name__})."
        raise ServiceUnavailableError(msg) from err
    return {"status": "ready", "database": "ok", "queue": "ok"}


@router.get(
    "/readyz",
    responses={503: {"description": "database or queue unreachable"}},
)
async def read_readiness(runtime: RuntimeDep) -> dict[str, str]:
    """The database and the job queue answer."""
    return await anyio.to_thread.run_sync(_check, runtime)
