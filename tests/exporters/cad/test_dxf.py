"""DXF export: read back with ezdxf, audit, and render with LibreCAD."""

from __future__ import annotations

import io
import itertools
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from exporters.cad.placement import parse_site
from exporters.colours import error_bins, scale_words, tolerance_bins
from exporters.errors import ExportError, ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval.core.polyline import polyline_distances
from loceval.evaluation import EvaluationResult
from tests.conftest import require_tool
from tests.exporters.conftest import expected_paths, with_reference_loss

ezdxf = pytest.importorskip("ezdxf")
from exporters.cad import dxf  # noqa: E402  (after the importorskip of its library)
from exporters.cad.dxf_bulk import BulkPolylines, ColouredPieces  # noqa: E402

SITE = "2000.25 -1500.5 12.3 30"
NAMES = ["OptiTrack", "RTAB-Map", "ISAAC"]


def read(data: bytes) -> ezdxf.document.Drawing:
    """Parse DXF bytes with ezdxf."""
    return ezdxf.read(io.StringIO(data.decode("utf-8")))


@pytest.fixture
def options() -> ExportOptions:
    """Return placement options with a site offset and rotation, in millimetres."""
    return ExportOptions(site=parse_site(SITE), evaluation_id="ev-42", title="Lab run")


@pytest.fixture
def drawing(two_estimates: EvaluationResult, options: ExportOptions) -> ezdxf.document.Drawing:
    """Return the exported DXF of the two-estimate evaluation, read back."""
    return read(dxf.export_dxf(two_estimates, options))


def test_one_3d_polyline_per_trajectory_round_trip(
    drawing: ezdxf.document.Drawing, two_estimates: EvaluationResult, options: ExportOptions
):
    """Each trajectory is one 3D POLYLINE on its layer, within 1 mm of the mapped poses."""
    msp = drawing.modelspace()
    assert len(msp.query("LWPOLYLINE")) == 0
    for name, expected in zip(NAMES, expected_paths(two_estimates, options), strict=True):
        polylines = msp.query(f'POLYLINE[layer=="{name}"]')
        assert len(polylines) == 1
        polyline = polylines[0]
        assert polyline.is_3d_polyline
        vertices = np.array([v.dxf.location.xyz for v in polyline.vertices])
        assert len(vertices) <= len(expected)
        np.testing.assert_allclose(vertices[[0, -1]], expected[[0, -1]], atol=1e-6)
        assert polyline_distances(expected, vertices).max() <= 1.0 + 1e-6  # mm
        assert np.ptp(vertices[:, 2]) > 100.0  # z kept: the walk rises and falls 0.2 m
        xdata = dict(t.split("=", 1) for _, t in polyline.get_xdata(dxf.APPID))
        assert xdata["name"] == name
        assert float(xdata["max_deviation_m"]) <= 0.001


def test_layers_colours(drawing: ezdxf.document.Drawing):
    """Layers are named after the trajectories with palette ACI and true colours."""
    expected = {
        "OptiTrack": (4, (0, 255, 255)),
        "RTAB-Map": (6, (255, 0, 255)),
        "ISAAC": (None, (0, 200, 0)),
    }
    for name, (aci, rgb) in expected.items():
        layer = drawing.layers.get(name)
        assert tuple(layer.rgb) == rgb
        assert layer.is_on()
        if aci is not None:
            assert layer.color == aci
        assert 1 <= layer.color <= 255
        if name != "OptiTrack":  # the reference has no gap, hence no markers
            assert tuple(drawing.layers.get(f"{name} markers").rgb) == rgb


def test_header_units_and_metadata(drawing: ezdxf.document.Drawing):
    """$INSUNITS is millimetres, $MEASUREMENT metric, and custom properties carry metadata."""
    assert drawing.dxfversion == "AC1027"  # R2013
    assert drawing.header["$INSUNITS"] == 4
    assert drawing.header["$MEASUREMENT"] == 1
    props = dict(drawing.header.custom_vars)
    assert props["loceval.evaluation_id"] == "ev-42"
    assert props["loceval.units"] == "mm"
    assert props["loceval.evaluation_frame"] == "map"
    assert float(props["loceval.max_deviation_m"]) <= 0.001
    assert float(props["loceval.simplify_tolerance_m"]) == 0.001
    base = json.loads(props["loceval.base_point"])
    assert np.abs(np.array(base) - [2000000.0, -1500000.0, 12000.0]).max() < 10_000.0
    assert base == [round(v / 1000) * 1000.0 for v in base]  # whole metres
    np.testing.assert_allclose(
        json.loads(props["loceval.site_matrix_m"]), parse_site(SITE).as_matrix(), atol=1e-12
    )


