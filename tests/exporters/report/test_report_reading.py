"""The report as a site engineer reads it: text taken from the PDF with pdftotext (issue 30).

Each test renders a report and reads the PDF's text the way a person reads the page:
one unit per figure and its interval, names that break only at their separators, no
heading alone at a page's foot, the tolerance asked for the way the report's front door
takes it, and information (a tf chain) told apart from warnings.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from exporters.options import ExportOptions, FrontDoor
from exporters.report import build_report_view, render_report, render_view_html, render_view_pdf
from exporters.report.render import DEFAULT_TEMPLATES_DIR
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.readers import parse_source, read_trajectory
from loceval.trajectory import Trajectory
from service.jobs.options import export_from_options
from service.schemas.evaluations import EvaluationOptions
from tests import bagfactory as bf
from tests.conftest import require_tool
from tests.exporters.conftest import noisy, walk

SEPARATORS = "_/@:."


def _pdf_text(pdf: bytes, tmp_path: Path, *, layout: bool = True) -> list[str]:
    """The PDF's pages as pdftotext reads them (one string per page)."""
    tool = require_tool("pdftotext")
    path = tmp_path / "report.pdf"
    path.write_bytes(pdf)
    args = [tool, *(["-layout"] if layout else []), str(path), "-"]
    text = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    return text.split("\f")


def _pdf(result: EvaluationResult, **options: object) -> bytes:
    view = build_report_view(result, ExportOptions(**options), plots=(), image_format="svg")  # type: ignore[arg-type]
    return render_view_pdf(view, templates_dir=DEFAULT_TEMPLATES_DIR)


def _precise(rng: np.random.Generator) -> EvaluationResult:
    """A millimetre-class estimate (Table 1 in mm) whose clock the motion can check."""
    truth = walk(rng, n=3000)
    est = noisy(rng, truth, every=3, sigma=0.003, drift=0.0, name="VIO")
    return evaluate(truth, [est])


# --- item 8: one unit per figure and interval ------------------------------------------


def test_interval_reads_in_the_unit_of_its_value(rng: np.random.Generator, tmp_path: Path) -> None:
    """``RMSE 3.0 mm (2.9–3.1)``: the interval in mm like the value, never metres after it."""
    result = _precise(rng)
    e = result.estimates[0]
    assert e.assessment is not None
    text = "\n".join(_pdf_text(_pdf(result), tmp_path))
    found = re.search(r"RMSE\s+(\d+\.\d) mm \((\d+\.\d)–(\d+\.\d)\)", text)
    assert found is not None, text[:3000]
    value, lo, hi = (float(g) for g in found.groups())
    assert value == pytest.approx(e.ate_translation.stats.rmse * 1e3, abs=0.05)
    ci_lo, ci_hi = e.assessment.intervals["ate_translation"].ci95["rmse"]
    assert (lo, hi) == (round(ci_lo * 1e3, 1), round(ci_hi * 1e3, 1))
    assert lo <= value <= hi


def test_clock_offsets_read_in_one_unit(rng: np.random.Generator, tmp_path: Path) -> None:
    """The offsets that fit read in ms like the estimated offset next to them."""
    result = _precise(rng)
    check = result.estimates[0].offsets
    assert check is not None
    assert check.time_offset is not None
    assert check.time_offset.candidates_s
    text = "\n".join(_pdf_text(_pdf(result), tmp_path))
    (line,) = [x for x in text.splitlines() if "Offsets that fit" in x]
    assert re.search(r"[+-]\d+\.\d\d ms", line), line
    assert not re.search(r"\d s\b", line), line


# --- item 9: names break at their separators or not at all ----------------------------


def _fragments_are_whole_parts(name: str, tokens: list[str]) -> list[str]:
    """Tokens that are a piece of ``name`` cut anywhere but at a separator."""
    bad = []
    for raw in tokens:
        token = raw.strip("()'\",")
        # A piece cut mid-word holds a separator on one side of the cut (its head);
        # words such as "ground" (from "ground truth") are not pieces of a name.
        if token == name or token not in name or not set(token) & set(SEPARATORS):
            continue
        start = name.index(token)
        end = start + len(token)
        starts_ok = start == 0 or name[start - 1] in SEPARATORS
        ends_ok = end == len(name) or name[end - 1] in SEPARATORS
        if not (starts_ok and ends_ok):
            bad.append(token)
    return bad


