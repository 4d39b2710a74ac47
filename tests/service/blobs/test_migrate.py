"""``loceval storage migrate``: a data folder's uploads and artifacts move into a bucket."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from tests.service._api_fixtures import open_api, tum_pair
from tests.service.blobs.conftest import SeaweedFS, object_keys
from tests.service.conftest import REPO, service_env

OPTIONS = {"formats": ["result.json"]}


def _migrate(data_dir: Path, extra: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "service.cli", "storage", "migrate"],
        capture_output=True,
        text=True,
        env=service_env(data_dir, extra),
        cwd=REPO,
        timeout=120,
        check=False,
    )


def test_a_folder_moves_into_a_bucket_and_the_service_runs_from_it(
    seaweedfs: SeaweedFS, bucket: str, s3_env: dict[str, str], tmp_path: Path
) -> None:
    """Upload and evaluate on the folder; migrate; the bucket serves both; again is a no-op."""
    truth, estimate = tum_pair(np.random.default_rng(5), tmp_path)
    with open_api(tmp_path) as api:
        ref = api.dataset("truth.txt", truth)
        est = api.dataset("slam.txt", estimate)
        body = {
            "reference": {"dataset_id": ref["id"]},
            "estimates": [{"dataset_id": est["id"]}],
            "options": OPTIONS,
        }
        first = api.evaluate(body).json()
        data_dir = api.data_dir
    url = f"s3://{bucket}/moved"
    moved = _migrate(data_dir, {"LOCEVAL_BLOB_URL": url, **s3_env})
    assert moved.returncode == 0, moved.stderr + moved.stdout
    assert "Moved 2 datasets and 1 artifact files" in moved.stdout
    keys = object_keys(seaweedfs, bucket)
    assert f"moved/evaluations/{first['id']}/artifacts/result.json" in keys
    assert len([k for k in keys if k.startswith("moved/datasets/")]) == 2
    with open_api(tmp_path, blob_url=url) as api:
        path = f"/api/v1/evaluations/{first['id']}"
        stored = api.client.get(f"{path}/artifacts/result.json", headers=api.headers)
        assert stored.status_code == 200
        assert stored.json() == api.client.get(path, headers=api.headers).json()["result"]
        again = api.evaluate(body).json()
        assert again["status"] == "succeeded", again
        assert api.upload("copy.txt", truth).status_code == 200  # found by its bytes
    twice = _migrate(data_dir, {"LOCEVAL_BLOB_URL": url, **s3_env})
    assert twice.returncode == 0, twice.stderr
    assert "Moved 0 datasets and 0 artifact files" in twice.stdout
    assert "2 datasets were there already" in twice.stdout


def test_migrate_without_a_bucket_says_what_to_set(tmp_path: Path) -> None:
    """No LOCEVAL_BLOB_URL: exit 1 naming the variable, no traceback."""
    (tmp_path / "datasets").mkdir()
    answer = _migrate(tmp_path, {})
    assert answer.returncode == 1
    assert "LOCEVAL_BLOB_URL=s3://" in answer.stderr
    assert "Traceback" not in answer.stderr
