"""Bad input on every endpoint: keys, ids, bodies, uploads, limits, routes.

Every error must be an ``application/problem+json`` document whose ``status`` is the HTTP
status (``assert_problem``), never a 500, must not name the server's folders, and must leave
nothing behind in ``datasets/`` or ``incoming/``.
"""

from __future__ import annotations

import io
import json
import re
import tempfile
import uuid
import zipfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import service.uploads.multipart
from service.auth import revoke_key
from service.db import EvaluationStatus
from tests import bagfactory
from tests.factories import make_trajectory, write_csv, write_tum
from tests.service._api_fixtures import (
    Api,
    api_routes,
    assert_no_server_paths,
    assert_problem,
    bearer,
    offline_app,
    open_api,
    tum_pair,
)

CHEAP = {"formats": ["result.json"]}

ENDPOINTS = [
    ("POST", "/api/v1/datasets"),
    ("GET", "/api/v1/datasets"),
    ("GET", "/api/v1/datasets/{dataset_id}"),
    ("DELETE", "/api/v1/datasets/{dataset_id}"),
    ("POST", "/api/v1/evaluations"),
    ("GET", "/api/v1/evaluations"),
    ("GET", "/api/v1/evaluations/{evaluation_id}"),
    ("GET", "/api/v1/evaluations/{evaluation_id}/artifacts/{name}"),
    ("POST", "/api/v1/evaluate"),
]
"""The contract's /api/v1 routes, tested below with real bodies and ids."""

WITH_IDS = [e for e in ENDPOINTS if "{" in e[1]]

ALL_ROUTES = sorted(
    (m, path) for m, path in api_routes(offline_app()) if path.startswith("/api/v1/")
)
"""Every /api/v1 route of the app, read from it: routes added later are covered by the
generic key and id tests without editing this file."""


@dataclass
class World:
    """An app with, in project site-a, two TUM datasets and a succeeded evaluation of them."""

    api: Api
    tmp_path: Path
    reference_id: str
    estimate_id: str
    evaluation_id: str
    new_file: bytes

    def url(self, template: str, **ids: str) -> str:
        """Fill a route template with this world's ids (or the given ones)."""
        values = {
            "dataset_id": self.reference_id,
            "evaluation_id": self.evaluation_id,
            "name": "result.json",
            **ids,
        }
        return template.format(**values)

    def send(self, method: str, template: str, headers: dict[str, str], **ids: str) -> Any:
        """Send a request that would succeed with site-a's key (a valid body for POSTs)."""
        url = self.url(template, **ids)
        client = self.api.client
        if template == "/api/v1/datasets" and method == "POST":
            return client.post(url, headers=headers, files={"file": ("new.txt", self.new_file)})
        if template == "/api/v1/evaluations" and method == "POST":
            body = {
                "reference": {"dataset_id": ids.get("dataset_id", self.reference_id)},
                "estimates": [{"dataset_id": self.estimate_id}],
                "options": CHEAP,
            }
            return client.post(url, headers=headers, json=body)
        if template == "/api/v1/evaluate":
            files = [
                ("reference", ("r.txt", self.new_file)),
                ("estimate", ("e.txt", self.new_file)),
            ]
            return client.post(
                url, headers=headers, files=files, data={"options": json.dumps(CHEAP)}
            )
        return client.request(method, url, headers=headers)

    def snapshot(self) -> tuple[list[Path], int]:
        """What a refused request must not change: the stored files and the evaluations."""
        return self.api.stored(), self.api.evaluation_count()


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Iterator[World]:
    """Datasets and a succeeded evaluation of project site-a, shared by the module.

    Tests compare the stored files and evaluations before and after what they send, so
    they may share it; the generator has the rng fixture's seed (that one is per test).
    """
    tmp_path = tmp_path_factory.mktemp("world")
    rng = np.random.default_rng(20240601)
    with open_api(tmp_path) as api:
        reference, estimate = tum_pair(rng, tmp_path)
        reference_id = api.dataset("truth.txt", reference)["id"]
        estimate_id = api.dataset("slam.txt", estimate)["id"]
        body = {
            "reference": {"dataset_id": reference_id},
            "estimates": [{"dataset_id": estimate_id}],
            "options": CHEAP,
        }
        evaluation = api.evaluate(body).json()
        assert evaluation["status"] == "succeeded"
        new_file = write_tum(tmp_path / "new.txt", make_trajectory(rng, 50)).read_bytes()
        yield World(api, tmp_path, reference_id, estimate_id, evaluation["id"], new_file)


@pytest.fixture
def make_dir(tmp_path: Path) -> Path:
    """A folder for files the tests write before uploading."""
    folder = tmp_path / "make"
    folder.mkdir()
    return folder


@pytest.fixture
def small(tmp_path: Path) -> Iterator[Api]:
    """An app that takes uploads of at most 10,000 bytes."""
    with open_api(tmp_path, max_upload_bytes=10_000) as api:
        yield api


def test_endpoint_lists(api: Api) -> None:
    """The contract's routes exist, and the generic tests see every route of the app."""
    routes = {(m, path) for m, path in api_routes(api.app) if path.startswith("/api/v1/")}
    assert set(ENDPOINTS) <= routes
    assert set(ALL_ROUTES) == routes


