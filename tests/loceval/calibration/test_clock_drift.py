"""A clock that drifts and steps: its rate, offset and steps, with sigmas, on known truth.

The recordings come from :mod:`tests.clock_factory` (a handheld body, reference at 100 Hz,
estimate at 30 Hz, 0.3 deg and 1 mm of noise, a drifting frame, three tracking losses).

Seeds. The method and its constants were chosen on the *tuning* seeds (0 to 59, 100 to 119
and 1000 to 1019 of the handheld, ground-robot, loop and position-only families, 10 min and
one hour). The criteria of issue 42 are checked on seeds 5000 to 5019 (:data:`HELD_OUT`),
which were run only after the method was frozen, and never to choose anything.
"""

from __future__ import annotations

import numpy as np
import pytest

from loceval.calibration.clock import estimate_time_offset
from loceval.calibration.drift import (
    MAX_RATE_PPM,
    ClockModel,
    rate_of_slope,
    slope_of_rate,
)
from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.options import option
from tests.calibration_factory import Motion, make_recording
from tests.clock_factory import ClockTruth, DriftRecording, make_drifting_recording

HELD_OUT = range(5000, 5020)
"""Seeds never used to tune the drift's method (20, the issue's minimum)."""
HOUR_SEEDS = range(5000, 5005)
"""The one-hour case in CI: five of the held-out seeds; ``benchmarks.clock_drift`` runs all 20."""
TEN_MINUTES = ClockTruth(offset_s=0.030, rate_ppm=-200.0)
ONE_HOUR = ClockTruth(offset_s=0.030, rate_ppm=50.0)
MID_RUN_STEP = ClockTruth(offset_s=0.030, step_at_s=300.0, jump_s=0.080)
CONTROL = ClockTruth(offset_s=0.030)


def _recording(seed: int, clock: ClockTruth, duration_s: float = 600.0) -> DriftRecording:
    return make_drifting_recording(np.random.default_rng(seed), clock, duration_s=duration_s)


def _errors_within(seed: int, errors: dict[str, tuple[float, float, float]]) -> None:
    """Each (error, sigma, bound): within the bound and within 3 sigma."""
    for name, (error, sigma, bound) in errors.items():
        assert abs(error) <= bound, (seed, name, error, bound)
        assert abs(error) <= 3.0 * sigma, (seed, name, error, sigma)


# --- the criteria, on held-out seeds ---------------------------------------------------


def _check_rate(seeds: range, clock: ClockTruth, duration_s: float, rate_bound: float) -> None:
    """Rate within ``rate_bound`` ppm, offset within 1 ms, both within 3 sigma, no step."""
    for seed in seeds:
        rec = _recording(seed, clock, duration_s=duration_s)
        found = estimate_time_offset(rec.reference, rec.estimate, clock_drift_ppm=None)
        drift = found.drift
        assert drift is not None
        assert found.rate_ppm == drift.rate_ppm  # applied
        assert found.sigma_s is not None
        _errors_within(
            seed,
            {
                "rate_ppm": (drift.rate_ppm - clock.rate_ppm, drift.sigma_rate_ppm, rate_bound),
                "offset_s": (found.value_s - clock.offset_s, found.sigma_s, 0.001),
            },
        )
        assert drift.steps == ()


@pytest.mark.slow
def test_ten_minutes_at_minus_200_ppm_over_seeds() -> None:
    """10 min at -200 ppm, 30 ms: rate within 5 ppm, offset within 1 ms, all within 3 sigma."""
    _check_rate(HELD_OUT, TEN_MINUTES, 600.0, rate_bound=5.0)


@pytest.mark.slow
def test_one_hour_at_50_ppm() -> None:
    """One hour at +50 ppm (reference 100 Hz, estimate 30 Hz): rate within 1 ppm, offset 1 ms.

    Five held-out seeds here (about 2 s each); ``python -m benchmarks.clock_drift`` runs the
    issue's 20 and times the estimate.
    """
    _check_rate(HOUR_SEEDS, ONE_HOUR, 3600.0, rate_bound=1.0)


