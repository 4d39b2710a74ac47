"""Model placement: site transform parsing, units, simplification, the polylines view."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from exporters.cad.placement import (
    PALETTE,
    PathKind,
    ate_bins,
    ate_edges_m,
    check_options,
    layer_name,
    palette_color,
    parse_site,
    parse_units,
    place_evaluation,
    read_site_matrix,
)
from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval.core.geometry import SimilarityTransform
from loceval.core.polyline import polyline_distances
from loceval.evaluation import EvaluationResult
from tests.exporters.conftest import with_reference_loss

SITE = "512340.25 5403210.5 112.3 37.5"


def model_positions(result: EvaluationResult, options: ExportOptions) -> list[np.ndarray]:
    """Reference then aligned estimates, site-transformed, in output units (no simplification)."""
    trajectories = [result.reference, *(e.aligned for e in result.estimates)]
    return [
        options.site.apply_positions(t.positions_xyz) * options.units.per_metre
        for t in trajectories
    ]


class TestParseSite:
    def test_translation_and_yaw(self):
        """A yaw of 90 degrees turns x into y, then the translation is added."""
        site = parse_site("10 20 3 90")
        np.testing.assert_allclose(site.apply_positions(np.array([[1.0, 0.0, 0.0]])), [[10, 21, 3]])
        assert site.is_rigid

    def test_commas_and_three_numbers(self):
        """Commas separate numbers, and a missing yaw means no rotation."""
        site = parse_site("1.5, -2, 0.25")
        np.testing.assert_allclose(site.rotation, np.eye(3))
        np.testing.assert_allclose(site.translation, [1.5, -2.0, 0.25])

    @pytest.mark.parametrize("text", ["", "1 2", "a b c d", "1 2 3 4 5", "nan 0 0 0", "1 2 3 inf"])
    def test_rejects_bad_text(self, text):
        """Anything but three or four finite numbers is an options error naming --site."""
        with pytest.raises(ExportOptionsError, match=r"site transform takes .*tx ty tz yaw_deg"):
            parse_site(text)


class TestReadSiteMatrix:
    @staticmethod
    def matrix() -> np.ndarray:
        return parse_site(SITE).as_matrix()

    def test_text_rows_with_comments(self, tmp_path: Path):
        """A text file of four rows with a comment gives the same transform."""
        rows = "\n".join(" ".join(repr(float(v)) for v in row) for row in self.matrix())
        path = tmp_path / "site.txt"
        path.write_text(f"# evaluation frame -> model, metres\n{rows}\n")
        np.testing.assert_allclose(read_site_matrix(path).as_matrix(), self.matrix(), atol=1e-9)

    @pytest.mark.parametrize("form", ["nested", "flat", "object"])
    def test_json_forms(self, tmp_path: Path, form: str):
        """JSON nested rows, a flat list of 16, and {"matrix": ...} are all accepted."""
        m = self.matrix()
        document = {
            "nested": m.tolist(),
            "flat": m.reshape(-1).tolist(),
            "object": {"matrix": m.tolist()},
        }[form]
        path = tmp_path / "site.json"
        path.write_text(json.dumps(document))
        np.testing.assert_allclose(read_site_matrix(path).as_matrix(), m, atol=1e-9)

    def test_uniform_scale(self, tmp_path: Path):
        """A uniformly scaled rotation is a similarity transform and keeps its scale."""
        m = self.matrix()
        m[:3, :3] *= 2.5
        path = tmp_path / "site.json"
        path.write_text(json.dumps(m.tolist()))
        assert read_site_matrix(path).scale == pytest.approx(2.5)

    @pytest.mark.parametrize(
        ("content", "match"),
        [
            ("1 2 3", "must hold 16 numbers"),
            ("[1, 2, 3]", "must hold 16 numbers"),
            ("{not json", "must hold 16 numbers"),
            ("1 0 0 0  0 1 0 0  0 0 0 0  0 0 0 1", "singular"),
            ("1 0 0 0  0 1 0 0  0 0 1 0  5 6 7 1", "column-major"),
            ("1 0.5 0 0  0 1 0 0  0 0 1 0  0 0 0 1", "not a rotation with uniform scale"),
            ("2 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1", "not a rotation with uniform scale"),
            ("-1 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1", "not a rotation with uniform scale"),
        ],
    )
    def test_rejects_bad_matrices(self, tmp_path: Path, content: str, match: str):
        """Wrong counts, singular, transposed, sheared or mirrored matrices are options errors."""
        path = tmp_path / "site.txt"
        path.write_text(content)
        with pytest.raises(ExportOptionsError, match=match):
            read_site_matrix(path)

    def test_missing_file(self, tmp_path: Path):
        """A missing file is an options error that names the path."""
        with pytest.raises(ExportOptionsError, match=r"Cannot read the site matrix file .*nope"):
            read_site_matrix(tmp_path / "nope.txt")


class TestUnitsAndOptions:
    @pytest.mark.parametrize(
        ("text", "units"), [("mm", Units.MM), ("CM", Units.CM), (" m ", Units.M)]
    )
    def test_parse_units(self, text: str, units: Units):
        """The three output units parse, ignoring case and spaces."""
        assert parse_units(text) is units

    def test_unknown_units(self):
        """Feet are not an output unit."""
        with pytest.raises(
            ExportOptionsError, match=r"CAD units must be one of mm, cm, m, got 'ft'"
        ):
            parse_units("ft")

    @pytest.mark.parametrize("value", [-0.001, float("nan"), float("inf")])
    def test_bad_simplify(self, value: float):
        """A negative or non-finite tolerance is an options error naming --simplify."""
        with pytest.raises(
            ExportOptionsError, match="simplification tolerance must be zero or a positive"
        ):
            check_options(ExportOptions(simplify_m=value))

    @pytest.mark.parametrize(
        ("name", "match"),
        [
            ("model.fbx", "not a supported mesh; export it as OBJ, PLY, STL, GLB"),
            ("no.obj", "does not exist"),
        ],
    )
    def test_bad_building(self, tmp_path: Path, name: str, match: str):
        """An unsupported or missing building file is refused before anything is read."""
        (tmp_path / "model.fbx").write_bytes(b"FBX")
        with pytest.raises(ExportOptionsError, match=match):
            check_options(ExportOptions(building=tmp_path / name))


class TestNamesAndColours:
    def test_palette_starts_like_the_paper(self):
        """Ground truth cyan, then magenta and green (the framework paper's Fig. 5)."""
        assert PALETTE[:3] == ((0, 255, 255), (255, 0, 255), (0, 200, 0))

    def test_palette_extends_with_distinct_colours(self):
        """Colours past the fixed palette keep being distinct."""
        colours = [palette_color(k) for k in range(24)]
        assert len(set(colours)) == 24
        assert all(0 <= c <= 255 for rgb in colours for c in rgb)

    @pytest.mark.parametrize(
        ("name", "expected"),
        [("RTAB-Map", "RTAB-Map"), ("a/b:c", "a_b_c"), ("x::y", "x_y"), ("  ", "unnamed")],
    )
    def test_layer_name(self, name: str, expected: str):
        """Characters DXF or Rhino reject in layer names become underscores."""
        assert layer_name(name) == expected

    def test_ate_bins(self):
        """Thresholds give bins from green to red with readable labels."""
        bins = ate_bins((0.10, 0.05, 0.15))
        assert [b.label for b in bins] == ["≤ 0.05 m", "0.05-0.1 m", "0.1-0.15 m", "> 0.15 m"]
        assert bins[0].color_rgb[1] > bins[0].color_rgb[0]
        assert bins[-1].color_rgb[0] > bins[-1].color_rgb[1]


class TestPlaceEvaluation:
    def test_paths_names_colours_and_vertices(self, two_estimates: EvaluationResult):
        """Reference then estimates, palette colours, vertices on the site-mapped poses."""
        options = ExportOptions(site=parse_site(SITE), evaluation_id="ev-1")
        placement = place_evaluation(two_estimates, options)
        assert [p.name for p in placement.paths] == ["OptiTrack", "RTAB-Map", "ISAAC"]
        assert [p.kind for p in placement.paths] == [
            PathKind.REFERENCE,
            PathKind.ESTIMATE,
            PathKind.ESTIMATE,
        ]
        assert [p.color_rgb for p in placement.paths] == list(PALETTE[:3])
        ref_model = options.site.apply_positions(two_estimates.reference.positions_xyz)
        centre = (ref_model.min(axis=0) + ref_model.max(axis=0)) / 2
        np.testing.assert_array_equal(placement.base_point_m, np.round(centre))
        assert np.abs(placement.base_point_m - [512340.0, 5403210.0, 113.0]).max() < 10.0
        for path, expected in zip(
            placement.paths, model_positions(two_estimates, options), strict=True
        ):
            assert path.poses == len(expected)
            assert len(path.vertices) <= path.poses
            np.testing.assert_allclose(
                path.local_vertices + placement.base_point, path.vertices, atol=1e-6
            )
            assert polyline_distances(expected, path.vertices).max() <= 1.0 + 1e-6  # 1 mm
            assert np.abs(path.local_vertices).max() < 10_000.0  # within 10 m of the base
            assert path.max_deviation_m <= options.simplify_m
        assert len(placement.paths[0].vertices) < placement.paths[0].poses / 10  # smooth truth
        assert placement.max_deviation_m == max(p.max_deviation_m for p in placement.paths)

    def test_units_scale_and_metadata(self, two_estimates: EvaluationResult):
        """Metres and millimetres differ by 1000, and the metadata names units and frame."""
        mm = place_evaluation(two_estimates, ExportOptions(units=Units.MM, evaluation_id="e"))
        m = place_evaluation(two_estimates, ExportOptions(units=Units.M, evaluation_id="e"))
        np.testing.assert_allclose(mm.paths[1].vertices, 1000 * m.paths[1].vertices)
        meta = mm.metadata()
        assert meta["units"] == "mm"
        assert meta["evaluation_id"] == "e"
        assert meta["frame"]["evaluation_frame"] == "map"
        assert meta["max_deviation_m"] <= 0.001
        json.dumps(meta, allow_nan=False)

    def test_no_simplification_keeps_every_pose(self, two_estimates: EvaluationResult):
        """simplify_m=0 keeps every pose, with zero deviation."""
        placement = place_evaluation(two_estimates, ExportOptions(simplify_m=0.0))
        assert [len(p.vertices) for p in placement.paths] == [p.poses for p in placement.paths]
        assert placement.max_deviation_m == 0.0

    def test_names_are_made_unique_and_valid(self, two_estimates: EvaluationResult):
        """Clashing, empty or invalid names still give distinct valid layers."""
        a, b = two_estimates.estimates
        renamed = replace(
            two_estimates,
            estimates=(
                replace(a, estimate=replace(a.estimate, name="OptiTrack")),
                replace(b, estimate=replace(b.estimate, name="")),
            ),
        )
        placement = place_evaluation(renamed, ExportOptions())
        assert [p.layer for p in placement.paths] == ["OptiTrack", "OptiTrack (2)", "estimate 2"]
        assert len({p.name for p in placement.paths}) == 3

    def test_markers(self, two_estimates: EvaluationResult):
        """Greatest errors get markers 2 s apart or more; a reference gap gets a marker."""
        ref = two_estimates.reference
        times = ref.times_s()
        gapped = with_reference_loss(two_estimates)
        placement = place_evaluation(gapped, ExportOptions(site=parse_site(SITE), units=Units.M))
        markers = placement.markers()
        gaps = [m for m in markers if m.kind == "gap" and m.path == "OptiTrack"]
        assert len(gaps) == 1
        assert "no pose for 3.0 s" in gaps[0].label
        last_before = placement.to_model(ref.positions_xyz[times < 20.0][-1:])[0]
        np.testing.assert_allclose(gaps[0].position, last_before)
        for est in gapped.estimates:
            worst = [m for m in markers if m.kind == "worst" and m.path == est.name]
            assert worst
            times = sorted(float(m.label.rsplit("t=", 1)[1].rstrip(" s")) for m in worst)
            assert np.all(np.diff(times) >= 2.0 - 0.05)
            assert worst[0].target is not None

    def test_identity_site(self, two_estimates: EvaluationResult):
        """The default site is the identity; the base point is the path's rounded centre."""
        site = ExportOptions().site
        assert isinstance(site, SimilarityTransform)
        np.testing.assert_array_equal(site.as_matrix(), np.eye(4))
        placement = place_evaluation(two_estimates, ExportOptions())
        np.testing.assert_array_equal(placement.base_point_m, [0.0, 0.0, 1.0])


class TestATEEdges:
    """The one ATE colour scale: the thresholds, extended to the errors' magnitude."""

    def test_thresholds_that_fit_stay(self, two_estimates: EvaluationResult):
        """Errors of a few centimetres keep the default 0.05/0.1/0.15 m bins."""
        top = max(np.percentile(e.ate_translation.values, 99.5) for e in two_estimates.estimates)
        assert 0.025 < top <= 0.30  # noisy walk: 2 and 5 cm noise plus drift
        assert ate_edges_m(two_estimates) == (0.05, 0.1, 0.15)

    def test_large_errors_add_edges_above(self, two_estimates: EvaluationResult):
        """Thresholds far below the errors get at most four 1-2-5 edges above them."""
        config = replace(two_estimates.config, thresholds_m=(0.001, 0.002))
        edges = ate_edges_m(replace(two_estimates, config=config))
        assert edges[:2] == (0.001, 0.002)
        assert 1 <= len(edges) - 2 <= 4
        assert all(round(v / 10 ** np.floor(np.log10(v)), 6) in {1, 2, 5} for v in edges[2:])
        assert list(edges) == sorted(edges)

    def test_small_errors_add_edges_below(self, two_estimates: EvaluationResult):
        """Thresholds far above the errors get 1-2-5 edges below them (fr2_desk: 2, 5, 10 mm)."""
        config = replace(two_estimates.config, thresholds_m=(5.0, 10.0))
        edges = ate_edges_m(replace(two_estimates, config=config))
        top = max(np.percentile(e.ate_translation.values, 99.5) for e in two_estimates.estimates)
        assert edges[-2:] == (5.0, 10.0)
        assert 1 <= len(edges) - 2 <= 4
        assert top / 10 <= edges[0]
        assert edges[-3] < top
        assert list(edges) == sorted(edges)


def test_ate_runs_are_cut_once_per_placement(two_estimates: EvaluationResult):
    """Every CAD file of a run asks for the same runs: the second ask is the first's work."""
    placement = place_evaluation(two_estimates, ExportOptions(units=Units.M))
    path = next(p for p in placement.paths if p.estimate is not None)
    first = placement.ate_runs(path)
    again = placement.ate_runs(path)
    assert again == first  # the same run objects (compared by identity)
    assert again is not first  # a list of the caller's own
    fresh = place_evaluation(two_estimates, ExportOptions(units=Units.M)).ate_runs(path)
    assert [r.bin_index for r in fresh] == [r.bin_index for r in first]
    for one, other in zip(fresh, first, strict=True):
        np.testing.assert_array_equal(one.vertices, other.vertices)
