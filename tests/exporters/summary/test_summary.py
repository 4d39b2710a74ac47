"""The scheduled summary report: data model, statistics, repeatability, HTML and PDF."""

from __future__ import annotations

import datetime as dt
import io
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from exporters.errors import ExportError
from exporters.report import DEFAULT_TEMPLATES_DIR
from exporters.summary import (
    SummaryInput,
    SummaryRun,
    SystemFigures,
    best_systems,
    build_summary_view,
    render_summary,
    render_summary_html,
    render_summary_pdf,
    render_summary_plots,
    repeatability,
    system_stats,
)
from loceval.core.polyline import PolylineIndex, path_distances, polyline_distances
from loceval.evaluation import EvaluationConfig, Tolerance, evaluate
from service.cli import main as cli_main
from tests.exporters._html_tables import html_tables
from tests.exporters.conftest import noisy, walk
from tests.factories import make_trajectory, perturb, write_tum

TEMPLATES = DEFAULT_TEMPLATES_DIR
MONDAY = dt.datetime(2026, 11, 16, 9, 0, tzinfo=dt.UTC)
GENERATED = dt.datetime(2026, 11, 23, 9, 12, tzinfo=dt.UTC)
SELECTION = "recordings tagged level-2 uploaded in the 7 days before 2026-11-23 07:00 UTC"
REASON = "The estimate bag has no /tf transform from map to base_link."


def _loop(n: int, *, offset_m: float = 0.0) -> np.ndarray:
    """The conftest walk's loop sampled at ``n`` parameter values, pushed ``offset_m`` sideways.

    The offset is along the path's normal in the x-y plane, so the offset path runs at
    exactly ``offset_m`` from the original (its curvature radius is over 0.5 m).
    """
    s = np.linspace(0.0, 2 * np.pi, n)
    x = 4.0 * np.cos(s) + 1.5 * np.cos(3 * s)
    y = 3.0 * np.sin(s)
    z = 1.3 + 0.1 * np.sin(5 * s)
    dx = -4.0 * np.sin(s) - 4.5 * np.sin(3 * s)
    dy = 3.0 * np.cos(s)
    norm = np.hypot(dx, dy)
    return np.stack([x + offset_m * dy / norm, y - offset_m * dx / norm, z], axis=1)


def _run(
    k: int,
    systems: dict[str, SystemFigures],
    *,
    xyz: np.ndarray | None = None,
    duration_s: float | None = 60.0,
) -> SummaryRun:
    return SummaryRun(
        dataset=f"level2-walk-{k:02d}",
        recorded_at=MONDAY + dt.timedelta(hours=13 * k),
        status="succeeded",
        evaluation_id=f"ev-{k:04d}",
        systems=systems,
        reference_xyz=xyz,
        duration_s=duration_s,
    )


def _failed(k: int, reason: str = REASON) -> SummaryRun:
    return SummaryRun(
        dataset=f"level2-walk-{k:02d}",
        recorded_at=MONDAY + dt.timedelta(hours=13 * k),
        status="failed",
        error=reason,
    )


def _week_runs(rng: np.random.Generator, count: int = 8) -> list[SummaryRun]:
    """Runs of two systems with random figures, paths re-driven with a few cm of offset."""
    runs: list[SummaryRun] = []
    for k in range(count):
        if k == 3:
            runs.append(_failed(k))
            continue
        figures = {
            name: SystemFigures(
                ate_rmse_m=float(rng.uniform(0.02, 0.12)),
                rpe_rmse_m=float(rng.uniform(0.002, 0.03)),
                matched=int(rng.integers(500, 3000)),
                verdict="pass" if rng.uniform() < 0.7 else "fail",
            )
            for name in ("RTAB-Map", "ISAAC")
        }
        xyz = _loop(int(rng.integers(800, 3000)), offset_m=float(rng.uniform(0.0, 0.05)))
        runs.append(_run(k, figures, xyz=xyz, duration_s=float(rng.uniform(55.0, 65.0))))
    rng.shuffle(runs)  # the report sorts them by date
    return runs


