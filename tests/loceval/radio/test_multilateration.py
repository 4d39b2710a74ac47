"""Positioning from ranges: epochs, NLLS and Min-Max against per-epoch implementations."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest
from scipy.optimize import least_squares

from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.radio.multilateration import (
    Solver,
    default_tag_height_m,
    make_epochs,
    solve_minmax,
    solve_nlls,
    solve_positions,
)
from loceval.readers.radio import Anchors, Ranges
from loceval.registration.alignment import AlignMethod
from loceval.registration.association import AssociationMethod
from tests.radio_factory import (
    ANCHOR_XYZ,
    T0_NS,
    TAG_HEIGHT_M,
    make_ranges,
    make_reference,
    walk_position,
)

EPOCH_NS = 100_000_000


def loop_epochs(ranges, *, dims, height=TAG_HEIGHT_M, epoch_ns=EPOCH_NS):
    """Independent epoching: a dict per window, mean range per anchor (plain Python)."""
    t0 = int(ranges.stamps_ns[0])
    windows = defaultdict(lambda: {"stamps": [], "ranges": defaultdict(list)})
    for t, a, r in zip(
        ranges.stamps_ns.tolist(),
        ranges.anchor_index.tolist(),
        ranges.range_m.tolist(),
        strict=True,
    ):
        w = windows[(t - t0) // epoch_ns]
        w["stamps"].append(t - t0)
        w["ranges"][a].append(r)
    out = []
    for key in sorted(windows):
        w = windows[key]
        stamp = t0 + round(sum(w["stamps"]) / len(w["stamps"]))
        anchors, dists = [], []
        for a, rs in sorted(w["ranges"].items()):
            r = sum(rs) / len(rs)
            xyz = ANCHOR_XYZ[a]
            if dims == 2:
                r = max(r * r - (xyz[2] - height) ** 2, 0.0) ** 0.5
            anchors.append(xyz[:dims])
            dists.append(r)
        out.append((stamp, np.array(anchors), np.array(dists)))
    return out


def scipy_nlls(anchors, dists):
    """Per-epoch NLLS with scipy.optimize.least_squares, started from a linear solution."""
    h = np.column_stack((-2 * anchors, np.ones(len(anchors))))
    b = dists**2 - (anchors**2).sum(axis=1)
    x0 = np.linalg.lstsq(h, b, rcond=None)[0][: anchors.shape[1]]
    res = least_squares(
        lambda x: np.linalg.norm(x - anchors, axis=1) - dists,
        x0,
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
    )
    return res.x


def box_centre(anchors, dists):
    """Per-epoch Min-Max: the centre of the intersection of the range boxes."""
    lower = (anchors - dists[:, None]).max(axis=0)
    upper = (anchors + dists[:, None]).min(axis=0)
    return (lower + upper) / 2


def expected_positions(ranges, dims, solve):
    """Run a per-epoch solver over the independent epochs with enough anchors."""
    stamps, positions = [], []
    for stamp, anchors, dists in loop_epochs(ranges, dims=dims):
        if len(dists) >= dims + 1:
            stamps.append(stamp)
            positions.append(solve(anchors, dists))
    return np.array(stamps), np.array(positions)


@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("noise", [0.0, 0.15])
def test_nlls_equals_per_epoch_scipy_least_squares(rng, dims, noise):
    """Batched Levenberg-Marquardt equals scipy's per-epoch least_squares within 1 cm."""
    rec = make_ranges(rng, noise_m=[noise] * 13, bias_m=[0.0] * 13, end_s=25.0)
    nlls = solve_positions(
        rec.ranges, solvers=(Solver.NLLS,), dims=dims, tag_height_m=TAG_HEIGHT_M
    )[0]
    stamps, positions = expected_positions(rec.ranges, dims, scipy_nlls)
    assert np.array_equal(nlls.stamps_ns, stamps)
    assert nlls.name == "nlls"
    assert nlls.quat_xyzw is None
    got = nlls.positions_xyz[:, :dims]
    # Measured (printing the difference): 4e-9 to 7e-7 m over the four cases; 1 cm asked.
    assert np.abs(got - positions).max() < 0.01
    if dims == 2:
        np.testing.assert_allclose(nlls.positions_xyz[:, 2], TAG_HEIGHT_M)


@pytest.mark.parametrize("dims", [2, 3])
def test_minmax_equals_per_epoch_box_intersection(rng, dims):
    """Min-Max equals a direct per-epoch box intersection within 1 cm (to rounding)."""
    rec = make_ranges(rng, noise_m=[0.0] * 13, bias_m=[0.0] * 13, end_s=40.0)
    minmax = solve_positions(
        rec.ranges, solvers=(Solver.MINMAX,), dims=dims, tag_height_m=TAG_HEIGHT_M
    )[0]
    stamps, positions = expected_positions(rec.ranges, dims, box_centre)
    assert minmax.name == "minmax"
    assert np.array_equal(minmax.stamps_ns, stamps)
    np.testing.assert_allclose(minmax.positions_xyz[:, :dims], positions, atol=1e-9)


