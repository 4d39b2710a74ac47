"""An evaluation against a baseline: each estimate and system against an earlier result.

The baseline is an earlier evaluation of the same systems: a loceval ``result.json`` (with
its ``errors.csv`` when at hand) or evo result zips (``evo_ape``/``evo_rpe
--save_results``); the front doors read it into a :class:`Baseline`
(``service.jobs.baseline``). Each estimate, and each system of trials, is compared with
the baseline's of the **same name**, on the RMSE of the ATE and of the RPE (translation),
as ``difference = current - baseline`` (negative: better now):

- **paired** where both keep per-pose errors at shared stamps (our ``errors.csv``, evo's
  ``error_array`` with ``timestamps``) of the same reference recording (a loceval baseline
  made against a reference of another SHA-256 never pairs: equal stamps of two recordings
  are not the same instants): the stamps are paired by nearest stamp within 10 ms
  (evo's tolerance) and the interval is the paired circular block bootstrap of
  :func:`loceval.assessment.comparison.compare_errors` (what both runs share cancels). RPE
  errors pair only when both were made with the same RPE pairs (delta, unit, all pairs):
  evo's RPE pairs, or loceval's with other options, are compared unpaired.
- **unpaired** otherwise: the MOVER combination (Zou & Donner 2008, "method of variance
  estimates recovery") of the two RMSEs' own 95 % intervals (each loceval's block
  bootstrap; an evo zip's RMSE bootstrapped here from its ``error_array``):
  ``[d - sqrt((c - l_c)^2 + (u_b - b)^2), d + sqrt((u_c - c)^2 + (b - l_b)^2)]``.
- **a system** against the baseline's system of the same name: over all trials of both
  (:func:`loceval.assessment.trials.compare_systems`: Hodges-Lehmann shift, Moses
  interval); against a baseline's single estimate of that name: the mean over trials
  minus the baseline's RMSE, the MOVER combination of the trials' t-interval and the
  baseline's interval (the baseline taken as exact when it has none).

Trials are compared only as their system: trial k now and trial k of the baseline are
different runs, and pairing their poses would leave out the spread from run to run.

The **verdict** is ``better`` (the interval wholly below 0), ``worse`` (wholly above),
``within_noise`` (it holds 0) or ``undetermined`` (no interval: too few trials, or neither
pairs nor intervals).

The comparison of a whole evaluation (:func:`loceval.results.baseline.compare_with_baseline`)
and the readers of a baseline from a result document or evo zips live in
:mod:`loceval.results.baseline`, a stage above the evaluation; this module holds the types
and the statistics.

Result document::

    baseline: {label, kind: loceval | evo, source,
      comparisons: [{name, level: estimate | system, metric: ate_rmse | rpe_rmse, unit,
                     current, baseline, difference, interval: [low, high] | null,
                     paired: bool, n, method,
                     verdict: better | worse | within_noise | undetermined, summary}],
      notes: [str]}                           names without a counterpart, and why
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Final, Literal

import numpy as np

from loceval.core.arrays import FloatArray, StampsNs
from loceval.core.quantities import signed_difference
from loceval.errors import LocevalError

__all__ = [
    "BASELINE_METRICS",
    "MOVER_METHOD",
    "PAIRED_METHOD",
    "Baseline",
    "BaselineComparison",
    "BaselineDifference",
    "BaselineEntry",
    "BaselineSystem",
    "baseline_verdict",
    "bootstrap_rmse_ci",
    "mover_interval",
    "paired_difference",
]

BASELINE_METRICS: Final[Mapping[str, str]] = {"ate_rmse": "ATE RMSE", "rpe_rmse": "RPE RMSE"}
"""The metrics compared with a baseline, by key, with their name in sentences."""

Verdict = Literal["better", "worse", "within_noise", "undetermined"]
_MAX_DT_S: Final = 0.01
PAIRED_METHOD: Final = "paired block bootstrap of the RMSE difference on the shared stamps"
MOVER_METHOD: Final = "unpaired: MOVER combination of the two RMSEs' 95 % intervals"


@dataclass(frozen=True, slots=True, eq=False)
class BaselineEntry:
    """One estimate of the baseline.

    Attributes:
        name: its name (the matching key).
        rmse: each metric's RMSE, by key (:data:`BASELINE_METRICS`).
        ci95: each metric's 95 % interval of the RMSE, when the baseline has one.
        series: each metric's per-pose errors ``(stamps_ns, errors)``, when kept.
        rpe_pairing: how its RPE pairs were made (``"1 m, consecutive"``), None: unknown.
        units: each metric's unit.
    """

    name: str
    rmse: Mapping[str, float]
    ci95: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    series: Mapping[str, tuple[StampsNs, FloatArray]] = field(default_factory=dict)
    rpe_pairing: str | None = None
    units: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, eq=False)
class BaselineSystem:
    """One system of the baseline: each metric's value per trial.

    Attributes:
        name: the system's name.
        values: each metric's per-trial values, by key.
        units: each metric's unit.
    """

    name: str
    values: Mapping[str, FloatArray]
    units: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True, eq=False)
class Baseline:
    """An earlier result to compare with.

    Attributes:
        label: how reports name it (a file name, an evaluation id).
        kind: ``loceval`` (a result document) or ``evo`` (result zips).
        source: where it came from (a path as given, ``evaluation:<id>``).
        estimates: its estimates.
        systems: its systems of trials.
        notes: what reading it found (an evo zip of a rotation metric left out...).
        reference_sha256: the SHA-256 of the reference it was made against (None: unknown).
    """

    label: str
    kind: Literal["loceval", "evo"]
    source: str
    estimates: tuple[BaselineEntry, ...] = ()
    systems: tuple[BaselineSystem, ...] = ()
    notes: tuple[str, ...] = ()
    reference_sha256: str | None = None


@dataclass(frozen=True, slots=True)
class BaselineDifference:
    """One figure now against the baseline's.

    Attributes:
        name: the estimate's or system's name.
        level: ``estimate`` or ``system``.
        metric: the key (:data:`BASELINE_METRICS`).
        unit: the unit.
        current: the figure now (a system: its median over trials).
        baseline: the baseline's figure (a system: its median over trials).
        difference: the difference (see the module's docstring for each level).
        interval: its 95 % interval, or None.
        paired: whether the interval is a paired one.
        n: shared stamps (paired), or trials now (a system).
        method: how the interval is made, in words.
        verdict: ``better``, ``worse``, ``within_noise`` or ``undetermined``.
    """

    name: str
    level: Literal["estimate", "system"]
    metric: str
    unit: str
    current: float
    baseline: float
    difference: float
    interval: tuple[float, float] | None
    paired: bool
    n: int
    method: str
    verdict: Verdict

    @property
    def summary(self) -> str:
        """One sentence for the report."""
        label = BASELINE_METRICS.get(self.metric, self.metric)
        d = signed_difference(self.difference, self.unit)
        words = {
            "better": "better than the baseline",
            "worse": "worse than the baseline",
            "within_noise": "within the noise of the baseline",
            "undetermined": "undetermined (no interval)",
        }[self.verdict]
        if self.interval is None:
            return f"{self.name}, {label}: {d} against the baseline, {words}."
        lo, hi = (signed_difference(v, self.unit) for v in self.interval)
        kind = "paired" if self.paired else "unpaired"
        return f"{self.name}, {label}: {d} ({kind} 95 % interval {lo} to {hi}), {words}."

    def to_dict(self) -> dict[str, object]:
        """Return the document's block (see the module's docstring)."""
        return {
            "name": self.name,
            "level": self.level,
            "metric": self.metric,
            "unit": self.unit,
            "current": self.current,
            "baseline": self.baseline,
            "difference": self.difference,
            "interval": None if self.interval is None else list(self.interval),
            "paired": self.paired,
            "n": self.n,
            "method": self.method,
            "verdict": self.verdict,
            "summary": self.summary,
        }


@dataclass(frozen=True, slots=True)
class BaselineComparison:
    """The result against the baseline.

    Attributes:
        label: the baseline's label.
        kind: ``loceval`` or ``evo``.
        source: where the baseline came from.
        differences: each estimate's and system's figures against the baseline's.
        notes: names without a counterpart, and what reading the baseline found.
    """

    label: str
    kind: str
    source: str
    differences: tuple[BaselineDifference, ...]
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, object]:
        """Return the document's ``baseline`` object."""
        return {
            "label": self.label,
            "kind": self.kind,
            "source": self.source,
            "comparisons": [d.to_dict() for d in self.differences],
            "notes": list(self.notes),
        }


