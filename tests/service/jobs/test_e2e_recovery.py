"""Crash recovery of the real server: abandoned jobs, a killed server, a cut-off upload.

A job's state lives in the database, so a job whose worker died (its heartbeat stopped) is
queued again when the server starts, or failed once it has been started ``job_attempts``
times; a server killed with SIGKILL mid-job finishes the job after a restart; an upload whose
client vanishes mid-body leaves neither a dataset nor a half-written file behind.
"""

from __future__ import annotations

import datetime as dt
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exporters import ARTIFACTS
from service.db import Evaluation, EvaluationStatus, create_db_engine, make_session_factory
from tests.service.conftest import (
    LiveServer,
    running_server,
    start_cut_upload,
    start_server,
    submit,
    succeeded,
    upload,
    wait_for_evaluation,
    wait_until,
)

pytestmark = [pytest.mark.slow]

GROUNDTRUTH = "freiburg1_xyz-groundtruth.txt"
ESTIMATE = "freiburg1_xyz-rgbdslam.txt"
ATTEMPTS = 3  # the default LOCEVAL_JOB_ATTEMPTS
# Large enough that the job runs for seconds (reading, evaluating, eight artifacts of tens of
# thousands of points), small enough that the whole job takes ~10 s on two cores.
SYNTHETIC_POSES = 30_000


def _abandon(data_dir: Path, template_id: str, *, attempts: int) -> str:
    """Insert a copy of an evaluation as a worker that died mid-job left it; return its id."""
    engine = create_db_engine(f"sqlite:///{(data_dir / 'loceval.db').resolve()}")
    try:
        with make_session_factory(engine)() as session:
            template = session.get_one(Evaluation, template_id)
            now = dt.datetime.now(dt.UTC)
            row = Evaluation(
                project_id=template.project_id,
                status=EvaluationStatus.RUNNING,
                stage="reading freiburg1_xyz-rgbdslam",
                fraction=0.1,
                request=template.request,
                dataset_ids=template.dataset_ids,
                attempts=attempts,
                worker="crashed-host:4242:dead00",
                heartbeat_at=now - dt.timedelta(minutes=10),
                created_at=now - dt.timedelta(minutes=11),
                started_at=now - dt.timedelta(minutes=10),
            )
            session.add(row)
            session.commit()
            return row.id
    finally:
        engine.dispose()


@pytest.fixture(scope="module")
def restarted(tmp_path_factory: pytest.TempPathFactory, public_data: Path) -> dict[str, Any]:
    """Two abandoned 'running' jobs (1 and 3 attempts) written while the server was down.

    The server is then started again with a 5 s lease; both jobs are polled to their end.
    """
    data_dir = tmp_path_factory.mktemp("data")
    with running_server(data_dir) as first, first.client() as client:
        ref = upload(client, public_data / GROUNDTRUTH)
        est = upload(client, public_data / ESTIMATE)
        template = submit(
            client,
            {"dataset_id": ref["id"]},
            [{"dataset_id": est["id"]}],
            {"formats": ["errors.csv"]},  # the copies run fast; all formats: the kill test
        )
        template = succeeded(wait_for_evaluation(client, template["id"]))
        api_key = first.api_key
    retried = _abandon(data_dir, template["id"], attempts=1)
    exhausted = _abandon(data_dir, template["id"], attempts=ATTEMPTS)
    env = {"LOCEVAL_JOB_LEASE_S": "5", "LOCEVAL_JOB_ATTEMPTS": str(ATTEMPTS)}
    with (
        running_server(data_dir, api_key=api_key, env=env) as second,
        second.client() as client,
    ):
        return {
            "template": template,
            "retried": wait_for_evaluation(client, retried),
            "exhausted": wait_for_evaluation(client, exhausted),
        }


@pytest.mark.public_data
def test_abandoned_job_is_run_again_after_a_restart(restarted: dict[str, Any]) -> None:
    """A 'running' job with a stale heartbeat and 1 attempt is queued again and succeeds."""
    evaluation = succeeded(restarted["retried"])
    assert evaluation["attempts"] == 2
    assert evaluation["progress"] == {"stage": "done", "fraction": 1.0}
    template = restarted["template"]
    assert evaluation["id"] != template["id"]
    assert evaluation["summary"] == template["summary"]
    assert [a["name"] for a in evaluation["artifacts"]] == ["result.json", "errors.csv"]


@pytest.mark.public_data
def test_job_interrupted_too_often_fails(restarted: dict[str, Any]) -> None:
    """A 'running' job abandoned after its last allowed attempt ends failed, interrupted."""
    evaluation = restarted["exhausted"]
    assert evaluation["status"] == "failed", evaluation
    assert evaluation["attempts"] == ATTEMPTS
    error = evaluation["error"]
    assert error["type"] == "evaluation.interrupted"
    assert error["status"] == 500
    assert f"interrupted {ATTEMPTS} times" in error["detail"]
    assert evaluation["finished_at"] is not None
    assert evaluation["artifacts"] is None


