"""A hostile corpus at the HTTP front door, by class of bad input.

1. Multipart framing and part headers (boundary, Content-Disposition, file names, parts):
   every answer is a 4xx problem document, never a 500, and nothing half-received stays.
2. Quietly dropped input: identical bytes merge their tags and say so; a name or tag over
   its limit is refused with the field and the limit, never cut; unknown or repeated
   fields are refused.
3. Links: ``Location`` and artifact URLs come from ``LOCEVAL_PUBLIC_URL``, whatever
   ``Host`` or forwarded headers the client sends.
"""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest
from pydantic import ValidationError
from sqlalchemy import select

from service.blobs.base import MAX_FILENAME_BYTES, sanitize_filename
from service.db import Dataset
from service.schedules.resource import select_datasets
from service.settings import Settings
from tests.factories import make_trajectory, write_tum
from tests.service._api_fixtures import Api, assert_problem, open_api, tum_pair

CHEAP = {"formats": ["result.json"]}
PUBLIC = "https://loceval.example.org/site/"
HOSTILE_HEADERS = {
    "host": "evil.example",
    "x-forwarded-host": "evil.example",
    "x-forwarded-proto": "http",
    "x-forwarded-prefix": "/phish",
    "forwarded": "host=evil.example;proto=http",
}


@pytest.fixture
def api(tmp_path: Path) -> Iterator[Api]:
    """A fresh app whose public address has a path prefix."""
    with open_api(tmp_path, public_url=PUBLIC) as api:
        yield api


@pytest.fixture
def tum(rng: np.random.Generator, tmp_path: Path) -> bytes:
    """A readable TUM trajectory."""
    return write_tum(tmp_path / "t.txt", make_trajectory(rng, 30)).read_bytes()


def _part(headers: list[bytes], body: bytes, boundary: bytes = b"B") -> bytes:
    return b"--" + boundary + b"\r\n" + b"\r\n".join(headers) + b"\r\n\r\n" + body + b"\r\n"


def _file_part(filename: bytes, body: bytes, *, field: bytes = b"file") -> bytes:
    disposition = b'Content-Disposition: form-data; name="' + field + b'"; ' + filename
    return _part([disposition, b"Content-Type: application/octet-stream"], body)


def _post_raw(api: Api, body: bytes, *, boundary: str = "B", path: str = "/api/v1/datasets") -> Any:
    headers = {**api.headers, "content-type": f"multipart/form-data; boundary={boundary}"}
    return api.client.post(path, headers=headers, content=body)


def _stored_names(api: Api) -> list[str]:
    """Return every stored file, relative to the data folder."""
    return [str(p.relative_to(api.data_dir)) for p in api.stored()]


# --- 1. multipart framing ----------------------------------------------------------------


@pytest.mark.parametrize("path", ["/api/v1/datasets", "/api/v1/evaluate"])
@pytest.mark.parametrize(
    "boundary",
    ["x" * 5000, "x" * 71, '"', "a\tb", "ä" * 10, "ends-in-space ", "semi;colon", "<>"],
    ids=["5000", "71", "quote", "tab", "non-ascii", "space-end", "semicolon", "angle"],
)
def test_boundaries_outside_rfc_2046_are_400(api: Api, path: str, boundary: str) -> None:
    """A boundary that is too long or has characters RFC 2046 forbids is 400, unread."""
    body = (
        f"--{boundary}\r\nContent-Disposition: form-data; name=file; filename=a.txt\r\n\r\n"
        f"1 0 0 0\r\n--{boundary}--\r\n"
    ).encode()
    headers = {
        **api.headers,
        "content-type": f'multipart/form-data; boundary="{boundary}"'.encode(),
    }
    response = api.client.post(path, headers=headers, content=body)
    assert_problem(response, 400, type_="upload.invalid", detail=r"boundary .* RFC 2046")
    assert api.stored() == []


def test_a_70_character_boundary_is_accepted(api: Api, tum: bytes) -> None:
    """The longest boundary RFC 2046 allows works (with its punctuation)."""
    boundary = ("'()+_,-./:=?" * 6)[:69] + "Z"
    body = _file_part(b'filename="run.txt"', tum).replace(b"--B", b"--" + boundary.encode())
    response = _post_raw(api, body + f"--{boundary}--\r\n".encode(), boundary=boundary)
    assert response.status_code == 201, response.text