@pytest.mark.parametrize("dims", [2, 3])
def test_nlls_recovers_the_walk_from_clean_synchronous_ranges(rng, dims):
    """Exact ranges taken at one instant per epoch give the true positions."""
    rec = make_ranges(rng, noise_m=[0.0] * 13, bias_m=[0.0] * 13, synchronous=True)
    nlls = solve_positions(rec.ranges, dims=dims, reference=make_reference())[0]
    truth = walk_position((nlls.stamps_ns - T0_NS) / 1e9)
    assert np.abs(nlls.positions_xyz - truth).max() < 1e-6
    assert nlls.warnings == ()


def test_epoch_stamps_and_mean_ranges():
    """Epochs start at the first range; stamps are their ranges' mean; repeats are averaged."""
    anchors = Anchors(("a", "b", "c", "d"), [[0, 0, 1.2], [10, 0, 1.2], [0, 10, 1.2], [10, 10, 3]])
    stamps = T0_NS + np.array([0, 10, 20, 30, 60, 100, 120, 130, 140]) * 1_000_000
    ranges = Ranges(
        anchors,
        stamps,
        np.array([0, 1, 2, 0, 3, 0, 1, 2, 3]),
        np.array([5.0, 7.0, 8.0, 6.0, 9.0, 5.0, 7.0, 8.0, 9.0]),
    )
    epochs = make_epochs(ranges, dims=3)
    assert epochs.total_epochs == 2
    assert epochs.skipped == 0
    # Window 0: stamps 0, 10, 20, 30, 60 ms -> mean 24 ms; window 1: 100..140 -> 122.5 ms.
    assert epochs.stamps_ns.tolist() == [T0_NS + 24_000_000, T0_NS + 122_500_000]
    # Anchor "a" heard twice in window 0 (5 m and 6 m): its mean, 5.5 m.
    assert epochs.range_m[(epochs.epoch_index == 0) & (epochs.anchor_index == 0)].tolist() == [5.5]


def test_epochs_with_too_few_anchors_are_skipped_and_counted(rng):
    """Epochs hearing fewer than 3 (2D) or 4 (3D) anchors are skipped and counted."""
    rec = make_ranges(rng, max_range_m=6.0, end_s=60.0)
    counts = [len(d) for _, _, d in loop_epochs(rec.ranges, dims=2)]
    for dims in (2, 3):
        expected = sum(c < dims + 1 for c in counts)
        assert expected > 0
        nlls, minmax = solve_positions(rec.ranges, dims=dims, tag_height_m=TAG_HEIGHT_M)
        note = f"{expected} of {len(counts)} epochs of 0.1 s skipped: fewer than {dims + 1}"
        assert any(w.startswith(note) for w in nlls.warnings)
        assert any(w.startswith(note) for w in minmax.warnings)
        assert len(minmax) == len(counts) - expected


def test_no_epoch_with_enough_anchors_is_a_clear_error():
    """When no epoch hears enough anchors the error names the epoch option."""
    anchors = Anchors(("a", "b", "c"), [[0, 0, 2], [5, 0, 2], [0, 5, 2]])
    ranges = Ranges(anchors, T0_NS + np.arange(6) * 200_000_000, np.tile([0, 1], 3), np.ones(6))
    with pytest.raises(InputError, match=r"No epoch of 0\.1 s has ranges to 3 anchors") as info:
        solve_positions(ranges, tag_height_m=1.0)
    assert info.value.option == "epoch_s"


def test_no_ranges_is_a_clear_error():
    """An empty set of ranges is refused with an InputError."""
    anchors = Anchors(("a", "b", "c"), [[0, 0, 2], [5, 0, 2], [0, 5, 2]])
    empty = Ranges(anchors, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.intp), [])
    with pytest.raises(InputError, match="No range measurements"):
        make_epochs(empty, tag_height_m=1.0)


def test_short_ranges_are_clamped_and_counted():
    """A 2D range shorter than the anchor's height above the tag becomes 0 and is counted."""
    anchors = Anchors(("a", "b", "c"), [[0, 0, 3.2], [5, 0, 1.2], [0, 5, 1.2]])
    ranges = Ranges(anchors, T0_NS + np.array([0, 1, 2]), np.array([0, 1, 2]), [1.5, 5.0, 5.0])
    epochs = make_epochs(ranges, dims=2, tag_height_m=1.2)
    assert epochs.clamped == 1
    assert epochs.range_m.tolist() == [0.0, 5.0, 5.0]
    assert "1 ranges were shorter than their anchor's height" in epochs.warnings[0]


