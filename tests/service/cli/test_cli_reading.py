"""The command line as a user reads it (issue 30): inspect's listing, KITTI without times,
EuRoC rows shorter than their header, and a closed pipe."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from tests.factories import make_trajectory, perturb, write_euroc, write_kitti, write_tum


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# --- item 14: a trajectory file's listing ------------------------------------------------


def test_inspect_lists_a_file_tidily(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Rounded values with units and the start as ISO time, as bags get; no raw dump."""
    path = write_tum(tmp_path / "gt.txt", make_trajectory(rng, 1500, dt_ns=4_999_999))
    code, out, _ = _run(capsys, "inspect", str(path))
    assert code == 0
    assert "duration_s" not in out
    assert "rate_hz" not in out
    assert "start_s" not in out
    assert not re.search(r"\d\.\d{6,}", out), out  # nothing printed to machine precision
    assert re.search(r"^\s+poses: 1,500$", out, re.MULTILINE), out
    assert re.search(r"^\s+start: \d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$", out, re.MULTILINE)
    assert re.search(r"^\s+duration: 7\.49 s$", out, re.MULTILINE), out  # 3 digits
    assert re.search(r"^\s+rate: 200\.0 Hz$", out, re.MULTILINE), out
    assert re.search(r"^\s+path length: \d+\.\d{3} m$", out, re.MULTILINE), out


# --- item 15: KITTI without a times file -----------------------------------------------


def test_kitti_without_times_says_so(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """No pretended duration in the listing; the evaluation names the missing times."""
    truth = make_trajectory(rng, 400, dt_ns=100_000_000)
    gt = write_kitti(tmp_path / "gt.txt", truth)
    est = write_kitti(tmp_path / "est.txt", perturb(truth, rng, sigma_m=0.02))
    code, out, _ = _run(capsys, "inspect", f"kitti:{gt}")
    assert code == 0
    assert "duration" not in out
    assert "rate" not in out
    assert "399.0" not in out
    assert re.search(r"^\s+times: none: the poses are numbered", out, re.MULTILINE), out
    code, out, _ = _run(capsys, "evaluate", f"kitti:{gt}", f"kitti:{est}")
    assert code == 0
    assert "too few poses between its gaps" not in out
    assert "correlate" not in out
    assert "have no times (poses are numbered" in out
    assert "the clocks are not checked" in out


def test_kitti_without_times_refuses_an_estimated_time_offset(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Asking for a time offset from the motion of numbered poses is bad input (exit 1)."""
    truth = make_trajectory(rng, 300, dt_ns=100_000_000)
    gt = write_kitti(tmp_path / "gt.txt", truth)
    est = write_kitti(tmp_path / "est.txt", perturb(truth, rng, sigma_m=0.02))
    code, _, err = _run(capsys, "evaluate", f"kitti:{gt}", f"kitti:{est}", "--time-offset", "auto")
    assert code == 1
    assert "--time-offset:" in err
    assert "no time offset can be estimated" in err
    assert "Traceback" not in err


# --- item 18: EuRoC rows shorter than their header -------------------------------------


def test_euroc_rows_shorter_than_the_header(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """The header names the quaternion, the rows carry t,x,y,z: refused, naming what is missing."""
    full = write_euroc(tmp_path / "full.csv", make_trajectory(rng, 50), extra_columns=False)
    header, *rows = full.read_text().splitlines()
    short = tmp_path / "short.csv"
    short.write_text("\n".join([header, *(",".join(r.split(",")[:4]) for r in rows)]) + "\n")
    for argv in (["inspect", f"euroc:{short}"], ["evaluate", f"euroc:{short}", f"euroc:{full}"]):
        code, _, err = _run(capsys, *argv)
        assert code == 1, argv
        assert "the rows do not match the header" in err
        assert "holds 4 values" in err
        assert "missing: q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []" in err


def test_euroc_position_only_header_still_reads(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """A header that names only t,x,y,z says position-only on purpose: read as before."""
    full = write_euroc(tmp_path / "full.csv", make_trajectory(rng, 50), extra_columns=False)
    _, *rows = full.read_text().splitlines()
    path = tmp_path / "pos.csv"
    path.write_text("\n".join(["#timestamp,x,y,z", *(",".join(r.split(",")[:4]) for r in rows)]))
    code, out, _ = _run(capsys, "inspect", f"euroc:{path}")
    assert code == 0
    assert "orientation: False" in out


# --- sibling: a reader that closes the pipe --------------------------------------------


def test_closed_pipe_is_no_bug(tmp_path: Path, rng: np.random.Generator) -> None:
    """``loceval inspect FILE | head -1``: no traceback, no 'this is a bug'."""
    path = write_tum(tmp_path / "gt.txt", make_trajectory(rng, 100))
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "inspect", str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None
    assert proc.stderr is not None
    proc.stdout.close()  # the reader leaves before the first line
    with proc.stderr:
        err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert "internal error" not in err
    assert "Traceback" not in err
    assert proc.returncode in {0, 141}