@pytest.mark.parametrize(
    "part",
    [
        _part([b"Content-Disposition: form-data"], b"x"),
        _part([b'Content-Disposition: form-data; name=""'], b"x"),
        _part([b"Content-Disposition: ;;;=="], b"x"),
        _part([b'Content-Disposition: attachment; name="file"; filename="a.txt"'], b"x"),
        _part([b'Content-Disposition: form-data; name="\xff\xfe"'], b"x"),
        _part([b"Content-Disposition: form-data; name=file; filename*=UTF-8''%ZZ"], b"x"),
        _part([b"Content-Disposition: form-data; name=file; filename*=koi8-r''%C1"], b"x"),
        _part([b"Content-Disposition: form-data; name=file; filename*=UTF-8''%FF.txt"], b"x"),
        _part([b'Content-Disposition: form-data; name="file"; filename="' + b"a" * 20_000], b"x"),
        _part(
            [b'Content-Disposition: form-data; name="file"; filename="a"'] + [b"X-A: b"] * 20, b""
        ),
    ],
    ids=[
        "no name",
        "empty name",
        "garbage",
        "attachment",
        "name not utf-8",
        "filename* bad escape",
        "filename* charset",
        "filename* not utf-8",
        "20 KB header",
        "21 headers",
    ],
)
def test_malformed_part_headers_are_400(api: Api, tum: bytes, part: bytes) -> None:
    """Each malformed Content-Disposition or header block is 400; no file is left behind."""
    body = _file_part(b'filename="ok.txt"', tum) + part + b"--B--\r\n"
    response = _post_raw(api, body)
    assert_problem(response, 400, type_="upload.invalid")
    assert api.stored() == []


@pytest.mark.parametrize(
    ("disposition", "stored"),
    [
        ('filename="' + "轨迹数据" * 37 + 'xy.txt"', None),
        ('filename="' + "r" * 300 + '.txt"', None),
        ('filename="../../etc/passwd"', "passwd"),
        ('filename="C:\\\\x\\\\y.txt"', "y.txt"),
        ('filename="/abs/olute/run.txt"', "run.txt"),
        ('filename="a\x01b\x7fc.txt"', "a_b_c.txt"),
        ('filename="a%00b.txt"', "a_00b.txt"),
        ('filename=".."', "upload"),
        ('filename="...hidden.txt"', "hidden.txt"),
        ("filename*=UTF-8''%E8%BD%A8%E8%BF%B9.txt", "轨迹.txt"),
        ("filename=\"plain.txt\"; filename*=UTF-8''%C3%A9t%C3%A9.txt", "été.txt"),
        ("filename*=iso-8859-1'fr'caf%E9.txt", "café.txt"),
    ],
    ids=[
        "cjk 150",
        "ascii 304",
        "traversal",
        "windows",
        "absolute",
        "controls",
        "percent-nul",
        "dots",
        "leading dots",
        "rfc5987",
        "rfc5987 wins",
        "latin-1 5987",
    ],
)
def test_hostile_file_names_are_display_text(
    api: Api, tum: bytes, disposition: str, stored: str | None
) -> None:
    """A file name never becomes a path: the stored name is plain, bounded, in its folder.

    What changed is said in ``upload.notes``; the file is directly in the dataset's folder.
    """
    response = _post_raw(api, _file_part(disposition.encode(), tum) + b"--B--\r\n")
    assert response.status_code == 201, response.text
    dataset = response.json()
    name = dataset["filename"]
    if stored is not None:
        assert name == stored
    assert len(name.encode()) <= MAX_FILENAME_BYTES
    assert name.endswith(".txt") or name in {"upload", "passwd"}
    assert not set(name) & {"/", "\\", "\x00"}
    assert all(ord(c) >= 0x20 and c != "\x7f" for c in name)
    assert _stored_names(api) == [f"datasets/{dataset['id']}/{name}"]
    if name not in disposition and "filename*" not in disposition:  # changed: said so
        assert repr(name) in dataset["upload"]["notes"][0], dataset["upload"]


