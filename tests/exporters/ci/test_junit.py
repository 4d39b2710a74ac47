"""``junit.xml``: read back by junitparser, valid against Jenkins' JUnit schema."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
import xmlschema
from junitparser import Error, Failure, JUnitXml, Skipped, TestCase, TestSuite

from exporters import ARTIFACTS, render_artifact
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult
from tests.verdict_factory import baseline_result, verdict_result

SCHEMA = xmlschema.XMLSchema(Path(__file__).parent / "data" / "junit-10.xsd")
"""The Jenkins xUnit plugin's junit-10.xsd (data/README.md: source and licence)."""


@pytest.fixture(scope="module")
def verdicts() -> EvaluationResult:
    """steady passes, lost fails, borderline is undecided (its own share required)."""
    return verdict_result()


@pytest.fixture(scope="module")
def against_baseline() -> EvaluationResult:
    """SLAM worse, VIO better, UWB within noise; the system ORB with a failed trial."""
    return baseline_result()


def _junit(result: EvaluationResult, *fail_on: str) -> JUnitXml:
    data = render_artifact("junit.xml", result, ExportOptions(fail_on=fail_on))
    SCHEMA.validate(data)  # raises with the first violation
    return JUnitXml.fromstring(data.decode())


def _outcome(case: TestCase) -> str:
    results = case.result
    if not results:
        return "passed"
    (only,) = results
    return {Failure: "failure", Skipped: "skipped", Error: "error"}[type(only)]


def _cases(suite: TestSuite) -> dict[str, str]:
    return {case.name: _outcome(case) for case in suite}


def test_the_artifact_is_registered() -> None:
    """junit.xml is an artifact of every evaluation, served as XML."""
    assert ARTIFACTS["junit.xml"].media_type == "application/xml"


def test_a_suite_per_estimate_a_case_per_check(verdicts: EvaluationResult) -> None:
    """Three suites; lost's tolerance case fails; undecided is skipped without the gate's word."""
    xml = _junit(verdicts)
    suites = {suite.name: suite for suite in xml}
    assert list(suites) == ["steady", "lost", "borderline"]
    tolerance = next(iter(_cases(suites["steady"])))
    assert tolerance.startswith("tolerance ")
    assert {name: _cases(s) for name, s in suites.items()} == {
        "steady": {tolerance: "passed"},
        "lost": {tolerance: "failure"},
        "borderline": {tolerance: "skipped"},
    }
    assert (xml.tests, xml.failures, xml.errors) == (3, 1, 0)
    assert [(s.tests, s.failures, s.skipped) for s in suites.values()] == [
        (1, 0, 0),
        (1, 1, 0),
        (1, 0, 1),
    ]


def test_undecided_is_a_failure_when_the_gate_fails_on_it(verdicts: EvaluationResult) -> None:
    """With fail_on undecided, borderline's case is a failure (the build fails for it)."""
    suites = {suite.name: suite for suite in _junit(verdicts, "undecided")}
    assert list(_cases(suites["borderline"]).values()) == ["failure"]
    assert _junit(verdicts, "undecided").failures == 2


def test_a_failure_message_holds_the_figures_and_interval(verdicts: EvaluationResult) -> None:
    """lost's failure says FAIL, its share within, the share's interval, and its ATE RMSE."""
    lost = next(s for s in _junit(verdicts) if s.name == "lost")
    (case,) = list(lost)
    (failure,) = case.result
    verdict = verdicts.estimates[1].verdict
    assert verdict is not None
    assert verdict.share_ci95 is not None
    low, high = verdict.share_ci95
    share = verdict.share_within * 100
    assert failure.type == "fail"
    assert failure.message.startswith(
        f"lost: FAIL: {share:.1f} % within 0.1 m (95 % interval "
        f"{low * 100:.1f}–{high * 100:.1f} %, "
    )
    rmse = verdicts.estimates[1].ate_translation.stats.rmse
    assert f"; ATE RMSE {rmse:.3f} m (" in failure.message
    assert "does not meet the tolerance" in failure.text
    properties = {p.name: p.value for p in lost.properties()}
    assert properties["verdict"] == "fail"
    assert properties["ate_rmse"].startswith(f"{rmse:.3f} m (")


def test_without_a_tolerance_the_check_is_skipped(verdicts: EvaluationResult) -> None:
    """No tolerance: each suite's one case is skipped, saying there is none."""
    config = replace(verdicts.config, tolerance=None)
    estimates = tuple(replace(e, verdict=None) for e in verdicts.estimates)
    xml = _junit(replace(verdicts, config=config, estimates=estimates))
    for suite in xml:
        (case,) = list(suite)
        (skipped,) = case.result
        assert isinstance(skipped, Skipped)
        assert "no tolerance" in skipped.message


def test_baseline_comparisons_and_systems(against_baseline: EvaluationResult) -> None:
    """A case per comparison (worse fails); ORB's suite holds its trials and the failed trial."""
    xml = _junit(against_baseline)
    suites = {suite.name: _cases(suite) for suite in xml}
    assert list(suites) == ["SLAM", "VIO", "UWB", "ORB"]
    tolerance = "tolerance 95 % of poses within 0.1 m"
    assert suites["SLAM"] == {
        tolerance: "failure",
        "baseline ATE RMSE": "failure",
        "baseline RPE RMSE": "failure",
    }
    assert suites["VIO"] == {
        tolerance: "passed",
        "baseline ATE RMSE": "passed",
        "baseline RPE RMSE": "passed",
    }
    assert suites["UWB"] == suites["VIO"]
    assert suites["ORB"] == {  # a system is compared over its trials, not trial by trial
        f"{tolerance}: orb-1": "passed",
        f"{tolerance}: orb-2": "skipped",  # borderline: 94.7 %, its interval straddles 95 %
        "trial orb-3": "error",
        "baseline ATE RMSE (over the trials)": "skipped",
        "baseline RPE RMSE (over the trials)": "skipped",
    }
    slam = next(s for s in xml if s.name == "SLAM")
    worse = next(c for c in slam if c.name == "baseline ATE RMSE").result[0]
    assert worse.type == "worse"
    assert worse.message.startswith("SLAM: worse: ATE RMSE ")
    assert " against " in worse.message
    assert "95 % interval " in worse.message
    orb = next(s for s in xml if s.name == "ORB")
    failed = next(c for c in orb if c.name == "trial orb-3").result[0]
    assert failed.message == "orb-3: orb-3.tum is empty."
    properties = {p.name: p.value for p in orb.properties()}
    assert (properties["trials"], properties["failed_trials"]) == ("2", "1")
    assert properties["ATE RMSE"].startswith("median ")
    assert ", 95 % interval too few trials" in properties["ATE RMSE"]  # 2 trials: none
    assert (xml.errors, orb.errors) == (1, 1)


def test_names_from_the_inputs_stay_text(verdicts: EvaluationResult) -> None:
    """Markup and control characters in a name neither break the XML nor reach it raw."""
    hostile = 'a|b <x>&"q"\x1b[31m'
    estimates = (replace(verdicts.estimates[0], estimate=replace(
        verdicts.estimates[0].estimate, name=hostile
    )),)  # fmt: skip
    xml = _junit(replace(verdicts, estimates=estimates))
    (suite,) = list(xml)
    assert suite.name == 'a|b <x>&"q"\ufffd[31m'
