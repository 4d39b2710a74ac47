"""Two "machines" that share nothing on disk: PostgreSQL, Redis and a bucket between them.

Machine A runs ``loceval serve --no-consumer`` on its own data folder, machine B a ``loceval
worker`` on another; neither sees the other's folder. Uploads go through A into the bucket, B
reads them from the bucket (its input cache) and writes the artifacts there, A streams them
back. Killing A mid-upload leaves no object and, after A's next start, no open multipart
upload; killing B mid-job loses nothing (the job runs again, and succeeds once); cutting B's
way to the bucket mid-job puts the job back in the queue, and it succeeds once the way is open.

Needs PostgreSQL (127.0.0.1:5432, user postgres, trust auth, a database ``test``: a fresh
database is created and dropped), Redis (127.0.0.1:6379: an empty database number is used and
only this test's keys are deleted) and SeaweedFS; each is skipped without (failed with CI set).
"""

from __future__ import annotations

import json
import signal
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.bagfactory import POSE, Poses, pose_records, random_poses, write_bag
from tests.factories import make_trajectory, perturb, write_tum
from tests.service._api_fixtures import schedule_body
from tests.service.blobs.conftest import Gate, SeaweedFS, object_keys, open_multipart_uploads
from tests.service.conftest import (
    LiveServer,
    ServiceProcess,
    assert_same_ate,
    cli_json,
    start_cut_upload,
    start_server,
    start_worker,
    submit,
    succeeded,
    upload,
    wait_for_evaluation,
    wait_until,
)

pytestmark = [pytest.mark.slow]


def _bag(path: Path, rng: np.random.Generator, *, noise: float) -> Path:
    truth = random_poses(rng, 150, dt_ns=50_000_000)
    moved = truth.positions + rng.normal(scale=noise, size=truth.positions.shape)
    records = pose_records("/gt", POSE, truth)
    records += pose_records("/est", POSE, Poses(truth.stamps_ns, moved, truth.quats))
    return write_bag(path, records, fmt="rosbag1")


def _local_blobs(folder: Path) -> list[str]:
    """Return the uploads and artifacts lying in a machine's data folder (none expected)."""
    found = []
    for sub in ("datasets", "evaluations", "runs", "incoming"):
        found += [str(p) for p in (folder / sub).rglob("*") if p.is_file()]
    return found


@pytest.fixture
def machines(
    tmp_path_factory: pytest.TempPathFactory,
    postgres_url: str,
    redis_url: str,
    seaweedfs: SeaweedFS,
    bucket: str,
) -> dict[str, Any]:
    """The shared settings (database, queue, bucket) and two separate data folders."""
    env = {
        "LOCEVAL_DATABASE_URL": postgres_url,
        "LOCEVAL_QUEUE_URL": redis_url,
        "LOCEVAL_BLOB_URL": f"s3://{bucket}/site-1",
        **seaweedfs.env(),
    }
    return {
        "env": env,
        "a": tmp_path_factory.mktemp("machine-a"),
        "b": tmp_path_factory.mktemp("machine-b"),
        "bucket": bucket,
    }


@pytest.mark.pdf
def test_upload_on_one_machine_evaluate_on_another(
    machines: dict[str, Any], seaweedfs: SeaweedFS, tmp_path: Path, rng: np.random.Generator
) -> None:
    """A recording and a schedule run: uploaded via A, run by B, downloaded via A."""
    env, bucket = machines["env"], machines["bucket"]
    truth = make_trajectory(rng, 300)
    reference = write_tum(tmp_path / "truth.txt", truth)
    estimate = write_tum(tmp_path / "slam.txt", perturb(truth, rng))
    server = start_server(machines["a"], env=env, args=("--no-consumer",))
    worker: ServiceProcess | None = None
    try:
        assert f"s3://{bucket}/site-1/" in server.output
        worker = start_worker(machines["b"], env)
        with server.client() as client:
            ref = upload(client, reference)
            est = upload(client, estimate)
            created = submit(client, {"dataset_id": ref["id"]}, [{"dataset_id": est["id"]}])
            done = succeeded(wait_for_evaluation(client, created["id"]))
            for artifact in done["artifacts"]:
                answer = client.get(artifact["url"])
                assert answer.status_code == 200, artifact["name"]
                assert len(answer.content) == artifact["size_bytes"] > 0
            assert client.get(done["artifacts"][0]["url"].replace("report.html", "result.json"))
            for k in range(2):
                bag = _bag(tmp_path / f"level2-run{k}.bag", rng, noise=0.02 * (k + 1))
                upload(client, bag, tags="level2")
            schedule = client.post("/api/v1/schedules", json=schedule_body()).json()
            started = client.post(f"/api/v1/schedules/{schedule['id']}/run")
            assert started.status_code == 202, started.text
            run = _wait_for_run(client, schedule["id"])
            assert run["status"] == "succeeded", run
            assert len(run["rows"]) == 2
            pdf = client.get(
                f"/api/v1/schedules/{schedule['id']}/runs/{run['id']}/artifacts/summary.pdf"
            )
            assert pdf.status_code == 200
            assert pdf.content.startswith(b"%PDF")
            ready = client.get("/readyz").json()
            assert ready["store"] == "s3"
    finally:
        if worker is not None:
            worker.stop()
        server.stop()
    assert_same_ate(done["result"], cli_json(str(reference), str(estimate)))
    assert _local_blobs(machines["a"]) == []
    assert _local_blobs(machines["b"]) == []
    cached = [p for p in (machines["b"] / "cache").rglob("*") if p.is_file() and p.name != ".lock"]
    assert {p.name for p in cached} >= {"truth.txt", "slam.txt", "level2-run0.bag"}
    assert not (machines["a"] / "cache").exists() or all(
        p.name.endswith((".txt", ".bag", ".lock")) for p in (machines["a"] / "cache").rglob("*.*")
    )
    keys = object_keys(seaweedfs, bucket, "site-1/")
    assert f"site-1/evaluations/{created['id']}/artifacts/report.pdf" in keys
    assert f"site-1/runs/{run['id']}/artifacts/summary.pdf" in keys
    assert not [k for k in keys if k.startswith("site-1/incoming/")]


