"""The baseline of an evaluation, read where the front doors find it.

``loceval evaluate --baseline PATH`` takes a ``result.json`` of an earlier evaluation (its
``errors.csv`` beside it gives the per-pose errors that pair), the folder ``--out`` wrote, an
evo result zip (``evo_ape``/``evo_rpe --save_results``), or a folder of such zips.
``POST /evaluations`` takes ``options.baseline``: the id of a succeeded evaluation of the
project (its stored result and ``errors.csv``). Both become one
:class:`~loceval.assessment.baseline.Baseline`, compared in the job
(:func:`loceval.assessment.baseline.compare_with_baseline`).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from loceval.assessment.baseline import Baseline
from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import InputError, LocevalError
from loceval.readers.evo_result import is_result_zip, read_result_zip
from loceval.results.baseline import baseline_from_document, baseline_from_evo
from loceval.results.document import read_result

if TYPE_CHECKING:
    from service.runtime import Runtime
    from service.schemas.evaluations import EvaluationCreate

__all__ = ["check_trials", "evaluation_baseline", "read_baseline"]

_COLUMNS = {"ate_rmse": "ate_m", "rpe_rmse": "rpe_m"}


def _series_from_csv(
    data: bytes | None,
) -> Callable[[str, str], tuple[StampsNs, FloatArray] | None] | None:
    """Return the reader of per-pose errors of ``errors.csv`` (None without the file)."""
    if data is None:
        return None
    from exporters.tables import read_error_series  # noqa: PLC0415  (exporters load on use)

    def series_of(name: str, metric: str) -> tuple[StampsNs, FloatArray] | None:
        try:
            return read_error_series(data, name, _COLUMNS[metric])
        except ValueError:
            return None

    return series_of


def read_baseline(path: Path) -> Baseline:
    """Read the baseline ``--baseline`` names.

    Raises:
        InputError: the path is none of the four (the message says which are), or its
            file cannot be read; the error carries the option ``baseline``.
    """
    try:
        return _read(path)
    except LocevalError as err:
        if err.option is None:
            err.option = "baseline"
        raise


def _read(path: Path) -> Baseline:
    if path.is_dir():
        if (path / "result.json").is_file():
            return _result_file(path / "result.json", label=path.name)
        zips = sorted(p for p in path.glob("*.zip") if is_result_zip(p))
        if zips:
            return _evo(zips, label=path.name, source=str(path))
        msg = (
            f"The baseline folder {str(path)!r} holds neither a result.json nor evo result "
            "zips; name an earlier evaluation's --out folder, its result.json or evo zips."
        )
        raise InputError(msg, option="baseline")
    if not path.is_file():
        msg = f"No baseline {str(path)!r}; name a result.json, an --out folder or an evo zip."
        raise InputError(msg, option="baseline")
    if is_result_zip(path):
        return _evo([path], label=path.name, source=str(path))
    return _result_file(path, label=path.parent.name or path.name)


def _result_file(path: Path, *, label: str) -> Baseline:
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as err:
        msg = (
            f"The baseline {str(path)!r} is not a result.json of loceval ({err}); name an "
            "earlier evaluation's result.json or an evo result zip."
        )
        raise InputError(msg, option="baseline") from None
    errors_csv = path.with_name("errors.csv")
    data = errors_csv.read_bytes() if errors_csv.is_file() else None
    baseline = baseline_from_document(
        read_result(document), label=label, source=str(path), series_of=_series_from_csv(data)
    )
    if data is None:
        unpaired = (
            "The baseline has no errors.csv beside its result.json, so no comparison with it "
            "is paired."
        )
        return replace(baseline, notes=(*baseline.notes, unpaired))
    return baseline


def _evo(zips: list[Path], *, label: str, source: str) -> Baseline:
    from exporters.summary.evo import evo_system_name  # noqa: PLC0415  (matplotlib)

    read = [read_result_zip(p) for p in zips]
    return baseline_from_evo([(evo_system_name(r), r) for r in read], label=label, source=source)


def evaluation_baseline(runtime: Runtime, project_id: str, evaluation_id: str) -> Baseline:
    """Read the baseline of ``options.baseline``: a succeeded evaluation of the project.

    Raises:
        NotFoundError: no such evaluation in the project.
        InputError: it has not succeeded (option ``baseline``).
    """
    from service.blobs import artifact_key  # noqa: PLC0415
    from service.blobs.base import EVALUATIONS  # noqa: PLC0415
    from service.db import Evaluation, JobStatus, get_owned  # noqa: PLC0415

    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    if evaluation.status != JobStatus.SUCCEEDED or not isinstance(evaluation.result, dict):
        msg = (
            f"The baseline evaluation {evaluation_id!r} is {evaluation.status}; name an "
            "evaluation that succeeded."
        )
        raise InputError(msg, option="baseline")
    key = artifact_key(EVALUATIONS, evaluation.id, "errors.csv")
    data = runtime.store.read_bytes(key) if runtime.store.exists(key) else None
    return baseline_from_document(
        read_result(evaluation.result),
        label=f"evaluation {evaluation.id}",
        source=f"evaluation:{evaluation.id}",
        series_of=_series_from_csv(data),
    )


def check_trials(runtime: Runtime, project_id: str, body: EvaluationCreate) -> None:
    """Check that a baseline is a succeeded evaluation of the project.

    The reference is no trial: its schema has no `system` (a 422 names `reference.system`).

    Raises:
        InputError: the baseline has not succeeded.
        NotFoundError: no baseline evaluation of that id in the project.
    """
    if body.options.baseline is not None:
        evaluation_baseline(runtime, project_id, body.options.baseline)
