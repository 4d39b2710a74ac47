"""``GET /metrics``: the service's figures in Prometheus' text format, without a key.

Nothing in a label names a project, a dataset or a row id: requests are labelled with their
route *template* (``/api/v1/evaluations/{evaluation_id}``; a path that no route matches is
``<unmatched>``), jobs with their kind and state. Each app owns its
:class:`~prometheus_client.CollectorRegistry` (never the global default), so several apps in
one process (tests) do not share or clash.

Where each figure comes from:

* ``loceval_http_requests_total{method,route,status}``,
  ``loceval_http_request_duration_seconds{route}`` and ``loceval_upload_bytes_total`` are
  counted in the web process that answers the request (:class:`MetricsMiddleware`,
  :func:`count_upload`); each replica reports its own, so sum them across replicas.
* ``loceval_jobs{kind,state}`` and ``loceval_job_duration_seconds{kind,outcome}`` are read
  from the database when ``/metrics`` is scraped (:class:`StateCollector`: two ``GROUP BY``
  queries per job table). Jobs run in the consumer threads of ``loceval serve`` or in separate
  ``loceval worker`` processes, which serve no HTTP; a histogram kept in the process that
  runs the jobs would be invisible (or split) in the second case and lost on every restart.
  The job rows hold each job's state and its last attempt's ``started_at`` and
  ``finished_at``, so the figures are the same whichever process ran the job. Every replica
  reports the same totals: take ``max``, not ``sum``, across replicas. The histogram holds
  every finished job in the tables (``increase()`` over a window gives the recent ones); a
  scrape scans the job rows once, cheap at the thousands of jobs a site makes. Deleting a
  schedule deletes its runs, which Prometheus sees as a counter reset.
* ``loceval_queue_depth`` is the queue's pending count (``huey.pending_count()``; always 0
  with the ``immediate`` queue), also read at scrape time.
* ``loceval_backend_up{backend}`` is 0 when the database or the queue could not be read for
  this scrape (their figures are then left out; the scrape itself still answers 200).
"""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import anyio.to_thread
from fastapi import APIRouter, Request, Response
from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from prometheus_client.core import GaugeMetricFamily, HistogramMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_PLAIN_0_0_4
from sqlalchemy import Float, case, extract, func, select
from sqlalchemy.orm import Session
from sqlalchemy.sql.elements import ColumnElement
from starlette.routing import BaseRoute, Mount, Route, WebSocketRoute, compile_path
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from loceval import __version__
from service.adapters import DATABASE_ERRORS, QUEUE_ERRORS
from service.db import JobStatus
from service.errors import ServiceUnavailableError
from service.runtime import JobModel, Runtime
from service.uploads.multipart import ReceivedForm

__all__ = [
    "CONTENT_TYPE",
    "UNMATCHED",
    "Metrics",
    "MetricsMiddleware",
    "StateCollector",
    "count_upload",
    "create_metrics",
    "route_templates",
    "router",
]

logger = logging.getLogger(__name__)

CONTENT_TYPE: Final = CONTENT_TYPE_PLAIN_0_0_4
"""The media type of ``/metrics`` (the classic text format, version 0.0.4)."""

UNMATCHED: Final = "<unmatched>"
"""The route label of a request whose path matches no route."""

HTTP_BUCKETS_S: Final = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 300)
JOB_BUCKETS_S: Final = (1, 2.5, 5, 10, 30, 60, 120, 300, 600, 1800, 3600, 7200)
_METHODS: Final = frozenset({"DELETE", "GET", "HEAD", "OPTIONS", "PATCH", "POST", "PUT"})
_FINISHED: Final = (JobStatus.SUCCEEDED, JobStatus.FAILED)