def _fill(template: str, value: str) -> str:
    return re.sub(r"\{[^}]+\}", value, template)


@pytest.mark.parametrize("kind", ["none", "unknown", "revoked"])
@pytest.mark.parametrize(("method", "template"), ALL_ROUTES)
def test_every_route_needs_a_valid_key(world: World, method: str, template: str, kind: str) -> None:
    """Every /api/v1 route refuses a missing, unknown or revoked key with 401, changing nothing."""
    headers = {} if kind == "none" else BAD_AUTHORIZATION[kind](world.api)
    body: dict[str, Any] = {"json": {}} if method in {"POST", "PUT", "PATCH"} else {}
    before = world.snapshot()
    url = _fill(template, str(uuid.uuid4()))
    response = world.api.client.request(method, url, headers=headers, **body)
    if method == "HEAD":  # a HEAD answer has no body (tus's HEAD /uploads/{id}): status only
        assert response.status_code == 401
    else:
        assert_problem(response, 401, type_="auth.unauthorized")
    assert response.headers["www-authenticate"] == "Bearer"
    assert world.snapshot() == before


@pytest.mark.parametrize(
    ("method", "template"), [r for r in ALL_ROUTES if "{" in r[1] and r[0] in {"GET", "DELETE"}]
)
def test_every_route_unknown_ids(world: World, method: str, template: str) -> None:
    """Every /api/v1 route with ids answers 404 for ids that do not exist."""
    before = world.snapshot()
    url = _fill(template, str(uuid.uuid4()))
    headers = {**world.api.headers, "Tus-Resumable": "1.0.0"}  # the uploads' protocol version
    assert_problem(world.api.client.request(method, url, headers=headers), 404)
    assert world.snapshot() == before


# --- keys ------------------------------------------------------------------------------


@pytest.mark.parametrize(("method", "template"), ENDPOINTS)
def test_no_key(world: World, method: str, template: str) -> None:
    """Without a key every endpoint answers 401 with WWW-Authenticate, changing nothing."""
    before = world.snapshot()
    response = world.send(method, template, {})
    assert_problem(response, 401, type_="auth.unauthorized", detail=r"Authorization: Bearer KEY")
    assert response.headers["www-authenticate"] == "Bearer"
    assert world.snapshot() == before


def _revoked_key(api: Api) -> str:
    with api.app.state.runtime.sessions() as session:
        from service.auth import create_key

        key = create_key(session, "site-a")
    with api.app.state.runtime.sessions() as session:
        revoke_key(session, key)
    return key


BAD_AUTHORIZATION: dict[str, Callable[[Api], dict[str, str]]] = {
    "unknown": lambda _api: bearer("lcv_" + "A" * 43),
    "revoked": lambda api: bearer(_revoked_key(api)),
    "no prefix": lambda api: bearer(api.key.removeprefix("lcv_")),
    "truncated": lambda api: bearer(api.key[:-1]),
    "basic": lambda api: {"Authorization": f"Basic {api.key}"},
    "empty bearer": lambda _api: {"Authorization": "Bearer "},
    "raw key": lambda api: {"Authorization": api.key},
    "huge": lambda _api: bearer("lcv_" + "x" * 100_000),
}


@pytest.mark.parametrize("kind", BAD_AUTHORIZATION)
@pytest.mark.parametrize(("method", "template"), ENDPOINTS)
def test_bad_key(world: World, method: str, template: str, kind: str) -> None:
    """Unknown, revoked or malformed keys are refused with 401, changing nothing."""
    headers = BAD_AUTHORIZATION[kind](world.api)
    before = world.snapshot()
    response = world.send(method, template, headers)
    assert_problem(response, 401, type_="auth.unauthorized")
    assert response.headers["www-authenticate"] == "Bearer"
    assert world.snapshot() == before


def test_revoked_key_worked_before(world: World) -> None:
    """The revoked key of the test above was valid until it was revoked."""
    api = world.api
    with api.app.state.runtime.sessions() as session:
        from service.auth import create_key

        key = create_key(session, "site-a")
    assert api.client.get("/api/v1/datasets", headers=bearer(key)).status_code == 200
    with api.app.state.runtime.sessions() as session:
        assert revoke_key(session, key) == 1
    assert_problem(api.client.get("/api/v1/datasets", headers=bearer(key)), 401)


@pytest.mark.parametrize("content", [b"{not json", b"\x80 not UTF-8"])
def test_undecodable_json_without_key_is_401(api: Api, content: bytes) -> None:
    """A request without a key is refused as such even when its JSON body is broken."""
    response = api.client.post(
        "/api/v1/evaluations", content=content, headers={"content-type": "application/json"}
    )
    assert_problem(response, 401)


# --- ids -------------------------------------------------------------------------------


@pytest.mark.parametrize(("method", "template"), [*WITH_IDS, ("POST", "/api/v1/evaluations")])
def test_other_projects_ids_are_not_found(world: World, method: str, template: str) -> None:
    """Another project's ids are 404 (not 403), worded as for ids that do not exist."""
    before = world.snapshot()
    theirs = world.send(method, template, world.api.other_headers)
    body = assert_problem(theirs, 404, type_="not_found")
    unknown_id = str(uuid.uuid4())
    ids = {"dataset_id": unknown_id, "evaluation_id": unknown_id}
    unknown = assert_problem(world.send(method, template, world.api.headers, **ids), 404)
    for known in (world.reference_id, world.estimate_id, world.evaluation_id):
        body["detail"] = body["detail"].replace(known, "ID")
    assert body["detail"] == unknown["detail"].replace(unknown_id, "ID")
    assert world.snapshot() == before