@pytest.mark.parametrize(("units", "insunits"), [(Units.MM, 4), (Units.CM, 5), (Units.M, 6)])
def test_units(two_estimates: EvaluationResult, units: Units, insunits: int):
    """Each output unit sets $INSUNITS and scales the vertices."""
    options = ExportOptions(units=units)
    doc = read(dxf.export_dxf(two_estimates, options))
    assert doc.header["$INSUNITS"] == insunits
    polyline = doc.modelspace().query('POLYLINE[layer=="OptiTrack"]')[0]
    first = np.array(polyline.vertices[0].dxf.location.xyz)
    expected = two_estimates.reference.positions_xyz[0] * units.per_metre
    np.testing.assert_allclose(first, expected, rtol=1e-12)


def test_audit_clean(tmp_path: Path, two_estimates: EvaluationResult, options: ExportOptions):
    """The drawing passes ezdxf's auditor and the `ezdxf audit` command without errors."""
    data = dxf.export_dxf(two_estimates, options)
    auditor = read(data).audit()
    assert not auditor.has_errors, [e.message for e in auditor.errors]
    assert not auditor.has_fixes, [f.message for f in auditor.fixes]
    path = tmp_path / "paths.dxf"
    path.write_bytes(data)
    run = subprocess.run(
        [sys.executable, "-m", "ezdxf", "audit", str(path)],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert "No errors found." in run.stdout


def test_ate_layer(drawing: ezdxf.document.Drawing, two_estimates: EvaluationResult):
    """The ATE layer (on, not frozen) covers the estimate in the report's colours, with legend.

    The evaluation has a tolerance (0.10 m): the colours are the scale anchored to it and the
    legend names it in words.
    """
    bins = error_bins(two_estimates)  # anchored to its tolerance (0.10 m)
    assert bins == tolerance_bins(0.10)
    bin_colours = {b.color_rgb for b in bins}
    for est in two_estimates.estimates:
        layer = drawing.layers.get(f"{est.name} ATE")
        assert layer.is_on()
        assert not layer.is_frozen()
        pieces = drawing.modelspace().query(f'POLYLINE[layer=="{est.name} ATE"]')
        assert len(pieces) > 1
        assert all(p.is_3d_polyline for p in pieces)
        assert {ezdxf.colors.int2rgb(p.dxf.true_color) for p in pieces} <= bin_colours
        vertices = np.concatenate(
            [np.array([v.dxf.location.xyz for v in p.vertices]) for p in pieces]
        )
        assert len(vertices) >= 2
        texts = [t.dxf.text for t in drawing.modelspace().query(f'TEXT[layer=="{est.name} ATE"]')]
        assert texts[0] == f"{est.name}: ATE translation"
        assert texts[1] == scale_words(two_estimates)
        assert "within 0.1 m for 95 % of poses" in texts[1]
        assert texts[2:] == [b.label for b in bins]


def test_ate_pieces_follow_the_estimate(two_estimates: EvaluationResult):
    """Joined, the ATE pieces trace the estimate within the tolerance, bin by bin."""
    options = ExportOptions(units=Units.M)
    doc = read(dxf.export_dxf(two_estimates, options))
    est = two_estimates.estimates[0]
    pieces = doc.modelspace().query(f'POLYLINE[layer=="{est.name} ATE"]')
    vertices = [np.array([v.dxf.location.xyz for v in p.vertices]) for p in pieces]
    expected = est.aligned.positions_xyz
    np.testing.assert_allclose(vertices[0][0], expected[0], atol=1e-9)
    np.testing.assert_allclose(vertices[-1][-1], expected[-1], atol=1e-9)
    for a, b in itertools.pairwise(vertices):
        np.testing.assert_allclose(a[-1], b[0], atol=1e-9)  # pieces join
    joined = np.concatenate(vertices)
    assert polyline_distances(expected, joined).max() <= 0.001 + 1e-9


def test_markers_at_worst_errors_and_gaps(two_estimates: EvaluationResult):
    """POINT and label at the greatest errors and at a tracking loss of the reference."""
    ref = two_estimates.reference
    times = ref.times_s()
    gapped = with_reference_loss(two_estimates)
    doc = read(dxf.export_dxf(gapped, ExportOptions(units=Units.M)))
    msp = doc.modelspace()
    # one marker for the one loss, on its own layer, not repeated per estimate
    loss_labels = [t.dxf.text for t in msp.query('TEXT[layer=="tracking loss"]')]
    assert len(loss_labels) == 1
    assert loss_labels[0].startswith("no pose for 3.0 s")
    gap_points = msp.query('POINT[layer=="tracking loss"]')
    assert len(gap_points) == 1
    gap_point = np.array(gap_points[0].dxf.location.xyz)
    np.testing.assert_allclose(gap_point, ref.positions_xyz[times < 20.0][-1], atol=1e-9)
    # every path breaks there: two polylines each, none bridging the 3 s
    for name in ("OptiTrack", *(e.name for e in gapped.estimates)):
        pieces = msp.query(f'POLYLINE[layer=="{name}"]')
        assert len(pieces) == 2
        ends = [np.array([v.dxf.location.xyz for v in p.vertices]) for p in pieces]
        assert np.linalg.norm(ends[1][0] - ends[0][-1]) > 1.0  # 3 s apart at about 0.6 m/s
    for est in gapped.estimates:
        labels = [t.dxf.text for t in msp.query(f'TEXT[layer=="{est.name} markers"]')]
        assert any(
            label.startswith(f"{est.name} #1: ATE {est.worst[0].error:.3f} m") for label in labels
        )
        points = msp.query(f'POINT[layer=="{est.name} markers"]')
        lines = msp.query(f'LINE[layer=="{est.name} markers"]')
        assert len(points) == len(labels) >= len(lines) >= 1
        worst_here = est.aligned.positions_xyz[est.worst[0].index]
        np.testing.assert_allclose(lines[0].dxf.start.xyz, worst_here, atol=1e-9)
        np.testing.assert_allclose(lines[0].dxf.end.xyz, est.worst[0].position_xyz, atol=1e-9)


def test_bad_options(two_estimates: EvaluationResult):
    """A negative tolerance is an options error, before anything is drawn."""
    with pytest.raises(ExportOptionsError, match="simplification tolerance"):
        dxf.export_dxf(two_estimates, ExportOptions(simplify_m=-1.0))


def test_ezdxf_errors_become_export_errors(
    two_estimates: EvaluationResult, monkeypatch: pytest.MonkeyPatch
):
    """An ezdxf failure surfaces as ExportError, not as an ezdxf exception."""

    def refuse(*_args: object, **_kwargs: object) -> None:
        msg = "invalid table name"
        raise ezdxf.DXFValueError(msg)

    monkeypatch.setattr(dxf, "new_drawing", refuse)
    with pytest.raises(ExportError, match="ezdxf could not write the DXF drawing"):
        dxf.export_dxf(two_estimates, ExportOptions())


def test_librecad_renders(tmp_path: Path, two_estimates: EvaluationResult, options: ExportOptions):
    """`librecad dxf2pdf` (headless) turns the drawing into a one-page PDF with content."""
    librecad = require_tool("librecad")
    pypdf = pytest.importorskip("pypdf")
    path = tmp_path / "paths.dxf"
    path.write_bytes(dxf.export_dxf(two_estimates, options))
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "XDG_RUNTIME_DIR": str(tmp_path)}
    run = subprocess.run(
        [librecad, "dxf2pdf", "-a", "-p", "420x297", "-t", str(tmp_path / "out"), str(path)],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
        env=env,
    )
    pdf = tmp_path / "out" / "paths.pdf"
    assert run.returncode == 0, run.stdout + run.stderr
    assert pdf.is_file(), run.stdout + run.stderr
    reader = pypdf.PdfReader(pdf)
    assert len(reader.pages) == 1
    assert len(reader.pages[0].get_contents().get_data()) > 10_000  # the paths were drawn


