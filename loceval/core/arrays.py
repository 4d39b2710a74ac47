"""Array aliases used across the core; shapes are documented where they are used."""

from __future__ import annotations

from typing import TypeAlias

import numpy as np
from numpy.typing import NDArray

StampsNs: TypeAlias = NDArray[np.int64]
"""(N,) int64 nanoseconds."""
FloatArray: TypeAlias = NDArray[np.float64]
"""float64 array; the shape is given where it is used."""
IntArray: TypeAlias = NDArray[np.intp]
BoolArray: TypeAlias = NDArray[np.bool_]