def test_long_cjk_name_is_shortened_with_a_note(api: Api, tum: bytes) -> None:
    """The 150-character CJK name of the corpus (a 500 before) is shortened and noted."""
    sent = "轨迹数据" * 37 + "xy.txt"
    response = api.upload(sent, tum)
    assert response.status_code == 201, response.text
    dataset = response.json()
    assert dataset["filename"].startswith("轨迹数据轨迹数据")
    assert dataset["filename"].endswith(".txt")
    assert dataset["name"] == dataset["filename"]
    [note] = dataset["upload"]["notes"]
    assert f"shortened to {MAX_FILENAME_BYTES} bytes" in note
    listed = api.client.get(f"/api/v1/datasets/{dataset['id']}", headers=api.headers).json()
    assert listed["filename"] == dataset["filename"]


def test_non_utf8_file_name_is_read_as_latin_1(api: Api, tum: bytes) -> None:
    """Old clients send Latin-1 names; they are read as such, not refused or mangled."""
    response = _post_raw(api, _file_part(b'filename="caf\xe9.txt"', tum) + b"--B--\r\n")
    assert response.status_code == 201, response.text
    assert response.json()["filename"] == "café.txt"


@pytest.mark.parametrize(
    ("body", "status", "detail"),
    [
        (_file_part(b'filename="empty.txt"', b""), 422, r"'empty\.txt' is empty"),
        (
            _file_part(b'filename="a.txt"', b"1 0 0 0\n") + _file_part(b'filename="b.txt"', b"x"),
            400,
            r"Too many files in one request \(at most 1\)",
        ),
        (_part([b'Content-Disposition: form-data; name="name"'], b"n"), 400, r"has no file"),
        (
            _part([b'Content-Disposition: form-data; name="name"'], b"\xff\xfe"),
            400,
            r"The form field 'name' is not UTF-8",
        ),
        (
            _part([b'Content-Disposition: form-data; name="title"'], b"x"),
            400,
            r"'title' is not one this endpoint reads; send only 'file', 'name', 'tags'",
        ),
        (
            _file_part(b'filename="a.txt"', b"1 0 0 0\n2 1 0 0\n3 2 0 0\n")
            + _part([b'Content-Disposition: form-data; name="name"'], b"first")
            + _part([b'Content-Disposition: form-data; name="name"'], b"second"),
            400,
            r"'name' was sent 2 times; send it once",
        ),
    ],
    ids=["empty file", "two files", "no file", "text not utf-8", "unknown field", "name twice"],
)
def test_bad_parts(api: Api, body: bytes, status: int, detail: str) -> None:
    """Empty, doubled, missing and unknown parts are 4xx problems; nothing is stored."""
    response = _post_raw(api, body + b"--B--\r\n")
    assert_problem(response, status, detail=detail)
    assert api.stored() == []


