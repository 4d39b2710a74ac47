"""Excursions: drift outside the tracked room, on a run whose drift is known."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.evaluation import EvaluationConfig, evaluate
from loceval.registration.alignment import AlignWindow
from loceval.trajectory import Trajectory

NS = 1_000_000_000
DT_NS = 10_000_000  # 100 Hz
DRIFT_PER_M = 0.005  # the estimate drifts 5 mm per metre walked while outside


def _run() -> tuple[Trajectory, Trajectory, float]:
    """A 100 s run: 20 s in the room, 45 s outside at 1 m/s, back in the room.

    The reference is lost while outside; the estimate goes on and drifts sideways by
    ``DRIFT_PER_M`` per metre walked, keeping the offset after coming back.
    """
    t = np.arange(0, 100 * NS, DT_NS, dtype=np.int64)
    s = t / NS
    x0, y0 = np.sin(20.0), np.cos(20.0) - 1  # where it leaves the room, continuously
    x = np.where(s < 20, np.sin(s), x0 + np.where(s < 65, s - 20, 45 - (s - 65) * 0.5))
    y = np.where(s < 20, np.cos(s) - 1, y0)
    xyz = np.column_stack([x, y, np.zeros_like(x)])
    walked = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xyz, axis=0), axis=1))])
    outside = (s >= 20) & (s < 65)
    leave = walked[np.argmax(outside)]
    drift = DRIFT_PER_M * np.clip(walked - leave, 0, None)
    drift[s >= 65] = drift[np.argmax(s >= 65) - 1]
    est_xyz = xyz + np.column_stack([np.zeros_like(x), drift, np.zeros_like(x)])
    inside = ~outside
    reference = Trajectory(t[inside], xyz[inside], None, name="mocap")
    estimate = Trajectory(t, est_xyz, None, name="slam")
    path_outside = float(walked[np.argmax(s >= 65)] - leave)
    return reference, estimate, path_outside


def test_an_excursion_reports_its_known_drift() -> None:
    """Aligned on the first stay only: 45 s, 45 m outside, 0 before, 0.225 m after."""
    reference, estimate, path_m = _run()
    config = EvaluationConfig(align_first=AlignWindow.parse("19s"), no_ci=True)
    result = evaluate(reference, [estimate], config)
    (excursion,) = result.estimates[0].excursions
    doc = result.to_dict()["estimates"][0]["excursions"][0]  # type: ignore[index]
    assert doc["start_s"] == pytest.approx(19.99, abs=0.011)
    assert doc["duration_s"] == pytest.approx(45.0, abs=0.011)
    assert doc["path_length_m"] == pytest.approx(path_m, abs=0.02)
    assert doc["error_before_m"] == pytest.approx(0.0, abs=1e-6)
    assert doc["error_after_m"] == pytest.approx(DRIFT_PER_M * path_m, abs=1e-3)
    assert doc["drift_per_m"] == pytest.approx(DRIFT_PER_M, abs=2e-5)
    assert excursion.drift_per_m == doc["drift_per_m"]


def test_short_losses_are_no_excursions() -> None:
    """A loss shorter than min_excursion_s is not listed; a longer minimum drops the 45 s one."""
    reference, estimate, _ = _run()
    result = evaluate(reference, [estimate], EvaluationConfig(min_excursion_s=50.0, no_ci=True))
    assert result.estimates[0].excursions == ()
    assert result.to_dict()["estimates"][0]["excursions"] == []  # type: ignore[index]


def test_no_excursion_when_the_estimate_stops_too() -> None:
    """Both lost at once: nothing to judge, so no excursion."""
    reference, estimate, _ = _run()
    keep = np.isin(estimate.stamps_ns, reference.stamps_ns)
    result = evaluate(reference, [estimate.select(keep)], EvaluationConfig(no_ci=True))
    assert result.estimates[0].excursions == ()