@dataclass
class Metrics:
    """One app's registry and the figures its web process counts.

    Attributes:
        registry: the app's own registry (``/metrics`` serves it).
        requests: requests by method, route template and status.
        request_duration: request latency by route template.
        upload_bytes: bytes of the files of accepted uploads.
        routes: the app's route templates with their patterns, in matching order (filled
            at the first request, when every route is in).
    """

    registry: CollectorRegistry
    requests: Counter
    request_duration: Histogram
    upload_bytes: Counter
    routes: list[tuple[re.Pattern[str], str]] | None = field(default=None)

    def route_of(self, scope: Scope) -> str:
        """Return the route template the request's path matches, or :data:`UNMATCHED`."""
        if self.routes is None:
            app = scope.get("app")
            found = route_templates(getattr(app, "routes", []))
            self.routes = [(compile_path(template)[0], template) for template in found]
        path = str(scope.get("path", ""))
        root = str(scope.get("root_path", ""))
        if root and path.startswith(root):
            path = path[len(root) :]
        for pattern, template in self.routes:
            if pattern.match(path):
                return template
        return UNMATCHED


def create_metrics(runtime: Runtime) -> Metrics:
    """Return a fresh registry with the request counters and the job and queue collectors.

    Args:
        runtime: the app's runtime, read only at scrape time (a placeholder is fine until
            then).
    """
    registry = CollectorRegistry()
    Gauge(
        "loceval_build_info",
        "The running loceval version (always 1).",
        ["version"],
        registry=registry,
    ).labels(version=__version__).set(1)
    requests = Counter(
        "loceval_http_requests",
        "HTTP requests answered, by method, route template and status.",
        ["method", "route", "status"],
        registry=registry,
    )
    duration = Histogram(
        "loceval_http_request_duration_seconds",
        "Time from a request's arrival to the end of its response, by route template.",
        ["route"],
        buckets=HTTP_BUCKETS_S,
        registry=registry,
    )
    upload_bytes = Counter(
        "loceval_upload_bytes",
        "Bytes of the files of accepted uploads (datasets and one-shot evaluations).",
        registry=registry,
    )
    registry.register(StateCollector(runtime))
    return Metrics(registry, requests, duration, upload_bytes)


def route_templates(routes: Iterable[BaseRoute], prefix: str = "") -> Iterator[str]:
    """Yield the full path template of every route, included routers' prefixes applied.

    FastAPI 0.16x keeps an included router nested (its routes' paths lack the prefix), so
    the nesting is walked here; a flat list of routes (older FastAPI) is read too.
    """
    for route in routes:
        nested = getattr(route, "original_router", None)
        if nested is not None:
            context = getattr(route, "include_context", None)
            yield from route_templates(nested.routes, prefix + str(getattr(context, "prefix", "")))
        elif isinstance(route, Mount):
            inner = route.routes
            if inner:
                yield from route_templates(inner, prefix + route.path)
            else:
                yield prefix + route.path + "/{path:path}"
        elif isinstance(route, Route | WebSocketRoute):
            yield prefix + route.path


class MetricsMiddleware:
    """Count every HTTP request by method, route template and status, and time it."""

    def __init__(self, app: ASGIApp, *, metrics: Metrics) -> None:
        """Wrap the application; count into ``metrics``."""
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass the request on; record it when the response is done (or failed)."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        status = 500
        started = time.perf_counter()

        async def send_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive, send_status)
        finally:
            elapsed = time.perf_counter() - started
            route = self.metrics.route_of(scope)
            method = str(scope.get("method", "")).upper()
            self.metrics.requests.labels(
                method=method if method in _METHODS else "other", route=route, status=str(status)
            ).inc()
            self.metrics.request_duration.labels(route=route).observe(elapsed)


def count_upload(request: Request, form: ReceivedForm) -> None:
    """Add the sizes of an accepted upload's files to ``loceval_upload_bytes_total``."""
    metrics: Metrics | None = getattr(request.app.state, "metrics", None)
    if metrics is not None:
        metrics.upload_bytes.inc(sum(received.size for received in form.files))


# --- read at scrape time -------------------------------------------------------------------


def _duration_s(model: JobModel, dialect: str) -> ColumnElement[Any] | None:
    """Return the SQL of a job's last attempt's duration in seconds, or None (unknown SQL)."""
    if dialect == "sqlite":
        days = func.julianday(model.finished_at, type_=Float) - func.julianday(
            model.started_at, type_=Float
        )
        return days * 86400.0
    if dialect == "postgresql":
        return extract("epoch", model.finished_at) - extract("epoch", model.started_at)
    return None