def test_other_projects_device_is_not_found(world: World) -> None:
    """A device file of another project is 404 too."""
    urdf = b'<robot name="r"><link name="a"/><link name="b"/></robot>'
    theirs = world.api.upload("r.urdf", urdf, headers=world.api.other_headers).json()["id"]
    body = {
        "reference": {"dataset_id": world.reference_id},
        "estimates": [{"dataset_id": world.estimate_id}],
        "options": {**CHEAP, "device": {"dataset_id": theirs, "from_link": "a", "to_link": "b"}},
    }
    assert_problem(world.api.evaluate(body), 404, detail=rf"No dataset '{theirs}' in this project")


@pytest.mark.parametrize("unknown", ["0", "no-such-id", "x" * 300, "%20", "..", "null"])
@pytest.mark.parametrize(("method", "template"), WITH_IDS)
def test_unknown_ids(world: World, method: str, template: str, unknown: str) -> None:
    """Ids that do not exist are 404 problems."""
    ids = {"dataset_id": unknown, "evaluation_id": unknown}
    response = world.send(method, template, world.api.headers, **ids)
    body = assert_problem(response, 404)
    assert body["type"] in {"not_found", "http"}  # ".." leaves the route: no such endpoint


def test_unknown_artifact_name(world: World) -> None:
    """An artifact name that is none is 404 listing the names."""
    url = world.url("/api/v1/evaluations/{evaluation_id}/artifacts/report.docx")
    assert_problem(
        world.api.client.get(url, headers=world.api.headers),
        404,
        type_="not_found",
        detail=r"No artifact 'report\.docx'; the artifacts are result\.json, errors\.csv",
    )


@pytest.mark.parametrize("name", ["..%2Fresult.json", "%2E%2E", "artifacts", ".staging"])
def test_artifact_names_cannot_leave_the_folder(world: World, name: str) -> None:
    """Names that try to reach other files are 404, never a file outside the artifacts."""
    url = world.url("/api/v1/evaluations/{evaluation_id}/artifacts/") + name
    response = world.api.client.get(url, headers=world.api.headers)
    assert_problem(response, 404)


@pytest.mark.parametrize("status", [EvaluationStatus.QUEUED, EvaluationStatus.RUNNING])
def test_artifact_of_unfinished_evaluation(world: World, status: str) -> None:
    """An evaluation that has not finished has no artifacts yet: 409, poll it."""
    evaluation_id = world.api.insert_evaluation([world.reference_id], status=status)
    url = f"/api/v1/evaluations/{evaluation_id}/artifacts/result.json"
    assert_problem(
        world.api.client.get(url, headers=world.api.headers),
        409,
        type_="evaluation.not_ready",
        detail=rf"is {status}, so it has no artifacts yet; poll",
    )
    unknown = world.api.client.get(url.replace("result.json", "x.bin"), headers=world.api.headers)
    assert_problem(unknown, 404)


def test_artifact_of_failed_evaluation(world: World) -> None:
    """A failed evaluation has no artifacts: 409, see its error."""
    body = {
        "reference": {"dataset_id": world.reference_id},
        "estimates": [{"dataset_id": world.estimate_id}],
        "options": {**CHEAP, "time_offset_s": 500.0},
    }
    evaluation = world.api.evaluate(body).json()
    assert evaluation["status"] == "failed"
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/result.json"
    assert_problem(
        world.api.client.get(url, headers=world.api.headers),
        409,
        type_="evaluation.not_ready",
        detail=r"is failed, so it has no artifacts; see its error",
    )


# --- JSON bodies and query parameters --------------------------------------------------


