"""Every output on the public recordings: low-rate AMCL drawn whole, paths split at tracking loss.

The reference figures were measured on the files in ``shared/data/public`` (README there):
fr2_desk's motion-capture ground truth (20,956 poses, 300 Hz) loses tracking 27 times for
more than 0.1 s, the longest 11.99 s; nav2_turtlebot's ``tf:map:base_link`` (2,502 poses,
36 ms median) 3 times; its ``/amcl_pose`` (135 poses, 0.6 s median) has 129 poses matched.
"""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import ezdxf
import numpy as np
import pytest

from exporters.cad import gltf
from exporters.cad.dxf import export_dxf
from exporters.cad.placement import place_evaluation
from exporters.options import ExportOptions, Units
from exporters.plots import estimate_colour, plot_ate_over_time, plot_overlay_xy
from loceval.core.gaps import path_breaks
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.readers import read_trajectory
from loceval.registration.alignment import AlignMethod

from .cad.test_gltf import accessor, load
from .conftest import Validator

pytestmark = pytest.mark.public_data

NS = 1_000_000_000
_NUMBER = re.compile(r"-?\d+(?:\.\d+)?")


@pytest.fixture(scope="module")
def nav2(public_data: Path) -> EvaluationResult:
    """Return AMCL (about 1.5 Hz) evaluated against tf map -> base_link in nav2_turtlebot."""
    bag = public_data / "nav2_turtlebot.mcap"
    ref = read_trajectory(f"{bag}@tf:map:base_link")
    return evaluate(ref, [read_trajectory(f"{bag}@/amcl_pose")])


@pytest.fixture(scope="module")
def fr2(public_data: Path) -> EvaluationResult:
    """Return ORB-SLAM (monocular, so Sim(3)) against fr2_desk's motion-capture truth."""
    ref = read_trajectory(str(public_data / "fr2_desk_groundtruth.txt"))
    est = read_trajectory(str(public_data / "fr2_desk_ORB.txt"))
    return evaluate(ref, [est], EvaluationConfig(align=AlignMethod.SIM3))


def _svg_line(svg: bytes, colour: str) -> tuple[int, int]:
    """Return (vertices, pieces) of the longest stroked path of one colour in an SVG.

    The figure kit writes a line broken by NaN as one ``<path>`` whose pieces each start with
    ``M`` (then ``L`` and implicit line-tos: a vertex is a pair of numbers); the legend's
    sample line is a separate, short path.
    """
    pattern = r'<path d="([^"]*)"[^>]*stroke="' + colour
    paths = [m.group(1) for m in re.finditer(pattern, svg.decode("utf-8"))]
    longest = max(paths, key=len)
    return len(_NUMBER.findall(longest)) // 2, longest.count("M")


def test_nav2_amcl_is_a_line_in_the_plots(nav2: EvaluationResult) -> None:
    """AMCL's path and ATE series are lines through every matched pose, in few pieces."""
    amcl = nav2.estimates[0]
    matched = len(amcl.association)
    assert matched == 129
    losses = nav2.reference.tracking_losses(NS // 10)
    assert len(losses) == 3
    colour = estimate_colour(0)
    for plot in (plot_overlay_xy(nav2), plot_ate_over_time(nav2)):
        assert plot.svg is not None
        vertices, pieces = _svg_line(plot.svg, colour)
        assert vertices == matched, plot.key
        # AMCL's intervals around the reference's 3 losses: 4 pieces of 55, 19, 38, 17 poses
        assert pieces == 1 + len(losses), plot.key


def test_nav2_notes_count_real_losses(nav2: EvaluationResult) -> None:
    """The AMCL estimate reports its one 9.3 s silence, not 134 gaps."""
    (note,) = [w for w in nav2.estimates[0].warnings if "itself has" in w]
    assert "has 1 gap longer than 3 s" in note
    gaps = nav2.to_dict()["reference"]["gaps"]  # type: ignore[index]
    assert len(gaps) == 3


def test_fr2_dxf_splits_paths_at_tracking_loss(fr2: EvaluationResult) -> None:
    """More than one polyline per trajectory, none bridging a loss (every pose kept)."""
    options = ExportOptions(units=Units.M, simplify_m=0.0)
    doc = ezdxf.read(io.StringIO(export_dxf(fr2, options).decode("utf-8")))
    msp = doc.modelspace()
    placement = place_evaluation(fr2, options)
    min_gap_ns = NS // 10
    losses = fr2.reference.tracking_losses(min_gap_ns)
    assert len(losses) == 27
    trajectories = {
        fr2.reference.name: fr2.reference,
        fr2.estimates[0].name: fr2.estimates[0].aligned,
    }
    for path in placement.paths:
        pieces = msp.query(f'POLYLINE[layer=="{path.layer}"]')
        assert len(pieces) > 1, path.name
        trajectory = trajectories[path.name]
        jump = path_breaks(trajectory.stamps_ns, min_gap_ns=min_gap_ns, losses=losses)
        steps = np.linalg.norm(np.diff(trajectory.positions_xyz, axis=0), axis=1)
        longest_step = float(steps[~jump].max())
        for polyline in pieces:
            vertices = np.array([v.dxf.location.xyz for v in polyline.vertices])
            segments = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
            assert segments.max() <= longest_step + 1e-9, path.name
    # before, the reference's 12 s loss was crossed by a 1.26 m chord; now no segment is
    # longer than a few centimetres (300 Hz motion capture, 0.1 m/s at most between poses)
    reference = msp.query(f'POLYLINE[layer=="{placement.paths[0].layer}"]')
    assert len(reference) == 1 + len(losses) - _single_pose_pieces(placement.paths[0])
    labels = [t.dxf.text for t in msp.query('TEXT[layer=="tracking loss"]')]
    assert 1 <= len(labels) <= len(losses)  # one per loss; losses < 2 s apart share one
    assert any("no pose for 12.0 s" in label for label in labels)


def _single_pose_pieces(path: object) -> int:
    return sum(1 for a, b in path.pieces() if b - a < 2)  # type: ignore[attr-defined]


def test_fr2_glb_has_vertex_colours_and_validates(
    fr2: EvaluationResult, validate: Validator
) -> None:
    """The GLB of fr2_desk carries COLOR_0 on the ATE node, loss markers, and validates."""
    data = gltf.export_glb(fr2, ExportOptions())
    model = load(data)
    ate = next(n for n in model.nodes if n.name == f"{fr2.estimates[0].name} ATE")
    primitives = model.meshes[ate.mesh].primitives
    assert len(primitives) > 1  # split at the reference's losses
    for primitive in primitives:
        colours = accessor(model, primitive.attributes.COLOR_0)
        assert len(colours) == model.accessors[primitive.attributes.POSITION].count
    losses = next(n for n in model.nodes if n.name == "tracking loss")
    assert 1 <= len(losses.children) <= 27
    report = validate(data)
    assert report["issues"]["numErrors"] == 0, json.dumps(report["issues"], indent=1)