@dataclass(frozen=True)
class _Durations:
    """Finished jobs of one kind and outcome: count, sum and cumulative bucket counts."""

    count: int
    sum_s: float
    buckets: Sequence[int]


_NONE: Final = _Durations(0, 0.0, (0,) * len(JOB_BUCKETS_S))


class StateCollector:
    """What the database and the queue hold, read at each scrape.

    Yields ``loceval_jobs{kind,state}``, ``loceval_job_duration_seconds{kind,outcome}``,
    ``loceval_queue_depth`` and ``loceval_backend_up{backend}``; a backend that cannot be
    read has ``up`` 0 and its figures left out, so the scrape still answers.
    """

    def __init__(self, runtime: Runtime) -> None:
        """Read ``runtime``'s job tables and queue at each scrape."""
        self.runtime = runtime

    def describe(self) -> list[Metric]:
        """Return the families this collector yields, without samples (no query)."""
        return [
            GaugeMetricFamily("loceval_jobs", "", labels=["kind", "state"]),
            HistogramMetricFamily("loceval_job_duration_seconds", "", labels=["kind", "outcome"]),
            GaugeMetricFamily("loceval_queue_depth", ""),
            GaugeMetricFamily("loceval_backend_up", "", labels=["backend"]),
            GaugeMetricFamily("loceval_blob_store_info", "", labels=["kind"]),
            GaugeMetricFamily("loceval_blob_cache_bytes", ""),
        ]

    def collect(self) -> Iterator[Metric]:
        """Query the job tables and the queue; yield their families and whether they answered."""
        up = GaugeMetricFamily(
            "loceval_backend_up",
            "Whether the backend could be read for this scrape (1) or not (0).",
            labels=["backend"],
        )
        try:
            counts, durations = self._read_jobs()
        except DATABASE_ERRORS:
            logger.warning("/metrics could not read the job tables", exc_info=True)
            up.add_metric(["database"], 0.0)
        else:
            up.add_metric(["database"], 1.0)
            yield from _job_families(counts, durations)
        try:
            pending = int(self.runtime.huey.pending_count())
        except QUEUE_ERRORS + DATABASE_ERRORS:
            logger.warning("/metrics could not read the queue", exc_info=True)
            up.add_metric(["queue"], 0.0)
        else:
            up.add_metric(["queue"], 1.0)
            yield GaugeMetricFamily(
                "loceval_queue_depth", "Tasks waiting in the queue for a worker.", pending
            )
        yield from self._store_families(up)
        yield up

    def _store_families(self, up: GaugeMetricFamily) -> Iterator[Metric]:
        """Yield the blob store's kind and cache size; add whether it answered to ``up``."""
        store = self.runtime.store
        try:
            store.ping()
        except ServiceUnavailableError:
            logger.warning("/metrics could not reach the blob store", exc_info=True)
            up.add_metric(["store"], 0.0)
        else:
            up.add_metric(["store"], 1.0)
        info = GaugeMetricFamily(
            "loceval_blob_store_info",
            "Where uploads and artifacts live: local (the data folder) or s3 (always 1).",
            labels=["kind"],
        )
        info.add_metric([store.kind], 1.0)
        yield info
        yield GaugeMetricFamily(
            "loceval_blob_cache_bytes",
            "Bytes of inputs this process's machine keeps in its local cache (s3 store only).",
            store.cached_bytes(),
        )

    def _read_jobs(self) -> tuple[dict[tuple[str, str], int], dict[tuple[str, str], _Durations]]:
        """Return the job counts by (kind, state) and the durations by (kind, outcome)."""
        counts: dict[tuple[str, str], int] = {}
        durations: dict[tuple[str, str], _Durations] = {}
        dialect = self.runtime.engine.dialect.name
        with self.runtime.sessions() as session:
            for name, kind in sorted(self.runtime.kinds.items()):
                counts.update({(name, str(state)): 0 for state in JobStatus})
                rows = session.execute(
                    select(kind.model.status, func.count()).group_by(kind.model.status)
                ).all()
                counts.update({(name, str(status)): int(number) for status, number in rows})
                found = _read_durations(session, kind.model, dialect)
                for outcome in _FINISHED:
                    durations[name, str(outcome)] = found.get(str(outcome), _NONE)
        return counts, durations


