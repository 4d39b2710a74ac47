"""The command line: contract, table layout, exit codes, artifacts."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from service.cli import main
from service.cli.demo import write_demo_recording


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Write the synthetic demo recording once."""
    return write_demo_recording(tmp_path_factory.mktemp("demo"))


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_json_contract(demo: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """--json prints one document with both estimates, named in order."""
    code, out, _ = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["RTAB-Map"]), str(demo["ISAAC"]),
        "--name", "RTAB-Map", "--name", "ISAAC", "--json", "--tolerance", "0.10@95",
    )  # fmt: skip
    assert code == 0
    doc = json.loads(out)
    assert [e["name"] for e in doc["estimates"]] == ["RTAB-Map", "ISAAC"]
    assert doc["reference"]["poses"] == 6000
    isaac = doc["estimates"][1]
    assert isaac["dropped"]["outside"] == 0
    assert isaac["verdict"]["required_share"] == pytest.approx(0.95)
    assert doc["inputs"][0]["sha256"]
    assert doc["options"]["association"] == "interpolate"


def test_input_records_hash_every_file(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """The checksums (computed while the files are read) are each file's SHA-256."""
    files = [demo["reference"], demo["RTAB-Map"], demo["ISAAC"]]
    code, out, _ = _run(capsys, "evaluate", *map(str, files), "--json", "--no-ci")
    assert code == 0
    inputs = json.loads(out)["inputs"]
    assert [i["role"] for i in inputs] == ["reference", "estimate", "estimate"]
    assert [i["sha256"] for i in inputs] == [
        hashlib.sha256(f.read_bytes()).hexdigest() for f in files
    ]
    assert [i["bytes"] for i in inputs] == [f.stat().st_size for f in files]


def test_no_ci_and_reference_sigma(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """--no-ci nulls every interval and the comparisons; --reference-sigma judges the reference."""
    files = (str(demo["reference"]), str(demo["RTAB-Map"]), str(demo["ISAAC"]))
    code, out, _ = _run(capsys, "evaluate", *files, "--json", "--reference-sigma", "0.0002")
    assert code == 0
    doc = json.loads(out)
    assert doc["options"]["reference_sigma_m"] == pytest.approx(0.0002)
    assert {c["metric"] for c in doc["comparisons"]} == {"ate_rmse", "rpe_rmse"}
    for est in doc["estimates"]:
        lo, hi = est["rpe"]["translation_m"]["ci95"]["median"]
        assert lo <= est["rpe"]["translation_m"]["median"] <= hi
        assert est["reference_error"]["rpe"]["reference_rms"] == pytest.approx(0.0002 * 6**0.5)
    code, out, _ = _run(capsys, "evaluate", *files, "--json", "--no-ci")
    assert code == 0
    off = json.loads(out)
    assert off["comparisons"] is None
    assert all(e["ate"]["translation_m"]["ci95"] is None for e in off["estimates"])


def test_table_layout(demo: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """Without --json the framework paper's tables come out, one column per estimate."""
    code, out, _ = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["RTAB-Map"]), str(demo["ISAAC"]),
        "--name", "RTAB-Map", "--name", "ISAAC",
    )  # fmt: skip
    assert code == 0
    assert "Absolute Trajectory Error (ATE)" in out
    assert "Relative Pose Error (RPE, delta 1 frame)" in out
    header = next(line for line in out.splitlines() if line.startswith("error metric"))
    assert header.split()[-2:] == ["RTAB-Map", "ISAAC"]
    for label in ("RMSE", "MEAN", "MEDIAN", "STD", "MIN", "MAX"):
        assert any(line.startswith(label) for line in out.splitlines())
    assert "Comparisons (95 % intervals)" in out
    # The demo mirrors the framework paper: ISAAC has the lower ATE, RTAB-Map the lower RPE.
    assert "  ISAAC's ATE is lower than RTAB-Map's: difference" in out
    assert "  RTAB-Map's RPE is lower than ISAAC's: difference" in out


def test_options_reach_the_result(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """Association, alignment, RPE and threshold options are applied and recorded."""
    code, out, _ = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["RTAB-Map"]), "--json",
        "--associate", "nearest", "--max-dt", "0.005", "--align", "sim3", "--align-first", "10s",
        "--rpe-delta", "0.5", "--rpe-unit", "m", "--thresholds", "0.2,0.4", "--time-offset", "0",
    )  # fmt: skip
    assert code == 0
    est = json.loads(out)["estimates"][0]
    assert est["alignment"]["method"] == "sim3"
    assert est["alignment"]["window"] == "10s"
    assert est["rpe"]["unit"] == "m"
    assert set(est["within"]) == {"0.2", "0.4"}


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["evaluate", "missing.txt", "also-missing.txt"], "missing.txt"),
        (["evaluate", "REF", "EST", "--tolerance", "ten@cm"], "--tolerance"),
        (["evaluate", "REF", "EST", "--align-first", "-1"], "--align-first"),
        (["evaluate", "REF", "EST", "--thresholds", "a,b"], "--thresholds"),
        (["evaluate", "REF", "EST", "--offset", "1 2"], "--offset"),
        (["evaluate", "REF", "EST", "--name", "a", "--name", "b"], "once per estimate"),
        (["evaluate", "REF", "EST", "--device-from", "a"], "--device"),
        (["evaluate", "REF", "EST", "--max-gap", "0"], "--max-gap"),
        (["evaluate", "REF", "EST", "--rpe-delta", "100000"], "--rpe-delta"),
        (["evaluate", "REF", "EST", "--time-offset", "1000"], "time offset"),
        (["evaluate", "REF", "EST", "--align", "calibrate", "--calibrate-at", "1e6"], "calibrate"),
        (["evaluate", "REF", "EST", "--time-offset", "1e12"], "--time-offset"),
        (["evaluate", "REF", "EST", "--rpe-delta", "1e12", "--rpe-unit", "s"], "--rpe-delta"),
        (["evaluate", "REF", "EST", "--calibrate-at", "1e12"], "--calibrate-at"),
        (["evaluate", "REF", "EST", "--align-first", "1e12s"], "--align-first"),
        (["evaluate", "REF", "EST", "--reference-sigma", "-0.1"], "--reference-sigma: "),
        (["evaluate", "REF", "EST", "--out", "/dev/null"], "not a folder"),
        (["evaluate", "REF", "EST", "--out", "/proc/loceval/out"], "Cannot create"),
    ],
)
def test_bad_input_exits_1_without_traceback(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str], argv: list[str], match: str
) -> None:
    """Every bad input prints a message naming the problem and exits 1, no traceback."""
    argv = [
        str(demo["reference"]) if a == "REF" else str(demo["ISAAC"]) if a == "EST" else a
        for a in argv
    ]
    code, _, err = _run(capsys, *argv)
    assert code == 1
    assert match in err
    assert "Traceback" not in err


