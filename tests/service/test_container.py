"""The Dockerfile, built and run: the image serves, evaluates and keeps its state in /data.

Builds the image with the classic builder from a base image (``LOCEVAL_DOCKER_BASE``, or a
debootstrap of Debian bookworm made here and imported once as ``loceval-test-base:bookworm``
where no registry answers), runs it as its unprivileged user with a named volume, waits for
the HEALTHCHECK, evaluates the public TUM pair through ``POST /api/v1/evaluate``, downloads
the PDF, restarts the container and finds the evaluation again, and then finds it from a new
container on the same volume. Docker keeps the base image and the build's layers, so a rerun
builds only what changed.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx2
import pytest

from exporters import ARTIFACTS
from tests.conftest import require_tool, skip_or_fail
from tests.service.conftest import REPO, assert_same_ate, cli_json, succeeded, wait_for_evaluation

pytestmark = [pytest.mark.slow, pytest.mark.public_data]

GROUNDTRUTH = "fr2_desk_groundtruth.txt"
ESTIMATE = "fr2_desk_ORB.txt"
# Monocular ORB-SLAM: its scale is arbitrary, so align with a similarity (as evo's `-as`).
OPTIONS = '{"align": "sim3"}'
CLI_OPTIONS = ("--align", "sim3")

BASE_IMAGE = "loceval-test-base:bookworm"
IMAGE = "loceval:test"
HOST_CA_BUNDLE = Path("/etc/ssl/certs/ca-certificates.crt")
HOST_PIP_CONF = Path("/etc/pip.conf")
DEBOOTSTRAP_TIMEOUT_S = 900.0
BUILD_TIMEOUT_S = 1200.0
HEALTHY_TIMEOUT_S = 120.0
_KEY_LINE = re.compile(r"API key for project 'default' \(shown once\): (\S+)")


def _docker(*args: str, timeout: float = 120, check: bool = True) -> str:
    """Run ``docker ARGS`` (classic builder) and return its stdout; fail with its output."""
    proc = subprocess.run(
        ["docker", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        env={**os.environ, "DOCKER_BUILDKIT": "0"},
    )
    if check and proc.returncode != 0:
        pytest.fail(
            f"docker {' '.join(args)} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
        )
    return proc.stdout


def _require_engine() -> None:
    """Skip (fail in CI) unless the docker command is installed and an engine answers."""
    require_tool("docker")
    proc = subprocess.run(
        ["docker", "version", "--format", "{{.Server.Version}}"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    if proc.returncode != 0:
        skip_or_fail(
            f"no Docker engine answers ({proc.stderr.strip()}); start one with "
            "`dockerd > /tmp/dockerd.log 2>&1 &` as root (.ci/run does)"
        )


def _image_exists(name: str) -> bool:
    return _docker("image", "inspect", name, check=False).strip() not in {"", "[]"}


def _debootstrap_base() -> None:
    """Import a debootstrap of bookworm with python3, python3-venv and this machine's CAs.

    The machine's CA bundle and /etc/pip.conf go into the image so that pip inside the
    build reaches the package registry the way it does here.
    """
    debootstrap = require_tool("debootstrap")
    if os.geteuid() != 0:
        skip_or_fail("debootstrap needs root to build the base image; run the test as root")
    root = Path(tempfile.mkdtemp(prefix="loceval-bookworm-"))
    try:
        proc = subprocess.run(
            [
                debootstrap,
                "--variant=minbase",
                "--include=python3,python3-venv,ca-certificates",
                "bookworm",
                str(root),
            ],
            capture_output=True,
            text=True,
            timeout=DEBOOTSTRAP_TIMEOUT_S,
            check=False,
        )
        if proc.returncode != 0:
            pytest.fail(f"debootstrap exited {proc.returncode}:\n{proc.stdout[-3000:]}")
        # The downloaded packages and apt's lists only bloat the image (the build updates).
        for cache in ("var/cache/apt/archives", "var/lib/apt/lists"):
            for path in (root / cache).glob("*"):
                if path.is_file():
                    path.unlink()
        if HOST_CA_BUNDLE.is_file():
            shutil.copyfile(HOST_CA_BUNDLE, root / "etc/ssl/certs/ca-certificates.crt")
        if HOST_PIP_CONF.is_file():
            shutil.copyfile(HOST_PIP_CONF, root / "etc/pip.conf")
        tar = subprocess.Popen(["tar", "-C", str(root), "-c", "."], stdout=subprocess.PIPE)
        try:
            imported = subprocess.run(
                ["docker", "import", "-", BASE_IMAGE],
                stdin=tar.stdout,
                capture_output=True,
                text=True,
                timeout=600,
                check=False,
            )
        finally:
            assert tar.stdout is not None
            tar.stdout.close()
            tar.wait(60)
        if imported.returncode != 0 or tar.returncode != 0:
            pytest.fail(f"docker import failed (tar {tar.returncode}): {imported.stderr}")
    finally:
        shutil.rmtree(root, ignore_errors=True)


@pytest.fixture(scope="module")
def image() -> str:
    """The image built from the worktree's Dockerfile (Docker's layer cache makes reruns fast)."""
    _require_engine()
    base = os.environ.get("LOCEVAL_DOCKER_BASE", BASE_IMAGE)
    if base == BASE_IMAGE and not _image_exists(BASE_IMAGE):
        _debootstrap_base()
    _docker(
        "build",
        "--network",
        "host",
        "--build-arg",
        f"BASE={base}",
        "--tag",
        IMAGE,
        str(REPO),
        timeout=BUILD_TIMEOUT_S,
    )
    return IMAGE


@dataclass
class Container:
    """A running container of the image: its name and the host port of its 8000."""

    name: str

    @property
    def url(self) -> str:
        """The service's address on this host (looked up again after a restart)."""
        mapping = _docker("port", self.name, "8000/tcp").splitlines()[0].strip()
        return f"http://127.0.0.1:{mapping.rsplit(':', 1)[1]}"

    @property
    def logs(self) -> str:
        """Everything the container printed (stdout and stderr), over all its starts."""
        proc = subprocess.run(
            ["docker", "logs", self.name], capture_output=True, text=True, timeout=60, check=False
        )
        return proc.stdout + proc.stderr

    def health(self) -> str:
        """The HEALTHCHECK's status: starting, healthy or unhealthy."""
        return _docker("inspect", "--format", "{{.State.Health.Status}}", self.name).strip()

    def wait_healthy(self) -> float:
        """Wait until the HEALTHCHECK says healthy; return the seconds it took."""
        start = time.monotonic()
        while time.monotonic() - start < HEALTHY_TIMEOUT_S:
            running = _docker("inspect", "--format", "{{.State.Running}}", self.name).strip()
            status = self.health()
            if status == "healthy":
                return time.monotonic() - start
            if status == "unhealthy" or running != "true":
                break
            time.sleep(0.2)
        pytest.fail(f"container {self.name} is {self.health()}, not healthy; log:\n{self.logs}")

    def client(self, api_key: str) -> httpx2.Client:
        """Return an HTTP client with the key; close it after use."""
        return httpx2.Client(
            base_url=self.url, headers={"Authorization": f"Bearer {api_key}"}, timeout=120
        )


