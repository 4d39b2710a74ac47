"""The error table and the problem+json handlers: every error class, bugs, HTTP errors."""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, ClassVar

import pytest
from fastapi import FastAPI, Query
from fastapi.testclient import TestClient
from starlette.exceptions import HTTPException as StarletteHTTPException

from exporters.errors import ExportError, ExportOptionsError, ExportUnavailableError
from loceval.errors import (
    AlignmentError,
    AssociationError,
    InputError,
    LocevalError,
    MetricError,
    ReaderError,
    TrajectoryError,
)
from service.auth import create_key
from service.errors import (
    STATUS_BY_ERROR,
    AuthenticationError,
    ConflictError,
    InsufficientStorageError,
    InvalidFieldsError,
    JobMemoryError,
    JobTimeoutError,
    NotFoundError,
    NotReadyError,
    ServiceUnavailableError,
    StartupError,
    StoreUnavailableError,
    TusVersionError,
    UploadChecksumError,
    UploadError,
    UploadLockedError,
    UploadMediaTypeError,
    UploadOffsetError,
    UploadTooLargeError,
    WebhookRefusedError,
    WebhookUnresolvedError,
    internal_problem,
    problem_for,
    status_for,
)
from service.main import create_app  # imports every module of the service, with its errors
from tests.service._api_fixtures import assert_problem, make_settings

EXPECTED: dict[type[LocevalError], tuple[int, str]] = {
    LocevalError: (500, "error"),
    InputError: (422, "input.invalid"),
    ReaderError: (422, "input.unreadable"),
    TrajectoryError: (422, "input.trajectory"),
    AssociationError: (422, "association.no_matches"),
    AlignmentError: (422, "alignment.degenerate"),
    MetricError: (422, "metric.invalid"),
    ExportError: (500, "export.failed"),
    ExportOptionsError: (422, "export.options"),
    ExportUnavailableError: (501, "export.unavailable"),
    NotFoundError: (404, "not_found"),
    NotReadyError: (409, "evaluation.not_ready"),
    ConflictError: (409, "conflict"),
    AuthenticationError: (401, "auth.unauthorized"),
    UploadError: (400, "upload.invalid"),
    UploadChecksumError: (460, "upload.checksum_mismatch"),
    UploadMediaTypeError: (415, "upload.media_type"),
    TusVersionError: (412, "upload.tus_version"),
    UploadOffsetError: (409, "upload.offset_mismatch"),
    UploadLockedError: (423, "upload.locked"),
    InvalidFieldsError: (422, "request.invalid"),
    UploadTooLargeError: (413, "upload.too_large"),
    ServiceUnavailableError: (503, "service.unavailable"),
    StoreUnavailableError: (503, "service.unavailable"),
    JobTimeoutError: (422, "job.timeout"),
    JobMemoryError: (422, "job.out_of_memory"),
    WebhookRefusedError: (422, "schedule.webhook_refused"),
    WebhookUnresolvedError: (422, "schedule.webhook_unresolved"),
    StartupError: (503, "service.startup"),
    InsufficientStorageError: (507, "storage.full"),
}
"""The intended status and ``type`` code of every error class the project defines."""

_PROJECT_MODULES = ("loceval.", "exporters.", "service.")
_ERROR_ID = re.compile(r"^[0-9a-f]{12}$")


def _project_error_classes() -> set[type[LocevalError]]:
    found: set[type[LocevalError]] = set()
    pending: list[type[LocevalError]] = [LocevalError]
    while pending:
        cls = pending.pop()
        if cls.__module__.startswith(_PROJECT_MODULES):
            found.add(cls)
        pending.extend(cls.__subclasses__())
    return found


class _SubReaderError(ReaderError):
    """A subclass the table does not name: the nearest mapped parent decides."""

    code: ClassVar[str] = "input.sub"


