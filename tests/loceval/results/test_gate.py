"""The gate of ``--fail-on``: its conditions, what it refuses, and its reasons."""

from __future__ import annotations

import pytest

from loceval.errors import InputError
from loceval.results.document import read_result
from loceval.results.gate import FAIL_ON, check_fail_on, judge_gate, parse_fail_on
from tests.verdict_factory import baseline_result, verdict_result


@pytest.fixture(scope="module")
def document() -> dict[str, object]:
    """The result document of three estimates: steady passes, lost fails, borderline undecided."""
    return verdict_result().to_dict()


def test_the_conditions_are_the_option_tables() -> None:
    """fail, undecided and worse, in that order, as the options table lists them."""
    assert FAIL_ON == ("fail", "undecided", "worse")


@pytest.mark.parametrize(
    ("given", "parsed"),
    [
        (None, ()),
        ([], ()),
        (["worse,fail"], ("fail", "worse")),
        (["undecided", "FAIL", " fail "], ("fail", "undecided")),
        (["fail,undecided,worse"], ("fail", "undecided", "worse")),
    ],
)
def test_parse_fail_on(given: list[str] | None, parsed: tuple[str, ...]) -> None:
    """Comma-separated or repeated, any case, each once, in the canonical order."""
    assert parse_fail_on(given) == parsed


def test_unknown_condition_is_refused_naming_the_option() -> None:
    """A word that is no condition is an InputError of fail_on listing the three."""
    with pytest.raises(InputError, match="fail, undecided, worse; 'failed'") as caught:
        parse_fail_on(["failed"])
    assert caught.value.option == "fail_on"


def test_conditions_without_what_they_judge_are_refused() -> None:
    """fail/undecided need a tolerance and worse a baseline: a gate that cannot close is refused."""
    with pytest.raises(InputError, match="no tolerance") as caught:
        check_fail_on(("fail",), tolerance=False, baseline=True)
    assert caught.value.option == "fail_on"
    with pytest.raises(InputError, match="no baseline"):
        check_fail_on(("worse",), tolerance=True, baseline=False)
    check_fail_on(("fail", "undecided"), tolerance=True, baseline=False)
    check_fail_on((), tolerance=False, baseline=False)


def test_each_condition_names_its_estimates_with_the_figures(document: dict[str, object]) -> None:
    """fail names lost, undecided names borderline, each with share, interval and requirement."""
    result = read_result(document)
    lost, borderline = result.estimates[1], result.estimates[2]
    assert lost.verdict is not None
    assert borderline.verdict is not None
    required = borderline.verdict.required_share
    assert required is not None

    gate = judge_gate(result, ["fail"])
    assert not gate.passed
    (reason,) = gate.reasons
    low, high = lost.verdict.ci95 or (0.0, 0.0)
    assert reason == (
        f"lost fails the tolerance ({lost.verdict.share_within * 100:.1f} % within 0.10 m, "
        f"95 % interval {low * 100:.1f}–{high * 100:.1f} %, needs {required * 100:g} %)"
    )
    assert gate.line() == f"gate: {reason}"

    (undecided,) = judge_gate(result, ["undecided"]).reasons
    assert undecided.startswith("borderline is undecided against the tolerance (")
    both = judge_gate(result, ["undecided,fail"])
    assert [r.split()[0] for r in both.reasons] == ["lost", "borderline"]
    assert both.to_dict() == {
        "passed": False,
        "fail_on": ["fail", "undecided"],
        "reasons": list(both.reasons),
    }


def test_a_gate_without_a_holding_condition_passes(document: dict[str, object]) -> None:
    """Only steady (pass) in the document: fail and undecided both hold for no estimate."""
    only_steady = {**document, "estimates": [document["estimates"][0]]}  # type: ignore[index]
    gate = judge_gate(read_result(only_steady), ["fail", "undecided"])
    assert gate.passed
    assert gate.reasons == ()
    assert gate.line() == (
        "gate: passed (no estimate is failing the tolerance or undecided against the tolerance)"
    )


def test_a_document_from_before_the_intervals_is_judged_by_passed() -> None:
    """A verdict with only passed (and the figures) fails the gate as fail; no interval shown."""
    old = {
        "estimates": [
            {
                "name": "ORB-SLAM3",
                "verdict": {
                    "passed": False,
                    "share_within": 0.872,
                    "tolerance_m": 0.1,
                    "required_share": 0.95,
                },
            }
        ]
    }
    (reason,) = judge_gate(read_result(old), ["fail"]).reasons
    assert reason == "ORB-SLAM3 fails the tolerance (87.2 % within 0.10 m, needs 95 %)"


def test_worse_judges_estimates_and_systems_not_trials() -> None:
    """SLAM got worse (ATE and RPE); a trial's own comparison never closes the gate."""
    document = baseline_result().to_dict()
    reasons = judge_gate(read_result(document), ["worse"]).reasons
    assert [r.split(" (")[0] for r in reasons] == [
        "SLAM is worse than the baseline",
        "SLAM is worse than the baseline",
    ]
    assert reasons[0].startswith("SLAM is worse than the baseline (ATE RMSE ")
    assert "paired 95 % interval +" in reasons[0] or "unpaired 95 % interval +" in reasons[0]
    baseline = document["baseline"]
    for comparison in baseline["comparisons"]:  # every trial's own comparison now says worse
        if comparison["name"] in {"orb-1", "orb-2"}:
            comparison["verdict"] = "worse"
    assert judge_gate(read_result(document), ["worse"]).reasons == reasons
    for comparison in baseline["comparisons"]:  # the system's over its trials does count
        if comparison["name"] == "ORB":
            comparison["verdict"] = "worse"
    more = judge_gate(read_result(document), ["worse"]).reasons
    assert more[2].startswith("ORB (over its trials) is worse than the baseline (ATE RMSE ")
