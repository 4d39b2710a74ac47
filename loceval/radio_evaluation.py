"""Radio ranging end to end: the ranges' own errors, then positions from them, evaluated.

:func:`evaluate_radio` answers the two questions of issue 17 on one recording: is it the
radio (:func:`loceval.radio.ranging.evaluate_ranging`: every range against the true distance from
the reference to its anchor) or the algorithm
(:func:`loceval.radio.multilateration.solve_positions`:
one position-only estimate per solver, named ``nlls`` / ``minmax``, evaluated by
:func:`loceval.evaluation.evaluate` like any estimate). The result is an
:class:`~loceval.evaluation.EvaluationResult` whose ``ranging`` holds the ranging figures, so
the artifacts, the service and the command line treat it as any evaluation.

In 2D the estimates' heights are the fixed tag height, so their errors are measured in
x-y only (``planar``); with a tag offset the reference is moved to the tag (the evaluation's
``reference_offset``) so that the positions compare with where the tag was.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Final

import numpy as np

from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, EvaluationResult, ProgressCallback, evaluate
from loceval.options import check_option, number_default
from loceval.radio.multilateration import Solver, solve_positions
from loceval.radio.ranging import evaluate_ranging
from loceval.readers.radio import Ranges
from loceval.registration.alignment import AlignMethod
from loceval.trajectory import MAX_OFFSET_M, Trajectory

__all__ = ["RangingConfig", "evaluate_radio", "parse_solvers", "parse_tag_offset"]

_NS_PER_S: Final = 1_000_000_000


@dataclass(frozen=True, slots=True)
class RangingConfig:
    """The options of the ranging evaluation and of positioning from ranges.

    Attributes:
        solvers: the positioning algorithms, in output order.
        dims: 2 (tag at a fixed height) or 3.
        epoch_s: the epoch length, seconds.
        tag_height_m: the tag's height in 2D, metres; None takes the reference's median.
        tag_offset_xyz: the tag in the reference body frame, metres; None at the origin.
        outlier_threshold_m: |error| beyond which a range is an outlier, metres.
        distance_bin_m: width of the error-versus-true-distance bins, metres.
    """

    solvers: tuple[Solver, ...] = (Solver.NLLS, Solver.MINMAX)
    dims: int = 2
    epoch_s: float = number_default("epoch_s")
    tag_height_m: float | None = None
    tag_offset_xyz: tuple[float, float, float] | None = None
    outlier_threshold_m: float = number_default("outlier_threshold_m")
    distance_bin_m: float = number_default("distance_bin_m")

    def __post_init__(self) -> None:
        """Check the values against the bounds of :data:`loceval.options.OPTIONS`.

        Raises:
            InputError: a value out of bounds; the error carries the option's key.
        """
        if not self.solvers or len(set(self.solvers)) != len(self.solvers):
            msg = f"Name each positioning algorithm once (nlls, minmax), got {self.solvers!r}."
            raise InputError(msg, option="solve")
        if self.dims not in (2, 3):
            msg = f"The number of dimensions must be 2 or 3, got {self.dims!r}."
            raise InputError(msg, option="dims")
        check_option("epoch_s", self.epoch_s, unit="seconds")
        if self.tag_height_m is not None:
            check_option("tag_height_m", self.tag_height_m, unit="metres")
        check_option("outlier_threshold_m", self.outlier_threshold_m, unit="metres")
        check_option("distance_bin_m", self.distance_bin_m, unit="metres")

    def to_dict(self) -> dict[str, object]:
        """Return the options as JSON (for the result's provenance)."""
        return {
            "solve": [s.value for s in self.solvers],
            "dims": self.dims,
            "epoch_s": self.epoch_s,
            "tag_height_m": self.tag_height_m,
            "tag_offset_xyz": None if self.tag_offset_xyz is None else list(self.tag_offset_xyz),
            "outlier_threshold_m": self.outlier_threshold_m,
            "distance_bin_m": self.distance_bin_m,
        }


def parse_solvers(names: Sequence[str]) -> tuple[Solver, ...]:
    """Return the solvers named (``["nlls", "minmax"]``), in order.

    Raises:
        InputError: a name is not a solver, or none is given.
    """
    known = [s.value for s in Solver]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        msg = (
            f"The positioning algorithms are {' and '.join(known)}, got "
            f"{', '.join(repr(n) for n in names) or 'none'}."
        )
        raise InputError(msg, option="solve", suggest=",".join(known))
    return tuple(Solver(n) for n in dict.fromkeys(names))


def parse_tag_offset(text: str | None) -> tuple[float, float, float] | None:
    """Parse ``"x y z"`` metres (commas allowed); None or empty text for no offset.

    Raises:
        InputError: not three finite numbers, or one beyond
            ±:data:`~loceval.trajectory.MAX_OFFSET_M` metres.
    """
    if text is None or not text.strip():
        return None
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) != 3 or not np.isfinite(values).all():
        msg = f'The tag offset takes three numbers "x y z" in metres, got {text!r}.'
        raise InputError(msg, option="tag_offset_xyz")
    if max(abs(v) for v in values) > MAX_OFFSET_M:
        msg = (
            f"The tag offset {text!r} reaches beyond ±{MAX_OFFSET_M:g} m, more than any lever "
            'arm on one device; give "x y z" in metres.'
        )
        raise InputError(msg, option="tag_offset_xyz")
    return (values[0], values[1], values[2])


