"""The one rule for showing lengths: which unit and how many digits, in every output.

The viewer, the web page, the reports and the command line show lengths by this rule
(docs/files.md, "Units and digits"):

- **Errors and distances** (ATE, RPE, the worst error of a stretch, a scale bar) read in
  metres to the millimetre, ``0.027 m``; a group of them shown together (one table, the
  viewer's read-outs, a list of stretches) reads in millimetres to a tenth, ``27.4 mm``,
  when every value in the group is below :data:`MM_BELOW_M` (a sub-centimetre system's
  errors would otherwise read ``0.000 m``). :func:`length_unit` picks the group's unit.
- **Tolerances** read as the user gave them, in metres (``0.025 m``).
- **Coordinates** read in the model's output units (``--units``), to the millimetre:
  three decimals in metres, one in centimetres, none in millimetres
  (:func:`coordinate_decimals`).
- **Lengths travelled and durations** read to a tenth: ``3.2 m``, ``4.1 s``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Final

__all__ = [
    "MM_BELOW_M",
    "RESOLUTION_M",
    "LengthUnit",
    "coordinate_decimals",
    "format_coordinate",
    "length_unit",
]

MM_BELOW_M: Final = 0.1
"""A group of lengths reads in millimetres when every value in it is below this many metres."""
RESOLUTION_M: Final = 0.001
"""Coordinates are shown to this many metres (a millimetre) in whatever units."""


@dataclass(frozen=True, slots=True)
class LengthUnit:
    """How one group of lengths is printed: ``m`` with 3 decimals, or ``mm`` with 1.

    Chosen per group from its magnitudes (:func:`length_unit`): a sub-centimetre system's
    RMSE reads ``6.2 mm``, not ``0.006 m``, and a car's ``12.345 m``, not ``12345.0 mm``.
    """

    symbol: str
    per_metre: float
    decimals: int

    def format(self, value_m: float) -> str:
        """Return ``value_m`` in this unit, without the symbol."""
        return f"{value_m * self.per_metre:.{self.decimals}f}"

    def text(self, value_m: float) -> str:
        """Return ``value_m`` in this unit with its symbol (``27.4 mm``)."""
        return f"{self.format(value_m)} {self.symbol}"

    def to_dict(self) -> dict[str, object]:
        """Return the unit as the viewer reads it: symbol, per_metre, decimals."""
        return {"symbol": self.symbol, "per_metre": self.per_metre, "decimals": self.decimals}


METRES: Final = LengthUnit("m", 1.0, 3)
MILLIMETRES: Final = LengthUnit("mm", 1000.0, 1)


def length_unit(values_m: Iterable[float]) -> LengthUnit:
    """Return millimetres when every finite value of the group is below 0.1 m, else metres."""
    finite = [abs(v) for v in values_m if math.isfinite(v)]
    if finite and max(finite) < MM_BELOW_M:
        return MILLIMETRES
    return METRES


def coordinate_decimals(per_metre: float) -> int:
    """Return the decimals that show a coordinate to the millimetre in a unit.

    Args:
        per_metre: how many of the unit make a metre (1000 for millimetres).

    Returns:
        3 for metres, 1 for centimetres, 0 for millimetres (2 for inches, 3 for feet).
    """
    return max(0, math.ceil(-math.log10(RESOLUTION_M * per_metre) - 1e-9))


def format_coordinate(value: float, *, per_metre: float) -> str:
    """Return a coordinate already in a unit (``per_metre`` of it make a metre), to the mm."""
    return f"{value:.{coordinate_decimals(per_metre)}f}"
