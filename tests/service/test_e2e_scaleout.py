"""Scale-out by settings only: PostgreSQL metadata, a Redis queue, separate worker processes.

``loceval serve --no-consumer`` takes the requests; two ``loceval worker`` processes with the
same settings and data folder run the jobs. Needs PostgreSQL (127.0.0.1:5432, user postgres,
trust auth, a database ``test`` to connect to) and Redis (127.0.0.1:6379); without them the
test is skipped (a failure when CI is set).
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from tests.service.conftest import (
    ServiceProcess,
    assert_same_ate,
    cli_json,
    start_server,
    start_worker,
    submit,
    succeeded,
    upload,
    wait_for_evaluation,
)

pytestmark = [pytest.mark.slow, pytest.mark.public_data]

GROUNDTRUTH = "freiburg1_xyz-groundtruth.txt"
ESTIMATE = "freiburg1_xyz-rgbdslam.txt"
JOBS = 4
WORKER_STOP_S = 20.0


def _workers_of(database_url: str) -> dict[str, str]:
    """Return each evaluation's ``worker`` column, read straight from PostgreSQL."""
    import psycopg

    dsn = database_url.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(dsn) as connection:
        rows = connection.execute("SELECT id, worker FROM evaluations").fetchall()
    return {str(row[0]): str(row[1]) for row in rows}


def _stop_worker(worker: ServiceProcess) -> tuple[int, float]:
    started = time.monotonic()
    code = worker.stop(timeout=WORKER_STOP_S)
    return code, time.monotonic() - started


@pytest.mark.pdf
def test_workers_run_the_jobs_of_a_server_without_consumer(
    tmp_path_factory: pytest.TempPathFactory,
    postgres_url: str,
    redis_url: str,
    public_data: Path,
) -> None:
    """serve --no-consumer + two workers on PostgreSQL and Redis: 4 jobs succeed like the CLI."""
    data_dir = tmp_path_factory.mktemp("shared-data")
    env = {"LOCEVAL_DATABASE_URL": postgres_url, "LOCEVAL_QUEUE_URL": redis_url}
    server = start_server(data_dir, env=env, args=("--no-consumer",))
    workers: list[ServiceProcess] = []
    try:
        assert "queue redis://" in server.output
        workers = [start_worker(data_dir, env) for _ in range(2)]
        with server.client() as client:
            ref = upload(client, public_data / GROUNDTRUTH)
            est = upload(client, public_data / ESTIMATE)
            created = [
                submit(
                    client,
                    {"dataset_id": ref["id"]},
                    [{"dataset_id": est["id"], "name": f"run {k}"}],
                )
                for k in range(JOBS)
            ]
            done = [succeeded(wait_for_evaluation(client, e["id"])) for e in created]
            answer = client.get(done[0]["artifacts"][0]["url"])
            assert answer.status_code == 200
            assert answer.json() == done[0]["result"]
    finally:
        stopped = [_stop_worker(w) for w in workers]
        server.stop()
    expected = cli_json(str(public_data / GROUNDTRUTH), str(public_data / ESTIMATE))
    for evaluation in done:
        assert_same_ate(evaluation["result"], expected)
        assert evaluation["attempts"] == 1
        assert {a["name"] for a in evaluation["artifacts"]} >= {"report.pdf", "paths.dxf"}
    host = socket.gethostname()
    worker_prefixes = {f"{host}:{w.process.pid}:" for w in workers}
    ran_on = _workers_of(postgres_url)
    assert set(ran_on) == {e["id"] for e in created}
    for worker_id in ran_on.values():
        assert worker_id.rsplit(":", 1)[0] + ":" in worker_prefixes, (worker_id, worker_prefixes)
    for (code, seconds), worker in zip(stopped, workers, strict=True):
        assert code == 0, f"worker exited {code} after {seconds:.1f} s:\n{worker.output}"
        assert seconds < WORKER_STOP_S