RunContainer = Callable[[str], tuple[Container, float]]
"""Start a container on a volume, wait until healthy; return it and the seconds that took."""


@pytest.fixture
def volume() -> Iterator[str]:
    """A fresh named volume, removed at the end."""
    name = f"loceval-test-{uuid.uuid4().hex[:12]}"
    _docker("volume", "create", name)
    yield name
    _docker("volume", "rm", "--force", name, check=False)


@pytest.fixture
def run_container(image: str) -> Iterator[RunContainer]:
    """Start containers of the image (``docker run -d``); each is removed at the end."""
    names: list[str] = []

    def run(volume: str) -> tuple[Container, float]:
        name = f"loceval-test-{uuid.uuid4().hex[:12]}"
        names.append(name)
        start = time.monotonic()
        _docker(
            "run",
            "--detach",
            "--name",
            name,
            "--publish",
            "127.0.0.1::8000",
            "--volume",
            f"{volume}:/data",
            "--health-interval",
            "1s",
            image,
        )
        container = Container(name)
        container.wait_healthy()
        return container, time.monotonic() - start

    yield run
    for name in names:
        _docker("rm", "--force", "--volumes", name, check=False)


def _api_key(container: Container) -> str:
    keys = _KEY_LINE.findall(container.logs)
    assert len(keys) == 1, f"expected one API key line in the log:\n{container.logs}"
    return str(keys[0])


