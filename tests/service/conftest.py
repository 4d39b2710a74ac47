"""The real service in subprocesses: ``loceval serve`` and ``loceval worker`` on free ports.

``live_server`` (one per test) and ``live_server_module`` (one per test module) start
``python -m service.cli serve`` with an empty data folder, read the first API key from its
output and wait for ``/readyz``. :func:`start_server` and :func:`start_worker` are the
building blocks for tests that restart, kill or scale out the service; the processes, ports
and readiness come from :mod:`tests.harness`, which the benchmarks use too.

``api`` is the in-process app of the HTTP API tests (:func:`tests.service._api_fixtures.open_api`).
"""

from __future__ import annotations

import contextlib
import json
import re
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx2
import pytest

from service.logs import reset_logging
from tests.conftest import skip_or_fail
from tests.harness import HarnessUnavailableError
from tests.harness.databases import empty_redis_database, fresh_database
from tests.harness.ports import free_port
from tests.harness.processes import (
    REPO,
    RunningService,
    ServiceNotReadyError,
    ServiceProcess,
    loceval_argv,
    service_env,
)
from tests.harness.processes import wait_ready as harness_wait_ready
from tests.harness.proxy import CuttingProxy
from tests.service._api_fixtures import Api, open_api

__all__ = [
    "REPO",
    "LiveServer",
    "ServiceProcess",
    "cli",
    "cli_json",
    "free_port",
    "running_server",
    "service_env",
    "start_cut_upload",
    "start_server",
    "start_worker",
    "submit",
    "succeeded",
    "upload",
    "wait_for_evaluation",
    "wait_ready",
    "wait_until",
]
READY_TIMEOUT_S = 90.0  # a loaded CI machine imports the app in tens of seconds
EVALUATION_TIMEOUT_S = 180.0
_KEY_LINE = re.compile(r"API key for project 'default' \(shown once\): (\S+)")


@pytest.fixture(autouse=True)
def _reset_logging() -> Iterator[None]:
    """Undo ``configure_logging`` (an app's start-up calls it) after every test."""
    yield
    reset_logging()


@pytest.fixture
def api(tmp_path: Path) -> Iterator[Api]:
    """A fresh app in-process (immediate jobs) with keys of projects ``site-a`` and ``site-b``.

    For the HTTP API tests; a module that needs other settings defines its own ``api``.
    """
    with open_api(tmp_path) as api:
        yield api


def cli(*args: str, env: Mapping[str, str] | None = None, timeout: float = 120) -> str:
    """Run ``python -m service.cli ARGS`` and return its stdout; fail with its output on error."""
    proc = subprocess.run(
        [sys.executable, "-m", "service.cli", *args],
        capture_output=True,
        text=True,
        env=dict(env) if env is not None else None,
        cwd=REPO,
        timeout=timeout,
        check=False,
    )
    if proc.returncode != 0:
        pytest.fail(
            f"loceval {' '.join(args)} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
        )
    return proc.stdout


def cli_json(*args: str) -> dict[str, Any]:
    """Return the ``--json`` document of ``loceval evaluate ARGS``."""
    document: dict[str, Any] = json.loads(cli("evaluate", *args, "--json"))
    return document


@dataclass
class LiveServer(RunningService):
    """A running ``loceval serve``: its address, first API key, data folder and process."""

    api_key: str = ""
    data_dir: Path = Path()

    def client(self, api_key: str | None = None) -> httpx2.Client:
        """Return an HTTP client with the project's key (or ``api_key``); close it after use."""
        key = self.api_key if api_key is None else api_key
        return httpx2.Client(
            base_url=self.url, headers={"Authorization": f"Bearer {key}"}, timeout=120
        )

    def anonymous_client(self) -> httpx2.Client:
        """Return an HTTP client without an API key."""
        return httpx2.Client(base_url=self.url, timeout=120)

    def create_key(self, project: str) -> str:
        """Return a new key of ``project`` from ``loceval keys create`` (same database)."""
        return cli("keys", "create", "--project", project, env=self.env).strip()

    def stop(self) -> int:
        """Stop the server (SIGTERM, then SIGKILL after 15 s); return its exit code."""
        return self.service.stop()

    def kill(self) -> int:
        """Kill the server with SIGKILL; return its exit code."""
        return self.service.kill()


