"""``POST /comparisons``: estimates of evaluations and uploaded evo result zips (issue 28).

The zips are evo 1.38.1's own (``tests/data/evo_results``, commands in its README), made from
the public Nav2 recording that the evaluations here read too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service._api_fixtures import Api, assert_no_server_paths

EVO = Path(__file__).parents[2] / "data" / "evo_results"
EVO_SE3_RMSE = 0.5123009339164919
"""evo_ape's rmse of nav2_amcl_odom_ape_se3.zip."""
EVO_OPTIONS = {"association": "nearest", "max_dt_s": 0.01, "align": "se3"}
"""evo_ape's matching (nearest stamp within 10 ms) and -a (SE(3) Umeyama)."""


def _zip(api: Api, name: str) -> dict[str, Any]:
    return api.dataset(name, (EVO / name).read_bytes())


def _evaluation(api: Api, public_data: Path, formats: list[str]) -> dict[str, Any]:
    """Evaluate /odom against /amcl_pose of the Nav2 recording as evo_ape -a does."""
    bag = api.dataset("nav2_turtlebot.mcap", (public_data / "nav2_turtlebot.mcap").read_bytes())
    answer = api.evaluate(
        {
            "reference": {"dataset_id": bag["id"], "selector": "/amcl_pose"},
            "estimates": [{"dataset_id": bag["id"], "selector": "/odom"}],
            "options": {**EVO_OPTIONS, "formats": formats},
        }
    )
    assert answer.status_code == 202, answer.text
    done = api.client.get(f"/api/v1/evaluations/{answer.json()['id']}", headers=api.headers)
    evaluation: dict[str, Any] = done.json()
    assert evaluation["status"] == "succeeded", evaluation
    return evaluation


def _compare(api: Api, body: dict[str, Any]) -> Any:
    return api.client.post("/api/v1/comparisons", headers=api.headers, json=body)


@pytest.mark.public_data
def test_an_evaluation_and_evo_zips_are_compared_pair_by_pair(api: Api, public_data: Path) -> None:
    """loceval's figures carry intervals, evo's none; each pair gets a paired interval."""
    evaluation = _evaluation(api, public_data, ["result.json", "errors.csv"])
    se3 = _zip(api, "nav2_amcl_odom_ape_se3.zip")
    origin = _zip(api, "nav2_amcl_odom_ape_origin.zip")
    answer = _compare(
        api,
        {
            "items": [
                {"evaluation_id": evaluation["id"], "label": "loceval se3"},
                {"dataset_id": se3["id"], "label": "evo se3"},
                {"dataset_id": origin["id"], "label": "evo origin"},
            ]
        },
    )
    assert answer.status_code == 200, answer.text
    found = answer.json()
    mine, evo_se3, evo_origin = found["items"]
    assert (mine["source"], evo_se3["source"], evo_origin["source"]) == ("loceval", "evo", "evo")
    assert mine["ci95"]["rmse"][0] < mine["stats"]["rmse"] < mine["ci95"]["rmse"][1]
    assert evo_se3["ci95"] is None
    assert "evo gives no confidence interval" in evo_se3["intervals"]
    assert evo_se3["stats"]["rmse"] == EVO_SE3_RMSE
    assert evo_se3["title"] == "APE w.r.t. translation part (m) (with SE(3) Umeyama alignment)"
    # the same options give evo's figure (the parity of tests/service/cli/test_cli_evo.py)
    assert mine["stats"]["rmse"] == pytest.approx(EVO_SE3_RMSE, rel=1e-6)
    pairs = {(p["a"], p["b"]): p for p in found["comparisons"]}
    assert set(pairs) == {
        ("loceval se3", "evo se3"),
        ("loceval se3", "evo origin"),
        ("evo se3", "evo origin"),
    }
    same = pairs[("loceval se3", "evo se3")]
    assert same["verdict"] == "within_noise" or "the same result" in same["unavailable"]
    aligned_vs_origin = pairs[("loceval se3", "evo origin")]
    assert aligned_vs_origin["unavailable"] is None
    assert aligned_vs_origin["n_common"] == 83
    lo, hi = aligned_vs_origin["ci95"]
    assert lo <= aligned_vs_origin["difference"] <= hi
    difference = mine["stats"]["rmse"] - evo_origin["stats"]["rmse"]
    assert aligned_vs_origin["difference"] == pytest.approx(difference, abs=1e-5)
    assert any("evo's figures as evo computed them" in note for note in found["notes"])


@pytest.mark.public_data
def test_an_evaluation_without_errors_csv_is_listed_without_a_paired_interval(
    api: Api, public_data: Path
) -> None:
    """Without the evaluation's errors.csv the pair says why it has no interval."""
    evaluation = _evaluation(api, public_data, ["result.json"])
    se3 = _zip(api, "nav2_amcl_odom_ape_se3.zip")
    body = {
        "items": [{"evaluation_id": evaluation["id"]}, {"dataset_id": se3["id"], "label": "evo"}]
    }
    answer = _compare(api, body)
    assert answer.status_code == 200, answer.text
    (pair,) = answer.json()["comparisons"]
    assert "kept no errors.csv" in pair["unavailable"]
    assert pair["ci95"] is None


def test_what_cannot_be_compared_is_a_problem_naming_the_item(api: Api) -> None:
    """A recording, an RPE zip under ate_rmse, a missing id, one source too many: 4xx naming it."""
    rpe = _zip(api, "nav2_amcl_odom_rpe_se3.zip")
    degrees = _zip(api, "nav2_amcl_odom_ape_angle_deg.zip")
    ape = _zip(api, "nav2_amcl_odom_ape_se3.zip")
    tum = api.dataset("walk.txt", b"0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n2 2 0 0 0 0 0 1\n")
    cases = [
        ([{"dataset_id": ape["id"]}, {"dataset_id": rpe["id"]}], 422, "items[1].dataset_id"),
        ([{"dataset_id": ape["id"]}, {"dataset_id": degrees["id"]}], 422, "rotation angle"),
        ([{"dataset_id": tum["id"]}, {"dataset_id": ape["id"]}], 422, "not an evo result zip"),
        ([{"dataset_id": ape["id"]}, {"dataset_id": "nope"}], 404, "No dataset 'nope'"),
        ([{"dataset_id": ape["id"]}, {"evaluation_id": "nope"}], 404, "No evaluation 'nope'"),
        ([{"dataset_id": ape["id"]}, {"dataset_id": ape["id"]}], 422, "labels ['/odom'] repeat"),
        (
            [{"dataset_id": ape["id"], "evaluation_id": "x"}, {"dataset_id": rpe["id"]}],
            422,
            "either evaluation_id",
        ),
    ]
    for items, status, words in cases:
        answer = _compare(api, {"items": items})
        assert answer.status_code == status, (items, answer.text)
        assert answer.headers["content-type"].startswith("application/problem+json")
        assert words in answer.text, answer.text
        assert_no_server_paths(answer.text, api.data_dir)
    rpes = _compare(
        api,
        {
            "metric": "rpe_rmse",
            "items": [{"dataset_id": rpe["id"]}, {"dataset_id": rpe["id"], "label": "again"}],
        },
    )
    assert rpes.status_code == 200, rpes.text
    assert "the same result" in rpes.json()["comparisons"][0]["unavailable"]
