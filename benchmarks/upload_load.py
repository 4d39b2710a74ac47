"""Load test: concurrent large uploads to the real ``loceval serve`` process, watching its RSS.

Run by hand (not a test):

    .venv/bin/python -m benchmarks.upload_load [--size-mb 500] [--clients 10] [--keep-data]

What it does:

1. Generates, once, one valid ROS 2 MCAP recording per client in ``benchmarks/_work/upload_load``
   (``benchmarks.bags.generate_bag``: tf at 120 Hz, 640x480 rgb8 images at 15 Hz). The server
   deduplicates uploads by SHA-256 within a project, so identical bytes would make every upload
   after the first a cheap 200. Padding a copy would corrupt the MCAP, so instead client k's bag
   is recorded k/15 s longer than the first: k more images, a different SHA-256, every upload a
   real, readable recording of about ``--size-mb`` MB. Sizes and SHA-256 are cached in
   ``manifest.json`` next to the bags and reused by later runs.
2. Starts ``.venv/bin/loceval serve`` on a free port with ``LOCEVAL_DATA_DIR`` in a fresh
   directory under the work folder, waits for ``/readyz`` and creates an API key with
   ``loceval keys create --project bench``.
3. Samples the RSS of the server process and all its descendants (``VmRSS`` and ``RssAnon``
   of ``/proc/<pid>/status``) every 50 ms: idle for a baseline, then during the uploads.
4. Uploads with ``--clients`` concurrent httpx2 clients (one thread each, started together),
   ``POST /api/v1/datasets`` multipart, streaming each file from disk in 64 KiB chunks: httpx2
   reads a file object passed in ``files=`` chunk by chunk and sends a Content-Length.
5. Prints one row per upload, the RSS figures and throughput, and a last line with the RSS
   growth against the target. Stops the server (and removes its data directory unless
   ``--keep-data``) even on errors or Ctrl-C.

Target: RSS growth (peak during uploads - idle baseline) < 100 MiB, every status 201.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx2 as httpx

from benchmarks.bags import IMAGE_HZ, generate_bag
from tests.harness.ports import free_port
from tests.harness.processes import RunningService, ServiceProcess, wait_ready

TARGET_GROWTH_MIB = 100.0
SAMPLE_INTERVAL_S = 0.05
BASELINE_S = 3.0
SETTLE_S = 3.0
CALIBRATION_IMAGES = 30
_MIB = 1 << 20
_MB = 1_000_000
_HASH_CHUNK = 1 << 20


# --------------------------------------------------------------------------- recordings


@dataclass(frozen=True)
class Recording:
    path: Path
    size_bytes: int
    sha256: str
    images: int


def _seconds_for(images: int) -> float:
    # generate_bag writes int(seconds * IMAGE_HZ) images; the half image keeps float rounding
    # from losing one.
    return (images + 0.5) / IMAGE_HZ


def _generate_mcap(target: Path, images: int) -> None:
    """Write a standalone .mcap file with ``images`` images at ``target`` (atomically)."""
    with tempfile.TemporaryDirectory(prefix="gen-", dir=target.parent) as tmp:
        mcap = generate_bag(Path(tmp) / "bag", seconds=_seconds_for(images))
        mcap.replace(target)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        while chunk := fh.read(_HASH_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def _bytes_per_image(folder: Path, manifest: dict[str, Any]) -> float:
    """Measure (once, then cached) how many bytes one more image adds to the bag."""
    cached = manifest.get("bytes_per_image")
    if isinstance(cached, float):
        return cached
    small, large = folder / "calibrate_a.mcap", folder / "calibrate_b.mcap"
    _generate_mcap(small, CALIBRATION_IMAGES)
    _generate_mcap(large, 2 * CALIBRATION_IMAGES)
    per_image = (large.stat().st_size - small.stat().st_size) / CALIBRATION_IMAGES
    small.unlink()
    large.unlink()
    manifest["bytes_per_image"] = per_image
    return per_image


def prepare_recordings(folder: Path, size_mb: float, clients: int) -> list[Recording]:
    """Return ``clients`` distinct valid MCAP files of about ``size_mb`` MB, generating them."""
    folder.mkdir(parents=True, exist_ok=True)
    manifest_path = folder / "manifest.json"
    manifest: dict[str, Any] = (
        json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    )
    files: dict[str, dict[str, Any]] = manifest.setdefault("files", {})
    per_image = _bytes_per_image(folder, manifest)
    base_images = max(1, round(size_mb * _MB / per_image))
    recordings = []
    for k in range(clients):
        images = base_images + k
        path = folder / f"upload_{images}img.mcap"
        entry = files.get(path.name)
        if not (entry and path.is_file() and path.stat().st_size == entry["size_bytes"]):
            print(f"generating {path} ({images} images) ...", flush=True)
            start = time.perf_counter()
            _generate_mcap(path, images)
            entry = {"size_bytes": path.stat().st_size, "sha256": _sha256(path), "images": images}
            files[path.name] = entry
            manifest_path.write_text(json.dumps(manifest, indent=2))
            print(f"  {entry['size_bytes'] / _MB:.1f} MB in {time.perf_counter() - start:.1f} s")
        recordings.append(Recording(path, entry["size_bytes"], entry["sha256"], images))
    manifest_path.write_text(json.dumps(manifest, indent=2))
    return recordings


# --------------------------------------------------------------------------- RSS sampling


def _descendants(root: int) -> list[int]:
    """Return ``root`` and every process below it, from the ppid fields of /proc/*/stat."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # the process ended while we looked
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    found, todo = [], [root]
    while todo:
        pid = todo.pop()
        found.append(pid)
        todo.extend(children.get(pid, []))
    return found


def _rss_kib(pid: int) -> tuple[int, int]:
    """Return (VmRSS, RssAnon) of one process in KiB, zeros when it is gone."""
    rss = anon = 0
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0, 0
    for line in text.splitlines():
        if line.startswith("VmRSS:"):
            rss = int(line.split()[1])
        elif line.startswith("RssAnon:"):
            anon = int(line.split()[1])
    return rss, anon


@dataclass(frozen=True)
class Sample:
    t: float
    rss_mib: float
    anon_mib: float
    processes: int


@dataclass
class RssSampler:
    """Sample the RSS of a process tree every ``interval`` seconds in a daemon thread."""

    pid: int
    interval: float = SAMPLE_INTERVAL_S
    samples: list[Sample] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="rss-sampler", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def _run(self) -> None:
        while not self._stop.is_set():
            pids = _descendants(self.pid)
            rss = anon = 0
            for pid in pids:
                one_rss, one_anon = _rss_kib(pid)
                rss += one_rss
                anon += one_anon
            now = time.perf_counter()
            self.samples.append(Sample(now, rss / 1024, anon / 1024, len(pids)))
            self._stop.wait(self.interval)

    def window(self, start: float, end: float) -> list[Sample]:
        return [s for s in list(self.samples) if start <= s.t <= end]


# --------------------------------------------------------------------------- server


def _cli() -> str:
    return str(Path(sys.executable).with_name("loceval"))


@contextlib.contextmanager
def running_server(data_dir: Path, log: Path) -> Iterator[RunningService]:
    """Start ``loceval serve`` on a free port with its own data dir; always stop it."""
    port = free_port()
    env = {**os.environ, "LOCEVAL_DATA_DIR": str(data_dir.resolve())}
    service = ServiceProcess.start(
        [_cli(), "serve", "--host", "127.0.0.1", "--port", str(port)],
        env,
        cwd=None,
        log=log,
        own_session=True,  # its own process group: stop all of it, nothing else
    )
    server = RunningService(f"http://127.0.0.1:{port}", env, service)
    try:
        wait_ready(server.url, service, timeout=120.0)
        yield server
    finally:
        service.stop(timeout=30)


def create_key(server: RunningService) -> str:
    done = subprocess.run(
        [_cli(), "keys", "create", "--project", "bench"],
        env=server.env,
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    key = done.stdout.strip()
    if done.returncode != 0 or not key or len(key.splitlines()) != 1:
        msg = f"keys create failed ({done.returncode}): {done.stdout!r} {done.stderr!r}"
        raise RuntimeError(msg)
    return key


# --------------------------------------------------------------------------- uploads


@dataclass(frozen=True)
class UploadResult:
    client: int
    recording: Recording
    status: int
    start: float
    end: float
    detail: str

    @property
    def seconds(self) -> float:
        return self.end - self.start


def _upload(
    client: int, recording: Recording, server: RunningService, key: str, barrier: threading.Barrier
) -> UploadResult:
    timeout = httpx.Timeout(connect=30.0, read=1800.0, write=1800.0, pool=30.0)
    headers = {"Authorization": f"Bearer {key}"}
    with (
        httpx.Client(base_url=server.url, headers=headers, timeout=timeout) as http,
        recording.path.open("rb") as fh,
    ):
        barrier.wait()
        start = time.perf_counter()
        try:
            answer = http.post(
                "/api/v1/datasets",
                files={"file": (recording.path.name, fh, "application/octet-stream")},
                data={"name": f"upload-load client {client}", "tags": "bench,upload-load"},
            )
        except httpx.HTTPError as exc:
            return UploadResult(client, recording, 0, start, time.perf_counter(), repr(exc))
        end = time.perf_counter()
    return UploadResult(
        client, recording, answer.status_code, start, end, _check(answer, recording)
    )


def _check(answer: httpx.Response, recording: Recording) -> str:
    """Return "ok" when the Dataset describes exactly the bytes sent, else what differs."""
    try:
        body = answer.json()
    except ValueError:
        return f"not JSON: {answer.text[:200]!r}"
    if answer.status_code != 201 or not isinstance(body, dict):
        return json.dumps(body)[:300]
    problems = []
    if body.get("sha256") != recording.sha256:
        problems.append(f"sha256 {body.get('sha256')}")
    if body.get("size_bytes") != recording.size_bytes:
        problems.append(f"size_bytes {body.get('size_bytes')}")
    if body.get("kind") != "rosbag2-mcap":
        problems.append(f"kind {body.get('kind')}")
    return "; ".join(problems) or f"ok {body.get('id')}"


def run_uploads(
    server: RunningService, key: str, recordings: list[Recording]
) -> list[UploadResult]:
    barrier = threading.Barrier(len(recordings))
    with ThreadPoolExecutor(max_workers=len(recordings), thread_name_prefix="client") as pool:
        futures = [
            pool.submit(_upload, k, rec, server, key, barrier) for k, rec in enumerate(recordings)
        ]
        return [f.result() for f in futures]


# --------------------------------------------------------------------------- report


def _report(results: list[UploadResult], sampler: RssSampler, t_idle: float) -> bool:
    """Print the table and the figures; return whether every target was met."""
    first = min(r.start for r in results)
    last = max(r.end for r in results)
    idle = sampler.window(t_idle, first)
    during = sampler.window(first, last + 2 * sampler.interval)
    after = sampler.window(last + SETTLE_S - 0.5, last + SETTLE_S + 1.0)
    print()
    print(f"{'client':>6} {'file':<24} {'MB':>8} {'status':>6} {'s':>8} {'MB/s':>7}  response")
    for r in results:
        mb = r.recording.size_bytes / _MB
        rate = mb / r.seconds if r.seconds > 0 else float("nan")
        print(
            f"{r.client:>6} {r.recording.path.name:<24} {mb:>8.1f} {r.status:>6} "
            f"{r.seconds:>8.2f} {rate:>7.1f}  {r.detail}"
        )
    total = sum(r.recording.size_bytes for r in results)
    wall = last - first
    baseline = statistics.median(s.rss_mib for s in idle)
    baseline_anon = statistics.median(s.anon_mib for s in idle)
    peak = max(during, key=lambda s: s.rss_mib)
    peak_anon = max(s.anon_mib for s in during)
    growth = peak.rss_mib - baseline
    times = sorted(r.seconds for r in results)
    statuses = sorted({r.status for r in results})
    print()
    print(f"uploads:            {len(results)} concurrent, statuses {statuses}")
    print(f"total bytes:        {total:,} ({total / _MB:.1f} MB)")
    print(f"wall time:          {wall:.2f} s (first request start to last response)")
    print(f"throughput:         {total / _MB / wall:.1f} MB/s aggregate")
    median = statistics.median(times)
    print(f"per upload:         min {times[0]:.2f} s, median {median:.2f} s, max {times[-1]:.2f} s")
    print(f"server processes:   {peak.processes} (server and descendants at the peak)")
    idle_note = f"median of {len(idle)} idle samples; anonymous {baseline_anon:.1f} MiB"
    print(f"RSS baseline:       {baseline:.1f} MiB ({idle_note})")
    peak_note = f"{len(during)} samples during uploads; anonymous peak {peak_anon:.1f} MiB"
    print(f"RSS peak:           {peak.rss_mib:.1f} MiB at +{peak.t - first:.2f} s ({peak_note})")
    if after:
        print(f"RSS {SETTLE_S:.0f} s after:      {after[-1].rss_mib:.1f} MiB")
    own_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"client peak RSS:    {own_mib:.1f} MiB (this script: the bodies were streamed)")
    all_created = all(r.status == 201 for r in results)
    met = growth < TARGET_GROWTH_MIB
    verdict = "met" if met else "MISSED"
    print(
        f"RSS growth {growth:.1f} MiB vs target < {TARGET_GROWTH_MIB:.0f} MiB: {verdict}; "
        f"all 201: {'yes' if all_created else 'NO'}"
    )
    return met and all_created


# --------------------------------------------------------------------------- main


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.upload_load", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--size-mb", type=float, default=500.0, help="size of each upload")
    parser.add_argument("--clients", type=int, default=10, help="concurrent uploads")
    parser.add_argument("--workdir", type=Path, default=Path("benchmarks/_work"))
    parser.add_argument("--keep-data", action="store_true", help="keep the server's data directory")
    args = parser.parse_args(argv)
    if args.clients < 1 or args.size_mb <= 0:
        parser.error("--clients and --size-mb must be positive")

    folder = args.workdir / "upload_load"
    recordings = prepare_recordings(folder, args.size_mb, args.clients)
    print(
        f"{len(recordings)} distinct MCAP recordings (client k: k more images, so no SHA-256 "
        f"dedupe), {min(r.size_bytes for r in recordings) / _MB:.1f}.."
        f"{max(r.size_bytes for r in recordings) / _MB:.1f} MB each"
    )
    data_dir = Path(tempfile.mkdtemp(prefix="server-", dir=folder))
    log = folder / "server.log"
    print(f"server data dir: {data_dir}, log: {log}", flush=True)
    ok = False
    try:
        with running_server(data_dir, log) as server:
            key = create_key(server)
            sampler = RssSampler(server.process.pid)
            sampler.start()
            try:
                t_idle = time.perf_counter()
                time.sleep(BASELINE_S)
                print(f"uploading with {len(recordings)} clients ...", flush=True)
                results = run_uploads(server, key, recordings)
                time.sleep(SETTLE_S + 1.0)
            finally:
                sampler.stop()
            ok = _report(results, sampler, t_idle)
            if not all(r.status == 201 for r in results):
                print(f"\nserver log tail:\n{server.service.tail(30)}")
    finally:
        if args.keep_data:
            print(f"kept {data_dir}")
        else:
            shutil.rmtree(data_dir, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