def test_long_names_break_only_at_separators(rng: np.random.Generator, tmp_path: Path) -> None:
    """``fr2_desk_groundtruth`` wraps after an underscore, never as ``groun|dtruth``."""
    truth = walk(rng, n=1500)
    truth = Trajectory(
        truth.stamps_ns,
        truth.positions_xyz,
        truth.quat_xyzw,
        name="fr2_desk_groundtruth",
        source="tum:/work/shared/data/public/fr2_desk_groundtruth.txt",
    )
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="orbslam3_monocular_run")
    result = evaluate(truth, [est])
    pages = _pdf_text(_pdf(result), tmp_path)
    tokens = " ".join(pages).split()
    for name in ("fr2_desk_groundtruth", "orbslam3_monocular_run"):
        assert _fragments_are_whole_parts(name, tokens) == [], name
    # The trajectories table's header is whole words too.
    assert "orientation" in tokens
    assert not [t for t in tokens if t in {"orienta", "orientati", "orientatio"}]
    html = render_view_html(
        build_report_view(result, ExportOptions(), plots=()), templates_dir=DEFAULT_TEMPLATES_DIR
    ).decode()
    assert "fr2_<wbr>desk_<wbr>groundtruth" in html
    # Only a SHA-256 (no separators, no words) may still wrap anywhere; names may not.
    assert ".source { overflow-wrap: anywhere; }" not in html


# --- item 10: no heading alone at a page's foot ----------------------------------------


@pytest.mark.parametrize("worst", [22, 25, 28])
def test_warnings_heading_stays_with_its_table(
    rng: np.random.Generator, tmp_path: Path, worst: int
) -> None:
    """The greatest-errors list long enough to fill the page: Warnings moves with its rows.

    On the layout before the fix these lengths left "Warnings" and its intro at the foot of
    one page and the table on the next.
    """
    del rng
    local = np.random.default_rng(3)
    truth = walk(local, n=3000)
    keep = np.ones(len(truth), dtype=bool)
    keep[1000:1100] = False
    est = noisy(local, truth, every=2, sigma=0.02, drift=0.0, name="VIO")
    result = evaluate(truth.select(keep), [est], EvaluationConfig(worst_count=worst))
    pages = [" ".join(p.split()) for p in _pdf_text(_pdf(result), tmp_path, layout=False)]
    (page,) = [p for p in pages if "Warnings What the evaluation noticed" in p]
    assert "about warning" in page
    assert "longer than 100 ms" in page


# --- item 11: the front door's words ----------------------------------------------------


def test_service_report_asks_for_the_tolerance_in_its_own_words(
    rng: np.random.Generator,
) -> None:
    """From the page or the API: no command-line flag, the page's field and the API's key."""
    truth = walk(rng, n=1200)
    result = evaluate(truth, [noisy(rng, truth, every=2, sigma=0.03, drift=0.0, name="AMCL")])
    service = ExportOptions(front_door=FrontDoor.SERVICE)
    html = render_view_html(
        build_report_view(result, service, plots=()), templates_dir=DEFAULT_TEMPLATES_DIR
    ).decode()
    assert "--tolerance" not in html
    assert (
        "(95 % of poses within 0.10 m) in the Tolerance field of the page or as "
        "options.tolerance in the API for a verdict"
    ) in " ".join(html.split())
    cli = render_view_html(
        build_report_view(result, ExportOptions(front_door=FrontDoor.CLI), plots=()),
        templates_dir=DEFAULT_TEMPLATES_DIR,
    ).decode()
    assert "--tolerance 0.10@95" in cli


def test_each_front_door_names_itself() -> None:
    """The service's jobs and the CLI build their export options with their own door."""
    options = EvaluationOptions()
    assert export_from_options(options, front_door="service").front_door is FrontDoor.SERVICE
    assert export_from_options(options, front_door="cli").front_door is FrontDoor.CLI


def test_service_pdf_has_no_flag(rng: np.random.Generator, tmp_path: Path) -> None:
    """The PDF made for the page or the API does not tell its reader to pass a flag."""
    truth = walk(rng, n=1200)
    result = evaluate(truth, [noisy(rng, truth, every=2, sigma=0.03, drift=0.0, name="AMCL")])
    text = " ".join(
        " ".join(_pdf_text(_pdf(result, front_door=FrontDoor.SERVICE), tmp_path)).split()
    )
    assert "--tolerance" not in text
    assert "options.tolerance in the API" in text


# --- item 12: information is not a warning ---------------------------------------------


