"""The HTML/PDF report: view model, content, plots and the PDF's pages."""

from __future__ import annotations

import base64
import io
import re
import xml.etree.ElementTree as ET
from html import unescape
from pathlib import Path

import numpy as np
import pytest

from exporters import ARTIFACTS
from exporters.errors import ExportError
from exporters.options import ExportOptions
from exporters.plots import (
    DEFAULT_MAX_POINTS,
    decimate_minmax,
    decimate_uniform,
    envelope,
    failing_span_markers,
    is_3d,
    plot_ate_over_time,
    render_plots,
)
from exporters.report import (
    BEST_MARK,
    DEFAULT_TEMPLATES_DIR,
    build_report_view,
    html_to_pdf,
    render_report,
    render_report_html,
    render_report_pdf,
    render_view_html,
)
from loceval.core.gaps import path_breaks
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.trajectory import Trajectory
from tests.exporters._html_tables import html_tables
from tests.exporters.conftest import noisy, walk

TITLE = "Lab run 1: RTAB-Map vs ISAAC"
INPUTS = (
    {
        "role": "reference",
        "path": "/data/run1/gt.tum",
        "file": "gt.tum",
        "format": "tum",
        "selector": None,
        "sha256": "a" * 64,
        "bytes": 123_456,
    },
    {
        "role": "estimate",
        "path": "/data/run1/rtab.bag",
        "file": "rtab.bag",
        "format": "bag",
        "selector": "tf:map:base_link",
        "sha256": "b" * 64,
        "bytes": 987_654_321,
    },
)


def _two_estimates(*, tolerance: Tolerance | None) -> EvaluationResult:
    """The conftest's ``two_estimates`` evaluation, rebuilt (module fixtures cannot use it)."""
    rng = np.random.default_rng(20240601)
    truth = walk(rng)
    a = noisy(rng, truth, every=3, sigma=0.02, drift=0.25, name="RTAB-Map")
    b = noisy(rng, truth, every=4, sigma=0.05, drift=0.05, name="ISAAC")
    return evaluate(truth, [a, b], EvaluationConfig(tolerance=tolerance), inputs=INPUTS)


@pytest.fixture(scope="module")
def result() -> EvaluationResult:
    """Return the two-estimate evaluation with a 0.10@95 tolerance and input provenance."""
    return _two_estimates(tolerance=Tolerance(0.10, 0.95))


@pytest.fixture(scope="module")
def rendered(result: EvaluationResult) -> tuple[str, bytes]:
    """Return the report as (HTML text, PDF bytes), rendered once for the module."""
    html, pdf = render_report(result, options=ExportOptions(title=TITLE, evaluation_id="ev-1"))
    return html.decode("utf-8"), pdf


def _stat_rows(table: list[list[str]]) -> dict[str, list[str]]:
    """Map ``"translation RMSE"`` etc. to the cells of a Table 1/2 body."""
    out: dict[str, list[str]] = {}
    group = "translation"
    for row in table[1:]:
        if len(row) == 1:
            group = row[0].lower()
        else:
            out[f"{group} {row[0]}"] = row[1:]
    return out


# --- view model -----------------------------------------------------------------------


def test_table_values_equal_the_statistics(two_estimates: EvaluationResult) -> None:
    """Tables 1 and 2 show each estimate's RMSE..MAX to 3 decimals, one column per estimate."""
    view = build_report_view(two_estimates, ExportOptions(), plots=())
    ate, rpe = view.tables
    assert (ate.number, ate.title) == (1, "Absolute Trajectory Error (ATE)")
    assert (rpe.number, rpe.title) == (2, "Relative Pose Error (RPE)")
    for table, attr in ((ate, "ate"), (rpe, "rpe")):
        groups = dict(table.groups)
        assert set(groups) == {"translation", "rotation"}
        for k, e in enumerate(two_estimates.estimates):
            t_stats = getattr(e, f"{attr}_translation").stats
            r_stats = getattr(e, f"{attr}_rotation").stats
            for row in groups["translation"]:
                assert row.cells[k].text == f"{getattr(t_stats, row.label.lower()):.3f} m"
            for row in groups["rotation"]:
                assert row.cells[k].text == f"{getattr(r_stats, row.label.lower()):.3f}°"
        assert [row.label for row in groups["translation"]] == [
            "RMSE",
            "MEAN",
            "MEDIAN",
            "STD",
            "MIN",
            "MAX",
        ]


