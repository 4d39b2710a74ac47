"""No link from a request's Host or X-Forwarded-* header, and a limit on a request's head.

Against a real ``loceval serve`` (uvicorn), since the header limit is the HTTP server's:
the in-process test client has none to test.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit

import httpx2
import numpy as np
import pytest

from service.settings import Settings
from tests.harness.ports import free_port
from tests.harness.processes import ServiceProcess, loceval_argv, service_env
from tests.service._api_fixtures import tum_pair
from tests.service.conftest import (
    _KEY_LINE,
    READY_TIMEOUT_S,
    LiveServer,
    running_server,
    succeeded,
    upload,
    wait_for_evaluation,
    wait_ready,
)

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


# --- links follow the address served on (issue 44, item 1) ---------------------------------


@pytest.mark.parametrize(
    ("env", "args", "links"),
    [
        ({"LOCEVAL_PORT": "{port}"}, (), "http://127.0.0.1:{port}"),
        ({"LOCEVAL_HOST": "0.0.0.0"}, ("--port", "{port}"), "http://127.0.0.1:{port}"),  # noqa: S104
        (
            {"LOCEVAL_PORT": "{port}", "LOCEVAL_PUBLIC_URL": "https://site.example/loceval/"},
            (),
            "https://site.example/loceval",
        ),
    ],
    ids=["LOCEVAL_PORT", "--port-on-every-interface", "public-url-wins"],
)
def test_links_follow_the_port_served_on_unless_a_public_url_is_set(
    tmp_path: Path, rng: np.random.Generator, env: dict[str, str], args: tuple[str, ...], links: str
) -> None:
    """`LOCEVAL_PORT=N make serve`: Location and artifact URLs point at port N, and work."""
    tum_pair(rng, tmp_path)  # reference.txt and estimate.txt
    port = free_port()
    full_env = service_env(tmp_path / "data", {k: v.format(port=port) for k, v in env.items()})
    argv = loceval_argv("serve", *(a.format(port=port) for a in args))
    service = ServiceProcess.start(argv, full_env)
    try:
        key = service.wait_for_line(_KEY_LINE, READY_TIMEOUT_S)
        assert key is not None, service.output
        url = f"http://127.0.0.1:{port}"
        wait_ready(url, service)
        base = links.format(port=port)
        assert f"links start with {base}/" in service.output
        headers = {"Authorization": f"Bearer {key.group(1)}"}
        with httpx2.Client(base_url=url, headers=headers, timeout=120) as client:
            reference = upload(client, tmp_path / "reference.txt")
            estimate = upload(client, tmp_path / "estimate.txt")
            body = {
                "reference": {"dataset_id": reference["id"]},
                "estimates": [{"dataset_id": estimate["id"]}],
                "options": {"formats": ["result.json"]},
            }
            answer = client.post("/api/v1/evaluations", json=body)
            assert answer.status_code == 202, answer.text
            evaluation = answer.json()
            assert answer.headers["location"] == f"{base}/api/v1/evaluations/{evaluation['id']}"
            done = succeeded(wait_for_evaluation(client, evaluation["id"]))
            artifact = done["artifacts"][0]["url"]
            assert artifact.startswith(f"{base}/api/v1/evaluations/{evaluation['id']}/")
            if base.startswith(url):  # the link itself answers on the port served on
                assert client.get(artifact).status_code == 200
    finally:
        service.stop()


@pytest.mark.parametrize(
    ("host", "public_url", "links"),
    [
        ("127.0.0.1", None, "http://127.0.0.1:18731"),
        ("0.0.0.0", None, "http://127.0.0.1:18731"),  # noqa: S104
        ("::", None, "http://[::1]:18731"),
        ("fe80::1", None, "http://[fe80::1]:18731"),
        ("site-pc.local", None, "http://site-pc.local:18731"),
        ("0.0.0.0", "https://h.example/loceval", "https://h.example/loceval"),  # noqa: S104
    ],
)
def test_the_public_url_defaults_to_the_address_served_on(
    tmp_path: Path, host: str, public_url: str | None, links: str
) -> None:
    """Unset, the public URL is http://HOST:PORT (every interface: this machine's loopback)."""
    settings = Settings(data_dir=tmp_path, host=host, port=18731, public_url=public_url)
    assert settings.resolved_public_url == links