@pytest.fixture
def app(tmp_path: Path) -> FastAPI:
    """An app with throwaway routes that raise on request."""
    app = create_app(make_settings(tmp_path / "data"))

    async def raise_error(name: str) -> None:
        cls = next(c for c in EXPECTED if c.__name__ == name)
        msg = f"{name} happened; do something about it."
        raise cls(msg)

    async def raise_bug() -> None:
        msg = "secret /srv/loceval/var/datasets/1234 password=hunter2"
        raise RuntimeError(msg)

    async def raise_http(status: int) -> None:
        raise StarletteHTTPException(status, detail=f"custom {status}")

    async def typed(
        *,
        count: Annotated[int, Query(ge=0)],
        a: int = 0,
        b: int = 0,
        c: int = 0,
        d: int = 0,
        e: int = 0,
        f: int = 0,
    ) -> dict[str, int]:
        return {"sum": count + a + b + c + d + e + f}

    async def echo(body: dict[str, int]) -> dict[str, int]:
        return body

    app.add_api_route("/test/error/{name}", raise_error)
    app.add_api_route("/test/echo", echo, methods=["POST"])
    app.add_api_route("/test/bug", raise_bug)
    app.add_api_route("/test/http/{status}", raise_http)
    app.add_api_route("/test/typed", typed)
    return app


@pytest.fixture
def client(app: FastAPI) -> Iterator[TestClient]:
    """A client that turns unhandled errors into responses, as a server does."""
    with TestClient(app, raise_server_exceptions=False) as client:
        yield client
    app.state.runtime.close()


def test_every_error_class_is_mapped() -> None:
    """The table and this test name every LocevalError class of the three packages."""
    modules = {c.__module__ for c in EXPECTED}
    assert modules == {"loceval.errors", "exporters.errors", "service.errors"}
    assert _project_error_classes() == set(EXPECTED)
    assert set(STATUS_BY_ERROR) <= set(EXPECTED)


@pytest.mark.parametrize(
    ("cls", "expected"), EXPECTED.items(), ids=lambda v: getattr(v, "__name__", "")
)
def test_status_and_type(cls: type[LocevalError], expected: tuple[int, str]) -> None:
    """Each class maps to its intended status and type code; the message is the detail."""
    status, code = expected
    error = cls("The thing is wrong; fix it.")
    assert status_for(error) == status
    assert problem_for(error) == {
        "type": code,
        "title": cls.__name__,
        "status": status,
        "detail": "The thing is wrong; fix it.",
    }


def test_most_specific_parent_wins() -> None:
    """An unlisted subclass takes the status of its nearest listed parent and keeps its code."""
    error = _SubReaderError("x")
    assert status_for(error) == 422
    assert problem_for(error)["type"] == "input.sub"
    assert status_for(UploadTooLargeError("x")) == 413  # not UploadError's 400 or InputError's 422


def test_statuses_are_errors() -> None:
    """Every mapped status is 4xx or 5xx; 500 is the base class's (a failed export inherits it)."""
    assert all(400 <= s < 600 for s in STATUS_BY_ERROR.values())
    assert {c for c, s in STATUS_BY_ERROR.items() if s == 500} == {LocevalError}


@pytest.mark.parametrize("cls", list(EXPECTED), ids=lambda c: c.__name__)
def test_handler_renders_each_error(
    client: TestClient, cls: type[LocevalError], caplog: pytest.LogCaptureFixture
) -> None:
    """A raised error becomes its problem document with its status."""
    status, code = EXPECTED[cls]
    with caplog.at_level(logging.ERROR, logger="service.errors"):
        response = client.get(f"/test/error/{cls.__name__}")
    body = assert_problem(response, status, type_=code, detail=rf"^{cls.__name__} happened")
    assert body["title"] == cls.__name__
    if cls is AuthenticationError:
        assert response.headers["www-authenticate"] == "Bearer"
    else:
        assert "www-authenticate" not in response.headers
    logged = [r for r in caplog.records if cls.__name__ in r.getMessage()]
    assert bool(logged) == (status >= 500)


def test_unexpected_exception_is_a_500_problem(
    client: TestClient, caplog: pytest.LogCaptureFixture
) -> None:
    """A bug answers 500 with an error id and nothing of the exception; the log has it all."""
    with caplog.at_level(logging.ERROR, logger="service.errors"):
        response = client.get("/test/bug")
    body = assert_problem(response, 500, type_="internal")
    assert body["title"] == "InternalError"
    error_id = body["error_id"]
    assert _ERROR_ID.match(error_id)
    assert error_id in body["detail"]
    for leak in ("secret", "hunter2", "/srv/", "RuntimeError", "Traceback", "raise_bug", ".py"):
        assert leak not in response.text
    record = next(r for r in caplog.records if error_id in r.getMessage())
    assert record.exc_info is not None
    assert isinstance(record.exc_info[1], RuntimeError)