def _get_evaluation(container: Container, api_key: str, evaluation_id: str) -> dict[str, Any]:
    with container.client(api_key) as http:
        answer = http.get(f"/api/v1/evaluations/{evaluation_id}")
    assert answer.status_code == 200, answer.text
    evaluation: dict[str, Any] = answer.json()
    return evaluation


def test_image_serves_evaluates_and_keeps_its_state(
    volume: str, run_container: RunContainer, public_data: Path
) -> None:
    """The image runs unprivileged, turns healthy, evaluates, and keeps it across restarts."""
    container, to_healthy_s = run_container(volume)
    print(f"docker run to healthy: {to_healthy_s:.1f} s")  # noqa: T201  (shown by pytest -s)
    assert _docker("exec", container.name, "id", "-un").strip() == "loceval"
    assert _docker("exec", container.name, "id", "-u").strip() == "10001"
    api_key = _api_key(container)

    with container.client(api_key) as http:
        gt, orb = public_data / GROUNDTRUTH, public_data / ESTIMATE
        with gt.open("rb") as reference, orb.open("rb") as estimate:
            answer = http.post(
                "/api/v1/evaluate",
                files=[("reference", (gt.name, reference)), ("estimate", (orb.name, estimate))],
                data={"options": OPTIONS},
            )
        assert answer.status_code == 202, answer.text
        evaluation_id = answer.json()["id"]
        evaluation = succeeded(wait_for_evaluation(http, evaluation_id))
        pdf = http.get(f"/api/v1/evaluations/{evaluation_id}/artifacts/report.pdf")
    # Every artifact was written: the CAD and PDF libraries load in the image.
    assert {a["name"] for a in evaluation["artifacts"]} == set(ARTIFACTS)
    assert pdf.status_code == 200, pdf.text[:500]
    assert pdf.headers["content-type"].startswith("application/pdf")
    assert pdf.content.startswith(b"%PDF")
    # The container computes what this checkout computes: the CLI here on the same files.
    assert_same_ate(evaluation["result"], cli_json(str(gt), str(orb), *CLI_OPTIONS))
    # Written by the unprivileged user into the volume.
    owners = _docker("exec", container.name, "find", "/data", "-not", "-user", "loceval")
    assert owners.strip() == "", f"files in /data not owned by loceval:\n{owners}"

    start = time.monotonic()
    _docker("restart", "--time", "15", container.name, timeout=120)
    stopped_s = time.monotonic() - start
    container.wait_healthy()
    # SIGTERM reached the service (tini passes it on) instead of a SIGKILL after 15 s.
    assert stopped_s < 10, f"docker restart took {stopped_s:.1f} s"
    again = _get_evaluation(container, api_key, evaluation_id)
    assert again["status"] == "succeeded"
    assert again["result"] == evaluation["result"]
    assert len(_KEY_LINE.findall(container.logs)) == 1, "a restart made a new key"

    # A clean stop: the service shut down on SIGTERM and the container exited with 0.
    _docker("stop", "--time", "15", container.name, timeout=60)
    assert _docker("inspect", "--format", "{{.State.ExitCode}}", container.name).strip() == "0"
    assert container.logs.count("Application shutdown complete") == 2

    # A new container on the same volume: the state lives in /data, not in the container.
    _docker("rm", container.name)
    fresh, _ = run_container(volume)
    assert _KEY_LINE.findall(fresh.logs) == [], "the database in the volume was not reused"
    assert _get_evaluation(fresh, api_key, evaluation_id)["status"] == "succeeded"
    with fresh.client(api_key) as http:
        pdf_again = http.get(f"/api/v1/evaluations/{evaluation_id}/artifacts/report.pdf")
    assert pdf_again.content == pdf.content
