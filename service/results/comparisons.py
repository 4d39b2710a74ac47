"""Compare systems across evaluations and uploaded evo result zips (``POST /comparisons``).

A team's archive of evo results joins the systems loceval evaluated: each item is an
estimate of a succeeded evaluation (loceval's figures, with its 95 % intervals) or an
uploaded evo result zip (evo's figures as evo wrote them; evo gives no interval, and the
answer says so rather than inventing one). Every pair whose error series are both at hand
(an evo zip keeps ``error_array`` and ``timestamps``; an evaluation its ``errors.csv``) is
compared with the paired block bootstrap on the instants both share
(:func:`loceval.assessment.comparison.compare_errors_nearest`); a pair without is listed
with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final, Literal

from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import InputError, LocevalError
from loceval.results.document import STAT_NAMES, EstimateRead, read_result
from service.blobs import artifact_key
from service.blobs.base import EVALUATIONS
from service.db import Dataset, Evaluation, JobStatus, get_owned
from service.errors import NotReadyError
from service.runtime import Runtime
from service.schemas.comparisons import (
    ComparedItem,
    ComparedResultPublic,
    ComparisonCreate,
    ComparisonPairPublic,
    ComparisonPublic,
)
from service.uploads.evo_results import is_evo_result, read_evo_dataset

__all__ = ["compare_items"]

_STATS: Final = tuple(name for name in STAT_NAMES if name not in {"var", "n"})
"""The statistics shown of each item, as evo's result zips hold them (no variance, no count)."""
_EVO_INTERVALS: Final = "evo gives no confidence interval; none is shown (none is made up)."


@dataclass(frozen=True, slots=True)
class _System:
    """One item as found: its public figures and its error series, or why it has none."""

    public: ComparedResultPublic
    series: tuple[StampsNs, FloatArray] | None
    no_series: str


def compare_items(runtime: Runtime, project_id: str, body: ComparisonCreate) -> ComparisonPublic:
    """Return the items' figures side by side and every pair compared.

    Raises:
        NotFoundError: an evaluation or dataset is not in the project.
        NotReadyError: an evaluation has not succeeded.
        InputError: an item is not comparable (a dataset that is no evo result zip, an
            estimate the evaluation lacks, an evo result of another metric, two labels
            alike); the message names ``items[k]``.
    """
    systems = [
        _system(runtime, project_id, k, item, body.metric) for k, item in enumerate(body.items)
    ]
    labels = [s.public.label for s in systems]
    repeated = sorted({label for label in labels if labels.count(label) > 1})
    if repeated:
        msg = f"items: the labels {repeated!r} repeat; give each item its own label."
        raise InputError(msg)
    pairs = [_pair(a, b, body.metric) for i, a in enumerate(systems) for b in systems[i + 1 :]]
    notes = []
    if any(s.public.source == "evo" for s in systems):
        notes.append(
            "Items from evo result zips carry evo's figures as evo computed them (its "
            "association and alignment, named in their title); " + _EVO_INTERVALS
        )
    return ComparisonPublic(
        metric=body.metric, items=[s.public for s in systems], comparisons=pairs, notes=notes
    )


def _system(runtime: Runtime, project_id: str, k: int, item: ComparedItem, metric: str) -> _System:
    if item.dataset_id is not None:
        dataset = get_owned(runtime.sessions, Dataset, item.dataset_id, project_id)
        return _evo_system(runtime, k, item, dataset, metric)
    assert item.evaluation_id is not None  # noqa: S101  (the schema requires one of them)
    evaluation = get_owned(runtime.sessions, Evaluation, item.evaluation_id, project_id)
    return _evaluation_system(runtime, k, item, evaluation, metric)


def _evo_system(
    runtime: Runtime, k: int, item: ComparedItem, dataset: Dataset, metric: str
) -> _System:
    where = f"items[{k}].dataset_id"
    if not is_evo_result(dataset):
        kind = dataset.inspection.get("format") or dataset.inspection.get("kind")
        msg = (
            f"{where}: the dataset {dataset.name!r} is a {kind} upload, not an evo result "
            "zip; evaluate it, then name the evaluation (evaluation_id)."
        )
        raise InputError(msg)
    try:
        result = read_evo_dataset(runtime, dataset)
    except LocevalError as err:
        msg = f"{where}: {err}"
        raise err.reworded(msg) from None
    wanted = {"ate_rmse": "ape", "rpe_rmse": "rpe"}[metric]
    if result.metric != wanted or not result.translation_m:
        msg = (
            f"{where}: {dataset.name!r} holds {result.title or 'no title'!r}, and "
            f"metric={metric!r} compares the {wanted.upper()} of the translation in metres; "
            f"name zips of evo_{wanted} -r trans_part, or change metric."
        )
        raise InputError(msg)
    from exporters.summary.evo import evo_system_name  # noqa: PLC0415  (matplotlib)

    errors = result.arrays.get("error_array")
    series = result.error_series()
    public = ComparedResultPublic(
        label=item.label or evo_system_name(result),
        source="evo",
        evaluation_id=None,
        dataset_id=dataset.id,
        title=" ".join(filter(None, [result.title, result.settings and f"({result.settings})"])),
        stats={key: result.stats.get(key) for key in _STATS},
        n=None if errors is None else int(errors.size),
        ci95=None,
        intervals=_EVO_INTERVALS,
    )
    why = f"{dataset.name!r} keeps no error series with stamps" if series is None else ""
    return _System(public, series, why)


