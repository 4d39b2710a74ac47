"""``loceval res ZIP...``: evo_res's table over result zips of evo and loceval, with intervals.

Each zip gives a row of the seven statistics (evo_res's columns and names). Where two zips
hold their error series with stamps (evo's ``error_array`` and ``timestamps``, loceval's
too), the RMSEs are compared with loceval's paired block bootstrap
(:func:`loceval.assessment.comparison.compare_errors`) on the stamps both share: B's stamps are
matched to A's nearest within 10 ms (evo's default), so two systems evaluated over the same
run pair their errors instant by instant. ``--out DIR`` writes ``comparison.html`` and
``comparison.json``.
"""

from __future__ import annotations

import html
import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from loceval.errors import InputError, LocevalError
from service.cli.evo.results import ResultZip, read_result_zip
from service.cli.output import emit

if TYPE_CHECKING:
    import argparse

    from loceval.assessment.comparison import Comparison

__all__ = ["Row", "format_table", "run_res"]

COLUMNS = ("rmse", "mean", "median", "std", "min", "max", "sse")
"""evo_res's columns, in its order."""

_PAIR_DT_S = 0.01


@dataclass(frozen=True, slots=True)
class Row:
    """One result: its label and zip."""

    label: str
    result: ResultZip


def _labels(results: list[ResultZip], *, use_filenames: bool) -> tuple[list[str], list[str]]:
    """Return each result's label (its estimate's name, as evo_res) and notes."""
    names = [str(r.info.get("est_name", r.path.name)) for r in results]
    if use_filenames:
        return [str(r.path) for r in results], []
    if len(set(names)) == len(names):
        return names, []
    note = (
        "Two results name the same estimate; they are labelled by their file names "
        "(evo_res needs --use_filenames here)."
    )
    return [str(r.path) for r in results], [note]


def _number(value: float) -> str:
    return f"{value:.6f}" if abs(value) >= 1e-4 or value == 0 else f"{value:.6g}"


def format_table(rows: list[Row]) -> str:
    """Return the title and evo_res's table: a row per result, its seven statistics."""
    title = rows[0].result.info.get("title", "")
    width = max(len(r.label) for r in rows)
    header = " " * width + "".join(f"{c:>12}" for c in COLUMNS)
    lines = ["", str(title), "", header]
    for row in rows:
        cells = "".join(f"{_number(row.result.stats.get(c, float('nan'))):>12}" for c in COLUMNS)
        lines.append(f"{row.label:<{width}}{cells}")
    return "\n".join(lines)


def _paired(a: Row, b: Row) -> Comparison | str:
    """Compare two results' RMSE on their shared instants, or say why not."""
    from loceval.assessment.comparison import ComparedMetric, compare_errors_nearest  # noqa: PLC0415  (scipy)

    series_a, series_b = a.result.error_series(), b.result.error_series()
    if series_a is None or series_b is None:
        return "a zip holds no error series with stamps"
    if a.result.title != b.result.title:
        return "the two results measure different things"
    metric = ComparedMetric.RPE_RMSE if "RPE" in a.result.title else ComparedMetric.ATE_RMSE
    try:
        return compare_errors_nearest(
            *series_a, *series_b, a=a.label, b=b.label, metric=metric, unit=a.result.unit,
            max_dt_s=_PAIR_DT_S,
        )  # fmt: skip
    except LocevalError as err:
        return str(err)


def run_res(args: argparse.Namespace) -> int:
    """Read the zips, print the table and the paired intervals, write the report."""
    results = [read_result_zip(Path(p)) for p in args.result_files]
    labels, notes = _labels(results, use_filenames=args.use_filenames)
    rows = [Row(label, result) for label, result in zip(labels, results, strict=True)]
    titles = {r.result.title for r in rows}
    if len(titles) > 1:
        notes.append(f"The results measure different things: {', '.join(sorted(titles))}.")
    emit(format_table(rows))
    compared: list[tuple[Row, Row, Comparison | str]] = [
        (a, b, _paired(a, b)) for i, a in enumerate(rows) for b in rows[i + 1 :]
    ]
    if compared:
        emit("\nPaired 95 % intervals of the RMSE difference (loceval, block bootstrap):")
        for a, b, found in compared:
            text = found if isinstance(found, str) else found.summary
            emit(f"  {a.label} vs {b.label}: {text}")
    for note in notes:
        emit(f"Note: {note}")
    if args.out is not None:
        path = _write_report(rows, compared, notes, Path(args.out))
        emit(f"\nComparison report written to {path}")
    return 0


def _document(
    rows: list[Row], compared: list[tuple[Row, Row, Comparison | str]], notes: list[str]
) -> dict[str, object]:
    return {
        "results": [
            {
                "label": row.label,
                "file": str(row.result.path),
                "title": row.result.info.get("title", ""),
                "written_by": "loceval" if row.result.loceval else "evo",
                "stats": {c: row.result.stats.get(c) for c in COLUMNS},
                "n": None
                if "error_array" not in row.result.arrays
                else int(row.result.arrays["error_array"].size),
            }
            for row in rows
        ],
        "comparisons": [
            {
                "a": a.label,
                "b": b.label,
                **({"unavailable": found} if isinstance(found, str) else found.to_dict()),
            }
            for a, b, found in compared
        ],
        "notes": notes,
    }


def _write_report(
    rows: list[Row], compared: list[tuple[Row, Row, Comparison | str]], notes: list[str], out: Path
) -> Path:
    """Write ``comparison.json`` and ``comparison.html`` into ``out``; return the HTML's path."""
    document = _document(rows, compared, notes)
    esc = html.escape
    head = "".join(f"<th>{c}</th>" for c in COLUMNS)
    body = "".join(
        f"<tr><th>{esc(row.label)}</th>"
        + "".join(f"<td>{_number(row.result.stats.get(c, float('nan')))}</td>" for c in COLUMNS)
        + f"<td>{'loceval' if row.result.loceval else 'evo'}</td></tr>"
        for row in rows
    )
    pairs = "".join(
        f"<li>{esc(a.label)} vs {esc(b.label)}: "
        f"{esc(found if isinstance(found, str) else found.summary)}</li>"
        for a, b, found in compared
    )
    title = esc(str(rows[0].result.info.get("title", "")).replace("\n", " "))
    page = (
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
        f"<title>Result comparison: {title}</title><style>body{{font-family:sans-serif;"
        "margin:2em}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:"
        ".3em .6em;text-align:right}th:first-child{text-align:left;overflow-wrap:anywhere}"
        f"</style></head><body><h1>Result comparison</h1><p>{title}</p>"
        f"<table><thead><tr><th>result</th>{head}<th>written by</th></tr></thead>"
        f"<tbody>{body}</tbody></table>"
        "<h2>Paired 95 % intervals of the RMSE difference</h2>"
        f"<ul>{pairs or '<li>one result: nothing to compare</li>'}</ul>"
        + "".join(f"<p class='note'>{esc(n)}</p>" for n in notes)
        + "</body></html>"
    )
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / "comparison.json").write_text(json.dumps(document, indent=1), encoding="utf-8")
        target = out / "comparison.html"
        target.write_text(page, encoding="utf-8")
    except OSError as err:
        msg = f"Cannot write the comparison into {str(out)!r} ({err.strerror}); name a folder."
        raise InputError(msg) from err
    return target
