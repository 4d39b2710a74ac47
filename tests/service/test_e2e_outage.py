"""Backend outages: the API answers 503 and keeps the connection; no job is lost or run twice.

One ``loceval serve --no-consumer`` and two ``loceval worker`` processes run on a PostgreSQL
and a Redis of the test's own (:mod:`tests.harness.databases`), with the default lease, so
the faults can be real: the database is stopped, restarted after 6 s, Redis is restarted
without persistence (its queue comes back empty), a worker is killed with SIGKILL mid-job.
After each fault every job must succeed exactly once (one ``succeeded`` line in all the
workers' logs, and no second start except for the jobs of a killed worker) and the last one
must finish within 20 s of the fault's end. Each test prints ``tried / held / lost`` and the
recovery time (``pytest -s``).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import re
import signal
import socket
import sys
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
import pytest

from tests.conftest import skip_or_fail
from tests.harness import HarnessUnavailableError
from tests.harness.databases import OwnPostgres, OwnRedis
from tests.service.conftest import (
    LiveServer,
    ServiceProcess,
    service_env,
    start_server,
    submit,
    upload,
)

pytestmark = [pytest.mark.slow]

RECOVERY_LIMIT_S: Final = 20.0
JOBS: Final = 8  # two workers of two threads: four run, four wait in the queue
POSES: Final = 6_000  # a job of a second or two: long enough to be hit mid-run
DONE_TIMEOUT_S: Final = 120.0
_WORKERS: Final = 2
_WORKER_START_S: Final = 120.0


@dataclass
class Cluster:
    """The servers and processes of the module: faults are injected into them."""

    postgres: OwnPostgres
    redis: OwnRedis
    data_dir: Path
    env: dict[str, str]
    server: LiveServer
    workers: list[ServiceProcess] = field(default_factory=list)
    retired: list[ServiceProcess] = field(default_factory=list)
    datasets: tuple[str, str] = ("", "")

    def logs(self) -> str:
        """Every line the workers (the killed ones included) printed."""
        return "\n".join(w.output for w in [*self.retired, *self.workers])

    def ensure_workers(self) -> None:
        """Start workers until two run, and warm new ones up with a round of jobs.

        A new worker's job processes wait for its forkserver to import the evaluation
        modules (tens of seconds on a loaded machine): that start-up is not what a fault
        test measures.
        """
        self.workers = [w for w in self.workers if w.process.poll() is None]
        if len(self.workers) == _WORKERS:
            return
        while len(self.workers) < _WORKERS:
            worker = ServiceProcess.start(
                [sys.executable, "-m", "service.cli", "worker"],
                service_env(self.data_dir, self.env),
            )
            self.workers.append(worker)
            # Not start_worker's 30 s: on a loaded machine the imports alone take 15 s.
            if worker.wait_for_line(re.compile(r"^loceval worker: "), _WORKER_START_S) is None:
                pytest.fail(f"the worker did not start; its output:\n{worker.output}")
        for _ in range(4):  # until every worker has finished a job (its forkserver is warm)
            ids = _submit(self)
            rows = _wait_done(self, ids)
            assert all(rows[i][0] == "succeeded" for i in ids), rows
            if all('"event": "succeeded"' in w.output for w in self.workers):
                break


def _write_pair(folder: Path) -> tuple[Path, Path]:
    """A wiggly ground truth at 100 Hz and a noisy estimate of it, as TUM files."""
    rng = np.random.default_rng(29)
    stamps = 1.7e9 + 0.01 * np.arange(POSES)
    angle = np.linspace(0.0, 6.0 * np.pi, POSES)
    truth = np.column_stack([5 * np.cos(angle), 3 * np.sin(angle), 0.1 * angle])
    estimate = truth + rng.normal(0.0, 0.02, truth.shape)
    quaternions = np.tile([0.0, 0.0, 0.0, 1.0], (POSES, 1))
    paths = (folder / "outage-groundtruth.txt", folder / "outage-estimate.txt")
    for path, xyz in zip(paths, (truth, estimate), strict=True):
        np.savetxt(path, np.column_stack([stamps, xyz, quaternions]), fmt="%.6f")
    return paths


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Cluster]:
    """Own PostgreSQL and Redis, ``serve --no-consumer`` and two workers (default lease)."""
    try:
        postgres = OwnPostgres.create()
    except HarnessUnavailableError as err:
        skip_or_fail(str(err))
        raise  # unreachable: skip_or_fail raised
    redis = None
    server = None
    cluster = None
    try:
        redis = OwnRedis.create(tmp_path_factory.mktemp("redis"))
        data_dir = tmp_path_factory.mktemp("shared-data")
        env = {"LOCEVAL_DATABASE_URL": postgres.url, "LOCEVAL_QUEUE_URL": redis.url}
        server = start_server(data_dir, env=env, args=("--no-consumer",))
        cluster = Cluster(postgres, redis, data_dir, env, server)
        reference, estimate = _write_pair(tmp_path_factory.mktemp("input"))
        with server.client() as client:
            cluster.datasets = (upload(client, reference)["id"], upload(client, estimate)["id"])
        cluster.ensure_workers()
        yield cluster
    finally:
        if cluster is not None:
            for worker in cluster.workers:
                worker.stop()
        if server is not None:
            server.stop()
        if redis is not None:
            redis.stop()
        postgres.destroy()


# --- items 2 and 3: no job lost or run twice, recovery within 20 s -----------------------


def _rows(cluster: Cluster, ids: list[str]) -> dict[str, tuple[str, int, dt.datetime | None]]:
    """Each job's status, attempts and end, read straight from PostgreSQL."""
    import psycopg

    with psycopg.connect(cluster.postgres.dsn) as connection:
        found = connection.execute(
            "SELECT id, status, attempts, finished_at FROM evaluations WHERE id = ANY(%s)",
            (ids,),
        ).fetchall()
    return {str(r[0]): (str(r[1]), int(r[2]), r[3]) for r in found}


