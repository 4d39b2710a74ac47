"""The report's "Clocks and device offset" section: given, estimated, sigma, and the plots.

Besides the table it says in words, per estimate, how much its clock moved along the run
(the drift's rate and steps, and whether they were corrected), and holds the figure of the
offset along the run next to the correlation's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from exporters.plots.figure import FigureView, ImageFormat, Plot
from loceval.calibration.drift import SIGNIFICANT_Z, describe_rate, describe_step
from loceval.calibration.offsets import OffsetCheck
from loceval.core.quantities import plus_minus
from loceval.evaluation import EstimateResult, EvaluationConfig, EvaluationResult

__all__ = [
    "ClockFigure",
    "ClockSection",
    "build_clock_section",
    "clock_drift_text",
    "drift_words",
    "time_offset_text",
]

_NONE = "–"


ClockFigure = FigureView
"""The section's numbered plot."""


@dataclass(frozen=True, slots=True)
class ClockSection:
    """What the section shows: (label, one value per estimate) rows, words and the plots.

    Attributes:
        rows: the table's rows.
        figure: the correlation plot, or None when no clock could be checked.
        drift: (estimate's name, sentences) on how its clock moved along the run, then
            what the clock check noted for information (nothing to do).
        drift_figure: the plot of the offset along the run, or None (no drift checked).
    """

    rows: tuple[tuple[str, tuple[str, ...]], ...]
    figure: ClockFigure | None
    drift: tuple[tuple[str, str], ...] = ()
    drift_figure: ClockFigure | None = None


def time_offset_text(config: EvaluationConfig) -> str:
    """Return the time offset option in words, for the report's options table."""
    if config.auto_time_offset:
        return "estimated from the motion (see Clocks and device offset)"
    return f"{config.time_offset_s:+g} s added to the estimates' stamps"


def clock_drift_text(config: EvaluationConfig) -> str:
    """Return the clock drift option in words, for the report's options table."""
    if config.auto_clock_drift:
        return "estimated from the motion, with any step (see Clocks and device offset)"
    if config.clock_drift_ppm == 0.0:
        return "none (the clocks checked for drift)"
    return f"{config.clock_drift_ppm:+g} ppm (the estimates' clocks run that much fast)"


def drift_words(e: EstimateResult, config: EvaluationConfig) -> str:
    """How much the estimate's clock moved along the run, and what was done about it."""
    check = e.offsets
    clock = None if check is None else check.time_offset
    if clock is None:
        return "Its clock was not checked (see the warnings)."
    drift = clock.drift
    if drift is None:
        return (
            "The run is too short, or moves too little, to tell whether its clock drifts; "
            "the offset was taken as constant."
        )
    minutes = drift.duration_s / 60.0
    words = (
        f"Its clock {describe_rate(drift.rate_ppm, drift.sigma_rate_ppm)} against the ground "
        f"truth's: over the {minutes:.1f} min run the time offset moves by "
        f"{drift.moved_s * 1e3:.1f} ms"
    )
    if drift.steps:
        words += "; " + "; ".join(describe_step(s) for s in drift.steps)
    if clock.rate_ppm != 0.0 or clock.steps_applied:
        whose = "estimated" if config.auto_clock_drift else "given"
        what = "rate and the steps were" if clock.steps_applied else "rate was"
        return f"{words}. The {whose} {what} applied along the run."
    if not drift.significant and not drift.steps:
        return f"{words}: no drift beyond {SIGNIFICANT_Z:g} sigma, so none was applied."
    return f"{words}. This was not corrected: one offset was applied to the whole run."


def _ms(value_s: float | None, sigma_s: float | None = None) -> str:
    if value_s is None:
        return _NONE
    sigma_ms = None if sigma_s is None else sigma_s * 1e3
    return plus_minus(value_s * 1e3, sigma_ms, "ms", sign=True, places=2)


def _given_time(result: EvaluationResult) -> str:
    cfg = result.config
    return "auto (estimated)" if cfg.auto_time_offset else _ms(cfg.time_offset_s)


def _estimated_time(check: OffsetCheck | None) -> str:
    if check is None or check.time_offset is None:
        return "not checked (see the warnings)"
    clock = check.time_offset
    return _ms(clock.estimated_s, clock.sigma_s)


def _candidates(check: OffsetCheck | None) -> str:
    if check is None or check.time_offset is None:
        return _NONE
    # In ms like the rows around it: one unit for one quantity down the column.
    return ", ".join(_ms(c) for c in check.time_offset.candidates_s)


def _given_device(result: EvaluationResult, check: OffsetCheck | None) -> str:
    cfg = result.config
    if cfg.auto_device:
        return "auto (estimated)"
    if cfg.reference_offset is None:
        return "none"
    t_mm = ", ".join(f"{v * 1e3:.1f}" for v in cfg.reference_offset.translation)
    source = "URDF / tf_static" if check is not None and check.device_source == "urdf" else "given"
    return f"({t_mm}) mm, {source}"


