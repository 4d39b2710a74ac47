"""Rhino .3dm export: read back with rhino3dm's File3dm.Read and FromByteArray."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exporters.cad.placement import parse_site, place_evaluation
from exporters.colours import error_bins
from exporters.errors import ExportError, ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval.core.polyline import polyline_distances
from loceval.evaluation import EvaluationResult
from tests.exporters.conftest import curve_vertices, expected_paths, with_reference_loss

rhino3dm = pytest.importorskip("rhino3dm")
from exporters.cad import rhino  # noqa: E402  (after the importorskip of its library)

SITE = "512340.25 5403210.5 112.3 37.5"
NAMES = ["OptiTrack", "RTAB-Map", "ISAAC"]
COLOURS = [(0, 255, 255), (255, 0, 255), (0, 200, 0)]


@pytest.fixture
def options() -> ExportOptions:
    """Return options with a national-grid-sized site offset, in millimetres."""
    return ExportOptions(site=parse_site(SITE), evaluation_id="ev-42", title="Lab run")


@pytest.fixture
def model_file(tmp_path: Path, two_estimates: EvaluationResult, options: ExportOptions) -> Path:
    """Write the exported .3dm to a file and return its path."""
    path = tmp_path / "paths.3dm"
    path.write_bytes(rhino.export_3dm(two_estimates, options))
    return path


def objects_by_layer(model: object) -> dict[str, list[object]]:
    """Group a model's objects by their layer's full path."""
    layers = {layer.Index: layer.FullPath for layer in model.Layers}
    out: dict[str, list[object]] = {}
    for obj in model.Objects:
        out.setdefault(layers[obj.Attributes.LayerIndex], []).append(obj)
    return out


def test_written_as_rhino_7(model_file: Path):
    """The file is a version 7 archive, which Rhino 7 and 8 open."""
    assert rhino3dm.File3dm.ReadArchiveVersion(str(model_file)) == 70


def test_curves_round_trip(
    model_file: Path, two_estimates: EvaluationResult, options: ExportOptions
):
    """Each trajectory is one named PolylineCurve within 1 mm of the mapped poses."""
    model = rhino3dm.File3dm.Read(str(model_file))
    by_layer = objects_by_layer(model)
    for name, expected in zip(NAMES, expected_paths(two_estimates, options), strict=True):
        (obj,) = by_layer[f"loceval::Lab run::{name}"]
        curve = obj.Geometry
        assert isinstance(curve, rhino3dm.PolylineCurve)
        assert obj.Attributes.Name == name
        vertices = curve_vertices(curve)
        np.testing.assert_allclose(vertices[[0, -1]], expected[[0, -1]], rtol=0, atol=1e-6)
        assert polyline_distances(expected, vertices).max() <= 1.0 + 1e-6  # mm


def test_layers_nested_with_colours(model_file: Path):
    """Layers nest as loceval::<evaluation>::<trajectory> with the palette colours."""
    model = rhino3dm.File3dm.Read(str(model_file))
    layers = {layer.FullPath: layer for layer in model.Layers}
    assert {"loceval", "loceval::Lab run"} <= set(layers)
    for name, rgb in zip(NAMES, COLOURS, strict=True):
        layer = layers[f"loceval::Lab run::{name}"]
        assert layer.Name == name
        assert tuple(layer.Color)[:3] == rgb
        assert layer.Visible


def test_user_strings(model_file: Path, two_estimates: EvaluationResult):
    """Curves carry source and ATE statistics as attribute user text."""
    model = rhino3dm.File3dm.Read(str(model_file))
    by_layer = objects_by_layer(model)
    (ref,) = by_layer["loceval::Lab run::OptiTrack"]
    assert ref.Attributes.GetUserString("loceval.source") == "gt.tum"
    assert ref.Attributes.GetUserString("loceval.kind") == "reference"
    assert ref.Attributes.GetUserString("loceval.poses") == "6000"
    for est in two_estimates.estimates:
        (obj,) = by_layer[f"loceval::Lab run::{est.name}"]
        stats = est.ate_translation.stats
        assert obj.Attributes.GetUserString("loceval.source") == est.estimate.source
        assert float(obj.Attributes.GetUserString("loceval.ate_rmse_m")) == stats.rmse
        assert float(obj.Attributes.GetUserString("loceval.ate_max_m")) == stats.max
        assert float(obj.Attributes.GetUserString("loceval.max_deviation_m")) <= 0.001
        assert obj.Geometry.GetUserString("loceval.name") == est.name


def test_units_base_point_and_document_text(
    model_file: Path, two_estimates: EvaluationResult, options: ExportOptions
):
    """Model units, EarthAnchorPoint base point and document user text are set."""
    model = rhino3dm.File3dm.Read(str(model_file))
    assert model.Settings.ModelUnitSystem == rhino3dm.UnitSystem.Millimeters
    base = model.Settings.EarthAnchorPoint.ModelBasePoint
    expected = place_evaluation(two_estimates, options).base_point
    np.testing.assert_array_equal([base.X, base.Y, base.Z], expected)
    assert np.abs(expected - [512340000.0, 5403210000.0, 112000.0]).max() < 10_000.0
    assert model.Strings["loceval.evaluation_id"] == "ev-42"
    assert model.Strings["loceval.units"] == "mm"
    assert float(model.Strings["loceval.max_deviation_m"]) <= 0.001


@pytest.mark.parametrize(
    ("units", "system"),
    [(Units.MM, "Millimeters"), (Units.CM, "Centimeters"), (Units.M, "Meters")],
)
def test_model_units(two_estimates: EvaluationResult, units: Units, system: str):
    """Each output unit sets the model unit system and scales the vertices."""
    model = rhino3dm.File3dm.FromByteArray(
        rhino.export_3dm(two_estimates, ExportOptions(units=units))
    )
    assert model.Settings.ModelUnitSystem == getattr(rhino3dm.UnitSystem, system)
    (ref,) = objects_by_layer(model)["loceval::loceval evaluation::OptiTrack"]
    first = curve_vertices(ref.Geometry)[0]
    expected = two_estimates.reference.positions_xyz[0] * units.per_metre
    np.testing.assert_allclose(first, expected, rtol=1e-12)


def test_ate_coloured_curves_and_dots(model_file: Path, two_estimates: EvaluationResult):
    """Each estimate has curves in the ATE bin colours on a visible ATE layer, and dots."""
    model = rhino3dm.File3dm.Read(str(model_file))
    layers = {layer.FullPath: layer for layer in model.Layers}
    by_layer = objects_by_layer(model)
    bins = error_bins(two_estimates)  # anchored to its tolerance (0.10 m)
    edges = np.array([b.high_m for b in bins[:-1]])
    assert model.Strings["loceval.ate_bins"].startswith(f"{bins[0].label}: #")
    for est in two_estimates.estimates:
        path = f"loceval::Lab run::{est.name}"
        assert layers[f"{path}::ATE"].Visible
        runs = by_layer[f"{path}::ATE"]
        assert len(runs) > 1
        assert all(isinstance(o.Geometry, rhino3dm.PolylineCurve) for o in runs)
        assert all(
            o.Attributes.ColorSource == rhino3dm.ObjectColorSource.ColorFromObject for o in runs
        )
        colours = [tuple(o.Attributes.ObjectColor)[:3] for o in runs]
        assert set(colours) <= {b.color_rgb for b in bins}
        # the first run starts at the first pose: its colour is the bin of that pose's error
        first_bin = int(np.searchsorted(edges, est.ate_translation.values[0], side="left"))
        assert colours[0] == bins[first_bin].color_rgb
        label_of = {b.color_rgb: b.label for b in bins}
        for run, rgb in zip(runs, colours, strict=True):  # named by its bin
            assert run.Attributes.Name == f"{est.name} ATE {label_of[rgb]}"
        dots = by_layer[f"{path}::markers"]
        assert all(isinstance(o.Geometry, rhino3dm.TextDot) for o in dots)
        assert dots[0].Geometry.Text.startswith(f"{est.name} #1: ATE {est.worst[0].error:.3f} m")


def test_tracking_loss_breaks_curves_once_marked(two_estimates: EvaluationResult):
    """A 3 s reference loss: two curves per trajectory and one dot on the loss layer."""
    gapped = with_reference_loss(two_estimates)
    model = rhino3dm.File3dm.FromByteArray(
        rhino.export_3dm(gapped, ExportOptions(units=Units.M, title="Gap run"))
    )
    by_layer = objects_by_layer(model)
    for name in NAMES:
        assert len(by_layer[f"loceval::Gap run::{name}"]) == 2
    (dot,) = by_layer["loceval::Gap run::tracking loss"]
    assert dot.Geometry.Text.startswith("no pose for 3.0 s")


def test_bad_options(two_estimates: EvaluationResult):
    """Unknown units are an options error."""
    with pytest.raises(ExportOptionsError, match="CAD units must be one of"):
        rhino.export_3dm(two_estimates, ExportOptions(units="ft"))  # type: ignore[arg-type]


def test_write_failure_becomes_export_error(
    two_estimates: EvaluationResult, monkeypatch: pytest.MonkeyPatch
):
    """A model rhino3dm refuses to write surfaces as ExportError."""

    class Unwritable:
        def Write(self, _path: str, _version: int) -> bool:  # noqa: N802  (rhino3dm's name)
            return False

    monkeypatch.setattr(rhino, "_model", lambda _placement: Unwritable())
    with pytest.raises(ExportError, match=r"rhino3dm could not write the \.3dm model"):
        rhino.export_3dm(two_estimates, ExportOptions())


def test_one_placement_shares_its_curves_between_the_3dm_and_its_json(
    two_estimates: EvaluationResult, options: ExportOptions, monkeypatch: pytest.MonkeyPatch
):
    """Both files from one placement equal each written from its own; curves built once."""
    alone_json = rhino.export_3dm_json(two_estimates, options)
    alone_model = rhino3dm.File3dm.FromByteArray(rhino.export_3dm(two_estimates, options))
    built = 0
    curve = rhino._curve

    def counted(*args: object) -> object:
        nonlocal built
        built += 1
        return curve(*args)

    monkeypatch.setattr(rhino, "_curve", counted)
    placement = place_evaluation(two_estimates, options)
    model = rhino3dm.File3dm.FromByteArray(
        rhino.export_3dm(two_estimates, options, placement=placement)
    )
    after_model = built
    shared_json = rhino.export_3dm_json(two_estimates, options, placement=placement)
    assert built == after_model > 0  # the JSON encoded the model's curves, built none
    assert shared_json == alone_json
    assert len(model.Objects) == len(alone_model.Objects)
    for one, other in zip(model.Objects, alone_model.Objects, strict=True):
        assert one.Attributes.Name == other.Attributes.Name
        assert one.Geometry.Encode()["data"] == other.Geometry.Encode()["data"]
