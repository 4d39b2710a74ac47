"""Create evaluations (checked before they are queued) and show them."""

from __future__ import annotations

import logging
from typing import Any

from sqlalchemy import select

from loceval.errors import InputError
from service.db import Dataset, Evaluation, EvaluationStatus, get_owned, utcnow
from service.errors import NotFoundError, ServiceUnavailableError
from service.jobs import Runtime
from service.options import config_from_options, export_from_options, offset_or_none
from service.schemas import (
    ArtifactPublic,
    EvaluationCreate,
    EvaluationOptions,
    EvaluationPublic,
    ProgressPublic,
    SourceRef,
)

__all__ = ["check_options", "create_evaluation", "evaluation_public"]

logger = logging.getLogger(__name__)


def create_evaluation(
    runtime: Runtime, project_id: str, body: EvaluationCreate, *, enqueue: bool = True
) -> Evaluation:
    """Check a new evaluation, record it and queue its job.

    With ``enqueue=False`` the job is only recorded (a schedule run executes it itself).

    Raises:
        NotFoundError: a dataset is not in the project.
        InputError: a selector or option cannot be used (before anything is queued).
        ServiceUnavailableError: the queue cannot be reached (the evaluation is kept, failed).
    """
    options = body.options
    with runtime.sessions() as session:
        refs = [body.reference, *body.estimates]
        wanted = {r.dataset_id for r in refs}
        if options.device is not None:
            wanted.add(options.device.dataset_id)
        datasets = {
            d.id: d
            for d in session.scalars(
                select(Dataset).where(Dataset.project_id == project_id, Dataset.id.in_(wanted))
            )
        }
        for dataset_id in sorted(wanted - set(datasets)):
            msg = f"No dataset {dataset_id!r} in this project; upload it first (POST /datasets)."
            raise NotFoundError(msg)
        for role, ref in [("reference", body.reference)] + [
            ("estimate", e) for e in body.estimates
        ]:
            _check_selector(datasets[ref.dataset_id], ref, role)
        check_options(options)
        evaluation = Evaluation(
            project_id=project_id,
            request=body.model_dump(mode="json"),
            dataset_ids=sorted(wanted),
            created_at=utcnow(),
        )
        session.add(evaluation)
        session.commit()
    if not enqueue:
        return evaluation
    try:
        runtime.enqueue(evaluation.id)
    except Exception as err:
        logger.exception("Cannot queue evaluation %s", evaluation.id)
        with runtime.sessions() as session:
            row = session.get_one(Evaluation, evaluation.id)
            if row.status == EvaluationStatus.QUEUED:
                row.status = EvaluationStatus.FAILED
                row.stage = "failed"
                row.error = {
                    "type": "service.unavailable",
                    "title": "ServiceUnavailableError",
                    "status": 503,
                    "detail": "The job queue could not be reached; start the evaluation again.",
                }
                session.commit()
        msg = "The job queue cannot be reached; try again in a minute (see GET /readyz)."
        raise ServiceUnavailableError(msg) from err
    return get_owned(runtime.sessions, Evaluation, evaluation.id, project_id)


def check_options(options: EvaluationOptions) -> None:
    """Fail now, with the CLI's messages, on option values the job could not use.

    Raises:
        InputError: an option's value cannot be used.
    """
    if options.device is not None and options.offset:
        msg = "Give the device offset either as offset or as device, not both."
        raise InputError(msg)
    config_from_options(options, reference_offset=offset_or_none(options.offset))
    export_from_options(options)


def _check_selector(dataset: Dataset, ref: SourceRef, role: str) -> None:
    inspection: dict[str, Any] = dataset.inspection
    fmt = inspection.get("format")
    label = f"The {role} dataset {dataset.name!r}"
    if fmt == "urdf":
        msg = f"{label} is a URDF, not a trajectory; use it as the device offset."
        raise InputError(msg)
    sources = inspection.get("sources", [])
    selectors = [s.get("selector") for s in sources]
    if fmt == "bag":
        topics = {t.get("name") for t in inspection.get("topics", [])}
        if ref.selector is None:
            listed = ", ".join(str(s) for s in selectors[:12]) or "none found"
            msg = (
                f"{label} is a bag; choose a selector (a pose topic or tf:PARENT:CHILD): {listed}."
            )
            raise InputError(msg)
        if not ref.selector.startswith("tf:") and ref.selector not in topics:
            listed = ", ".join(str(s) for s in selectors[:12]) or "none found"
            msg = f"{label} has no topic {ref.selector!r}; its trajectory sources are: {listed}."
            raise InputError(msg)
        return
    if fmt == "motive":
        if ref.selector is None and len(selectors) == 1:
            return
        if ref.selector not in selectors:
            listed = ", ".join(str(s) for s in selectors)
            msg = f"{label} holds the rigid bodies {listed}; choose one as selector."
            raise InputError(msg)
        return
    if ref.selector is not None:
        msg = f"{label} is a {fmt} file with one trajectory; leave its selector empty (null)."
        raise InputError(msg)


def evaluation_public(
    evaluation: Evaluation, *, base_url: str, with_result: bool
) -> EvaluationPublic:
    """Return the HTTP view of an evaluation."""
    request = evaluation.request
    succeeded = evaluation.status == EvaluationStatus.SUCCEEDED
    artifacts = None
    if succeeded and evaluation.artifacts is not None:
        artifacts = [
            ArtifactPublic(
                **a, url=f"{base_url}api/v1/evaluations/{evaluation.id}/artifacts/{a['name']}"
            )
            for a in evaluation.artifacts
        ]
    return EvaluationPublic.model_validate(
        {
            "id": evaluation.id,
            "status": evaluation.status,
            "progress": ProgressPublic(stage=evaluation.stage, fraction=evaluation.fraction),
            "attempts": evaluation.attempts,
            "created_at": evaluation.created_at,
            "started_at": evaluation.started_at,
            "finished_at": evaluation.finished_at,
            "reference": request["reference"],
            "estimates": request["estimates"],
            "options": request.get("options", {}),
            "summary": evaluation.summary if succeeded else None,
            "error": evaluation.error,
            "artifacts": artifacts,
            "result": evaluation.result if (succeeded and with_result) else None,
        }
    )