def test_invalid_choice_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    """A value outside an option's choices is a usage error with exit code 1."""
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "a", "b", "--align", "wobble"])
    assert exc.value.code == 1
    assert "invalid choice: 'wobble'" in capsys.readouterr().err


def test_usage_errors_exit_1() -> None:
    """An unknown option is bad input: exit code 1, not argparse's 2."""
    proc = subprocess.run(
        [sys.executable, "-m", "service.cli", "evaluate", "--bogus"],
        capture_output=True, text=True, check=False,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[3])},
    )  # fmt: skip
    assert proc.returncode == 1
    assert "Traceback" not in proc.stderr


def test_out_writes_result_json_atomically(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """--out with --formats result.json writes the same document as --json."""
    out_dir = tmp_path / "run"
    code, _, _ = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["ISAAC"]), "--out", str(out_dir),
        "--formats", "result.json",
    )  # fmt: skip
    assert code == 0
    doc = json.loads((out_dir / "result.json").read_text())
    assert doc["evaluation_id"] == "run"
    assert doc["estimates"][0]["matched"] > 1000
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".run.partial")]


def test_unknown_artifact_is_an_input_error(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """--formats with an unknown name lists the known ones and writes nothing."""
    code, _, err = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["ISAAC"]),
        "--out", str(tmp_path / "x"), "--formats", "paths.step",
    )  # fmt: skip
    assert code == 1
    assert "report.pdf" in err
    assert not (tmp_path / "x").exists()


@pytest.mark.pdf
def test_out_writes_every_artifact(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """--out writes the report, tables and CAD files; result.json records the placement."""
    out_dir = tmp_path / "all"
    code, _, err = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["ISAAC"]), "--out", str(out_dir),
        "--units", "m", "--site", "100 200 0 90", "--simplify", "0.005", "--tolerance", "0.1@90",
    )  # fmt: skip
    assert code == 0, err
    names = {p.name for p in out_dir.iterdir()}
    assert names == {
        "result.json", "errors.csv", "map_cells.csv", "report.html", "report.pdf", "paths.dxf",
        "paths.3dm", "paths.3dm.json", "paths.glb", "paths.ifc", "viewer.html", "junit.xml",
        "summary.md",
    }  # fmt: skip
    doc = json.loads((out_dir / "result.json").read_text())
    assert doc["cad"]["units"] == "m"
    assert 0 < doc["cad"]["max_deviation_m"] <= 0.005
    assert (out_dir / "report.pdf").read_bytes().startswith(b"%PDF")


@pytest.mark.parametrize(
    ("option", "match"),
    [
        (("--site", "1 2"), "--site"),
        (("--simplify", "-1"), "simplif"),
        (("--building", "missing.obj"), "missing.obj"),
    ],
)
def test_bad_export_options_fail_before_evaluating(
    demo: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    option: tuple[str, str],
    match: str,
) -> None:
    """Bad placement options exit 1 with the option named, and nothing is written."""
    out_dir = tmp_path / "bad"
    code, _, err = _run(
        capsys, "evaluate", str(demo["reference"]), str(demo["ISAAC"]), "--out", str(out_dir),
        *option,
    )  # fmt: skip
    assert code == 1
    assert match in err
    assert not out_dir.exists()


def test_pipes_are_refused(
    demo: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
):
    """A named pipe is refused at once (reading it twice would give wrong results or hang)."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for argv in (["inspect", str(fifo)], ["evaluate", str(demo["reference"]), str(fifo)]):
        assert main(argv) == 1
        assert "pipe or device" in capsys.readouterr().err


def test_demo_into_an_unwritable_place_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    """loceval demo --out /dev/null is bad input, not a bug."""
    assert main(["demo", "--out", "/dev/null"]) == 1
    assert "Cannot write the demo" in capsys.readouterr().err
