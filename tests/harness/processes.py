"""A server as a subprocess: ``loceval serve`` and ``worker`` for tests and benchmarks.

:class:`ServiceProcess` starts a command with its output kept (in memory, or in a log file
for a long benchmark), waits for a line of it, and stops it: SIGTERM, then SIGKILL (of its
whole process group when it has its own session). :func:`wait_ready` waits for
``GET /readyz`` to answer 200 and raises :class:`ServiceNotReadyError` with the server's output
otherwise. :func:`service_env` is the environment of a service process.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import httpx2

__all__ = [
    "REPO",
    "RunningService",
    "ServiceNotReadyError",
    "ServiceProcess",
    "loceval_argv",
    "service_env",
    "wait_ready",
]

REPO = Path(__file__).resolve().parents[2]
"""The project's folder (the tests run the service from it)."""
_TAIL_LINES = 60


class ServiceNotReadyError(RuntimeError):
    """A server that exited, or did not answer ``/readyz``, in time (with its output)."""


def loceval_argv(*args: str) -> list[str]:
    """Return the command line of ``loceval ARGS`` run by this interpreter."""
    return [sys.executable, "-m", "service.cli", *args]


def service_env(data_dir: Path, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Return the environment of a service process: this one's, minus stray LOCEVAL_ settings."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("LOCEVAL_") or k == "LOCEVAL_PUBLIC_DATA"
    }
    env.update(LOCEVAL_DATA_DIR=str(data_dir), LOCEVAL_WORKERS="2", PYTHONUNBUFFERED="1")
    env.update(extra or {})
    return env


@dataclass
class ServiceProcess:
    """A subprocess whose output (stdout and stderr) is kept: in memory, or in ``log``."""

    process: subprocess.Popen[str]
    log: Path | None = None
    own_session: bool = False
    lines: list[str] = field(default_factory=list)
    _reader: threading.Thread | None = None
    _changed: threading.Condition = field(default_factory=threading.Condition)

    @classmethod
    def start(
        cls,
        argv: list[str],
        env: Mapping[str, str],
        *,
        cwd: Path | None = REPO,
        log: Path | None = None,
        own_session: bool = False,
    ) -> ServiceProcess:
        """Start ``argv``.

        Args:
            argv: the command.
            env: its whole environment.
            cwd: its working folder (None: this process's; a benchmark that runs another
                source tree by ``PYTHONPATH`` must not start in this one).
            log: write the output to this file (else it is kept in memory by a thread).
            own_session: give it its own process group, so a stop ends its children too.
        """
        with contextlib.ExitStack() as stack:
            out = (
                stack.enter_context(log.open("w", encoding="utf-8"))
                if log is not None
                else subprocess.PIPE
            )
            process = subprocess.Popen(
                argv,
                stdout=out,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                text=True,
                env=dict(env),
                cwd=cwd,
                start_new_session=own_session,
            )
        started = cls(process, log, own_session)
        if log is None:
            started._reader = threading.Thread(target=started._drain, daemon=True)
            started._reader.start()
        return started

    @property
    def pid(self) -> int:
        """The process id."""
        return self.process.pid

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
        if self.log is not None:
            try:
                return self.log.read_text(encoding="utf-8", errors="replace")
            except OSError:
                return ""
        with self._changed:
            return "\n".join(self.lines)

    def tail(self, lines: int = _TAIL_LINES) -> str:
        """The last lines of the output."""
        return "\n".join(self.output.splitlines()[-lines:])

    def wait_for_line(self, pattern: re.Pattern[str], timeout: float) -> re.Match[str] | None:
        """Return the first match of ``pattern`` in the output, waiting up to ``timeout``."""
        deadline = time.monotonic() + timeout
        while True:
            with self._changed:
                for line in self.output.splitlines() if self.log else self.lines:
                    match = pattern.search(line)
                    if match:
                        return match
                remaining = deadline - time.monotonic()
                if remaining <= 0 or (self.process.poll() is not None and not self._alive()):
                    return None
                if self.log is None:
                    self._changed.wait(min(remaining, 0.2))
            if self.log is not None:
                time.sleep(min(remaining, 0.2))

    def _alive(self) -> bool:
        return self._reader is not None and self._reader.is_alive()

    def stop(self, timeout: float = 15.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout``; close the pipe; return the exit code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self._kill()
        return self._reap()

    def kill(self) -> int:
        """SIGKILL (a crash: no shutdown code runs); close the pipe; return the exit code."""
        if self.process.poll() is None:
            self._kill()
        return self._reap()

    def _kill(self) -> None:
        if self.own_session:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.process.pid, signal.SIGKILL)
        else:
            self.process.kill()
        self.process.wait(30)

    def _reap(self) -> int:
        if self._reader is not None:
            self._reader.join(5)
        if self.process.stdout is not None:
            self.process.stdout.close()
        return self.process.returncode


@dataclass
class RunningService:
    """A running ``loceval serve``: its address, its environment and its process."""

    url: str
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


def wait_ready(url: str, service: ServiceProcess, timeout: float) -> None:
    """Wait for ``GET url/readyz`` to answer 200.

    Raises:
        ServiceNotReadyError: the process exited, or did not answer 200 within ``timeout``; the
            message holds the end of its output.
    """
    deadline = time.monotonic() + timeout
    last = "no answer"
    with httpx2.Client(base_url=url, timeout=5.0) as client:
        while time.monotonic() < deadline:
            if service.process.poll() is not None:
                msg = (
                    f"the server exited with {service.process.returncode} before it was "
                    f"ready; its output:\n{service.tail()}"
                )
                raise ServiceNotReadyError(msg)
            try:
                answer = client.get("/readyz")
            except httpx2.TransportError as err:
                last = repr(err)
            else:
                if answer.status_code == 200:
                    return
                last = f"{answer.status_code} {answer.text[:200]}"
            time.sleep(0.1)
    msg = f"/readyz did not answer 200 within {timeout:g} s ({last}); output:\n{service.tail()}"
    raise ServiceNotReadyError(msg)
