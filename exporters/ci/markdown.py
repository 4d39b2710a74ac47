"""``summary.md``: the results in GitHub-flavoured Markdown, for CI job summaries.

GitHub Actions shows it when it is appended to ``$GITHUB_STEP_SUMMARY``; GitLab and Gitea
show it as a merge-request comment. It holds, from the report's figure-free view model:
the gate (when ``--fail-on`` is given), the results table (an estimate per row: its system,
verdict, ATE and RPE RMSE with their 95 % intervals, the shares within the thresholds), each
verdict in words, the systems over their trials (with the failed trials), the comparisons
with the baseline, the comparisons of estimates, and the warnings (folded).

Text from the inputs (names, messages) is escaped: a ``|`` in a name cannot split a table
cell, and ``*``, ``_``, `````, ``[``, ``<`` cannot start emphasis, code, links or HTML.
"""

from __future__ import annotations

import re
from typing import Final

from exporters.options import ExportOptions
from exporters.report.results import ResultsView, build_results_view
from loceval.core.display import display_text
from loceval.evaluation import EvaluationResult

__all__ = [
    "BASELINE_MARKS",
    "STATUS_MARKS",
    "export_summary_md",
    "markdown_text",
    "summary_markdown",
]

STATUS_MARKS: Final = {
    "pass": "✅ PASS",
    "fail": "❌ FAIL",
    "undecided": "⚠️ UNDECIDED",
    "none": "— (no tolerance)",
}
"""How the results table shows a verdict (a mark and the word, so it reads without colour)."""

_SPECIAL: Final = re.compile(r"([\\`*_{}\[\]<>|#~!])")
"""Markdown's punctuation that could start markup inside a line or end a table cell."""


def markdown_text(text: str) -> str:
    """Return one line of text from the inputs with Markdown's punctuation escaped."""
    return _SPECIAL.sub(r"\\\1", display_text(text))


BASELINE_MARKS: Final = {
    "better": "✅ better",
    "worse": "❌ worse",
    "within_noise": "➖ within noise",
    "undetermined": "❔ undetermined",
}
"""How the baseline table shows a comparison's verdict."""


def _row(cells: list[str]) -> str:
    return "| " + " | ".join(markdown_text(c) for c in cells) + " |"


def _rule(left: int, right: int) -> str:
    return "| " + " | ".join(["---"] * left + ["---:"] * right) + " |"


def _table(view: ResultsView) -> list[str]:
    systems = any(view.estimate_systems)
    heads = ["Estimate", *(["System"] if systems else []), "Verdict"]
    figures = ["ATE RMSE (95 % CI)", "RPE RMSE (95 % CI)"]
    figures += [f"{label} (share of poses)" for label, _ in view.shares]
    lines = [_row(heads + figures), _rule(len(heads), len(figures))]
    for k, name in enumerate(view.estimate_names):
        cells = [
            name,
            *([view.estimate_systems[k] or "—"] if systems else []),
            STATUS_MARKS.get(view.verdicts[k].status, view.verdicts[k].badge),
            view.figure(1, "RMSE", k),
            view.figure(2, "RMSE", k),
            *(values[k] for _, values in view.shares),
        ]
        lines.append(_row(cells))
    return lines


def _systems(view: ResultsView) -> list[str]:
    found = view.trials
    if found is None:
        return []
    heads = ["System", "Figure", "Trials", "Median", "Mean", "Std", "95 % interval"]
    lines = ["### Systems over their trials", "", _row(heads), _rule(2, len(heads) - 2)]
    lines += [
        _row([r.system, r.metric, r.trials, r.median, r.mean, r.std, r.interval])
        for r in found.rows
    ]
    lines.append("")
    if found.failed:
        lines += ["Failed trials (counted, not averaged):", ""]
        lines += [
            f"- **{markdown_text(f.name)}** ({markdown_text(f.system)}): {markdown_text(f.reason)}"
            for f in found.failed
        ]
        lines.append("")
    if found.comparisons:
        lines += [f"- {markdown_text(c)}" for c in found.comparisons]
        lines.append("")
    return lines


def _baseline(view: ResultsView) -> list[str]:
    found = view.baseline
    if found is None:
        return []
    lines = ["### Against the baseline", "", f"Baseline: {markdown_text(found.source)}.", ""]
    if found.rows:
        heads = ["Estimate or system", "Figure", "Now", "Baseline", "Difference", "95 % interval"]
        lines += [_row([*heads, "Verdict"]), _rule(2, len(heads) - 2) + " --- |"]
        for r in found.rows:
            interval = r.interval if r.interval == "—" else f"{r.interval} ({r.how})"
            mark = BASELINE_MARKS.get(r.status, r.verdict)
            shown = mark if (r.name, r.metric) in view.judged else f"{mark} (a trial: not judged)"
            lines.append(_row([r.name, r.metric, r.now, r.baseline, r.difference, interval, shown]))
        lines.append("")
    if found.notes:
        lines += [f"- {markdown_text(n)}" for n in found.notes]
        lines.append("")
    return lines


def _gate(view: ResultsView) -> list[str]:
    gate = view.gate
    if gate is None:
        return []
    conditions = ", ".join(gate.fail_on)
    if gate.passed:
        return [f"**Gate: ✅ passed** (fails on {conditions})", ""]
    lines = [f"**Gate: ❌ closed** (fails on {conditions}):", ""]
    lines += [f"- {markdown_text(reason)}" for reason in gate.reasons]
    return [*lines, ""]


def summary_markdown(view: ResultsView) -> str:
    """Return ``summary.md`` of an evaluation's view model."""
    lines = [f"## {markdown_text(view.title)}", "", markdown_text(view.summary), ""]
    lines += _gate(view)
    if view.tolerance:
        lines += [f"Tolerance: {markdown_text(view.tolerance)}.", ""]
    lines += [*_table(view), ""]
    lines += ["### Verdicts", ""]
    lines += [  # a headline may name its estimate already ("ORB: undecided: ..."): once
        f"- **{markdown_text(v.name)}**: {markdown_text(v.headline.removeprefix(f'{v.name}: '))}"
        for v in view.verdicts
    ]
    lines.append("")
    lines += _systems(view)
    lines += _baseline(view)
    if view.confidence.comparisons:
        lines += ["### Comparisons of the estimates", ""]
        lines += [f"- {markdown_text(c)}" for c in view.confidence.comparisons]
        lines.append("")
    if view.confidence.note:
        lines += [markdown_text(view.confidence.note), ""]
    if view.warnings:
        lines += [f"<details><summary>Warnings ({len(view.warnings)})</summary>", ""]
        lines += [
            f"- **{markdown_text(about)}**: {markdown_text(text)}" for about, text in view.warnings
        ]
        lines += ["", "</details>", ""]
    lines.append(
        f"<sub>loceval evaluation {markdown_text(view.evaluation_id)}, "
        f"{markdown_text(view.created_at)}</sub>"
    )
    return "\n".join(lines) + "\n"


def export_summary_md(result: EvaluationResult, options: ExportOptions) -> bytes:
    """Return ``summary.md``: the results table, verdicts, comparisons and gate.

    Args:
        result: the evaluation.
        options: the title, the evaluation id and the gate's conditions (``fail_on``).
    """
    return summary_markdown(build_results_view(result, options)).encode()
