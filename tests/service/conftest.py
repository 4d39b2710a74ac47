"""The real service in subprocesses: ``loceval serve`` and ``loceval worker`` on free ports.

``live_server`` (one per test) and ``live_server_module`` (one per test module) start
``python -m service.cli serve`` with an empty data folder, read the first API key from its
output and wait for ``/readyz``. :func:`start_server` and :func:`start_worker` are the
building blocks for tests that restart, kill or scale out the service.

``api`` is the in-process app of the HTTP API tests (:func:`tests.service._api_fixtures.open_api`).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx2
import pytest

from service.logs import reset_logging
from tests.service._api_fixtures import Api, open_api

REPO = Path(__file__).resolve().parents[2]
READY_TIMEOUT_S = 90.0  # a loaded CI machine imports the app in tens of seconds
STOP_TIMEOUT_S = 15.0
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


def free_port() -> int:
    """Return a loopback port that was free a moment ago."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def service_env(data_dir: Path, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Return the environment of a service process: this one's, minus stray LOCEVAL_ settings."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("LOCEVAL_") or k == "LOCEVAL_PUBLIC_DATA"
    }
    env.update(
        LOCEVAL_DATA_DIR=str(data_dir),
        LOCEVAL_WORKERS="2",
        PYTHONUNBUFFERED="1",
    )
    env.update(extra or {})
    return env


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
class ServiceProcess:
    """A ``serve`` or ``worker`` subprocess whose output (stdout and stderr) is collected."""

    process: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)
    _reader: threading.Thread | None = None
    _changed: threading.Condition = field(default_factory=threading.Condition)

    @classmethod
    def start(cls, argv: list[str], env: Mapping[str, str]) -> ServiceProcess:
        """Start ``argv`` with its output drained by a thread."""
        process = subprocess.Popen(
            argv,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            text=True,
            env=dict(env),
            cwd=REPO,
        )
        started = cls(process)
        started._reader = threading.Thread(target=started._drain, daemon=True)
        started._reader.start()
        return started

    def _drain(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            with self._changed:
                self.lines.append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def output(self) -> str:
        """Everything the process printed so far."""
        with self._changed:
            return "\n".join(self.lines)

    def wait_for_line(self, pattern: re.Pattern[str], timeout: float) -> re.Match[str] | None:
        """Return the first match of ``pattern`` in the output, waiting up to ``timeout``."""
        deadline = time.monotonic() + timeout
        with self._changed:
            while True:
                for line in self.lines:
                    match = pattern.search(line)
                    if match:
                        return match
                remaining = deadline - time.monotonic()
                if remaining <= 0 or (self.process.poll() is not None and not self._alive()):
                    return None
                self._changed.wait(min(remaining, 0.2))

    def _alive(self) -> bool:
        return self._reader is not None and self._reader.is_alive()

    def stop(self, timeout: float = STOP_TIMEOUT_S) -> int:
        """SIGTERM, then SIGKILL after ``timeout``; close the pipe; return the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5)
        return self._reap()

    def kill(self) -> int:
        """SIGKILL (a crash: no shutdown code runs); close the pipe; return the exit code."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(5)
        return self._reap()

    def _reap(self) -> int:
        if self._reader is not None:
            self._reader.join(5)
        if self.process.stdout is not None:
            self.process.stdout.close()
        return self.process.returncode


@dataclass
class LiveServer:
    """A running ``loceval serve``: its address, first API key, data folder and process."""

    url: str
    api_key: str
    data_dir: Path
    env: dict[str, str]
    service: ServiceProcess

    @property
    def process(self) -> subprocess.Popen[str]:
        """The server's process."""
        return self.service.process

    @property
    def output(self) -> str:
        """What the server printed so far (stdout and stderr)."""
        return self.service.output

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


def wait_ready(url: str, service: ServiceProcess, timeout: float = READY_TIMEOUT_S) -> None:
    """Wait for ``GET /readyz`` to answer 200; fail with the server's output otherwise."""
    deadline = time.monotonic() + timeout
    last = "no answer"
    with httpx2.Client(base_url=url, timeout=5) as client:
        while time.monotonic() < deadline:
            if service.process.poll() is not None:
                service.stop()
                pytest.fail(
                    f"the server exited with {service.process.returncode} before it was "
                    f"ready; its output:\n{service.output}"
                )
            try:
                answer = client.get("/readyz")
            except httpx2.TransportError as err:
                last = repr(err)
            else:
                if answer.status_code == 200:
                    return
                last = f"{answer.status_code} {answer.text}"
            time.sleep(0.1)
    service.stop()
    pytest.fail(
        f"/readyz did not answer 200 within {timeout:g} s ({last}); output:\n{service.output}"
    )


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
    service = ServiceProcess.start(
        [sys.executable, "-m", "service.cli", "serve", "--port", str(port), *args], full_env
    )
    if api_key is None:
        match = service.wait_for_line(_KEY_LINE, READY_TIMEOUT_S)
        if match is None:
            service.stop()
            pytest.fail(f"the server printed no API key; its output:\n{service.output}")
        api_key = match.group(1)
    url = f"http://127.0.0.1:{port}"
    wait_ready(url, service)
    return LiveServer(url=url, api_key=api_key, data_dir=data_dir, env=full_env, service=service)


def start_worker(data_dir: Path, env: Mapping[str, str] | None = None) -> ServiceProcess:
    """Start ``loceval worker`` and wait for its start line; fail with its output otherwise."""
    service = ServiceProcess.start(
        [sys.executable, "-m", "service.cli", "worker"], service_env(data_dir, env)
    )
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