def test_best_value_of_each_row_is_marked(two_estimates: EvaluationResult) -> None:
    """The lowest printed value of every row is marked best, ties alike, nothing else."""
    view = build_report_view(two_estimates, ExportOptions(), plots=())
    for table in view.tables:
        assert table.marks_best
        for _, rows in table.groups:
            for row in rows:
                values = [float(c.text.split()[0].rstrip("°")) for c in row.cells]
                assert [c.best for c in row.cells] == [v == min(values) for v in values]


def test_single_estimate_marks_no_best(rng: np.random.Generator) -> None:
    """With one estimate there is nothing to compare, so no value is marked."""
    truth = walk(rng, n=600)
    one = evaluate(truth, [noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="VIO")])
    view = build_report_view(one, ExportOptions(), plots=())
    assert not any(
        c.best for t in view.tables for _, rows in t.groups for r in rows for c in r.cells
    )
    html = render_view_html(view, templates_dir=DEFAULT_TEMPLATES_DIR).decode()
    assert "lowest (best) value" not in html


def test_failing_verdict_in_words(two_estimates: EvaluationResult) -> None:
    """A failed tolerance reads as a sentence with the share, the requirement and where it fails."""
    view = build_report_view(two_estimates, ExportOptions(), plots=())
    for k, (v, e) in enumerate(zip(view.verdicts, two_estimates.estimates, strict=True)):
        assert e.verdict is not None
        assert not e.verdict.passed
        assert (v.status, v.badge) == ("fail", "FAIL")
        assert v.headline.startswith(f"{e.name} does not meet the tolerance")
        assert f"{e.verdict.share_within * 100:.1f} %" in v.headline
        assert "95 % required" in v.headline
        assert v.spans_total == len(e.verdict.failing_spans)
        assert [s.number for s in v.spans] == list(range(1, min(5, v.spans_total) + 1))
        assert v.spans[0].max_error_m == f"{e.verdict.failing_spans[0].max_error_m:.3f}"
        assert f"Figure {2 + k}" not in " ".join(v.details)  # no plots rendered: no figure
    assert view.tolerance == "95 % of poses within 0.1 m"


def test_passing_verdict_in_words(rng: np.random.Generator) -> None:
    """A met tolerance says so, with a PASS badge and no failing stretches."""
    truth = walk(rng, n=1200)
    est = noisy(rng, truth, every=2, sigma=0.01, drift=0.0, name="UWB")
    res = evaluate(truth, [est], EvaluationConfig(tolerance=Tolerance(0.5, 0.95)))
    (v,) = build_report_view(res, ExportOptions(), plots=()).verdicts
    assert (v.status, v.badge) == ("pass", "PASS")
    assert v.headline.startswith("UWB meets the tolerance: 100.0 % of its poses")
    assert v.spans == ()
    assert "never exceeds 0.5 m" in v.details[0]


def test_failing_spans_use_the_reference_clock(two_estimates: EvaluationResult) -> None:
    """Span times are seconds since the reference's first pose, like every time in the report."""
    view = build_report_view(two_estimates, ExportOptions(), plots=())
    for v, e in zip(view.verdicts, two_estimates.estimates, strict=True):
        assert e.verdict is not None
        span = e.verdict.failing_spans[0]
        shift = (
            int(e.association.reference.stamps_ns[0]) - int(two_estimates.reference.stamps_ns[0])
        ) / 1e9
        assert v.spans[0].start_s == f"{span.start_s + shift:.2f}"


def test_no_tolerance_says_so_and_shows_shares(rng: np.random.Generator) -> None:
    """Without a tolerance the report says there is no verdict and shows the shares within."""
    truth = walk(rng, n=1200)
    est = noisy(rng, truth, every=2, sigma=0.03, drift=0.0, name="AMCL")
    res = evaluate(truth, [est])
    view = build_report_view(res, ExportOptions(), plots=())
    html = render_view_html(view, templates_dir=DEFAULT_TEMPLATES_DIR).decode()
    assert view.verdicts[0].status == "none"
    assert "No application tolerance was given" in html
    assert "--tolerance 0.10@95" in html
    shares = html_tables(html)["Share of poses within each distance of the ground truth (ATE)"]
    e = res.estimates[0]
    assert shares[1:] == [[f"≤ {t:g} m", f"{e.within[t] * 100:.1f} %"] for t in e.within]