def _wait_for_run(client: Any, schedule_id: str, timeout: float = 240) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    runs: list[dict[str, Any]] = []
    while time.monotonic() < deadline:
        runs = client.get(f"/api/v1/schedules/{schedule_id}/runs").json()["items"]
        if runs and runs[0]["status"] in {"succeeded", "failed"}:
            return runs[0]
        time.sleep(0.3)
    pytest.fail(f"no finished run of {schedule_id} within {timeout} s: {runs}")


def _start_upload(server: LiveServer, size: int) -> socket.socket:
    """Send the first ``size`` bytes of a much larger upload and keep the connection open."""
    body = np.random.default_rng(7).bytes(size)
    return start_cut_upload(
        server, body, declared=size * 4, filename="big.txt", content_type="text/plain"
    )


def test_api_killed_mid_upload_leaves_no_object_and_no_open_upload(
    machines: dict[str, Any], seaweedfs: SeaweedFS
) -> None:
    """SIGKILL while 40 MB of an upload have streamed into the bucket; restart; all clean."""
    env, bucket = machines["env"], machines["bucket"]
    first = start_server(machines["a"], env=env, args=("--no-consumer",))
    sock: socket.socket | None = None
    try:
        sock = _start_upload(first, 40 << 20)
        assert wait_until(lambda: open_multipart_uploads(seaweedfs, bucket), 60), (
            "the upload never reached the bucket"
        )
    finally:
        code = first.kill()
        if sock is not None:
            sock.close()
    assert code == -signal.SIGKILL, first.output
    assert object_keys(seaweedfs, bucket, "site-1/uploads/") == []
    assert open_multipart_uploads(seaweedfs, bucket) != []  # the crash left it open ...
    second = start_server(machines["a"], api_key=first.api_key, env=env, args=("--no-consumer",))
    try:
        assert open_multipart_uploads(seaweedfs, bucket) == []  # ... the next start aborted it
        assert "partial uploads and 0 unrecorded dataset folders left by processes" in second.output
        with second.client() as client:
            assert client.get("/api/v1/datasets").json()["count"] == 0
    finally:
        second.stop()
    assert object_keys(seaweedfs, bucket) == []


def _read_answer(sock: socket.socket) -> tuple[int, bytes]:
    """Read one HTTP/1.1 answer with a Content-Length: its status and body."""
    data = b""
    while b"\r\n\r\n" not in data:
        data += sock.recv(65536)
    head, body = data.split(b"\r\n\r\n", 1)
    lines = head.decode("latin-1").split("\r\n")
    length = next(
        int(v) for k, _, v in (x.partition(":") for x in lines[1:]) if k.lower() == "content-length"
    )
    while len(body) < length:
        body += sock.recv(65536)
    return int(lines[0].split()[1]), body


def test_a_second_api_on_the_same_host_keeps_the_first_ones_upload(
    machines: dict[str, Any], seaweedfs: SeaweedFS, tmp_path: Path, rng: np.random.Generator
) -> None:
    """API A is mid-upload when API B (same host name, its own folder) starts and sweeps:
    A's multipart upload stays open, and A completes it into a dataset."""
    import json

    env, bucket = machines["env"], machines["bucket"]
    content = write_tum(tmp_path / "long.txt", make_trajectory(rng, 150_000)).read_bytes()
    assert len(content) > 10 << 20  # more than one 8 MiB part
    boundary = "loceval-two-apis"
    head = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="long.txt"\r\n'
        "Content-Type: text/plain\r\n\r\n"
    ).encode()
    body = head + content + f"\r\n--{boundary}--\r\n".encode()
    first = start_server(machines["a"], env=env, args=("--no-consumer",))
    second: LiveServer | None = None
    try:
        port = int(first.url.rsplit(":", 1)[1])
        request = (
            "POST /api/v1/datasets HTTP/1.1\r\n"
            f"Host: 127.0.0.1:{port}\r\n"
            f"Authorization: Bearer {first.api_key}\r\n"
            f"Content-Type: multipart/form-data; boundary={boundary}\r\n"
            f"Content-Length: {len(body)}\r\n\r\n"
        ).encode()
        with socket.create_connection(("127.0.0.1", port), timeout=120) as sock:
            sock.sendall(request + body[: 10 << 20])
            assert wait_until(lambda: open_multipart_uploads(seaweedfs, bucket), 60), (
                "the upload never reached the bucket"
            )
            second = start_server(
                machines["b"], api_key=first.api_key, env=env, args=("--no-consumer",)
            )
            assert "0 partial uploads" not in second.output  # nothing was swept: no line
            assert open_multipart_uploads(seaweedfs, bucket) != []  # A's upload is still open
            sock.sendall(body[10 << 20 :])
            status, answer = _read_answer(sock)
        assert status == 201, answer
        dataset = json.loads(answer)
        assert dataset["inspection"]["sources"][0]["pose_count"] == 150_000
        with second.client() as client:  # B sees the dataset A stored
            assert client.get(f"/api/v1/datasets/{dataset['id']}").status_code == 200
    finally:
        if second is not None:
            second.stop()
        first.stop()
    assert open_multipart_uploads(seaweedfs, bucket) == []
    assert [k for k in object_keys(seaweedfs, bucket) if "/pending/" in k] == []


