"""The stretches outside the tracked room as every CAD file and the viewer draw them.

An excursion (:mod:`loceval.metrics.excursions`) is a reference loss longer than the minimum
while an estimate went on. :func:`excursion_paths` selects, once for every output, the
estimate's aligned poses inside each excursion (evaluation frame) and writes its label
("slam excursion: 45 s, 45 m, error 0.00 -> 0.22 m"); the DXF, 3DM, GLB and IFC place them
with :meth:`~exporters.cad.placement.Placement.to_model` (:func:`placed_excursions`) and the
viewer with its own local frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from exporters.cad.placement import Placement
from loceval.core.arrays import FloatArray
from loceval.core.quantities import ARROW
from loceval.evaluation import EvaluationResult
from loceval.metrics.excursions import Excursion

__all__ = [
    "EXCURSION_LAYER",
    "EXCURSION_RGB",
    "ExcursionPath",
    "excursion_paths",
    "placed_excursions",
]

EXCURSION_LAYER: Final = "excursions"
"""The layer (DXF, 3DM), node (GLB) and ``ObjectType`` (IFC) of the excursions."""
EXCURSION_RGB: Final = (106, 27, 154)
"""The excursions' colour: the report's hatched bands' purple."""
_NS_PER_S: Final = 1_000_000_000


@dataclass(frozen=True, slots=True, eq=False)
class ExcursionPath:
    """One estimate's path outside the tracked room.

    Attributes:
        estimate: the estimate's name.
        index: the estimate's position in the evaluation's estimates.
        excursion: the figures (:class:`~loceval.metrics.excursions.Excursion`).
        positions_xyz: (M, 3) the aligned estimate's positions inside the excursion,
            evaluation frame, metres (two or more).
        label: what it measured, in one line.
        figures: the result document's record (``start_s`` since the reference's first
            stamp, ``duration_s``, ``path_length_m``, ``error_before_m``,
            ``error_after_m``, ``drift_per_m``).
    """

    estimate: str
    index: int
    excursion: Excursion
    positions_xyz: FloatArray
    label: str
    figures: dict[str, float | None]

    @property
    def duration_s(self) -> float:
        """The excursion's duration, seconds."""
        return (self.excursion.end_ns - self.excursion.start_ns) / _NS_PER_S


def excursion_label(name: str, excursion: Excursion) -> str:
    """Return ``"<name> excursion: 45 s, 45 m, error 0.00 → 0.22 m"`` (``-``: not measured)."""
    before = "-" if excursion.error_before_m is None else f"{excursion.error_before_m:.2f}"
    after = "-" if excursion.error_after_m is None else f"{excursion.error_after_m:.2f}"
    duration = (excursion.end_ns - excursion.start_ns) / _NS_PER_S
    return (
        f"{name} excursion: {duration:.0f} s, {excursion.path_length_m:.0f} m, "
        f"error {before} {ARROW} {after} m"
    )


def excursion_paths(result: EvaluationResult) -> list[ExcursionPath]:
    """Return every estimate's excursions with their aligned poses (evaluation frame).

    An excursion whose estimate has fewer than two poses inside it is left out: there is
    no path to draw.
    """
    out = []
    t0_ns = int(result.reference.stamps_ns[0]) if len(result.reference) else 0
    for index, estimate in enumerate(result.estimates):
        if not estimate.excursions:
            continue
        stamps = estimate.estimate.stamps_ns + np.int64(estimate.association.offset_ns)
        for excursion in estimate.excursions:  # a few stretches per run
            lo = int(np.searchsorted(stamps, excursion.start_ns, side="left"))
            hi = int(np.searchsorted(stamps, excursion.end_ns, side="right"))
            if hi - lo < 2:
                continue
            xyz = estimate.alignment.transform.apply_positions(
                estimate.estimate.positions_xyz[lo:hi]
            )
            label = excursion_label(estimate.name, excursion)
            out.append(
                ExcursionPath(estimate.name, index, excursion, xyz, label, excursion.to_dict(t0_ns))
            )
    return out


def placed_excursions(placement: Placement) -> list[tuple[ExcursionPath, FloatArray]]:
    """Return each excursion path with its vertices in model coordinates (output units)."""
    return [
        (path, placement.to_model(path.positions_xyz)) for path in excursion_paths(placement.result)
    ]
