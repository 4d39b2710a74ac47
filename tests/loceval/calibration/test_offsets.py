"""The evaluation's clock and device-offset check: given values checked, ``auto`` applied."""

from __future__ import annotations

import numpy as np
import pytest

from loceval.calibration.offsets import check_offsets
from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from tests.calibration_factory import Motion, Recording, make_recording
from tests.factories import make_trajectory

TIME_KEYS = {
    "value_s",
    "sigma_s",
    "source",
    "estimated_s",
    "candidates_s",
    "rate_ppm",
    "rate_source",
    "estimated_rate_ppm",
    "sigma_rate_ppm",
    "steps",
}
DEVICE_KEYS = {
    "translation_m",
    "rotation_xyzw",
    "sigma_translation_m",
    "sigma_rotation_deg",
    "source",
    "unobservable",
}


def _run(rec: Recording, config: EvaluationConfig) -> tuple[EvaluationResult, dict[str, object]]:
    result = evaluate(rec.reference, [rec.estimate], config)
    estimates = result.to_dict()["estimates"]
    assert isinstance(estimates, list)
    return result, estimates[0]


def _notes(doc: dict[str, object]) -> list[str]:
    notes = doc["warnings"]
    assert isinstance(notes, list)
    return notes


def test_auto_time_offset_is_applied(rng: np.random.Generator) -> None:
    """``auto`` recovers the generated 45 ms delay within 1 ms and applies it."""
    rec = make_recording(rng)
    result, doc = _run(rec, EvaluationConfig(auto_time_offset=True))
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert set(clock) == TIME_KEYS
    assert clock["source"] == "estimated"
    assert clock["value_s"] == pytest.approx(rec.time_offset_s, abs=0.001)  # generated: -0.045
    # The value applied is the association's offset, to the nanosecond.
    assert doc["time_offset_s"] == pytest.approx(clock["value_s"], abs=1e-9)
    assert doc["device_offset"] is None
    assert any(
        w.startswith("Time offset estimated and applied: the estimate lags") for w in _notes(doc)
    )
    assert result.config.to_dict()["auto_time_offset"] is True


def test_given_clock_that_disagrees_is_flagged(rng: np.random.Generator) -> None:
    """The default 0 against a 45 ms delay: a warning with the estimate in ms; still applied."""
    rec = make_recording(rng)
    _, doc = _run(rec, EvaluationConfig())
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert clock["source"] == "given"
    assert clock["value_s"] == 0.0
    assert doc["time_offset_s"] == 0.0
    assert clock["estimated_s"] == pytest.approx(-0.045, abs=0.001)
    warning = next(w for w in _notes(doc) if "disagree" in w)
    assert "the estimate lags the ground truth by 4" in warning
    assert warning.endswith("you gave 0.0 ms.")


def test_given_clock_that_agrees_is_quiet(rng: np.random.Generator) -> None:
    """The true offset given: checked (estimate and sigma reported), no disagreement warning."""
    rec = make_recording(rng)
    _, doc = _run(rec, EvaluationConfig(time_offset_s=rec.time_offset_s))
    clock = doc["time_offset"]
    assert isinstance(clock, dict)
    assert clock["sigma_s"] is not None
    assert abs(clock["estimated_s"] - rec.time_offset_s) <= 3 * clock["sigma_s"]
    assert not any("disagree" in w for w in _notes(doc))


def test_auto_device_matches_the_truth(rng: np.random.Generator) -> None:
    """Both ``auto``: offsets within the issue's tolerances, ATE within 1 % of the truth's."""
    rec = make_recording(rng)
    result, doc = _run(rec, EvaluationConfig(auto_time_offset=True, auto_device=True))
    device = doc["device_offset"]
    assert isinstance(device, dict)
    assert set(device) == DEVICE_KEYS
    assert device["source"] == "estimated"
    assert device["unobservable"] == []
    np.testing.assert_allclose(device["translation_m"], rec.device.translation, atol=0.002)
    assert doc["time_offset_s"] == pytest.approx(rec.time_offset_s, abs=0.001)
    truth = evaluate(
        rec.reference,
        [rec.estimate],
        EvaluationConfig(time_offset_s=rec.time_offset_s, reference_offset=rec.device),
    )
    rmse = result.estimates[0].ate_translation.stats.rmse
    assert rmse == pytest.approx(truth.estimates[0].ate_translation.stats.rmse, rel=0.01)