@pytest.mark.pdf
def test_worker_killed_mid_job_loses_nothing(
    machines: dict[str, Any], tmp_path: Path, rng: np.random.Generator
) -> None:
    """SIGKILL the worker while a job runs; a new worker runs it again; it succeeds once."""
    env = {**machines["env"], "LOCEVAL_JOB_LEASE_S": "2"}
    truth = make_trajectory(rng, 30_000)
    reference = write_tum(tmp_path / "truth.txt", truth)
    estimate = write_tum(tmp_path / "slam.txt", perturb(truth, rng))
    server = start_server(machines["a"], env=env, args=("--no-consumer",))
    try:
        first = start_worker(machines["b"], env)
        with server.client() as client:
            ref = upload(client, reference)
            est = upload(client, estimate)
            created = submit(client, {"dataset_id": ref["id"]}, [{"dataset_id": est["id"]}])
            running = wait_for_evaluation(
                client, created["id"], until=frozenset({"running"}), timeout=120, interval=0.05
            )
            assert running["attempts"] == 1
            assert first.kill() == -signal.SIGKILL
            time.sleep(2.5)  # the dead worker's heartbeat is older than the 2 s lease now
            second = start_worker(machines["b"], env)
            try:
                done = succeeded(wait_for_evaluation(client, created["id"], timeout=300))
            finally:
                second.stop()
            assert done["attempts"] == 2
            for artifact in done["artifacts"]:
                answer = client.get(artifact["url"])
                assert answer.status_code == 200, artifact["name"]
                assert len(answer.content) == artifact["size_bytes"] > 0
            assert done["result"]["estimates"][0]["matched"] == 30_000
    finally:
        server.stop()
    assert _local_blobs(machines["b"]) == []
    assert not any((machines["b"] / "staging").rglob("*.json"))


def test_a_store_outage_puts_the_job_back_and_it_succeeds_once_the_store_returns(
    machines: dict[str, Any], seaweedfs: SeaweedFS, tmp_path: Path, rng: np.random.Generator
) -> None:
    """The worker's way to the bucket is cut while it fetches a job's inputs: the job goes
    back to the queue (not failed, the attempt not counted) and succeeds once it is back."""
    gate = Gate(seaweedfs)
    truth = make_trajectory(rng, 500)
    reference = write_tum(tmp_path / "truth.txt", truth)
    estimate = write_tum(tmp_path / "slam.txt", perturb(truth, rng))
    server = start_server(machines["a"], env=machines["env"], args=("--no-consumer",))
    worker: ServiceProcess | None = None
    try:
        worker = start_worker(machines["b"], {**machines["env"], "AWS_ENDPOINT_URL": gate.endpoint})
        with server.client() as client:
            ref = upload(client, reference)
            est = upload(client, estimate)
            gate.shut()
            created = submit(client, {"dataset_id": ref["id"]}, [{"dataset_id": est["id"]}])
            url = f"/api/v1/evaluations/{created['id']}"

            def put_back() -> bool:
                seen = client.get(url).json()
                assert seen["status"] in {"queued", "running"}, seen  # never failed
                return "object store could not be reached" in seen["progress"]["stage"]

            assert wait_until(put_back, timeout=120), client.get(url).json()
            waiting = client.get(url).json()
            assert waiting["attempts"] == 0  # the outage's run is not counted
            gate.open()
            done = succeeded(wait_for_evaluation(client, created["id"], timeout=240))
            assert done["attempts"] == 1
            assert done["result"]["estimates"][0]["matched"] == 500
    finally:
        gate.shut()
        if worker is not None:
            worker.stop()
        server.stop()
    events = [json.loads(line) for line in worker.lines if line.startswith("{")]
    deferred = [e for e in events if e.get("event") == "deferred"]
    assert deferred, "the worker logged no deferral"
    assert {e["error"] for e in deferred} == {"StoreUnavailableError"}
    assert not [e for e in events if e["level"] == "error" or "Traceback" in e["message"]]