def _write_synthetic_pair(folder: Path, poses: int) -> tuple[Path, Path]:
    """A long, wiggly ground truth at 100 Hz and a noisy estimate of it, as TUM files."""
    rng = np.random.default_rng(20240601)
    stamps = 1.7e9 + 0.01 * np.arange(poses)
    angle = np.linspace(0.0, 8.0 * np.pi, poses)
    wander = np.cumsum(rng.normal(0.0, 0.002, (poses, 3)), axis=0)
    truth = np.column_stack([5 * np.cos(angle), 3 * np.sin(angle), 0.1 * angle]) + wander
    estimate = truth + rng.normal(0.0, 0.02, truth.shape)
    quaternions = np.tile([0.0, 0.0, 0.0, 1.0], (poses, 1))
    paths = (folder / "long-groundtruth.txt", folder / "long-estimate.txt")
    for path, xyz in zip(paths, (truth, estimate), strict=True):
        np.savetxt(path, np.column_stack([stamps, xyz, quaternions]), fmt="%.6f")
    return paths


@pytest.mark.pdf
def test_server_killed_mid_job_finishes_it_after_a_restart(
    tmp_path: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    """SIGKILL while a job runs; after a restart (2 s lease) it runs again and succeeds."""
    data_dir = tmp_path_factory.mktemp("data")
    reference, estimate = _write_synthetic_pair(tmp_path, SYNTHETIC_POSES)
    first = start_server(data_dir)
    try:
        with first.client() as client:
            ref = upload(client, reference)
            est = upload(client, estimate)
            created = submit(client, {"dataset_id": ref["id"]}, [{"dataset_id": est["id"]}])
            running = wait_for_evaluation(
                client, created["id"], until=frozenset({"running"}), timeout=60, interval=0.05
            )
            assert running["attempts"] == 1
            answer = client.get(f"/api/v1/evaluations/{created['id']}/artifacts/result.json")
            assert answer.status_code == 409
            assert "poll" in answer.json()["detail"]
            answer = client.delete(f"/api/v1/datasets/{ref['id']}")
            assert answer.status_code == 409
            assert answer.json()["type"] == "conflict"
    finally:
        code = first.kill()
    killed_at = time.monotonic()
    assert code == -signal.SIGKILL, first.output
    assert not (data_dir / "evaluations" / created["id"] / "artifacts").exists()
    # The last heartbeat is at most the moment of the kill: wait out the restart's 2 s lease.
    time.sleep(max(0.0, 2.5 - (time.monotonic() - killed_at)))
    with (
        running_server(data_dir, api_key=first.api_key, env={"LOCEVAL_JOB_LEASE_S": "2"}) as second,
        second.client() as client,
    ):
        done = succeeded(wait_for_evaluation(client, created["id"]))
        assert done["attempts"] == 2
        assert len(done["artifacts"]) == len(ARTIFACTS)  # every artifact, paths.ifc included
        for artifact in done["artifacts"]:
            answer = client.get(artifact["url"])
            assert answer.status_code == 200, artifact["name"]
            assert len(answer.content) == artifact["size_bytes"] > 0
        assert done["result"]["estimates"][0]["matched"] == SYNTHETIC_POSES
    leftovers = [p.name for p in (data_dir / "evaluations" / created["id"]).iterdir()]
    assert leftovers == ["artifacts"]


def _incoming_parts(server: LiveServer) -> list[Path]:
    return sorted((server.data_dir / "incoming").glob("*.part"))


def test_upload_cut_off_mid_body_leaves_nothing(live_server: LiveServer) -> None:
    """A client that vanishes mid-upload leaves no dataset and no .part file behind."""
    lines = b"".join(f"{1000 + k * 0.01:.2f} {k} 0 0 0 0 0 1\n".encode() for k in range(80_000))
    # ~2.5 MB: the server writes it to incoming/ in 1 MB batches
    declared = len(lines) + 10_000_000
    with start_cut_upload(
        live_server,
        lines,
        declared=declared,
        filename="cut.txt",
        content_type="text/plain",
        timeout_s=10,
    ):
        assert wait_until(lambda: _incoming_parts(live_server), 10), (
            "the upload never reached incoming/"
        )
    assert wait_until(lambda: not _incoming_parts(live_server), 10), _incoming_parts(live_server)
    with live_server.client() as client:
        assert client.get("/api/v1/datasets").json() == {"items": [], "count": 0}
        assert client.get("/readyz").status_code == 200
    assert not any((live_server.data_dir / "datasets").iterdir())