@pytest.mark.slow
def test_step_at_mid_run_over_seeds() -> None:
    """An 80 ms step at mid-run: its time within 1 s, its size within 2 ms, within 3 sigma."""
    for seed in HELD_OUT:
        rec = _recording(seed, MID_RUN_STEP)
        found = estimate_time_offset(rec.reference, rec.estimate, clock_drift_ppm=None)
        drift = found.drift
        assert drift is not None
        assert len(drift.steps) == 1, (seed, drift.steps)
        assert found.steps_applied
        step = drift.steps[0]
        assert found.sigma_s is not None
        # The clock jumps ahead at 300 s on the reference's clock: the offset falls 80 ms.
        _errors_within(
            seed,
            {
                "at_s": (step.at_s - 300.0, step.sigma_at_s, 1.0),
                "size_s": (step.size_s + MID_RUN_STEP.jump_s, step.sigma_size_s, 0.002),
                "offset_s": (found.value_s - MID_RUN_STEP.offset_s, found.sigma_s, 0.001),
                "rate_ppm": (drift.rate_ppm, drift.sigma_rate_ppm, 5.0),
            },
        )


@pytest.mark.slow
def test_control_drift_is_insignificant_and_not_applied() -> None:
    """No drift, ``auto``: found insignificant, nothing applied, the offset as without it."""
    for seed in HELD_OUT:
        rec = _recording(seed, CONTROL)
        found = estimate_time_offset(rec.reference, rec.estimate, clock_drift_ppm=None)
        drift = found.drift
        assert drift is not None
        assert not drift.significant, (seed, drift.rate_ppm, drift.sigma_rate_ppm)
        assert drift.steps == ()
        assert found.rate_ppm == 0.0
        assert not found.steps_applied
        assert found.model.varies is False
        assert any(n.startswith("No clock drift to apply") for n in found.notes)
        assert not any("drift" in w for w in found.warnings)
        if seed >= HELD_OUT[4]:
            continue
        # The constant offset is the estimator's as before the drift existed, to the bit.
        plain = estimate_time_offset(rec.reference, rec.estimate)
        assert found.value_s == plain.value_s
        assert abs(found.value_s - CONTROL.offset_s) <= 3.0 * (found.sigma_s or 0.0)
        # Cross-check: the drift's line, at the first pose, agrees with that estimator.
        assert abs(drift.offset_s - plain.value_s) <= 3.0 * np.hypot(
            drift.sigma_offset_s, plain.sigma_s or 0.0
        )


@pytest.mark.slow
@pytest.mark.parametrize("clock", [TEN_MINUTES, MID_RUN_STEP], ids=["rate", "step"])
def test_ate_after_correction_equals_true_clock(clock: ClockTruth) -> None:
    """The ATE with the drift corrected is within 1 % of the ATE with the true clock.

    The true clock is the generator's: the same estimate poses stamped on the reference's
    clock, evaluated with no offset. Cross-checked once with evo (by hand, out of tree, on the
    generator's true-clock poses written as TUM): ``evo_ape tum gt.txt true_clock.txt -a`` on
    seed 5000 of the -200 ppm case gives an RMSE of 0.04346 m (nearest stamps within 10 ms of
    a 100 Hz reference); loceval's drift-corrected run of the drifting estimate, 0.04343 m.
    """
    for seed in HELD_OUT[:3]:
        rec = _recording(seed, clock)
        corrected = evaluate(
            rec.reference,
            [rec.estimate],
            EvaluationConfig(auto_time_offset=True, auto_clock_drift=True, no_ci=True),
        ).estimates[0]
        true = evaluate(
            rec.reference, [rec.true_clock_estimate], EvaluationConfig(no_ci=True)
        ).estimates[0]
        ate, ate_true = corrected.ate_translation.stats.rmse, true.ate_translation.stats.rmse
        assert ate == pytest.approx(ate_true, rel=0.01), (seed, ate, ate_true)
        # Without the correction the same run is far worse: the drift is no small effect.
        plain = evaluate(
            rec.reference, [rec.estimate], EvaluationConfig(auto_time_offset=True, no_ci=True)
        ).estimates[0]
        assert plain.ate_translation.stats.rmse > 1.1 * ate_true


