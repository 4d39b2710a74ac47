"""The progress a job reports: "done" only at its end, whatever step reports it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from exporters.options import ExportOptions
from loceval.evaluation import EvaluationConfig
from loceval.readers import SourceSpec
from service.jobs.runner import JobSource, TrajectoryJob, run_job
from tests.factories import make_trajectory, write_tum


def test_done_is_reported_only_at_the_end(tmp_path: Path, rng: np.random.Generator) -> None:
    """The evaluation's own "done" is not passed on at 45 % while the files are written."""
    truth = make_trajectory(rng, 300)
    ref = write_tum(tmp_path / "ref.txt", truth)
    est = write_tum(tmp_path / "est.txt", truth)
    job = TrajectoryJob(
        reference=JobSource(SourceSpec(None, ref), "ref"),
        estimates=[JobSource(SourceSpec(None, est), "est")],
        config=EvaluationConfig(),
        export=ExportOptions(),
        formats=["result.json", "errors.csv"],
    )
    seen: list[tuple[str, float]] = []
    run_job(job, tmp_path / "out", lambda stage, fraction: seen.append((stage, fraction)))

    assert seen[-1] == ("done", 1.0)
    assert [s for s, _ in seen].count("done") == 1
    fractions = [f for _, f in seen]
    assert fractions == sorted(fractions)  # the bar never goes back
    stages = [s for s, _ in seen]
    assert stages.index("preparing the files") < stages.index("writing result.json")
