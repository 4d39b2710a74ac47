"""``loceval upload`` and ``loceval submit`` against a real ``loceval serve`` (the site laptop).

The server is a real ``loceval serve`` subprocess (``tests/service/conftest.py``); the cut
connections are a loopback proxy (:mod:`tests.harness.proxy`). Each command runs as a
subprocess with the key in ``LOCEVAL_API_KEY`` and its own cache folder (``XDG_CACHE_HOME``),
where tuspy keeps the address of an unfinished upload.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import httpx2 as httpx
import numpy as np
import pytest

from tests.factories import write_large_tum
from tests.harness.ports import free_port
from tests.service.cli.test_cli_map import _recording
from tests.service.conftest import REPO, LiveServer, server_behind_proxy

pytestmark = [pytest.mark.slow]

__all__ = ["_recording"]  # the map test's recording (a fixture), imported for submit's

GROUNDTRUTH = "fr2_desk_groundtruth.txt"
ESTIMATE = "fr2_desk_ORB.txt"
OPTIONS = ("--align", "sim3", "--formats", "json")  # ORB-SLAM monocular: scale unknown
MIB = 1 << 20


def _run(
    *args: str,
    server: LiveServer | None,
    cache: Path,
    key: str | None = None,
    cwd: Path = REPO,
) -> subprocess.CompletedProcess[str]:
    """Run ``loceval ARGS`` with the server's key (or ``key``) and its own cache folder."""
    env = {**os.environ, "XDG_CACHE_HOME": str(cache)}
    env["LOCEVAL_API_KEY"] = key if key is not None else (server.api_key if server else "")
    return subprocess.run(
        [sys.executable, "-m", "service.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
        timeout=600,
        check=False,
    )


def _one_line_error(proc: subprocess.CompletedProcess[str]) -> str:
    """The command failed with exit 1 and one line ``loceval: error: ...`` (no traceback)."""
    assert proc.returncode == 1, (proc.returncode, proc.stdout, proc.stderr)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("loceval: error: "), proc.stderr
    assert "Traceback" not in proc.stderr
    return lines[0]


def _api(server: LiveServer, path: str, **params: Any) -> Any:
    response = httpx.get(
        f"{server.url}/api/v1{path}",
        params=params,
        headers={"Authorization": f"Bearer {server.api_key}"},
        timeout=60,
    )
    response.raise_for_status()
    return response.json()


def _post_dataset(server: LiveServer, path: Path) -> dict[str, Any]:
    """Upload a file with the plain ``POST /datasets`` (as curl would)."""
    with path.open("rb") as stream:
        response = httpx.post(
            f"{server.url}/api/v1/datasets",
            files={"file": (path.name, stream)},
            headers={"Authorization": f"Bearer {server.api_key}"},
            timeout=120,
        )
    response.raise_for_status()
    document: dict[str, Any] = response.json()
    return document


_RUN_KEYS = frozenset({"evaluation_id", "created_at"})
"""What differs between two runs of the same evaluation: its id and time."""
_SERVICE_PROVENANCE = frozenset({"dataset_id", "format"})
"""What the service adds to each input's record: the dataset, and the format it recognised at
upload (``loceval evaluate`` records the format as given: none, sniffed)."""


def _without_run(document: dict[str, Any]) -> dict[str, Any]:
    """The result document without the run's id and times and the service's input records."""
    kept = {k: v for k, v in document.items() if k not in _RUN_KEYS}
    kept["inputs"] = [
        {k: v for k, v in item.items() if k not in _SERVICE_PROVENANCE}
        for item in document.get("inputs", [])
    ]
    return kept


# --- errors: one line, exit 1 ---------------------------------------------------------------


def test_unreachable_server_is_one_line_exit_1(tmp_path: Path, public_data: Path) -> None:
    """No server at the address: upload and submit say so in one line and exit 1."""
    data = public_data
    url = f"http://127.0.0.1:{free_port()}"
    for args in (
        ("upload", str(data / GROUNDTRUTH), "--server", url),
        ("submit", str(data / GROUNDTRUTH), str(data / ESTIMATE), "--server", url),
    ):
        line = _one_line_error(_run(*args, server=None, cache=tmp_path, key="lcv_x"))
        assert f"Cannot reach the loceval service at {url}" in line


def test_wrong_key_and_refused_option_are_one_line_exit_1(
    live_server: LiveServer, tmp_path: Path, public_data: Path
) -> None:
    """A key the server refuses (401) and an option it refuses (422): one line, exit 1."""
    data = public_data
    files = (str(data / GROUNDTRUTH), str(data / ESTIMATE))
    wrong = _run(
        "submit", *files, "--server", live_server.url, server=live_server, cache=tmp_path,
        key="lcv_" + "x" * 43,
    )  # fmt: skip
    assert "refused the API key (401)" in _one_line_error(wrong)
    wrong_upload = _run(
        "upload", files[0], "--server", live_server.url, server=live_server, cache=tmp_path,
        key="lcv_" + "x" * 43,
    )  # fmt: skip
    assert "refused the API key (401)" in _one_line_error(wrong_upload)
    for path in files:  # held already: the refusal is the option's, not an upload's
        _post_dataset(live_server, Path(path))
    refused = _run(
        "submit", *files, "--tolerance", "fast please", "--server", live_server.url, "--quiet",
        server=live_server, cache=tmp_path,
    )  # fmt: skip
    line = _one_line_error(refused)
    assert line.startswith("loceval: error: --tolerance: ")  # the CLI's flag, not options.KEY
    assert "fast please" in line


# --- the upload: resumable -----------------------------------------------------------------


def test_upload_continues_after_cut_connections(tmp_path: Path, rng: np.random.Generator) -> None:
    """Connections cut at 30, 60 and 90 %: the upload continues from the server's offset.

    The dataset holds the file's bytes (its SHA-256), and the proxy carried at most one part
    again per cut (not the whole file).
    """
    part = 1 * MIB
    path = write_large_tum(tmp_path / "walk.txt", 6 * MIB, rng)
    size = path.stat().st_size
    cuts = [int(size * f) for f in (0.3, 0.6, 0.9)]
    with server_behind_proxy(tmp_path / "data", cuts) as (server, proxy):
        proc = _run(
            "upload", str(path), "--server", proxy.url, "--chunk-mib", "1", "--json",
            server=server, cache=tmp_path / "cache",
        )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proxy.cuts == cuts
    (dataset,) = json.loads(proc.stdout)
    assert dataset["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert dataset["size_bytes"] == size
    assert proxy.sent <= size + len(cuts) * part + 256 * 1024  # headers and HEADs besides


def test_upload_run_again_continues_where_it_stopped(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    """The network goes for good at 50 %: exit 1 saying to run again; the next run continues.

    The second run finds the upload's address in the cache folder (tuspy's URL storage) and
    sends only the rest: the two runs together carry less than 1.3 times the file.
    """
    path = write_large_tum(tmp_path / "walk.txt", 6 * MIB, rng)
    size = path.stat().st_size
    cache = tmp_path / "cache"
    with server_behind_proxy(tmp_path / "data", [size // 2], stay_down=True) as (server, proxy):
        first = _run(
            "upload", str(path), "--server", proxy.url, "--chunk-mib", "1", "--quiet",
            server=server, cache=cache,
        )  # fmt: skip
        assert "run the same command again" in _one_line_error(first)
        assert list(cache.glob("loceval/uploads.json"))
        proxy.allow()
        second = _run(
            "upload", str(path), "--server", proxy.url, "--chunk-mib", "1", "--json",
            server=server, cache=cache,
        )  # fmt: skip
        assert second.returncode == 0, second.stderr
        (dataset,) = json.loads(second.stdout)
        assert dataset["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
        assert proxy.sent < 1.3 * size
        # the plain lines: id, name, kind
        third = _run("upload", str(path), "--server", proxy.url, "--quiet",
                     server=server, cache=cache)  # fmt: skip
    assert third.returncode == 0, third.stderr
    assert third.stdout.split() == [dataset["id"], dataset["name"], dataset["kind"]]


# --- submit: the public fr2_desk pair end to end -------------------------------------------


def test_submit_writes_the_result_of_evaluate_and_uploads_once(
    live_server: LiveServer, tmp_path: Path, public_data: Path
) -> None:
    """``loceval submit`` on fr2_desk writes ``loceval evaluate``'s result.json (but id, times).

    A second submit of the same files uploads nothing: the server holds both by SHA-256.
    """
    files = (GROUNDTRUTH, ESTIMATE)  # both run in the data folder: the same paths recorded
    local_run = _run(
        "evaluate", *files, *OPTIONS, "--out", str(tmp_path / "local"),
        server=None, cache=tmp_path / "cache", cwd=public_data,
    )  # fmt: skip
    assert local_run.returncode == 0, local_run.stderr
    proc = _run(
        "submit", *files, *OPTIONS, "--out", str(tmp_path / "remote"),
        "--server", live_server.url, server=live_server, cache=tmp_path / "cache",
        cwd=public_data,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("uploaded as dataset") == 2, proc.stderr
    assert "Artifacts written to" in proc.stdout
    local = json.loads((tmp_path / "local" / "result.json").read_text(encoding="utf-8"))
    remote = json.loads((tmp_path / "remote" / "result.json").read_text(encoding="utf-8"))
    assert _without_run(remote) == _without_run(local)
    assert _api(live_server, "/datasets")["count"] == 2

    again = _run(
        "submit", *files, *OPTIONS, "--json", "--server", live_server.url,
        server=live_server, cache=tmp_path / "cache", cwd=public_data,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert "uploaded as dataset" not in again.stderr
    assert again.stderr.count("held by the service") == 2, again.stderr
    assert _api(live_server, "/datasets")["count"] == 2
    assert _without_run(json.loads(again.stdout)) == _without_run(local)


def test_submit_sends_the_files_of_options_map_and_building(
    live_server: LiveServer, tmp_path: Path, recording: dict[str, Path]
) -> None:
    """``--map`` and ``--building`` name local files: submit uploads them and refers to them.

    The map measured on the service is the one ``loceval evaluate`` measures (but the name of
    its source: the service's is the dataset's file name).
    """
    folder = recording["folder"]
    argv = (
        "gt.txt", "slam.txt", "--name", "SLAM", "--map", "map.zip", "--building", "plan.dxf",
        "--no-ci", "--json",
    )  # fmt: skip
    local = _run("evaluate", *argv, server=None, cache=tmp_path, cwd=folder)
    assert local.returncode == 0, local.stderr
    remote = _run(
        "submit", *argv, "--server", live_server.url, server=live_server, cache=tmp_path,
        cwd=folder,
    )  # fmt: skip
    assert remote.returncode == 0, remote.stderr
    assert remote.stderr.count("uploaded as dataset") == 4, remote.stderr
    kinds = {d["filename"]: d["kind"] for d in _api(live_server, "/datasets")["items"]}
    assert set(kinds) == {"gt.txt", "slam.txt", "map.zip", "plan.dxf"}
    on_service, here = json.loads(remote.stdout)["map"], json.loads(local.stdout)["map"]
    # the figures are the same; the service names the map by its dataset's file only
    assert on_service.pop("source") == "map.zip"
    assert here.pop("source").startswith("map.zip")
    assert on_service == here


def test_submit_sends_systems_and_closes_the_gate_as_evaluate(
    live_server: LiveServer, tmp_path: Path, public_data: Path
) -> None:
    """``--system`` reaches the service; ``--fail-on fail`` exits 3 with the gate's line last.

    fr2_desk's ORB estimate after a sim3 fit has ATE errors of about a centimetre, so a 1 mm
    tolerance fails it for most poses: the same verdict ``loceval evaluate`` gives.
    """
    files = (str(public_data / GROUNDTRUTH), str(public_data / ESTIMATE))
    proc = _run(
        "submit", *files, *OPTIONS, "--system", "ORB", "--tolerance", "0.001@95",
        "--fail-on", "fail", "--server", live_server.url, "--quiet",
        server=live_server, cache=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 3, (proc.stdout, proc.stderr)
    last = proc.stdout.strip().splitlines()[-1]
    assert last.startswith("gate: "), proc.stdout
    assert "fails the tolerance" in last, proc.stdout
    [evaluation] = _api(live_server, "/evaluations")["items"][:1]
    assert [e.get("system") for e in evaluation["estimates"]] == ["ORB"]