# --- what the evaluation says and applies -------------------------------------------------------


@pytest.fixture(scope="module")
def drifting() -> DriftRecording:
    """A tuning recording: 10 min, -200 ppm and an 80 ms step at 300 s."""
    return make_drifting_recording(
        np.random.default_rng(11),
        ClockTruth(offset_s=0.030, rate_ppm=-200.0, step_at_s=300.0, jump_s=0.080),
        duration_s=600.0,
    )


def test_drift_not_asked_is_a_warning_with_the_figure(drifting: DriftRecording) -> None:
    """By default the drift is checked, not applied: a warning in ms over the run and the option."""
    result = evaluate(drifting.reference, [drifting.estimate], EvaluationConfig(no_ci=True))
    e = result.estimates[0]
    assert e.offsets is not None
    assert e.offsets.clock(drifting.estimate).varies is False
    spec = option("clock_drift_ppm")
    rate = [w for w in e.warnings if w.startswith("The estimate's clock runs ")]
    assert len(rate) == 1
    assert "ppm slow, so the time offset moves by 1" in rate[0]  # ~120 ms
    assert "more than the 10 ms association tolerance" in rate[0]
    assert f"{spec.flag} auto" in rate[0]
    assert f"{spec.key}: auto" in rate[0]
    step = [w for w in e.warnings if w.startswith("The estimate's clock steps: at 299.")]
    assert len(step) == 1  # 299.5 +/- 0.4 s: the body hardly turns at 300 s in this one
    assert "jumped ahead by 80." in step[0]
    doc = result.to_dict()["estimates"][0]
    clock = doc["time_offset"]
    assert clock["rate_ppm"] == 0.0
    assert clock["rate_source"] == "given"
    assert clock["estimated_rate_ppm"] == pytest.approx(-200.0, abs=3.0)
    assert clock["sigma_rate_ppm"] > 0
    assert clock["steps"] == [
        {
            "at_s": pytest.approx(300.0, abs=1.0),
            "sigma_at_s": pytest.approx(clock["steps"][0]["sigma_at_s"]),
            "size_s": pytest.approx(-0.080, abs=0.002),
            "sigma_size_s": pytest.approx(clock["steps"][0]["sigma_size_s"]),
            "applied": False,
        }
    ]
    # A tolerance wider than the drift over the run: a note, not a warning.
    wide = evaluate(
        drifting.reference,
        [drifting.estimate],
        EvaluationConfig(no_ci=True, max_dt_s=0.5),
    ).estimates[0]
    assert not any("clock" in w for w in wide.warnings)
    assert any("within the 500 ms association tolerance" in n for n in wide.notes)


def test_auto_applies_rate_and_step_to_the_association(drifting: DriftRecording) -> None:
    """``auto``: the line is applied; the matched stamps are the true clock's, to 1 ms."""
    result = evaluate(
        drifting.reference,
        [drifting.estimate],
        EvaluationConfig(auto_time_offset=True, auto_clock_drift=True, no_ci=True),
    )
    e = result.estimates[0]
    assert e.offsets is not None
    model = e.offsets.clock(drifting.estimate)
    assert model.varies
    assert model.rate_ppm == pytest.approx(-200.0, abs=3.0)
    assert len(model.steps) == 1
    # The matched poses now carry their true times (the generator's), but near the step,
    # whose time this recording tells to 0.4 s only (the body hardly turns there): poses are
    # matched to the true-clock poses by position, which the clock does not change.
    true = drifting.true_clock_estimate
    positions = {tuple(p): k for k, p in enumerate(true.positions_xyz)}
    index = [positions[tuple(p)] for p in e.association.estimate.positions_xyz]
    error_ms = (e.association.estimate.stamps_ns - true.stamps_ns[index]) / 1e6
    assert np.median(np.abs(error_ms)) < 0.2
    assert (np.abs(error_ms) < 1.0).mean() > 0.99
    doc = result.to_dict()
    clock = doc["estimates"][0]["time_offset"]
    assert clock["rate_source"] == "estimated"
    assert clock["rate_ppm"] == clock["estimated_rate_ppm"]
    assert clock["steps"][0]["applied"] is True
    assert doc["options"]["auto_clock_drift"] is True
    assert any(w.startswith("Clock drift estimated and applied") for w in e.warnings)


