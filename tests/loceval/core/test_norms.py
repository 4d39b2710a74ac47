"""row_norms gives np.linalg.norm(x, axis=-1)'s doubles bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.core.norms import row_norms

_SMALL = float(np.sqrt(0.75 * 2.0**-52))
"""Its square is below half an ulp of 1, two of them above: the order of the sum shows."""


def _bits(value: object) -> list[int]:
    out: list[int] = np.atleast_1d(np.asarray(value, dtype=np.float64)).view(np.int64).tolist()
    return out


@pytest.mark.parametrize("shape", [(3,), (4,), (1, 3), (7, 4), (1000, 3), (5, 6, 4), (9, 2)])
def test_rows_of_every_magnitude_match_numpy(
    rng: np.random.Generator, shape: tuple[int, ...]
) -> None:
    """Rows mixing magnitudes from 1e-9 to 1e9 give NumPy's norms, in any array shape."""
    for _ in range(50):
        x = rng.normal(size=shape) * 10.0 ** rng.integers(-9, 10, size=shape)
        assert _bits(row_norms(x)) == _bits(np.linalg.norm(x, axis=-1))


@pytest.mark.parametrize(
    "row",
    [
        [1.0, _SMALL, _SMALL],
        [_SMALL, _SMALL, 1.0],
        [_SMALL, 1.0, _SMALL],
        [1.0, _SMALL, _SMALL, _SMALL],
        [_SMALL, _SMALL, _SMALL, 1.0],
    ],
)
def test_sums_that_depend_on_their_order_match_numpy(row: list[float]) -> None:
    """Where (a + b) + c and a + (b + c) round apart, the norm is still NumPy's."""
    x = np.array(row)
    many = np.tile(x, (100, 1))
    assert _bits(row_norms(x)) == _bits(np.linalg.norm(x, axis=-1))
    assert _bits(row_norms(many)) == _bits(np.linalg.norm(many, axis=-1))


def test_special_values_and_wide_rows_match_numpy() -> None:
    """Zeros, inf, NaN and rows of one or of five values come out as NumPy's."""
    x = np.array([[0.0, -0.0, 0.0], [np.inf, 1.0, 2.0], [np.nan, 1.0, 0.0], [1e200, 1e200, 0]])
    with np.errstate(over="ignore"):
        assert _bits(row_norms(x)) == _bits(np.linalg.norm(x, axis=-1))
    for wide in (np.arange(5.0).reshape(1, 5), np.ones((3, 1))):
        assert _bits(row_norms(wide)) == _bits(np.linalg.norm(wide, axis=-1))