def _read_durations(session: Session, model: JobModel, dialect: str) -> dict[str, _Durations]:
    """Return the durations of a table's finished jobs by outcome (one ``GROUP BY``)."""
    finished = (
        model.status.in_(_FINISHED),
        model.started_at.is_not(None),
        model.finished_at.is_not(None),
    )
    seconds = _duration_s(model, dialect)
    if seconds is None:  # another database: read the stamps, count here
        stamps = session.execute(
            select(model.status, model.started_at, model.finished_at).where(*finished)
        ).all()
        return _bucketed(
            (str(state), (end - start).total_seconds())
            for state, start, end in stamps
            if start is not None and end is not None
        )
    below = [func.sum(case((seconds <= bound, 1), else_=0)) for bound in JOB_BUCKETS_S]
    grouped = session.execute(
        select(model.status, func.count(), func.sum(seconds), *below)
        .where(*finished)
        .group_by(model.status)
    ).all()
    return {
        str(state): _Durations(int(n), float(total or 0.0), [int(c) for c in cumulative])
        for state, n, total, *cumulative in grouped
    }


def _job_families(
    counts: dict[tuple[str, str], int], durations: dict[tuple[str, str], _Durations]
) -> Iterator[Metric]:
    """Yield ``loceval_jobs`` and ``loceval_job_duration_seconds`` from what was read."""
    jobs = GaugeMetricFamily(
        "loceval_jobs", "Jobs by kind and state (queued, running, ...).", labels=["kind", "state"]
    )
    for (kind, state), number in counts.items():
        jobs.add_metric([kind, state], float(number))
    yield jobs
    histogram = HistogramMetricFamily(
        "loceval_job_duration_seconds",
        "Duration of finished jobs' last attempt (started to finished), by kind and outcome.",
        labels=["kind", "outcome"],
    )
    bounds = [*(repr(float(b)) for b in JOB_BUCKETS_S), "+Inf"]
    for (kind, outcome), done in durations.items():
        histogram.add_metric(
            [kind, outcome],
            buckets=list(zip(bounds, [*done.buckets, done.count], strict=True)),
            sum_value=done.sum_s,
        )
    yield histogram


def _bucketed(observations: Iterable[tuple[str, float]]) -> dict[str, _Durations]:
    """Return the durations by outcome from ``(outcome, seconds)`` pairs."""
    by_outcome: dict[str, list[float]] = {}
    for outcome, seconds in observations:
        by_outcome.setdefault(outcome, []).append(seconds)
    return {
        outcome: _Durations(
            len(values), sum(values), [sum(1 for v in values if v <= b) for b in JOB_BUCKETS_S]
        )
        for outcome, values in by_outcome.items()
    }


# --- the route ------------------------------------------------------------------------------

router = APIRouter(tags=["health"])


@router.get(
    "/metrics",
    response_class=Response,
    responses={
        200: {
            "description": "the metrics in Prometheus' text format (version 0.0.4)",
            "content": {
                CONTENT_TYPE: {
                    "schema": {"type": "string"},
                    "example": "# HELP loceval_http_requests_total HTTP requests answered, "
                    "by method, route template and status.\n"
                    "# TYPE loceval_http_requests_total counter\n"
                    'loceval_http_requests_total{method="GET",route="/api/v1/datasets",'
                    'status="200"} 4.0\n',
                }
            },
        }
    },
)
async def read_metrics(request: Request) -> Response:
    """Request, job, queue and upload figures for Prometheus (no key; no names or ids)."""
    metrics: Metrics = request.app.state.metrics
    body = await anyio.to_thread.run_sync(generate_latest, metrics.registry)
    return Response(content=body, media_type=CONTENT_TYPE)
