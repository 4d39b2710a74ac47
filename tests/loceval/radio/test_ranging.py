"""Ranging evaluation: per-anchor and overall errors of the distance measurements."""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from loceval.errors import AssociationError, InputError
from loceval.radio.ranging import RangingResult, evaluate_ranging
from loceval.registration.association import DEFAULT_MAX_GAP_NS
from tests.radio_factory import ANCHOR_IDS, ANCHOR_XYZ, make_ranges, make_reference


def loop_errors(reference, ranges, max_gap_ns=DEFAULT_MAX_GAP_NS):
    """Independent per-measurement computation: bisect, interpolate, subtract (plain Python)."""
    t_ref = reference.stamps_ns.tolist()
    p_ref = reference.positions_xyz.tolist()
    out = []  # (anchor, true, error)
    outside = gap = 0
    for t, a, r in zip(
        ranges.stamps_ns.tolist(),
        ranges.anchor_index.tolist(),
        ranges.range_m.tolist(),
        strict=True,
    ):
        if t < t_ref[0] or t > t_ref[-1]:
            outside += 1
            continue
        i = bisect.bisect_left(t_ref, t)
        if t_ref[i] == t:
            p = p_ref[i]
        else:
            t0, t1 = t_ref[i - 1], t_ref[i]
            if t1 - t0 > max_gap_ns:
                gap += 1
                continue
            w = (t - t0) / (t1 - t0)
            p = [p_ref[i - 1][k] + w * (p_ref[i][k] - p_ref[i - 1][k]) for k in range(3)]
        true = math.dist(p, ANCHOR_XYZ[a].tolist())
        out.append((a, true, r - true))
    return out, outside, gap


def loop_stats(errors, threshold):
    """Plain-Python statistics of a list of errors."""
    n = len(errors)
    mean = sum(errors) / n
    inl = [e for e in errors if abs(e) <= threshold]
    mean_in = sum(inl) / len(inl)
    return {
        "n": n,
        "bias_m": mean,
        "std_m": math.sqrt(sum((e - mean) ** 2 for e in errors) / n),
        "rmse_m": math.sqrt(sum(e * e for e in errors) / n),
        "mae_m": sum(abs(e) for e in errors) / n,
        "max_abs_m": max(abs(e) for e in errors),
        "outlier_share": (n - len(inl)) / n,
        "inliers": {
            "bias_m": mean_in,
            "std_m": math.sqrt(sum((e - mean_in) ** 2 for e in inl) / len(inl)),
            "rmse_m": math.sqrt(sum(e * e for e in inl) / len(inl)),
        },
    }


