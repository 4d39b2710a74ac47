"""The evaluation pipeline and its JSON document."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, Tolerance, evaluate, parse_offset
from loceval.registration.alignment import AlignMethod
from loceval.trajectory import Trajectory

from .conftest import smooth_trajectory

STATS_KEYS = {
    "rmse", "mean", "median", "std", "var", "min", "max", "sse", "n", "ci95", "n_effective"
}  # fmt: skip


def _estimate(rng: np.random.Generator, truth: Trajectory, name: str, sigma: float) -> Trajectory:
    sample = truth.select(np.arange(0, len(truth), 3))
    frame = SimilarityTransform(Rotation.from_euler("z", 0.7).as_matrix(), np.array([5.0, 1, 0]))
    noisy = Trajectory(
        sample.stamps_ns,
        sample.positions_xyz + rng.normal(0, sigma, (len(sample), 3)),
        sample.quat_xyzw,
        name=name,
        source=f"{name}.tum",
    )
    return noisy.transformed(frame)


def test_json_document_has_the_contract_keys(rng: np.random.Generator) -> None:
    """The --json document carries the keys later issues and users rely on."""
    truth = smooth_trajectory(rng, n=1000)
    estimates = [_estimate(rng, truth, "A", 0.01), _estimate(rng, truth, "B", 0.05)]
    result = evaluate(truth, estimates, EvaluationConfig(tolerance=Tolerance(0.05, 0.9)))
    doc = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert {"loceval_version", "reference", "estimates"} <= doc.keys()
    assert {"name", "source", "poses", "duration_s", "length_m"} <= doc["reference"].keys()
    for est in doc["estimates"]:
        assert {
            "name", "source", "poses", "duration_s", "length_m", "rate_hz", "matched",
            "time_offset_s", "alignment", "ate", "rpe", "within", "worst", "drift_pct",
            "warnings",
        } <= est.keys()  # fmt: skip
        assert {"method", "rotation", "translation", "scale"} <= est["alignment"].keys()
        assert set(est["ate"]["translation_m"]) == STATS_KEYS
        assert set(est["rpe"]["rotation_deg"]) == STATS_KEYS
        assert set(est["within"]) == {"0.05", "0.1", "0.15"}
        assert est["rpe"]["delta"] == 1
        assert est["rpe"]["unit"] == "frames"
    a, b = doc["estimates"]
    assert a["ate"]["translation_m"]["rmse"] < b["ate"]["translation_m"]["rmse"]
    assert a["verdict"]["passed"] is True
    assert b["verdict"]["passed"] is False
    assert b["verdict"]["failing_spans"]


def test_alignment_undoes_the_frame_change(rng: np.random.Generator) -> None:
    """With no noise the SE3 alignment removes the frame change and ATE is ~0."""
    truth = smooth_trajectory(rng, n=600)
    est = _estimate(rng, truth, "exact", 0.0)
    result = evaluate(truth, [est])
    assert result.estimates[0].ate_translation.stats.max < 1e-9
    assert result.estimates[0].alignment.method is AlignMethod.SE3


def test_reference_offset_is_applied(rng: np.random.Generator) -> None:
    """A device offset moves the reference along its body axes before evaluating."""
    truth = smooth_trajectory(rng, n=300)
    offset = parse_offset("0.1 0 0 0 0 0 1")
    camera = truth.with_body_offset(offset)
    result = evaluate(
        truth,
        [camera],
        EvaluationConfig(reference_offset=offset, align=AlignMethod.NONE),
    )
    assert result.estimates[0].ate_translation.stats.max < 1e-12
    assert any("Device offset" in w for w in result.reference_warnings)


@pytest.mark.parametrize("text", ["1 2", "a b c", "0 0 0 0 0 0 2", "nan 0 0"])
def test_bad_offsets_are_rejected(text: str) -> None:
    """The device offset needs 3 or 7 finite numbers with a unit quaternion."""
    with pytest.raises(InputError, match="device offset") as err:
        parse_offset(text)
    assert err.value.option == "offset"


@pytest.mark.parametrize(
    ("text", "distance", "share"),
    [("0.10@95", 0.10, 0.95), ("0.2", 0.2, 0.95), ("0.05m@80%", 0.05, 0.8)],
)
def test_tolerance_parsing(text: str, distance: float, share: float) -> None:
    """--tolerance reads METRES@PERCENT."""
    tol = Tolerance.parse(text)
    assert (tol.distance_m, tol.share) == pytest.approx((distance, share))


@pytest.mark.parametrize("text", ["", "x@95", "0.1@0", "0.1@150", "-1@50"])
def test_bad_tolerances_are_rejected(text: str) -> None:
    """A tolerance that is not METRES@PERCENT in range is an InputError."""
    with pytest.raises(InputError, match="tolerance"):
        Tolerance.parse(text)


@pytest.mark.parametrize(
    ("kwargs", "match", "key"),
    [
        ({"max_dt_s": float("nan")}, "finite", "max_dt_s"),
        ({"max_gap_s": 0.0}, "maximum gap", "max_gap_s"),
        ({"max_gap_s": 1e-300}, "maximum gap must be at least 1 ns", "max_gap_s"),
        ({"thresholds_m": (0.1, -1.0)}, "thresholds", "thresholds_m"),
        ({"worst_count": -1}, "number of worst poses", "worst"),
        ({"reference_sigma_m": -0.001}, "reference's standard deviation", "reference_sigma_m"),
        ({"reference_sigma_m": float("inf")}, "finite number of metres", "reference_sigma_m"),
    ],
)
def test_bad_config_values_are_rejected(kwargs: dict[str, object], match: str, key: str) -> None:
    """Option values a user can get wrong raise InputError carrying the option's key."""
    with pytest.raises(InputError, match=match) as err:
        EvaluationConfig(**kwargs)  # type: ignore[arg-type]
    assert err.value.option == key


def test_no_estimate_is_an_input_error(truth: Trajectory) -> None:
    """Evaluating nothing is refused with a message."""
    with pytest.raises(InputError, match="at least one estimate"):
        evaluate(truth, [])


def test_progress_is_reported(rng: np.random.Generator) -> None:
    """The progress callback sees every estimate and the end."""
    truth = smooth_trajectory(rng, n=300)
    seen: list[tuple[str, float]] = []
    evaluate(truth, [truth, truth], progress=lambda stage, f: seen.append((stage, f)))
    assert [f for _, f in seen] == [0.0, 0.5, 1.0]


def test_position_only_estimate(rng: np.random.Generator) -> None:
    """A position-only system (UWB) gets translation metrics and no rotation metrics."""
    truth = smooth_trajectory(rng, n=300)
    uwb = truth.without_orientation()
    result = evaluate(truth, [uwb])
    est = result.estimates[0]
    assert est.ate_rotation is None
    assert est.rpe_rotation is None
    assert result.to_dict()["estimates"][0]["ate"]["rotation_deg"] is None  # type: ignore[index]
    assert any("no orientations" in w for w in est.warnings)


def test_estimate_tracking_loss_is_reported(rng: np.random.Generator) -> None:
    """A gap in the estimate's own stamps (the system lost tracking) becomes a warning."""
    truth = smooth_trajectory(rng, n=600)
    keep = np.ones(600, dtype=bool)
    keep[200:260] = False  # 0.6 s without estimate poses
    result = evaluate(truth, [truth.select(keep)])
    assert any("its own tracking loss" in w for w in result.estimates[0].warnings)
