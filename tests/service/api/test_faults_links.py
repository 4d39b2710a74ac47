"""No link from a request's Host or X-Forwarded-* header, and a limit on a request's head.

Against a real ``loceval serve`` (uvicorn), since the header limit is the HTTP server's:
the in-process test client has none to test.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Iterator
from urllib.parse import urlsplit

import httpx2
import pytest

from tests.service.conftest import LiveServer, running_server

PROBLEM_JSON = "application/problem+json"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """One ``loceval serve`` for the module."""
    with running_server(tmp_path_factory.mktemp("data")) as server:
        yield server


HOSTILE = {
    "Host": "evil.example",
    "X-Forwarded-Host": "evil.example",
    "X-Forwarded-Proto": "https",
    "X-Forwarded-Prefix": "/phish",
    "Forwarded": "host=evil.example;proto=https",
}


@pytest.mark.parametrize("keyed", [False, True], ids=["no-key", "key"])
@pytest.mark.parametrize(
    "path", ["/api/v1/datasets/", "/api/v1/evaluations/", "/api/v1/schedules/", "/docs/"]
)
def test_a_trailing_slash_is_not_redirected_to_the_host_a_client_names(
    server: LiveServer, path: str, *, keyed: bool
) -> None:
    """The other slash form is a 404 naming the path, with no Location and no host in it."""
    headers = dict(HOSTILE)
    if keyed:
        headers["Authorization"] = f"Bearer {server.api_key}"
    with httpx2.Client(base_url=server.url, timeout=30, follow_redirects=False) as client:
        answer = client.get(path, headers=headers)
    assert answer.status_code == 404, (answer.status_code, answer.headers)
    assert "location" not in answer.headers
    assert answer.headers["content-type"].startswith(PROBLEM_JSON)
    assert "evil.example" not in answer.text
    assert answer.json()["detail"] == (
        f"No such endpoint; did you mean {path.rstrip('/')} (no redirect is sent)?"
    )


def test_links_in_answers_start_with_the_public_url(server: LiveServer) -> None:
    """A created resource's Location is the configured address whatever the Host says."""
    headers = {**HOSTILE, "Authorization": f"Bearer {server.api_key}"}
    body = b"0 0 0 0\n1 1 0 0\n2 2 0 0\n3 3 0 0\n"
    with httpx2.Client(base_url=server.url, timeout=60) as client:
        answer = client.post("/api/v1/datasets", headers=headers, files={"file": ("gt.txt", body)})
    assert answer.status_code in {200, 201}, answer.text
    location = urlsplit(answer.headers["location"])
    assert f"{location.scheme}://{location.netloc}" == server.url
    assert "evil" not in answer.text


def _raw_request(server: LiveServer, head: bytes) -> bytes:
    """Send a request head on a fresh connection; return all the server answers."""
    address = urlsplit(server.url)
    with socket.create_connection((address.hostname, address.port), timeout=30) as sock:
        # the server may answer and stop reading before it has read everything
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):
            sock.sendall(head)
        chunks = []
        while chunk := sock.recv(65536):
            chunks.append(chunk)
    return b"".join(chunks)


@pytest.mark.parametrize(
    "head",
    [
        b"X-Big: " + b"a" * 200_000 + b"\r\n",
        b"".join(b"X-Many-%d: %s\r\n" % (k, b"b" * 100) for k in range(2000)),
    ],
    ids=["one-long-header", "many-headers"],
)
def test_an_oversize_request_head_is_431(server: LiveServer, head: bytes) -> None:
    """Header lines over the limit: 431 as a problem document; the server goes on serving."""
    request = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n" + head + b"\r\n"
    answer = _raw_request(server, request)
    status_line, _, rest = answer.partition(b"\r\n")
    assert status_line.startswith(b"HTTP/1.1 431 "), answer[:500]
    headers, _, body = rest.partition(b"\r\n\r\n")
    assert b"content-type: application/problem+json" in headers.lower()
    assert b'"status": 431' in body
    assert b"64 KiB" in body
    with httpx2.Client(base_url=server.url, timeout=30) as client:
        fine = client.get("/healthz", headers={"X-Normal": "c" * 8000})
    assert fine.status_code == 200
