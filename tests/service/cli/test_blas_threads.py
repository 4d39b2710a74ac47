"""The ``loceval`` command runs OpenBLAS on one thread unless the user says otherwise.

Why (``service/__init__.py``): figures that do not depend on the machine's core count, and
no spinning BLAS threads competing with loceval's own. Checked in a fresh interpreter,
since numpy reads ``OPENBLAS_NUM_THREADS`` once, when it is first imported.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

_PROBE = """
import os
import service
import numpy as np
x = np.random.default_rng(1).normal(size=300_000)
x @ x  # a BLAS call big enough for OpenBLAS to use its threads
print(os.environ.get("OPENBLAS_NUM_THREADS"), len(os.listdir("/proc/self/task")))
"""


def _probe(**env: str) -> tuple[str, int]:
    base = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    root = str(Path(__file__).resolve().parents[3])
    out = subprocess.run(
        [sys.executable, "-c", _PROBE],
        env={**base, **env, "PYTHONPATH": root},
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    return out[0], int(out[1])


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
def test_importing_the_service_leaves_numpy_one_thread():
    """Without the variable, the process has no thread but the main one after a BLAS call."""
    setting, threads = _probe()
    assert setting == "1"
    assert threads == 1


def test_the_users_setting_wins():
    """An explicit ``OPENBLAS_NUM_THREADS`` is kept as the user set it."""
    setting, _ = _probe(OPENBLAS_NUM_THREADS="2")
    assert setting == "2"