@pytest.mark.parametrize("path", ["/api/v1/datasets", "/api/v1/evaluate"])
@pytest.mark.parametrize("cut", [0.3, 0.99])
def test_client_disconnect_mid_body_leaves_nothing(api: Api, path: str, cut: float) -> None:
    """A client that goes away mid-body leaves no file in incoming/ or datasets/.

    The request goes through the whole app (key check, logging, routes) as an ASGI call
    whose body stops with ``http.disconnect``.
    """
    payload = b"1.0 0 0 0\n" * 300_000
    field = b"file" if path.endswith("datasets") else b"reference"
    body = _file_part(b'filename="big.txt"', payload, field=field) + b"--B--\r\n"
    sent = body[: int(len(body) * cut)]
    chunks = [sent[k : k + 65536] for k in range(0, len(sent), 65536)]
    messages: list[dict[str, Any]] = [
        {"type": "http.request", "body": c, "more_body": True} for c in chunks
    ]
    messages.append({"type": "http.disconnect"})
    started: list[dict[str, Any]] = []

    async def receive() -> dict[str, Any]:
        return messages.pop(0) if messages else {"type": "http.disconnect"}

    async def send(message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            started.append(message)

    scope = {
        "type": "http",
        "asgi": {"version": "3.0"},
        "http_version": "1.1",
        "method": "POST",
        "scheme": "http",
        "path": path,
        "raw_path": path.encode(),
        "query_string": b"",
        "root_path": "",
        "headers": [
            (b"host", b"testserver"),
            (b"authorization", f"Bearer {api.key}".encode()),
            (b"content-type", b"multipart/form-data; boundary=B"),
            (b"content-length", str(len(body)).encode()),
        ],
        "client": ("127.0.0.1", 5000),
        "server": ("testserver", 80),
        "app": api.app,
    }
    anyio.run(api.app, scope, receive, send)
    assert [m["status"] for m in started] == [400]
    assert api.stored() == []
    assert api.evaluation_count() == 0


# --- 2. nothing dropped without a word ---------------------------------------------------


def test_identical_bytes_merge_tags_so_a_schedule_finds_them(api: Api, tum: bytes) -> None:
    """Uploading the same bytes with a new tag adds the tag: selecting by it finds the data.

    Before, the second upload returned the old dataset and dropped the tag, so a schedule
    selecting ``level2`` missed the recording.
    """
    first = api.upload("run.txt", tum, tags="level3")
    again = api.upload("renamed.txt", tum, tags="level2, level3", name="Level 2 run")
    assert (first.status_code, again.status_code) == (201, 200)
    dataset = again.json()
    assert dataset["id"] == first.json()["id"]
    assert dataset["tags"] == ["level3", "level2"]
    assert dataset["name"] == "run.txt"
    assert dataset["upload"]["deduplicated"] is True
    assert dataset["upload"]["tags_added"] == ["level2"]
    assert dataset["upload"]["name_kept"] == "run.txt"
    notes = " ".join(dataset["upload"]["notes"])
    assert "uploaded before as 'run.txt'" in notes
    assert "keeps its name 'run.txt'; the name 'Level 2 run' of this request was not applied" in (
        notes
    )
    assert "Tags added to the dataset: level2." in notes
    tagged = api.client.get("/api/v1/datasets", params={"tag": "level2"}, headers=api.headers)
    assert [d["id"] for d in tagged.json()["items"]] == [dataset["id"]]
    with api.app.state.runtime.sessions() as session:
        rows = session.scalars(select(Dataset)).all()
    picked = select_datasets(rows, {"tags": ["level2"]}, as_of=dt.datetime.now(dt.UTC))
    assert [d.id for d in picked] == [dataset["id"]]
    third = api.upload("run.txt", tum, tags="level2").json()
    assert third["upload"]["tags_added"] == []
    assert third["upload"]["name_kept"] is None
    assert third["tags"] == ["level3", "level2"]


def test_merged_tags_over_the_limit_are_refused(api: Api, tum: bytes) -> None:
    """A merge that would give a dataset more than 20 tags is 422; its tags stay."""
    first = api.dataset("run.txt", tum, tags=",".join(f"t{k}" for k in range(15)))
    response = api.upload("run.txt", tum, tags=",".join(f"n{k}" for k in range(6)))
    assert_problem(response, 422, detail=r"tags: .* with 15 tags; adding 6 would pass the limit")
    again = api.client.get(f"/api/v1/datasets/{first['id']}", headers=api.headers).json()
    assert again["tags"] == first["tags"]


@pytest.mark.parametrize(
    ("fields", "detail"),
    [
        ({"name": "n" * 425}, r"name: String should have at most 300 characters"),
        ({"name": "a\x00b"}, r"name: holds control characters"),
        ({"name": "line\nbreak"}, r"name: holds control characters"),
        ({"tags": "ok, " + "t" * 51}, r"tags\.1: String should have at most 50 characters"),
        ({"tags": ",".join(f"t{k}" for k in range(21))}, r"tags: List should have at most 20"),
        ({"tags": "a\tb"}, r"tags\.0: holds control characters"),
    ],
    ids=["name 425", "name nul", "name newline", "tag 51", "21 tags", "tag tab"],
)
def test_over_limit_fields_are_refused_not_cut(
    api: Api, tum: bytes, fields: dict[str, str], detail: str
) -> None:
    """A name or tag over its limit is 422 naming the field and the limit; nothing stored."""
    response = api.upload("run.txt", tum, **fields)
    body = assert_problem(response, 422, type_="request.invalid", detail=detail)
    assert body["errors"][0]["loc"][0] in fields
    assert api.stored() == []


def test_names_at_the_limit_are_kept_whole(api: Api, tum: bytes) -> None:
    """A 300-character name and 20 tags of 50 characters are stored as sent."""
    name = "é" * 300
    tags = [f"{k:02d}" + "t" * 48 for k in range(20)]
    dataset = api.dataset("run.txt", tum, name=name, tags=",".join(tags))
    assert dataset["name"] == name
    assert dataset["tags"] == tags


def test_one_shot_repeated_single_field_is_refused(api: Api, rng: np.random.Generator) -> None:
    """Two 'options' fields would drop one without a word: 400 naming the field."""
    reference, estimate = tum_pair(rng, api.data_dir.parent)
    files = [("reference", ("r.txt", reference)), ("estimate", ("e.txt", estimate))]
    data = {"options": [json.dumps(CHEAP), json.dumps({"units": "mm"})]}
    response = api.client.post("/api/v1/evaluate", headers=api.headers, files=files, data=data)
    assert_problem(response, 400, detail=r"'options' was sent 2 times; send it once")
    assert api.stored() == []


def test_sanitize_filename_reports_each_change() -> None:
    """The sanitiser names every kind of change and is stable on its own output."""
    name, changes = sanitize_filename("../a b/" + "x" * 200 + ".mcap")
    assert name.endswith(".mcap")
    assert len(name.encode()) == MAX_FILENAME_BYTES
    assert changes == [
        "its folders were removed",
        f"it was shortened to {MAX_FILENAME_BYTES} bytes",
    ]
    assert sanitize_filename(name) == (name, [])
    assert sanitize_filename("run.bag") == ("run.bag", [])


_SCHEDULE = {
    "name": "weekly",
    "cron": "0 7 * * mon",
    "template": {"reference": {"selector": "/gt"}, "estimates": [{"selector": "/est"}]},
}


@pytest.mark.parametrize("database", ["sqlite", "postgresql"])
def test_nul_characters_are_refused_everywhere(
    tmp_path: Path, tum: bytes, database: str, request: pytest.FixtureRequest
) -> None:
    """NUL in a path, a query, a JSON body, a form field or a Hops id is a 4xx, never a 500.

    PostgreSQL cannot store or compare text holding NUL: each of these was a 500 there.
    """
    url = "" if database == "sqlite" else request.getfixturevalue("postgres_url")
    with open_api(tmp_path, database_url=url, raise_server_exceptions=False) as api:
        dataset = api.dataset("run.txt", tum)
        client, headers = api.client, api.headers
        evaluation = {
            "reference": {"dataset_id": dataset["id"], "name": "r\x00"},
            "estimates": [{"dataset_id": dataset["id"]}],
        }
        selection = {**_SCHEDULE, "selection": {"tags": ["a\x00"], "name_pattern": "\x00"}}
        hops = {
            "pointer": "hops/paths",
            "values": [
                {
                    "ParamName": "Evaluation",
                    "InnerTree": {"{0}": [{"type": "System.String", "data": '"a\\u0000"'}]},
                }
            ],
        }
        answers = {
            "path id": client.get("/api/v1/datasets/a%00", headers=headers),
            "patch id": client.patch("/api/v1/schedules/x%00", headers=headers, json={}),
            "query tag": client.get("/api/v1/datasets", params={"tag": "a\x00"}, headers=headers),
            "query status": client.get("/api/v1/evaluations?status=%00", headers=headers),
            "schedule name": client.post(
                "/api/v1/schedules", headers=headers, json={**_SCHEDULE, "name": "a\x00"}
            ),
            "schedule selection": client.post("/api/v1/schedules", headers=headers, json=selection),
            "evaluation name": client.post("/api/v1/evaluations", headers=headers, json=evaluation),
            "upload name": api.upload("other.txt", tum + b"\n", name="a\x00"),
            "hops id": client.post("/solve", headers=headers, json=hops),
        }
        statuses = {k: r.status_code for k, r in answers.items()}
        assert all(400 <= s < 500 for s in statuses.values()), statuses
        for what in ("path id", "query tag", "query status", "schedule name", "evaluation name"):
            assert_problem(answers[what], 422, type_="request.invalid")
        assert answers["query tag"].json()["errors"][0]["loc"] == ["query", "tag"]
        assert statuses["hops id"] == 404, answers["hops id"].text
        locations = {tuple(e["loc"]) for e in answers["schedule selection"].json()["errors"]}
        assert locations == {("body", "selection", "tags"), ("body", "selection", "name_pattern")}
        assert len(api.stored()) == 1


# --- 3. links from the configured address ------------------------------------------------


def test_links_ignore_host_and_forwarded_headers(api: Api, rng: np.random.Generator) -> None:
    """Location and artifact URLs start with LOCEVAL_PUBLIC_URL (its prefix included)."""
    headers = {**api.headers, **HOSTILE_HEADERS}
    reference, estimate = tum_pair(rng, api.data_dir.parent)
    ids = []
    for name, content in (("r.txt", reference), ("e.txt", estimate)):
        response = api.client.post(
            "/api/v1/datasets", headers=headers, files={"file": (name, content)}
        )
        assert response.status_code == 201, response.text
        ids.append(response.json()["id"])
        assert response.headers["location"] == f"{PUBLIC}api/v1/datasets/{ids[-1]}"
    body = {
        "reference": {"dataset_id": ids[0]},
        "estimates": [{"dataset_id": ids[1]}],
        "options": CHEAP,
    }
    created = api.client.post("/api/v1/evaluations", headers=headers, json=body)
    assert created.status_code == 202, created.text
    evaluation = created.json()
    own = f"{PUBLIC}api/v1/evaluations/{evaluation['id']}"
    assert created.headers["location"] == own
    assert [a["url"] for a in evaluation["artifacts"]] == [f"{own}/artifacts/result.json"]
    for url in (f"/api/v1/evaluations/{evaluation['id']}", "/api/v1/evaluations"):
        text = api.client.get(url, headers=headers).text
        assert "evil.example" not in text
        assert "testserver" not in text
        assert f"{own}/artifacts/result.json" in text
    files = [("reference", ("r.txt", reference)), ("estimate", ("e.txt", estimate))]
    one_shot = api.client.post(
        "/api/v1/evaluate", headers=headers, files=files, data={"options": json.dumps(CHEAP)}
    )
    assert one_shot.status_code == 202, one_shot.text
    assert one_shot.headers["location"].startswith(f"{PUBLIC}api/v1/evaluations/")
    assert "evil.example" not in one_shot.text


def test_schedule_links_ignore_host(api: Api) -> None:
    """A schedule's Location comes from the public address too."""
    body = {
        "name": "weekly",
        "cron": "0 7 * * mon",
        "template": {"reference": {"selector": "/gt"}, "estimates": [{"selector": "/est"}]},
    }
    response = api.client.post(
        "/api/v1/schedules", headers={**api.headers, **HOSTILE_HEADERS}, json=body
    )
    assert response.status_code == 201, response.text
    assert response.headers["location"] == f"{PUBLIC}api/v1/schedules/{response.json()['id']}"


@pytest.mark.parametrize(
    ("public_url", "expected"),
    [
        ("https://h.example", "https://h.example/api/v1/datasets/"),
        ("https://h.example/", "https://h.example/api/v1/datasets/"),
        ("https://h.example/loceval", "https://h.example/loceval/api/v1/datasets/"),
        ("http://10.0.0.5:8080/a/b//", "http://10.0.0.5:8080/a/b/api/v1/datasets/"),
    ],
)
def test_public_url_forms(tmp_path: Path, tum: bytes, public_url: str, expected: str) -> None:
    """With or without a trailing slash or a path prefix, links have one slash between."""
    with open_api(tmp_path, public_url=public_url) as api:
        response = api.client.post(
            "/api/v1/datasets",
            headers={**api.headers, "host": "evil.example"},
            files={"file": ("run.txt", tum)},
        )
    assert response.headers["location"] == expected + response.json()["id"]


@pytest.mark.parametrize(
    "public_url", ["", "evil.example", "ftp://h.example/", "https://", "https://h/?a=1", "/x"]
)
def test_bad_public_url_is_refused_at_start(tmp_path: Path, public_url: str) -> None:
    """A public address that cannot start a link is a settings error naming the variable."""
    with pytest.raises(ValidationError, match=r"LOCEVAL_PUBLIC_URL must be"):
        Settings(data_dir=tmp_path, public_url=public_url)


def test_a_query_parameter_given_twice_is_refused(api: Api) -> None:
    """``?tag=a&tag=b`` is a 422 naming the parameter: the schema says one value, and
    FastAPI alone would keep the last one silently (schemathesis checks the same)."""
    answers = {
        "tag": api.client.get("/api/v1/datasets?tag=a&tag=b", headers=api.headers),
        "limit": api.client.get("/api/v1/evaluations?limit=5&limit=6", headers=api.headers),
    }
    for name, answer in answers.items():
        assert_problem(answer, 422, type_="request.invalid")
        assert answer.json()["errors"] == [
            {
                "loc": ["query", name],
                "msg": "is given more than once; give it once",
                "type": "repeated_parameter",
            }
        ]
    once = api.client.get("/api/v1/datasets?tag=a&limit=5", headers=api.headers)
    assert once.status_code == 200
