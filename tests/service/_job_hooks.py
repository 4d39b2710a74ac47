"""Stand-ins for ``service.jobs.runner.run_job`` that a job's process runs (tests patch them in).

A job's process imports its work by name, so a test cannot hand it a closure: these are
module-level functions, in a module that imports little (a job's process imports it).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np

from exporters import ArtifactCallback
from loceval.errors import AssociationError, InputError
from loceval.evaluation import ProgressCallback
from service.jobs.runner import Job, run_job

__all__ = [
    "CHUNK_MIB",
    "HOLD_FILE",
    "MAX_CHUNKS",
    "SLEEPER",
    "crash",
    "exit_quietly",
    "fail_after_result",
    "grow",
    "header_stamps_zero",
    "hold_after_result",
    "killed",
    "no_overlap",
    "report_then_fail",
    "sleep_forever",
    "sleep_if_sleeper",
]

SLEEPER = "sleeper"
"""The reference name that makes :func:`sleep_if_sleeper` sleep (other jobs evaluate)."""
CHUNK_MIB = 64
MAX_CHUNKS = 64
""":func:`grow` stops at 4 GiB even without a limit, so a broken limit fails, not the host."""


def no_overlap(_job: Job, out_dir: Path, **_kwargs: object) -> None:
    """Fail as the core does, naming a file by its server path."""
    root, evaluation_id = out_dir.parents[2], out_dir.parent.name  # .../evaluations/ID/.staging
    msg = f"No overlap in {root}/datasets/{evaluation_id}/est.txt; time offset?"
    raise AssociationError(msg, option="time_offset_s")


def header_stamps_zero(*_args: object, **_kwargs: object) -> None:
    """Fail with an error that names an option and the value that would fix it."""
    msg = "Every header stamp is zero."
    raise InputError(msg, option="stamp", suggest="receive")


def crash(*_args: object, **_kwargs: object) -> None:
    """Fail with a bug."""
    msg = "boom"
    raise RuntimeError(msg)


def sleep_if_sleeper(job: Job, out_dir: Path, progress: ProgressCallback) -> None:
    """Hang (as an endless pair search would) if the reference is named so; else evaluate."""
    if job.reference.name == SLEEPER:
        progress("searching pairs", 0.3)
        time.sleep(3600)
    run_job(job, out_dir, progress)


HOLD_FILE = "go-on"
"""Created in the evaluation's folder, it lets :func:`hold_after_result` go on."""
HOLD_LIMIT_S = 60.0


def hold_after_result(
    job: Job,
    out_dir: Path,
    progress: ProgressCallback,
    *,
    on_artifact: ArtifactCallback,
) -> None:
    """Evaluate, stopping after result.json until the test creates :data:`HOLD_FILE`."""
    go_on = out_dir.parent / HOLD_FILE  # .../evaluations/ID/.staging-...

    def hold(name: str, path: Path) -> None:
        on_artifact(name, path)
        deadline = time.monotonic() + HOLD_LIMIT_S  # a broken test fails, it does not hang
        while name == "result.json" and not go_on.exists() and time.monotonic() < deadline:
            time.sleep(0.02)

    run_job(job, out_dir, progress, on_artifact=hold)


def fail_after_result(
    job: Job,
    out_dir: Path,
    progress: ProgressCallback,
    *,
    on_artifact: ArtifactCallback,
) -> None:
    """Evaluate, then fail as a report can once result.json was published."""

    def fail(name: str, path: Path) -> None:
        on_artifact(name, path)
        msg = "The floor plan is unreadable; upload it again."
        raise InputError(msg)

    run_job(job, out_dir, progress, on_artifact=fail)


def sleep_forever(*, progress: ProgressCallback) -> None:
    """Report the process id, then hang."""
    progress(f"pid {os.getpid()}", 0.0)
    time.sleep(3600)


def grow(*_args: object, **_kwargs: object) -> None:
    """Take memory 64 MiB at a time (touched, so it is really used), as a runaway search does."""
    chunks = [np.ones(CHUNK_MIB << 17) for _ in range(MAX_CHUNKS)]  # 2**17 float64 per MiB
    msg = f"took {len(chunks) * CHUNK_MIB} MiB and was not stopped"
    raise AssertionError(msg)


def killed(*_args: object, **_kwargs: object) -> None:
    """Die as the kernel's out-of-memory killer ends a process."""
    os.kill(os.getpid(), signal.SIGKILL)


def exit_quietly(*_args: object, **_kwargs: object) -> None:
    """Leave without a result (a library that calls exit)."""
    os._exit(3)


def report_then_fail(*_args: object, progress: ProgressCallback, **_kwargs: object) -> None:
    """Report a stage and a fraction, then fail (the failed job keeps its stage)."""
    progress("reading the halfway file", 0.5)
    msg = "The halfway file is unreadable; upload it again."
    raise InputError(msg)
