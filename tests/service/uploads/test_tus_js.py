"""tus-js-client (the client of the page) under node against a real ``loceval serve``.

The client's connection is cut at 30 %, 60 % and 90 % by the loopback proxy, on the folder
and on the bucket: it resumes each time, the server receives at most one part again per
cut, and the dataset is the file. The client is installed from the npm registry at the
version ``tus_js/package-lock.json`` pins (skipped when the registry cannot be reached; a
failure when CI is set).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.conftest import require_tool, skip_or_fail
from tests.harness.proxy import CuttingProxy
from tests.service.conftest import start_server
from tests.service.uploads.test_tus_clients import (
    CHUNK,
    HEADERS_SLACK,
    assert_dataset_is_the_file,
    backend,
    proxy,
    upload_state,
)

__all__ = ["backend", "proxy"]

pytestmark = [pytest.mark.slow]

CLIENT_DIR = Path(__file__).resolve().parent / "tus_js"


@pytest.fixture(scope="session")
def tus_js() -> tuple[str, Path]:
    """Return node and the upload script, with tus-js-client installed beside it."""
    node = require_tool("node")
    npm = require_tool("npm")
    if not (CLIENT_DIR / "node_modules" / "tus-js-client").is_dir():
        install = subprocess.run(
            [npm, "ci", "--prefix", str(CLIENT_DIR), "--no-audit", "--no-fund"],
            capture_output=True,
            text=True,
            check=False,
            timeout=600,
        )
        if install.returncode != 0:
            skip_or_fail(f"npm could not install tus-js-client: {install.stderr[-2000:]}")
    return node, CLIENT_DIR / "upload.js"


def test_tus_js_client_resumes_cut_connections(  # noqa: PLR0917  (fixtures)
    tmp_path: Path,
    proxy: CuttingProxy,
    backend: dict[str, str],
    large_recording: Path,
    tus_js: tuple[str, Path],
    request: pytest.FixtureRequest,
) -> None:
    size = large_recording.stat().st_size
    cuts = [int(size * f) for f in (0.3, 0.6, 0.9)]
    proxy.cut_at(cuts)
    env = {"LOCEVAL_PUBLIC_URL": proxy.url, "LOCEVAL_MIN_FREE_BYTES": "0", **backend}
    server = start_server(tmp_path / "data", env=env)
    try:
        proxy.target = int(server.url.rsplit(":", 1)[1])
        node, script = tus_js
        done = subprocess.run(
            [
                node,
                str(script),
                f"{proxy.url}/api/v1/uploads",
                server.api_key,
                str(large_recording),
                str(CHUNK),
            ],
            capture_output=True,
            text=True,
            check=False,
            timeout=300,
        )
        assert done.returncode == 0, done.stderr
        assert proxy.cuts == cuts
        request.node.user_properties.append(("bytes_received", proxy.sent))
        request.node.user_properties.append(("file_bytes", size))
        assert proxy.sent <= size + len(cuts) * CHUNK + HEADERS_SLACK, (proxy.sent, size)
        url = json.loads(done.stdout.strip().splitlines()[-1])["url"]
        assert_dataset_is_the_file(upload_state(server, url), large_recording)
    finally:
        server.stop()