def _summary(runs: list[SummaryRun], **kwargs: object) -> SummaryInput:
    values: dict[str, object] = {
        "title": "Weekly site report: Level 2",
        "generated_at": GENERATED,
        "selection": SELECTION,
        "runs": runs,
        "tolerance": Tolerance(0.10, 0.95),
        "notes": ("The service was down at 07:00; this run started at 09:12.",),
        "schedule_id": "sch-42",
        "run_id": "run-7",
    }
    values.update(kwargs)
    return SummaryInput(**values)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def week() -> SummaryInput:
    """Return a week of runs: two systems, one failed run (module fixtures cannot use rng)."""
    return _summary(_week_runs(np.random.default_rng(20240601)))


@pytest.fixture(scope="module")
def rendered(week: SummaryInput) -> tuple[str, bytes]:
    """Return the week's summary as (HTML text, PDF bytes), rendered once for the module."""
    html, pdf = render_summary(week, templates_dir=TEMPLATES)
    return html.decode("utf-8"), pdf


def _pdf_text(pdf: bytes) -> str:
    pypdf = pytest.importorskip("pypdf")
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    return " ".join(" ".join((page.extract_text() or "").split()) for page in reader.pages)


# --- input --------------------------------------------------------------------------------


def test_from_result_reads_the_cli_json(
    rng: np.random.Generator, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run from `loceval evaluate --json` carries names, RMSEs, verdicts and duration."""
    truth = make_trajectory(rng, n=1500, name="truth")
    gt = write_tum(tmp_path / "gt.txt", truth)
    good = write_tum(tmp_path / "good.txt", perturb(truth, rng, sigma_m=0.01))
    bad = write_tum(tmp_path / "bad.txt", perturb(truth, rng, sigma_m=0.2))
    code = cli_main(["evaluate", str(gt), str(good), str(bad), "--json", "--tolerance", "0.10@95"])
    assert code == 0
    document = json.loads(capsys.readouterr().out)
    run = SummaryRun.from_result(
        document, dataset="lab-1", recorded_at=MONDAY, evaluation_id="ev-1"
    )
    assert run.status == "succeeded"
    assert run.dataset == "lab-1"
    assert run.evaluation_id == "ev-1"
    assert run.duration_s == pytest.approx(document["reference"]["duration_s"])
    assert list(run.systems) == [e["name"] for e in document["estimates"]]
    for e in document["estimates"]:
        figures = run.systems[e["name"]]
        assert figures.ate_rmse_m == e["ate"]["translation_m"]["rmse"]
        assert figures.rpe_rmse_m == e["rpe"]["translation_m"]["rmse"]
        assert figures.matched == e["matched"]
        assert figures.verdict == ("pass" if e["verdict"]["passed"] else "fail")
    assert [f.verdict for f in run.systems.values()] == ["pass", "fail"]


def test_from_result_reads_to_dict_without_tolerance(rng: np.random.Generator) -> None:
    """An in-memory result's to_dict() works too; no tolerance means no verdict."""
    truth = walk(rng, n=1200)
    estimate = noisy(rng, truth, every=3, sigma=0.02, drift=0.1, name="RTAB-Map")
    result = evaluate(truth, [estimate], EvaluationConfig())
    xyz = truth.positions_xyz
    run = SummaryRun.from_result(
        result.to_dict(), dataset="walk", recorded_at=MONDAY, reference_xyz=xyz
    )
    figures = run.systems["RTAB-Map"]
    assert figures.ate_rmse_m == pytest.approx(result.estimates[0].ate_translation.stats.rmse)
    assert figures.rpe_rmse_m == pytest.approx(result.estimates[0].rpe_translation.stats.rmse)
    assert figures.verdict is None
    assert run.reference_xyz is not None
    np.testing.assert_array_equal(run.reference_xyz, xyz)
    assert run.duration_s == pytest.approx(truth.duration_s)


def test_from_result_names_unnamed_and_repeated_estimates() -> None:
    """Missing names become `estimate k`; a repeated name gets a suffix; NaN becomes None."""
    estimate = {"matched": 10, "ate": {"translation_m": {"rmse": 0.1}}, "verdict": None}
    document = {
        "reference": {"duration_s": 12.5},
        "estimates": [
            {**estimate, "name": ""},
            {**estimate, "name": "A"},
            {**estimate, "name": "A", "rpe": {"translation_m": {"rmse": math.nan}}},
        ],
    }
    run = SummaryRun.from_result(document, dataset="d", recorded_at=MONDAY)
    assert list(run.systems) == ["estimate 1", "A", "A (2)"]
    assert run.systems["A (2)"].rpe_rmse_m is None
    assert run.systems["A"].ate_rmse_m == 0.1
    with pytest.raises(ValueError, match="estimates"):
        SummaryRun.from_result({"reference": {}}, dataset="d", recorded_at=MONDAY)


def test_dates_must_be_aware_and_are_kept_in_utc() -> None:
    """A naive date is refused; another zone is converted to UTC."""
    with pytest.raises(ValueError, match="timezone-aware"):
        SummaryRun(dataset="d", recorded_at=dt.datetime(2026, 11, 16, 9, 0), status="failed")  # noqa: DTZ001
    cet = dt.timezone(dt.timedelta(hours=1))
    run = SummaryRun(
        dataset="d", recorded_at=dt.datetime(2026, 11, 16, 10, 0, tzinfo=cet), status="failed"
    )
    assert run.recorded_at == MONDAY
    assert run.recorded_at.tzinfo == dt.UTC
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        SummaryRun(dataset="d", recorded_at=MONDAY, status="failed", reference_xyz=np.zeros(3))


def test_trend_draws_the_tolerance_distance_it_is_given(rng: np.random.Generator) -> None:
    """The dashed line is the Tolerance's distance, a value (not read back from words)."""
    runs = _week_runs(rng)
    trend = render_summary_plots(_summary(runs, tolerance=Tolerance(0.05, 0.99)))[0]
    assert trend.key == "trend"
    assert "The dashed line is the tolerance distance (0.05 m)" in trend.caption
    plain = render_summary_plots(_summary(runs, tolerance=None))[0]
    assert "dashed line" not in plain.caption


# --- statistics ---------------------------------------------------------------------------


def test_system_stats_match_numpy(rng: np.random.Generator) -> None:
    """Runs count, mean, std, min, max and pass rate equal numpy's over the succeeded runs."""
    runs = _week_runs(rng, count=10)
    stats = {s.name: s for s in system_stats(runs)}
    assert set(stats) == {"RTAB-Map", "ISAAC"}
    done = [r for r in runs if r.status == "succeeded"]
    for name, s in stats.items():
        ate = np.array([r.systems[name].ate_rmse_m for r in done])
        rpe = np.array([r.systems[name].rpe_rmse_m for r in done])
        passed = sum(r.systems[name].verdict == "pass" for r in done)
        assert s.runs == len(done) == 9
        assert s.ate_mean == pytest.approx(ate.mean())
        assert s.ate_std == pytest.approx(ate.std())
        assert min(s.ate_rmse_m) == ate.min()
        assert max(s.ate_rmse_m) == ate.max()
        assert s.rpe_mean == pytest.approx(rpe.mean())
        assert s.rpe_std == pytest.approx(rpe.std())
        assert s.pass_rate == pytest.approx(passed / len(done))
    view = build_summary_view(_summary(runs))
    for row in view.stats:
        s = stats[row.name]
        assert row.ate_mean == f"{s.ate_mean:.3f}"
        assert row.ate_std == f"{s.ate_std:.3f}"
        assert row.ate_min == f"{min(s.ate_rmse_m):.3f}"
        assert row.rpe_max == f"{max(s.rpe_rmse_m):.3f}"
        assert row.runs == "9"


def test_best_system_is_marked_and_stated() -> None:
    """The lowest mean ATE RMSE is marked in the table and named in one sentence."""
    runs = [
        _run(k, {"A": SystemFigures(a, 0.01, 100, None), "B": SystemFigures(b, 0.01, 100, None)})
        for k, (a, b) in enumerate([(0.05, 0.04), (0.06, 0.03), (0.07, 0.05)])
    ]
    assert best_systems(system_stats(runs)) == ["B"]
    view = build_summary_view(_summary(runs, tolerance=None))
    assert [row.best for row in view.stats] == [False, True]
    b = np.array([0.04, 0.03, 0.05])
    assert view.best_sentence == (
        f"B had the lowest mean ATE RMSE over 3 runs: {b.mean():.3f} m (std {b.std():.3f} m)."
    )
    html = render_summary_html(_summary(runs, tolerance=None), templates_dir=TEMPLATES).decode()
    assert view.best_sentence in html
    stats_rows = html_tables(html, key="class")["data stats summary-stats"]
    assert stats_rows[-1][2].startswith(f"{b.mean():.3f}")
    assert "★" in stats_rows[-1][2]
    assert "★" not in stats_rows[-2][2]


def test_systems_not_in_every_run_are_counted_apart() -> None:
    """A system missing from a run counts fewer runs; its cells say it was not evaluated."""
    runs = [
        _run(0, {"A": SystemFigures(0.05, 0.01, 100, "pass")}),
        _run(
            1,
            {
                "A": SystemFigures(0.07, 0.01, 100, "fail"),
                "B": SystemFigures(0.02, 0.01, 9, "pass"),
            },
        ),
    ]
    stats = {s.name: s for s in system_stats(runs)}
    assert (stats["A"].runs, stats["B"].runs) == (2, 1)
    assert stats["A"].pass_rate == pytest.approx(0.5)
    view = build_summary_view(_summary(runs))
    assert view.runs[0].cells[1].status == "missing"
    assert any("not evaluated on the same runs" in note for note in view.stats_notes)


# --- repeatability ------------------------------------------------------------------------


def test_repeatability_of_a_path_shifted_sideways() -> None:
    """The same path 5 cm to the side is 5 cm away everywhere: median and max both 0.05."""
    runs = [
        _run(0, {}, xyz=_loop(3000)),
        _run(1, {}, xyz=_loop(2000, offset_m=0.05)),
    ]
    rows = repeatability(runs)
    assert [r.baseline for r in rows] == [True, False]
    assert rows[0].median_m is None
    assert rows[1].median_m == pytest.approx(0.05, abs=1e-3)
    assert rows[1].max_m == pytest.approx(0.05, abs=1e-3)
    assert rows[1].points == 2000


def test_repeatability_of_a_path_redriven_with_other_sampling() -> None:
    """The same path sampled at other instants, slower, another day: about zero distance."""
    s = np.sort(np.random.default_rng(7).uniform(0.0, 1.0, 1777))  # irregular stamps
    x = 4.0 * np.cos(2 * np.pi * s) + 1.5 * np.cos(6 * np.pi * s)
    y = 3.0 * np.sin(2 * np.pi * s)
    z = 1.3 + 0.1 * np.sin(10 * np.pi * s)
    runs = [
        _run(0, {}, xyz=_loop(6000), duration_s=60.0),
        _run(5, {}, xyz=np.stack([x, y, z], axis=1), duration_s=66.5),
    ]
    second = repeatability(runs)[1]
    assert second.median_m is not None
    assert second.max_m is not None
    assert second.median_m < 1e-3
    assert second.max_m < 2e-3
    assert second.duration_diff_s == pytest.approx(6.5)


def test_repeatability_takes_the_first_run_by_date_as_baseline(rng: np.random.Generator) -> None:
    """Runs are ordered by date; runs without a path are left out; durations are differenced."""
    runs = [
        _run(2, {}, xyz=_loop(900, offset_m=0.02), duration_s=61.0),
        _run(1, {}, xyz=None),
        _run(0, {}, xyz=_loop(1000), duration_s=60.0),
        _failed(3),
        _run(4, {}, xyz=_loop(1100, offset_m=0.03), duration_s=None),
    ]
    rng.shuffle(runs)
    rows = repeatability(runs)
    assert [r.dataset for r in rows] == ["level2-walk-00", "level2-walk-02", "level2-walk-04"]
    assert rows[0].baseline
    assert rows[1].duration_diff_s == pytest.approx(1.0)
    assert rows[2].duration_diff_s is None
    assert rows[1].median_m == pytest.approx(0.02, abs=1e-3)
    assert rows[2].max_m == pytest.approx(0.03, abs=1e-3)
    assert repeatability([_failed(0)]) == []


def test_path_distances_match_brute_force(rng: np.random.Generator) -> None:
    """The KD-tree distances equal exact point-to-segment distances within 1 mm, never below."""
    truth = make_trajectory(rng, n=3000)
    vertices = truth.positions_xyz
    near = perturb(truth, rng, sigma_m=0.05).positions_xyz[::3]
    far = rng.uniform(-10.0, 10.0, (500, 3))
    points = np.vstack([near, far, vertices[::7]])
    fast = path_distances(points, vertices)
    exact = polyline_distances(points, vertices)
    assert np.all(fast >= exact - 1e-12)
    assert np.max(fast - exact) < 1e-3
    assert np.max(fast[-len(vertices[::7]) :]) < 1e-9  # the polyline's own vertices
    single = PolylineIndex.build(vertices[:1]).distances(points[:5])
    np.testing.assert_allclose(single, np.linalg.norm(points[:5] - vertices[0], axis=1))


def test_path_distances_on_long_paths(rng: np.random.Generator) -> None:
    """50,000 shuffled points against a 50,000-vertex path: each one's distance is found."""
    base = _loop(50_000)
    redriven = _loop(50_000, offset_m=0.03)[rng.permutation(50_000)]
    distances = path_distances(redriven, base)  # how fast: benchmarks/polyline.py
    assert np.median(distances) == pytest.approx(0.03, abs=1e-3)


# --- HTML -------------------------------------------------------------------------------


def test_table_values_equal_the_inputs(week: SummaryInput, rendered: tuple[str, bytes]) -> None:
    """Every run's row shows its date, dataset and each system's RMSEs and verdict."""
    html, _ = rendered
    rows = html_tables(html, key="class")["data summary-runs"][2:]
    runs = sorted(week.runs, key=lambda r: r.recorded_at)
    assert len(rows) == len(runs)
    for row, run in zip(rows, runs, strict=True):
        assert row[0] == run.recorded_at.strftime("%Y-%m-%d %H:%M")
        assert row[1].startswith(run.dataset)
        if run.status == "failed":
            assert row[2] == f"FAILED {run.error}"
            continue
        cells = row[2:]
        for k, name in enumerate(("RTAB-Map", "ISAAC")):
            figures = run.systems[name]
            assert cells[3 * k] == f"{figures.ate_rmse_m:.3f}"
            assert cells[3 * k + 1] == f"{figures.rpe_rmse_m:.3f}"
            assert cells[3 * k + 2] == str(figures.verdict).upper()


def test_no_tolerance_shows_a_dash_for_the_verdict() -> None:
    """Without a verdict the cell shows a dash, and the header says there is no tolerance."""
    runs = [_run(0, {"A": SystemFigures(0.04, 0.01, 100, None)})]
    html = render_summary_html(_summary(runs, tolerance=None), templates_dir=TEMPLATES).decode()
    row = html_tables(html, key="class")["data summary-runs"][2]
    assert row[2:] == ["0.040", "0.010", "—"]
    assert "none given" in html


def test_failed_runs_are_listed_with_their_reasons(rendered: tuple[str, bytes]) -> None:
    """A failed run is listed in the header and its row with its reason; the rest are reported."""
    html, pdf = rendered
    assert "1 of the recordings could not be evaluated" in html
    assert html.count(REASON) == 2  # the header list and the table row
    assert "7 evaluated, 1 failed" in html
    assert "Systems side by side" in html
    assert REASON in _pdf_text(pdf)


def test_all_runs_failed_shows_only_the_reasons() -> None:
    """When every run failed the report lists them and draws no empty figures or tables."""
    summary = _summary([_failed(0), _failed(1, "The reference file is empty.")])
    view = build_summary_view(summary)
    assert not view.any_succeeded
    assert view.figures == ()
    html = render_summary_html(summary, templates_dir=TEMPLATES).decode()
    assert "The reference file is empty." in html
    assert "Systems side by side" not in html
    assert "<img" not in html


def test_html_is_self_contained(rendered: tuple[str, bytes]) -> None:
    """No external URL: plots are data: URIs and there are no links, scripts or stylesheets."""
    html, _ = rendered
    assert not re.search(r"(?:https?:)?//[a-z0-9.-]+\.[a-z]{2,}", html, re.IGNORECASE)
    assert "<script" not in html
    assert "<link" not in html
    sources = re.findall(r'src="([^"]*)"', html)
    assert len(sources) == 2  # the trend and the paths from above
    assert all(src.startswith("data:image/svg+xml;base64,") for src in sources)


def test_html_shows_header_trend_and_repeatability(
    week: SummaryInput, rendered: tuple[str, bytes]
) -> None:
    """Header facts, the trend figure and the repeatability table with its caption are there."""
    html, _ = rendered
    for text in (week.title, SELECTION, "95 % of poses within 0.1 m", "sch-42", "run-7",
                 "2026-11-23 09:12 UTC", "The service was down at 07:00"):  # fmt: skip
        assert text in html
    assert 'data-plot="trend"' in html
    assert 'data-plot="paths_xy"' in html
    rows = html_tables(html, key="class")["data summary-repeatability"][2:]
    expected = repeatability(week.runs)
    assert len(rows) == len(expected) == 7
    assert rows[0][3] == "baseline (the first run)"
    for row, r in zip(rows[1:], expected[1:], strict=True):
        assert row[3] == f"{r.median_m:.3f}"
        assert row[4] == f"{r.max_m:.3f}"
        assert row[6] == f"{r.duration_diff_s:+.1f}"
    assert "not by time" in html


def test_names_are_escaped() -> None:
    """Dataset names and reasons are text, never markup."""
    run = SummaryRun(
        dataset="<b>lab</b>", recorded_at=MONDAY, status="failed", error="<script>x</script>"
    )
    html = render_summary_html(_summary([run]), templates_dir=TEMPLATES).decode()
    assert "<b>lab</b>" not in html
    assert "&lt;b&gt;lab&lt;/b&gt;" in html
    assert "<script>x" not in html


def test_many_runs_render(rng: np.random.Generator) -> None:
    """Sixty runs give sixty rows and one trend figure."""
    runs = [
        _run(k, {"A": SystemFigures(float(rng.uniform(0.02, 0.08)), 0.01, 100, "pass")})
        for k in range(60)
    ]
    view = build_summary_view(_summary(runs))
    assert len(view.runs) == 60
    assert [f.key for f in view.figures] == ["trend"]
    assert view.runs_count == "60"


def test_missing_template_is_an_export_error(tmp_path: Path) -> None:
    """A templates folder without summary.html.j2 is refused with a clear error."""
    with pytest.raises(ExportError, match=r"summary\.html\.j2"):
        render_summary_html(_summary([]), templates_dir=tmp_path)


# --- empty, one run and PDF ---------------------------------------------------------------


def test_empty_selection_says_so_in_html_and_pdf() -> None:
    """No runs: one clear sentence, no tables or figures, in the HTML and in the PDF."""
    summary = _summary([])
    html, pdf = render_summary(summary, templates_dir=TEMPLATES)
    text = html.decode()
    sentence = f"No recordings matched the selection ({SELECTION})."
    assert sentence in text
    assert "<table" not in text
    assert "<img" not in text
    assert "No recordings matched the selection" in _pdf_text(pdf)


def test_pdf_has_the_run_dates_and_dataset_names(
    week: SummaryInput, rendered: tuple[str, bytes]
) -> None:
    """The PDF is readable and names every run's date and dataset."""
    _, pdf = rendered
    assert pdf.startswith(b"%PDF")
    text = _pdf_text(pdf)
    for run in week.runs:
        assert run.recorded_at.strftime("%Y-%m-%d %H:%M") in text
        assert run.dataset in text
    assert "Repeatability of the path" in text
    assert "RTAB-Map" in text


def test_one_run_renders_html_and_pdf() -> None:
    """A single run is a single point in the trend; the report says there is no re-drive yet."""
    runs = [_run(0, {"A": SystemFigures(0.04, 0.01, 100, "pass")}, xyz=_loop(500))]
    summary = _summary(runs)
    html = render_summary_html(summary, templates_dir=TEMPLATES).decode()
    assert 'data-plot="trend"' in html
    assert "no re-drive to compare" in html
    assert "A had a mean ATE RMSE of 0.040 m (std 0.000 m) over 1 run." in html
    text = _pdf_text(render_summary_pdf(summary, templates_dir=TEMPLATES))
    assert "2026-11-16 09:00" in text
    assert "level2-walk-00" in text
