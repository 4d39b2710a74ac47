"""Re-drive timing: two runs of one path, the second slower along one stretch."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.errors import InputError
from loceval.metrics.redrive import redrive_timing


def _path(s: np.ndarray) -> np.ndarray:
    """A loop through two rooms, by arc-length parameter ``s`` in metres (40 m long)."""
    angle = s / 40.0 * 2 * np.pi
    return np.column_stack([8 * np.cos(angle), 4 * np.sin(2 * angle) + 3 * np.sin(angle), 0 * s])


def test_a_known_timing_shift_in_one_stretch_is_found() -> None:
    """The later run waits 2.5 s at 15 m: on time before, 2.5 s late after, one stretch."""
    t1 = np.arange(0.0, 40.0, 0.05)  # 1 m/s
    first = _path(t1)
    t2 = np.arange(0.0, 42.5, 0.05)
    s2 = np.where(t2 < 15.0, t2, np.where(t2 < 17.5, 15.0, t2 - 2.5))  # stands 2.5 s at 15 m
    later = _path(np.minimum(s2, 39.95))
    timing = redrive_timing(t1, first, t2, later, tolerance_s=1.0)
    before = t1 < 14.9
    after = t1 > 15.1
    np.testing.assert_allclose(timing.difference_s[before], 0.0, atol=0.02)
    np.testing.assert_allclose(timing.difference_s[after], 2.5, atol=0.02)
    (stretch,) = timing.stretches
    assert stretch.start_s == pytest.approx(15.0, abs=0.1)
    assert stretch.duration_s == pytest.approx(40.0 - 15.0, abs=0.2)
    assert stretch.max_abs_s == pytest.approx(2.5, abs=0.02)
    assert timing.max_abs_s == pytest.approx(2.5, abs=0.02)
    assert timing.share_within == pytest.approx(15.0 / 40.0, abs=0.01)
    assert timing.to_dict()["stretches"][0]["start_s"] == stretch.start_s


def test_a_faithful_redrive_has_no_stretch() -> None:
    """Same path and pace, sampled at other instants: differences under the sample step."""
    t1 = np.arange(0.0, 40.0, 0.1)
    t2 = np.arange(0.03, 40.0, 0.07)
    timing = redrive_timing(t1, _path(t1), t2, _path(t2 - 0.03))
    assert timing.stretches == ()
    assert timing.max_abs_s < 0.05


def test_too_few_positions_are_refused() -> None:
    """A run of one position cannot be timed."""
    with pytest.raises(InputError, match="at least two positions"):
        redrive_timing(np.zeros(1), np.zeros((1, 3)), np.arange(3.0), np.zeros((3, 3)))
