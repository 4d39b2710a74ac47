"""One numbering of the greatest errors and one tolerance-anchored colour scale in every output.

The office run (:mod:`tests.exporters.office`: 0.010 m everywhere, two bursts to 0.060 m
and 0.045 m in the office) with a tolerance of 0.025 m. The greatest errors are numbered
``#1`` ... ``#N`` by rank, without gaps, at the same poses, in the viewer, the report, the
DXF, the .3dm, the GLB and the IFC; the ATE layers of the DXF, .3dm, GLB and IFC colour each
vertex with the tolerance's scale: green where its error is within 0.025 m, orange to red
exactly where it is beyond.
"""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import KDTree

from exporters.colours import ATEBin, error_bins, tolerance_bins
from exporters.options import ExportOptions, Units
from exporters.report.view import build_report_view
from exporters.viewer.scene import viewer_scene
from loceval.evaluation import EvaluationResult
from tests.exporters.office import TOLERANCE_M, evaluate_office

ezdxf = pytest.importorskip("ezdxf")
rhino3dm = pytest.importorskip("rhino3dm")
pygltflib = pytest.importorskip("pygltflib")
ifcopenshell = pytest.importorskip("ifcopenshell")

OPTIONS = ExportOptions(units=Units.M, simplify_m=0.0, title="office")
_RANK = re.compile(r"#(\d+)\b")


@pytest.fixture(scope="module")
def run() -> EvaluationResult:
    """The office run against a 0.025 m tolerance, no alignment (the ATE is the known error)."""
    return evaluate_office()