def _estimate(document: dict[str, Any], k: int, item: ComparedItem) -> EstimateRead:
    """Return the item's estimate in an evaluation's result."""
    estimates = read_result(document).estimates
    names = [e.label for e in estimates]
    if item.estimate is None and len(estimates) == 1:
        return estimates[0]
    if item.estimate in names:
        return estimates[names.index(item.estimate)]
    given = "names none" if item.estimate is None else f"names {item.estimate!r}"
    msg = (
        f"items[{k}].estimate {given}; evaluation {item.evaluation_id!r} has the estimates "
        f"{names!r}: name one."
    )
    raise InputError(msg)


def _evaluation_system(
    runtime: Runtime, k: int, item: ComparedItem, evaluation: Evaluation, metric: str
) -> _System:
    if evaluation.status != JobStatus.SUCCEEDED or not isinstance(evaluation.result, dict):
        msg = (
            f"items[{k}].evaluation_id: evaluation {evaluation.id!r} is {evaluation.status}; "
            "compare it once it has succeeded."
        )
        raise NotReadyError(msg)
    estimate = _estimate(evaluation.result, k, item)
    name = estimate.name or item.estimate or "estimate 1"
    measured: Literal["ate", "rpe"] = "ate" if metric == "ate_rmse" else "rpe"
    block = estimate.block(measured)
    if block is None:
        msg = (
            f"items[{k}]: the estimate {name!r} of evaluation {evaluation.id!r} has no "
            f"{measured.upper()} in metres; compare another metric."
        )
        raise InputError(msg)
    public = ComparedResultPublic(
        label=item.label or name,
        source="loceval",
        evaluation_id=evaluation.id,
        dataset_id=None,
        title=f"{measured.upper()} w.r.t. translation part (m), loceval",
        stats={key: block.value(key) for key in _STATS},
        n=block.n,
        ci95=None if block.ci95 is None else dict(block.ci95),
        intervals="loceval's 95 % moving-block bootstrap intervals"
        if block.ci95 is not None
        else "the evaluation was made without intervals (no_ci).",
    )
    series, why = _evaluation_series(runtime, evaluation, name, metric)
    return _System(public, series, why)


def _evaluation_series(
    runtime: Runtime, evaluation: Evaluation, name: str, metric: str
) -> tuple[tuple[StampsNs, FloatArray] | None, str]:
    """Return the estimate's ATE series from the evaluation's errors.csv, or why not."""
    if metric != "ate_rmse":
        return None, (
            f"evaluation {evaluation.id!r}: RPE pairs are defined by each tool's own pairing, "
            "so its RPE errors are not paired with another tool's"
        )
    key = artifact_key(EVALUATIONS, evaluation.id, "errors.csv")
    if not runtime.store.exists(key):
        return None, (
            f"evaluation {evaluation.id!r} kept no errors.csv (its formats left it out); "
            "evaluate again with errors.csv among the formats"
        )
    from exporters.tables import read_ate_series  # noqa: PLC0415  (exporters load lazily)

    try:
        stamps, ate = read_ate_series(runtime.store.read_bytes(key), name)
    except (ValueError, OSError) as err:
        return None, f"evaluation {evaluation.id!r}: its errors.csv cannot be read ({err})"
    if not stamps.size:
        return None, f"evaluation {evaluation.id!r}: errors.csv has no rows of {name!r}"
    return (stamps, ate), ""


def _pair(a: _System, b: _System, metric: str) -> ComparisonPairPublic:
    """Compare two systems on their paired instants, or say why there is no interval."""
    from loceval.assessment.comparison import ComparedMetric, compare_errors_nearest  # noqa: PLC0415  (scipy)

    la, lb = a.public.label, b.public.label
    if a.series is None or b.series is None:
        why = a.no_series or b.no_series
        return ComparisonPairPublic(
            a=la, b=lb, summary=f"{la} vs {lb}: no paired interval: {why}.", unavailable=why
        )
    try:
        found = compare_errors_nearest(
            *a.series, *b.series, a=la, b=lb, metric=ComparedMetric(metric), unit="m"
        )
    except LocevalError as err:
        why = str(err).rstrip(".")
        return ComparisonPairPublic(
            a=la, b=lb, summary=f"{la} vs {lb}: no paired interval: {why}.", unavailable=why
        )
    return ComparisonPairPublic(
        a=la,
        b=lb,
        difference=found.difference,
        ci95=list(found.ci95),
        verdict=found.verdict.value,
        n_common=found.n_common,
        summary=found.summary,
    )