def _wait_done(cluster: Cluster, ids: list[str]) -> dict[str, tuple[str, int, dt.datetime | None]]:
    """Poll the rows (retrying through the outage) until every job has ended."""
    import psycopg

    deadline = time.monotonic() + DONE_TIMEOUT_S
    rows: dict[str, tuple[str, int, dt.datetime | None]] = {}
    while time.monotonic() < deadline:
        with contextlib.suppress(psycopg.OperationalError):
            rows = _rows(cluster, ids)
            if all(rows.get(i, ("",))[0] in {"succeeded", "failed"} for i in ids):
                return rows
        time.sleep(0.25)
    return rows


def _submit(cluster: Cluster, jobs: int = JOBS) -> list[str]:
    reference, estimate = cluster.datasets
    with cluster.server.client() as client:
        return [
            submit(
                client,
                {"dataset_id": reference},
                [{"dataset_id": estimate, "name": f"job {k}"}],
                {"formats": ["errors.csv"]},
            )["id"]
            for k in range(jobs)
        ]


def _wait_running(cluster: Cluster, ids: list[str], *, worker: int | None = None) -> None:
    """Wait until a job runs (on the worker of that pid, if given): the fault hits mid-job."""
    prefix = f"{socket.gethostname()}:{worker}:" if worker is not None else ""
    import psycopg

    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        with psycopg.connect(cluster.postgres.dsn) as connection:
            running = connection.execute(
                "SELECT count(*) FROM evaluations WHERE id = ANY(%s) AND status = 'running' "
                "AND worker LIKE %s",
                (ids, prefix + "%"),
            ).fetchone()
        if running is not None and running[0]:
            return
        time.sleep(0.05)
    pytest.fail(f"no job started within 60 s:\n{cluster.logs()}")


_EVENT = re.compile(r'^\{.*"event": "(started|succeeded|failed|deferred)".*\}$')