def _sigmas(values: Sequence[float | None], scale: float, unit: str, decimals: int) -> str:
    return ", ".join(_NONE if v is None else f"{v * scale:.{decimals}f}" for v in values) + unit


def _device_rows(check: OffsetCheck | None) -> tuple[str, str, str, str]:
    """Estimated translation, its sigma, rotation and its sigma, as words."""
    found = None if check is None else check.device
    if found is None:
        return (_NONE, _NONE, _NONE, _NONE)
    t_mm = ", ".join(f"{v * 1e3:.1f}" for v in found.translation_m)
    rotation = ", ".join(f"{v:.4f}" for v in found.rotation_xyzw)
    return (
        f"({t_mm}) mm",
        _sigmas(found.sigma_translation_m, 1e3, " mm", 2),
        rotation,
        _sigmas(found.sigma_rotation_deg, 1.0, " deg", 3),
    )


def _drift_rows(result: EvaluationResult, check: OffsetCheck | None) -> tuple[str, str, str, str]:
    """The drift given, estimated (1 sigma), its steps and what was applied, as words."""
    cfg = result.config
    given = "auto (estimated)" if cfg.auto_clock_drift else f"{cfg.clock_drift_ppm:+g} ppm"
    clock = None if check is None else check.time_offset
    drift = None if clock is None else clock.drift
    if clock is None or drift is None:
        applied = _NONE if check is None else f"{check.clock_drift_ppm:+g} ppm"
        return (given, "not checked", _NONE, applied)
    steps = "; ".join(
        f"{plus_minus(s.size_s * 1e3, s.sigma_size_s * 1e3, 'ms', sign=True)} at "
        f"{plus_minus(s.at_s, s.sigma_at_s, 's')}"
        for s in drift.steps
    )
    applied = f"{clock.rate_ppm:+.2f} ppm" if clock.rate_ppm != 0.0 else "none"
    if clock.steps_applied:
        applied += f" and {len(drift.steps)} step{'s' if len(drift.steps) > 1 else ''}"
    return (
        given,
        plus_minus(drift.rate_ppm, drift.sigma_rate_ppm, "ppm", sign=True),
        steps or "none",
        applied,
    )


def _column(result: EvaluationResult, e: EstimateResult) -> tuple[str, ...]:
    check = e.offsets
    device = _device_rows(check)
    compared = _NONE if check is None or check.comparison is None else check.comparison.message
    unobservable = _NONE
    if check is not None and check.device is not None:
        unobservable = ", ".join(check.device.unobservable) or "none"
    return (
        _given_time(result),
        _estimated_time(check),
        _candidates(check),
        _ms(None if check is None else check.time_offset_s),
        *_drift_rows(result, check),
        _given_device(result, check),
        *device,
        unobservable,
        compared,
    )


_LABELS = (
    "Time offset given",
    "Time offset estimated (1 sigma)",
    "Offsets that fit",
    "Time offset applied (at the first pose)",
    "Clock drift given",
    "Clock drift estimated (1 sigma)",
    "Clock steps found (offset change at time)",
    "Clock drift applied",
    "Device offset given",
    "Device offset estimated",
    "  1 sigma per axis (x, y, z)",
    "  rotation (x, y, z, w)",
    "  1 sigma about x, y, z",
    "Not observable",
    "Estimate against given",
)


def build_clock_section(
    result: EvaluationResult,
    *,
    number: int,
    plot: Plot | None,
    drift_plot: Plot | None = None,
    image_format: ImageFormat = "svg",
) -> ClockSection:
    """Format the section, with its plots as the figures ``number`` and after.

    Args:
        result: the evaluation.
        number: the first plot's figure number.
        plot: the section's plot (:func:`exporters.plots.clock.plot_clock_correlation`),
            holding ``image_format``; None when there is none.
        drift_plot: the offset along the run (:func:`exporters.plots.clock.plot_clock_drift`),
            holding ``image_format``; None when there is none.
        image_format: ``svg`` for the HTML, ``png`` for the PDF.

    Returns:
        The section's view.
    """
    columns = [_column(result, e) for e in result.estimates]
    rows = tuple((label, tuple(column[i] for column in columns)) for i, label in enumerate(_LABELS))
    figure = None if plot is None else plot.as_figure(number, image_format)
    after = number if figure is None else number + 1
    return ClockSection(
        rows=rows,
        figure=figure,
        drift=tuple(
            (e.name or f"estimate {k + 1}", words)
            for k, e in enumerate(result.estimates)
            for words in (drift_words(e, result.config), *e.notes)
        ),
        drift_figure=None if drift_plot is None else drift_plot.as_figure(after, image_format),
    )
