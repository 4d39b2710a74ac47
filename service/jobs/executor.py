"""The evaluation job: a stored evaluation's inputs read, run within limits, published.

:func:`execute_evaluation` is the executor of the ``evaluation`` kind
(:data:`service.jobs.kinds.JOB_KINDS`). It runs inside
:func:`service.jobs.tracking.tracked_job` (claim, heartbeat, finish, cleanup); the
computation runs in a child process within the settings' wall-time and memory limits
(:func:`service.jobs.limits.run_limited`), so a runaway one fails with the reason and frees its
worker.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sqlalchemy import update
from sqlalchemy.orm import Session

from exporters import ARTIFACTS
from loceval.errors import InputError, LocevalError
from loceval.readers import SourceSpec, TrajectoryFormat
from loceval.results.document import read_result
from service.adapters import DATABASE_ERRORS
from service.blobs.base import EVALUATIONS
from service.db import Dataset, Evaluation, JobStatus
from service.jobs.baseline import evaluation_baseline
from service.jobs.evaluations import visits_dataset_id
from service.jobs.kinds import EVALUATION, request_kind
from service.jobs.limits import Limits, run_limited
from service.jobs.mapjob import map_source
from service.jobs.options import (
    checkpoints_from_options,
    config_from_options,
    device_offset,
    export_from_options,
    ranging_from_options,
)
from service.jobs.runner import (
    Job,
    JobSource,
    RangingJob,
    RangingSources,
    evaluation_job,
    file_provenance,
    run_job,
)
from service.jobs.tracking import tracked_job
from service.runtime import Runtime, load_target
from service.schemas.evaluations import (
    DeviceOffset,
    EstimateRef,
    EvaluationCreate,
    RangingCreate,
    SourceRef,
)

__all__ = [
    "ReadyArtifacts",
    "artifact_entry",
    "evaluation_summary",
    "execute_evaluation",
    "log_warnings",
    "ranging_job",
    "stored_request",
    "trajectory_job",
]

logger = logging.getLogger(__name__)


def execute_evaluation(runtime: Runtime, evaluation_id: str) -> None:
    """Run one evaluation job to succeeded or failed; a no-op if someone else claimed it."""
    with tracked_job(runtime, EVALUATION, evaluation_id) as job:
        if job is None:
            return
        with runtime.store.pinned():  # inputs from a bucket stay in the local cache meanwhile
            with runtime.sessions() as session:
                evaluation = session.get_one(Evaluation, evaluation_id)
                work = _job_for(session, runtime, evaluation)
            runtime.store.clear_job(job.kind.folder, evaluation_id)
            staging = job.staging_dir()
            ready = ReadyArtifacts(runtime, evaluation_id, staging)
            ready.forget()  # an earlier attempt's files are gone with clear_job
            # In a child process: stopped at the wall-time limit, capped at the memory limit.
            try:
                run_limited(
                    Limits.from_settings(runtime.settings),
                    run_job,
                    work,
                    staging,
                    progress=job.progress,
                    artifacts=ready,
                )
            except BaseException:
                if ready.ready:  # a failed evaluation keeps none of the files it published
                    runtime.store.clear_job(job.kind.folder, evaluation_id)
                raise
        final = job.publish(staging)
        document = json.loads((final / "result.json").read_text())
        job.succeed(
            result=document,
            summary=evaluation_summary(document),
            artifacts=[
                artifact_entry(name, final / name) for name in ARTIFACTS if (final / name).is_file()
            ],
        )
        log_warnings(document)


def log_warnings(document: Mapping[str, Any]) -> None:
    """Write each warning of a job's result to the log, at warning level, one line each.

    An operator reading the log of an odd job sees what the result warns of (a clock that
    disagrees with the given offset, duplicate stamps dropped), not only its transitions;
    the job's context (``job_id``, ``kind``, ``project``) is on every line, and
    ``warning_in`` says where in the result it is (``reference``, an estimate, ``map``).
    """
    for where, text in read_result(document).warnings():
        logger.warning("%s", text, extra={"warning_in": where})


def artifact_entry(name: str, path: Path) -> dict[str, Any]:
    """Return an artifact's row in an evaluation's ``artifacts``: name, media type, size."""
    return {
        "name": name,
        "media_type": ARTIFACTS[name].media_type,
        "size_bytes": path.stat().st_size,
    }


class ReadyArtifacts:
    """Publishes each artifact of a running evaluation the moment its process writes it.

    Called (in the worker, through :func:`service.jobs.limits.run_limited`) with an artifact's
    name and its file in the job's staging folder: the file is published to the store
    and the evaluation's row lists it, so ``GET /evaluations/{id}`` shows it and it can
    be downloaded while the others are still being made. ``result.json`` comes first;
    with it the row gets the result document and the summary, and the page shows the
    figures. The finished set replaces all of it when the job succeeds. A store or
    database that fails here costs only the early view: the job goes on.
    """

    def __init__(self, runtime: Runtime, evaluation_id: str, staging: Path) -> None:
        """Publish for ``evaluation_id``, whose artifacts are written into ``staging``."""
        self.runtime = runtime
        self.evaluation_id = evaluation_id
        self.staging = staging
        self.ready: list[dict[str, Any]] = []

    def forget(self) -> None:
        """Clear the row's artifacts, result and summary (a new attempt starts)."""
        self._store_row(artifacts=None, result=None, summary=None)

    def __call__(self, name: str, path: str) -> None:
        """Publish the artifact ``name`` written at ``path``."""
        # The child moves the whole set into the staging folder once the last file is
        # written, possibly before this message is read: the file is then there.
        found = next((p for p in (Path(path), self.staging / name) if p.is_file()), None)
        if found is None or name not in ARTIFACTS:
            return
        try:
            self.runtime.store.publish_job_artifact(EVALUATIONS, self.evaluation_id, name, found)
            entry = artifact_entry(name, found)
            document = json.loads(found.read_bytes()) if name == "result.json" else None
        except (OSError, ValueError, LocevalError) as err:
            logger.warning("%s of %s not published early (%s)", name, self.evaluation_id, err)
            return
        self.ready.append(entry)
        values: dict[str, Any] = {"artifacts": list(self.ready)}
        if document is not None:
            values.update(result=document, summary=evaluation_summary(document))
        self._store_row(**values)

    def _store_row(self, **values: Any) -> None:  # noqa: ANN401
        try:
            with self.runtime.sessions() as session:
                session.execute(
                    update(Evaluation)
                    .where(Evaluation.id == self.evaluation_id)
                    .where(Evaluation.status == JobStatus.RUNNING)
                    .values(**values)
                )
                session.commit()
        except DATABASE_ERRORS as err:  # shown early, not kept: the finished job stores all
            logger.warning("Artifacts of %s not listed early (%s)", self.evaluation_id, err)