def _events(logs: str) -> Counter[tuple[str, str]]:
    """Count the (job id, transition) lines in the workers' JSON logs."""
    counts: Counter[tuple[str, str]] = Counter()
    for line in logs.splitlines():
        if _EVENT.match(line):
            record: dict[str, Any] = json.loads(line)
            counts[str(record["job_id"]), str(record["event"])] += 1
    return counts


def _judge(
    cluster: Cluster, fault: str, ids: list[str], fault_end: float, *, reruns: set[str]
) -> None:
    """Check every job succeeded exactly once, the last within 20 s of the fault's end."""
    rows = _wait_done(cluster, ids)
    time.sleep(1.0)  # let the workers' last log lines arrive
    events = _events(cluster.logs())
    held = [
        i
        for i in ids
        if rows.get(i, ("",))[0] == "succeeded"
        and events[i, "succeeded"] == 1
        and events[i, "failed"] == 0
        # a start put off by the outage before any work ("deferred") is not a run
        and (events[i, "started"] - events[i, "deferred"] == 1 or i in reruns)
    ]
    ends = [r[2].timestamp() for r in rows.values() if r[2] is not None]
    recovery = max(ends) - fault_end if ends else float("inf")
    print(  # noqa: T201  (the figures of the issue's note: pytest -s)
        f"\n{fault}: tried {len(ids)} / held {len(held)} / lost {len(ids) - len(held)}; "
        f"last job finished {recovery:.1f} s after the fault's end"
    )
    details = {
        i: (rows.get(i), {e: events[i, e] for e in ("started", "deferred", "succeeded")})
        for i in ids
    }
    missing = set(ids) - set(held)
    if missing:  # the whole story, for the one reading the failure (captured stdout)
        print("workers' logs:\n" + cluster.logs())  # noqa: T201
    said = [line for line in cluster.logs().splitlines() if any(i in line for i in missing)]
    assert held == ids, (
        {i: details[i] for i in missing},
        "\n".join(said)[-3000:],
    )
    assert recovery < RECOVERY_LIMIT_S, (recovery, details)
    assert "failed with a bug" not in cluster.logs()


def _held_by(cluster: Cluster, ids: list[str], worker: ServiceProcess) -> set[str]:
    """The jobs the (killed) worker holds as running in the database."""
    import psycopg

    prefix = f"{socket.gethostname()}:{worker.process.pid}:%"
    with psycopg.connect(cluster.postgres.dsn) as connection:
        rows = connection.execute(
            "SELECT id FROM evaluations WHERE id = ANY(%s) AND status = 'running' "
            "AND worker LIKE %s",
            (ids, prefix),
        ).fetchall()
    return {str(row[0]) for row in rows}


def test_worker_killed_mid_job_its_jobs_run_again_within_20_s(cluster: Cluster) -> None:
    """SIGKILL of a worker mid-job: its jobs are noticed (10 s lease) and run elsewhere."""
    cluster.ensure_workers()
    victim = cluster.workers[0]
    # One job per thread: what is timed is the killed worker's jobs coming back, not one
    # remaining worker draining a backlog alone.
    ids = _submit(cluster, 2 * _WORKERS)
    started = re.compile(rf"evaluation ({'|'.join(ids)}) started")
    if victim.wait_for_line(started, 60) is None:
        pytest.fail(f"the worker started no job within 60 s:\n{victim.output}")
    fault_end = time.time()  # the kill is the fault (kill() then waits for the pipes)
    victim.kill()
    cluster.workers.remove(victim)
    cluster.retired.append(victim)
    assert victim.process.returncode == -signal.SIGKILL
    mine = _events(victim.output)
    interrupted = {i for i in ids if mine[i, "started"] and not mine[i, "succeeded"]}
    interrupted |= _held_by(cluster, ids, victim)  # a claim whose log line was not read yet
    assert interrupted, victim.output
    _judge(cluster, "kill -9 of a worker", ids, fault_end, reruns=interrupted)
    rows = _rows(cluster, ids)
    assert all(rows[i][1] == 2 for i in interrupted), rows  # started again once
    assert all(rows[i][1] == 1 for i in set(ids) - interrupted), rows


