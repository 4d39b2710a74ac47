"""What a site network needs from the service: /docs offline, plain 404s, a settable port."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import httpx2

from tests.service._api_fixtures import Api, assert_problem
from tests.service.conftest import ServiceProcess, free_port, service_env, wait_ready


def test_docs_page_and_its_assets_come_from_the_service(api: Api) -> None:
    """/docs names no external address, and every file it references is served here."""
    page = api.client.get("/docs")
    assert page.status_code == 200
    assert "swagger" in page.text.lower()
    assert not re.search(r"https?://", page.text), page.text
    referenced = re.findall(r"""(?:src|href|url)\s*[=:]\s*['"]([^'"]+)['"]""", page.text)
    assets = [ref for ref in referenced if ref.startswith("/docs/assets/")]
    assert sorted(assets) == [
        "/docs/assets/favicon-32x32.png",
        "/docs/assets/swagger-ui-bundle.js",
        "/docs/assets/swagger-ui.css",
    ]
    assert "/openapi.json" in referenced
    for ref in referenced:
        answer = api.client.get(ref)
        assert answer.status_code == 200, ref
        assert len(answer.content) > 500, ref  # the real file (the icon: 628 bytes)
    assert "SwaggerUIBundle" in api.client.get("/docs/assets/swagger-ui-bundle.js").text
    assert (
        api.client.get("/docs/assets/swagger-ui.css").headers["content-type"].startswith("text/css")
    )


def test_docs_assets_serve_only_the_page_files(api: Api) -> None:
    """Another name under /docs/assets is a 404 problem, not a file of the package."""
    assert_problem(api.client.get("/docs/assets/index.html"), 404, detail="not a file")
    assert api.client.get("/redoc").status_code == 404  # ReDoc needs a CDN: not offered


def test_unknown_api_path_is_404_without_a_key(api: Api) -> None:
    """/api/v1/healthz matches no route: 404 pointing at /docs, with or without a key."""
    assert_problem(api.client.get("/api/v1/healthz"), 404, type_="http", detail=r"/docs")
    assert_problem(
        api.client.get("/api/v1/healthz", headers=api.headers), 404, type_="http", detail="/docs"
    )
    assert_problem(api.client.get("/api/v1/no/such/thing"), 404, type_="http")


def test_known_route_still_needs_a_key(api: Api) -> None:
    """An unknown id on a real route, or a wrong method, still answers 401 without a key."""
    for method, path in (
        ("GET", "/api/v1/datasets/0123456789abcdef0123456789abcdef"),
        ("GET", "/api/v1/evaluations/nope"),
        ("DELETE", "/api/v1/evaluations"),
        ("GET", "/api/v1/datasets"),
        ("GET", "/api/v1"),
    ):
        answer = api.client.request(method, path)
        if path == "/api/v1":  # no route is /api/v1 itself: a 404 like any unknown path
            assert_problem(answer, 404, type_="http")
            continue
        assert_problem(answer, 401, detail="API key")


def test_serve_port_and_host_from_the_environment(tmp_path: Path) -> None:
    """Without --port and --host, loceval serve listens where LOCEVAL_PORT/LOCEVAL_HOST say."""
    port = free_port()
    env = service_env(tmp_path / "data", {"LOCEVAL_PORT": str(port), "LOCEVAL_HOST": "127.0.0.1"})
    service = ServiceProcess.start([sys.executable, "-m", "service.cli", "serve"], env)
    try:
        url = f"http://127.0.0.1:{port}"
        wait_ready(url, service)
        assert httpx2.get(f"{url}/healthz", timeout=10).json() == {"status": "ok"}
        assert f"http://127.0.0.1:{port}/" in service.output
    finally:
        service.stop()


def test_bad_port_setting_is_one_clear_line(tmp_path: Path) -> None:
    """LOCEVAL_PORT=0 is refused before anything starts, naming the variable."""
    proc = subprocess.run(
        [sys.executable, "-m", "service.cli", "serve"],
        capture_output=True,
        text=True,
        env=service_env(tmp_path / "data", {"LOCEVAL_PORT": "0"}),
        timeout=120,
        check=False,
    )
    assert proc.returncode != 0
    assert "LOCEVAL_PORT" in proc.stderr, proc.stderr
