"""Trials of each system: a box plot per metric, every trial a point.

Each system's trials (:mod:`loceval.assessment.trials`) are drawn as a box (quartiles,
median, whiskers to the furthest trial within 1.5 IQR) with every trial as a dot beside it
(spread evenly across the box, so equal values stay visible), the mean as a diamond with
its 95 % t-interval over trials as a bar, and, when the baseline has that system, the
baseline's median as a dashed line across the box. Failed trials have no value; the tick
label counts them. The figures use the fixed layout of :mod:`exporters.plots.layout`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import numpy as np

from exporters.plots.figure import (
    ImageFormat,
    Plot,
    encode_plot,
    estimate_colour,
)
from exporters.plots.mpl import legend_above, new_figure, style_axes
from loceval.assessment.trials import TRIAL_METRICS, SystemTrials
from loceval.evaluation import EvaluationResult

__all__ = ["plot_trials"]

_BASELINE_COLOUR: Final = "#424242"
_UNITS: Final = {"m": "m", "deg": "°", "%": "%"}


def _baseline_medians(result: EvaluationResult, metric: str) -> dict[str, float]:
    """The baseline's figure of each system (its median, or its single run's RMSE)."""
    if result.baseline is None:
        return {}
    return {
        d.name: d.baseline
        for d in result.baseline.differences
        if d.level == "system" and d.metric == metric
    }


def _limits(
    shown: Sequence[SystemTrials], metric: str, baseline: dict[str, float]
) -> tuple[float, float]:
    """The value axis: every trial, interval and baseline figure, with a margin.

    Not from 0: trials of one system differ by a few percent, which a zero-based axis
    flattens.
    """
    drawn = [v for s in shown for v in s.metrics[metric].values]
    for s in shown:
        m = s.metrics[metric]
        if m.interval is not None:
            drawn += [m.interval.low, m.interval.high]
        if s.name in baseline:
            drawn.append(baseline[s.name])
    lo, hi = min(drawn), max(drawn)
    margin = max(0.08 * (hi - lo), 0.02 * max(abs(hi), 1e-9))
    return max(0.0, lo - margin), hi + margin


def plot_trials(
    result: EvaluationResult, *, formats: Sequence[ImageFormat] = ("svg",)
) -> tuple[Plot, ...]:
    """Return one box plot per metric the systems have (none without systems).

    Args:
        result: the evaluation.
        formats: the encodings (SVG for HTML and the PDF, PNG for a WeasyPrint PDF).

    Returns:
        The plots, keyed ``trials_<metric>``, in :data:`TRIAL_METRICS` order.
    """
    systems = [s for s in result.systems if s.metrics]
    plots = []
    for metric, label in TRIAL_METRICS.items():
        shown = [s for s in systems if metric in s.metrics]
        if not shown:
            continue
        unit = shown[0].metrics[metric].unit
        fig = new_figure(3.2 if len(shown) <= 4 else 4.0)
        ax = fig.add_subplot()
        values = [s.metrics[metric].values for s in shown]
        positions = np.arange(1, len(shown) + 1, dtype=np.float64)
        ax.boxplot(
            values,
            positions=positions,
            widths=0.45,
            whis=1.5,
            showfliers=False,
            medianprops={"color": "#212121", "linewidth": 1.4},
            boxprops={"color": "#616161"},
            whiskerprops={"color": "#616161"},
            capprops={"color": "#616161"},
        )
        baseline = _baseline_medians(result, metric)
        first_in_baseline = next((s.name for s in shown if s.name in baseline), None)
        for k, (system, x) in enumerate(zip(shown, positions, strict=True)):
            m = system.metrics[metric]
            n = m.values.size
            offsets = np.linspace(-0.15, 0.15, n) if n > 1 else np.zeros(1)
            ax.plot(
                x + offsets,
                m.values,
                linestyle="none",
                marker="o",
                markersize=4.5,
                markerfacecolor=estimate_colour(k),
                markeredgecolor="white",
                markeredgewidth=0.5,
                zorder=4,
                label="a trial" if k == 0 else None,
            )
            if m.interval is not None:
                ax.errorbar(
                    [x + 0.32],
                    [m.mean],
                    yerr=[[m.mean - m.interval.low], [m.interval.high - m.mean]],
                    fmt="D",
                    markersize=4,
                    color="#1565c0",
                    capsize=3,
                    linewidth=1.0,
                    zorder=4,
                    label="mean and its 95 % interval" if k == 0 else None,
                )
            if system.name in baseline:
                ax.hlines(
                    baseline[system.name],
                    x - 0.3,
                    x + 0.3,
                    colors=_BASELINE_COLOUR,
                    linestyles="--",
                    linewidth=1.2,
                    zorder=3,
                    label="baseline" if system.name == first_in_baseline else "_nolegend_",
                )
        ticks = [
            f"{s.name}: {len(s.trials)} trials" + (f", {len(s.failed)} failed" if s.failed else "")
            for s in shown
        ]
        ax.set_xticks(positions, ticks, fontsize=8)
        ax.set_xlim(0.4, len(shown) + 0.6)
        ax.set_ylim(*_limits(shown, metric, baseline))
        ax.set_ylabel(f"{label} [{_UNITS.get(unit, unit)}]")
        style_axes(ax)
        legend_above(fig, ax)
        failed = sum(len(s.failed) for s in shown)
        caption = (
            f"{label} of every trial (dots) of each system: box from the first to the third "
            "quartile, line at the median, whiskers to the furthest trial within 1.5 times "
            "the box; the diamond is the mean with its 95 % Student-t interval over trials "
            "(3 trials or more)."
        )
        if baseline:
            caption += " The dashed line is the baseline's figure of that system."
        if failed:
            caption += f" {failed} failed {'trial has' if failed == 1 else 'trials have'} no value."
        plots.append(
            encode_plot(
                fig, formats, key=f"trials_{metric}", title=f"Trials: {label}", caption=caption
            )
        )
    return tuple(plots)