def test_redis_restart_without_persistence_loses_no_job(cluster: Cluster) -> None:
    """Redis restarts empty: the queued jobs it lost are queued again and run once."""
    cluster.ensure_workers()
    ids = _submit(cluster)
    _wait_running(cluster, ids)
    cluster.redis.stop()
    time.sleep(1.0)
    cluster.redis.start()
    fault_end = time.time()
    _judge(cluster, "Redis restart without persistence", ids, fault_end, reruns=set())
    assert all(row[1] == 1 for row in _rows(cluster, ids).values())


def test_six_second_database_restart_loses_no_job(cluster: Cluster) -> None:
    """PostgreSQL away for 6 s: no message dropped, no job failed or run twice."""
    cluster.ensure_workers()
    ids = _submit(cluster)
    _wait_running(cluster, ids)
    cluster.postgres.stop(mode="immediate")
    time.sleep(6.0)
    cluster.postgres.start()
    fault_end = time.time()
    _judge(cluster, "6 s PostgreSQL restart", ids, fault_end, reruns=set())
    assert all(row[1] == 1 for row in _rows(cluster, ids).values())
    assert all(w.process.poll() is None for w in cluster.workers)


# --- item 1: 503 with Retry-After, the connection kept ------------------------------------


def _exchange(sock: socket.socket, request: bytes) -> tuple[int, dict[str, str], bytes]:
    """Send one HTTP/1.1 request on an open connection and read its whole response."""
    sock.sendall(request)
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(65536)
        if not chunk:
            msg = f"the server closed the connection; got {data!r}"
            raise ConnectionError(msg)
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = {k.strip().lower(): v.strip() for k, _, v in (h.partition(":") for h in lines[1:])}
    length = int(headers.get("content-length", "0"))
    while len(body) < length:
        chunk = sock.recv(65536)
        if not chunk:
            msg = "the server closed the connection mid-body"
            raise ConnectionError(msg)
        body += chunk
    return status, headers, body


def _request(method: str, path: str, port: int, key: str, body: bytes = b"") -> bytes:
    return (
        f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
        f"Authorization: Bearer {key}\r\nContent-Type: application/json\r\n"
        f"Content-Length: {len(body)}\r\n\r\n"
    ).encode() + body


def test_database_outage_is_503_with_retry_after_on_a_kept_connection(cluster: Cluster) -> None:
    """With PostgreSQL stopped every route answers 503 + Retry-After, never 500 or a reset."""
    server = cluster.server
    port = int(server.url.rsplit(":", 1)[1])
    key = server.api_key
    evaluation = json.dumps(
        {
            "reference": {"dataset_id": cluster.datasets[0]},
            "estimates": [{"dataset_id": cluster.datasets[1]}],
        }
    ).encode()
    requests = [
        ("GET", "/api/v1/datasets", b""),
        ("GET", "/api/v1/evaluations", b""),
        ("POST", "/api/v1/evaluations", evaluation),
        ("GET", "/api/v1/schedules", b""),
        ("GET", "/readyz", b""),
    ]
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        status, _, _ = _exchange(sock, _request("GET", "/api/v1/datasets", port, key))
        assert status == 200
        cluster.postgres.stop()
        try:
            for _ in range(2):  # each on the same connection: none may reset it
                for method, path, body in requests:
                    status, headers, content = _exchange(
                        sock, _request(method, path, port, key, body)
                    )
                    assert status == 503, (method, path, status, content)
                    assert headers["content-type"] == "application/problem+json"
                    assert int(headers["retry-after"]) > 0
                    assert headers.get("connection", "").lower() != "close"
                    problem = json.loads(content)
                    assert problem["type"] == "service.unavailable", problem
                    assert "cannot be reached" in problem["detail"]
                    assert "bug" not in problem["detail"]
        finally:
            cluster.postgres.start()
        status, _, _ = _exchange(sock, _request("GET", "/api/v1/datasets", port, key))
        assert status == 200
    assert "this is a bug" not in server.output
    assert "Unhandled error" not in server.output
