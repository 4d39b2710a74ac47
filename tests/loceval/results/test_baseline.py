"""An evaluation against a baseline: paired, unpaired, per system, from loceval or evo."""

from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from loceval.assessment.baseline import mover_interval
from loceval.evaluation import EvaluationConfig, EvaluationResult, evaluate
from loceval.readers.evo_result import read_result_zip
from loceval.results.baseline import (
    baseline_from_document,
    baseline_from_evo,
    compare_with_baseline,
)
from loceval.results.document import read_result
from tests.factories import make_trajectory, perturb

NO_CI = EvaluationConfig(no_ci=True)


def _series_of(result: EvaluationResult):
    """Per-pose errors of an earlier result, as its errors.csv would give them."""
    by_name = {e.name: e for e in result.estimates}

    def series_of(name: str, metric: str):
        e = by_name.get(name)
        if e is None:
            return None
        s = e.ate_translation if metric == "ate_rmse" else e.rpe_translation
        return s.stamps_ns, s.values

    return series_of


def _with_more_noise(trajectory, rng, sigma_m):
    return replace(
        trajectory,
        positions_xyz=trajectory.positions_xyz + rng.normal(0, sigma_m, (len(trajectory), 3)),
    )


def test_known_paired_difference_and_the_three_verdicts(rng):
    """Same errors: 0 and within noise; 2 cm more noise per axis: worse by the RMSE difference
    on the shared stamps, paired; the other way round: better."""
    ref = make_trajectory(rng, n=2000)
    before = replace(perturb(ref, rng, sigma_m=0.02), name="orb")
    worse = replace(_with_more_noise(before, rng, 0.02), name="orb")
    old = evaluate(ref, [before], NO_CI)
    baseline = baseline_from_document(
        read_result(old.to_dict()), label="v1", source="v1/result.json", series_of=_series_of(old)
    )
    same = compare_with_baseline(evaluate(ref, [before], NO_CI), baseline)
    ate_same = next(d for d in same.differences if d.metric == "ate_rmse")
    assert ate_same.paired
    assert ate_same.difference == 0.0
    assert ate_same.verdict == "within_noise"

    now = evaluate(ref, [worse], NO_CI)
    found = compare_with_baseline(now, baseline)
    ate = next(d for d in found.differences if d.metric == "ate_rmse")
    expected = (
        now.estimates[0].ate_translation.stats.rmse - old.estimates[0].ate_translation.stats.rmse
    )
    assert ate.difference == pytest.approx(expected, rel=1e-9)
    assert ate.difference == pytest.approx(math.sqrt(3) * (math.sqrt(2) - 1) * 0.02, rel=0.15)
    assert ate.paired
    assert ate.n == 2000
    assert ate.verdict == "worse"
    assert ate.interval is not None
    assert 0.0 < ate.interval[0] < ate.difference < ate.interval[1]
    rpe = next(d for d in found.differences if d.metric == "rpe_rmse")
    assert rpe.paired  # same RPE options: the same pairs
    assert rpe.verdict == "worse"
    assert "worse than the baseline" in ate.summary

    flipped = baseline_from_document(
        read_result(now.to_dict()), label="v2", source="-", series_of=_series_of(now)
    )
    better = compare_with_baseline(old, flipped)
    assert {d.verdict for d in better.differences} == {"better"}
    assert found.to_dict()["comparisons"][0]["verdict"] == "worse"


def test_rpe_of_other_pairs_is_not_paired(rng):
    """A baseline with other RPE options has other pairs: its RPE is compared unpaired."""
    ref = make_trajectory(rng, n=1200)
    est = replace(perturb(ref, rng, sigma_m=0.02), name="orb")
    old = evaluate(ref, [est], EvaluationConfig(rpe_delta=5))
    baseline = baseline_from_document(
        read_result(old.to_dict()), label="v1", source="-", series_of=_series_of(old)
    )
    found = compare_with_baseline(evaluate(ref, [est], EvaluationConfig(rpe_delta=1)), baseline)
    rpe = next(d for d in found.differences if d.metric == "rpe_rmse")
    assert not rpe.paired
    assert rpe.method.startswith("unpaired: MOVER")