BAD_BODIES: list[tuple[Any, set[tuple[Any, ...]]]] = [
    ({}, {("body", "reference"), ("body", "estimates")}),
    ({"reference": 5, "estimates": "x"}, {("body", "reference"), ("body", "estimates")}),
    ([], {("body",)}),
    ("text", {("body",)}),
    (None, {("body",)}),
    ({"reference": {"dataset_id": "R"}, "estimates": []}, {("body", "estimates")}),
    ({"reference": {}, "estimates": [{"dataset_id": "E"}]}, {("body", "reference", "dataset_id")}),
    (
        {"reference": {"dataset_id": ""}, "estimates": [{"dataset_id": "E", "selector": ""}]},
        {("body", "reference", "dataset_id"), ("body", "estimates", 0, "selector")},
    ),
    (
        {"reference": {"dataset_id": "x" * 65}, "estimates": [{"dataset_id": "E"}]},
        {("body", "reference", "dataset_id")},
    ),
    (
        {"reference": {"dataset_id": "R"}, "estimates": [{"dataset_id": "E"}] * 21},
        {("body", "estimates")},
    ),
    (
        {"reference": {"dataset_id": 7}, "estimates": [{"dataset_id": ["E"]}]},
        {("body", "reference", "dataset_id"), ("body", "estimates", 0, "dataset_id")},
    ),
    (
        {"reference": {"dataset_id": "R"}, "estimates": [{"dataset_id": "E"}], "extra": 1},
        {("body", "extra")},
    ),
    (
        {"reference": {"dataset_id": "R"}, "estimates": [{"dataset_id": "E"}], "options": []},
        {("body", "options")},
    ),
    (
        {
            "reference": {"dataset_id": "R"},
            "estimates": [{"dataset_id": "E", "name": "n" * 121}],
            "options": {"worst": "ten", "rpe_all_pairs": "maybe", "site_matrix": [[1, 0, 0]] * 3},
        },
        {
            ("body", "estimates", 0, "name"),
            ("body", "options", "worst"),
            ("body", "options", "rpe_all_pairs"),
            ("body", "options", "site_matrix"),
        },
    ),
    (
        {
            "reference": {"dataset_id": "R"},
            "estimates": [{"dataset_id": "E"}],
            "options": {"device": {"dataset_id": "D"}, "formats": [], "stamp": "now"},
        },
        {
            ("body", "options", "device", "from_link"),
            ("body", "options", "device", "to_link"),
            ("body", "options", "formats"),
            ("body", "options", "stamp"),
        },
    ),
    (
        {
            "reference": {"dataset_id": "R"},
            "estimates": [{"dataset_id": "E"}],
            "options": {"no_ci": "maybe", "reference_sigma_m": -0.0002},
        },
        {("body", "options", "no_ci"), ("body", "options", "reference_sigma_m")},
    ),
    (
        {
            "reference": {"dataset_id": "R"},
            "estimates": [{"dataset_id": "E"}],
            "options": {"reference_sigma_m": 11.0},
        },
        {("body", "options", "reference_sigma_m")},
    ),
]


@pytest.mark.parametrize(("body", "locations"), BAD_BODIES, ids=lambda v: str(v)[:30])
def test_bad_evaluation_bodies(world: World, body: object, locations: set[tuple[Any, ...]]) -> None:
    """Wrong types, missing and extra fields: 422 with an errors list naming each place."""
    before = world.snapshot()
    response = world.api.client.post(
        "/api/v1/evaluations",
        headers={**world.api.headers, "content-type": "application/json"},
        content=json.dumps(body),
    )
    problem = assert_problem(response, 422, type_="request.invalid")
    assert {
        tuple(e["loc"][: len(loc)]) for e in problem["errors"] for loc in locations
    } >= locations
    assert all(e["msg"] and e["type"] for e in problem["errors"])
    assert world.snapshot() == before


@pytest.mark.parametrize(
    ("content", "content_type", "status"),
    [
        (b"{not json", "application/json", 422),
        (b'{"reference": ', "application/json", 422),
        (b"\xff\xfe\x00", "application/json", 422),  # not UTF-8 (FastAPI's 400, made a 422)
        (b'{"reference": "\xe9"}', "application/json", 422),
        (b"reference=x", "application/x-www-form-urlencoded", 422),
        (b"hello", "text/plain", 422),
        (b"", "application/json", 422),
    ],
)
def test_undecodable_evaluation_bodies(
    world: World, content: bytes, content_type: str, status: int
) -> None:
    """Bodies that are not a JSON object (or not UTF-8) are 422 problems."""
    response = world.api.client.post(
        "/api/v1/evaluations",
        headers={**world.api.headers, "content-type": content_type},
        content=content,
    )
    assert_problem(response, status)


@pytest.mark.parametrize(
    ("path", "params", "loc"),
    [
        ("/api/v1/datasets", {"limit": "abc"}, "limit"),
        ("/api/v1/datasets", {"limit": "0"}, "limit"),
        ("/api/v1/datasets", {"limit": "501"}, "limit"),
        ("/api/v1/datasets", {"offset": "-1"}, "offset"),
        ("/api/v1/datasets", {"offset": "1e3"}, "offset"),
        ("/api/v1/datasets", {"tag": "t" * 51}, "tag"),
        ("/api/v1/evaluations", {"status": "done"}, "status"),
        ("/api/v1/evaluations", {"limit": "-5"}, "limit"),
        ("/api/v1/evaluations", {"offset": "9999999"}, "offset"),
    ],
)
def test_bad_query_parameters(world: World, path: str, params: dict[str, str], loc: str) -> None:
    """Query parameters of the wrong type or out of range are 422 naming the parameter."""
    response = world.api.client.get(path, params=params, headers=world.api.headers)
    body = assert_problem(response, 422, type_="request.invalid", detail=rf"query\.{loc}")
    assert body["errors"][0]["loc"] == ["query", loc]


# --- uploads: the request ----------------------------------------------------------------


UPLOADS = ["/api/v1/datasets", "/api/v1/evaluate"]