def test_extents_cover_the_paths(drawing: ezdxf.document.Drawing):
    """$EXTMIN/$EXTMAX hold the drawing's real extents, not ezdxf's ±1e20 placeholders."""
    lo = np.array(drawing.header["$EXTMIN"])
    hi = np.array(drawing.header["$EXTMAX"])
    assert np.all(np.abs(lo) < 1e9)
    assert np.all(np.abs(hi) < 1e9)
    assert np.all(hi > lo)
    for polyline in drawing.modelspace().query("POLYLINE"):
        points = np.array([v.dxf.location for v in polyline.vertices])
        assert np.all(points >= lo - 1e-6)
        assert np.all(points <= hi + 1e-6)


class _OneEntityPerVertex:
    """ezdxf's own way: every vertex an entity object (the slow path the bulk writer replaces)."""

    def __init__(self, doc: ezdxf.document.Drawing) -> None:
        del doc

    @staticmethod
    def add(msp, vertices, dxfattribs):
        return msp.add_polyline3d(vertices.tolist(), dxfattribs=dict(dxfattribs))

    @staticmethod
    def add_coloured(msp, layer, pieces):
        for vertices, aci, true_color in pieces:
            attribs = {"layer": layer, "color": aci, "true_color": true_color}
            msp.add_polyline3d(vertices.tolist(), dxfattribs=attribs)

    @staticmethod
    def splice(text: str) -> str:
        return text


