"""``loceval ranging`` end to end on generated radio recordings (tests.radio_factory).

The command runs in process through :func:`service.cli.main` (its exit code and output are
what a user sees); one bad-input case runs as a subprocess to check the contract (exit 1,
one error line, no traceback).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from service.cli import main
from tests import bagfactory as bf
from tests.cli_contract import cli_error_line, run_cli
from tests.factories import write_tum
from tests.radio_factory import (
    make_anchors,
    make_ranges,
    make_reference,
    write_anchors_csv,
    write_ranges_csv,
)


def _inputs(
    folder: Path, rng: np.random.Generator, **ranges_options: object
) -> tuple[Path, Path, Path]:
    """Write reference, anchors and ranges; return their paths."""
    reference = write_tum(folder / "reference.txt", make_reference())
    anchors = write_anchors_csv(folder / "anchors.csv", make_anchors())
    recording = make_ranges(rng, **ranges_options)  # type: ignore[arg-type]
    ranges = write_ranges_csv(folder / "ranges.csv", recording.ranges)
    return reference, anchors, ranges


def _run_json(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> dict[str, Any]:
    """Run ``loceval ranging ARGV --json``; assert exit 0 and return the document."""
    code = main(["ranging", *map(str, argv), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    document: dict[str, Any] = json.loads(out)
    return document


def _error(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> str:
    """Run ``loceval ranging ARGV``; assert exit 1 and return the error line."""
    code = main(["ranging", *map(str, argv)])
    _, err = capsys.readouterr()
    assert code == 1, err
    assert "Traceback" not in err
    return err.strip()


def test_json_ranging_and_estimates(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """The document holds the ranging object and one evaluated estimate per solver."""
    recording = make_ranges(rng, nlos_share=0.05)
    reference = write_tum(tmp_path / "reference.txt", make_reference())
    anchors = write_anchors_csv(tmp_path / "anchors.csv", make_anchors())
    ranges = write_ranges_csv(tmp_path / "ranges.csv", recording.ranges)
    doc = _run_json(capsys, reference, "--anchors", anchors, "--ranges", ranges)
    ranging = doc["ranging"]
    assert ranging["outlier_threshold_m"] == 1.0
    assert ranging["unused_anchors"] == ["FAR"]
    assert [a["id"] for a in ranging["anchors"]] == [f"A{k:02d}" for k in range(1, 13)]
    # Independent figures: measured minus the generator's exact distances, all ranges.
    error = recording.ranges.range_m - recording.true_m
    overall = ranging["overall"]
    assert overall["n"] == error.size
    rmse = float(np.sqrt(np.mean(error**2)))
    assert overall["rmse_m"] == pytest.approx(rmse, rel=0.01)
    assert overall["bias_m"] == pytest.approx(float(error.mean()), abs=0.01 * rmse)
    assert overall["std_m"] == pytest.approx(float(error.std()), rel=0.01)
    assert overall["outlier_share"] == pytest.approx(float(np.mean(np.abs(error) > 1.0)), abs=1e-3)
    assert ranging["options"]["dims"] == 2
    assert ranging["options"]["tag_height_m"] == pytest.approx(1.2)  # the walk's height
    estimates = doc["estimates"]
    assert [e["name"] for e in estimates] == ["nlls", "minmax"]
    assert doc["options"]["align"] == "none"
    assert doc["options"]["planar"] is True
    roles = [i["role"] for i in doc["inputs"]]
    assert roles == ["reference", "anchors", "ranges"]


def test_clean_ranges_position_the_walk(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Noise-free synchronous ranges: NLLS lands on the walk (ATE < 1 cm), 2D and 3D."""
    reference, anchors, ranges = _inputs(
        tmp_path, rng, bias_m=[0.0] * 13, noise_m=[0.0] * 13, synchronous=True
    )
    for dims in ("2", "3"):
        doc = _run_json(
            capsys, reference, "--anchors", anchors, "--ranges", ranges, "--dims", dims,
            "--solve", "nlls",
        )  # fmt: skip
        (nlls,) = doc["estimates"]
        assert nlls["name"] == "nlls"
        assert nlls["ate"]["translation_m"]["max"] < 0.01, dims
        assert nlls["dropped"] == {"outside": 0, "gap": 0, "unmatched": 0}


