"""Helpers of the HTTP API tests: an app with two projects' keys, uploads, problems, schedules.

Each test module builds its fixtures from :func:`open_api`, so every test gets its own data
folder and database (``queue_url="immediate"``: a job runs inside the request that queues it).
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from fastapi import FastAPI
from fastapi.routing import APIRoute
from fastapi.testclient import TestClient

from service.auth import create_key
from service.db import Evaluation, EvaluationStatus, utcnow
from service.main import create_app
from service.settings import Settings
from tests.factories import make_trajectory, perturb, write_tum

PROBLEM_JSON = "application/problem+json"
PROBLEM_KEYS = frozenset({"type", "title", "status", "detail"})


@dataclass
class Api:
    """A running app (TestClient) with a key of project ``site-a`` and one of ``site-b``."""

    app: FastAPI
    client: TestClient
    data_dir: Path
    key: str
    other_key: str

    @property
    def headers(self) -> dict[str, str]:
        """The Authorization header of ``site-a``."""
        return bearer(self.key)

    @property
    def other_headers(self) -> dict[str, str]:
        """The Authorization header of ``site-b``."""
        return bearer(self.other_key)

    def upload(
        self,
        filename: str,
        content: bytes,
        *,
        headers: Mapping[str, str] | None = None,
        **fields: str,
    ) -> Any:
        """POST one file to /api/v1/datasets (with text fields ``name``, ``tags``, ...)."""
        return self.client.post(
            "/api/v1/datasets",
            headers=self.headers if headers is None else dict(headers),
            files={"file": (filename, content)},
            data=fields,
        )

    def dataset(self, filename: str, content: bytes, **fields: str) -> dict[str, Any]:
        """Upload a file that must be accepted; return the dataset."""
        response = self.upload(filename, content, **fields)
        assert response.status_code in {200, 201}, response.text
        dataset: dict[str, Any] = response.json()
        return dataset

    def evaluate(self, body: Mapping[str, Any], *, headers: Mapping[str, str] | None = None) -> Any:
        """POST an evaluation."""
        return self.client.post(
            "/api/v1/evaluations",
            headers=self.headers if headers is None else dict(headers),
            json=dict(body),
        )

    def project_id(self, key: str | None = None) -> str:
        """Return the project id of a key (default: ``site-a``'s)."""
        from service.auth import authenticate

        with self.app.state.runtime.sessions() as session:
            project = authenticate(session, key or self.key)
        assert project is not None
        return project

    def insert_evaluation(
        self, dataset_ids: list[str], *, status: str = EvaluationStatus.QUEUED
    ) -> str:
        """Record an evaluation row directly (nothing is queued); return its id."""
        request = {
            "reference": {"dataset_id": dataset_ids[0], "selector": None, "name": None},
            "estimates": [{"dataset_id": d, "selector": None, "name": None} for d in dataset_ids],
            "options": {},
        }
        evaluation = Evaluation(
            project_id=self.project_id(),
            status=status,
            stage=status,
            request=request,
            dataset_ids=sorted(set(dataset_ids)),
            created_at=utcnow(),
        )
        with self.app.state.runtime.sessions() as session:
            session.add(evaluation)
            session.commit()
        return evaluation.id

    def evaluation_count(self) -> int:
        """Return how many evaluations the database holds (all projects)."""
        from sqlalchemy import func, select

        with self.app.state.runtime.sessions() as session:
            return int(session.scalar(select(func.count()).select_from(Evaluation)) or 0)

    def stored(self) -> list[Path]:
        """Return every file under datasets/ and incoming/ of the data folder."""
        return stored_files(self.data_dir)


def bearer(key: str) -> dict[str, str]:
    """Return an Authorization header."""
    return {"Authorization": f"Bearer {key}"}


def make_settings(data_dir: Path, **overrides: Any) -> Settings:
    """Return test settings: a fresh data folder, jobs run inside the request."""
    values: dict[str, Any] = {"queue_url": "immediate", "database_url": "", **overrides}
    return Settings(data_dir=data_dir, **values)


@contextmanager
def open_api(
    tmp_path: Path, *, raise_server_exceptions: bool = True, **settings: Any
) -> Iterator[Api]:
    """Start an app on ``tmp_path / "data"`` with keys of two projects; close it afterwards."""
    data_dir = tmp_path / "data"
    app = create_app(make_settings(data_dir, **settings))
    runtime = app.state.runtime
    try:
        with TestClient(app, raise_server_exceptions=raise_server_exceptions) as client:
            with runtime.sessions() as session:
                key = create_key(session, "site-a")
            with runtime.sessions() as session:
                other_key = create_key(session, "site-b")
            yield Api(app, client, data_dir.resolve(), key, other_key)
    finally:
        runtime.close()


def api_routes(app: FastAPI) -> set[tuple[str, str]]:
    """Return ``(method, path)`` of every documented APIRoute of the app.

    FastAPI 0.16x keeps included routers nested (``_IncludedRouter`` with the router and
    its prefix) instead of copying their routes into ``app.routes``; both layouts are read.
    """
    found: set[tuple[str, str]] = set()

    def walk(routes: Any, prefix: str) -> None:
        for route in routes:
            if isinstance(route, APIRoute):
                if route.include_in_schema:
                    found.update((method, prefix + route.path) for method in route.methods)
                continue
            router = getattr(route, "original_router", None)
            if router is not None:
                walk(router.routes, prefix + route.include_context.prefix)

    walk(app.routes, "")
    return found


@cache
def offline_app() -> FastAPI:
    """Return the app built on a placeholder runtime: for its routes and OpenAPI, never served.

    Test modules need these at import (to parametrize), before any data folder exists.
    """
    settings = Settings(data_dir=Path("unused"), queue_url="immediate")
    return create_app(settings, runtime=SimpleNamespace())  # type: ignore[arg-type]


def stored_files(data_dir: Path) -> list[Path]:
    """Return every file under datasets/ and incoming/ (uploads that were kept or left)."""
    return sorted(
        p
        for folder in ("datasets", "incoming")
        for p in (data_dir / folder).rglob("*")
        if p.is_file()
    )


def assert_problem(
    response: Any,
    status: int,
    *,
    type_: str | None = None,
    detail: str | None = None,
) -> dict[str, Any]:
    """Assert an RFC 9457 problem response with ``status``; return its body.

    Args:
        response: the TestClient response.
        status: the expected HTTP status (never 500 unless asked for).
        type_: the expected ``type`` code.
        detail: a regular expression searched in ``detail``.
    """
    assert response.status_code == status, (response.status_code, response.text)
    assert response.headers["content-type"].split(";")[0] == PROBLEM_JSON, response.headers
    body: dict[str, Any] = response.json()
    assert body.keys() >= PROBLEM_KEYS, body
    assert body["status"] == response.status_code
    assert isinstance(body["title"], str)
    assert body["title"]
    assert isinstance(body["detail"], str)
    assert body["detail"]
    if type_ is not None:
        assert body["type"] == type_, body
    if detail is not None:
        assert re.search(detail, body["detail"]), body["detail"]
    return body


def assert_no_server_paths(text: str, *paths: Path) -> None:
    """Assert that no server folder (as given or resolved) appears in a message."""
    for path in paths:
        for form in {str(path), str(path.resolve())}:
            assert form not in text, (form, text)
    assert "/incoming/" not in text
    assert ".part" not in text


def tum_pair(rng: np.random.Generator, folder: Path, *, n: int = 200) -> tuple[bytes, bytes]:
    """Write a reference and a noisy estimate as TUM files; return their bytes."""
    truth = make_trajectory(rng, n)
    reference = write_tum(folder / "reference.txt", truth)
    estimate = write_tum(folder / "estimate.txt", perturb(truth, rng))
    return reference.read_bytes(), estimate.read_bytes()


def schedule_body(**overrides: Any) -> dict[str, Any]:
    """Return a POST /schedules body: weekly, the level-2 recordings' /gt against /est.

    ``overrides`` replace top-level fields.
    """
    body: dict[str, Any] = {
        "name": "Weekly level 2",
        "cron": "0 7 * * mon",
        "timezone": "Europe/Berlin",
        "selection": {"tags": ["level2"]},
        "template": {
            "reference": {"selector": "/gt", "name": "OptiTrack"},
            "estimates": [{"selector": "/est", "name": "AMCL"}],
            "options": {"tolerance": "0.10@95", "association": "nearest", "max_dt_s": 0.005},
        },
    }
    body.update(overrides)
    return body