@pytest.fixture(scope="module")
def files(run: EvaluationResult, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every CAD file of the run, written by write_artifacts (one placement, as the CLI)."""
    from exporters import write_artifacts

    out = tmp_path_factory.mktemp("cad")
    names = ["paths.dxf", "paths.3dm", "paths.glb", "paths.ifc"]
    return {p.name: p for p in write_artifacts(run, out, OPTIONS, names=names)}


def ranks_in(labels: list[str]) -> list[int]:
    """The ``#k`` numbers of labels, in order."""
    return [int(m.group(1)) for m in (_RANK.search(t) for t in labels) if m]


def test_the_greatest_errors_are_distinct_peaks(run: EvaluationResult) -> None:
    """The two bursts are #1 and #2, at their peaks; no two listed errors are 2 s apart or less."""
    (est,) = run.estimates
    assert [round(w.error, 3) for w in est.worst[:2]] == [0.060, 0.045]
    times = np.array([w.t_s for w in est.worst])
    gaps = np.abs(times[:, None] - times[None, :])[~np.eye(len(times), dtype=bool)]
    assert gaps.min() >= 2.0
    values = est.ate_translation.values
    stamps = est.ate_translation.stamps_ns
    for w in est.worst:  # each is the greatest within 2 s either side of itself
        near = np.abs(stamps - w.stamp_ns) < 2_000_000_000
        assert w.error == values[near].max()


def test_one_numbering_in_every_output(run: EvaluationResult, files: dict[str, Path]) -> None:
    """#1..#N by rank, no gap, at the same poses in viewer, report, DXF, .3dm, GLB and IFC."""
    (est,) = run.estimates
    n = len(est.worst)
    assert n == run.config.worst_count  # a 53 s run has room for ten distinct peaks
    expected = list(range(1, n + 1))
    at = np.array([est.aligned.positions_xyz[w.index] for w in est.worst])

    scene = viewer_scene(run, OPTIONS)
    assert [w["rank"] for w in scene["worst"]] == expected
    assert ranks_in([w["label"] for w in scene["worst"]]) == expected
    (table,) = build_report_view(run, OPTIONS, plots=()).worst
    assert [row.rank for row in table.rows] == expected

    dxf = ezdxf.readfile(files["paths.dxf"])
    texts = dxf.modelspace().query('TEXT[layer=="slam markers"]')
    assert ranks_in([t.dxf.text for t in texts]) == expected
    points = dxf.modelspace().query('POINT[layer=="slam markers"]')
    np.testing.assert_allclose([p.dxf.location.xyz for p in points], at, atol=1e-6)

    model = rhino3dm.File3dm.Read(str(files["paths.3dm"]))
    dots = [o.Geometry for o in model.Objects if isinstance(o.Geometry, rhino3dm.TextDot)]
    worst_dots = [d for d in dots if "ATE" in d.Text]
    assert ranks_in([d.Text for d in worst_dots]) == expected
    np.testing.assert_allclose(
        [[d.Point.X, d.Point.Y, d.Point.Z] for d in worst_dots], at, atol=1e-6
    )

    glb = pygltflib.GLTF2.load_from_bytes(files["paths.glb"].read_bytes())
    (group,) = [node for node in glb.nodes if node.name == "slam markers"]
    labels = [glb.nodes[c].name for c in group.children]
    assert ranks_in(labels) == expected

    ifc = ifcopenshell.open(str(files["paths.ifc"]))
    marks = [a for a in ifc.by_type("IfcAnnotation") if a.ObjectType == "greatest error"]
    assert ranks_in([a.Name for a in marks]) == expected


def _bin_of(bins: tuple[ATEBin, ...], error: float) -> ATEBin:
    return next(b for b in bins if error <= b.high_m)


def _check_colours(
    run: EvaluationResult, runs: list[tuple[np.ndarray, tuple[int, int, int]]], what: str
) -> None:
    """Each run's vertices but its last (shared with the next run) have its colour's bin."""
    (est,) = run.estimates
    bins = error_bins(run)
    tree = KDTree(est.aligned.positions_xyz)
    beyond_colours = {b.color_rgb for b in bins if b.beyond}
    seen_beyond = seen_within = 0
    for vertices, rgb in runs:
        distance, index = tree.query(vertices[:-1])
        assert distance.max() < 1e-6, what  # every vertex is a pose (no simplification)
        errors = est.ate_translation.values[index]
        assert {_bin_of(bins, e).color_rgb for e in errors} == {rgb}, what
        beyond = rgb in beyond_colours
        assert bool(np.all(errors > TOLERANCE_M)) == beyond, what
        seen_beyond += int(beyond) * len(errors)
        seen_within += int(not beyond) * len(errors)
    # the vertices beyond the tolerance are exactly the poses beyond it (the last of the
    # recording is a run's last vertex, never counted)
    over = int(np.sum(est.ate_translation.values[:-1] > TOLERANCE_M))
    assert seen_beyond == over, what
    assert seen_within > 0, what


def test_tolerance_colours_in_the_cad_layers(run: EvaluationResult, files: dict[str, Path]) -> None:
    """The ATE layers use the tolerance's scale, beyond colours exactly where ATE > 0.025 m."""
    bins = error_bins(run)
    assert bins == tolerance_bins(TOLERANCE_M)
    assert [b.beyond for b in bins] == [False, False, True, True, True]
    assert [b.high_m for b in bins[:-1]] == pytest.approx([0.0125, 0.025, 0.0375, 0.05])

    dxf = ezdxf.readfile(files["paths.dxf"])
    pieces = dxf.modelspace().query('POLYLINE[layer=="slam ATE"]')
    _check_colours(
        run,
        [
            (
                np.array([v.dxf.location.xyz for v in p.vertices]),
                ezdxf.colors.int2rgb(p.dxf.true_color),
            )
            for p in pieces
        ],
        "dxf",
    )
    legend = [t.dxf.text for t in dxf.modelspace().query('TEXT[layer=="slam ATE"]')]
    assert "Tolerance: within 0.025 m for 95 % of poses." in legend[1]

    model = rhino3dm.File3dm.Read(str(files["paths.3dm"]))
    layers = {layer.Index: layer.FullPath for layer in model.Layers}
    curves = [o for o in model.Objects if layers[o.Attributes.LayerIndex].endswith("slam::ATE")]
    _check_colours(
        run,
        [
            (
                np.array(
                    [
                        [p.X, p.Y, p.Z]
                        for p in (c.Geometry.Point(i) for i in range(c.Geometry.PointCount))
                    ]
                ),
                tuple(c.Attributes.ObjectColor)[:3],
            )
            for c in curves
        ],
        "3dm",
    )
    assert "within 0.025 m for 95 % of poses" in model.Strings["loceval.ate_legend"]

    glb = pygltflib.GLTF2.load_from_bytes(files["paths.glb"].read_bytes())
    _check_colours(run, _glb_runs(glb, bins), "glb")

    ifc = ifcopenshell.open(str(files["paths.ifc"]))
    (ate,) = [a for a in ifc.by_type("IfcAnnotation") if a.ObjectType == "ATE"]
    assert ate.Name == "slam ATE"
    assert "within 0.025 m for 95 % of poses" in ate.Description
    colour_of = {}
    for styled in ifc.by_type("IfcStyledItem"):
        colour = styled.Styles[0].CurveColour
        colour_of[styled.Item.id()] = tuple(
            round(c * 255) for c in (colour.Red, colour.Green, colour.Blue)
        )
    items = ate.Representation.Representations[0].Items
    _check_colours(run, [(np.array(c.Points.CoordList), colour_of[c.id()]) for c in items], "ifc")


def _glb_runs(
    glb: object, bins: tuple[ATEBin, ...]
) -> list[tuple[np.ndarray, tuple[int, int, int]]]:
    """The GLB's ATE strip cut back into runs: a run ends where a vertex repeats."""
    from exporters.cad.gltf_scene import linear_rgba

    (node,) = [n for n in glb.nodes if n.name == "slam ATE"]
    base = np.array(glb.scenes[0].extras["base_point"])
    blob = glb.binary_blob()

    def read(index: int) -> np.ndarray:
        acc = glb.accessors[index]
        view = glb.bufferViews[acc.bufferView]
        start = view.byteOffset + (acc.byteOffset or 0)
        return np.frombuffer(blob, np.float32, acc.count * 3, start).reshape(-1, 3)

    linear = {tuple(np.round(linear_rgba(b.color_rgb)[:3], 4)): b.color_rgb for b in bins}
    out = []
    for primitive in glb.meshes[node.mesh].primitives:
        xyz = read(primitive.attributes.POSITION).astype(np.float64) + base
        rgb = [
            linear[tuple(np.round(c, 4))] for c in read(primitive.attributes.COLOR_0).astype(float)
        ]
        ends = [i + 1 for i in range(len(xyz) - 1) if np.array_equal(xyz[i], xyz[i + 1])]
        for a, b in zip([0, *ends], [*ends, len(xyz)], strict=True):
            out.append((xyz[a:b], rgb[a]))
    return out


def test_hops_reads_the_coloured_runs(run: EvaluationResult) -> None:
    """paths.3dm.json, which Hops serves, carries every run in its tolerance colour."""
    from exporters.cad.rhino import export_3dm_json

    document = json.loads(export_3dm_json(run, OPTIONS))
    (slam,) = [p for p in document["paths"] if p["name"] == "slam"]
    bins = error_bins(run)
    assert {tuple(r["color"]) for r in slam["ate"]} == {b.color_rgb for b in bins}
    assert [b["beyond"] for b in document["ate_bins"]] == [False, False, True, True, True]
    assert "within 0.025 m" in document["ate_legend"]


def test_dxf_legends_outside_the_building(run: EvaluationResult, tmp_path: Path) -> None:
    """With a building, the DXF's title and legends lie outside its extent (not in a room)."""
    from exporters.cad.dxf import export_dxf
    from tests.exporters.office import write_office

    ifc = write_office(tmp_path / "office.ifc")
    options = ExportOptions(units=Units.M, building=ifc, title="office")
    doc = ezdxf.read(io.StringIO(export_dxf(run, options).decode("utf-8")))
    lo, hi = np.array([-0.2, -0.2]), np.array([10.2, 6.2])  # the outer walls' faces
    texts = [t for t in doc.modelspace().query("TEXT") if t.dxf.layer in ("loceval", "slam ATE")]
    assert len(texts) >= 7  # the title, the heading, the legend sentence, five bins
    for text in texts:
        x, y = text.dxf.insert.x, text.dxf.insert.y
        inside = lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]
        assert not inside, (text.dxf.text, x, y)
