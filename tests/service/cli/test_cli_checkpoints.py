"""``loceval evaluate points:survey.csv EST``: control points end to end on the command line.

The recording is the reference-robot paper's test (``001_...`` §IV): a 5 x 9 floor grid at
30 cm, each mark visited three times with a 3 s stop, survey sigma 1 mm; the estimate has
3 mm noise per axis and a (10, -20, 5) mm bias (``tests.checkpoint_factory``). Expected
figures are computed independently here: a Python loop over the true visit windows (per
axis median), and loops over the Hilti tiers and the LaMAria curve.
"""

from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from loceval.checkpoints.fit import evaluate_checkpoints
from loceval.controlpoints import Visits
from loceval.readers.points import read_visits
from service.cli import main
from tests import bagfactory as bf
from tests.checkpoint_factory import (
    NS,
    StopAndGo,
    estimate_tum_rows,
    grid_points,
    stop_and_go,
    write_points,
)
from tests.checkpoint_factory import write_visits as write_true_visits


@pytest.fixture
def recording(rng: np.random.Generator, tmp_path: Path) -> StopAndGo:
    """The 5 x 9 grid visited three times; survey, TUM and CSV estimate under tmp_path."""
    rec = stop_and_go(rng, grid_points())
    write_points(tmp_path / "survey.csv", rec.points)
    rows = estimate_tum_rows(rec)
    (tmp_path / "est.txt").write_text("\n".join(rows) + "\n")
    (tmp_path / "est.csv").write_text("t,x,y,z\n" + "\n".join(r.replace(" ", ",") for r in rows))
    write_true_visits(tmp_path / "visits.csv", rec)
    return rec


def _run(capsys: pytest.CaptureFixture[str], *argv: str | Path) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _truth_errors(rec: StopAndGo) -> np.ndarray:
    """Per-visit measured - surveyed: a loop over the true windows, per-axis median."""
    out = []
    stamps, pos = rec.estimate.stamps_ns.tolist(), rec.estimate.positions_xyz
    for pid, a, b in zip(rec.visit_ids, rec.visit_start_ns, rec.visit_end_ns, strict=True):
        inside = [k for k, s in enumerate(stamps) if a <= s <= b]
        median = [float(np.median(pos[inside, axis])) for axis in range(3)]
        out.append(np.subtract(median, rec.points.positions_xyz[rec.points.ids.index(pid)]))
    return np.array(out)


def _hilti(errors: np.ndarray) -> float:
    total = 0
    for e in errors:
        for bound, points in ((0.005, 20), (0.01, 10), (0.03, 6), (0.06, 5), (0.1, 3), (0.4, 1)):
            if e < bound:
                total += points
                break
    return 100.0 * total / (20 * len(errors))


def _lamaria(errors: np.ndarray) -> float:
    knots = [(0.05, 20), (0.2, 18), (0.5, 15), (1, 12), (2, 8), (5, 4), (10, 0)]
    total = 0.0
    for e in errors:
        if e <= knots[0][0]:
            total += 20
        for (x0, y0), (x1, y1) in itertools.pairwise(knots):
            if x0 < e <= x1:
                total += y0 + (y1 - y0) * (e - x0) / (x1 - x0)
    return 100.0 * total / (20 * len(errors))


def _check_against_truth(doc: dict[str, Any], rec: StopAndGo) -> None:
    [entry] = doc["estimates"]
    visits = entry["checkpoints"]["visits"]
    assert [v["id"] for v in visits] == rec.visit_ids
    assert len(visits) == 135
    truth = _truth_errors(rec)
    measured = np.array([v["measured"] for v in visits]) - np.array([v["surveyed"] for v in visits])
    np.testing.assert_allclose(measured, truth, atol=1e-3)
    e3 = np.linalg.norm(truth, axis=1)
    eh = np.hypot(truth[:, 0], truth[:, 1])
    np.testing.assert_allclose([v["error_m"] for v in visits], e3, atol=1e-3)
    np.testing.assert_allclose([v["error_v_m"] for v in visits], truth[:, 2], atol=1e-3)
    score = entry["checkpoints"]["score"]
    # The bias is 23 mm (3D), far from the tier bounds 10 and 30 mm: every visit earns 6 of 20.
    assert _hilti(e3) == pytest.approx(30.0)
    assert score["hilti"] == pytest.approx(_hilti(e3))
    assert score["lamaria"] == pytest.approx(_lamaria(eh), abs=1e-9)
    assert entry["checkpoints"]["unvisited"] == []
    assert entry["checkpoints"]["unmatched_stops"] == []
    assert entry["checkpoints"]["recall"] == {"0.05": 1.0, "0.1": 1.0, "0.15": 1.0}
    assert entry["ate"]["translation_m"]["n"] == 135
    assert entry["ate"]["translation_m"]["rmse"] == pytest.approx(np.sqrt(np.mean(e3**2)), abs=1e-3)
    assert entry["ate"]["rotation_deg"] is None