def evaluate_radio(
    reference: Trajectory,
    ranges: Ranges,
    ranging: RangingConfig,
    config: EvaluationConfig | None = None,
    *,
    inputs: Sequence[Mapping[str, object]] = (),
    progress: ProgressCallback | None = None,
) -> EvaluationResult:
    """Evaluate the ranges, position the tag from them and evaluate each solver's positions.

    Args:
        reference: the ground truth of the tag's carrier.
        ranges: the measurements and their anchors.
        ranging: the ranging and positioning options.
        config: the evaluation options of the solvers' estimates (``planar`` is set in 2D;
            the tag offset becomes the reference offset); None: the defaults with alignment
            ``none``, since the anchors are in building coordinates already.
        inputs: provenance of the input files for the result.
        progress: called with (stage, fraction done).

    Returns:
        The evaluation of the solvers' estimates, with ``ranging`` set.

    Raises:
        InputError: an option is out of range, a tag offset together with a device offset
            or for a reference without orientations, or no epoch has enough anchors.
        AssociationError: no range, or no epoch, falls within the reference's coverage.
    """
    config = config or EvaluationConfig(align=AlignMethod.NONE)
    report = progress or (lambda _stage, _fraction: None)
    offset = ranging.tag_offset_xyz
    if offset is not None and config.reference_offset is not None:
        msg = "Give the tag offset or a device offset of the reference, not both."
        raise InputError(msg, option="tag_offset_xyz")
    report("evaluating the ranges", 0.0)
    ranging_result = evaluate_ranging(
        reference,
        ranges,
        max_gap_ns=round(config.max_gap_s * _NS_PER_S),
        tag_offset_xyz=offset,
        outlier_threshold_m=ranging.outlier_threshold_m,
        distance_bin_m=ranging.distance_bin_m,
    )
    report("positioning", 0.3)
    estimates = solve_positions(
        ranges,
        solvers=ranging.solvers,
        epoch_s=ranging.epoch_s,
        dims=ranging.dims,
        tag_height_m=ranging.tag_height_m,
        reference=reference,
        tag_offset_xyz=offset,
    )
    if offset is not None and any(offset):
        lever = SimilarityTransform.from_pose(np.array(offset), np.array([0.0, 0.0, 0.0, 1.0]))
        config = replace(config, reference_offset=lever)
    config = replace(config, planar=config.planar or ranging.dims == 2)

    def evaluating(stage: str, fraction: float) -> None:
        report(stage, 0.5 + 0.5 * fraction)

    result = evaluate(reference, estimates, config, inputs=inputs, progress=evaluating)
    options = {**ranging.to_dict(), "tag_height_m": _tag_height_m(estimates, ranging)}
    return replace(result, ranging=ranging_result, ranging_options=options)


def _tag_height_m(estimates: Sequence[Trajectory], ranging: RangingConfig) -> float | None:
    """Return the 2D tag height used (the estimates' z), None in 3D."""
    if ranging.dims == 3 or not estimates:
        return None
    return float(estimates[0].positions_xyz[0, 2])