def test_given_rate_is_applied_and_checked(drifting: DriftRecording) -> None:
    """A given rate is applied from the first pose; the step it leaves is still a warning."""
    config = EvaluationConfig(auto_time_offset=True, clock_drift_ppm=-200.0, no_ci=True)
    e = evaluate(drifting.reference, [drifting.estimate], config).estimates[0]
    assert e.offsets is not None
    assert e.offsets.time_offset is not None
    assert e.offsets.time_offset.rate_ppm == -200.0
    assert e.offsets.time_offset.rate_source.value == "given"
    assert not any(w.startswith("The estimate's clock runs") for w in e.warnings)  # agrees
    assert any(w.startswith("The estimate's clock steps") for w in e.warnings)
    with pytest.raises(InputError, match=r"clock drift must be a finite number of ppm") as err:
        EvaluationConfig(clock_drift_ppm=5000.0)
    assert err.value.option == "clock_drift_ppm"
    assert option("clock_drift_ppm").maximum == MAX_RATE_PPM


def test_auto_on_a_short_run_names_the_option() -> None:
    """``auto`` on a 40 s run fails, naming the option; a mere check there stays silent."""
    rec = make_recording(np.random.default_rng(3), duration_s=40.0)
    with pytest.raises(InputError, match=r"too short to tell a clock drift") as err:
        estimate_time_offset(rec.reference, rec.estimate, clock_drift_ppm=None)
    assert err.value.option == "clock_drift_ppm"
    quiet = estimate_time_offset(rec.reference, rec.estimate)
    assert quiet.drift is None
    assert quiet.notes == ()
    assert quiet.to_dict()["estimated_rate_ppm"] is None


def test_position_only_drift_within_3_sigma() -> None:
    """A position-only estimate (a tag): the lever arm and the drift's windows still tell it."""
    rec = make_drifting_recording(
        np.random.default_rng(5), TEN_MINUTES, duration_s=600.0, estimate_orientation=False
    )
    found = estimate_time_offset(rec.reference, rec.estimate, clock_drift_ppm=None)
    drift = found.drift
    assert drift is not None
    assert abs(drift.rate_ppm - TEN_MINUTES.rate_ppm) <= 3.0 * drift.sigma_rate_ppm
    assert drift.sigma_rate_ppm < 1.0


# --- the quiet check ----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def loop() -> DriftRecording:
    """A 60 s loop driven five times, its clocks agreeing (offset 0)."""
    return make_drifting_recording(
        np.random.default_rng(2), ClockTruth(offset_s=0.0), motion=Motion.LOOP, duration_s=300.0
    )


def test_repeats_with_the_given_offset_among_them_is_a_note(loop: DriftRecording) -> None:
    """Nothing asked and the given 0 s one of the offsets that fit: an information line."""
    found = estimate_time_offset(loop.reference, loop.estimate, given_offset_s=0.0)
    assert len(found.candidates_s) >= 3
    assert not any("The motion repeats" in w for w in found.warnings)
    notes = [n for n in found.notes if n.startswith("The motion repeats")]
    assert len(notes) == 1
    assert "the given 0 s is one of them, and the data agree with it there" in notes[0]
    result = evaluate(loop.reference, [loop.estimate], EvaluationConfig(no_ci=True))
    doc = result.to_dict()["estimates"][0]
    assert not any("The motion repeats" in w for w in doc["warnings"])
    assert any("The motion repeats" in n for n in doc["notes"])


