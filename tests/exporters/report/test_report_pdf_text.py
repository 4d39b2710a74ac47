"""report.pdf (Typst) and report.html (Jinja2) print the same text, read back with pdftotext.

Each case renders one view model both ways and compares them block by block
(:func:`tests.exporters._pdf_text.text_differences`): every paragraph, cell, caption and
heading the HTML prints is in the PDF, and the PDF prints nothing else. The cases cover
every section and variant the view model has (a verdict that fails, passes or is undecided,
no tolerance, intervals off, NEES, ranging, a map with its history, a tf chain's notes, the
service's words, real data), so a section, sentence or number one template gains and the
other lacks fails here whichever section it is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from exporters.options import ExportOptions, FrontDoor
from exporters.plots import Plot
from exporters.report import (
    DEFAULT_TEMPLATES_DIR,
    build_report_view,
    render_report_plots,
    render_view_html,
    render_view_pdf,
)
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.readers import parse_source, read_trajectory
from loceval.trajectory import Trajectory
from tests.exporters._pdf_text import text_differences
from tests.exporters.conftest import noisy, walk
from tests.exporters.report.test_report import INPUTS

TITLE = "Site run 4: the same words in both"


def _two_failing() -> EvaluationResult:
    rng = np.random.default_rng(20240601)
    truth = walk(rng)
    a = noisy(rng, truth, every=3, sigma=0.02, drift=0.25, name="RTAB-Map")
    b = noisy(rng, truth, every=4, sigma=0.05, drift=0.05, name="ISAAC")
    return evaluate(truth, [a, b], EvaluationConfig(tolerance=Tolerance(0.10, 0.95)), inputs=INPUTS)


def _one_without_tolerance() -> EvaluationResult:
    rng = np.random.default_rng(7)
    truth = walk(rng, n=2000)
    return evaluate(truth, [noisy(rng, truth, every=2, sigma=0.03, drift=0.0, name="AMCL")])


def _passing_without_intervals() -> EvaluationResult:
    rng = np.random.default_rng(8)
    truth = walk(rng, n=2000)
    est = noisy(rng, truth, every=2, sigma=0.005, drift=0.0, name="total station")
    return evaluate(truth, [est], EvaluationConfig(tolerance=Tolerance(0.1, 0.9), no_ci=True))


def _undecided_with_nees() -> EvaluationResult:
    rng = np.random.default_rng(9)
    truth = walk(rng, n=3000)
    est = noisy(rng, truth, every=1, sigma=0.02, drift=0.0, name="AMCL").without_orientation()
    cov = np.zeros((len(est), 6, 6))
    cov[:, :3, :3] = 0.02**2 * np.eye(3)
    est = Trajectory(est.stamps_ns, est.positions_xyz, name="AMCL", cov6=cov)
    probe = evaluate(truth, [est]).estimates[0].ate_translation.values
    distance = float(np.quantile(probe, 0.9))
    return evaluate(truth, [est], EvaluationConfig(tolerance=Tolerance(distance, 0.9)))


def _ranging() -> EvaluationResult:
    from loceval.radio_evaluation import RangingConfig, evaluate_radio
    from tests.radio_factory import make_ranges, make_reference

    rng = np.random.default_rng(10)
    return evaluate_radio(make_reference(), make_ranges(rng, end_s=20.0).ranges, RangingConfig())


def _map_with_history(tmp_path: Path) -> EvaluationResult:
    from loceval.core.geometry import SimilarityTransform
    from loceval.maps import OccupancyGrid, evaluate_map_source
    from loceval.registration.alignment import AlignWindow
    from tests.loceval.metrics.test_excursions import _run
    from tests.mapfactory import Distortion, draw_map, office_plan, write_map_bag

    reference, estimate, _ = _run()
    config = EvaluationConfig(align_first=AlignWindow.parse("19s"), no_ci=True)
    result = evaluate(reference, [estimate], config)
    plan = office_plan()
    rng = np.random.default_rng(3)
    grids = [
        (s, draw_map(plan, Distortion(scale=k), resolution_m=0.05, rng=rng))
        for s, k in ((30, 0.995), (60, 0.99))
    ]
    empty = OccupancyGrid(np.full(grids[0][1].shape, -1, dtype=np.int8), 0.05)
    bag = write_map_bag(tmp_path, [(10, empty), *grids])
    t0 = int(result.reference.stamps_ns[0])
    found = evaluate_map_source(f"{bag}@/map", plan, SimilarityTransform.identity(), t0_ns=t0)
    return replace(result, map=found)


def _tf_chain(tmp_path: Path) -> EvaluationResult:
    from tests.exporters.report.test_report_reading import _tf_bag

    bag = _tf_bag(tmp_path, np.random.default_rng(11))
    reference = read_trajectory(parse_source(f"{bag}@tf:map:base_link"))
    estimate = read_trajectory(parse_source(f"{bag}@/amcl_pose"), name="AMCL")
    return evaluate(reference, [estimate])


def _trials_and_baseline() -> EvaluationResult:
    """2 systems of 3 trials (and one failed) against a baseline of 3 systems."""
    from loceval.results.baseline import baseline_from_document, compare_with_baseline
    from loceval.results.document import read_result

    rng = np.random.default_rng(41)
    truth = walk(rng, n=1500)

    def trials(levels: dict[str, float]) -> tuple[list[Trajectory], list[str | None]]:
        found, systems = [], []
        for system, sigma in levels.items():
            for k in range(3):
                found.append(noisy(rng, truth, every=3, sigma=sigma * (1 + 0.05 * k), drift=0.0,
                                   name=f"{system}-{k + 1}"))  # fmt: skip
                systems.append(system)
        return found, systems

    config = EvaluationConfig(no_ci=True)
    old, old_systems = trials({"ORB": 0.02, "VINS": 0.03, "RTAB": 0.05})
    before = evaluate(truth, old, config, systems=old_systems)
    baseline = baseline_from_document(read_result(before.to_dict()), label="v1.2", source="-")
    now, systems = trials({"ORB": 0.04, "VINS": 0.03})  # RTAB: the baseline's only
    lost = replace(now[0], name="ORB-lost")
    lost = Trajectory(
        lost.stamps_ns[:40], lost.positions_xyz[:40], lost.quat_xyzw[:40], name="ORB-lost"
    )
    result = evaluate(truth, [*now, lost], config, systems=[*systems, "ORB"])
    return replace(result, baseline=compare_with_baseline(result, baseline))


CASES: dict[str, tuple[Callable[[Path], EvaluationResult], FrontDoor, bool]] = {
    "trials, baseline, figures": (lambda _: _trials_and_baseline(), FrontDoor.CLI, True),
    # name: (evaluation, front door, whether its figures are drawn: their captions)
    "two failing, inputs, figures": (lambda _: _two_failing(), FrontDoor.CLI, True),
    "no tolerance, the service's words": (
        lambda _: _one_without_tolerance(),
        FrontDoor.SERVICE,
        False,
    ),
    "passing, intervals off": (lambda _: _passing_without_intervals(), FrontDoor.CLI, False),
    "undecided, NEES": (lambda _: _undecided_with_nees(), FrontDoor.CLI, False),
    "ranging, figures": (lambda _: _ranging(), FrontDoor.CLI, True),
    "map over time": (_map_with_history, FrontDoor.CLI, False),
    "tf chain notes": (_tf_chain, FrontDoor.CLI, False),
}


def _both(result: EvaluationResult, options: ExportOptions, *, figures: bool) -> tuple[str, bytes]:
    """The printable HTML (no interactive view, as the PDF) and the PDF of one view model."""
    plots: tuple[Plot, ...] | object = ()
    if figures:
        plots = render_report_plots(result, options, formats=("svg",))
    view = build_report_view(result, options, plots=plots, image_format="svg")  # type: ignore[arg-type]
    html = render_view_html(view, templates_dir=DEFAULT_TEMPLATES_DIR).decode("utf-8")
    return html, render_view_pdf(view, templates_dir=DEFAULT_TEMPLATES_DIR)


@pytest.mark.parametrize("case", list(CASES))
def test_pdf_prints_what_the_html_prints(case: str, tmp_path: Path) -> None:
    """Every text block of the HTML is in the PDF's text, and the PDF holds nothing else."""
    make, door, figures = CASES[case]
    options = ExportOptions(title=TITLE, evaluation_id="ev-42", front_door=door)
    html, pdf = _both(make(tmp_path), options, figures=figures)
    missing, extra = text_differences(html, pdf, tmp_path, title=TITLE)
    assert missing == [], missing
    assert extra == [], extra