def test_statistics_come_from_every_pose_not_the_plot(two_estimates: EvaluationResult) -> None:
    """Decimating the plots to a handful of points leaves the table values unchanged."""
    coarse = build_report_view(two_estimates, ExportOptions(), max_points=50)
    fine = build_report_view(two_estimates, ExportOptions(), plots=())
    assert coarse.tables == fine.tables
    assert len(coarse.figures) == 7


def test_names_are_escaped(rng: np.random.Generator) -> None:
    """Names and paths from the user are HTML-escaped (autoescape is on)."""
    truth = walk(rng, n=600)
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="<script>alert(1)</script>")
    res = evaluate(truth, [est], inputs=[{"role": "estimate", "path": "/x/<b>.csv"}])
    html = render_view_html(
        build_report_view(res, ExportOptions(title="A & B"), plots=()),
        templates_dir=DEFAULT_TEMPLATES_DIR,
    ).decode()
    assert "<script>alert" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert "<title>A &amp; B</title>" in html
    assert "&lt;b&gt;.csv" in html


def test_warnings_are_listed(rng: np.random.Generator) -> None:
    """Reference gaps and dropped estimate poses appear in the warnings table."""
    truth = walk(rng, n=3000)
    keep = np.ones(len(truth), dtype=bool)
    keep[1000:1100] = False  # 1 s of tracking loss
    gappy = truth.select(keep)
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="VIO")
    res = evaluate(gappy, [est])
    html = render_view_html(
        build_report_view(res, ExportOptions(), plots=()), templates_dir=DEFAULT_TEMPLATES_DIR
    ).decode()
    warnings = html_tables(html)["table" + str(len(html_tables(html)) - 1)]
    text = " ".join(" ".join(row) for row in warnings)
    assert "OptiTrack (reference)" in text
    assert "gaps longer than 100 ms" in text
    assert "fall in reference gaps" in text


# --- plots ------------------------------------------------------------------------------


def test_decimate_uniform_keeps_ends_and_caps_count() -> None:
    """Uniform decimation keeps the first and last sample and at most max_points."""
    idx = decimate_uniform(1_000_003, 5000)
    assert idx[0] == 0
    assert idx[-1] == 1_000_002
    assert len(idx) <= 5000
    assert np.all(np.diff(idx) > 0)
    assert np.array_equal(decimate_uniform(10, 5000), np.arange(10))


def test_decimate_minmax_keeps_every_peak(rng: np.random.Generator) -> None:
    """Min/max decimation keeps each bucket's extremes, so the global extremes survive."""
    values = rng.normal(size=200_001)
    values[123_457] = 50.0
    values[7] = -50.0
    idx = decimate_minmax(values, 1000)
    assert len(idx) <= 1000
    assert {0, 7, 123_457, 200_000} <= set(idx.tolist())
    assert np.all(np.diff(idx) > 0)


def test_envelope_breaks_at_gaps_and_bounds_values() -> None:
    """The band holds every value between its bucket bounds and breaks at time gaps."""
    stamps = np.concatenate([np.arange(1000), np.arange(2000, 3000)]).astype(np.int64) * 10**7
    values = np.sin(np.arange(2000) / 30.0)
    jump = path_breaks(stamps, min_gap_ns=100_000_000)
    t, lo, hi, mean = envelope(stamps / 1e9, values, jump, buckets=100)
    gap = np.flatnonzero(np.isnan(t))
    assert gap.size == 1
    assert t[gap[0] - 1] < 10.0
    assert t[gap[0] + 1] > 20.0
    ok = ~np.isnan(t)
    assert np.all(lo[ok] <= mean[ok])
    assert np.all(mean[ok] <= hi[ok])
    assert np.nanmax(hi) == values.max()
    assert np.nanmin(lo) == values.min()