def evaluation_summary(document: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Return the headline figures per estimate from a result document."""
    return [
        {
            "name": estimate.name,
            "ate_rmse_m": estimate.rmse_m("ate"),
            "rpe_rmse_m": estimate.rmse_m("rpe"),
            "matched": estimate.matched,
            "verdict": None if estimate.verdict is None else estimate.verdict.outcome,
        }
        for estimate in read_result(document).estimates
    ]


def stored_request(evaluation: Evaluation) -> EvaluationCreate | RangingCreate:
    """Read an evaluation's stored request as the model of its recorded kind.

    The kind is the one the evaluation was made as (``evaluations.kind``), looked up in
    :data:`service.jobs.kinds.REQUEST_KINDS`; the request is checked as when it was made.

    Raises:
        LocevalError: a kind this version does not know.
        pydantic.ValidationError: the stored request no longer fits its model.
    """
    return request_kind(evaluation.kind).read(evaluation.request)


def _job_for(session: Session, runtime: Runtime, evaluation: Evaluation) -> Job:
    """Return the job of a stored evaluation, made as its request's kind says."""
    kind = request_kind(evaluation.kind)
    job: Job = load_target(kind.job)(session, runtime, evaluation, kind.read(evaluation.request))
    return job


def trajectory_job(
    session: Session, runtime: Runtime, evaluation: Evaluation, request: EvaluationCreate
) -> Job:
    """Return the job of a stored trajectory (or control-point) evaluation."""
    options = request.options
    project_id = evaluation.project_id
    reference = _source(session, runtime, project_id, request.reference, "reference")
    # A control-point job reads arrivals from its estimates' files too: those stay local.
    ranged = reference.spec.format is not TrajectoryFormat.POINTS
    estimates = [
        _source(session, runtime, project_id, e, "estimate", ranged=ranged)
        for e in request.estimates
    ]
    device_transform = None
    if isinstance(options.device, DeviceOffset):
        dataset = _dataset(session, project_id, options.device.dataset_id)
        device_transform = device_offset(
            _file(runtime, dataset),
            from_link=options.device.from_link,
            to_link=options.device.to_link,
        )
    visits = None
    visits_id = visits_dataset_id(options.visits)
    if visits_id is not None:
        table = _dataset(session, project_id, visits_id)
        spec = SourceSpec(None, _file(runtime, table))
        provenance = file_provenance("visits", spec, sha256=table.sha256)
        provenance.update(path=table.filename, dataset_id=table.id)
        visits = JobSource(spec, Path(table.filename).stem, provenance, table.filename)
    building = None
    if options.building is not None:
        building = _file(runtime, _dataset(session, project_id, options.building))
    export = export_from_options(
        options, front_door="service", evaluation_id=evaluation.id, building=building
    )
    the_map = None
    map_ref = options.map_ref
    if map_ref is not None:
        dataset = _dataset(session, project_id, map_ref.dataset_id)
        source = str(_file(runtime, dataset))
        if map_ref.selector:
            source = f"{source}@{map_ref.selector}"
        the_map = map_source(
            source,
            export,
            estimate=options.map_estimate,
            clutter_m=options.clutter_m,
            display=dataset.filename + (f"@{map_ref.selector}" if map_ref.selector else ""),
        )
    return evaluation_job(
        reference=reference,
        estimates=estimates,
        config=config_from_options(options, device_transform=device_transform),
        stamp=options.stamp,
        export=export,
        formats=options.formats,
        visits=visits,
        checkpoints=checkpoints_from_options(options),
        the_map=the_map,
        baseline=None
        if options.baseline is None
        else evaluation_baseline(runtime, project_id, options.baseline),
    )


def ranging_job(
    session: Session, runtime: Runtime, evaluation: Evaluation, request: RangingCreate
) -> RangingJob:
    """Return the job of a stored ranging evaluation."""
    options = request.options
    project_id = evaluation.project_id
    reference = _source(session, runtime, project_id, request.reference, "reference")
    ranges_ref = request.ranges_ref
    records = []
    for role, dataset_id in (("anchors", request.anchors), ("ranges", ranges_ref.dataset_id)):
        dataset = _dataset(session, project_id, dataset_id)
        bag = dataset.inspection.get("format") == "bag"
        spec = SourceSpec(
            TrajectoryFormat.BAG if bag else None,
            _file(runtime, dataset),
            ranges_ref.selector if role == "ranges" else None,
        )
        provenance = file_provenance(role, spec, sha256=dataset.sha256)
        provenance.update(path=dataset.filename, dataset_id=dataset.id)
        records.append((spec, provenance, dataset.filename))
    (anchors, anchors_record, anchors_name), (ranges, ranges_record, ranges_name) = records
    return RangingJob(
        reference=reference,
        config=config_from_options(options),
        stamp=options.stamp,
        export=export_from_options(options, front_door="service", evaluation_id=evaluation.id),
        formats=options.formats,
        ranging=RangingSources(
            anchors=anchors.path,
            ranges=ranges,
            config=ranging_from_options(options),
            provenance=(anchors_record, ranges_record),
            display_paths={str(anchors.path): anchors_name, str(ranges.path): ranges_name},
        ),
    )


def _file(runtime: Runtime, dataset: Dataset) -> Path:
    """Return a local file with a dataset's bytes (from a bucket: the input cache's copy)."""
    return runtime.store.local_path(
        dataset.storage_path, filename=dataset.filename, sha256=dataset.sha256
    )


def _dataset(session: Session, project_id: str, dataset_id: str) -> Dataset:
    dataset = session.get(Dataset, dataset_id)
    if dataset is None or dataset.project_id != project_id:
        msg = (
            f"Dataset {dataset_id!r} was deleted after the evaluation was queued; upload it again."
        )
        raise InputError(msg)
    return dataset


def _source(
    session: Session,
    runtime: Runtime,
    project_id: str,
    ref: SourceRef,
    role: str,
    *,
    ranged: bool = True,
) -> JobSource:
    """Return a dataset as a job's trajectory source.

    A large MCAP file in a bucket is read where it lies (``ranged``, see
    :meth:`service.blobs.Blobs.job_input`); any other file from a local copy.
    """
    dataset = _dataset(session, project_id, ref.dataset_id)
    fmt = dataset.inspection.get("format")
    if fmt not in {f.value for f in TrajectoryFormat}:
        msg = f"Dataset {dataset.name!r} is a {dataset.kind} file, not a trajectory recording."
        raise InputError(msg)
    fmt = TrajectoryFormat(fmt)
    remote = None
    if ranged and fmt is TrajectoryFormat.BAG:
        remote = runtime.store.job_input(
            dataset.storage_path,
            filename=dataset.filename,
            sha256=dataset.sha256,
            size=dataset.size_bytes,
        )
    if remote is None:
        spec = SourceSpec(fmt, _file(runtime, dataset), ref.selector)
        provenance = file_provenance(role, spec, sha256=dataset.sha256)
    else:  # the path only names the file: it is read through ``remote``
        spec = SourceSpec(fmt, Path(dataset.filename), ref.selector)
        provenance = file_provenance(role, spec, sha256=dataset.sha256, size=dataset.size_bytes)
    provenance.update(path=dataset.filename, dataset_id=dataset.id)
    name = ref.name or ref.selector or Path(dataset.filename).stem
    return JobSource(
        spec,
        str(name),
        provenance,
        display_path=dataset.filename,
        remote=remote,
        system=ref.system if isinstance(ref, EstimateRef) else None,
    )