@pytest.mark.public_data
def test_fr2_desk_pdf_prints_what_the_html_prints(public_data: Path, tmp_path: Path) -> None:
    """The real recording with a tolerance it fails: stretches, warnings, clock figure."""
    reference = read_trajectory(parse_source(str(public_data / "fr2_desk_groundtruth.txt")))
    estimate = read_trajectory(parse_source(str(public_data / "fr2_desk_ORB.txt")))
    config = EvaluationConfig(tolerance=Tolerance(0.01, 0.95))
    result = evaluate(reference, [estimate], config)
    options = ExportOptions(title=TITLE, evaluation_id="fr2")
    html, pdf = _both(result, options, figures=True)
    missing, extra = text_differences(html, pdf, tmp_path, title=TITLE)
    assert missing == [], missing
    assert extra == [], extra


def test_a_sentence_one_template_lacks_is_found(tmp_path: Path) -> None:
    """The comparison is not blind: a sentence only the HTML prints, or only the PDF, shows."""
    options = ExportOptions(title=TITLE, evaluation_id="ev-42")
    html, pdf = _both(_one_without_tolerance(), options, figures=False)
    added = "<p>The HTML alone says 12.345 m here.</p>"
    missing, extra = text_differences(
        html.replace("</main>", added + "</main>"), pdf, tmp_path, title=TITLE
    )
    assert missing == ["the html alone says 12.345 m here."]
    assert extra == []
    shorter = html.replace("Times in this report are seconds", "Times here are seconds")
    missing, extra = text_differences(shorter, pdf, tmp_path, title=TITLE)
    assert missing == ["times here are seconds since the first pose of the reference."]
    sentence = "times in this report are seconds since the first pose of the reference."
    assert extra == sentence.split(" ")