@pytest.mark.parametrize(
    ("kwargs", "why"),
    [
        ({"given_offset_s": None}, "estimated: the choice is the data's"),
        ({"given_offset_s": 0.0, "clock_drift_ppm": None}, "the drift asked for"),
        ({"given_offset_s": 0.5}, "the given offset is none of them"),
    ],
    ids=["auto", "drift-auto", "disagrees"],
)
def test_repeats_stay_a_warning_when_something_was_asked(
    loop: DriftRecording, kwargs: dict[str, float | None], why: str
) -> None:
    """An estimate asked for, or a given offset the data do not fit: still a warning."""
    found = estimate_time_offset(loop.reference, loop.estimate, **kwargs)  # type: ignore[arg-type]
    assert any("The motion repeats" in w for w in found.warnings), why
    assert not any("The motion repeats" in n for n in found.notes), why


# --- the model ----------------------------------------------------------------------------------


def test_rate_and_slope_are_inverse() -> None:
    """A clock 50 ppm fast loses the offset 50/1.00005 µs per second; the inverse undoes it."""
    assert slope_of_rate(50.0) == pytest.approx(-50e-6 / (1 + 50e-6), rel=1e-12)
    for rate in (-1000.0, -200.0, 0.0, 0.5, 50.0, 1000.0):
        assert rate_of_slope(slope_of_rate(rate)) == pytest.approx(rate, abs=1e-9)


def test_model_restamps_and_drops_interleaved_poses() -> None:
    """The offset's change goes into the stamps; a step that sets them back drops what overlaps."""
    traj = make_recording(np.random.default_rng(1), duration_s=20.0).estimate
    epoch = int(traj.stamps_ns[0])
    model = ClockModel(offset_s=0.03, epoch_ns=epoch, rate_ppm=-200.0)
    moved = model.restamped(traj)
    since_s = (traj.stamps_ns - epoch) / 1e9
    np.testing.assert_allclose(
        (moved.stamps_ns - traj.stamps_ns) / 1e9, since_s * 200e-6 / (1 - 200e-6), atol=1e-9
    )
    assert ClockModel(offset_s=0.03, epoch_ns=epoch).restamped(traj) is traj
    # The offset falls by 50 ms at pose 300: it lands before pose 299 (33 ms earlier) and is
    # dropped; pose 301 lands 17 ms after pose 299, and the stamps increase again.
    step_at = int(traj.stamps_ns[300])
    back = ClockModel(offset_s=0.0, epoch_ns=epoch, steps=((step_at, -0.050),)).restamped(traj)
    assert (np.diff(back.stamps_ns) > 0).all()
    assert len(traj) - len(back) == 1
    assert back.stamps_ns[300] == traj.stamps_ns[301] - 50_000_000


def test_control_points_take_a_given_rate() -> None:
    """A control-point evaluation applies a given clock rate from the estimate's first pose."""
    from loceval.checkpoint_evaluation import CheckpointConfig, evaluate_control_points
    from loceval.registration.alignment import AlignMethod
    from tests.checkpoint_factory import grid_points, stop_and_go

    rec = stop_and_go(np.random.default_rng(4), grid_points(3, 4), passes=1)
    result = evaluate_control_points(
        rec.points,
        [rec.estimate],
        EvaluationConfig(align=AlignMethod.NONE, clock_drift_ppm=-500.0),
        CheckpointConfig(),
    )
    stamps = result.estimates[0].estimate.stamps_ns
    since_s = (rec.estimate.stamps_ns - rec.estimate.stamps_ns[0]) / 1e9
    np.testing.assert_allclose(
        (stamps - rec.estimate.stamps_ns) / 1e9, since_s * slope_of_rate(-500.0), atol=1e-9
    )


@pytest.mark.parametrize("dof", [5, 8, 20, 62, 500])
def test_student_factor_matches_scipy(dof: int) -> None:
    """The line's Student factor (an expansion, no scipy import) is scipy's within 0.3 %."""
    from scipy.stats import t as student

    from loceval.calibration._drift_steps import _student_at_3_sigma

    assert _student_at_3_sigma(dof) == pytest.approx(student.ppf(0.99865, dof), rel=0.003)
