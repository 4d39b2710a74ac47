"""An uploaded evo result zip is a dataset of kind ``evo_result`` (issue 28)."""

from __future__ import annotations

import zipfile
from pathlib import Path

from tests.service._api_fixtures import Api

EVO_ZIP = Path(__file__).parents[2] / "data" / "evo_results" / "nav2_amcl_odom_ape_se3.zip"


def test_an_evo_result_zip_uploads_as_a_dataset(api: Api) -> None:
    """The inspection holds the title, the names, evo's statistics and the error count."""
    dataset = api.dataset("archive_amcl.zip", EVO_ZIP.read_bytes())
    inspection = dataset["inspection"]
    assert inspection["kind"] == "evo_result"
    assert inspection["format"] == "evo"
    result = inspection["result"]
    assert result["title"].startswith("APE w.r.t. translation part (m)")
    assert (result["ref_name"], result["est_name"]) == ("/amcl_pose", "/odom")
    assert result["n"] == 83
    assert result["stats"]["rmse"] == 0.5123009339164919  # evo 1.38.1's own figure
    assert result["series"] is True


def test_a_broken_result_zip_is_refused_naming_the_problem(api: Api, tmp_path: Path) -> None:
    """A zip with evo's JSON files that cannot be read is a 4xx naming the file."""
    broken = tmp_path / "broken.zip"
    with zipfile.ZipFile(broken, "w") as archive:
        archive.writestr("info.json", "{")
        archive.writestr("stats.json", "{}")
    answer = api.upload("broken.zip", broken.read_bytes())
    assert 400 <= answer.status_code < 500
    assert "broken.zip" in answer.json()["detail"]
    assert str(tmp_path) not in answer.json()["detail"]


def test_an_evo_result_is_no_trajectory_to_evaluate(api: Api) -> None:
    """Named as the reference of an evaluation, it is refused with a 4xx, not a 500."""
    dataset = api.dataset("archive_amcl.zip", EVO_ZIP.read_bytes())
    answer = api.evaluate(
        {
            "reference": {"dataset_id": dataset["id"]},
            "estimates": [{"dataset_id": dataset["id"]}],
        }
    )
    assert answer.status_code == 422, answer.text
    assert "is an evo result (figures, not poses)" in answer.json()["detail"]