def test_collinear_anchors_are_skipped_by_nlls():
    """Anchors on one line leave the 2D position mirrored: nlls skips and counts the epoch."""
    anchors = Anchors(("a", "b", "c", "d"), [[0, 0, 1], [5, 0, 1], [10, 0, 1], [0, 5, 1]])
    stamps = T0_NS + np.array([0, 1, 2, 200, 201, 202, 203]) * 1_000_000
    ranges = Ranges(
        anchors, stamps, np.array([0, 1, 2, 0, 1, 2, 3]), [3.0, 3.0, 7.0, 3.0, 3.0, 7.0, 3.0]
    )
    nlls = solve_nlls(make_epochs(ranges, dims=2, tag_height_m=1.0))
    assert len(nlls) == 1
    assert "1 of 2 epochs skipped by nlls: their anchors lie on one line" in nlls.warnings[0]
    minmax = solve_minmax(make_epochs(ranges, dims=2, tag_height_m=1.0))
    assert len(minmax) == 2


def test_anchors_on_one_plane_in_every_epoch_are_a_clear_error():
    """3D positioning with all anchors at one height is refused by nlls, not returned empty."""
    anchors = Anchors(("a", "b", "c", "d"), [[0, 0, 2.5], [5, 0, 2.5], [0, 5, 2.5], [5, 5, 2.5]])
    ranges = Ranges(anchors, T0_NS + np.arange(4), np.arange(4), [3.0, 4.0, 4.0, 5.0])
    with pytest.raises(InputError, match="In all 1 epochs the anchors heard lie on one plane"):
        solve_nlls(make_epochs(ranges, dims=3))


def test_minmax_counts_boxes_that_do_not_intersect():
    """Inconsistent ranges whose boxes do not meet are counted in the warnings."""
    anchors = Anchors(("a", "b", "c"), [[0, 0, 1], [10, 0, 1], [0, 10, 1]])
    ranges = Ranges(anchors, T0_NS + np.arange(3), np.arange(3), [1.0, 1.0, 1.0])
    minmax = solve_minmax(make_epochs(ranges, dims=2, tag_height_m=1.0))
    assert "In 1 of 1 epochs the range boxes do not intersect" in minmax.warnings[0]
    # Bounds x: max(-1, 9, -1) = 9 and min(1, 11, 1) = 1 -> centre 5; y likewise 5.
    np.testing.assert_allclose(minmax.positions_xyz, [[5.0, 5.0, 1.0]])


@pytest.mark.parametrize(
    ("kwargs", "option", "match"),
    [
        ({"dims": 4}, "dims", "must be 2 or 3, got 4"),
        ({"epoch_s": 0.0}, "epoch_s", "epoch length must be a positive number"),
        ({"epoch_s": float("nan")}, "epoch_s", "epoch length"),
        ({"dims": 2}, "tag_height_m", "needs the tag's height"),
    ],
)
def test_options_are_checked(rng, kwargs, option, match):
    """Bad solver options raise InputError naming the option's key, never a flag."""
    rec = make_ranges(rng, end_s=3.0)
    with pytest.raises(InputError, match=match) as info:
        solve_positions(rec.ranges, **kwargs)
    assert info.value.option == option
    assert "--" not in str(info.value)


def test_default_tag_height_is_the_reference_median():
    """Without a tag height, 2D takes the median height of the tag along the reference."""
    reference = make_reference()
    assert default_tag_height_m(reference) == pytest.approx(TAG_HEIGHT_M)
    assert default_tag_height_m(reference, (0.1, 0.0, 0.4)) == pytest.approx(TAG_HEIGHT_M + 0.4)


@pytest.mark.parametrize(
    ("association", "max_dt_s"),
    [(AssociationMethod.INTERPOLATE, 0.01), (AssociationMethod.NEAREST, 0.005)],
)
def test_solver_outputs_go_through_the_normal_evaluation(rng, association, max_dt_s):
    """evaluate() matches every epoch and measures the solvers' ATE against the walk."""
    rec = make_ranges(rng, noise_m=[0.0] * 13, bias_m=[0.0] * 13, synchronous=True)
    reference = make_reference()
    nlls, minmax = solve_positions(rec.ranges, reference=reference)
    config = EvaluationConfig(align=AlignMethod.NONE, association=association, max_dt_s=max_dt_s)
    result = evaluate(reference, [nlls, minmax], config)
    assert [e.name for e in result.estimates] == ["nlls", "minmax"]
    for estimate, solved in zip(result.estimates, (nlls, minmax), strict=True):
        assert len(estimate.association) == len(solved)  # one error row per epoch
    # Synchronous epochs sit on reference stamps: nlls is exact; Min-Max is not (its box
    # centre is biased towards the anchors' middle): mean error measured 0.5-1 m here.
    assert result.estimates[0].ate_translation.stats.max < 1e-6
    assert 0.05 < result.estimates[1].ate_translation.stats.mean < 2.0
