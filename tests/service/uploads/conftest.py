"""The resumable uploads' tests: the bucket's fixtures (SeaweedFS) and a large recording."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.factories import make_trajectory, write_tum
from tests.service.blobs.conftest import _patient_start, bucket, s3_env, seaweedfs

__all__ = ["_patient_start", "bucket", "large_recording", "s3_env", "seaweedfs"]


@pytest.fixture(scope="session")
def large_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A TUM trajectory of about 20 MB: three parts of the bucket's 8 MiB and a tail."""
    folder = tmp_path_factory.mktemp("recording")
    trajectory = make_trajectory(np.random.default_rng(40), 125_000)
    return write_tum(folder / "site-walk.txt", trajectory)
