"""The median and quantiles that spare numpy.ma give NumPy's doubles bit for bit."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from loceval.core.quantiles import median, quantiles


def _bits(value: object) -> list[int]:
    out: list[int] = np.atleast_1d(np.asarray(value, dtype=np.float64)).view(np.int64).tolist()
    return out


def _series(rng: np.random.Generator, kind: int, n: int) -> np.ndarray:
    if kind == 0:
        return rng.normal(size=n) * 10.0 ** int(rng.integers(-5, 15))
    if kind == 1:
        return rng.integers(-(2**62), 2**62, size=n)  # int64: the mean of two as doubles
    if kind == 2:
        return np.diff(np.cumsum(rng.integers(1, 10**9, size=n + 1)))  # stamp steps
    if kind == 3:
        return rng.choice([0.0, -0.0, 1.0, 2.0], size=n)  # signed zeros, many ties
    return rng.random(n).round(2)


@pytest.mark.parametrize("kind", range(5))
def test_median_and_quantiles_match_numpy_bit_for_bit(kind: int) -> None:
    rng = np.random.default_rng(kind)
    for _ in range(300):
        x = _series(rng, kind, int(rng.integers(1, 700)))
        assert _bits(median(x)) == _bits(np.median(x))
        for q in ([0.025, 0.975], [0.0, 1.0], [0.5], [0.3, 0.31, 0.99]):
            assert _bits(quantiles(x, q)) == _bits(np.quantile(x.astype(np.float64), q))


def test_nan_gives_nan() -> None:
    for x in (np.array([1.0, np.nan, 2.0]), np.array([np.nan]), np.array([3.0, 1.0, np.nan, 2])):
        assert np.isnan(median(x))
        assert np.isnan(quantiles(x, [0.1, 0.9])).all()


def test_an_evaluation_does_not_import_numpy_ma() -> None:
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from loceval.assessment.uncertainty import interval_stats\n"
        "from loceval.metrics.pose_errors import ErrorStats\n"
        "x = np.abs(np.random.default_rng(1).normal(size=2000))\n"
        "interval_stats(x, thresholds_m=[0.5])\n"
        "ErrorStats.of(x)\n"
        "print('numpy.ma' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