def test_auto_visits_on_the_command_line(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--visits auto (the default) finds all 135 visits, assigns them right, scores them."""
    code, out, err = _run(
        capsys, "evaluate", f"points:{tmp_path / 'survey.csv'}", tmp_path / "est.txt",
        "--align", "none", "--json",
    )  # fmt: skip
    assert code == 0, err
    doc = json.loads(out)
    assert doc["reference"]["kind"] == "control_points"
    assert doc["reference"]["points"] == 45
    assert doc["reference"]["source"] == "points:survey.csv"
    assert doc["options"]["visits"] == "auto"
    assert [i["role"] for i in doc["inputs"]] == ["reference", "estimate"]
    _check_against_truth(doc, recording)


def test_visits_file_and_artifacts(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--visits FILE (sniffed survey, CSV estimate) gives the core's figures; errors.csv too."""
    out_dir = tmp_path / "out"
    code, out, err = _run(
        capsys, "evaluate", tmp_path / "survey.csv", tmp_path / "est.csv", "--align", "none",
        "--visits", tmp_path / "visits.csv", "--json", "--out", out_dir,
        "--formats", "result.json,errors.csv",
    )  # fmt: skip
    assert code == 0, err
    doc = json.loads(out)
    _check_against_truth(doc, recording)
    assert doc["options"]["visits"] == "file"
    assert doc["inputs"][-1]["role"] == "visits"
    core = evaluate_checkpoints(
        recording.points,
        recording.estimate,
        visits=read_visits(tmp_path / "visits.csv", recording.points),
    )
    np.testing.assert_allclose(
        [v["error_m"] for v in doc["estimates"][0]["checkpoints"]["visits"]],
        [v.error_m for v in core.visits],
        atol=1e-9,
    )
    assert sorted(p.name for p in out_dir.iterdir()) == ["errors.csv", "result.json"]
    written = json.loads((out_dir / "result.json").read_text())
    assert written["estimates"] == doc["estimates"]
    with (out_dir / "errors.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 135
    assert [r["id"] for r in rows] == recording.visit_ids
    np.testing.assert_allclose(
        [float(r["error_m"]) for r in rows], [v.error_m for v in core.visits], atol=1e-12
    )
    assert {r["used_for_alignment"] for r in rows} == {"false"}


def test_text_tables_and_alignment_points(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --json: scores, recall and visits; --align-points marks the stationing visits."""
    del recording  # the survey, estimate and visits files are written by the fixture
    code, out, err = _run(
        capsys, "evaluate", f"points:{tmp_path / 'survey.csv'}", tmp_path / "est.txt",
        "--align", "se3", "--visits", tmp_path / "visits.csv",
        "--align-points", "P00,P08,P40,P48",
    )  # fmt: skip
    assert code == 0, err
    assert "123 visits scored, 12 fixed the alignment (se3)" in out
    assert "Hilti" in out
    assert "LaMAria" in out
    assert "recall 0.05 m" in out
    assert out.count("(alignment)") == 12


def test_a_gate_on_control_points_is_refused(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--tolerance (and --fail-on) beside a survey exit 1 and say why: no verdict to judge.

    The estimate's errors are about 22 mm; a 10 mm tolerance with ``--fail-on fail`` passed
    before, as the gate found no verdict to fail.
    """
    del recording
    code, _, err = _run(
        capsys, "evaluate", f"points:{tmp_path / 'survey.csv'}", tmp_path / "est.txt",
        "--align", "none", "--tolerance", "0.01@95", "--fail-on", "fail", "--json",
    )  # fmt: skip
    assert code == 1
    assert "--tolerance" in err
    assert "no verdict to gate on" in err
    assert "Traceback" not in err


def test_inspect_lists_the_points(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """loceval inspect of a survey names the kind, the point count and the extent."""
    write_points(tmp_path / "survey.csv", grid_points())
    code, out, _ = _run(capsys, "inspect", tmp_path / "survey.csv", "--json")
    assert code == 0
    doc = json.loads(out)
    assert (doc["kind"], doc["points"], doc["sources"]) == ("points", 45, [])
    assert doc["extent_m"] == pytest.approx([2.4, 1.2, 0.0])  # 8 and 4 steps of 0.3 m


def _survey(path: Path, rows: list[str]) -> Path:
    path.write_text("id,x,y,z\n" + "\n".join(rows) + "\n")
    return path


BAD_INPUT = {
    "duplicate ids": (
        lambda d: [f"points:{_survey(d / 's.csv', ['A,0,0,0', 'B,1,0,0', 'A,0,1,0'])}"],
        r"duplicate|twice|more than once",
    ),
    "fewer than 3 points": (
        lambda d: [f"points:{_survey(d / 's.csv', ['A,0,0,0', 'B,1,0,0'])}"],
        r"2 control points given; at least 3",
    ),
    "unknown id in the visits": (
        lambda d: ["--visits", _visits(d, "P00,1700000002.0,1700000004.0\nZZ9,1.0,2.0")],
        r"ZZ9",
    ),
    "visits outside the estimate": (
        lambda d: ["--visits", _visits(d, "P00,10.0,12.0")],
        r"outside the estimate's time range",
    ),
    "alignment not for points": (
        lambda _d: ["--align", "origin"],
        r"^--align: Control points are aligned with none, se3, sim3 or yaw",
    ),
}


def _visits(folder: Path, rows: str) -> Path:
    path = folder / "bad_visits.csv"
    path.write_text(f"id,t_start,t_end\n{rows}\n")
    return path


@pytest.mark.parametrize("case", list(BAD_INPUT))
def test_bad_input_exits_1_with_the_message(
    case: str, recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each bad input of the issue's list exits 1 with one error line saying what to do."""
    del recording  # the survey and estimate files are written by the fixture
    build, pattern = BAD_INPUT[case]
    extra = build(tmp_path)
    reference = extra.pop(0) if str(extra[0]).startswith("points:") else None
    argv = [
        "evaluate",
        reference or f"points:{tmp_path / 'survey.csv'}",
        tmp_path / "est.txt",
        *(["--align", "none"] if "--align" not in extra else []),
        *extra,
    ]
    code, out, err = _run(capsys, *argv)
    assert code == 1, (out, err)
    [line] = [line for line in err.splitlines() if line.startswith("loceval: error: ")]
    message = line.removeprefix("loceval: error: ")
    assert "Traceback" not in err
    assert __import__("re").search(pattern, message), message


def test_no_stationary_period(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An estimate that never stands still: --visits auto says so and how to fix it."""
    write_points(tmp_path / "survey.csv", grid_points())
    t = np.arange(0.0, 20.0, 1 / 30)
    rows = [f"{s:.6f} {np.cos(s):.6f} {np.sin(s):.6f} 0" for s in t]  # 1 m/s around a circle
    (tmp_path / "moving.txt").write_text("\n".join(rows) + "\n")
    code, _, err = _run(
        capsys, "evaluate", f"points:{tmp_path / 'survey.csv'}", tmp_path / "moving.txt",
        "--align", "none",
    )  # fmt: skip
    assert code == 1
    assert "--visits: No stationary period found in moving" in err
    assert "lower the minimum stop duration, or give a visits file" in err


def test_visits_with_a_trajectory_reference(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A visits file with a trajectory reference is refused, naming the option."""
    del recording
    code, _, err = _run(
        capsys, "evaluate", tmp_path / "est.txt", tmp_path / "est.txt",
        "--visits", tmp_path / "visits.csv",
    )  # fmt: skip
    assert code == 1
    assert "--visits: A visits table applies to a control-point reference" in err


def test_control_points_are_no_estimate(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A survey given as an estimate is refused: it is a reference."""
    del recording
    code, _, err = _run(
        capsys, "evaluate", tmp_path / "est.txt", tmp_path / "survey.csv", "--align", "none"
    )
    assert code == 1
    assert "holds control points (id,x,y,z), not a trajectory" in err


@pytest.mark.parametrize(
    ("fmt", "msgtype"), [("mcap", bf.POINT), ("rosbag1", bf.STRING)], ids=["point", "string"]
)
def test_visits_from_a_bag_topic_of_arrivals(
    fmt: str,
    msgtype: str,
    recording: StopAndGo,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """--visits run.bag@/arrivals: each message starts a visit of the minimum stop duration."""
    records = []
    for pid, start in zip(recording.visit_ids, recording.visit_start_ns.tolist(), strict=True):
        if msgtype == bf.POINT:
            records.append(bf.Record("/arrivals", msgtype, start + 7, (start, (0, 0, 0), None),
                                     frame_id=pid))  # fmt: skip
        else:
            records.append(bf.Record("/arrivals", msgtype, start, pid))
    bag = bf.write_bag(bf.bag_path(tmp_path, fmt, "arrivals"), records, fmt=fmt)
    code, out, err = _run(
        capsys, "evaluate", f"points:{tmp_path / 'survey.csv'}", tmp_path / "est.txt",
        "--align", "none", "--visits", f"{bag}@/arrivals", "--stop-min", "2", "--json",
    )  # fmt: skip
    assert code == 0, err
    visits = json.loads(out)["estimates"][0]["checkpoints"]["visits"]
    index = recording.points.index_of(recording.visit_ids, where="test")
    start = recording.visit_start_ns
    expected = evaluate_checkpoints(
        recording.points,
        recording.estimate,
        visits=Visits(index, start, start + 2 * NS, source="bag"),
    )
    assert [v["id"] for v in visits] == recording.visit_ids
    assert [v["t_end_s"] - v["t_start_s"] for v in visits] == pytest.approx([2.0] * 135)
    np.testing.assert_allclose(
        [v["error_m"] for v in visits], [v.error_m for v in expected.visits], atol=1e-6
    )


def test_a_bag_topic_that_announces_nothing(
    recording: StopAndGo, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A pose topic is not a topic of arrivals; the message names the types that are."""
    del recording
    poses = bf.random_poses(np.random.default_rng(2), 5, dt_ns=NS)
    bag = bf.write_bag(
        tmp_path / "poses.bag", bf.pose_records("/pose", bf.POSE, poses), fmt="rosbag1"
    )
    code, _, err = _run(
        capsys, "evaluate", f"points:{tmp_path / 'survey.csv'}", tmp_path / "est.txt",
        "--align", "none", "--visits", f"{bag}@/pose",
    )  # fmt: skip
    assert code == 1
    assert "arrivals at control points are read from std_msgs/String" in err


@pytest.mark.pdf
@pytest.mark.usefixtures("recording")
def test_every_cad_format_with_out(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--out writes every format; the CAD files agree on the error lines at the site."""
    rhino3dm = pytest.importorskip("rhino3dm")
    pygltflib = pytest.importorskip("pygltflib")
    ezdxf = pytest.importorskip("ezdxf")
    out_dir = tmp_path / "out"
    code, out, err = _run(
        capsys, "evaluate", tmp_path / "survey.csv", tmp_path / "est.txt", "--align", "none",
        "--json", "--out", out_dir, "--units", "m", "--site", "100 200 0 90",
    )  # fmt: skip
    assert code == 0, err
    assert sorted(p.name for p in out_dir.iterdir()) == [
        "errors.csv", "paths.3dm", "paths.3dm.json", "paths.dxf", "paths.glb", "report.html",
        "report.pdf", "result.json", "viewer.html",
    ]  # fmt: skip
    visits = json.loads(out)["estimates"][0]["checkpoints"]["visits"]
    # the site "100 200 0 90" by hand: a quarter turn about z (east becomes north, north
    # becomes west), then 100 m east and 200 m north
    lines = []
    for v in visits:  # a reference loop, per visit
        (sx, sy, sz), (mx, my, mz) = v["surveyed"], v["measured"]
        lines.append([100 - sy, 200 + sx, sz, 100 - my, 200 + mx, mz])
    expected = np.array(lines)
    msp = ezdxf.readfile(out_dir / "paths.dxf").modelspace()
    dxf = np.array([(*e.dxf.start, *e.dxf.end) for e in msp.query('LINE[layer=="est errors"]')])
    np.testing.assert_allclose(dxf, expected, atol=1e-3)
    doc = json.loads((out_dir / "paths.3dm.json").read_text())
    curves = [rhino3dm.CommonObject.Decode(c) for c in doc["paths"][0]["curves"]]
    ends = [(c.PointAtStart, c.PointAtEnd) for c in curves]
    got = np.array([[a.X, a.Y, a.Z, b.X, b.Y, b.Z] for a, b in ends])
    np.testing.assert_allclose(got, expected, atol=1e-3)
    model = rhino3dm.File3dm.Read(str(out_dir / "paths.3dm"))
    kinds = [type(o.Geometry).__name__ for o in model.Objects]
    assert kinds.count("LineCurve") == 135
    assert kinds.count("Point") == 45 + 135  # the grid, then a measured position per visit
    glb = pygltflib.GLTF2.load_from_bytes((out_dir / "paths.glb").read_bytes())
    roots = [glb.nodes[k].name for k in glb.scenes[0].nodes]
    assert roots == ["control points", "est measured", "est errors"]
    errors = glb.nodes[glb.scenes[0].nodes[2]]
    assert [glb.nodes[k].name for k in errors.children] == [
        f"{v['id']} {v['error_m'] * 1000:.1f} mm" for v in visits
    ]
