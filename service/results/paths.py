"""An evaluation's paths as the CAD files carry them, with its figures: what Hops serves.

The paths are the ones the evaluation wrote to ``paths.3dm.json`` (model coordinates in the
evaluation's units, the same vertices as ``paths.dxf``); the figures come from its
``result.json``, read through :func:`loceval.results.document.read_result`. The routes in
:mod:`service.api.hops` only translate these into the Hops protocol.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from loceval.results.document import ResultRead, read_result
from service.blobs import artifact_key
from service.blobs.base import EVALUATIONS
from service.db import Evaluation, JobStatus, get_owned
from service.errors import NotFoundError, NotReadyError
from service.runtime import Runtime

__all__ = ["EvaluationPaths", "read_paths"]


@dataclass(frozen=True, slots=True)
class EvaluationPaths:
    """A succeeded evaluation's paths and figures.

    Attributes:
        evaluation_id: the evaluation.
        units: the paths' length unit (``mm``, ``cm``, ``m``).
        paths: each trajectory's entry of ``paths.3dm.json`` (name, kind, colour, curves,
            ATE runs, ...), in its order.
        result: the evaluation's result document, read.
        ate_runs: each path's ATE runs by its name (``curve`` and ``color``: the path cut
            where its error changes colour; none for the reference).
        ate_legend: what the ATE runs' colours mean (``paths.3dm.json``'s legend: the
            tolerance in words and the bins), or None in a document written without one.
    """

    evaluation_id: str
    units: str
    paths: Sequence[Mapping[str, Any]]
    result: ResultRead
    ate_runs: Mapping[str, Sequence[Mapping[str, Any]]] = dataclasses.field(default_factory=dict)
    ate_legend: Any = None


def read_paths(runtime: Runtime, project_id: str, evaluation_id: str) -> EvaluationPaths:
    """Return a succeeded evaluation's paths and its result.

    Raises:
        NotFoundError: no such evaluation in the project, or it wrote no ``paths.3dm.json``.
        NotReadyError: the evaluation has not succeeded (yet).
    """
    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    if evaluation.status != JobStatus.SUCCEEDED:
        msg = (
            f"Evaluation {evaluation_id!r} is {evaluation.status}, so it has no paths yet; "
            "solve again when it has succeeded."
        )
        raise NotReadyError(msg)
    paths_key = artifact_key(EVALUATIONS, evaluation.id, "paths.3dm.json")
    if not runtime.store.exists(paths_key):
        msg = (
            f"Evaluation {evaluation_id!r} did not write 'paths.3dm.json' (its formats left it "
            "out); run it again with the CAD files."
        )
        raise NotFoundError(msg)
    document = json.loads(runtime.store.read_bytes(paths_key).decode("utf-8"))
    result_key = artifact_key(EVALUATIONS, evaluation.id, "result.json")
    result = read_result(json.loads(runtime.store.read_bytes(result_key).decode("utf-8")))
    return EvaluationPaths(
        evaluation.id,
        str(document["units"]),
        document["paths"],
        result,
        ate_runs={str(path["name"]): path.get("ate", []) for path in document["paths"]},
        ate_legend=document.get("ate_legend"),
    )
