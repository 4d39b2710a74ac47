"""A job's heavy work in a child process, with a wall-time and a memory limit.

A worker runs jobs in threads, and a thread can be neither stopped nor limited: an
evaluation that grows without end (a tiny RPE step over a long recording) would hold its
worker and the server's memory for ever. :func:`run_limited` therefore runs the work in a
child process: the child's address space is capped (``RLIMIT_AS``) at ``job_memory_mb``, the
parent waits at most ``job_timeout_s`` and then kills it. Whatever happens in the child
becomes one outcome in the parent:

* it returns: :func:`run_limited` returns (the work's output is its files);
* a :class:`~loceval.errors.LocevalError`: the same error is raised (class, message,
  option and suggestion), so the job fails with the same problem document as before;
* it runs out of memory (a ``MemoryError``, or killed by the kernel): :class:`JobMemoryError`;
* it runs too long: :class:`JobTimeoutError`, after the child was killed;
* anything else (a bug, a crash): :class:`JobProcessError`, with the child's traceback.

Children are forked from a *forkserver* that has the evaluation modules loaded: a job's
process starts in milliseconds instead of importing NumPy, SciPy and the exporters anew,
and no child is forked from the threaded server itself. The child reports its progress
through a pipe; the parent stores it (and its heartbeat thread keeps beating) while it waits.

The child configures no logging of its own: its one handler sends each record (and each
Python warning, captured) through the same pipe, and the parent hands it to its loggers in
the waiting thread, so the line is written by the service's one handler with the job's
context (``job_id``, ``kind``, ``project``), exactly as if the job had run in the parent.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import resource
import signal
import threading
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from multiprocessing.connection import Connection, wait
from multiprocessing.context import ForkServerContext
from multiprocessing.reduction import ForkingPickler
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Final

from loceval.errors import LocevalError
from service.errors import JobMemoryError, JobTimeoutError

if TYPE_CHECKING:
    from pathlib import Path

    from service.settings import Settings

__all__ = [
    "JobMemoryError",
    "JobProcessError",
    "JobTimeoutError",
    "Limits",
    "run_limited",
    "warm_up",
]

logger = logging.getLogger(__name__)

_MIB: Final = 1 << 20
_PROGRESS_INTERVAL_S: Final = 0.1
_EXIT_GRACE_S: Final = 5.0
_PRELOAD: Final = ("service.jobs.limits", "service.jobs.preload")
"""What the forkserver imports once (:mod:`service.jobs.preload` names the heavy modules)."""
_CRASH_SIGNALS: Final = frozenset({signal.SIGSEGV, signal.SIGABRT, signal.SIGBUS})
"""How a C library that does not check its allocations dies when the address space is full."""
_ADVICE: Final = (
    "evaluate shorter recordings or fewer estimates, or use coarser options (a larger "
    "options.rpe_delta, fewer options.formats); the operator can raise {setting}."
)

Progress = Callable[[str, float], None]
Artifacts = Callable[[str, str], None]
"""Called in the parent with an artifact's name and the path of its finished file."""


def _mapping_proxy(items: dict[Any, Any]) -> MappingProxyType[Any, Any]:
    """Return a read-only view of ``items`` (the class itself cannot be pickled by name)."""
    return MappingProxyType(items)


def _reduce_mapping_proxy(
    proxy: MappingProxyType[Any, Any],
) -> tuple[Callable[[dict[Any, Any]], MappingProxyType[Any, Any]], tuple[dict[Any, Any]]]:
    """Pickle a read-only mapping (a source's options) as a read-only copy of it."""
    return _mapping_proxy, (dict(proxy),)


# Only for what goes to a job's process (multiprocessing's own pickler), not pickling at large.
ForkingPickler.register(MappingProxyType, _reduce_mapping_proxy)


class JobProcessError(RuntimeError):
    """The job's process failed with a bug or died; the message holds what it left."""


