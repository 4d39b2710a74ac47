"""The report's "Clocks and device offset" section: given, estimated, sigma, and the plot."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from exporters.plots.figure import FigureView, ImageFormat, Plot
from loceval.calibration.offsets import OffsetCheck
from loceval.evaluation import EstimateResult, EvaluationConfig, EvaluationResult

__all__ = ["ClockFigure", "ClockSection", "build_clock_section", "time_offset_text"]

_NONE = "–"


ClockFigure = FigureView
"""The section's numbered plot."""


@dataclass(frozen=True, slots=True)
class ClockSection:
    """What the section shows: (label, one value per estimate) rows and the plot.

    Attributes:
        rows: the table's rows.
        figure: the correlation plot, or None when no clock could be checked.
    """

    rows: tuple[tuple[str, tuple[str, ...]], ...]
    figure: ClockFigure | None


def time_offset_text(config: EvaluationConfig) -> str:
    """Return the time offset option in words, for the report's options table."""
    if config.auto_time_offset:
        return "estimated from the motion (see Clocks and device offset)"
    return f"{config.time_offset_s:+g} s added to the estimates' stamps"


def _ms(value_s: float | None, sigma_s: float | None = None) -> str:
    if value_s is None:
        return _NONE
    pm = "" if sigma_s is None else f" ± {sigma_s * 1e3:.2f}"
    return f"{value_s * 1e3:+.2f}{pm} ms"


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
        _given_device(result, check),
        *device,
        unobservable,
        compared,
    )


_LABELS = (
    "Time offset given",
    "Time offset estimated (1 sigma)",
    "Offsets that fit",
    "Time offset applied",
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
    image_format: ImageFormat = "svg",
) -> ClockSection:
    """Format the section, with its plot as the figure ``number``.

    Args:
        result: the evaluation.
        number: the plot's figure number.
        plot: the section's plot (:func:`exporters.plots.clock.plot_clock_correlation`),
            holding ``image_format``; None when there is none.
        image_format: ``svg`` for the HTML, ``png`` for the PDF.

    Returns:
        The section's view.
    """
    columns = [_column(result, e) for e in result.estimates]
    rows = tuple((label, tuple(column[i] for column in columns)) for i, label in enumerate(_LABELS))
    figure = None if plot is None else plot.as_figure(number, image_format)
    return ClockSection(rows=rows, figure=figure)
