"""Benchmark: a large bag uploaded through the API and evaluated by a worker, folder vs bucket.

Run by hand (not a test; needs PostgreSQL on 127.0.0.1:5432 as postgres, Redis on
127.0.0.1:6379, and SeaweedFS's ``weed`` from the dev extra):

    .venv/bin/python -m benchmarks.object_store [--size-mb 2000] [--backends local,s3]
        [--repeats 3] [--upload-only] [--code after=. --code before=/tmp/loceval-main]

For each backend it starts ``loceval serve --no-consumer`` and one ``loceval worker`` on a
fresh PostgreSQL database and an empty Redis database number (both removed afterwards):

- ``local``: API and worker share one data folder (the NFS-style deployment on one machine);
- ``s3``: API and worker have separate data folders and share a bucket of a SeaweedFS
  started on loopback ports for the run (``weed server -s3``, its data in the work folder).

It uploads one generated ROS 2 MCAP bag (``benchmarks.bags.generate_bag``: tf at 120 Hz,
640x480 images at 15 Hz; cached in ``benchmarks/_work/object_store``), streaming it from disk,
then evaluates ``tf:odom:base_link`` against ``tf:map:base_link`` of it (result.json only),
and prints per backend: upload time and throughput, the job's time (queue to succeeded,
including whatever the worker fetches from the store), the peak RSS growth of the API's and
the worker's process trees (the job's own process included) over their idle baseline, and the
CPU seconds the API's process tree and SeaweedFS spent during the upload.

With the bucket, the same run also uploads the bag with a bare boto3 client
(``upload_file``, default ``TransferConfig``) into the same store, before the API's upload in
odd rounds and after it in even ones, so the two meet the same store and machine load.

SeaweedFS runs on the same machine: it takes about 19-21 CPU seconds per 2 GB (a bare boto3
upload of the bag, no loceval involved, takes 11 s on two vCPUs), so on a small machine the
bucket's throughput is bound by the store's CPU, which the API's upload competes with; in a
deployment the store runs elsewhere.

With ``--code LABEL=DIR`` (repeatable) the service runs from each source tree in turn
(``PYTHONPATH=DIR``, the same virtual environment): a before/after comparison in one run.
The runs are interleaved (every code and backend once per round, ``--repeats`` rounds), since
the machine's load changes over minutes, and the medians are printed.

Targets (issue 26): the bucket's upload throughput at least half the folder's; memory flat in
the file's size (the API's growth well under the file's size). Issue 40: the API's upload into
the bucket at least 0.8 of the bare boto3 upload's throughput, and the evaluation job from the
bucket within 1.5x of the same job from the folder; both ratios are printed from the medians.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx2 as httpx
from boto3.s3.transfer import TransferConfig

from benchmarks.upload_load import RssSampler, _descendants, prepare_recordings
from tests.harness.databases import SHARED_REDIS, empty_redis_database, fresh_database
from tests.harness.ports import free_port
from tests.harness.processes import ServiceProcess, wait_ready
from tests.harness.seaweedfs import SeaweedFS, running_seaweedfs

POSTGRES = "host=127.0.0.1 port=5432 user=postgres dbname=postgres connect_timeout=5"
REDIS = SHARED_REDIS
BASELINE_S = 2.0
_MB = 1_000_000
_CREDENTIALS = {"AWS_ACCESS_KEY_ID": "bench", "AWS_SECRET_ACCESS_KEY": "bench-secret"}


@dataclass
class Figures:
    backend: str
    size_bytes: int
    upload_s: float
    job_s: float
    api_idle_mib: float
    api_peak_mib: float
    worker_idle_mib: float
    worker_peak_mib: float
    status: str
    api_cpu_s: float = 0.0
    store_cpu_s: float = 0.0
    boto3_s: float | None = None
    """A bare boto3 upload of the same file into the same store (s3 only), same run."""
    boto3_store_cpu_s: float = 0.0


def _loceval() -> str:
    return str(Path(sys.executable).with_name("loceval"))


@contextlib.contextmanager
def _process(argv: list[str], env: dict[str, str], log: Path) -> Iterator[ServiceProcess]:
    """Run a service process (its own process group, its output in ``log``); always stop it."""
    process = ServiceProcess.start(argv, env, cwd=None, log=log, own_session=True)
    try:
        yield process
    finally:
        process.stop(timeout=30)


def _cpu_s(root: int | None) -> float:
    """Return the CPU seconds (user + system) a process tree has used so far (0: no tree)."""
    if root is None:
        return 0.0
    ticks = 0
    for pid in _descendants(root):
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended meanwhile
            continue
        ticks += int(fields[11]) + int(fields[12])  # utime, stime
    return ticks / os.sysconf("SC_CLK_TCK")


def _peak(sampler: RssSampler, start: float, end: float) -> float:
    window = sampler.window(start, end)
    return max((s.rss_mib for s in window), default=0.0)


def _boto3_upload(store: SeaweedFS, bucket: str, bag: Path) -> tuple[float, float]:
    """Upload ``bag`` with a bare boto3 client (default TransferConfig).

    Returns:
        The seconds it took and the store's CPU seconds meanwhile.
    """
    client = store.client()
    cpu = _cpu_s(store.process.pid)
    start = time.perf_counter()
    client.upload_file(str(bag), bucket, f"boto3/{bag.name}", Config=TransferConfig())
    elapsed = time.perf_counter() - start
    cpu = _cpu_s(store.process.pid) - cpu
    client.delete_object(Bucket=bucket, Key=f"boto3/{bag.name}")
    return elapsed, cpu


def _evaluate(http: httpx.Client, dataset: str) -> tuple[float, str]:
    """Evaluate the bag's two tf chains (result.json only); return when it ended and how."""
    body: dict[str, Any] = {
        "reference": {"dataset_id": dataset, "selector": "tf:map:base_link"},
        "estimates": [{"dataset_id": dataset, "selector": "tf:odom:base_link"}],
        "options": {"formats": ["result.json"], "max_dt_s": 0.001},
    }
    created = http.post("/api/v1/evaluations", json=body)
    if created.status_code != 202:
        msg = f"evaluation: {created.status_code} {created.text[:500]}"
        raise RuntimeError(msg)
    evaluation_id = created.json()["id"]
    status = "queued"
    while status not in {"succeeded", "failed"}:
        time.sleep(0.1)
        status = http.get(f"/api/v1/evaluations/{evaluation_id}").json()["status"]
    return time.perf_counter(), status