@dataclass(frozen=True, slots=True)
class Limits:
    """How long and with how much memory a job may run.

    Attributes:
        timeout_s: wall time after which the job is stopped.
        memory_mb: the job process's address space in MiB; 0: no limit.
        what: what the job is, in messages (``"evaluation"``).
    """

    timeout_s: float
    memory_mb: int
    what: str = "evaluation"

    @classmethod
    def from_settings(cls, settings: Settings, *, what: str = "evaluation") -> Limits:
        """Return the limits that ``job_timeout_s`` and ``job_memory_mb`` set."""
        return cls(settings.job_timeout_s, settings.job_memory_mb, what)

    def timeout_error(self) -> JobTimeoutError:
        """Return the error of a job stopped at the time limit."""
        msg = (
            f"The {self.what} was stopped after {self.timeout_s:g} s "
            "(LOCEVAL_JOB_TIMEOUT_S, the longest a job may run); "
            + _ADVICE.format(setting="LOCEVAL_JOB_TIMEOUT_S")
        )
        return JobTimeoutError(msg)

    def memory_error(self, *, killed: bool = False) -> JobMemoryError:
        """Return the error of a job that ran out of memory (``killed``: by the system)."""
        if killed:
            msg = (
                f"The {self.what} was killed by the system (SIGKILL), most likely because the "
                "server ran out of memory; " + _ADVICE.format(setting="the server's memory")
            )
        elif self.memory_mb:
            msg = (
                f"The {self.what} needed more than {self.memory_mb} MiB of memory "
                "(LOCEVAL_JOB_MEMORY_MB) and was stopped; "
                + _ADVICE.format(setting="LOCEVAL_JOB_MEMORY_MB")
            )
        else:
            msg = (
                f"The {self.what} ran out of memory (the server has no more) and was stopped; "
                + _ADVICE.format(setting="the server's memory")
            )
        return JobMemoryError(msg)


@lru_cache(maxsize=1)
def _context() -> ForkServerContext:
    """Return the forkserver context, its server preloading the evaluation modules."""
    context = multiprocessing.get_context("forkserver")
    assert isinstance(context, ForkServerContext)  # noqa: S101  (Linux and macOS have it)
    context.set_forkserver_preload(list(_PRELOAD))
    return context


def warm_up() -> None:
    """Start the forkserver now (it imports the evaluation modules), not at the first job."""
    from multiprocessing import forkserver  # noqa: PLC0415

    _context()
    forkserver.ensure_running()


def run_limited(
    limits: Limits,
    target: Callable[..., object],
    *args: object,
    progress: Progress | None = None,
    artifacts: Artifacts | None = None,
) -> None:
    """Run ``target(*args, progress=...)`` in a child process within ``limits``.

    The target must be importable by name (a module-level function) and its arguments
    picklable; its return value is dropped (a job's output is its files). Progress the
    target reports is passed on to ``progress`` in this process. With ``artifacts``, a
    target that takes ``on_artifact=`` is given a callback whose calls (an artifact's name
    and file, as it is written) reach ``artifacts`` in this process, in order.

    Args:
        limits: the wall time and memory it may use.
        target: the work, called with the arguments and ``progress=`` a callback.
        *args: the arguments.
        progress: called here with (stage, fraction) as the child reports them.
        artifacts: called here with (name, path) of each artifact the child reports.

    Raises:
        LocevalError: the target raised it (the same class, message, option and suggestion).
        JobTimeoutError: the child ran longer than ``limits.timeout_s`` and was killed.
        JobMemoryError: the child ran out of memory.
        JobProcessError: the child failed with another exception, or died.
    """
    context = _context()
    results, child_results = context.Pipe(duplex=False)
    child_lifeline, lifeline = context.Pipe(duplex=False)
    memory_bytes = limits.memory_mb * _MIB
    process = context.Process(
        target=_child,
        args=(child_results, child_lifeline, memory_bytes, target, args),
        kwargs={"with_artifacts": artifacts is not None},
        name=f"loceval-{limits.what}",
        daemon=True,
    )
    process.start()
    child_results.close()
    child_lifeline.close()
    outcome: tuple[Any, ...] | None = ("timeout",)
    try:
        outcome = _wait(results, limits.timeout_s, progress, artifacts)
    finally:
        if outcome is not None and outcome[0] != "timeout":
            process.join(_EXIT_GRACE_S)  # it has sent its outcome and is exiting
        if process.is_alive():
            process.kill()
        process.join()
        results.close()
        lifeline.close()
        exitcode = process.exitcode
        process.close()
    _raise(outcome, exitcode, limits)


