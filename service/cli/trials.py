"""The terminal blocks of trials and the baseline, under ``loceval evaluate``'s tables.

The figures are formatted once, by the report's view models (:mod:`exporters.report.trials`),
so the terminal, the HTML and the PDF print the same numbers.
"""

from __future__ import annotations

from loceval.evaluation import EvaluationResult

__all__ = ["trial_lines"]


def trial_lines(result: EvaluationResult) -> list[str]:
    """Return the blocks of the systems' trials and of the baseline (none without either).

    The blocks: "Systems over their trials", "Failed trials", "Systems compared over all
    their trials" and "Against the baseline".
    """
    if not result.systems and result.baseline is None:
        return []
    from exporters.report.trials import build_baseline_view, build_trials_view  # noqa: PLC0415

    lines: list[str] = []
    trials = build_trials_view(result, ())
    if trials is not None:
        lines += ["", "Systems over their trials (95 % interval: Student t of the mean)"]
        lines += [
            f"  {r.system}, {r.metric}: median {r.median}, mean {r.mean}, std {r.std}, "
            f"range {r.range}, IQR {r.iqr}, interval {r.interval} ({r.trials} trials)"
            for r in trials.rows
        ]
        if trials.failed:
            lines += ["", f"Failed trials ({len(trials.failed)})"]
            lines += [f"  {f.system} / {f.name}: {f.reason}" for f in trials.failed]
        if trials.comparisons:
            lines += ["", "Systems compared over all their trials"]
            lines += [f"  {sentence}" for sentence in trials.comparisons]
    baseline = build_baseline_view(result)
    if baseline is not None:
        lines += ["", f"Against the baseline {baseline.source}"]
        lines += [
            f"  {r.name}, {r.metric}: now {r.now}, baseline {r.baseline}, difference "
            f"{r.difference} ({r.how} 95 % interval {r.interval}): {r.verdict}"
            for r in baseline.rows
        ]
        lines += [f"  {note}" for note in baseline.notes]
    return lines