def baseline_verdict(interval: tuple[float, float] | None) -> Verdict:
    """Better (interval below 0), worse (above), within noise (holds 0), undetermined (none)."""
    if interval is None:
        return "undetermined"
    lo, hi = interval
    return "better" if hi < 0.0 else "worse" if lo > 0.0 else "within_noise"


def mover_interval(
    current: float,
    current_ci: tuple[float, float],
    baseline: float,
    baseline_ci: tuple[float, float],
) -> tuple[float, float]:
    """Return the MOVER 95 % interval of ``current - baseline`` from the two intervals.

    Zou & Donner (2008): ``L = d - sqrt((c - l_c)^2 + (u_b - b)^2)``,
    ``U = d + sqrt((u_c - c)^2 + (b - l_b)^2)``; for independent estimates.
    """
    d = current - baseline
    lo = d - math.hypot(current - current_ci[0], baseline_ci[1] - baseline)
    hi = d + math.hypot(current_ci[1] - current, baseline - baseline_ci[0])
    return lo, hi


def bootstrap_rmse_ci(errors: FloatArray) -> tuple[float, float] | None:
    """The 95 % block-bootstrap interval of an error series' RMSE (None: fewer than 8)."""
    from loceval.assessment.uncertainty import interval_stats  # noqa: PLC0415  (scipy)

    try:
        lo, hi = interval_stats(np.asarray(errors, dtype=np.float64)).ci95["rmse"]
    except LocevalError:
        return None
    return float(lo), float(hi)


