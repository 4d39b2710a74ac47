"""The ATE runs of paths.3dm.json and paths.3dm: the fast writers give rhino3dm's curves.

``exporters.cad.rhino_encode`` writes ``CommonObject.Encode()`` of a polyline curve with
NumPy; rhino3dm itself (a ``PolylineCurve`` built point by point, then ``Encode()``) is the
slow path it replaces. Both are compared byte for byte and read back with rhino3dm.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from exporters.cad.placement import parse_site, place_evaluation
from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult
from tests.exporters.conftest import curve_vertices

rhino3dm = pytest.importorskip("rhino3dm")
from exporters.cad import rhino, rhino_encode  # noqa: E402  (after the importorskip)

SITE = "512340.25 5403210.5 112.3 37.5"


@pytest.mark.parametrize("n", [1, 2, 3, 17, 1000])
def test_the_encoding_is_rhino3dms_byte_for_byte(n: int) -> None:
    """Coordinates of every magnitude and sign: the same dict as rhino3dm's Encode()."""
    rng = np.random.default_rng(n)
    vertices = rng.normal(size=(n, 3)) * np.array([1e-9, 1.0, 5e6])
    vertices[0] = [-0.0, 1e300, -1e-300]
    (fast,) = rhino_encode.encode_polylines([vertices])
    assert fast == rhino_encode.polyline_curve(vertices).Encode()
    curve = rhino3dm.CommonObject.Decode(fast)
    assert isinstance(curve, rhino3dm.PolylineCurve)
    assert np.array_equal(curve_vertices(curve), vertices)


def test_the_checked_layout_is_in_use() -> None:
    """This rhino3dm writes the layout the encoder writes (else it falls back to rhino3dm)."""
    header = rhino_encode._header()
    assert header is not None
    assert set(header) == {"version", "archive3dm", "opennurbs"}


def test_the_json_runs_are_the_curves_rhino3dm_would_encode(
    two_estimates: EvaluationResult,
) -> None:
    """Each ATE run's ``curve`` is rhino3dm's encoding of that run, and decodes to it."""
    options = ExportOptions(site=parse_site(SITE), evaluation_id="ev-42")
    placement = place_evaluation(two_estimates, options)
    document = json.loads(rhino.export_3dm_json(two_estimates, options, placement=placement))
    checked = 0
    for entry, path in zip(document["paths"][1:], placement.paths[1:], strict=True):
        runs = placement.ate_runs(path)
        assert len(entry["ate"]) == len(runs) > 10
        assert len({run.bin_index for run in runs}) > 1  # several bins, several colours
        for item, run in zip(entry["ate"], runs, strict=True):
            assert item["curve"] == rhino_encode.polyline_curve(run.vertices).Encode()
            curve = rhino3dm.CommonObject.Decode(item["curve"])
            assert np.array_equal(curve_vertices(curve), run.vertices)
            checked += 1
    assert checked == sum(len(placement.ate_runs(p)) for p in placement.paths)


def test_the_3dm_runs_are_polyline_curves_through_the_runs(
    two_estimates: EvaluationResult,
) -> None:
    """The .3dm's ATE objects, read back, are polyline curves through each run in order."""
    options = ExportOptions(site=parse_site(SITE), evaluation_id="ev-42")
    placement = place_evaluation(two_estimates, options)
    model = rhino3dm.File3dm.FromByteArray(
        rhino.export_3dm(two_estimates, options, placement=placement)
    )
    layers = {layer.Index: layer.FullPath for layer in model.Layers}
    for path in placement.paths[1:]:
        layer = f"{rhino.layer_path(placement, path)}::ATE"
        objects = [o for o in model.Objects if layers[o.Attributes.LayerIndex] == layer]
        runs = placement.ate_runs(path)
        assert len(objects) == len(runs) > 10
        for obj, run in zip(objects, runs, strict=True):
            assert isinstance(obj.Geometry, rhino3dm.PolylineCurve)
            assert np.array_equal(curve_vertices(obj.Geometry), run.vertices)
            expected = rhino_encode.polyline_curve(run.vertices).Encode()["data"]
            assert obj.Geometry.Encode()["data"] == expected