@pytest.mark.parametrize("path", UPLOADS)
@pytest.mark.parametrize(
    ("content_type", "content"),
    [
        ("application/json", b'{"file": "x"}'),
        ("application/x-www-form-urlencoded", b"file=1+2+3+4"),
        ("text/plain", b"1 0 0 0\n"),
        ("application/octet-stream", b"\x89MCAP0\r\n"),
        ("multipart/form-data", b"--x\r\n"),
        ("multipart/mixed; boundary=x", b"--x--\r\n"),
        (None, b"1 0 0 0\n"),
    ],
)
def test_wrong_content_type(
    world: World, path: str, content_type: str | None, content: bytes
) -> None:
    """Uploads that are not multipart/form-data with a boundary are 400, nothing stored."""
    before = world.snapshot()
    headers = dict(world.api.headers)
    if content_type is not None:
        headers["content-type"] = content_type
    response = world.api.client.post(path, headers=headers, content=content)
    assert_problem(response, 400, type_="upload.invalid", detail=r"multipart/form-data")
    assert world.snapshot() == before


@pytest.mark.parametrize(
    ("path", "files", "data", "detail"),
    [
        (
            "/api/v1/datasets",
            [("name", (None, b"x")), ("tags", (None, b"a"))],
            None,
            r"has no file; send it in the multipart field 'file'",
        ),
        ("/api/v1/datasets", {"upload": ("a.txt", b"1 0 0 0\n")}, None, r"'upload' holds a file"),
        ("/api/v1/datasets", {"file": (None, b"1 0 0 0\n")}, None, r"has no file"),
        ("/api/v1/datasets", {"name": ("n.txt", b"x")}, None, r"'name' holds a file"),
        (
            "/api/v1/evaluate",
            [("estimate_selector", (None, b"/odom"))],
            None,
            r"exactly one file in the field 'reference', got 0",
        ),
        (
            "/api/v1/evaluate",
            [("estimate", ("e.txt", b"1 0 0 0\n"))],
            None,
            r"exactly one file in the field 'reference', got 0",
        ),
        (
            "/api/v1/evaluate",
            [("reference", ("r.txt", b"1 0 0 0\n")), ("options", ("o.json", b"{}"))],
            None,
            r"'options' holds a file",
        ),
    ],
)
def test_multipart_without_the_file(
    world: World, path: str, files: Any, data: dict[str, str] | None, detail: str
) -> None:
    """A form without its file field, or with files in text fields, is 400."""
    before = world.snapshot()
    response = world.api.client.post(path, headers=world.api.headers, files=files, data=data)
    assert_problem(response, 400, type_="upload.invalid", detail=detail)
    assert world.snapshot() == before


def test_multipart_without_any_field(world: World) -> None:
    """An empty multipart form (only the closing boundary) is 400."""
    response = world.api.client.post(
        "/api/v1/datasets",
        headers={**world.api.headers, "content-type": "multipart/form-data; boundary=B"},
        content=b"--B--\r\n",
    )
    assert_problem(response, 400, detail=r"has no file")


@pytest.mark.parametrize(
    "body",
    [
        b"not a multipart body at all",
        b'--B\r\nContent-Disposition: form-data; name="file"; filename="a.txt"\r\n\r\n1 0 0',
        b'--B\r\nContent-Disposition: form-data; name="file"; filename="a.txt"\r\n',
        b"--B\r\nContent-Type: text/plain\r\n\r\nabc\r\n--B--\r\n",
        b'--B\r\nContent-Disposition: form-data; name="' + b"n" * (2 * 1024 * 1024) + b'"\r\n',
        b"",
    ],
    ids=[
        "no boundary",
        "truncated file",
        "truncated headers",
        "no disposition",
        "huge header",
        "empty",
    ],
)
@pytest.mark.parametrize("path", UPLOADS)
def test_malformed_multipart(world: World, path: str, body: bytes) -> None:
    """Malformed or truncated multipart bodies are 400 and leave nothing in incoming/."""
    before = world.snapshot()
    response = world.api.client.post(
        path,
        headers={**world.api.headers, "content-type": "multipart/form-data; boundary=B"},
        content=body,
    )
    assert_problem(response, 400, type_="upload.invalid")
    assert world.snapshot() == before


# --- uploads: the file -------------------------------------------------------------------


def _bag_bytes(rng: np.random.Generator, tmp_path: Path, fmt: str) -> bytes:
    poses = bagfactory.random_poses(rng, 40, dt_ns=20_000_000)
    records = bagfactory.pose_records("/pose", bagfactory.POSE, poses)
    written = bagfactory.write_bag(bagfactory.bag_path(tmp_path, fmt, "cut"), records, fmt=fmt)
    return (written if fmt == "rosbag1" else next(written.glob("*.mcap"))).read_bytes()


def _zip(members: dict[str, bytes], *, compression: int = zipfile.ZIP_DEFLATED) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=compression) as archive:
        for name, content in members.items():
            archive.writestr(name, content)
    return buffer.getvalue()