def _wait(
    results: Connection,
    timeout_s: float,
    progress: Progress | None,
    artifacts: Artifacts | None = None,
) -> tuple[Any, ...] | None:
    """Pass on the child's progress and artifacts until its outcome; None: it died first."""
    deadline = time.monotonic() + timeout_s
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return ("timeout",)
        if not wait([results], timeout=min(remaining, 1.0)):
            continue
        try:
            message: tuple[Any, ...] = results.recv()
        except EOFError:  # the child exited without a word: killed or crashed
            return None
        if message[0] == "log":
            _log_from_child(message[1])
            continue
        if message[0] == "artifact":
            if artifacts is not None:
                artifacts(message[1], message[2])
            continue
        if message[0] != "progress":
            return message
        if progress is not None:
            progress(message[1], message[2])


def _raise(outcome: tuple[Any, ...] | None, exitcode: int | None, limits: Limits) -> None:
    """Turn the child's outcome into this function's return or exception."""
    if outcome is None:
        if exitcode is not None and exitcode < 0:
            sig = signal.Signals(-exitcode)
            # Not our kill (that is a timeout): the kernel's out-of-memory killer, or a C
            # library whose allocation failed at the address-space limit.
            if sig is signal.SIGKILL:
                raise limits.memory_error(killed=True)
            if limits.memory_mb and sig in _CRASH_SIGNALS:
                raise limits.memory_error()
            msg = f"The {limits.what}'s process was killed by {sig.name}."
            raise JobProcessError(msg)
        msg = f"The {limits.what}'s process exited with code {exitcode} and no result."
        raise JobProcessError(msg)
    kind = outcome[0]
    if kind == "done":
        return
    if kind == "timeout":
        logger.warning("Stopped a %s after %g s", limits.what, limits.timeout_s)
        raise limits.timeout_error()
    if kind == "memory":
        raise limits.memory_error()
    if kind == "error":
        error = outcome[1]
        assert isinstance(error, LocevalError)  # noqa: S101  (only the child sends it)
        raise error
    msg = f"The {limits.what}'s process failed:\n{outcome[1]}"
    raise JobProcessError(msg)


# --- in the child ----------------------------------------------------------------------


def _child(
    results: Connection,
    lifeline: Connection,
    memory_bytes: int,
    target: Callable[..., object],
    args: tuple[object, ...],
    *,
    with_artifacts: bool = False,
) -> None:
    """Run the target in the child process and send its outcome (or its progress)."""
    # Ctrl-C in a terminal reaches the whole process group: the parent decides what stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if memory_bytes:
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        if hard != resource.RLIM_INFINITY:
            memory_bytes = min(memory_bytes, hard)
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, hard))
    threading.Thread(target=_orphaned, args=(lifeline,), daemon=True).start()
    sender = _Sender(results)
    _log_to_parent(sender)
    report = _Reporter(sender)
    outcome: tuple[object, ...]
    try:
        if with_artifacts and _takes(target, "on_artifact"):
            target(*args, progress=report, on_artifact=report.artifact)
        else:
            target(*args, progress=report)
        outcome = ("done",)
    except MemoryError:
        outcome = ("memory",)
    except LocevalError as err:
        outcome = ("error", _portable(err))
    except BaseException:  # noqa: BLE001  (a bug: the parent logs it under an error id)
        outcome = ("bug", traceback.format_exc())
    # The failed work's frames (and their arrays) are gone here, so sending needs no memory.
    sender(outcome)
    results.close()