def _tf_bag(tmp_path: Path, rng: np.random.Generator) -> Path:
    """map -> odom -> base_link (odom's link loses 1.5 s of data) and an /amcl_pose topic."""
    truth = walk(rng, n=1500, rate_hz=50.0)
    stamps = truth.stamps_ns
    ident = np.tile([0.0, 0.0, 0.0, 1.0], (len(truth), 1))
    keep = np.ones(len(truth), dtype=bool)
    keep[600:675] = False  # 1.5 s without odom -> base_link
    base = bf.Poses(stamps[keep], truth.positions_xyz[keep], truth.quat_xyzw[keep])
    odom = bf.Poses(stamps[::5], np.zeros((len(stamps[::5]), 3)), ident[::5])
    amcl_sel = np.arange(0, len(truth), 10)
    amcl = bf.Poses(
        stamps[amcl_sel],
        truth.positions_xyz[amcl_sel] + rng.normal(0, 0.02, (amcl_sel.size, 3)),
        truth.quat_xyzw[amcl_sel],
    )
    records = [
        *bf.tf_records(bf.link_transforms("map", "odom", odom)),
        *bf.tf_records(bf.link_transforms("odom", "base_link", base)),
        *bf.pose_records("/amcl_pose", bf.POSE_COV, amcl),
    ]
    return bf.write_bag(bf.bag_path(tmp_path, "mcap"), records, fmt="mcap")


def test_tf_chain_is_information_and_its_gaps_are_no_tracking_loss(
    rng: np.random.Generator, tmp_path: Path
) -> None:
    """The chain is told under how the trajectories were read, its gaps as missing links."""
    bag = _tf_bag(tmp_path, rng)
    reference = read_trajectory(parse_source(f"{bag}@tf:map:base_link"))
    assert not any("tf chain map" in w for w in reference.warnings)
    assert any("map → odom → base_link" in n for n in reference.notes)
    estimate = read_trajectory(parse_source(f"{bag}@/amcl_pose"), name="AMCL")
    result = evaluate(reference, [estimate])
    assert not any("tracking loss" in w for w in result.reference_warnings)
    assert any("a link of its tf chain without data" in w for w in result.reference_warnings)
    view = build_report_view(result, ExportOptions(), plots=())
    assert not any("tf chain map" in message for _, message in view.warnings)
    (note,) = [n for _, n in view.notes]
    assert "map\u00a0→\u00a0odom\u00a0→\u00a0base_link" in note  # no line splits the arrow
    assert result.to_dict()["reference"]["notes"] == list(reference.notes)  # type: ignore[index]


def test_uncompared_estimates_are_not_about_the_reference(rng: np.random.Generator) -> None:
    """Two estimates over different stretches: the note is about the pair, not the reference."""
    truth = walk(rng, n=3000)
    est = noisy(rng, truth, every=2, sigma=0.02, drift=0.0, name="A")
    t = est.stamps_ns
    first = est.select(t <= t[760])
    first = Trajectory(first.stamps_ns, first.positions_xyz, first.quat_xyzw, name="A")
    second = est.select(t >= t[756])
    second = Trajectory(second.stamps_ns, second.positions_xyz, second.quat_xyzw, name="B")
    result = evaluate(truth, [first, second])
    assert result.comparison_notes
    assert not any("not compared" in w for w in result.reference_warnings)
    view = build_report_view(result, ExportOptions(), plots=())
    labelled = [about for about, w in view.warnings if "not compared" in w]
    assert labelled
    assert all("reference" not in about for about in labelled)
    assert result.to_dict()["comparison_notes"] == list(result.comparison_notes)


def test_whole_report_renders_for_the_tf_bag(rng: np.random.Generator, tmp_path: Path) -> None:
    """The PDF lists the chain under how the trajectories were read, not under Warnings."""
    bag = _tf_bag(tmp_path, rng)
    reference = read_trajectory(parse_source(f"{bag}@tf:map:base_link"))
    estimate = read_trajectory(parse_source(f"{bag}@/amcl_pose"), name="AMCL")
    _, pdf = render_report(evaluate(reference, [estimate]))
    text = " ".join(" ".join(_pdf_text(pdf, tmp_path, layout=False)).split())
    read_at = text.index("How the trajectories were read")
    warnings_at = text.index("Warnings What the evaluation noticed")
    chain_at = text.index("tf chain map → odom → base_link")
    assert read_at < chain_at < warnings_at
