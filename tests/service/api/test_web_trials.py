"""The page groups trials under their system and shows the baseline's verdicts.

Real Chromium (Playwright, the system package) against a real ``loceval serve``: 3 systems of
5 trials each against a baseline evaluation of the same systems (made through the API),
opened on the page; then the form itself sends trials (a system per estimate row) with the
earlier evaluation as baseline. Screenshots are left in the test's tmp_path.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.factories import make_trajectory, perturb, write_tum
from tests.service.api.test_web_browser import (
    _choose,
    _enter_key,
    browser,
    page,
    wait_until_succeeded,
)
from tests.service.conftest import submit, upload, wait_for_evaluation

__all__ = ["browser", "page"]  # the fixtures, used by name

pytestmark = [pytest.mark.slow]

LEVELS_BEFORE = {"ORB-SLAM3": 0.02, "VINS-Fusion": 0.03, "RTAB-Map": 0.05}
LEVELS_NOW = {"ORB-SLAM3": 0.04, "VINS-Fusion": 0.03, "RTAB-Map": 0.025}


def _trials(
    client: Any, tmp_path: Path, levels: dict[str, float], tag: str, seed: int
) -> list[dict[str, Any]]:
    rng = np.random.default_rng(seed)
    truth = make_trajectory(np.random.default_rng(41), n=600)
    refs = []
    for system, sigma in levels.items():
        for k in range(5):
            trial = replace(perturb(truth, rng, sigma_m=sigma * (1 + 0.04 * k)), name="x")
            path = write_tum(tmp_path / f"{tag}-{system}-{k + 1}.txt", trial)
            dataset = upload(client, path)
            refs.append(
                {"dataset_id": dataset["id"], "name": f"{system} #{k + 1}", "system": system}
            )
    return refs


def test_page_groups_trials_and_shows_the_baseline(live_server: Any, page: Any, tmp_path: Path):
    """3 systems x 5 trials against a baseline: a group row per system, its trials under it,
    a failed trial named, and a verdict per system and metric; the form sends trials too."""

    truth = make_trajectory(np.random.default_rng(41), n=600)
    with live_server.client() as client:
        gt = upload(client, write_tum(tmp_path / "groundtruth.txt", truth))
        reference = {"dataset_id": gt["id"], "name": "OptiTrack"}
        before = submit(client, reference, _trials(client, tmp_path, LEVELS_BEFORE, "v1", 1))
        assert wait_for_evaluation(client, before["id"])["status"] == "succeeded"
        now = _trials(client, tmp_path, LEVELS_NOW, "v2", 2)
        lost = upload(
            client,
            write_tum(tmp_path / "lost.txt", make_trajectory(np.random.default_rng(5), n=40)),
        )
        now.append({"dataset_id": lost["id"], "name": "ORB-SLAM3 #6", "system": "ORB-SLAM3"})
        evaluation = submit(client, reference, now, {"baseline": before["id"]})
        done = wait_for_evaluation(client, evaluation["id"])
        assert done["status"] == "succeeded", done

    _check_shown(page, live_server, evaluation["id"], tmp_path)
    _form_with_trials(page, live_server, before["id"])


def _check_shown(page: Any, live_server: Any, evaluation_id: str, tmp_path: Path) -> None:
    """The evaluation opened on the page: systems, trials, comparisons and the baseline."""
    from playwright.sync_api import expect

    page.goto(f"{live_server.url}/")
    _enter_key(page, live_server.api_key)
    page.locator(f"button[aria-label='Open evaluation {evaluation_id}']").click()
    assert wait_until_succeeded(page) == evaluation_id
    summary = page.locator("#summary-body")
    expect(summary.locator("tr.system-row")).to_have_count(3)
    expect(summary.locator("tr.trial-row")).to_have_count(16)  # 15 trials and the failed one
    groups = summary.locator("tr.system-row").all_inner_texts()
    assert groups[0].startswith("ORB-SLAM3")
    assert "5 trials, 1 failed" in groups[0]
    assert "95 % interval of the mean" in groups[1]
    order = summary.locator("tr").evaluate_all("rows => rows.map(r => r.dataset.system || '')")
    assert order[:7] == ["ORB-SLAM3"] * 7  # the group row, its 5 trials and the failed one
    expect(summary.locator("tr.trial-failed")).to_contain_text("FAILED TRIAL")
    expect(page.locator("#system-comparisons li")).to_have_count(12)  # 3 pairs x 4 metrics
    baseline = page.locator("#baseline-body tr")
    expect(baseline).to_have_count(6)
    verdicts = {
        row.get_attribute("data-verdict") for row in baseline.all() if "ATE" in row.inner_text()
    }
    assert verdicts == {"worse", "within_noise", "better"}
    expect(page.locator("#baseline-table")).to_contain_text("ORB-SLAM3 (system)")
    page.locator("#current-card").screenshot(path=str(tmp_path / "trials-baseline.png"))


def _form_with_trials(page: Any, live_server: Any, baseline_id: str) -> None:
    """The form (on the same page, the key entered): two estimate rows of one system, and
    the earlier evaluation as baseline."""
    from playwright.sync_api import expect

    shown = page.locator("#current-card").get_attribute("data-evaluation-id")
    _choose(page.locator("#reference-select"), "groundtruth")
    _choose(page.locator(".estimate-select").first, "v2-ORB-SLAM3-1")
    page.locator(".estimate-system").first.fill("ORB-SLAM3")
    page.click("#add-estimate")
    _choose(page.locator(".estimate-select").nth(1), "v2-ORB-SLAM3-2")
    page.locator(".estimate-system").nth(1).fill("ORB-SLAM3")
    page.locator("#other-options").evaluate("d => { if (d.tagName === 'DETAILS') d.open = true; }")
    _choose(page.locator("#other-options-grid select.evaluation-choice"), baseline_id[:8])
    page.click("#start-button")
    expect(page.locator("#current-card")).not_to_have_attribute("data-evaluation-id", shown or "")
    formed = wait_until_succeeded(page)
    with live_server.client() as client:
        result = client.get(f"/api/v1/evaluations/{formed}").json()["result"]
    assert result["systems"][0]["name"] == "ORB-SLAM3"
    assert result["systems"][0]["n_trials"] == 2
    assert result["baseline"]["source"] == f"evaluation:{baseline_id}"
    expect(page.locator("#summary-body tr.system-row")).to_have_count(1)
    expect(page.locator("#current-baseline")).to_be_visible()
