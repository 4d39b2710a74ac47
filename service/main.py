"""The FastAPI application: ``create_app(settings)``.

``loceval serve`` builds it with the queue consumer running in the same process; tests build
it with ``queue_url="immediate"`` (jobs run inside the request) or against a real server.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import APIRouter, FastAPI

from loceval import __version__
from service.adapters import OUTAGE_ERRORS, unavailable
from service.api import (
    comparisons,
    datasets,
    docs,
    evaluations,
    health,
    hops,
    schedules,
    uploads,
    web,
)
from service.api.metrics import MetricsMiddleware, create_metrics
from service.api.metrics import router as metrics_router
from service.api.middleware import ApiKeyMiddleware
from service.api.problems import install_error_handlers
from service.api.requestlog import RequestLogMiddleware
from service.errors import StartupError
from service.jobs.queue import create_runtime
from service.jobs.retention import sweep_leftovers
from service.jobs.tracking import recover
from service.logs import configure_logging
from service.preflight import check_data_dir
from service.runtime import Runtime
from service.schedules.resource import tick
from service.settings import Settings, get_settings

__all__ = ["create_app"]

logger = logging.getLogger(__name__)

_DESCRIPTION = """
How well does this localization system work in *our* building? Upload recordings (ROS 1/2
bags, MCAP, zipped bag folders, TUM, EuRoC, KITTI, OptiTrack Motive CSV, generic CSV) and
building models (IFC, GLB, OBJ, PLY, STL, DXF floor plans), evaluate an estimate against the
ground truth as a background job, and download the report (HTML, PDF), the errors (CSV) and
the paths for CAD (DXF, Rhino 3dm, 3DM JSON, glTF, IFC).

Every `/api/v1` request needs `Authorization: Bearer KEY`; every error is an
`application/problem+json` document whose `detail` says what to do.
"""


def create_app(
    settings: Settings | None = None,
    *,
    runtime: Runtime | None = None,
    consumer: bool = False,
) -> FastAPI:
    """Return the application.

    Args:
        settings: the settings (default: from the environment).
        runtime: an open runtime to use (default: one is opened from the settings, with
            the migrations applied).
        consumer: run the queue consumer threads inside this process (``loceval serve``).
    """
    settings = settings or get_settings()
    runtime = runtime or create_runtime(settings)

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        configure_logging()  # here, after uvicorn set up its loggers: they go through ours
        try:  # again: the runtime may have been opened long before (and logging was not set up)
            low_space = check_data_dir(runtime.settings)
        except StartupError as err:
            logger.error("%s", err)  # noqa: TRY400  (the message says what to do; no traceback)
            raise
        if low_space:
            logger.warning("%s", low_space)
        sweep_leftovers(runtime, startup=True)  # what processes that are gone left behind
        running = runtime.start_consumer() if consumer else None
        if running is not None:
            requeued = recover(runtime)
            if requeued:
                logger.warning("Queued %d interrupted jobs again", len(requeued))
            fired = tick(runtime)  # a fire missed while the service was down runs now, once
            if fired:
                logger.warning("Started %d schedule runs that were due", len(fired))
        app.state.runtime = runtime
        try:
            yield
        finally:
            if running is not None:
                runtime.stop_consumer(running)
            runtime.store.leave()  # a bucket's lease goes: uvicorn re-raises SIGTERM after this

    app = FastAPI(
        title="loceval",
        version=__version__,
        description=_DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # service.api.docs serves /docs with its files: no CDN, works offline
        redoc_url=None,  # ReDoc loads from a CDN too; /docs is the one documentation page
        # Starlette's redirect of "/path/" to "/path" builds an absolute Location from the
        # request's Host and X-Forwarded-Proto: a link to any host a client names. The other
        # form answers 404 instead, whose detail names the path to use (service.errors).
        redirect_slashes=False,
    )
    app.state.runtime = runtime
    app.state.settings = settings
    app.state.metrics = create_metrics(runtime)
    install_error_handlers(app, outages=OUTAGE_ERRORS, unavailable=unavailable)
    app.add_middleware(ApiKeyMiddleware)
    app.add_middleware(uploads.TusHeadersMiddleware)  # outside the key's check: 401s too
    app.add_middleware(MetricsMiddleware, metrics=app.state.metrics)  # 401s counted too
    app.add_middleware(RequestLogMiddleware)  # added last: the outermost, it sees every request
    _include_routes(app)
    return app


def _include_routes(app: FastAPI) -> None:
    """Add every route: the API under /api/v1, then health, metrics, Hops, /docs, the page."""
    api = APIRouter(prefix="/api/v1")
    api.include_router(datasets.router)
    api.include_router(uploads.router)
    api.include_router(evaluations.router)
    api.include_router(schedules.router)
    api.include_router(comparisons.router)
    app.include_router(api)
    app.include_router(health.router)
    app.include_router(metrics_router)  # GET /metrics: Prometheus, no key, no names or ids
    app.include_router(hops.router)  # Grasshopper Hops: /hops/ and POST /solve at the root
    app.include_router(docs.router)
    docs.document_examples(app)  # the answers' examples, shown by /docs
    app.include_router(web.router)