def paired_difference(
    current: tuple[StampsNs, FloatArray],
    baseline: tuple[StampsNs, FloatArray],
    name: str,
    metric: str,
) -> tuple[float, tuple[float, float], int] | None:
    """Return ``(difference, interval, n)`` on the shared stamps, or None (too few)."""
    from loceval.assessment.comparison import ComparedMetric, compare_errors  # noqa: PLC0415
    from loceval.registration.stamps import match_nearest_seconds  # noqa: PLC0415

    t_c, e_c = np.asarray(current[0], np.int64), np.asarray(current[1], np.float64)
    t_b, e_b = np.asarray(baseline[0], np.int64), np.asarray(baseline[1], np.float64)
    keep = np.unique(t_c, return_index=True)[1]
    t_c, e_c = t_c[keep], e_c[keep]
    order = np.argsort(t_b, kind="stable")
    t_b, e_b = t_b[order], e_b[order]
    c_idx, b_idx = match_nearest_seconds(t_c, t_b, max_dt_s=_MAX_DT_S)
    first = np.unique(c_idx, return_index=True)[1]
    c_idx, b_idx = c_idx[first], b_idx[first]
    if c_idx.size < 8:
        return None
    ec, eb = e_c[c_idx], e_b[b_idx]
    if np.allclose(ec, eb, rtol=1e-9, atol=0.0):  # the same errors: no difference at all
        d = math.sqrt(float(np.mean(ec**2))) - math.sqrt(float(np.mean(eb**2)))
        return d, (d, d), int(c_idx.size)
    stamps = t_c[c_idx]
    found = compare_errors(
        stamps, ec, stamps, eb, a=name, b="baseline", metric=ComparedMetric(metric)
    )
    return found.difference, found.ci95, found.n_common