def test_artifacts_errors_csv_one_row_per_epoch(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """--out writes result.json (with the ranging object) and errors.csv, a row per epoch."""
    reference, anchors, ranges = _inputs(tmp_path, rng)
    out = tmp_path / "out"
    code = main([
        "ranging", str(reference), "--anchors", str(anchors), "--ranges", str(ranges),
        "--out", str(out), "--formats", "errors.csv",
    ])  # fmt: skip
    text, err = capsys.readouterr()
    assert code == 0, err
    assert "Ranging errors" in text
    assert "nlls" in text
    assert "minmax" in text
    document = json.loads((out / "result.json").read_text())
    assert document["ranging"]["overall"]["n"] > 0
    with (out / "errors.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    matched = {e["name"]: e["matched"] for e in document["estimates"]}
    assert {name: sum(r["estimate"] == name for r in rows) for name in matched} == matched
    # Epochs of 0.1 s over the 83.3 s walk, ranged 0.1 s before its end: 832 epochs.
    assert matched == {"nlls": 832, "minmax": 832}


def test_tag_offset_moves_the_true_distances(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ranges from a tag 0.5 m ahead: with --tag-offset the bias is the generated one."""
    bias = [0.1] * 13
    reference, anchors, ranges = _inputs(
        tmp_path, rng, bias_m=bias, noise_m=[0.01] * 13, tag_offset_xyz=(0.5, 0.0, 0.3)
    )
    argv = (reference, "--anchors", anchors, "--ranges", ranges)
    shifted = _run_json(capsys, *argv, "--tag-offset", "0.5 0 0.3")
    plain = _run_json(capsys, *argv)
    assert shifted["ranging"]["overall"]["bias_m"] == pytest.approx(0.1, abs=0.005)
    assert plain["ranging"]["overall"]["std_m"] > 0.1


def test_bad_rows_are_dropped_and_counted(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Unknown anchor ids, negative and NaN ranges are dropped, counted and named."""
    reference, anchors, ranges = _inputs(tmp_path, rng)
    lines = ranges.read_text().splitlines()
    stamp = lines[1].split(",")[0]
    bad = [f"{stamp},ZZ9,3.0", f"{stamp},A01,-1.0", f"{stamp},A02,nan"]
    ranges.write_text("\n".join([*lines, *bad]) + "\n")
    doc = _run_json(capsys, reference, "--anchors", anchors, "--ranges", ranges)
    warnings = " ".join(doc["ranging"]["warnings"])
    assert "3 of " in warnings
    assert "1 whose range is NaN" in warnings
    assert "1 with a negative range" in warnings
    assert "1 with an anchor id not in the anchors file ('ZZ9')" in warnings


def test_too_few_anchors_skip_epochs(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """With anchors heard only within 6 m, epochs with fewer than 4 anchors are skipped (3D)."""
    reference, anchors, ranges = _inputs(tmp_path, rng, max_range_m=6.0)
    doc = _run_json(capsys, reference, "--anchors", anchors, "--ranges", ranges, "--dims", "3")
    for estimate in doc["estimates"]:
        skipped = [w for w in estimate["warnings"] if "skipped" in w]
        assert len(skipped) == 1, estimate["warnings"]
        assert "fewer than 4 anchors heard (3D positioning needs 4)" in skipped[0]


def test_no_time_overlap_is_an_error(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ranges from another day than the reference: exit 1, the spans named."""
    reference, anchors, _ = _inputs(tmp_path, rng)
    recording = make_ranges(rng, t0_ns=2_000_000_000 * 10**9)
    ranges = write_ranges_csv(tmp_path / "later.csv", recording.ranges)
    line = _error(capsys, reference, "--anchors", anchors, "--ranges", ranges)
    assert "falls within the reference" in line
    assert "same clock" in line


def test_no_usable_row_is_an_error(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ranges whose ids match no anchor: exit 1 naming the ids and the columns."""
    reference, anchors, _ = _inputs(tmp_path, rng)
    ranges = tmp_path / "ranges.csv"
    ranges.write_text("t,anchor_id,range_m\n1700000001.0,X1,2.0\n1700000001.1,X2,2.5\n")
    line = _error(capsys, reference, "--anchors", anchors, "--ranges", ranges)
    assert "none of the 2 range rows is usable" in line
    assert "'X1'" in line


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (("--epoch", "0"), "--epoch: The epoch length must be a finite number of seconds more"),
        (("--solve", "nlls,kalman"), "--solve: The positioning algorithms are nlls and minmax"),
        (("--tag-offset", "1 2"), '--tag-offset: The tag offset takes three numbers "x y z"'),
        (("--outlier-threshold", "-1"), "--outlier-threshold: The outlier threshold must be"),
        (("--tag-height", "nan"), "--tag-height: The tag height must be a finite number"),
    ],
)
def test_bad_options_name_their_flag(
    tmp_path: Path,
    rng: np.random.Generator,
    capsys: pytest.CaptureFixture[str],
    argv: tuple[str, ...],
    expected: str,
) -> None:
    """Each bad ranging option fails with its flag and the allowed values."""
    reference, anchors, ranges = _inputs(tmp_path, rng)
    line = _error(capsys, reference, "--anchors", anchors, "--ranges", ranges, *argv)
    assert expected in line


def test_bad_input_contract_as_a_subprocess(tmp_path: Path, rng: np.random.Generator) -> None:
    """As a user runs it: a missing anchors file exits 1 with one error line."""
    reference, _, ranges = _inputs(tmp_path, rng)
    missing = tmp_path / "missing.csv"
    proc = run_cli("ranging", reference, "--anchors", missing, "--ranges", ranges, timeout=120)
    assert "missing.csv" in cli_error_line(proc)


def test_ranges_from_a_bag_topic(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """--ranges BAG@TOPIC reads sensor_msgs/msg/Range; a bag without a topic is refused."""
    reference, anchors, _ = _inputs(tmp_path, rng)
    ranges = make_ranges(rng, end_s=10.0).ranges
    ids = np.array(ranges.anchors.ids)[ranges.anchor_index]
    records = [
        bf.Record("/uwb/range", bf.RANGE, int(t), (int(t), float(r)), frame_id=str(i))
        for t, r, i in zip(ranges.stamps_ns, ranges.range_m, ids, strict=True)
    ]
    bag = bf.write_bag(tmp_path / "uwb.mcap", records, fmt="mcap")
    doc = _run_json(capsys, reference, "--anchors", anchors, "--ranges", f"{bag}@/uwb/range")
    assert doc["ranging"]["overall"]["n"] == len(ranges)
    assert doc["inputs"][2]["selector"] == "/uwb/range"
    line = _error(capsys, reference, "--anchors", anchors, "--ranges", bag)
    assert "name the topic of its sensor_msgs/msg/Range messages" in line
