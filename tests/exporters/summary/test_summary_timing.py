"""The summary's repeatability table with the re-drive timing of each later run."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from exporters.summary import SummaryRun, repeatability
from exporters.summary.view import _repeatability_view

MONDAY = dt.datetime(2026, 3, 2, 9, 0, tzinfo=dt.UTC)


def _walk(t: np.ndarray, *, wait_at_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A 60 s loop at constant pace; optionally standing 3 s at ``wait_at_s``."""
    s = t if wait_at_s is None else np.where(t < wait_at_s, t, np.maximum(wait_at_s, t - 3.0))
    a = np.minimum(s, 59.9) / 60.0 * 2 * np.pi
    xyz = np.column_stack([4 * np.cos(a) + 1.5 * np.cos(3 * a), 3 * np.sin(a), 0 * a + 1.3])
    return t + 1000.0, xyz  # any time origin: each run counts from its own start


def _run(k: int, t_s: np.ndarray, xyz: np.ndarray) -> SummaryRun:
    return SummaryRun(
        dataset=f"run-{k}",
        recorded_at=MONDAY + dt.timedelta(days=k),
        status="succeeded",
        reference_xyz=xyz,
        reference_t_s=t_s,
        duration_s=float(t_s[-1] - t_s[0]),
    )


def test_a_run_that_stood_3_s_shows_one_late_stretch() -> None:
    """Standing 3 s at 20 s makes the second run 3 s late from there on; the view says so."""
    first = _run(0, *_walk(np.arange(0.0, 60.0, 0.1)))
    later = _run(1, *_walk(np.arange(0.0, 63.0, 0.1), wait_at_s=20.0))
    rows = repeatability([first, later])
    timing = rows[1].timing
    assert rows[0].timing is None
    assert timing is not None
    (stretch,) = timing.stretches
    assert stretch.start_s == pytest.approx(20.0, abs=0.2)
    assert stretch.max_abs_s == pytest.approx(3.0, abs=0.15)  # within a sample (0.1 s)
    assert timing.median_abs_s == pytest.approx(3.0, abs=0.05)  # two thirds of the loop late
    view = _repeatability_view(rows)[1]
    assert view.timing_max_s == f"{timing.max_abs_s:.2f}"
    assert view.timing_stretches.startswith("20 s +")


def test_runs_without_times_leave_timing_out() -> None:
    """Without reference times the timing cells show a dash."""
    t, xyz = _walk(np.arange(0.0, 60.0, 0.1))
    runs = [
        _run(0, t, xyz),
        SummaryRun("old", MONDAY + dt.timedelta(days=2), "succeeded", reference_xyz=xyz),
    ]
    rows = repeatability(runs)
    assert rows[1].timing is None
    assert _repeatability_view(rows)[1].timing_median_s == "\u2014"  # the table's dash
