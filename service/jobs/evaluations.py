"""The evaluations resource: create (checked before queued), list, show, artifacts.

The routes in :mod:`service.api.evaluations` only translate HTTP to these calls.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence

from pydantic import ValidationError
from sqlalchemy import func, select
from sqlalchemy.orm import Session, defer

from exporters import ARTIFACTS
from loceval.errors import InputError
from loceval.results.gate import gate_of_document
from service.blobs import artifact_key
from service.blobs.base import EVALUATIONS, download_filename
from service.db import ACTIVE_STATUSES, Dataset, Evaluation, JobStatus, get_owned, utcnow
from service.errors import (
    InvalidFieldsError,
    NotFoundError,
    NotReadyError,
    ServiceUnavailableError,
    UploadError,
    problem_for,
)
from service.jobs.kinds import EVALUATION, RANGING, TRAJECTORY
from service.jobs.options import (
    CONTROL_POINTS_NO_TOLERANCE,
    config_from_options,
    export_from_options,
    ranging_from_options,
)
from service.jobs.selectors import check_selector
from service.runtime import Runtime
from service.schemas.evaluations import (
    ArtifactPublic,
    DeviceOffset,
    EstimateRef,
    EvaluationCreate,
    EvaluationOptions,
    EvaluationPublic,
    ProgressPublic,
    RangingCreate,
    RangingOptions,
    SourceRef,
    SummaryRow,
)
from service.uploads.datasets import store_upload
from service.uploads.multipart import ReceivedForm

__all__ = [
    "artifact_filename",
    "artifact_path",
    "check_options",
    "create_evaluation",
    "create_ranging",
    "evaluate_form",
    "evaluation_public",
    "list_evaluations",
    "visits_dataset_id",
]

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
        if isinstance(options.device, DeviceOffset):
            wanted.add(options.device.dataset_id)
        if visits_dataset_id(options.visits) is not None:
            wanted.add(options.visits.strip())
        if options.building is not None:
            wanted.add(options.building)
        map_ref = options.map_ref
        if map_ref is not None:
            wanted.add(map_ref.dataset_id)
        datasets = _datasets(session, project_id, wanted)
        for role, ref in [("reference", body.reference)] + [
            ("estimate", e) for e in body.estimates
        ]:
            check_selector(datasets[ref.dataset_id], ref, role)
        _check_visits(datasets, body)
        if options.tolerance is not None and _is_points(datasets[body.reference.dataset_id]):
            raise InputError(CONTROL_POINTS_NO_TOLERANCE, option="tolerance")
        if options.building is not None:
            _check_building(datasets[options.building])
        if map_ref is not None:
            _check_map(datasets[map_ref.dataset_id], map_ref.selector, options)
        check_options(options)
        from service.jobs.baseline import check_trials  # noqa: PLC0415

        check_trials(runtime, project_id, body)
        evaluation = Evaluation(
            project_id=project_id,
            kind=TRAJECTORY,
            request=body.model_dump(mode="json"),
            dataset_ids=sorted(wanted),
            created_at=utcnow(),
        )
        session.add(evaluation)
        session.commit()
    return _queued(runtime, project_id, evaluation, enqueue=enqueue)


def create_ranging(runtime: Runtime, project_id: str, body: RangingCreate) -> Evaluation:
    """Check a new ranging evaluation, record it as an evaluation and queue its job.

    The record is an evaluation whose request holds the ranging body and, as its estimates,
    the solvers' outputs (named ``nlls`` / ``minmax``, from the ranges dataset); the job
    runs :func:`loceval.radio_evaluation.evaluate_radio` (see
    :func:`service.jobs.executor.execute_evaluation`).

    Raises:
        NotFoundError: a dataset is not in the project.
        InputError: a dataset is of the wrong kind, a selector or option cannot be used.
        ServiceUnavailableError: the queue cannot be reached (the evaluation is kept, failed).
    """
    options = body.options
    ranges = body.ranges_ref
    with runtime.sessions() as session:
        wanted = {body.reference.dataset_id, body.anchors, ranges.dataset_id}
        datasets = _datasets(session, project_id, wanted)
        check_selector(datasets[body.reference.dataset_id], body.reference, "reference")
        _check_radio(datasets[body.anchors], datasets[ranges.dataset_id], ranges)
        check_ranging_options(options)
        request = body.model_dump(mode="json")
        request["estimates"] = [
            {"dataset_id": ranges.dataset_id, "selector": ranges.selector, "name": solver}
            for solver in options.solve
        ]
        evaluation = Evaluation(
            project_id=project_id,
            kind=RANGING,
            request=request,
            dataset_ids=sorted(wanted),
            created_at=utcnow(),
        )
        session.add(evaluation)
        session.commit()
    return _queued(runtime, project_id, evaluation, enqueue=True)


def _datasets(session: Session, project_id: str, wanted: set[str]) -> dict[str, Dataset]:
    """Return the project's datasets ``wanted`` by id.

    Raises:
        NotFoundError: one is not in the project (the first by id).
    """
    datasets = {
        d.id: d
        for d in session.scalars(
            select(Dataset).where(Dataset.project_id == project_id, Dataset.id.in_(wanted))
        )
    }
    for dataset_id in sorted(wanted - set(datasets)):
        msg = f"No dataset {dataset_id!r} in this project; upload it first (POST /datasets)."
        raise NotFoundError(msg)
    return datasets


def check_ranging_options(options: EvaluationOptions) -> None:
    """Fail now on ranging option values the job could not use.

    Raises:
        InputError: a device offset, a map, a baseline or a trials' coverage is given (a
            ranging evaluation has no use for them), or an option's value cannot be used.
    """
    if options.offset or options.device is not None:
        msg = (
            "A ranging evaluation takes no device offset; give the tag's position in the "
            "reference body frame as the tag offset."
        )
        raise InputError(msg, option="tag_offset_xyz")
    if options.map is not None:
        msg = "A map is measured in a trajectory evaluation, not a ranging one; leave it out."
        raise InputError(msg, option="map")
    if options.baseline is not None:
        msg = (
            "A baseline is compared with the estimates of a trajectory evaluation; a ranging "
            "evaluation's solvers have none: leave it out."
        )
        raise InputError(msg, option="baseline")
    if "min_trial_coverage" in options.model_fields_set:
        msg = (
            "The trials' coverage counts the trials of a named system in a trajectory "
            "evaluation; a ranging evaluation has none: leave it out."
        )
        raise InputError(msg, option="min_trial_coverage")
    check_options(options)


def _check_radio(anchors: Dataset, ranges: Dataset, ref: SourceRef) -> None:
    if anchors.inspection.get("format") not in {"anchors", "points"}:  # a survey id,x,y,z
        msg = (
            f"The anchors dataset {anchors.name!r} is a {anchors.kind} file, not an anchors "
            "table; upload a CSV with the header id,x,y,z."
        )
        raise InputError(msg)
    fmt = ranges.inspection.get("format")
    if fmt == "ranges":
        if ref.selector is not None:
            msg = f"The ranges dataset {ranges.name!r} is a table; leave its selector empty."
            raise InputError(msg)
        return
    if fmt != "bag":
        msg = (
            f"The ranges dataset {ranges.name!r} is a {ranges.kind} file, not ranges; upload "
            "a CSV with the header t,anchor_id,range_m or a bag with sensor_msgs/msg/Range."
        )
        raise InputError(msg)
    topics = [
        t.get("name")
        for t in ranges.inspection.get("topics", [])
        if t.get("msgtype") == "sensor_msgs/msg/Range"
    ]
    if ref.selector not in topics:
        listed = ", ".join(str(t) for t in topics) or "none"
        msg = (
            f"The ranges dataset {ranges.name!r} is a bag; choose its sensor_msgs/msg/Range "
            f"topic as selector ({listed})."
        )
        raise InputError(msg)


def _queued(
    runtime: Runtime, project_id: str, evaluation: Evaluation, *, enqueue: bool
) -> Evaluation:
    if not enqueue:
        return evaluation
    try:
        runtime.enqueue(EVALUATION, evaluation.id)
    except ServiceUnavailableError as err:
        logger.error("Cannot queue evaluation %s: %s", evaluation.id, err)  # noqa: TRY400
        with runtime.sessions() as session:
            row = session.get_one(Evaluation, evaluation.id)
            if row.status == JobStatus.QUEUED:
                row.status = JobStatus.FAILED
                row.stage = "failed"
                row.error = problem_for(
                    ServiceUnavailableError(
                        "The job queue could not be reached; start the evaluation again."
                    ),
                    private=runtime.private_roots,
                )
                session.commit()
        raise
    return get_owned(runtime.sessions, Evaluation, evaluation.id, project_id)


def _check_building(dataset: Dataset) -> None:
    """Fail now when the building option names a dataset that is not a building model."""
    if dataset.inspection.get("kind") != "building":
        msg = (
            f"The dataset {dataset.name!r} is not a building model; upload an IFC, OBJ, PLY, "
            "STL or GLB model, or a DXF floor plan, and give its id."
        )
        raise InputError(msg, option="building")


def _check_map(dataset: Dataset, selector: str | None, options: EvaluationOptions) -> None:
    """Fail now when the map names no map zip or bag, a bag without its topic, or no plan."""
    kind = dataset.inspection.get("kind")
    bag = dataset.inspection.get("format") == "bag"
    if kind != "map" and not bag:
        msg = (
            f"The dataset {dataset.name!r} is not a map; upload a zip of map_server's map.yaml "
            "and its image, or a bag with the map's topic, and give its id."
        )
        raise InputError(msg, option="map")
    if bag and not selector:
        msg = (
            f"The map dataset {dataset.name!r} is a bag; give the topic of its "
            'nav_msgs/msg/OccupancyGrid messages: {"dataset_id": ..., "selector": "/map"}.'
        )
        raise InputError(msg, option="map")
    if options.building is None:
        msg = "A map is measured against the building's plan; give options.building too."
        raise InputError(msg, option="map")


def check_options(options: EvaluationOptions) -> None:
    """Fail now, with the CLI's messages, on option values the job could not use.

    Raises:
        InputError: an option's value cannot be used.
    """
    config_from_options(options)  # each text option by its one grammar (parse_text)
    export_from_options(options, front_door="service")
    if isinstance(options, RangingOptions):
        ranging_from_options(options)


def visits_dataset_id(visits: str) -> str | None:
    """Return the dataset id of the visits option, None for ``auto`` (find the stops)."""
    text = visits.strip()
    return None if text.lower() == "auto" else text


def _is_points(dataset: Dataset) -> bool:
    """Whether a dataset is a control-point survey (its evaluation scores points)."""
    return dataset.inspection.get("format") == "points"


def _check_visits(datasets: dict[str, Dataset], body: EvaluationCreate) -> None:
    """A visits dataset must be a visits table, and the reference control points."""
    dataset_id = visits_dataset_id(body.options.visits)
    if dataset_id is None:
        return
    visits = datasets[dataset_id]
    if visits.inspection.get("format") != "visits":
        msg = (
            f"The visits dataset {visits.name!r} is a {visits.kind} file, not a visits table "
            "id,t_start,t_end; upload the visits table and give its id."
        )
        raise InputError(msg, option="visits")
    reference = datasets[body.reference.dataset_id]
    if not _is_points(reference):
        msg = (
            f"Visits apply to a control-point reference, and the reference {reference.name!r} "
            "is a trajectory; leave the visits at auto."
        )
        raise InputError(msg, option="visits")


def evaluation_public(
    evaluation: Evaluation, *, base_url: str, with_result: bool
) -> EvaluationPublic:
    """Return the HTTP view of an evaluation."""
    request = evaluation.request
    succeeded = evaluation.status == JobStatus.SUCCEEDED
    # A running evaluation shows what it has made so far (result.json first, then each file).
    shown = succeeded or evaluation.status == JobStatus.RUNNING
    document = evaluation.result if (shown and with_result) else None  # its gate as the CLI's
    artifacts = None
    if shown and evaluation.artifacts is not None:
        artifacts = [
            ArtifactPublic(
                **a,
                url=f"{base_url}api/v1/evaluations/{evaluation.id}/artifacts/{a['name']}",
                filename=artifact_filename(evaluation, a["name"]),
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
            "summary": evaluation.summary if shown else None,
            "error": evaluation.error,
            "artifacts": artifacts,
            "result": document,
            "gate": gate_of_document(document, request.get("options", {}).get("fail_on")),
        }
    )


def list_evaluations(
    runtime: Runtime, project_id: str, *, status: str | None, limit: int, offset: int
) -> tuple[Sequence[Evaluation], int]:
    """Return a page of the project's evaluations, newest first, and how many there are.

    The page is cut in SQL and the result documents (the large column) are not loaded.
    """
    where = [Evaluation.project_id == project_id]
    if status is not None:
        where.append(Evaluation.status == status)
    with runtime.sessions() as session:
        count = session.scalar(select(func.count()).select_from(Evaluation).where(*where))
        rows = session.scalars(
            select(Evaluation)
            .where(*where)
            .options(defer(Evaluation.result, raiseload=True))
            .order_by(Evaluation.created_at.desc(), Evaluation.id)
            .limit(limit)
            .offset(offset)
        ).all()
    return rows, int(count or 0)


def artifact_filename(evaluation: Evaluation, name: str) -> str:
    """Return the name a download of an artifact is saved under: ``<evaluation>-<name>``.

    An evaluation is named by its estimates (the names its summary gives them, else the
    request's), ``+`` between several; one with no estimate names (a ranging evaluation's
    request names none) by its id.
    """
    names = [SummaryRow.model_validate(row).name for row in evaluation.summary or ()]
    if not any(names):
        names = [EstimateRef.model_validate(ref).name for ref in evaluation.request["estimates"]]
    stem = "+".join(dict.fromkeys(n for n in names if n))
    return download_filename(stem, name, default=evaluation.id)


def artifact_path(
    runtime: Runtime, project_id: str, evaluation_id: str, name: str
) -> tuple[str, str]:
    """Return the blob key of an evaluation's artifact and the name it is saved under.

    Raises:
        NotFoundError: no such evaluation, artifact name, or file (its formats left it out).
        NotReadyError: the evaluation has not succeeded and has not written this one yet.
    """
    evaluation = get_owned(runtime.sessions, Evaluation, evaluation_id, project_id)
    if name not in ARTIFACTS:
        msg = f"No artifact {name!r}; the artifacts are {', '.join(ARTIFACTS)}."
        raise NotFoundError(msg)
    ready = evaluation.status == JobStatus.RUNNING and any(
        a.get("name") == name for a in evaluation.artifacts or ()
    )
    if evaluation.status != JobStatus.SUCCEEDED and not ready:
        msg = f"Evaluation {evaluation_id!r} is {evaluation.status}, so it has no artifacts" + (
            " yet; poll GET /evaluations/{id} until it succeeds."
            if evaluation.status in ACTIVE_STATUSES
            else "; see its error."
        )
        if evaluation.status == JobStatus.RUNNING and evaluation.artifacts:  # some are ready
            msg = f"Evaluation {evaluation_id!r} is running and has not written {name!r} yet; "
            msg += "poll GET /evaluations/{id} until its artifacts list it."
        raise NotReadyError(msg)
    key = artifact_key(EVALUATIONS, evaluation.id, name)
    if not runtime.store.exists(key):
        msg = f"Evaluation {evaluation_id!r} did not write {name!r} (its formats left it out)."
        raise NotFoundError(msg)
    return key, artifact_filename(evaluation, name)


def evaluate_form(runtime: Runtime, project_id: str, form: ReceivedForm) -> Evaluation:
    """Store the files of a one-shot upload as datasets and create their evaluation.

    Everything about the form is checked before any file is stored.

    Raises:
        UploadError: the form's fields do not fit together.
        InvalidFieldsError: the options or names are not valid (each error names its
            place, ``options.max_dt_s``, ``estimates.0.name``).
    """
    references = [f for f in form.files if f.field == "reference"]
    estimates = [f for f in form.files if f.field == "estimate"]
    if len(references) != 1:
        msg = f"Send exactly one file in the field 'reference', got {len(references)}."
        raise UploadError(msg)
    options = _form_options(form.value("options"))
    selectors = form.values("estimate_selector")
    names = form.values("estimate_name")
    count = len(estimates) or len(selectors)
    if count == 0:
        msg = (
            "Name the estimates: send 'estimate' files, or 'estimate_selector' values when "
            "the reference file holds them (a bag)."
        )
        raise UploadError(msg)
    if estimates and selectors and len(selectors) != len(estimates):
        msg = f"Send one estimate_selector per estimate file ({len(estimates)}), or none."
        raise UploadError(msg)
    if names and len(names) != count:
        msg = f"Send one estimate_name per estimate ({count}), or none."
        raise UploadError(msg)
    reference_ref: dict[str, str | None] = {
        "dataset_id": "pending",
        "selector": form.value("reference_selector"),
    }
    estimate_refs: list[dict[str, str | None]] = [
        {
            "dataset_id": "pending",
            "selector": (selectors[k] or None) if selectors else None,
            "name": (names[k] or None) if names else None,
        }
        for k in range(count)
    ]
    draft = {"reference": reference_ref, "estimates": estimate_refs, "options": options}
    try:  # checked before any file is stored; every error names its place (estimates.0.name)
        EvaluationCreate.model_validate(draft)
    except ValidationError as err:
        raise InvalidFieldsError(errors=err.errors()) from None
    reference, _ = store_upload(runtime, project_id, references[0])
    stored = [store_upload(runtime, project_id, f)[0] for f in estimates]
    reference_ref["dataset_id"] = reference.id
    for k, estimate in enumerate(estimate_refs):
        estimate["dataset_id"] = stored[k].id if stored else reference.id
    return create_evaluation(runtime, project_id, EvaluationCreate.model_validate(draft))


def _form_options(text: str | None) -> EvaluationOptions:
    if not text:
        return EvaluationOptions()
    try:
        json.loads(text)
    except json.JSONDecodeError as err:
        msg = f"The 'options' field is not JSON ({err.msg} at character {err.pos})."
        raise UploadError(msg) from None
    try:
        return EvaluationOptions.model_validate_json(text)
    except ValidationError as err:
        errors = [{**e, "loc": ("options", *e["loc"])} for e in err.errors()]
        raise InvalidFieldsError(errors=errors) from None
