"""A plot over time counts poses, not seconds, when the reference has no times."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exporters.plots import series
from exporters.plots.svg.canvas import Figure
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.readers.kitti import read_kitti
from loceval.readers.tum import read_tum
from tests.factories import make_trajectory, perturb, write_kitti, write_tum


def _x_labels(monkeypatch: pytest.MonkeyPatch, result: object) -> list[str]:
    """The x label of the ATE and RPE plots, read from their figures as drawn."""
    labels: list[str] = []
    encode = series.encode_plot

    def recording(fig: Figure, *args: object, **kwargs: object) -> object:
        labels.append(fig.axes[-1].xlabel)
        return encode(fig, *args, **kwargs)

    monkeypatch.setattr(series, "encode_plot", recording)
    series.plot_ate_over_time(result)  # type: ignore[arg-type]
    series.plot_rpe_over_time(result)  # type: ignore[arg-type]
    return labels


def test_kitti_without_times_counts_poses(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """KITTI files without their times file: both axes say pose number, never seconds."""
    truth = make_trajectory(rng, 200, dt_ns=100_000_000)
    gt = read_kitti(write_kitti(tmp_path / "gt.txt", truth))
    est = read_kitti(write_kitti(tmp_path / "est.txt", perturb(truth, rng, sigma_m=0.02)))
    assert gt.indexed
    result = evaluate(gt, [est], EvaluationConfig())
    labels = _x_labels(monkeypatch, result)
    assert (
        labels == ["pose number since the start of the reference (the reference has no times)"] * 2
    )


def test_timed_reference_counts_seconds(
    tmp_path: Path, rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reference with stamps keeps its axis in seconds."""
    truth = make_trajectory(rng, 200, dt_ns=100_000_000)
    gt = read_tum(write_tum(tmp_path / "gt.txt", truth))
    est = read_tum(write_tum(tmp_path / "est.txt", perturb(truth, rng, sigma_m=0.02)))
    result = evaluate(gt, [est], EvaluationConfig())
    assert _x_labels(monkeypatch, result) == ["time since the start of the reference [s]"] * 2
