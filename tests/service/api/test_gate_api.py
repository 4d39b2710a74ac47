"""The gate over the API: ``options.fail_on``, the evaluation's ``gate``, the CI artifacts."""

from __future__ import annotations

from pathlib import Path

import pytest
from junitparser import JUnitXml

from tests.service._api_fixtures import Api, assert_problem
from tests.verdict_factory import write_verdict_files

FAST = {"formats": ["junit.xml", "summary.md"], "no_ci": False}
"""The CI files only (no reports or CAD files), intervals on (the verdicts use them)."""


@pytest.fixture
def ids(api: Api, tmp_path: Path) -> dict[str, str]:
    """The reference, steady (pass) and lost (fail) uploaded; their dataset ids by name."""
    files = write_verdict_files(tmp_path / "verdicts")
    return {
        name: api.dataset(f"{name}.tum", files[name].read_bytes())["id"]
        for name in ("reference", "steady", "lost")
    }


def _body(ids: dict[str, str], *estimates: str, **options: object) -> dict[str, object]:
    return {
        "reference": {"dataset_id": ids["reference"]},
        "estimates": [{"dataset_id": ids[e], "name": e} for e in estimates],
        "options": {**FAST, **options},
    }


def test_the_gate_closes_with_the_clis_reasons(api: Api, ids: dict[str, str]) -> None:
    """fail_on fail: lost fails, so gate.passed is false and the reason names it with figures."""
    created = api.evaluate(_body(ids, "steady", "lost", tolerance="0.10@95", fail_on=["fail"]))
    assert created.status_code == 202, created.text
    evaluation = api.client.get(
        f"/api/v1/evaluations/{created.json()['id']}", headers=api.headers
    ).json()
    assert evaluation["status"] == "succeeded"
    gate = evaluation["gate"]
    assert gate["passed"] is False
    assert gate["fail_on"] == ["fail"]
    (reason,) = gate["reasons"]
    verdict = evaluation["result"]["estimates"][1]["verdict"]
    low, high = verdict["ci95"]
    assert reason == (
        f"lost fails the tolerance ({verdict['share_within'] * 100:.1f} % within 0.10 m, "
        f"95 % interval {low * 100:.1f}–{high * 100:.1f} %, needs 95 %)"
    )
    listed = {a["name"] for a in evaluation["artifacts"]}
    assert listed == {"result.json", "junit.xml", "summary.md"}
    url = f"/api/v1/evaluations/{evaluation['id']}/artifacts/junit.xml"
    response = api.client.get(url, headers=api.headers)
    assert response.headers["content-type"].split(";")[0] == "application/xml"
    xml = JUnitXml.fromstring(response.text)
    assert [(s.name, s.failures) for s in xml] == [("steady", 0), ("lost", 1)]
    summary = api.client.get(url.replace("junit.xml", "summary.md"), headers=api.headers)
    assert 'summary.md"' in summary.headers["content-disposition"]  # saved under its name
    assert "Gate: ❌ closed" in summary.text


def test_a_passing_gate_and_no_gate(api: Api, ids: dict[str, str]) -> None:
    """steady alone passes (gate.passed true, no reasons); without fail_on gate is null."""
    created = api.evaluate(_body(ids, "steady", tolerance="0.10@95", fail_on=["fail", "worse"]))
    assert created.status_code == 422  # worse without a baseline: refused before it runs
    created = api.evaluate(_body(ids, "steady", tolerance="0.10@95", fail_on=["undecided", "fail"]))
    evaluation = api.client.get(
        f"/api/v1/evaluations/{created.json()['id']}", headers=api.headers
    ).json()
    assert evaluation["gate"] == {"passed": True, "fail_on": ["fail", "undecided"], "reasons": []}
    plain = api.evaluate(_body(ids, "lost", tolerance="0.10@95")).json()
    shown = api.client.get(f"/api/v1/evaluations/{plain['id']}", headers=api.headers).json()
    assert shown["gate"] is None
    listed = api.client.get("/api/v1/evaluations", headers=api.headers).json()
    assert all(item["gate"] is None for item in listed["items"])  # as result: one only


@pytest.mark.parametrize(
    ("options", "detail"),
    [
        ({"fail_on": ["fail"]}, "judge the tolerance verdict, and no tolerance is given"),
        ({"tolerance": "0.1@95", "fail_on": ["worse"]}, "no baseline is given"),
    ],
)
def test_a_gate_that_cannot_close_is_refused(
    api: Api, ids: dict[str, str], options: dict[str, object], detail: str
) -> None:
    """fail_on without what it judges is a 422 naming options.fail_on, before anything runs."""
    problem = assert_problem(api.evaluate(_body(ids, "steady", **options)), 422, detail=detail)
    assert "fail_on" in str(problem)


def test_an_unknown_condition_is_refused_by_the_schema(api: Api, ids: dict[str, str]) -> None:
    """fail_on takes only fail, undecided and worse (the options table's choices)."""
    response = api.evaluate(_body(ids, "steady", tolerance="0.1@95", fail_on=["failed"]))
    problem = assert_problem(response, 422)
    assert "fail_on" in str(problem)