_PER_DRAWING = {"$TDCREATE", "$TDUCREATE", "$TDUPDATE", "$TDUUPDATE", "$FINGERPRINTGUID"}
_PER_DRAWING |= {"$VERSIONGUID"}


_WRITTEN_AT = re.compile(r"^\d+\.\d+\.\d+ @ \d{4}-\d\d-\d\dT")  # ezdxf's "written by" stamp


def _without_stamps(text: str) -> list[str]:
    """The drawing's group-code lines, minus the values that differ per drawing and save."""
    lines = text.splitlines()
    skip = {i + k for i, line in enumerate(lines) if line in _PER_DRAWING for k in (1, 2, 3)}
    return [line for i, line in enumerate(lines) if i not in skip and not _WRITTEN_AT.match(line)]


def test_bulk_vertices_equal_ezdxf_byte_for_byte(
    monkeypatch: pytest.MonkeyPatch, two_estimates: EvaluationResult, options: ExportOptions
):
    """The spliced VERTEX records are the file ezdxf writes with one entity per vertex."""
    fast = dxf.export_dxf(two_estimates, options).decode("utf-8")
    monkeypatch.setattr(dxf, "BulkPolylines", _OneEntityPerVertex)
    slow = dxf.export_dxf(two_estimates, options).decode("utf-8")
    assert fast.count("\nVERTEX\n") == slow.count("\nVERTEX\n") > 1000
    assert fast.count("\nPOLYLINE\n") == slow.count("\nPOLYLINE\n") > 20  # ATE runs as text
    assert _without_stamps(fast) == _without_stamps(slow)


def test_bulk_pieces_equal_ezdxf_with_signed_zeros_and_shared_numbers() -> None:
    """Pieces as arrays, numbers shared and -0.0 beside 0.0: the text ezdxf writes itself."""
    path = np.array([[0.0, -0.0, 1e300], [1.5, 2.25, -0.0], [1 / 3, 0.0, 7.0]])
    pieces = [(path[:2], 1, 0xFF0000), (path[1:], 3, 0x00FF00), (path[::-1], 1, 0xFF0000)]

    def written(*, bulk: bool) -> str:
        doc = ezdxf.new("R2013", setup=False)
        msp = doc.modelspace()
        stream = io.StringIO()
        if bulk:
            writer = BulkPolylines(doc)
            writer.add(msp, path, {"layer": "path"})
            writer.add_coloured(msp, "ate", ColouredPieces.of(pieces))
            doc.write(stream)
            return writer.splice(stream.getvalue())
        msp.add_polyline3d(path.tolist(), dxfattribs={"layer": "path"})
        for vertices, aci, rgb in pieces:
            attribs = {"layer": "ate", "color": aci, "true_color": rgb}
            msp.add_polyline3d(vertices.tolist(), dxfattribs=attribs)
        doc.write(stream)
        return stream.getvalue()

    fast = written(bulk=True)
    assert "\n-0.0\n" in fast
    assert _without_stamps(fast) == _without_stamps(written(bulk=False))
