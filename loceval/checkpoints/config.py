"""The options of a control-point evaluation, apart from the evaluation itself.

:class:`CheckpointConfig` lives here, not in :mod:`loceval.checkpoint_evaluation`, so a
trajectory evaluation (whose job carries a default one) does not import the control-point
scoring; :mod:`loceval.checkpoint_evaluation` re-exports it under its old name.
"""

from __future__ import annotations

from dataclasses import dataclass

from loceval.options import check_option, number_default

__all__ = ["CheckpointConfig"]


@dataclass(frozen=True, slots=True)
class CheckpointConfig:
    """The options that only a control-point reference uses.

    Attributes:
        visit_radius_m: how near a stop must be to a point to visit it; None: half the
            smallest distance between two points.
        align_points: ids of the points that fix the alignment (the rest are scored);
            empty: every visited point fixes it.
        stop_speed_mps: stops: the speed below which the device stands still, m/s.
        stop_min_s: stops: how long it must stand still, seconds.
    """

    visit_radius_m: float | None = None
    align_points: tuple[str, ...] = ()
    stop_speed_mps: float = number_default("stop_speed_mps")
    stop_min_s: float = number_default("stop_min_s")

    def __post_init__(self) -> None:
        """Check the values against the bounds of :data:`loceval.options.OPTIONS`.

        Raises:
            InputError: a value out of bounds; the error carries the option's key.
        """
        if self.visit_radius_m is not None:
            check_option("visit_radius_m", self.visit_radius_m, unit="metres")
        check_option("stop_speed_mps", self.stop_speed_mps, unit="metres per second")
        check_option("stop_min_s", self.stop_min_s, unit="seconds")

    def to_dict(self) -> dict[str, object]:
        """Return the options as JSON."""
        return {
            "visit_radius_m": self.visit_radius_m,
            "align_points": list(self.align_points),
            "stop_speed_mps": self.stop_speed_mps,
            "stop_min_s": self.stop_min_s,
        }
