"""A schedule summary's comparisons of systems across runs, as sentences.

The runs of a schedule are different recordings, so two systems share no stamps across
them; :func:`loceval.assessment.comparison.compare_runs` compares their mean per-run RMSE with an
unpaired block bootstrap. A pair with fewer than 8 runs of either system is not compared
(a percentile interval over so few values says little); one sentence says so.
"""

from __future__ import annotations

from collections.abc import Sequence

from exporters.summary.model import SystemStats
from loceval.errors import InputError

__all__ = ["across_runs"]

_MIN_RUNS = 8


def across_runs(stats: Sequence[SystemStats]) -> list[str]:
    """Return one sentence per pair of systems and metric (A before B, in table order)."""
    if len(stats) < 2:
        return []
    from loceval.assessment.comparison import ComparedMetric, compare_runs  # noqa: PLC0415  (scipy)

    sentences = []
    short = False
    for i, sa in enumerate(stats):
        for sb in stats[i + 1 :]:
            for metric, va, vb in (
                (ComparedMetric.ATE_RMSE, sa.ate_rmse_m, sb.ate_rmse_m),
                (ComparedMetric.RPE_RMSE, sa.rpe_rmse_m, sb.rpe_rmse_m),
            ):
                if min(len(va), len(vb)) < _MIN_RUNS:
                    short = True
                    continue
                try:
                    found = compare_runs(va, vb, a=sa.name, b=sb.name, metric=metric)
                except InputError:
                    short = True
                    continue
                sentences.append(f"Across runs (mean RMSE per run): {found.summary}")
    if short:
        sentences.append(
            f"Systems with fewer than {_MIN_RUNS} evaluated runs are not compared across "
            "runs: too few runs for a confidence interval."
        )
    return sentences
