"""Bad input found by a QA hunt over the command line, kept as regression tests.

The contract: bad input to ``loceval evaluate`` and ``loceval inspect`` exits 1 and prints one
``loceval: error: ...`` line that names the problem and says what to do; good input exits 0.
The CLI runs as a subprocess, as a user runs it; inputs are generated under ``tmp_path``
(bags with ``tests.bagfactory``).
"""

from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tests import bagfactory as bf
from tests.cli_contract import cli_error_line, run_cli


def _cli(*argv: str | Path) -> subprocess.CompletedProcess[str]:
    """Run ``python -m service.cli ARGV`` from the project root (up to 120 s)."""
    return run_cli(*argv, timeout=120)


def _circle(n: int, *, rate_hz: float = 100.0, t0: float = 1000.0) -> np.ndarray:
    """Return rows ``t x y z qx qy qz qw`` of a path around a circle (alignment well posed)."""
    a = np.linspace(0.0, 2.0 * math.pi, n)
    t = t0 + np.arange(n) / rate_hz
    zeros = np.zeros(n)
    return np.stack(
        [t, 2 * np.cos(a), 2 * np.sin(a), 0.2 * np.sin(3 * a), zeros, zeros,
         np.sin(a / 2), np.cos(a / 2)],
        axis=1,
    )  # fmt: skip


def _write_tum(path: Path, rows: np.ndarray) -> Path:
    path.write_text("\n".join(" ".join(f"{v:.6f}" for v in row) for row in rows) + "\n")
    return path


# --- text files -----------------------------------------------------------------------------


def test_euroc_stamps_in_seconds_are_not_collapsed_silently(tmp_path: Path) -> None:
    """EuRoC rows with float seconds instead of integer ns are refused, not collapsed."""
    rows = _circle(2000, rate_hz=200.0, t0=1403715524.907143)
    header = (
        "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],"
        "q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
    )
    body = [
        f"{r[0]:.6f},{r[1]:.6f},{r[2]:.6f},{r[3]:.6f},{r[7]:.6f},{r[4]:.6f},{r[5]:.6f},{r[6]:.6f}"
        for r in rows
    ]
    path = tmp_path / "data.csv"
    path.write_text(header + "\n" + "\n".join(body) + "\n")
    proc = _cli("inspect", path, "--json")
    if proc.returncode == 0:
        assert json.loads(proc.stdout)["poses"] == 2000, proc.stdout
    else:
        line = cli_error_line(proc).replace(str(path), "FILE")
        assert "second" in line, line


def test_tum_nanosecond_stamps_message_gives_a_possible_fix(tmp_path: Path) -> None:
    """TUM stamps in nanoseconds: the message says they look like nanoseconds and what to do."""
    rows = _circle(300, t0=1_700_000_000.0)
    lines = [f"{round(r[0] * 1e9)} " + " ".join(f"{v:.6f}" for v in r[1:]) for r in rows]
    path = tmp_path / "ns.txt"
    path.write_text("\n".join(lines) + "\n")
    line = cli_error_line(_cli("inspect", path)).replace(str(path), "FILE")
    assert "nanosecond" in line, line


# --- bags -----------------------------------------------------------------------------------


def _poses(n: int = 300) -> bf.Poses:
    rows = _circle(n)
    stamps = bf.T0_NS + np.arange(n, dtype=np.int64) * 50_000_000
    return bf.Poses(stamps, rows[:, 1:4].copy(), rows[:, 4:8].copy())


@pytest.mark.parametrize("fmt", bf.FORMATS)
def test_zero_header_stamps_message_suggests_stamp_receive(tmp_path: Path, fmt: str) -> None:
    """A publisher that never fills header.stamp: the message suggests --stamp receive."""
    ref = _poses()
    records = bf.pose_records("/gt", bf.POSE, ref)
    records += [
        bf.Record("/est", bf.POSE, int(ref.stamps_ns[i]) + 5_000_000,
                  (0, ref.positions[i], ref.quats[i]))
        for i in range(len(ref.stamps_ns))
    ]  # fmt: skip
    bag = bf.write_bag(bf.bag_path(tmp_path, fmt), records, fmt=fmt)
    assert _cli("evaluate", f"{bag}@/gt", f"{bag}@/est", "--stamp", "receive").returncode == 0
    line = cli_error_line(_cli("evaluate", f"{bag}@/gt", f"{bag}@/est"))
    assert "--stamp receive" in line, line


@pytest.mark.parametrize("fmt", bf.FORMATS)
def test_broken_unrelated_tf_link_does_not_block_other_chains(tmp_path: Path, fmt: str) -> None:
    """One NaN on an unrelated link (odom -> wheel) drops that sample, not every tf chain."""
    ref = _poses()
    bad = ref.positions.copy()
    bad[5] = np.nan
    records = bf.pose_records("/gt", bf.POSE, ref)
    records += bf.tf_records(bf.link_transforms("map", "base_link", ref))
    records += bf.tf_records(
        bf.link_transforms("odom", "wheel", bf.Poses(ref.stamps_ns, bad, ref.quats))
    )
    bag = bf.write_bag(bf.bag_path(tmp_path, fmt), records, fmt=fmt)
    proc = _cli("evaluate", f"{bag}@/gt", f"{bag}@tf:map:base_link")
    assert proc.returncode == 0, proc.stderr
    proc = _cli("inspect", bag)
    assert proc.returncode == 0, proc.stderr


def test_damaged_bag_metadata_message_is_one_line(tmp_path: Path) -> None:
    """A malformed metadata.yaml gives a one-line message, not the YAML parser's report."""
    folder = tmp_path / "bag"
    bf.write_bag(folder, bf.pose_records("/gt", bf.POSE, _poses()), fmt="sqlite3")
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n")
    proc = _cli("inspect", folder)
    cli_error_line(proc)
    assert len([line for line in proc.stderr.splitlines() if line.strip()]) == 1, proc.stderr


# --- options --------------------------------------------------------------------------------


@pytest.fixture
def pair(tmp_path: Path) -> tuple[Path, Path]:
    rows = _circle(1000)
    est = rows.copy()
    est[:, 1:4] += np.random.default_rng(1).normal(0, 0.01, size=(len(est), 3))
    return _write_tum(tmp_path / "ref.txt", rows), _write_tum(tmp_path / "est.txt", est)


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["--max-gap=1e-300"], "--max-gap"),  # "max_dt must not be negative ... max_gap_ns=0"
        (["--worst", "-1"], "--worst"),  # "worst_count must not be negative, got -1."
    ],
)
def test_option_errors_name_the_option(
    pair: tuple[Path, Path], argv: list[str], option: str
) -> None:
    """Option errors name the option to fix, not an internal field."""
    line = cli_error_line(_cli("evaluate", *pair, *argv))
    assert option in line, line


@pytest.mark.parametrize(
    ("option", "value"),
    [("--time-offset", "-1e6"), ("--thresholds", "-0.1,0.2"), ("--tolerance", "-0.1@95")],
)
def test_negative_option_value_message_says_how_to_pass_it(
    pair: tuple[Path, Path], option: str, value: str
) -> None:
    """A value that starts with '-' given apart from its option: say to write OPTION=VALUE."""
    line = cli_error_line(_cli("evaluate", *pair, option, value))
    assert f"{option}=" in line, line
