"""``loceval evaluate --fail-on``: exit codes 0, 1, 2 and 3, and the gate's last line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from loceval.results import gate as gate_module
from service.cli import main
from tests.verdict_factory import undecided_tolerance, write_verdict_files


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The reference and the steady (pass), lost (fail) and borderline estimates as TUM files."""
    return write_verdict_files(tmp_path_factory.mktemp("verdicts"))


def _share(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> str:
    code = main(
        ["evaluate", str(files["reference"]), str(files["borderline"]), "--json",
         "--tolerance", "0.1@50"]
    )  # fmt: skip
    out, _ = capsys.readouterr()
    assert code == 0
    return undecided_tolerance(json.loads(out)["estimates"][0]["verdict"]["share_within"])


def _run(
    capsys: pytest.CaptureFixture[str], files: dict[str, Path], *estimates: str, args: list[str]
) -> tuple[int, str, str]:
    argv = ["evaluate", str(files["reference"]), *(str(files[e]) for e in estimates), *args]
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _last_line(text: str) -> str:
    return text.rstrip("\n").splitlines()[-1]


def test_exit_0_when_no_condition_holds(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """steady passes: --fail-on fail,undecided exits 0, the last line says the gate passed."""
    code, out, _ = _run(
        capsys, files, "steady", args=["--tolerance", "0.10@95", "--fail-on", "fail,undecided"]
    )
    assert code == 0
    assert _last_line(out) == (
        "gate: passed (no estimate is failing the tolerance or undecided against the tolerance)"
    )


def test_exit_3_on_fail_with_the_reason_last(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """lost fails: exit 3, and the last line names it with its share, interval and requirement."""
    code, out, _ = _run(
        capsys, files, "steady", "lost", args=["--tolerance", "0.10@95", "--fail-on", "fail"]
    )
    assert code == 3
    last = _last_line(out)
    assert last.startswith("gate: lost fails the tolerance (")
    assert " % within 0.10 m, 95 % interval " in last
    assert last.endswith(", needs 95 %)")
    assert "steady" not in last


def test_without_fail_on_a_failing_verdict_exits_0(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """0 keeps its meaning: the verdict is in the tables, the exit code stays 0, no gate line."""
    code, out, _ = _run(capsys, files, "lost", args=["--tolerance", "0.10@95"])
    assert code == 0
    assert "lost: FAIL" in out
    assert "gate:" not in out


def test_undecided_closes_the_gate_only_when_named(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """borderline is undecided: --fail-on fail exits 0, adding undecided (repeated flag) exits 3."""
    tolerance = _share(files, capsys)
    code, out, _ = _run(
        capsys, files, "borderline", args=["--tolerance", tolerance, "--fail-on", "fail"]
    )
    assert code == 0
    assert "borderline: UNDECIDED" in out
    code, out, _ = _run(
        capsys,
        files,
        "borderline",
        args=["--tolerance", tolerance, "--fail-on", "fail", "--fail-on", "undecided"],
    )
    assert code == 3
    assert _last_line(out).startswith("gate: borderline is undecided against the tolerance (")


def test_json_keeps_stdout_a_document_and_says_why_on_stderr(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """With --json stdout is the document alone; the gate's line is the last of stderr."""
    code, out, err = _run(
        capsys, files, "lost", args=["--tolerance", "0.10@95", "--fail-on", "fail", "--json"]
    )
    assert code == 3
    assert json.loads(out)["estimates"][0]["verdict"]["outcome"] == "fail"
    assert _last_line(err).startswith("gate: lost fails the tolerance (")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--fail-on", "fail"], "--fail-on: The gate's fail judge the tolerance verdict"),
        (
            ["--tolerance", "0.1@95", "--fail-on", "fail,failed"],
            "--fail-on: The gate takes the conditions fail, undecided, worse; 'failed'",
        ),
        (["--tolerance", "0.1@95", "--fail-on", "worse"], "--fail-on: The gate's worse judges"),
    ],
)
def test_exit_1_on_a_gate_that_cannot_be_judged(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    """Bad input exits 1 before the evaluation runs, one line naming --fail-on."""
    code, out, err = _run(capsys, files, "steady", args=args)
    assert code == 1
    assert out == ""
    (line,) = err.splitlines()
    assert line.startswith(f"loceval: error: {message}")


def test_exit_2_stays_a_bug(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A bug while judging the gate is exit 2 with the traceback, not a closed gate (3)."""

    def broken(*_args: object) -> None:
        msg = "a bug in the gate"
        raise RuntimeError(msg)

    monkeypatch.setattr(gate_module, "judge_gate", broken)
    code, _, err = _run(capsys, files, "lost", args=["--tolerance", "0.10@95", "--fail-on", "fail"])
    assert code == 2
    assert "RuntimeError: a bug in the gate" in err


def test_the_process_exits_3_as_a_ci_job_sees_it(files: dict[str, Path], tmp_path: Path) -> None:
    """Run as a CI job runs it (a process): exit status 3, the gate's line last on stdout."""
    completed = subprocess.run(
        [
            sys.executable, "-m", "service.cli", "evaluate", str(files["reference"]),
            str(files["lost"]), "--tolerance", "0.10@95", "--fail-on", "fail",
            "--out", str(tmp_path / "out"), "--formats", "junit.xml,summary.md",
        ],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])},
        timeout=600,
    )  # fmt: skip
    assert completed.returncode == 3, completed.stderr
    assert _last_line(completed.stdout).startswith("gate: lost fails the tolerance (")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "junit.xml",
        "result.json",
        "summary.md",
    ]


def test_worse_closes_the_gate_against_a_baseline(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """SLAM was steady in the baseline: lost now exits 3 for worse, steady again exits 0."""
    baseline = tmp_path / "release"
    code, _, err = _run(
        capsys, files, "steady", args=["--name", "SLAM", "--out", str(baseline),
                                        "--formats", "json,csv"],
    )  # fmt: skip
    assert code == 0, err
    worse = ["--name", "SLAM", "--baseline", str(baseline), "--fail-on", "worse"]
    code, out, _ = _run(capsys, files, "lost", args=worse)
    assert code == 3
    last = _last_line(out)
    assert last.startswith("gate: SLAM is worse than the baseline (ATE RMSE ")
    assert "; SLAM is worse than the baseline (RPE RMSE " in last
    assert "paired 95 % interval +" in last  # errors.csv beside result.json pairs them
    code, out, _ = _run(capsys, files, "steady", args=worse)
    assert code == 0
    assert _last_line(out) == "gate: passed (no estimate is worse than the baseline)"
