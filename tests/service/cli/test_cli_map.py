"""``loceval evaluate --map SOURCE --building PLAN``: the map in result.json, bad maps exit 1."""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

from loceval.core.geometry import SimilarityTransform
from service.cli import main
from tests.factories import make_trajectory, write_tum
from tests.mapfactory import (
    Distortion,
    draw_map,
    office_plan,
    write_map_bag,
    write_map_server,
)

YAW_DEG = 30.0
SHIFT = (2.0, -1.0)


def _slam_frame() -> SimilarityTransform:
    """The SLAM system's frame: reference frame -> estimate frame (yaw 30°, shifted)."""
    a = math.radians(YAW_DEG)
    rotation = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    return SimilarityTransform(rotation, [*SHIFT, 0.0])


def write_dxf_plan(path: Path, segments: np.ndarray) -> Path:
    """Write the plan's walls as DXF lines in metres."""
    import ezdxf

    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 6
    space = doc.modelspace()
    for (x0, y0), (x1, y1) in segments.tolist():  # a few lines of a test plan
        space.add_line((x0, y0), (x1, y1))
    doc.saveas(path)
    return path


@pytest.fixture(scope="module", name="recording")
def _recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A reference, an estimate in the SLAM frame, its map (yaml, zip) and the plan (DXF)."""
    folder = tmp_path_factory.mktemp("maprun")
    rng = np.random.default_rng(20240601)
    truth = make_trajectory(rng, n=300, planar=True)
    truth = truth.transformed(SimilarityTransform(np.eye(3), [8.0, 2.0, 0.0]))
    plan = office_plan()
    slam = _slam_frame()
    estimate = truth.transformed(slam)
    map_dist = Distortion(yaw_deg=YAW_DEG, translation=SHIFT)
    grid = draw_map(plan, map_dist, resolution_m=0.05, rng=rng, noise_m=0.003)
    yaml = write_map_server(folder / "map", grid)
    bag = write_map_bag(folder / "bag", [(1, grid), (2, grid)])
    zipped = folder / "map.zip"
    with zipfile.ZipFile(zipped, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.write(yaml, "map.yaml")
        archive.write(folder / "map" / "map.pgm", "map.pgm")
    return {
        "reference": write_tum(folder / "gt.txt", truth),
        "estimate": write_tum(folder / "slam.txt", estimate),
        "yaml": yaml,
        "zip": zipped,
        "bag": bag,
        "dxf": write_dxf_plan(folder / "plan.dxf", plan),
        "folder": folder,
    }


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("which", ["yaml", "zip"])
def test_the_map_is_placed_by_the_alignment_and_measured(
    recording: dict[str, Path], capsys: pytest.CaptureFixture[str], which: str
) -> None:
    """The map in the estimate's frame lands on the plan: result.json's map has the figures."""
    code, out, err = _run(
        capsys,
        "evaluate",
        str(recording["reference"]),
        str(recording["estimate"]),
        "--name",
        "SLAM",
        "--map",
        str(recording[which]),
        "--building",
        str(recording["dxf"]),
        "--no-ci",
        "--json",
    )
    assert code == 0, err
    doc = json.loads(out)
    found = doc["map"]
    assert found["placed_by"]["estimate"] == "SLAM"
    assert found["wall_distance_m"]["rmse"] < 0.025
    assert found["wall_distance_m"]["n"] > 1000
    assert found["within"]["0.05"] > 0.95
    assert found["plan_coverage"] > 0.95
    assert found["clutter_cells"] == 0
    assert abs(found["fit"]["rigid"]["rotation_deg"]) < 0.05
    assert abs(found["fit"]["similarity"]["scale"] - 1.0) < 2e-3
    assert doc["estimates"][0]["excursions"] == []


def test_a_map_from_a_bag_topic_as_over_the_api(
    recording: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """``--map BAG@/map`` reads the topic's maps, as the API's dataset and selector (issue 44, 17).

    On main it ended in an internal error: the path was handed on where text was read.
    """
    code, out, err = _run(
        capsys, "evaluate", str(recording["reference"]), str(recording["estimate"]),
        "--map", f"{recording['bag']}@/map", "--building", str(recording["dxf"]),
        "--no-ci", "--json",
    )  # fmt: skip
    assert code == 0, err
    found = json.loads(out)["map"]
    assert len(found["history"]) == 2
    assert found["wall_distance_m"]["rmse"] < 0.025
    assert found["plan_coverage"] > 0.95


def test_the_map_estimate_must_name_an_estimate(
    recording: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """--map-estimate naming no estimate exits 1 listing the names."""
    code, _, err = _run(
        capsys,
        "evaluate",
        str(recording["reference"]),
        str(recording["estimate"]),
        "--map",
        str(recording["yaml"]),
        "--building",
        str(recording["dxf"]),
        "--map-estimate",
        "ORB",
        "--no-ci",
    )
    assert code == 1
    assert "No estimate is named 'ORB'" in err
    assert "Traceback" not in err


def _broken(folder: Path, kind: str, recording: dict[str, Path]) -> str:
    """Write a broken map of one kind; return its source."""
    folder.mkdir(parents=True, exist_ok=True)
    yaml_text = recording["yaml"].read_text(encoding="utf-8")
    pgm = (recording["folder"] / "map" / "map.pgm").read_bytes()
    (folder / "map.yaml").write_text(yaml_text, encoding="utf-8")
    if kind == "truncated":
        (folder / "map.pgm").write_bytes(pgm[: len(pgm) // 2])
    elif kind == "huge":
        (folder / "map.pgm").write_bytes(b"P5\n200000 300000\n255\n" + pgm[-100:])
    elif kind == "empty":
        width, height = 50, 40
        body = bytes([254]) * (width * height)
        (folder / "map.pgm").write_bytes(f"P5\n{width} {height}\n255\n".encode() + body)
    elif kind == "missing":
        pass
    elif kind == "far":
        text = "\n".join(
            "origin: [500.0, 500.0, 0.0]" if line.startswith("origin:") else line
            for line in yaml_text.splitlines()
        )
        (folder / "map.yaml").write_text(text, encoding="utf-8")
        (folder / "map.pgm").write_bytes(pgm)
    return str(folder / "map.yaml")


@pytest.mark.parametrize(
    ("kind", "match"),
    [
        ("truncated", "the image is truncated or does not belong to this map"),
        ("huge", "200000 x 300000 cells"),
        ("empty", "has no occupied cell"),
        ("missing", "is not beside it"),
        ("far", "do not overlap"),
    ],
)
def test_a_bad_map_exits_1_with_the_reason(
    recording: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    kind: str,
    match: str,
) -> None:
    """A PGM not matching its YAML, a huge map, no occupied cell, no image, no overlap: exit 1."""
    source = _broken(tmp_path / kind, kind, recording)
    code, _, err = _run(
        capsys,
        "evaluate",
        str(recording["reference"]),
        str(recording["estimate"]),
        "--map",
        source,
        "--building",
        str(recording["dxf"]),
        "--no-ci",
    )
    assert code == 1
    assert match in err
    assert "Traceback" not in err


def test_a_map_needs_a_plan(recording: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """--map without --building exits 1 saying to give the plan."""
    code, _, err = _run(
        capsys,
        "evaluate",
        str(recording["reference"]),
        str(recording["estimate"]),
        "--map",
        str(recording["yaml"]),
    )
    assert code == 1
    assert "give the plan too" in err


def test_the_tables_show_the_map(
    recording: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """Without --json the tables end with the map's figures as placed and after the fits."""
    code, out, err = _run(
        capsys,
        "evaluate",
        str(recording["reference"]),
        str(recording["estimate"]),
        "--map",
        str(recording["yaml"]),
        "--building",
        str(recording["dxf"]),
        "--no-ci",
    )
    assert code == 0, err
    assert "Map against the plan (map.yaml (map.pgm), 0 clutter cells)" in out
    for label in ("as placed", "rigid fit", "similarity fit"):
        assert f"  {label}" in out
