"""Tests for loceval.inspection on files: text trajectories, Motive takes, URDF, the registry."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from loceval.errors import InputError, ReaderError
from loceval.inspection import (
    INSPECTORS,
    Inspection,
    input_kind,
    inspect,
    render_inspection_text,
)
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory
from tests.factories import (
    ROVER_URDF,
    make_trajectory,
    write_csv,
    write_euroc,
    write_kitti,
    write_motive,
    write_tum,
)

SUMMARY_KEYS = {
    "source",
    "poses",
    "start_s",
    "end_s",
    "duration_s",
    "length_m",
    "rate_hz",
    "orientation",
}
"""The keys ``loceval inspect --json`` printed for text files before the one inspection."""


def _writers(tmp_path: Path):
    return {
        "tum": lambda t: write_tum(tmp_path / "run.txt", t),
        "euroc": lambda t: write_euroc(tmp_path / "gt.csv", t),
        "kitti": lambda t: write_kitti(tmp_path / "00.txt", t),
        "csv": lambda t: write_csv(tmp_path / "log.csv", t),
    }


@pytest.mark.parametrize("fmt", ["tum", "euroc", "kitti", "csv"])
def test_text_file_is_one_source_with_what_reading_gives(tmp_path, rng, fmt):
    """A text file: one source whose count, range, rate and length are what reading gives."""
    path = _writers(tmp_path)[fmt](make_trajectory(rng, 120, dt_ns=20_000_000))
    insp = inspect(path)
    truth = read_trajectory(str(path))
    assert (insp.kind, insp.format) == (fmt, fmt)
    [source] = insp.sources
    assert (source.selector, source.kind) == (None, "file")
    assert source.pose_count == len(truth) == 120
    assert source.first_stamp_ns == truth.stamps_ns[0]
    assert source.last_stamp_ns == truth.stamps_ns[-1]
    assert source.length_m == pytest.approx(truth.length_m)
    assert source.orientation is True
    expected_rate = 1.0 if fmt == "kitti" else 50.0  # KITTI without times: 1 s per pose
    assert source.rate_hz == pytest.approx(expected_rate, rel=1e-6)
    assert insp.single is source
    assert insp.warnings == truth.warnings


def test_text_file_json_keeps_the_cli_summary(tmp_path, rng):
    """to_dict() of a text file holds the CLI's summary keys next to sources and warnings."""
    truth = make_trajectory(rng, 10, dt_ns=100_000_000)
    path = write_tum(tmp_path / "gt.txt", truth)
    data = json.loads(json.dumps(inspect(path).to_dict()))
    assert set(data) >= SUMMARY_KEYS
    assert data["format"] == data["kind"] == "tum"
    assert data["poses"] == 10
    assert data["start_s"] == pytest.approx(int(truth.stamps_ns[0]) / 1e9)
    assert data["duration_s"] == pytest.approx(0.9)
    assert data["rate_hz"] == pytest.approx(10.0)
    assert data["orientation"] is True
    [source] = data["sources"]
    assert source["selector"] is None
    assert source["pose_count"] == 10
    assert "topics" not in data
    assert "links" not in data


def test_kitti_times_option_is_used(tmp_path, rng):
    """A source's options are used as for reading: KITTI with its times file."""
    truth = make_trajectory(rng, 30, dt_ns=100_000_000)
    poses = write_kitti(tmp_path / "00.txt", truth, times_path=tmp_path / "times.txt")
    insp = inspect(f"kitti:{poses}@times=times.txt")
    [source] = insp.sources
    assert source.first_stamp_ns == read_trajectory(f"kitti:{poses}@times=times.txt").stamps_ns[0]
    assert source.rate_hz == pytest.approx(10.0, rel=1e-6)


def test_motive_lists_every_rigid_body(tmp_path, rng):
    """A Motive take with several rigid bodies lists one source per body."""
    a = make_trajectory(rng, 50, dt_ns=10_000_000, name="Drone")
    b = make_trajectory(rng, 50, dt_ns=10_000_000, name="Helmet")
    path = write_motive(tmp_path / "take.csv", {"Drone": a, "Helmet": b}, lost={"Helmet": [7]})
    insp = inspect(path)
    assert insp.kind == "motive"
    assert [(s.selector, s.kind, s.pose_count) for s in insp.sources] == [
        ("Drone", "rigid_body", 50),
        ("Helmet", "rigid_body", 49),  # frame 7 lost
    ]
    drone = read_trajectory(f"{path}@Drone")
    assert insp.sources[0].length_m == pytest.approx(drone.length_m)
    assert insp.single is None
    assert "poses" not in insp.to_dict()
    assert len(set(insp.warnings)) == len(insp.warnings)
    text = render_inspection_text(insp)
    assert "type FILE@SELECTOR" in text
    assert "Drone" in text
    assert "Helmet" in text


def test_motive_selector_limits_to_one_body(tmp_path, rng):
    """A selector inspects that rigid body only, and the file summary is given for it."""
    a = make_trajectory(rng, 40, dt_ns=10_000_000)
    path = write_motive(tmp_path / "take.csv", {"A": a, "B": a})
    insp = inspect(f"{path}@B")
    assert [s.selector for s in insp.sources] == ["B"]
    assert insp.to_dict()["poses"] == 40


def test_motive_without_rigid_bodies(tmp_path, rng):
    """A take without Rigid Body columns is a ReaderError that says what to export."""
    path = write_motive(tmp_path / "take.csv", {"A": make_trajectory(rng, 10)})
    text = path.read_text().replace("Rigid Body", "Marker")
    path.write_text(text)
    with pytest.raises(ReaderError, match="no Rigid Body columns; export the take"):
        inspect(SourceSpec(TrajectoryFormat.MOTIVE, path))