def test_every_plot_is_rendered(two_estimates: EvaluationResult) -> None:
    """Overlay, one error-coloured path per estimate, ATE, RPE, CDF and side views (3D path)."""
    plots = render_plots(two_estimates, formats=("svg", "png"))
    assert [p.key for p in plots] == [
        "overlay_xy",
        "ate_path_0",
        "ate_path_1",
        "ate_time",
        "rpe_time",
        "error_cdf",
        "side_views",
    ]
    for p in plots:
        assert p.svg is not None
        assert p.png is not None
        root = ET.fromstring(p.svg)  # noqa: S314  (our own SVG, not untrusted input)
        assert root.tag == "{http://www.w3.org/2000/svg}svg"
        assert p.png.startswith(b"\x89PNG\r\n\x1a\n")
        assert p.data_uri("png").startswith("data:image/png;base64,")


def test_flat_path_has_no_side_views(rng: np.random.Generator) -> None:
    """A path at one height (a ground robot) gets no x-z / y-z views."""
    truth = walk(rng, n=800)
    flat = Trajectory(
        truth.stamps_ns,
        truth.positions_xyz * [1.0, 1.0, 0.0],
        truth.quat_xyzw,
        name="AMCL",
    )
    est = noisy(rng, flat, every=2, sigma=0.01, drift=0.0, name="UWB")
    res = evaluate(flat, [est])
    assert not is_3d(res)
    assert "side_views" not in [p.key for p in render_plots(res, formats=())]


def test_tracking_loss_is_shaded(rng: np.random.Generator) -> None:
    """The time plots carry a tracking-loss band (its legend entry) when the reference has gaps."""
    truth = walk(rng, n=3000)
    keep = np.ones(len(truth), dtype=bool)
    keep[1000:1100] = False
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="VIO")
    res = evaluate(truth.select(keep), [est])
    plot = plot_ate_over_time(res)
    assert plot.svg is not None
    # the figure kit writes each text as an SVG <text> element.
    assert b"tracking loss (reference gap)" in plot.svg
    assert "Grey bands are tracking loss of the reference" in plot.caption
    assert "A break in a line" in plot.caption
    plain = plot_ate_over_time(evaluate(truth, [est]))
    assert plain.svg is not None
    assert b"tracking loss" not in plain.svg
    assert "Grey bands" not in plain.caption


def test_failing_span_markers_follow_the_verdict(two_estimates: EvaluationResult) -> None:
    """The map's numbered markers sit at the worst failing stretches' largest errors, in order."""
    e = two_estimates.estimates[0]
    assert e.verdict is not None
    markers = failing_span_markers(e)
    assert [m[0] for m in markers] == [1, 2, 3, 4, 5]
    for (_, x, y), span in zip(markers, e.verdict.failing_spans, strict=False):
        assert (x, y) == span.max_error_position_xyz[:2]


def test_large_series_render_small(rng: np.random.Generator) -> None:
    """A 300,000-pose evaluation draws decimated plots: each SVG stays well under 1 MB."""
    truth = walk(rng, n=300_000, rate_hz=1000.0)
    est = noisy(rng, truth, every=3, sigma=0.02, drift=0.1, name="VIO")
    res = evaluate(truth, [est])
    for p in render_plots(res):
        assert p.svg is not None
        assert len(p.svg) < 700_000, p.key
    assert len(res.estimates[0].ate_translation) > DEFAULT_MAX_POINTS


# --- HTML -------------------------------------------------------------------------------


def test_html_is_self_contained(rendered: tuple[str, bytes]) -> None:
    """The HTML loads nothing: no scripts, links or non-data URLs; a CSP forbids the rest."""
    html, _ = rendered
    # the one exception (issue 24): the interactive viewer's inline scene and two scripts,
    # which load nothing (no src) and run only because the CSP names their hashes
    assert re.findall(r"<script[^>]*>", html) == [
        '<script type="application/json" id="loceval-viewer-scene">',
        "<script>",
        "<script>",
    ]
    assert re.search(r"script-src 'sha256-[^' ]+' 'sha256-[^' ]+'\"", unescape(html))
    assert "<link" not in html
    srcs = re.findall(r'(?:src|href)="([^"]*)"', html)
    assert srcs
    assert all(s.startswith(("data:", "#")) for s in srcs)
    assert "default-src 'none'" in html
    assert len(html.encode()) < 3_000_000