def wait_ready(url: str, service: ServiceProcess, timeout: float | None = None) -> None:
    """Wait for ``GET /readyz`` to answer 200; stop the server and fail with its output else."""
    try:
        harness_wait_ready(url, service, READY_TIMEOUT_S if timeout is None else timeout)
    except ServiceNotReadyError as err:
        service.stop()
        pytest.fail(str(err))


def start_server(
    data_dir: Path,
    *,
    api_key: str | None = None,
    env: Mapping[str, str] | None = None,
    args: tuple[str, ...] = (),
) -> LiveServer:
    """Start ``loceval serve`` on a free port and wait until it is ready.

    Args:
        data_dir: LOCEVAL_DATA_DIR.
        api_key: the key to use when the database exists already (a restart); None reads
            the key that the first start prints.
        env: more LOCEVAL_* variables.
        args: more ``serve`` options (``--no-consumer``).
    """
    port = free_port()
    # links (Location, artifact URLs) are built from the configured public address
    public = {"LOCEVAL_PUBLIC_URL": f"http://127.0.0.1:{port}"}
    full_env = service_env(data_dir, {**public, **(env or {})})
    service = ServiceProcess.start(loceval_argv("serve", "--port", str(port), *args), full_env)
    if api_key is None:
        match = service.wait_for_line(_KEY_LINE, READY_TIMEOUT_S)
        if match is None:
            service.stop()
            pytest.fail(f"the server printed no API key; its output:\n{service.output}")
        api_key = match.group(1)
    url = f"http://127.0.0.1:{port}"
    wait_ready(url, service)
    return LiveServer(url=url, api_key=api_key, data_dir=data_dir, env=full_env, service=service)


def start_cut_upload(
    server: LiveServer,
    body: bytes,
    *,
    declared: int,
    filename: str,
    content_type: str = "application/octet-stream",
    timeout_s: float = 30,
) -> socket.socket:
    """Start ``POST /datasets`` of a file that never ends: send its first bytes, keep it open.

    The form declares ``declared`` bytes (its Content-Length) and sends the part's headers
    and ``body``; the caller closes the connection (the client went away) or kills the
    server, then looks at what the service kept.
    """
    boundary = "loceval-cut-boundary"
    head = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="{filename}"\r\n'
        f"Content-Type: {content_type}\r\n\r\n"
    ).encode()
    port = int(server.url.rsplit(":", 1)[1])
    request = (
        "POST /api/v1/datasets HTTP/1.1\r\n"
        f"Host: 127.0.0.1:{port}\r\n"
        f"Authorization: Bearer {server.api_key}\r\n"
        f"Content-Type: multipart/form-data; boundary={boundary}\r\n"
        f"Content-Length: {declared}\r\n\r\n"
    ).encode()
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout_s)
    sock.sendall(request + head + body)
    return sock


def wait_until(condition: Callable[[], object], timeout: float) -> bool:
    """Whether ``condition()`` turns true within ``timeout`` seconds (asked every 50 ms)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return bool(condition())


def start_worker(data_dir: Path, env: Mapping[str, str] | None = None) -> ServiceProcess:
    """Start ``loceval worker`` and wait for its start line; fail with its output otherwise."""
    service = ServiceProcess.start(loceval_argv("worker"), service_env(data_dir, env))
    if service.wait_for_line(re.compile(r"^loceval worker: "), READY_TIMEOUT_S) is None:
        service.stop()
        pytest.fail(f"the worker did not start; its output:\n{service.output}")
    return service


@contextlib.contextmanager
def running_server(data_dir: Path, **kwargs: Any) -> Iterator[LiveServer]:
    """Run a server for the ``with`` block, stopped at its end whatever happens."""
    server = start_server(data_dir, **kwargs)
    try:
        yield server
    finally:
        server.stop()


@contextlib.contextmanager
def server_behind_proxy(
    data_dir: Path,
    cuts: Sequence[int] = (),
    *,
    stay_down: bool = False,
    bytes_per_s: float | None = None,
) -> Iterator[tuple[LiveServer, CuttingProxy]]:
    """A server whose public address is a cutting proxy (its upload addresses point at it)."""
    with (
        CuttingProxy(0, cuts, stay_down=stay_down, bytes_per_s=bytes_per_s) as proxy,
        running_server(data_dir, env={"LOCEVAL_PUBLIC_URL": proxy.url}) as server,
    ):
        proxy.target = int(server.url.rsplit(":", 1)[1])
        yield server, proxy


@pytest.fixture
def live_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A fresh ``loceval serve`` (SQLite, 2 workers) for one test."""
    with running_server(tmp_path_factory.mktemp("data")) as server:
        yield server


