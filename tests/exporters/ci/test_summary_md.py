"""``summary.md``: parsed as GitHub-flavoured Markdown, its tables read cell by cell."""

from __future__ import annotations

from dataclasses import replace

import pytest
from markdown_it import MarkdownIt
from markdown_it.token import Token

from exporters import ARTIFACTS, render_artifact
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult
from tests.verdict_factory import baseline_result, verdict_result


@pytest.fixture(scope="module")
def verdicts() -> EvaluationResult:
    """steady passes, lost fails, borderline is undecided (its own share required)."""
    return verdict_result()


def _tokens(text: str) -> list[Token]:
    """Parse as GitHub does: CommonMark with the GFM table rule."""
    return MarkdownIt("commonmark").enable("table").parse(text)


def _plain(inline: Token) -> str:
    """The text a reader sees in an inline token (escapes resolved, markup dropped)."""
    return "".join(c.content for c in inline.children or () if c.type in {"text", "code_inline"})


def tables(text: str) -> list[list[list[str]]]:
    """Every table of the document as rows of cell texts, the head row first."""
    found: list[list[list[str]]] = []
    row: list[str] | None = None
    for token in _tokens(text):
        if token.type == "table_open":
            found.append([])
        elif token.type == "tr_open":
            row = []
        elif token.type == "inline" and row is not None:
            row.append(_plain(token))
        elif token.type == "tr_close" and row is not None:
            found[-1].append(row)
            row = None
    return found


def headings(text: str) -> list[str]:
    """Every heading's text, in order."""
    tokens = _tokens(text)
    return [_plain(tokens[k + 1]) for k, t in enumerate(tokens) if t.type == "heading_open"]


def _summary(result: EvaluationResult, *fail_on: str) -> str:
    return render_artifact("summary.md", result, ExportOptions(fail_on=fail_on)).decode()


def test_the_artifact_is_registered() -> None:
    """summary.md is an artifact of every evaluation, served as Markdown."""
    assert ARTIFACTS["summary.md"].media_type == "text/markdown"


def test_the_results_table(verdicts: EvaluationResult) -> None:
    """A row per estimate: its verdict, ATE and RPE RMSE with intervals, the shares within."""
    text = _summary(verdicts)
    (table,) = tables(text)
    head, *rows = table
    assert head[:4] == ["Estimate", "Verdict", "ATE RMSE (95 % CI)", "RPE RMSE (95 % CI)"]
    assert head[4:] == [f"≤ {t:g} m (share of poses)" for t in verdicts.config.thresholds_m]
    assert [r[0] for r in rows] == ["steady", "lost", "borderline"]
    assert [r[1] for r in rows] == ["✅ PASS", "❌ FAIL", "⚠️ UNDECIDED"]
    for row, estimate in zip(rows, verdicts.estimates, strict=True):
        ate = estimate.ate_translation.stats.rmse
        assert row[2].startswith(f"{ate:.3f} m (") or row[2].startswith(f"{ate * 1000:.1f} mm (")
        within = [f"{estimate.within[t] * 100:.1f} %" for t in verdicts.config.thresholds_m]
        assert row[4:] == within
    assert headings(text)[:2] == [ExportOptions().title, "Verdicts"]


def test_the_gate_is_stated_with_its_reasons(verdicts: EvaluationResult) -> None:
    """With fail_on the summary says the gate closed and lists why, one item per reason."""
    text = _summary(verdicts, "fail", "undecided")
    tokens = _tokens(text)
    strong = [_plain(t) for t in tokens if t.type == "inline" and "Gate" in t.content]
    assert strong[0].startswith("Gate: ❌ closed")
    items = [
        _plain(tokens[k + 2])
        for k, t in enumerate(tokens)
        if t.type == "list_item_open" and tokens[k + 2].type == "inline"
    ]
    assert items[0].startswith("lost fails the tolerance (")
    assert items[1].startswith("borderline is undecided against the tolerance (")
    assert "Gate" not in _summary(verdicts)  # without conditions: no gate


def test_pipes_and_markup_in_names_stay_in_their_cell(verdicts: EvaluationResult) -> None:
    """A name with |, * and <b> is one cell that reads as written; no HTML comes through."""
    hostile = "ORB|SLAM *3* <b>x</b> [a](b)"
    first = verdicts.estimates[0]
    estimates = (replace(first, estimate=replace(first.estimate, name=hostile)),)
    text = _summary(replace(verdicts, estimates=estimates))
    (table,) = tables(text)
    assert [row[0] for row in table[1:]] == [hostile]
    assert all(len(row) == len(table[0]) for row in table)
    html = MarkdownIt("commonmark").enable("table").render(text)
    assert "<b>x</b>" not in html
    assert "<em>" not in html


def test_baseline_and_systems_tables() -> None:
    """The systems over their trials (with the failed trial) and a row per baseline comparison."""
    text = _summary(baseline_result(), "worse")
    results, systems, baseline = tables(text)
    assert [r[:2] for r in results[1:]] == [
        ["SLAM", "—"],
        ["VIO", "—"],
        ["UWB", "—"],
        ["orb-1", "ORB"],
        ["orb-2", "ORB"],
    ]
    assert systems[0] == [
        "System", "Figure", "Trials", "Median", "Mean", "Std", "95 % interval"
    ]  # fmt: skip
    assert [row[:3] for row in systems[1:3]] == [
        ["ORB", "ATE RMSE", "2 (1 failed)"],
        ["ORB", "RPE RMSE", "2 (1 failed)"],
    ]
    assert systems[1][6] == "too few trials"
    assert baseline[0] == [
        "Estimate or system", "Figure", "Now", "Baseline", "Difference", "95 % interval",
        "Verdict",
    ]  # fmt: skip
    verdicts = {(r[0], r[1]): r[6] for r in baseline[1:]}
    assert verdicts[("SLAM", "ATE RMSE")] == "❌ worse"
    assert verdicts[("VIO", "ATE RMSE")] == "✅ better"
    assert verdicts[("UWB", "ATE RMSE")] == "➖ within noise"
    assert verdicts[("ORB (system)", "ATE RMSE")] == "❔ undetermined"
    assert not any(name.startswith("orb-") for name, _ in verdicts)  # the system's, not a trial's
    slam = next(r for r in baseline[1:] if r[:2] == ["SLAM", "ATE RMSE"])
    assert slam[4].startswith("+")
    assert slam[5].endswith("(unpaired)")  # the factory keeps no errors.csv: unpaired
    assert "Against the baseline" in headings(text)
    assert "Baseline: release-1.4 (a loceval result)." in text
    assert "Systems over their trials" in headings(text)
    assert "orb-3" in text  # the failed trial is named, not dropped


def test_a_verdict_names_its_estimate_once(verdicts: EvaluationResult) -> None:
    """The list item is "**name**: undecided: ...", not "**name**: name: undecided: ..."."""
    text = _summary(verdicts)
    for name in ("steady", "lost", "borderline"):
        assert f"**{name}**: {name}: " not in text
        assert f"**{name}**: " in text