def test_html_header_names_inputs_and_options(
    rendered: tuple[str, bytes], result: EvaluationResult
) -> None:
    """The header shows title, time, version, files with SHA-256, selectors and the transform."""
    html, _ = rendered
    assert f"<h1>{TITLE}</h1>" in html
    assert result.created_at in html
    assert f"loceval {result.loceval_version}" in html
    tables = html_tables(html)
    files = tables["Input files"]
    assert files[1:] == [
        ["reference", "gt.tum", "tum", "", "123.5 kB"],
        ["", f"SHA-256 {'a' * 64}"],
        ["estimate", "rtab.bag", "bag", "tf:map:base_link", "987.7 MB"],
        ["", f"SHA-256 {'b' * 64}"],
    ]
    trajectories = tables["Trajectories"]
    ref = result.reference
    assert trajectories[1][:4] == ["OptiTrack", "reference", "gt.tum", f"{len(ref):,}"]
    assert f"{ref.length_m:.1f} m" in trajectories[1]
    options = {row[0]: row[1] for row in tables["Options"]}
    assert options["Alignment"] == "se3 (estimated on all poses)"
    assert options["Tolerance"] == "95 % of poses within 0.1 m"
    alignment = tables["Alignment onto the ground truth (the transform found)"]
    t = result.estimates[1].alignment.transform.translation
    assert alignment[3] == [  # to the millimetre: the one rule for coordinates
        "translation [m]",
        ", ".join(f"{v:.3f}" for v in result.estimates[0].alignment.transform.translation),
        ", ".join(f"{v:.3f}" for v in t),
    ]


def test_html_tables_equal_the_statistics(
    rendered: tuple[str, bytes], result: EvaluationResult
) -> None:
    """Table 1 and Table 2 in the HTML carry the result's numbers and the best marks."""
    html, _ = rendered
    tables = html_tables(html)
    ate = _stat_rows(tables["Table 1 Absolute Trajectory Error (ATE)"])
    rpe = _stat_rows(tables["Table 2 Relative Pose Error (RPE)"])
    for label in ("RMSE", "MEAN", "MEDIAN", "STD", "MIN", "MAX"):
        for rows, attr in ((ate, "ate"), (rpe, "rpe")):
            for k, e in enumerate(result.estimates):
                value = getattr(getattr(e, f"{attr}_translation").stats, label.lower())
                assert rows[f"translation {label}"][k].startswith(f"{value:.3f} m")
    # ISAAC has the lower ATE RMSE, RTAB-Map the lower RPE RMSE (the paper's finding, too).
    assert ate["translation RMSE"][1].endswith(BEST_MARK)
    assert not ate["translation RMSE"][0].endswith(BEST_MARK)
    assert rpe["translation RMSE"][0].endswith(BEST_MARK)
    assert not rpe["translation RMSE"][1].endswith(BEST_MARK)


def test_html_has_every_plot_inline(rendered: tuple[str, bytes]) -> None:
    """Every figure is an inline SVG data URI that parses, with its numbered caption."""
    html, _ = rendered
    figures = re.findall(
        r'<figure class="plot" id="figure-(\d+)" data-plot="([a-z_0-9]+)">\s*'
        r'<img src="data:image/svg\+xml;base64,([A-Za-z0-9+/=]+)"',
        html,
    )
    assert [key for _, key in [(n, k) for n, k, _ in figures]] == [
        "overlay_xy",
        "ate_path_0",
        "ate_path_1",
        "ate_time",
        "rpe_time",
        "error_cdf",
        "side_views",
        "clock_correlation",  # in the "Clocks and device offset" section, after the plots
    ]
    for number, (n, _, data) in enumerate(figures, start=1):
        assert int(n) == number
        assert f"Figure {number}</span>" in html
        root = ET.fromstring(base64.b64decode(data))  # noqa: S314  (our own SVG)
        assert root.tag == "{http://www.w3.org/2000/svg}svg"


def test_html_verdict_comes_first(rendered: tuple[str, bytes]) -> None:
    """The verdict is the first section, before the inputs, tables and plots."""
    html, _ = rendered
    order = [html.index(f'id="{s}"') for s in ("verdict", "evaluated", "statistics", "plots")]
    assert order == sorted(order)
    verdict = html[order[0] : order[1]]
    assert "RTAB-Map does not meet the tolerance" in verdict
    assert "ISAAC does not meet the tolerance" in verdict
    assert "numbered on its map (Figure 2)" in verdict
    assert "numbered on its map (Figure 3)" in verdict