def _bucket(
    stack: contextlib.ExitStack, folder: Path, env: dict[str, str]
) -> tuple[SeaweedFS, str]:
    """Start a SeaweedFS for the run, make a bucket, point ``env`` at it; return both."""
    store = stack.enter_context(
        running_seaweedfs(
            folder / "seaweedfs",
            volume_size_mb=1024,
            volume_max=200,
            credentials=_CREDENTIALS,
            own_session=True,
        )
    )
    bucket = store.new_bucket("bench")
    env.update(store.env(), LOCEVAL_BLOB_URL=f"s3://{bucket}/bench")
    return store, bucket


def run_backend(
    backend: str,
    bag: Path,
    work: Path,
    *,
    code: Path | None = None,
    evaluate: bool = True,
    boto3_first: bool = True,
) -> Figures:
    """Upload and evaluate ``bag`` with one backend; return the figures.

    Args:
        backend: ``local`` or ``s3``.
        bag: the recording.
        work: a folder for the data folders, logs and SeaweedFS.
        code: run the service from this source tree (None: the installed one).
        evaluate: also evaluate it (else only the upload is timed).
        boto3_first: with the bucket, the bare boto3 upload goes before the API's (else
            after it; the rounds alternate, so neither always meets a fresher store).
    """
    folder = work / backend
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    with contextlib.ExitStack() as stack:
        database = stack.enter_context(fresh_database(POSTGRES, prefix="loceval_bench"))
        queue = stack.enter_context(empty_redis_database(REDIS))
        env = {k: v for k, v in os.environ.items() if not k.startswith(("LOCEVAL_", "AWS_"))}
        env.update(
            LOCEVAL_DATABASE_URL=database,
            LOCEVAL_QUEUE_URL=queue,
            LOCEVAL_WORKERS="1",
            LOCEVAL_MAX_UPLOAD_BYTES=str(8 << 30),
            LOCEVAL_JOB_TIMEOUT_S="3600",
            LOCEVAL_JOB_MEMORY_MB="0",
        )
        if code is not None:
            env["PYTHONPATH"] = str(code.resolve())
        api_dir, worker_dir = folder / "api", folder / "api"
        store, bucket = _bucket(stack, folder, env) if backend == "s3" else (None, "")
        store_pid = None if store is None else store.process.pid
        if store is not None:
            worker_dir = folder / "worker"
        port = free_port()
        url = f"http://127.0.0.1:{port}"
        api_env = {**env, "LOCEVAL_DATA_DIR": str(api_dir), "LOCEVAL_PUBLIC_URL": url}
        api = stack.enter_context(
            _process(
                [_loceval(), "serve", "--port", str(port), "--no-consumer"],
                api_env,
                folder / "api.log",
            )
        )
        wait_ready(url, api, timeout=120.0)
        key = subprocess.run(
            [_loceval(), "keys", "create", "--project", "bench"],
            env=api_env,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        worker = stack.enter_context(
            _process(
                [_loceval(), "worker"],
                {**env, "LOCEVAL_DATA_DIR": str(worker_dir)},
                folder / "worker.log",
            )
        )
        api_rss, worker_rss = RssSampler(api.pid), RssSampler(worker.pid)
        api_rss.start()
        worker_rss.start()
        stack.callback(api_rss.stop)
        stack.callback(worker_rss.stop)
        time.sleep(BASELINE_S + 3)  # the worker warms up its job process meanwhile
        idle_end = time.perf_counter()
        boto3_s, boto3_cpu = None, 0.0
        if store is not None and boto3_first:
            boto3_s, boto3_cpu = _boto3_upload(store, bucket, bag)
        timeout = httpx.Timeout(connect=30.0, read=3600.0, write=3600.0, pool=30.0)
        headers = {"Authorization": f"Bearer {key}"}
        with httpx.Client(base_url=url, headers=headers, timeout=timeout) as http:
            with bag.open("rb") as fh:
                cpu = _cpu_s(api.pid), _cpu_s(store_pid)
                start = time.perf_counter()
                answer = http.post(
                    "/api/v1/datasets",
                    files={"file": (bag.name, fh, "application/octet-stream")},
                )
                uploaded = time.perf_counter()
                api_cpu, store_cpu = _cpu_s(api.pid) - cpu[0], _cpu_s(store_pid) - cpu[1]
            if answer.status_code != 201:
                msg = f"upload: {answer.status_code} {answer.text[:500]}"
                raise RuntimeError(msg)
            dataset = answer.json()["id"]
            if store is not None and not boto3_first:
                boto3_s, boto3_cpu = _boto3_upload(store, bucket, bag)
            evaluated = time.perf_counter()
            finished, status = _evaluate(http, dataset) if evaluate else (evaluated, "uploaded")
        return Figures(
            backend,
            bag.stat().st_size,
            uploaded - start,
            finished - evaluated,
            _peak(api_rss, idle_end - BASELINE_S, idle_end),
            _peak(api_rss, start, uploaded),
            _peak(worker_rss, idle_end - BASELINE_S, idle_end),
            _peak(worker_rss, evaluated, finished),
            status,
            api_cpu,
            store_cpu,
            boto3_s,
            boto3_cpu,
        )


def _print_ratios(
    label: str, results: dict[tuple[str, str], list[Figures]], *, evaluated: bool
) -> None:
    """Print the bucket's two ratios of one source tree, from the medians of its rounds."""
    local, s3 = results.get((label, "local"), []), results.get((label, "s3"), [])
    name = label or "-"
    if local and s3:
        ratio = statistics.median(f.upload_s for f in local) / statistics.median(
            f.upload_s for f in s3
        )
        print(f"{name}: bucket upload throughput / folder's: {ratio:.2f} (issue 26: >= 0.5)")
    if s3:
        api_s = statistics.median(f.upload_s for f in s3)
        boto3_s = statistics.median(f.boto3_s or 0.0 for f in s3)
        print(
            f"{name}: upload into the bucket: API {api_s:.1f} s, bare boto3 {boto3_s:.1f} s; "
            f"API time / boto3 time {api_s / boto3_s:.2f}, API throughput / boto3's "
            f"{boto3_s / api_s:.2f} (target >= 0.8)"
        )
    if local and s3 and evaluated:
        folder_s = statistics.median(f.job_s for f in local)
        bucket_s = statistics.median(f.job_s for f in s3)
        print(
            f"{name}: evaluation job: bucket {bucket_s:.1f} s, folder {folder_s:.1f} s; "
            f"bucket / folder {bucket_s / folder_s:.2f} (target <= 1.5)"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size-mb", type=float, default=2000.0)
    parser.add_argument("--backends", default="local,s3")
    parser.add_argument("--workdir", type=Path, default=Path("benchmarks/_work/object_store"))
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--upload-only", action="store_true", help="time the upload only")
    parser.add_argument(
        "--code", action="append", default=[], metavar="LABEL=DIR", help="a source tree to run"
    )
    args = parser.parse_args(argv)
    args.workdir = args.workdir.resolve()  # SeaweedFS runs in its own folder
    codes: list[tuple[str, Path | None]] = [
        (label, Path(folder)) for label, _, folder in (c.partition("=") for c in args.code)
    ] or [("", None)]
    [recording] = prepare_recordings(args.workdir / "bags", args.size_mb, 1)
    results: dict[tuple[str, str], list[Figures]] = {}
    for round_ in range(args.repeats):
        for label, code in codes:
            for backend in args.backends.split(","):
                figures = run_backend(
                    backend,
                    recording.path,
                    args.workdir / "runs",
                    code=code,
                    evaluate=not args.upload_only,
                    boto3_first=round_ % 2 == 0,
                )
                results.setdefault((label, backend), []).append(figures)
                print(
                    f"round {round_ + 1} {label or '-'} {backend}: upload {figures.upload_s:.1f} s "
                    f"({figures.size_bytes / _MB / figures.upload_s:.1f} MB/s), "
                    f"API peak {figures.api_peak_mib:.0f} MiB, CPU s: API "
                    f"{figures.api_cpu_s:.1f}, store {figures.store_cpu_s:.1f}; "
                    f"job {figures.job_s:.1f} s; {figures.status}"
                    + (
                        ""
                        if figures.boto3_s is None
                        else f"; bare boto3 upload {figures.boto3_s:.1f} s "
                        f"(store CPU {figures.boto3_store_cpu_s:.1f} s)"
                    ),
                    flush=True,
                )
    size_mb = recording.size_bytes / _MB
    print(f"\nbag: {size_mb:,.0f} MB ({recording.path.name}); medians of {args.repeats}")
    print(
        f"{'code':8} {'backend':8} {'upload s':>9} {'MB/s':>7} {'job s':>7} "
        f"{'API idle→peak MiB':>19} {'worker idle→peak MiB':>22} {'API CPU s':>10} "
        f"{'store CPU s':>12}"
    )
    medians: dict[tuple[str, str], float] = {}
    for (label, backend), runs in results.items():
        upload_s = statistics.median(f.upload_s for f in runs)
        medians[label, backend] = upload_s
        size = runs[0].size_bytes
        print(
            f"{label or '-':8} {backend:8} {upload_s:9.1f} {size / _MB / upload_s:7.1f} "
            f"{statistics.median(f.job_s for f in runs):7.1f} "
            f"{statistics.median(f.api_idle_mib for f in runs):8.0f} → "
            f"{statistics.median(f.api_peak_mib for f in runs):6.0f}   "
            f"{statistics.median(f.worker_idle_mib for f in runs):9.0f} → "
            f"{statistics.median(f.worker_peak_mib for f in runs):7.0f} "
            f"{statistics.median(f.api_cpu_s for f in runs):10.1f} "
            f"{statistics.median(f.store_cpu_s for f in runs):12.1f}"
        )
    for label, _ in codes:
        _print_ratios(label, results, evaluated=not args.upload_only)
    shutil.rmtree(args.workdir / "runs", ignore_errors=True)
    ok = {"succeeded", "uploaded"}
    return 0 if all(f.status in ok for runs in results.values() for f in runs) else 1


if __name__ == "__main__":
    raise SystemExit(main())