CORRUPT: dict[str, tuple[Callable[[np.random.Generator, Path], tuple[str, bytes]], str]] = {
    "empty": (lambda _rng, _tmp: ("run.txt", b""), r"'run\.txt' is empty; upload the recording"),
    "random .mcap": (
        lambda rng, _tmp: ("run.mcap", rng.bytes(4096)),
        r"Cannot tell the format of 'run\.mcap'",
    ),
    "truncated mcap": (
        lambda rng, tmp: ("run.mcap", _bag_bytes(rng, tmp, "mcap")[:-200]),
        r"Bag 'run\.mcap' cannot be read; it looks truncated",
    ),
    "mcap header only": (
        lambda rng, tmp: ("run.mcap", _bag_bytes(rng, tmp, "mcap")[:40]),
        r"Bag 'run\.mcap' cannot be read",
    ),
    "truncated rosbag1": (
        lambda rng, tmp: ("run.bag", (b := _bag_bytes(rng, tmp, "rosbag1"))[: len(b) // 2]),
        r"Bag 'run\.bag' cannot be read; it looks truncated",
    ),
    "bag magic, txt name": (
        lambda rng, tmp: ("run.txt", _bag_bytes(rng, tmp, "rosbag1")[:300]),
        r"cannot be read",
    ),
    "csv wrong column": (
        lambda _rng, _tmp: ("run.csv", b"time,east,north\n1.0,0,0\n2.0,1,1\n3.0,2,2\n"),
        r"run\.csv, line 1: no column for 'x' among \['time', 'east', 'north'\]",
    ),
    "tum with NaN": (
        lambda _rng, _tmp: ("run.txt", b"1.0 0 0 0\n2.0 nan 0 0\n3.0 2 0 0\n"),
        r"run\.txt, line 2: position is NaN",
    ),
    "tum too short": (
        lambda _rng, _tmp: ("run.txt", b"1.0 0 0 0\n1.0 1 0 0\n2.0 2 0 0\n"),
        r"run\.txt: 2 poses, but at least 3 are needed",
    ),
    "tum zero quaternions": (
        lambda _rng, _tmp: (
            "run.txt",
            b"1.0 0 0 0 0 0 0 0\n2.0 0 0 0 0 0 0 0\n3.0 1 0 0 0 0 0 0\n",
        ),
        r"run\.txt, line 1: quaternion has norm 0",
    ),
    "tum ragged": (
        lambda _rng, _tmp: ("run.txt", b"1.0 0 0 0\n2.0 0 0\n3.0 1 1 1\n"),
        r"run\.txt, line 2: 3 values, but line 1 has 4",
    ),
    "binary garbage": (
        lambda _rng, _tmp: ("run.txt", bytes(range(256)) * 8),
        r"Cannot tell the format of 'run\.txt'",
    ),
    "not a urdf": (
        lambda _rng, _tmp: ("robot.urdf", b"<html><body/></html>"),
        r"XML but not a URDF",
    ),
    "zip without bag": (
        lambda _rng, _tmp: ("bag.zip", _zip({"notes.txt": b"hello"})),
        r"holds no bag .* it holds: notes\.txt",
    ),
    "truncated zip": (
        lambda rng, tmp: ("bag.zip", _zip({"run.mcap": _bag_bytes(rng, tmp, "mcap")})[:-100]),
        r"'bag\.zip' is not a readable zip archive",
    ),
}


@pytest.mark.parametrize("path", UPLOADS)
@pytest.mark.parametrize("case", CORRUPT)
def test_unreadable_files(
    world: World, rng: np.random.Generator, make_dir: Path, case: str, path: str
) -> None:
    """Files no reader takes are 422 with the reader's message, no server paths, nothing kept."""
    make, detail = CORRUPT[case]
    filename, content = make(rng, make_dir)
    before = world.snapshot()
    if path == "/api/v1/datasets":
        response = world.api.upload(filename, content)
    else:
        response = world.api.client.post(
            path,
            headers=world.api.headers,
            files=[("reference", (filename, content))],
            data={"estimate_selector": "/pose", "options": json.dumps(CHEAP)},
        )
    body = assert_problem(response, 422, detail=detail)
    assert body["type"].startswith("input.")
    assert_no_server_paths(body["detail"], world.tmp_path, world.api.data_dir, make_dir)
    assert world.snapshot() == before


@pytest.mark.public_data
@pytest.mark.parametrize(
    ("name", "fraction"),
    [
        ("nav2_turtlebot.mcap", 0.5),
        ("nav2_turtlebot.mcap", 0.999),
        ("tf_example.bag", 0.3),
        ("tf_example.bag", 0.98),
    ],
)
def test_truncated_public_bags(world: World, public_data: Path, name: str, fraction: float) -> None:
    """Real bags cut short (an interrupted copy) are 422 with the reader's message."""
    content = (public_data / name).read_bytes()
    before = world.snapshot()
    response = world.api.upload(name, content[: int(len(content) * fraction)])
    body = assert_problem(response, 422, type_="input.unreadable", detail=rf"Bag '{name}'")
    assert_no_server_paths(body["detail"], world.tmp_path, world.api.data_dir, public_data)
    assert world.snapshot() == before


@pytest.mark.parametrize(
    "member",
    ["../{evil}", "../../{evil}", "/tmp/{evil}", "bag/../../{evil}", "C:/{evil}"],  # noqa: S108
)
def test_zip_traversal(world: World, member: str) -> None:
    """A zip member that would land outside the extraction folder is refused; nothing escapes."""
    evil = f"evil-{uuid.uuid4().hex}"
    content = _zip({member.format(evil=evil): b"pwned", "bag/metadata.yaml": b"x"})
    before = world.snapshot()
    response = world.api.upload("bag.zip", content)
    body = assert_problem(
        response, 422, type_="input.unreadable", detail=r"leaves the extraction folder"
    )
    assert_no_server_paths(body["detail"], world.tmp_path, world.api.data_dir)
    assert world.snapshot() == before
    assert not list(world.tmp_path.rglob(f"{evil}*"))  # the data folder is inside it
    for folder in (Path(tempfile.gettempdir()), Path("/tmp"), Path.cwd()):  # noqa: S108
        assert not list(folder.glob(f"{evil}*"))


def test_zip_bomb(world: World) -> None:
    """A member that inflates a thousandfold is refused before it is extracted."""
    content = _zip({"run.mcap": b"\0" * (60 * 1024 * 1024)})
    assert len(content) < 100_000
    before = world.snapshot()
    response = world.api.upload("bag.zip", content)
    body = assert_problem(response, 422, type_="input.unreadable", detail=r"zip bomb")
    assert_no_server_paths(body["detail"], world.tmp_path, world.api.data_dir)
    assert world.snapshot() == before
    leftovers = list(Path(tempfile.gettempdir()).glob("loceval-zip-*/run.mcap"))
    assert leftovers == []


def test_zip_symlink(world: World) -> None:
    """A symbolic link in a zip is refused."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        info = zipfile.ZipInfo("bag/run.mcap")
        info.external_attr = 0o120777 << 16  # a symlink to /etc/passwd
        archive.writestr(info, "/etc/passwd")
    before = world.snapshot()
    response = world.api.upload("bag.zip", buffer.getvalue())
    assert_problem(response, 422, detail=r"symbolic link 'bag/run\.mcap'")
    assert world.snapshot() == before


# --- uploads: size limit ---------------------------------------------------------------


class _FeedSpy:
    """Wraps the receiver's body reader to see whether and how the body was read."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls: list[str | None] = []
        original = service.uploads.multipart._feed

        async def feed(request: Any, parser: Any) -> None:
            self.calls.append(request.headers.get("content-length"))
            await original(request, parser)

        monkeypatch.setattr(service.uploads.multipart, "_feed", feed)


@pytest.mark.parametrize("path", UPLOADS)
def test_oversize_announced(small: Api, path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A Content-Length beyond the limit is 413 before the body is read; nothing kept."""
    spy = _FeedSpy(monkeypatch)
    field = "file" if path == "/api/v1/datasets" else "reference"
    content = b"1 0 0 0\n" * 200_000  # 1.6 MB: beyond the limit plus the form allowance
    response = small.client.post(path, headers=small.headers, files={field: ("big.txt", content)})
    assert_problem(response, 413, type_="upload.too_large", detail=r"limit of 10,000 bytes")
    assert spy.calls == []
    assert small.stored() == []


@pytest.mark.parametrize("path", UPLOADS)
def test_oversize_streamed(small: Api, path: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A chunked upload without Content-Length is cut off at the limit with 413."""
    spy = _FeedSpy(monkeypatch)
    field = "file" if path == "/api/v1/datasets" else "reference"

    def body() -> Iterator[bytes]:
        yield (
            f'--B\r\nContent-Disposition: form-data; name="{field}"; filename="big.txt"\r\n\r\n'
        ).encode()
        for _ in range(40):
            yield b"1 0 0 0\n" * 1000
        yield b"\r\n--B--\r\n"

    response = small.client.post(
        path,
        headers={**small.headers, "content-type": "multipart/form-data; boundary=B"},
        content=body(),
    )
    assert_problem(response, 413, type_="upload.too_large", detail=r"LOCEVAL_MAX_UPLOAD_BYTES")
    assert spy.calls == [None]  # streamed: no Content-Length to refuse it by
    assert small.stored() == []


def test_upload_at_the_limit_is_accepted(
    small: Api, rng: np.random.Generator, tmp_path: Path
) -> None:
    """A file just under the limit is taken (the limit counts file bytes, not the form)."""
    content = write_tum(tmp_path / "r.txt", make_trajectory(rng, 80), header=False).read_bytes()
    content = content[: content.rfind(b"\n", 0, 10_000) + 1]
    assert 9_000 < len(content) <= 10_000
    response = small.upload("r.txt", content, name="n" * 200, tags="a,b")
    assert response.status_code == 201, response.text


# --- the one-shot form's text fields ---------------------------------------------------


def _one_shot(world: World, **data: Any) -> Any:
    files = [("reference", ("r.txt", world.new_file)), ("estimate", ("e.txt", world.new_file))]
    return world.api.client.post(
        "/api/v1/evaluate", headers=world.api.headers, files=files, data=data
    )


@pytest.mark.parametrize(
    ("options", "status", "detail"),
    [
        ("{not json", 400, r"'options' field is not JSON \(Expecting property name"),
        ("{'formats': 1}", 400, r"'options' field is not JSON"),
        ("[1, 2]", 422, r"options: Input should be an object"),
        ("null", 422, r"options: Input should be an object"),
        ('"text"', 422, r"options: Input should be an object"),
        ('{"formats": "result.json"}', 422, r"options\.formats: Input should be a valid array"),
        ('{"units": "km"}', 422, r"options\.units"),
        ('{"extra": true}', 422, r"options\.extra: Extra inputs are not permitted"),
        ('{"tolerance": "most"}', 422, r"tolerance takes METRES@PERCENT"),
        ('{"max_dt_s": NaN}', 422, r"options\.max_dt_s"),
    ],
)
def test_one_shot_bad_options(world: World, options: str, status: int, detail: str) -> None:
    """Options that are not JSON are 400; JSON that is not valid options is 422."""
    evaluations = world.api.evaluation_count()
    assert_problem(_one_shot(world, options=options), status, detail=detail)
    assert world.api.evaluation_count() == evaluations


@pytest.mark.parametrize(
    ("data", "status", "detail"),
    [
        ({"estimate_selector": ["a", "b"]}, 400, r"one estimate_selector per estimate file \(1\)"),
        ({"estimate_name": ["a", "b"]}, 400, r"one estimate_name per estimate \(1\)"),
        (
            {"estimate_selector": "s" * 501},
            422,
            r"estimates\.0\.selector: String should have at most 500",
        ),
        ({"estimate_name": "n" * 121}, 422, r"estimates\.0\.name: String should have at most 120"),
        (
            {"reference_selector": "s" * 501},
            422,
            r"reference\.selector: String should have at most",
        ),
        (
            {"reference_selector": "/pose"},
            422,
            r"is a tum file with one trajectory; leave its selector",
        ),
        ({"estimate_selector": "/pose"}, 422, r"estimate dataset .* leave its selector empty"),
        (
            {"tags": "x", "name": "y"},
            400,
            (
                r"The form field '(tags|name)' is not one this endpoint reads; send only "
                r"'estimate', 'estimate_name', 'estimate_selector', 'options', 'reference', "
                r"'reference_selector'\."
            ),
        ),
    ],
)
def test_one_shot_bad_fields(world: World, data: dict[str, Any], status: int, detail: str) -> None:
    """Fields that do not fit the files, or that the endpoint does not read, are 400/422.

    An unknown field is refused, not ignored: a misspelt field would otherwise be dropped
    without a word.
    """
    before = world.snapshot()
    response = _one_shot(world, options=json.dumps(CHEAP), **data)
    assert_problem(response, status, detail=detail)
    if status == 400:
        assert world.snapshot() == before


def test_one_shot_too_many_estimates(world: World) -> None:
    """More than 20 estimate files are refused while receiving, nothing kept."""
    before = world.snapshot()
    files = [("reference", ("r.txt", world.new_file))] + [
        ("estimate", (f"e{k}.txt", world.new_file)) for k in range(21)
    ]
    response = world.api.client.post("/api/v1/evaluate", headers=world.api.headers, files=files)
    assert_problem(response, 400, detail=r"Too many files in one request \(at most 21\)")
    assert world.snapshot() == before


def test_one_shot_too_many_text_fields(world: World) -> None:
    """Hundreds of text fields are refused (400)."""
    data = {"estimate_name": ["x"] * 250}
    assert_problem(_one_shot(world, **data), 400, detail=r"Too many form fields")


def test_one_shot_estimate_csv_with_wrong_column(world: World, tmp_path: Path) -> None:
    """An unreadable estimate file is 422; the readable reference may stay, the rest does not."""
    bad = write_csv(
        tmp_path / "e.csv",
        make_trajectory(np.random.default_rng(1), 20),
        names={"t": "time", "x": "east", "y": "north"},
    ).read_bytes()
    response = world.api.client.post(
        "/api/v1/evaluate",
        headers=world.api.headers,
        files=[("reference", ("r.txt", world.new_file)), ("estimate", ("e.csv", bad))],
    )
    body = assert_problem(response, 422, type_="input.unreadable", detail=r"e\.csv, line 1")
    assert_no_server_paths(body["detail"], tmp_path, world.api.data_dir)
    assert list((world.api.data_dir / "incoming").iterdir()) == []


# --- routes ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "path", ["/api/v2/datasets", "/api/v1/dataset", "/api/v1/evaluations/x/y", "/nope", "/api/v1/"]
)
def test_unknown_routes(api: Api, path: str) -> None:
    """Paths no route matches are 404 problems, with or without a key (issue 12)."""
    assert_problem(api.client.get(path, headers=api.headers), 404, type_="http", detail=r"/docs")
    assert_problem(api.client.post(path), 404, type_="http", detail=r"/docs")


@pytest.mark.parametrize(
    ("method", "path", "allowed"),
    [
        ("PUT", "/api/v1/datasets", "GET, POST"),
        ("PATCH", "/api/v1/datasets/x", "GET, DELETE"),
        ("DELETE", "/api/v1/evaluations", "GET, POST"),
        ("POST", "/api/v1/evaluations/x", "GET, DELETE"),
        ("DELETE", "/api/v1/evaluations/x/artifacts/result.json", "GET"),
        ("GET", "/api/v1/evaluate", "POST"),
        ("POST", "/healthz", "GET"),
        ("PUT", "/readyz", "GET"),
    ],
)
def test_wrong_methods(api: Api, method: str, path: str, allowed: str) -> None:
    """A method the path does not take is a 405 problem whose Allow lists the right ones."""
    response = api.client.request(method, path, headers=api.headers)
    assert_problem(response, 405, type_="http", detail=allowed)
    assert response.headers["allow"] == allowed
