"""The report's ranging section: the per-anchor table of range errors, formatted.

Built only for an evaluation positioned from radio ranges (``result.ranging`` is set); the
figures (error against distance, error over time, the plan) are drawn by
:mod:`exporters.plots.ranging` and listed with the report's other plots.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from loceval.evaluation import EvaluationResult

__all__ = ["RangingView", "build_ranging_view"]


@dataclass(frozen=True, slots=True)
class RangingView:
    """The ranging section, formatted.

    Attributes:
        outlier_threshold: the outlier threshold in words (``1 m``).
        rows: one per anchor heard, then ``overall``: id, position, n, bias, std, RMSE,
            MAE, max |error|, outlier share, inlier RMSE, fit offset and scale.
        unused: the ids of anchors never heard.
        options: the ranging options as (label, value).
        warnings: the ranging evaluation's warnings.
    """

    outlier_threshold: str
    rows: tuple[Mapping[str, str], ...]
    unused: tuple[str, ...]
    options: tuple[tuple[str, str], ...]
    warnings: tuple[str, ...]


def _m(value: float | None) -> str:
    return "–" if value is None else f"{value:.3f}"


def build_ranging_view(result: EvaluationResult) -> RangingView | None:
    """Return the ranging section of the report, or None when there is no ranging part."""
    ranging = result.ranging
    if ranging is None:
        return None
    rows = []
    for anchor in ranging.anchors:  # a few dozen anchors
        s = anchor.stats
        x, y, z = anchor.position_xyz
        fit = anchor.fit
        rows.append(
            {
                "id": anchor.id,
                "position": f"{x:.2f}, {y:.2f}, {z:.2f}",
                "n": str(s.n),
                "bias": _m(s.bias_m),
                "std": _m(s.std_m),
                "rmse": _m(s.rmse_m),
                "mae": _m(s.mae_m),
                "max": _m(s.max_abs_m),
                "outliers": f"{s.outlier_share * 100:.1f} %",
                "inlier_rmse": _m(s.inlier_rmse_m),
                "fit": "–" if fit is None else f"{fit.offset_m:+.3f} m + {fit.scale:.4f} d",
            }
        )
    o = ranging.overall
    rows.append(
        {
            "id": "overall",
            "position": "",
            "n": str(o.n),
            "bias": _m(o.bias_m),
            "std": _m(o.std_m),
            "rmse": _m(o.rmse_m),
            "mae": _m(o.mae_m),
            "max": _m(o.max_abs_m),
            "outliers": f"{o.outlier_share * 100:.1f} %",
            "inlier_rmse": _m(o.inlier_rmse_m),
            "fit": "",
        }
    )
    return RangingView(
        outlier_threshold=f"{ranging.outlier_threshold_m:g} m",
        rows=tuple(rows),
        unused=ranging.unused_anchors,
        options=tuple((key, _option_text(value)) for key, value in result.ranging_options.items()),
        warnings=ranging.warnings,
    )


def _option_text(value: object) -> str:
    if value is None:
        return "–"
    if isinstance(value, list | tuple):
        return ", ".join(str(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)