@pytest.mark.public_data
def test_public_motive_take_lists_three_bodies(public_data):
    """motive_take_sample.csv: three rigid bodies, device05 untracked in one frame."""
    insp = inspect(public_data / "motive_take_sample.csv")
    # 40 data rows (47 lines - 7 header lines, counted with wc -l); frame 72229 has 7
    # empty device05 cells (awk over columns 19-25), so device05 keeps 39 poses.
    assert [(s.selector, s.pose_count) for s in insp.sources] == [
        ("device02", 40),
        ("device03", 40),
        ("device05", 39),
    ]
    # Time (Seconds) runs 722.10 .. 722.49 at 100 Hz (first and last rows of the file).
    assert insp.sources[0].duration_s == pytest.approx(0.39)
    assert insp.sources[0].rate_hz == pytest.approx(100.0)
    assert any("Y-up" in w for w in insp.warnings)


def test_urdf_lists_links_and_joints(tmp_path):
    """A URDF: robot name, links in file order, joints, no sources."""
    path = tmp_path / "device.urdf"
    path.write_text(ROVER_URDF)
    insp = inspect(path)
    assert (insp.kind, insp.format, insp.robot) == ("urdf", "urdf", "rover")
    assert insp.links == ("rigid_body", "camera_link")
    assert insp.sources == ()
    data = insp.to_dict()
    assert data["links"] == ["rigid_body", "camera_link"]
    assert data["joints"] == [
        {"name": "mount", "type": "fixed", "parent": "rigid_body", "child": "camera_link"}
    ]
    assert data["sources"] == []
    text = render_inspection_text(insp)
    assert "mount  (fixed): rigid_body → camera_link" in text


def test_urdf_by_kind_and_refused_when_not_urdf(tmp_path):
    """kind='urdf' inspects any name as URDF; other XML is refused as not a URDF."""
    path = tmp_path / "blob.bin"
    path.write_text(ROVER_URDF)
    assert inspect(path, kind="urdf").links == ("rigid_body", "camera_link")
    html = tmp_path / "page.xml"
    html.write_text("<html><body/></html>")
    with pytest.raises(ReaderError, match="XML but not a URDF"):
        inspect(html)


def test_unknown_kind(tmp_path, rng):
    """An unknown kind is an InputError listing the known ones."""
    path = write_tum(tmp_path / "run.txt", make_trajectory(rng, 10))
    with pytest.raises(InputError, match=r"Unknown input kind 'sdf'; use one of tum, euroc"):
        inspect(path, kind="sdf")


def test_format_prefix_wins_over_sniffing(tmp_path, rng):
    """A FORMAT: prefix names the kind, as for reading."""
    path = write_tum(tmp_path / "run.txt", make_trajectory(rng, 10))
    assert input_kind(SourceSpec(TrajectoryFormat.TUM, path)) == "tum"
    assert input_kind(SourceSpec(None, tmp_path / "robot.URDF")) == "urdf"
    assert inspect(f"tum:{path}").kind == "tum"


def test_reader_errors_pass_through(tmp_path):
    """A file no reader takes is the reader's ReaderError."""
    path = tmp_path / "run.txt"
    path.write_text("1.0 0 0 0\n2.0 0 0\n3.0 1 1 1\n")
    with pytest.raises(ReaderError, match=r"line 2: 3 values, but line 1 has 4"):
        inspect(path)


def test_registry_covers_every_format():
    """Every trajectory format, URDF, visits tables and radio ranges have an inspector."""
    assert set(INSPECTORS) == {f.value for f in TrajectoryFormat} | {"urdf", "visits"} | {
        "anchors",
        "ranges",
    }
    for key, spec in INSPECTORS.items():
        assert spec.kind == key
        assert callable(spec.load())


def test_file_text_lists_the_summary(tmp_path, rng):
    """The terminal text of a text file shows the summary lines the CLI printed."""
    path = write_tum(tmp_path / "gt.txt", make_trajectory(rng, 10, dt_ns=100_000_000))
    text = render_inspection_text(inspect(path))
    assert text.startswith(f"{path}  (tum)\n")
    assert "         poses: 10\n" in text
    assert "   orientation: True" in text


def test_result_is_frozen(tmp_path, rng):
    """Inspection is a frozen dataclass."""
    insp = inspect(write_tum(tmp_path / "gt.txt", make_trajectory(rng, 10)))
    assert isinstance(insp, Inspection)
    with pytest.raises(AttributeError):
        insp.kind = "csv"  # type: ignore[misc]


def test_import_loads_no_inspector_module():
    """Importing loceval.inspection loads neither rosbags nor an inspector module."""
    code = (
        "import sys, loceval.inspection; "
        "print(sorted(m for m in sys.modules if m.startswith(('rosbags', "
        "'loceval.inspection.bag', 'loceval.inspection.files', 'loceval.inspection.robot'))))"
    )
    root = Path(__file__).resolve().parents[3]
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root
    )
    assert out.stdout.strip() == "[]"


def test_rates_are_numbers_in_json(tmp_path, rng):
    """Every source's JSON is plain numbers (no numpy types)."""
    path = write_tum(tmp_path / "gt.txt", make_trajectory(rng, 10))
    data = inspect(path).to_dict()
    assert json.loads(json.dumps(data)) == data
    assert isinstance(data["poses"], int)
    assert np.isfinite(float(data["length_m"]))  # type: ignore[arg-type]