@pytest.fixture(scope="module")
def live_server_module(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    """A ``loceval serve`` shared by the tests of a module (they must not interfere)."""
    with running_server(tmp_path_factory.mktemp("data")) as server:
        yield server


@pytest.fixture
def postgres_url() -> Iterator[str]:
    """A fresh database on the machine's PostgreSQL for this test, dropped afterwards."""
    try:
        with fresh_database() as url:
            yield url
    except HarnessUnavailableError as err:
        skip_or_fail(str(err))


@pytest.fixture
def redis_url() -> Iterator[str]:
    """An unused database number of the machine's Redis; its loceval keys deleted after."""
    try:
        with empty_redis_database() as url:
            yield url
    except HarnessUnavailableError as err:
        skip_or_fail(str(err))


# --- API helpers -------------------------------------------------------------------------


def upload(
    client: httpx2.Client, path: Path, *, expect: int = 201, **fields: str
) -> dict[str, Any]:
    """Upload a file as a dataset and return it; fail unless the status is ``expect``."""
    with path.open("rb") as fh:
        answer = client.post("/api/v1/datasets", files={"file": (path.name, fh)}, data=dict(fields))
    assert answer.status_code == expect, answer.text
    dataset: dict[str, Any] = answer.json()
    return dataset


def submit(
    client: httpx2.Client,
    reference: dict[str, Any],
    estimates: list[dict[str, Any]],
    options: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """POST an evaluation (202) and return it."""
    body = {"reference": reference, "estimates": estimates, "options": dict(options or {})}
    answer = client.post("/api/v1/evaluations", json=body)
    assert answer.status_code == 202, answer.text
    evaluation: dict[str, Any] = answer.json()
    assert answer.headers["location"].endswith(f"/api/v1/evaluations/{evaluation['id']}")
    return evaluation


def wait_for_evaluation(
    client: httpx2.Client,
    evaluation_id: str,
    *,
    until: frozenset[str] = frozenset({"succeeded", "failed"}),
    timeout: float = EVALUATION_TIMEOUT_S,
    interval: float = 0.2,
) -> dict[str, Any]:
    """Poll an evaluation until its status is in ``until``; fail after ``timeout``."""
    deadline = time.monotonic() + timeout
    evaluation: dict[str, Any] = {}
    while time.monotonic() < deadline:
        answer = client.get(f"/api/v1/evaluations/{evaluation_id}")
        assert answer.status_code == 200, answer.text
        evaluation = answer.json()
        if evaluation["status"] in until:
            return evaluation
        time.sleep(interval)
    pytest.fail(
        f"evaluation {evaluation_id} not {sorted(until)} within {timeout:g} s; last state: "
        f"{evaluation.get('status')} {evaluation.get('progress')}"
    )


def succeeded(evaluation: dict[str, Any]) -> dict[str, Any]:
    """Return the evaluation after checking it succeeded (else fail with its error)."""
    assert evaluation["status"] == "succeeded", evaluation.get("error")
    return evaluation


ATE_FIELDS = ("rmse", "mean", "median", "max")


def assert_same_ate(actual: dict[str, Any], expected: dict[str, Any]) -> None:
    """Check two result documents have the same ATE per estimate (1e-12 relative)."""
    assert len(actual["estimates"]) == len(expected["estimates"])
    for got, want in zip(actual["estimates"], expected["estimates"], strict=True):
        assert got["matched"] == want["matched"]
        for key in ATE_FIELDS:
            assert got["ate"]["translation_m"][key] == pytest.approx(
                want["ate"]["translation_m"][key], rel=1e-12, abs=0
            ), key
