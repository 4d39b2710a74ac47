"""Estimates of known verdicts for the gate and the CI artifacts: pass, fail and undecided.

One reference (a 30 s random walk at 100 Hz) and three noisy copies of it:

- ``steady`` (1 cm per axis): every pose within 0.1 m, so it passes any share;
- ``lost`` (20 cm per axis): about a tenth within 0.1 m, so it fails;
- ``borderline`` (3.6 cm per axis): about 95 % within 0.1 m. A tolerance that requires
  exactly its measured share (:func:`undecided_tolerance`) lies inside that share's 95 %
  interval, so its verdict is undecided by construction, whatever the noise drew.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from loceval.assessment.trials import FailedTrial
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance, evaluate
from loceval.results.baseline import baseline_from_document, compare_with_baseline
from loceval.results.document import read_result
from loceval.trajectory import Trajectory
from tests.factories import make_trajectory, perturb, write_tum

SIGMAS_M = {"steady": 0.01, "lost": 0.2, "borderline": 0.036}
"""Each estimate's position noise per axis, metres."""
DISTANCE_M = 0.1
"""The tolerance's distance."""


def verdict_trajectories(seed: int = 41) -> tuple[Trajectory, dict[str, Trajectory]]:
    """Return the reference and the three estimates by name (same seed, same data)."""
    rng = np.random.default_rng(seed)
    truth = make_trajectory(rng, n=3000, name="OptiTrack")
    estimates = {
        name: replace(perturb(truth, rng, sigma_m=sigma, sigma_rad=0.002), name=name)
        for name, sigma in SIGMAS_M.items()
    }
    return truth, estimates


def borderline_share(truth: Trajectory, borderline: Trajectory) -> float:
    """Return the share of the borderline estimate's poses within 0.1 m (measured)."""
    result = evaluate(truth, [borderline], EvaluationConfig(tolerance=Tolerance(DISTANCE_M, 0.5)))
    verdict = result.estimates[0].verdict
    assert verdict is not None
    return verdict.share_within


def undecided_tolerance(share: float) -> str:
    """Return the tolerance text that requires ``share`` within 0.1 m (``0.1@94.87``)."""
    return f"{DISTANCE_M:g}@{share * 100:.2f}"


def verdict_result(seed: int = 41) -> EvaluationResult:
    """Return one evaluation of the three estimates: pass, fail and undecided."""
    truth, estimates = verdict_trajectories(seed)
    share = borderline_share(truth, estimates["borderline"])
    tolerance = Tolerance.parse(undecided_tolerance(share))
    return evaluate(truth, list(estimates.values()), EvaluationConfig(tolerance=tolerance))


def write_verdict_files(folder: Path, seed: int = 41) -> dict[str, Path]:
    """Write the reference and the estimates as TUM files; return the paths by name."""
    truth, estimates = verdict_trajectories(seed)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"reference": write_tum(folder / "reference.tum", truth)}
    paths.update({name: write_tum(folder / f"{name}.tum", e) for name, e in estimates.items()})
    return paths


def baseline_result(seed: int = 41) -> EvaluationResult:
    """Return an evaluation against a baseline, with a system of trials and a failed trial.

    The baseline ran ``SLAM`` as steady, ``VIO`` as borderline and ``UWB`` as steady; now
    ``SLAM`` is lost (worse), ``VIO`` steady (better) and ``UWB`` the same steady run (within
    noise). ``ORB`` is a system of two trials (steady, borderline) and one trial that failed
    (``orb-3``, unreadable), against the baseline's two (borderline): compared over its
    trials (too few for an interval: undetermined). The tolerance is 0.1 m for 95 %.
    """
    truth, runs = verdict_trajectories(seed)
    config = EvaluationConfig(tolerance=Tolerance(DISTANCE_M, 0.95))

    def named(run: str, name: str) -> Trajectory:
        return replace(runs[run], name=name)

    before = evaluate(
        truth,
        [
            named("steady", "SLAM"),
            named("borderline", "VIO"),
            named("steady", "UWB"),
            named("borderline", "orb-1"),
            named("borderline", "orb-2"),
        ],
        config,
        systems=[None, None, None, "ORB", "ORB"],
    )
    baseline = baseline_from_document(
        read_result(before.to_dict()), label="release-1.4", source="release-1.4/result.json"
    )
    now = evaluate(
        truth,
        [
            named("lost", "SLAM"),
            named("steady", "VIO"),
            named("steady", "UWB"),
            named("steady", "orb-1"),
            named("borderline", "orb-2"),
        ],
        config,
        systems=[None, None, None, "ORB", "ORB"],
        failed_trials=[FailedTrial("orb-3", "ORB", "input.unreadable", "orb-3.tum is empty.")],
    )
    return replace(now, baseline=compare_with_baseline(now, baseline))


def write_trial_runs(folder: Path, sigmas_m: dict[str, float], seed: int = 41) -> dict[str, Path]:
    """Write the reference and one noisy run per name (its own noise draw) as TUM files.

    Args:
        folder: where to write ``reference.tum`` and ``NAME.tum``.
        sigmas_m: each run's position noise per axis, metres, by name.
        seed: the seed of the reference (the same as :func:`verdict_trajectories`') and of
            the runs' noise.
    """
    truth, _ = verdict_trajectories(seed)
    rng = np.random.default_rng(seed + 1)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {"reference": write_tum(folder / "reference.tum", truth)}
    for name, sigma in sigmas_m.items():
        run = replace(perturb(truth, rng, sigma_m=sigma, sigma_rad=0.002), name=name)
        paths[name] = write_tum(folder / f"{name}.tum", run)
    return paths