def assert_stats_close(actual: dict[str, object], expected: dict[str, object]) -> None:
    """Compare two stats dicts key by key (relative 1e-9: far inside the required 1 %)."""
    for key, value in expected.items():
        if isinstance(value, dict):
            assert_stats_close(actual[key], value)  # type: ignore[arg-type]
        else:
            assert actual[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


def test_bias_and_std_over_all_measurements_without_nlos(rng):
    """Without NLOS errors, bias and std over all measurements match the generator."""
    rec = make_ranges(rng)
    result = evaluate_ranging(make_reference(), rec.ranges)
    for anchor in result.anchors:
        k = ANCHOR_IDS.index(anchor.id)
        n, sigma = anchor.stats.n, rec.noise_m[k]
        # Standard errors sigma / sqrt(n) and sigma / sqrt(2 n), 4 of them, + 3 mm (corners).
        assert anchor.stats.bias_m == pytest.approx(rec.bias_m[k], abs=4 * sigma / n**0.5 + 3e-3)
        assert anchor.stats.std_m == pytest.approx(sigma, abs=4 * sigma / (2 * n) ** 0.5 + 3e-3)


def test_per_anchor_bias_and_std_equal_the_generated_values(rng):
    """Inlier bias and std per anchor match the generator within 4 standard errors."""
    rec = make_ranges(rng, nlos_share=0.05)
    result = evaluate_ranging(make_reference(), rec.ranges, outlier_threshold_m=1.5)
    assert len(result.anchors) == 12
    for anchor in result.anchors:
        k = ANCHOR_IDS.index(anchor.id)
        mine = rec.ranges.anchor_index == k
        n_in = int((mine & ~rec.nlos).sum())
        # NLOS errors are >= 3 - 0.2 - 4 * 0.2 > 1.5 m and clean ones < 1.5 m: the threshold
        # separates them exactly, so the outlier share is the generated NLOS share.
        assert anchor.stats.n == int(mine.sum())
        assert anchor.stats.inlier_n == n_in
        assert anchor.stats.outlier_share == pytest.approx(1 - n_in / mine.sum())
        sigma = rec.noise_m[k]
        # Standard error of a mean: sigma / sqrt(n); of a std: sigma / sqrt(2 n); plus 3 mm
        # for the linear interpolation of the 100 Hz reference at the walk's corners.
        assert anchor.stats.inlier_bias_m == pytest.approx(
            rec.bias_m[k], abs=4 * sigma / math.sqrt(n_in) + 0.003
        )
        assert anchor.stats.inlier_std_m == pytest.approx(
            sigma, abs=4 * sigma / math.sqrt(2 * n_in) + 0.003
        )
    assert result.unused_anchors == ("FAR",)


def test_overall_and_per_anchor_figures_equal_a_loop_computation(rng):
    """Every figure equals a plain-Python loop over the measurements (late start and loss)."""
    rec = make_ranges(rng, nlos_share=0.04)
    reference = make_reference(start_s=2.0, loss_s=(30.0, 31.5))
    result = evaluate_ranging(reference, rec.ranges)
    rows, outside, gap = loop_errors(reference, rec.ranges)
    # 2 s before the reference starts and 1.5 s of loss at 10 Hz per heard anchor.
    assert (result.dropped_outside, result.dropped_gap) == (outside, gap)
    assert outside > 0
    assert gap > 0
    overall = loop_stats([e for _, _, e in rows], 1.0)
    inliers = overall.pop("inliers")
    assert_stats_close(result.to_dict()["overall"], overall)
    assert_stats_close(result.overall.inliers_dict(), inliers)
    assert result.overall.n == len(rows)
    by_anchor = {a.id: a.to_dict() for a in result.anchors}
    for k, anchor_id in enumerate(ANCHOR_IDS[:12]):
        errors = [e for a, _, e in rows if a == k]
        expected = loop_stats(errors, 1.0)
        assert_stats_close(by_anchor[anchor_id], expected)
        true = [d for a, d, _ in rows if a == k]
        measured = [d + e for a, d, e in rows if a == k]
        scale, offset = np.polyfit(true, measured, 1)
        assert by_anchor[anchor_id]["fit"] == {
            "offset_m": pytest.approx(offset, rel=1e-7, abs=1e-9),
            "scale": pytest.approx(scale, rel=1e-9),
        }
    assert any("tracking loss" in w for w in result.warnings)
    assert any("outside the reference's time span" in w for w in result.warnings)


def test_distance_bins_partition_the_measurements(rng):
    """The error-versus-distance bins hold every measurement once, with their own figures."""
    rec = make_ranges(rng, nlos_share=0.02)
    result = evaluate_ranging(make_reference(), rec.ranges, distance_bin_m=2.5)
    assert sum(b.n for b in result.distance_bins) == result.overall.n
    rows, _, _ = loop_errors(make_reference(), rec.ranges)
    for b in result.distance_bins:
        errors = [e for _, d, e in rows if b.start_m <= d < b.end_m]
        expected = loop_stats(errors, math.inf)
        assert b.n == expected["n"]
        assert b.bias_m == pytest.approx(expected["bias_m"], rel=1e-9, abs=1e-12)
        assert b.rmse_m == pytest.approx(expected["rmse_m"], rel=1e-9)
    assert [b.start_m for b in result.distance_bins] == sorted(
        b.start_m for b in result.distance_bins
    )


def test_error_series_is_measured_minus_true_over_time(rng):
    """The per-measurement errors carry their stamps and are measured minus true distance."""
    rec = make_ranges(rng, noise_m=[0.0] * 13, bias_m=[0.5] * 13, synchronous=True)
    result = evaluate_ranging(make_reference(), rec.ranges)
    assert np.array_equal(result.errors.stamps_ns, rec.ranges.stamps_ns)
    # Synchronous ticks coincide with reference stamps: the true distances are exact.
    np.testing.assert_allclose(result.true_distance_m, rec.true_m, atol=1e-12)
    np.testing.assert_allclose(result.errors.values, 0.5, atol=1e-12)
    assert result.overall.outlier_share == 0.0


def test_fit_recovers_scale_and_offset(rng):
    """A per-anchor scale and offset are recovered within 5 standard errors of the slope."""
    rec = make_ranges(rng, scale=[1.02] * 13, bias_m=[0.1] * 13, noise_m=[0.05] * 13)
    result = evaluate_ranging(make_reference(), rec.ranges)
    for anchor in result.anchors:
        k = ANCHOR_IDS.index(anchor.id)
        true = rec.true_m[rec.ranges.anchor_index == k]
        # OLS slope standard error: sigma / (sqrt(n) * std(true)); offset ~ mean(true) times it.
        se = 0.05 / (math.sqrt(true.size) * true.std())
        assert anchor.fit is not None
        assert anchor.fit.scale == pytest.approx(1.02, abs=5 * se + 1e-3)
        assert anchor.fit.offset_m == pytest.approx(
            0.1, abs=5 * se * (true.mean() + true.std()) + 3e-3
        )


def test_tag_offset_in_the_body_frame(rng):
    """Ranges from a tag mounted off the tracked origin are exact once the offset is given."""
    offset = (0.3, -0.2, 0.5)
    rec = make_ranges(
        rng, noise_m=[0.0] * 13, bias_m=[0.0] * 13, synchronous=True, tag_offset_xyz=offset
    )
    with_offset = evaluate_ranging(make_reference(), rec.ranges, tag_offset_xyz=offset)
    assert with_offset.overall.max_abs_m < 1e-9
    without = evaluate_ranging(make_reference(), rec.ranges)
    assert without.overall.max_abs_m > 0.3


def test_tag_offset_needs_orientations(rng):
    """A position-only reference with a tag offset is a clear error naming the option."""
    rec = make_ranges(rng)
    with pytest.raises(InputError, match="has no orientations, so the tag offset") as info:
        evaluate_ranging(make_reference(orientation=False), rec.ranges, tag_offset_xyz=(0, 0, 1))
    assert info.value.option == "tag_offset_xyz"
    # A zero offset needs no orientation.
    result = evaluate_ranging(
        make_reference(orientation=False), rec.ranges, tag_offset_xyz=(0, 0, 0)
    )
    assert result.overall.n == len(rec.ranges)


def test_bad_tag_offset_is_an_error(rng):
    """An offset that is not three finite numbers is refused."""
    rec = make_ranges(rng)
    with pytest.raises(InputError, match="three finite metres"):
        evaluate_ranging(make_reference(), rec.ranges, tag_offset_xyz=(0.0, math.nan, 1.0))


def test_no_time_overlap_is_a_clear_error(rng):
    """Ranges recorded in another clock (no overlap) raise an AssociationError, no traceback."""
    rec = make_ranges(rng)
    late = replace(rec.ranges, stamps_ns=rec.ranges.stamps_ns + 10_000 * 10**9)
    with pytest.raises(AssociationError, match=r"None of the \d+ ranges .* falls within"):
        evaluate_ranging(make_reference(), late)


def test_ranges_only_in_tracking_loss_are_a_clear_error(rng):
    """When every range falls in a reference gap the error says so instead of dividing by 0."""
    rec = make_ranges(rng, end_s=5.0)
    inside = replace(rec.ranges, stamps_ns=rec.ranges.stamps_ns + 10 * 10**9)  # 10 s to 15 s
    reference = make_reference(loss_s=(5.0, 20.0))
    with pytest.raises(AssociationError, match="outside its tracking loss"):
        evaluate_ranging(reference, inside)


@pytest.mark.parametrize(
    ("kwargs", "option", "match"),
    [
        ({"outlier_threshold_m": 0.0}, "outlier_threshold_m", "The outlier threshold must"),
        ({"outlier_threshold_m": math.nan}, "outlier_threshold_m", "The outlier threshold"),
        ({"distance_bin_m": -1.0}, "distance_bin_m", "The distance bin width must"),
        ({"max_gap_ns": 0}, "max_gap_s", "longest bridged reference gap"),
        ({"distance_bin_m": 1e-6}, "distance_bin_m", "into more than 1000 bins"),
    ],
)
def test_options_are_checked(rng, kwargs, option, match):
    """Out-of-range options raise an InputError that names the option's key, not a flag."""
    rec = make_ranges(rng, end_s=3.0)
    with pytest.raises(InputError, match=match) as info:
        evaluate_ranging(make_reference(), rec.ranges, **kwargs)
    assert info.value.option == option
    assert "--" not in str(info.value)


def test_no_ranges_is_a_clear_error(rng):
    """An empty set of ranges is a clear InputError, not an IndexError."""
    rec = make_ranges(rng, end_s=3.0)
    empty = replace(
        rec.ranges,
        stamps_ns=rec.ranges.stamps_ns[:0],
        anchor_index=rec.ranges.anchor_index[:0],
        range_m=rec.ranges.range_m[:0],
    )
    with pytest.raises(InputError, match=r"No range measurements in 'ranges\.csv' to evaluate"):
        evaluate_ranging(make_reference(), empty)


def test_json_contract(rng):
    """to_dict() is exactly the contract's ranging object and serialises without NaN."""
    rec = make_ranges(rng, nlos_share=0.03)
    result = evaluate_ranging(make_reference(), rec.ranges)
    doc = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert set(doc) == {"outlier_threshold_m", "anchors", "overall", "unused_anchors"}
    assert doc["outlier_threshold_m"] == 1.0
    assert set(doc["overall"]) == {
        "n", "bias_m", "std_m", "rmse_m", "mae_m", "max_abs_m", "outlier_share",
    }  # fmt: skip
    for anchor in doc["anchors"]:
        assert set(anchor) == {
            "id", "position", "n", "bias_m", "std_m", "rmse_m", "mae_m", "max_abs_m",
            "outlier_share", "inliers", "fit",
        }  # fmt: skip
        assert set(anchor["inliers"]) == {"bias_m", "std_m", "rmse_m"}
        assert set(anchor["fit"]) == {"offset_m", "scale"}
    assert doc["anchors"][0]["position"] == [0.2, 0.2, 2.6]
    assert doc["unused_anchors"] == ["FAR"]


def test_all_outliers_give_null_inlier_figures(rng):
    """With a threshold below every error the inlier figures are null, not NaN."""
    rec = make_ranges(rng, end_s=5.0, bias_m=[1.0] * 13, noise_m=[0.01] * 13)
    result: RangingResult = evaluate_ranging(make_reference(), rec.ranges, outlier_threshold_m=0.5)
    doc = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert doc["overall"]["outlier_share"] == 1.0
    assert doc["anchors"][0]["inliers"] == {"bias_m": None, "std_m": None, "rmse_m": None}


def test_an_anchor_heard_once_has_no_fit(rng):
    """A fit needs two measurements at different distances; otherwise it is null."""
    rec = make_ranges(rng, end_s=3.0)
    first = np.flatnonzero(rec.ranges.anchor_index == 0)[0]
    keep = (rec.ranges.anchor_index != 0) | (np.arange(len(rec.ranges)) == first)
    ranges = replace(
        rec.ranges,
        stamps_ns=rec.ranges.stamps_ns[keep],
        anchor_index=rec.ranges.anchor_index[keep],
        range_m=rec.ranges.range_m[keep],
    )
    result = evaluate_ranging(make_reference(), ranges)
    a01 = next(a for a in result.anchors if a.id == "A01")
    assert a01.stats.n == 1
    assert a01.stats.std_m == 0.0
    assert a01.fit is None