def test_each_bug_gets_its_own_id(client: TestClient) -> None:
    """Two failures are told apart by their error ids."""
    first = client.get("/test/bug").json()["error_id"]
    second = client.get("/test/bug").json()["error_id"]
    assert first != second


def test_bug_propagates_to_test_clients(app: FastAPI) -> None:
    """Under a raising TestClient the original exception reaches the test (after the 500)."""
    with TestClient(app) as client, pytest.raises(RuntimeError, match=r"^secret"):
        client.get("/test/bug")
    app.state.runtime.close()


def test_internal_problem_shape() -> None:
    """internal_problem names the id it is given, or makes one."""
    assert internal_problem("abc123")["error_id"] == "abc123"
    made = internal_problem()
    assert _ERROR_ID.match(made["error_id"])
    assert made["status"] == 500


def test_validation_error_lists_errors(client: TestClient) -> None:
    """Request validation errors are a 422 problem with an errors list (loc, msg, type)."""
    response = client.get("/test/typed", params={"count": "-1", "a": "x"})
    body = assert_problem(response, 422, type_="request.invalid", detail=r"query\.count")
    assert {tuple(e["loc"]) for e in body["errors"]} == {("query", "count"), ("query", "a")}
    assert all(e.keys() == {"loc", "msg", "type"} for e in body["errors"])
    assert {e["type"] for e in body["errors"]} == {"greater_than_equal", "int_parsing"}


def test_validation_detail_names_at_most_five(client: TestClient) -> None:
    """The detail names the first five errors; the errors list has them all."""
    params = {"count": "x", **dict.fromkeys("abcdef", "x")}
    body = assert_problem(client.get("/test/typed", params=params), 422)
    assert len(body["errors"]) == 7
    assert body["detail"].count("query.") == 5


def test_missing_field_is_named(client: TestClient) -> None:
    """A missing required parameter is named in the detail."""
    body = assert_problem(client.get("/test/typed"), 422, detail=r"query\.count: Field required")
    assert body["errors"][0]["type"] == "missing"


@pytest.mark.parametrize("content", [b"\x80", b'{"a": "\xe9"}', b"\xff\xfe\x00"])
def test_body_not_utf8_is_422(client: TestClient, content: bytes) -> None:
    """A JSON body that is not UTF-8 is the 422 of undecodable JSON (FastAPI says 400)."""
    response = client.post(
        "/test/echo", content=content, headers={"content-type": "application/json"}
    )
    body = assert_problem(response, 422, type_="request.invalid", detail=r"not UTF-8")
    assert body["errors"] == [
        {
            "loc": ["body"],
            "msg": "JSON decode error (the body is not UTF-8)",
            "type": "json_invalid",
        }
    ]


def test_body_not_json_is_422(client: TestClient) -> None:
    """A body that is not JSON is a 422 naming the JSON decode error."""
    response = client.post(
        "/test/echo", content=b"{nope", headers={"content-type": "application/json"}
    )
    body = assert_problem(response, 422, type_="request.invalid", detail=r"JSON decode error")
    assert body["errors"][0]["type"] == "json_invalid"
    assert client.post("/test/echo", json={"a": 1}).json() == {"a": 1}


def test_unknown_route(client: TestClient) -> None:
    """An unknown path is a 404 problem that points at /docs."""
    assert_problem(client.get("/no/such/thing"), 404, type_="http", detail=r"/docs")


def test_wrong_method_lists_allowed(app: FastAPI, client: TestClient) -> None:
    """A wrong method is a 405 problem whose Allow names every method of the path."""
    with app.state.runtime.sessions() as session:
        key = create_key(session, "site")
    response = client.delete("/api/v1/datasets", headers={"Authorization": f"Bearer {key}"})
    assert_problem(response, 405, type_="http", detail=r"GET, POST")
    assert response.headers["allow"] == "GET, POST"


@pytest.mark.parametrize("status", [400, 404, 418, 503])
def test_raised_http_exceptions(client: TestClient, status: int) -> None:
    """HTTPExceptions raised in routes keep their status and detail, as problems."""
    body = assert_problem(client.get(f"/test/http/{status}"), status, type_="http")
    assert body["detail"] == f"custom {status}"
