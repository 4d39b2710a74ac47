"""Trials and a baseline over the HTTP API: estimates[k].system, options.baseline."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from tests.factories import make_trajectory, perturb, write_tum
from tests.service._api_fixtures import Api, assert_problem


def _upload_trials(
    api: Api, tmp_path: Path, rng: np.random.Generator, levels: dict[str, float], tag: str
) -> tuple[str, list[dict[str, Any]]]:
    """Upload a reference (once per tag) and 3 trials per system; return the ids and refs."""
    truth = make_trajectory(np.random.default_rng(41), n=600)
    reference = api.dataset("gt.txt", write_tum(tmp_path / "gt.txt", truth).read_bytes())
    estimates = []
    for system, sigma in levels.items():
        for k in range(3):
            trial = replace(
                perturb(truth, rng, sigma_m=sigma * (1 + 0.05 * k)), name=f"{system}-{k}"
            )
            path = write_tum(tmp_path / f"{tag}-{system}-{k}.txt", trial)
            dataset = api.dataset(path.name, path.read_bytes())
            estimates.append(
                {"dataset_id": dataset["id"], "name": f"{system}-{k}", "system": system}
            )
    return reference["id"], estimates


def test_trials_and_a_baseline_over_the_api(api: Api, tmp_path: Path, rng: np.random.Generator):
    """Estimates with a system are grouped in the result; a second evaluation names the first
    as its baseline and each system gets its difference and verdict; a failed trial is counted."""
    reference, estimates = _upload_trials(api, tmp_path, rng, {"orb": 0.02, "vins": 0.04}, "v1")
    first = api.evaluate({"reference": {"dataset_id": reference}, "estimates": estimates})
    assert first.status_code == 202, first.text
    first_id = first.json()["id"]
    done = api.client.get(f"/api/v1/evaluations/{first_id}", headers=api.headers).json()
    assert done["status"] == "succeeded", done
    result = done["result"]
    assert [s["name"] for s in result["systems"]] == ["orb", "vins"]
    assert result["systems"][0]["trials"] == ["orb-0", "orb-1", "orb-2"]
    assert [e["system"] for e in result["estimates"]] == ["orb"] * 3 + ["vins"] * 3
    comparison = next(c for c in result["system_comparisons"] if c["metric"] == "ate_rmse")
    assert comparison["verdict"] == "too_few_trials"  # 3 against 3 trials: no 95 % interval

    _, now = _upload_trials(api, tmp_path, rng, {"orb": 0.02, "vins": 0.04}, "v2")
    lost = write_tum(tmp_path / "lost.txt", make_trajectory(rng, n=40))  # 0.4 s of a 6 s run
    lost_id = api.dataset("lost.txt", lost.read_bytes())["id"]
    now.append({"dataset_id": lost_id, "name": "orb-lost", "system": "orb"})
    second = api.evaluate(
        {
            "reference": {"dataset_id": reference},
            "estimates": now,
            "options": {"baseline": first_id},
        }
    )
    assert second.status_code == 202, second.text
    body = api.client.get(f"/api/v1/evaluations/{second.json()['id']}", headers=api.headers)
    result = body.json()["result"]
    orb = result["systems"][0]
    assert orb["n_failed"] == 1
    assert orb["failed"][0]["name"] == "orb-lost"
    baseline = result["baseline"]
    assert baseline["source"] == f"evaluation:{first_id}"
    rows = {(c["name"], c["metric"]): c for c in baseline["comparisons"]}
    assert set(rows) == {
        ("orb", "ate_rmse"),
        ("orb", "rpe_rmse"),
        ("vins", "ate_rmse"),
        ("vins", "rpe_rmse"),
    }
    assert {c["verdict"] for c in rows.values()} == {"undetermined"}  # 3 trials each side
    assert rows["orb", "ate_rmse"]["level"] == "system"


def test_baseline_must_be_a_succeeded_evaluation_of_the_project(
    api: Api, tmp_path: Path, rng: np.random.Generator
):
    """An unknown baseline is a 404 problem, a queued one a 422 naming the option, and a
    reference cannot be a trial."""
    reference, estimates = _upload_trials(api, tmp_path, rng, {"orb": 0.02}, "v1")
    body = {"reference": {"dataset_id": reference}, "estimates": estimates}
    unknown = api.evaluate({**body, "options": {"baseline": "no-such-evaluation"}})
    assert_problem(unknown, 404)
    queued = api.insert_evaluation([reference])
    waiting = api.evaluate({**body, "options": {"baseline": queued}})
    assert_problem(waiting, 422)
    assert "succeeded" in waiting.json()["detail"]
    trial_reference = api.evaluate(
        {"reference": {"dataset_id": reference, "system": "gt"}, "estimates": estimates}
    )
    assert_problem(trial_reference, 422)
    assert "reference.system" in trial_reference.json()["detail"]