def test_registry_points_at_these_exporters() -> None:
    """ARTIFACTS names the report functions with the exporter signature."""
    assert ARTIFACTS["report.html"].load() is render_report_html
    assert ARTIFACTS["report.pdf"].load() is render_report_pdf


def test_registry_html_exporter(two_estimates: EvaluationResult, tmp_path: Path) -> None:
    """render_report_html returns the UTF-8 report with the title and templates_dir honoured."""
    html = render_report_html(two_estimates, ExportOptions(title="Run 7")).decode()
    assert "<h1>Run 7</h1>" in html
    with pytest.raises(ExportError, match="No report template"):
        render_report_html(two_estimates, ExportOptions(templates_dir=tmp_path))


# --- PDF --------------------------------------------------------------------------------


def _pdf_pages(pdf: bytes) -> list[str]:
    pypdf = pytest.importorskip("pypdf")
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    return [" ".join(page.extract_text().split()) for page in reader.pages]


def test_pdf_pages_and_text(rendered: tuple[str, bytes], result: EvaluationResult) -> None:
    """The PDF is A4 with the verdict on page 1 and each section starting a new page."""
    pypdf = pytest.importorskip("pypdf")
    _, pdf = rendered
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    pages = _pdf_pages(pdf)
    assert 7 <= len(pages) <= 12
    for page in reader.pages:
        box = page.mediabox
        assert (round(float(box.width)), round(float(box.height))) == (595, 842)
    for n, text in enumerate(pages, start=1):
        assert f"page {n} of {len(pages)}" in text
    assert TITLE in pages[0]
    assert "Verdict" in pages[0]
    assert "RTAB-Map does not meet the tolerance" in pages[0]

    def first_page(needle: str) -> int:
        return next(n for n, text in enumerate(pages) if needle in text)

    evaluated = first_page("What was evaluated Trajectories")
    statistics = first_page("Table 1 Absolute Trajectory Error (ATE)")
    plots = first_page("Figure 1 Paths from above")
    worst = first_page("Greatest errors The largest")
    assert 0 < evaluated < statistics < plots < worst
    assert "Table 2 Relative Pose Error (RPE)" in pages[statistics]
    rmse = f"{result.estimates[1].ate_translation.stats.rmse:.3f} m"
    assert rmse in pages[statistics]
    for number in range(1, 8):
        assert any(f"Figure {number} " in text for text in pages)
    assert "Warnings" in pages[-1]


def test_pdf_embeds_every_plot(rendered: tuple[str, bytes]) -> None:
    """Each of the eight figures (seven plots and the clock check's) is drawn as vectors.

    Typst draws each figure's SVG into its page as paths (no raster image stands for a
    figure: the PDF of WeasyPrint had eight PNG images here); the page of each caption
    carries the drawing's path operators, hundreds per figure.
    """
    pypdf = pytest.importorskip("pypdf")
    _, pdf = rendered
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    captions: dict[int, int] = {}
    for n, text in enumerate(_pdf_pages(pdf)):
        for number in re.findall(r"Figure (\d+) ", text):
            captions.setdefault(int(number), n)
    assert sorted(captions) == list(range(1, 9))
    for page_number in set(captions.values()):
        figures = sum(1 for n in captions.values() if n == page_number)
        content = reader.pages[page_number].get_contents()
        assert content is not None
        paths = re.findall(rb"(?<=\s)[lc](?=\s)", content.get_data())
        assert len(paths) >= 200 * figures, (page_number, len(paths))


def test_pdf_tables_are_not_split(rendered: tuple[str, bytes]) -> None:
    """Table 1 and Table 2 each sit whole on one page (caption through MAX row)."""
    _, pdf = rendered
    pages = _pdf_pages(pdf)
    for caption in ("Table 1 Absolute", "Table 2 Relative"):
        (page,) = [text for text in pages if caption in text]
        tail = page[page.index(caption) :]
        assert tail.count("MAX") >= 2  # translation and rotation groups both there


@pytest.mark.pdf
def test_pdf_refuses_external_resources() -> None:
    """A non-data URL in the HTML stops the PDF instead of touching the network or disk."""
    for url in ("http://example.invalid/x.png", "file:///etc/hostname"):
        html = f'<!DOCTYPE html><html><body><img src="{url}"></body></html>'.encode()
        with pytest.raises(ExportError, match="not embedded"):
            html_to_pdf(html)