def test_given_urdf_is_compared_with_the_motion(rng: np.random.Generator) -> None:
    """A URDF's offset is applied as given (no sigma) and compared with the estimate."""
    rec = make_recording(rng)
    config = EvaluationConfig(
        time_offset_s=rec.time_offset_s,
        reference_offset=rec.device,
        reference_offset_source="urdf",
    )
    result, doc = _run(rec, config)
    device = doc["device_offset"]
    assert isinstance(device, dict)
    assert device["source"] == "urdf"
    assert device["sigma_translation_m"] == [None, None, None]
    np.testing.assert_allclose(device["translation_m"], rec.device.translation)
    offsets = result.estimates[0].offsets
    assert offsets is not None
    assert offsets.comparison is not None
    assert offsets.comparison.consistent
    assert any("differs from the URDF or /tf_static link by" in w for w in _notes(doc))


def test_a_wrong_urdf_is_flagged(rng: np.random.Generator) -> None:
    """A URDF 5 cm off in x: the comparison says beyond 3 sigma."""
    rec = make_recording(rng)
    wrong = SimilarityTransform(
        rec.device.rotation, rec.device.translation + np.array([0.05, 0.0, 0.0])
    )
    config = EvaluationConfig(
        time_offset_s=rec.time_offset_s, reference_offset=wrong, reference_offset_source="urdf"
    )
    _, doc = _run(rec, config)
    message = next(w for w in _notes(doc) if "differs from the URDF" in w)
    assert "beyond 3 sigma" in message


def test_ground_robot_reports_z_unobservable(rng: np.random.Generator) -> None:
    """Rotation about z only: ``device: auto`` lists z as unobservable, with no sigma."""
    rec = make_recording(rng, motion=Motion.GROUND)
    _, doc = _run(rec, EvaluationConfig(auto_time_offset=True, auto_device=True))
    device = doc["device_offset"]
    assert isinstance(device, dict)
    assert device["unobservable"] == ["z"]
    assert device["translation_m"][2] == 0.0
    assert device["sigma_translation_m"][2] is None


def test_position_only_gets_the_time_offset_only(rng: np.random.Generator) -> None:
    """A position-only estimate: the speed gives the time offset; no device offset, a note."""
    rec = make_recording(rng, estimate_orientation=False)
    _, doc = _run(rec, EvaluationConfig(auto_time_offset=True, auto_device=True))
    assert doc["device_offset"] is None
    assert doc["time_offset_s"] == pytest.approx(rec.time_offset_s, abs=0.005)
    assert any("has no orientations" in w for w in _notes(doc))


def test_a_check_that_cannot_run_is_a_warning(rng: np.random.Generator) -> None:
    """Ten poses: the evaluation runs with a warning; asking for ``auto`` is an error."""
    truth = make_trajectory(rng, 10)
    result = evaluate(truth, [truth])
    offsets = result.estimates[0].offsets
    assert offsets is not None
    assert offsets.time_offset is None
    assert (
        result.estimates[0]
        .warnings[0]
        .startswith("The time offset could not be checked against the motion: Trajectory")
    )
    assert offsets.time_offset_dict() == {
        "value_s": 0.0,
        "sigma_s": None,
        "source": "given",
        "estimated_s": None,
        "candidates_s": [],
        "rate_ppm": 0.0,
        "rate_source": "given",
        "estimated_rate_ppm": None,
        "sigma_rate_ppm": None,
        "steps": [],
    }
    with pytest.raises(InputError, match=r"has 10 poses; .* give the offset instead") as err:
        evaluate(truth, [truth], EvaluationConfig(auto_time_offset=True))
    assert err.value.option == "time_offset_s"


def test_device_given_and_auto_is_an_error() -> None:
    """A device offset given and ``auto`` at once is refused, naming the device option."""
    with pytest.raises(InputError, match=r"^Give the device offset or have it estimated") as err:
        EvaluationConfig(auto_device=True, reference_offset=SimilarityTransform.identity())
    assert err.value.option == "device"


def test_repeating_loop_lists_candidates(rng: np.random.Generator) -> None:
    """A 60 s loop driven three times: several candidates, the one nearest 0 applied, a warning."""
    rec = make_recording(rng, motion=Motion.LOOP, duration_s=240.0)
    check = check_offsets(rec.reference, rec.estimate, time_offset_s=None, max_gap_s=0.1)
    assert check.time_offset is not None
    candidates = check.time_offset.candidates_s
    assert len(candidates) >= 2
    assert check.time_offset_s == pytest.approx(rec.time_offset_s, abs=0.005)
    assert min(candidates, key=abs) == check.time_offset_s
    assert any("The motion repeats" in w for w in check.warnings)