def _takes(target: Callable[..., object], name: str) -> bool:
    """Return whether ``target`` takes the keyword argument ``name``."""
    import inspect  # noqa: PLC0415

    parameters = inspect.signature(target).parameters
    return name in parameters or any(p.kind is p.VAR_KEYWORD for p in parameters.values())


class _Sender:
    """The child's end of the results pipe, shared by the work, its logging and its outcome."""

    def __init__(self, results: Connection) -> None:
        """Send on ``results``, one message at a time (threads of the work may log too)."""
        self.results = results
        self.lock = threading.Lock()

    def __call__(self, message: tuple[object, ...]) -> None:
        """Send one message."""
        with self.lock:
            self.results.send(message)


class _ToParent(logging.Handler):
    """The child's only log handler: each record goes to the parent as plain fields."""

    def __init__(self, sender: _Sender) -> None:
        """Send through ``sender``."""
        super().__init__(logging.INFO)
        self.sender = sender

    def emit(self, record: logging.LogRecord) -> None:
        """Send the record's fields (its message formatted here: its arguments may not pickle)."""
        try:
            fields = {
                key: value if isinstance(value, str | int | float | bool | None) else str(value)
                for key, value in record.__dict__.items()
                if key not in _NOT_SENT
            }
            fields["msg"], fields["args"] = record.getMessage(), None
            if record.exc_info and not record.exc_text:
                fields["exc_text"] = logging.Formatter().formatException(record.exc_info)
            self.sender(("log", fields))
        except Exception:  # noqa: BLE001  (logging must never fail the work)
            self.handleError(record)


_NOT_SENT: Final = frozenset({"msg", "args", "exc_info", "stack_info", "context"})


def _log_to_parent(sender: _Sender) -> None:
    """Route every log record and Python warning of this (child) process to the parent."""
    root = logging.getLogger()
    for handler in list(root.handlers):
        root.removeHandler(handler)
    root.addHandler(_ToParent(sender))
    root.setLevel(logging.INFO)
    logging.captureWarnings(capture=True)


def _log_from_child(fields: dict[str, Any]) -> None:
    """Write a record the child sent, through this process's loggers and context."""
    record = logging.makeLogRecord(fields)
    child = logging.getLogger(record.name)
    if child.isEnabledFor(record.levelno):
        child.handle(record)


class _Reporter:
    """The child's progress callback: sends (stage, fraction) to the parent, 10 times a second."""

    def __init__(self, send: Callable[[tuple[object, ...]], None]) -> None:
        """Send through ``send``."""
        self.send = send
        self.stage = ""
        self.at = 0.0

    def __call__(self, stage: str, fraction: float) -> None:
        """Send the stage and the fraction, unless the same stage was sent just now."""
        now = time.monotonic()
        if stage == self.stage and now - self.at < _PROGRESS_INTERVAL_S:
            return
        self.stage, self.at = stage, now
        self.send(("progress", stage, float(fraction)))

    def artifact(self, name: str, path: Path) -> None:
        """Send an artifact's name and file the moment it is written (never dropped)."""
        self.send(("artifact", name, str(path)))


def _portable(err: LocevalError) -> LocevalError:
    """Return the error, or a copy without what cannot be pickled (its class kept)."""
    import pickle  # noqa: PLC0415

    try:
        pickle.loads(pickle.dumps(err))  # noqa: S301  (our own bytes)
    except Exception:  # noqa: BLE001  (any attribute that does not survive pickling)
        return type(err)(str(err), option=err.option, suggest=err.suggest)
    return err


def _orphaned(lifeline: Connection) -> None:
    """End the child when its parent is gone (its end of the lifeline closes)."""
    with contextlib.suppress(EOFError, OSError):
        lifeline.recv()  # the parent never sends: this returns only when it is gone
    os._exit(1)