def test_unpaired_mover_interval(rng):
    """Without per-pose errors the two RMSE intervals combine by MOVER, as the formula says."""
    assert mover_interval(0.05, (0.04, 0.07), 0.03, (0.025, 0.04)) == pytest.approx(
        (0.02 - math.hypot(0.01, 0.01), 0.02 + math.hypot(0.02, 0.005))
    )
    ref = make_trajectory(rng, n=800)
    old = evaluate(ref, [replace(perturb(ref, rng, sigma_m=0.02), name="orb")])
    now = evaluate(ref, [replace(perturb(ref, rng, sigma_m=0.02), name="orb")])
    baseline = baseline_from_document(read_result(old.to_dict()), label="v1", source="-")
    ate = next(
        d for d in compare_with_baseline(now, baseline).differences if d.metric == "ate_rmse"
    )
    assert not ate.paired
    mine = now.estimates[0].assessment.intervals["ate_translation"].ci95["rmse"]
    theirs = old.estimates[0].assessment.intervals["ate_translation"].ci95["rmse"]
    assert ate.interval == pytest.approx(mover_interval(ate.current, mine, ate.baseline, theirs))
    assert ate.verdict == "within_noise"  # the same noise level


def test_systems_against_the_baseline_systems(rng):
    """Per system over all trials: more noise is worse, the same is within noise, less better;
    the trials themselves are not compared one by one."""
    ref = make_trajectory(rng, n=600)

    def trials(levels):
        estimates, systems = [], []
        for system, sigma in levels.items():
            for k in range(6):
                estimates.append(
                    replace(perturb(ref, rng, sigma_m=sigma * (1 + 0.03 * k)), name=f"{system}-{k}")
                )
                systems.append(system)
        return evaluate(ref, estimates, NO_CI, systems=systems)

    old = trials({"orb": 0.02, "vins": 0.03, "rtab": 0.05})
    baseline = baseline_from_document(read_result(old.to_dict()), label="v1", source="-")
    now = trials({"orb": 0.04, "vins": 0.03, "rtab": 0.025, "new": 0.02})
    found = compare_with_baseline(now, baseline)
    verdicts = {(d.name, d.metric): d.verdict for d in found.differences}
    assert verdicts["orb", "ate_rmse"] == "worse"
    assert verdicts["vins", "ate_rmse"] == "within_noise"
    assert verdicts["rtab", "ate_rmse"] == "better"
    assert {d.level for d in found.differences} == {"system"}
    assert any("'new'" in note for note in found.notes)


def _evo_zip(path: Path, *, title: str, est_name: str, stamps_s, errors) -> Path:
    """Write a zip in evo's documented --save_results layout (no evo code involved)."""
    errors = np.asarray(errors, dtype=np.float64)
    stats = {
        "rmse": float(np.sqrt(np.mean(errors**2))),
        "mean": float(errors.mean()),
        "median": float(np.median(errors)),
        "std": float(errors.std()),
        "min": float(errors.min()),
        "max": float(errors.max()),
        "sse": float(np.sum(errors**2)),
    }
    info = {"title": title, "ref_name": "gt.txt", "est_name": est_name, "label": "APE (m)"}
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("info.json", json.dumps(info))
        archive.writestr("stats.json", json.dumps(stats))
        for name, array in (("error_array", errors), ("timestamps", np.asarray(stamps_s))):
            buffer = io.BytesIO()
            np.save(buffer, array)
            archive.writestr(f"{name}.npy", buffer.getvalue())
    return path


def test_evo_zip_baseline_pairs_its_error_array(rng, tmp_path):
    """An evo APE zip of the same run pairs by its timestamps; a rotation zip is left out, noted."""
    ref = make_trajectory(rng, n=1500)
    est = replace(perturb(ref, rng, sigma_m=0.02), name="orb")
    before = evaluate(ref, [est], NO_CI).estimates[0].ate_translation
    ape = _evo_zip(
        tmp_path / "orb_ape.zip",
        title="APE w.r.t. translation part (m)\n(with SE(3) Umeyama alignment)",
        est_name="orb.txt",
        stamps_s=before.stamps_ns / 1e9,
        errors=before.values,
    )
    angle = _evo_zip(
        tmp_path / "orb_angle.zip",
        title="APE w.r.t. rotation angle in degrees (deg)",
        est_name="orb.txt",
        stamps_s=before.stamps_ns / 1e9,
        errors=np.ones(before.values.size),
    )
    baseline = baseline_from_evo(
        [("orb", read_result_zip(ape)), ("orb", read_result_zip(angle))], label="evo", source="-"
    )
    assert baseline.kind == "evo"
    assert any("orb_angle.zip" in n for n in baseline.notes)
    now = evaluate(ref, [replace(_with_more_noise(est, rng, 0.03), name="orb")], NO_CI)
    found = compare_with_baseline(now, baseline)
    (ate,) = found.differences
    assert ate.paired
    assert ate.n == 1500
    assert ate.verdict == "worse"
    assert ate.baseline == pytest.approx(before.stats.rmse)
