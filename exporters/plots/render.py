"""Every plot of the evaluation report, in report order.

The plots drawn for every evaluation use the figure kit (:mod:`exporters.plots.svg`); those
of trials, ranging and a robot's map are matplotlib figures, whose modules are imported
only when the evaluation has them (matplotlib takes a third of a second to import).
"""

from __future__ import annotations

from collections.abc import Sequence

from exporters.plots.figure import DEFAULT_MAX_POINTS, ImageFormat, Plot
from exporters.plots.maps import is_3d, plot_ate_path, plot_overlay_xy, plot_side_views
from exporters.plots.series import plot_ate_over_time, plot_error_cdf, plot_rpe_over_time
from loceval.core.arrays import FloatArray
from loceval.evaluation import EvaluationResult

__all__ = ["render_plots"]


def render_plots(
    result: EvaluationResult,
    *,
    max_points: int = DEFAULT_MAX_POINTS,
    formats: Sequence[ImageFormat] = ("svg",),
    floor_plan: FloatArray | None = None,
) -> tuple[Plot, ...]:
    """Render every plot of the report, in report order.

    Args:
        result: the evaluation.
        max_points: most vertices drawn per line (drawing only; statistics use all poses).
        formats: the encodings to produce from each figure (SVG for HTML, PNG for PDF).
        floor_plan: the building's floor plan drawn under the plan views, (K, 2, 2)
            evaluation-frame metres (see :func:`exporters.plots.underlay.floor_plan_segments`).

    Returns:
        The overlay, one error-coloured path per estimate, ATE and RPE over time, the CDF
        and, for a 3D path, the side views; then, for ranges, the ranging plots.
    """
    plots = [plot_overlay_xy(result, max_points=max_points, formats=formats, floor_plan=floor_plan)]
    plots.extend(
        plot_ate_path(result, k, max_points=max_points, formats=formats, floor_plan=floor_plan)
        for k in range(len(result.estimates))
    )
    plots.append(plot_ate_over_time(result, max_points=max_points, formats=formats))
    plots.append(plot_rpe_over_time(result, max_points=max_points, formats=formats))
    plots.append(plot_error_cdf(result, max_points=max_points, formats=formats))
    if any(s.metrics for s in result.systems):
        from exporters.plots.trials import plot_trials  # noqa: PLC0415  (matplotlib)

        plots.extend(plot_trials(result, formats=formats))
    if is_3d(result):
        plots.append(plot_side_views(result, max_points=max_points, formats=formats))
    if result.ranging is not None:
        from exporters.plots.ranging import plot_ranging  # noqa: PLC0415  (matplotlib)

        plots.extend(plot_ranging(result, max_points=max_points, formats=formats))
    if result.map is not None:
        from exporters.plots.mapplan import plot_map, plot_map_history  # noqa: PLC0415

        plots.extend(plot_map(result, max_points=max_points, formats=formats))
        plots.extend(plot_map_history(result, formats=formats))
    return tuple(plots)
