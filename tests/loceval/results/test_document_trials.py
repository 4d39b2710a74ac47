"""The result document's trials, system comparisons and baseline, read back by their types."""

from __future__ import annotations

from dataclasses import replace

import pytest

from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.results.baseline import baseline_from_document, compare_with_baseline
from loceval.results.document import read_result
from tests.factories import make_trajectory, perturb


def test_trials_and_baseline_round_trip(rng):
    """Every field the pipeline writes about trials and the baseline reads back typed."""
    ref = make_trajectory(rng, n=500)
    estimates = [
        replace(perturb(ref, rng, sigma_m=s), name=f"{sys}-{k}")
        for sys, s in (("A", 0.01), ("B", 0.03))
        for k in range(3)
    ]
    lost = replace(estimates[0], name="A-lost")
    lost = type(lost)(
        lost.stamps_ns[:50], lost.positions_xyz[:50], lost.quat_xyzw[:50], name="A-lost"
    )
    config = EvaluationConfig(no_ci=True)
    result = evaluate(ref, [*estimates, lost], config, systems=["A"] * 3 + ["B"] * 3 + ["A"])
    base = baseline_from_document(read_result(result.to_dict()), label="v1", source="x")
    result = replace(result, baseline=compare_with_baseline(result, base))
    read = read_result(result.to_dict())
    assert [e.system for e in read.estimates] == ["A"] * 3 + ["B"] * 3 + ["A"]
    a, _ = read.systems
    assert a.trials == ("A-0", "A-1", "A-2")
    assert [(f.name, f.code) for f in a.failed] == [("A-lost", "trial.tracking_lost")]
    assert read.failed_trials[0][0] == "A"
    ate = a.metrics["ate_rmse"]
    written = result.systems[0].metrics["ate_rmse"]
    assert ate.values == tuple(written.values)
    assert ate.figure("median") == written.median
    assert ate.interval is not None
    assert written.interval is not None
    assert (ate.interval.low, ate.interval.high) == (written.interval.low, written.interval.high)
    assert ate.median_interval is None
    (first, *_) = read.system_comparisons
    assert (first.a, first.b, first.metric, first.verdict) == (
        "A",
        "B",
        "ate_rmse",
        "too_few_trials",
    )
    assert read.baseline is not None
    assert read.baseline.label == "v1"
    assert {c.verdict for c in read.baseline.comparisons} == {"undetermined"}  # 3 vs 3 trials
    assert {c.level for c in read.baseline.comparisons} == {"system"}


def test_document_before_trials_reads_as_none():
    """A document written before trials has no systems, no comparisons and no baseline."""
    read = read_result({"estimates": [{"name": "a"}]})
    assert read.systems == ()
    assert read.system_comparisons == ()
    assert read.baseline is None
    assert read.estimates[0].system is None


def test_baseline_verdict_must_be_known():
    """A baseline comparison without one of the four verdicts is not a result document."""
    with pytest.raises(InputError, match=r"baseline.comparisons\[0\]"):
        read_result({"estimates": [], "baseline": {"comparisons": [{"verdict": "meh"}]}})
