"""One evaluation job, run the same way by the CLI and by the service's queue.

A job is of one of three kinds, each a type: :class:`TrajectoryJob` (estimates against a
reference trajectory), :class:`ControlPointJob` (estimates scored at surveyed points) and
:class:`RangingJob` (a radio system's ranges and solved positions). :func:`evaluation_job`
picks the kind of ``loceval evaluate`` and ``POST /evaluations`` from the reference, once;
``loceval ranging`` and ``POST /ranging`` build a :class:`RangingJob`. :func:`run_job` reads
the sources, evaluates and writes the artifacts. The options a job runs with are built from
the front doors' options by :mod:`service.jobs.options`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, overload

from loceval.checkpoints.config import CheckpointConfig
from loceval.errors import InputError, LocevalError
from loceval.evaluation import EvaluationConfig, EvaluationResult, ProgressCallback, evaluate
from loceval.options import choice_default
from loceval.readers import (
    SourceSpec,
    TrajectoryFormat,
    read_stored_bag,
    read_trajectory,
    sniff_format,
)
from loceval.trajectory import Trajectory
from service.jobs.options import CONTROL_POINTS_NO_TOLERANCE

if TYPE_CHECKING:
    from exporters import ArtifactCallback
    from exporters.options import ExportOptions
    from loceval.assessment.baseline import Baseline
    from loceval.assessment.trials import FailedTrial
    from loceval.checkpoint_evaluation import CheckpointEvaluation
    from loceval.controlpoints import ControlPoints, Visits
    from loceval.radio_evaluation import RangingConfig
    from loceval.readers.radio import Ranges
    from loceval.readers.rosbag import RemoteFile
    from service.jobs.mapjob import MapSource

__all__ = [
    "ControlPointJob",
    "Job",
    "JobSource",
    "RangingJob",
    "RangingSources",
    "TrajectoryJob",
    "default_name",
    "evaluation_job",
    "file_provenance",
    "run_job",
    "unique_names",
]

# Shares of the progress bar: reading, evaluating, writing the artifacts.
_READ, _EVALUATE = 0.25, 0.45


@dataclass(frozen=True, slots=True)
class JobSource:
    """A trajectory to read and what to record about where it came from.

    Attributes:
        spec: the parsed source.
        name: the trajectory's name in the result.
        provenance: the input record of the result (file, checksum, selector, dataset id).
        display_path: shown instead of the file's path in the result and the reports (the
            service shows the uploaded file name, not its folders on the server).
        remote: a bag read by position where it is stored (an MCAP file in a bucket)
            instead of ``spec.path``, which then only names it.
        system: the system this estimate is a trial of (None: not a trial).
    """

    spec: SourceSpec
    name: str
    provenance: Mapping[str, object] = field(default_factory=dict)
    display_path: str | None = None
    remote: RemoteFile | None = None
    system: str | None = None

    def read(self, *, stamp: str) -> Trajectory:
        """Read the trajectory, naming the file by ``display_path`` when given."""
        if self.remote is None:
            trajectory = read_trajectory(self.spec, name=self.name, stamp=stamp)
        else:
            trajectory = read_stored_bag(self.spec, self.remote, name=self.name, stamp=stamp)
        if self.display_path is None:
            return trajectory
        path, shown = str(self.spec.path), self.display_path
        return replace(
            trajectory,
            source=trajectory.source.replace(path, shown),
            warnings=tuple(w.replace(path, shown) for w in trajectory.warnings),
            notes=tuple(n.replace(path, shown) for n in trajectory.notes),
        )


@dataclass(frozen=True, slots=True)
class RangingSources:
    """The radio inputs of a ranging job: anchors, ranges and the ranging options.

    Attributes:
        anchors: the anchors CSV (``id,x,y,z``).
        ranges: the ranges: a CSV (``t,anchor_id,range_m``) or a bag with the topic of
            ``sensor_msgs/msg/Range`` as selector.
        config: the ranging and positioning options.
        provenance: the input records of the anchors and of the ranges.
        display_paths: shown instead of the files' paths in warnings (the service's names).
    """

    anchors: Path
    ranges: SourceSpec
    config: RangingConfig
    provenance: tuple[Mapping[str, object], ...] = ()
    display_paths: Mapping[str, str] = field(default_factory=dict)

    def read(self, *, stamp: str) -> Ranges:
        """Read the anchors and the ranges (a CSV, or a bag topic when a selector is given).

        Raises:
            ReaderError: a file cannot be read or holds no usable range.
            InputError: a bag is given without the topic of its ranges.
        """
        from loceval.errors import InputError  # noqa: PLC0415
        from loceval.readers.radio import read_anchors, read_ranges  # noqa: PLC0415
        from loceval.readers.rosbag import is_bag_path  # noqa: PLC0415

        anchors = read_anchors(self.anchors)
        spec = self.ranges
        if spec.format is TrajectoryFormat.BAG or is_bag_path(spec.path):
            if not spec.selector:
                msg = (
                    f"The ranges {spec.path.name!r} are a bag; name the topic of its "
                    "sensor_msgs/msg/Range messages as the selector (run.bag@/uwb/range)."
                )
                raise InputError(msg)
            from loceval.readers.rosbag import StampSource, read_range_topic  # noqa: PLC0415

            ranges = read_range_topic(spec.path, spec.selector, anchors, stamp=StampSource(stamp))
        else:
            ranges = read_ranges(spec.path, anchors)
        if not self.display_paths:
            return ranges
        warnings = list(ranges.warnings)
        for path, shown in self.display_paths.items():
            warnings = [w.replace(path, shown) for w in warnings]
        return replace(ranges, warnings=tuple(warnings))


@dataclass(frozen=True, slots=True, kw_only=True)
class _JobBase:
    """What every kind of job takes besides its inputs.

    Attributes:
        reference: the ground truth (a trajectory, or a control-point survey).
        config: the core's options.
        stamp: bags: ``header`` or ``receive`` stamps.
        export: artifact options; None writes no artifacts.
        formats: the artifacts to write (None: all).
    """

    reference: JobSource
    config: EvaluationConfig
    stamp: str = choice_default("stamp")
    export: ExportOptions | None = None
    formats: Sequence[str] | None = None

    def artifact_names(self) -> list[str] | None:
        """Return the files to write, ``result.json`` first (None: all)."""
        return None if self.formats is None else list(dict.fromkeys(["result.json", *self.formats]))


@dataclass(frozen=True, slots=True, kw_only=True)
class TrajectoryJob(_JobBase):
    """Estimated trajectories evaluated pose by pose against a reference trajectory.

    Attributes:
        estimates: the systems under evaluation.
        map: the robot's occupancy grid map to measure against the building plan.
        baseline: an earlier result each estimate and system is compared with.
    """

    estimates: Sequence[JobSource]
    map: MapSource | None = None
    baseline: Baseline | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class ControlPointJob(_JobBase):
    """Estimated trajectories scored at the surveyed control points they visit.

    Attributes:
        estimates: the systems under evaluation.
        visits: the visits table (or a bag's arrivals); None finds the stops.
        checkpoints: the control-point options.
    """

    estimates: Sequence[JobSource]
    visits: JobSource | None = None
    checkpoints: CheckpointConfig = field(default_factory=CheckpointConfig)


@dataclass(frozen=True, slots=True, kw_only=True)
class RangingJob(_JobBase):
    """A radio system's ranges, and the positions solved from them, against the reference.

    Attributes:
        ranging: the anchors, the ranges and the ranging options; the solvers' positions
            are the estimates (:func:`loceval.radio_evaluation.evaluate_radio`).
    """

    ranging: RangingSources


Job = TrajectoryJob | ControlPointJob | RangingJob
"""One evaluation job, of one of the three kinds; each front door builds its kind."""


def evaluation_job(
    *,
    reference: JobSource,
    estimates: Sequence[JobSource],
    config: EvaluationConfig,
    stamp: str = choice_default("stamp"),
    export: ExportOptions | None = None,
    formats: Sequence[str] | None = None,
    visits: JobSource | None = None,
    checkpoints: CheckpointConfig | None = None,
    the_map: MapSource | None = None,
    baseline: Baseline | None = None,
) -> TrajectoryJob | ControlPointJob:
    """Return the job of ``loceval evaluate`` and ``POST /evaluations``: its kind by its reference.

    A control-point survey (``points:survey.csv``, or a file sniffed as one) makes a
    :class:`ControlPointJob`; any other reference a :class:`TrajectoryJob`.

    Raises:
        InputError: an input of the other kind: a visits table beside a trajectory
            reference; a map, a baseline, trials or a tolerance beside a control-point
            survey.
    """
    if is_control_points(reference.spec):
        if baseline is not None or any(e.system for e in estimates):
            msg = (
                "Trials and a baseline compare trajectory evaluations, and the reference is "
                "a control-point survey; leave --system and --baseline out."
            )
            raise InputError(msg, option="baseline")
        if the_map is not None:
            msg = (
                "A map is measured along an evaluated trajectory, and the reference is a "
                "control-point survey; evaluate the map with a trajectory reference."
            )
            raise InputError(msg, option="map")
        if config.tolerance is not None:
            raise InputError(CONTROL_POINTS_NO_TOLERANCE, option="tolerance")
        return ControlPointJob(
            reference=reference,
            config=config,
            stamp=stamp,
            export=export,
            formats=formats,
            estimates=estimates,
            visits=visits,
            checkpoints=checkpoints or CheckpointConfig(),
        )
    if visits is not None:
        msg = (
            "A visits table applies to a control-point reference (points:FILE), and the "
            "reference is a trajectory; leave the visits out."
        )
        raise InputError(msg, option="visits")
    return TrajectoryJob(
        reference=reference,
        config=config,
        stamp=stamp,
        export=export,
        formats=formats,
        estimates=estimates,
        map=the_map,
        baseline=baseline,
    )


@overload
def run_job(
    job: TrajectoryJob | RangingJob, out_dir: Path | None, progress: ProgressCallback | None = None
) -> EvaluationResult: ...


@overload
def run_job(
    job: ControlPointJob, out_dir: Path | None, progress: ProgressCallback | None = None
) -> CheckpointEvaluation: ...


@overload
def run_job(
    job: Job, out_dir: Path | None, progress: ProgressCallback | None = None
) -> EvaluationResult | CheckpointEvaluation: ...


def run_job(
    job: Job,
    out_dir: Path | None,
    progress: ProgressCallback | None = None,
    *,
    on_artifact: ArtifactCallback | None = None,
) -> EvaluationResult | CheckpointEvaluation:
    """Read, evaluate and (with ``out_dir`` and ``job.export``) write the artifacts.

    Args:
        job: the job; its kind says how it is evaluated.
        out_dir: the artifact folder, written all or nothing; None writes nothing.
        progress: called with (stage, overall fraction done).
        on_artifact: called with the name and staged path of each artifact of a trajectory
            evaluation as soon as it is written (:func:`exporters.write_artifacts`), before
            the whole set moves into ``out_dir``.

    Returns:
        The evaluation result (a control-point job's: its scores at the points).

    Raises:
        LocevalError: bad input (reader, association, alignment, metric or export errors).
    """
    report = progress or (lambda _stage, _fraction: None)
    if isinstance(job, ControlPointJob):
        return _run_checkpoints(job, out_dir, report)
    if isinstance(job, RangingJob):
        result = _run_ranging(job, report)
    else:
        result = _run_trajectories(job, report)
    if out_dir is not None and job.export is not None:
        from exporters import write_artifacts  # noqa: PLC0415

        def writing(stage: str, fraction: float) -> None:
            report(stage, _EVALUATE + (1.0 - _EVALUATE) * fraction)

        report("preparing the files", _EVALUATE)  # placing the paths comes before any file
        title = f"{result.reference.name} vs {', '.join(_compared(result))}"
        write_artifacts(
            result,
            out_dir,
            replace(job.export, title=title),
            names=job.artifact_names(),
            progress=writing,
            on_written=on_artifact,
        )
    report("done", 1.0)
    return result


def _compared(result: EvaluationResult) -> list[str]:
    """What the evaluation compares, for its title: each system once, then other estimates."""
    systems = [f"{s.name} ({len(s.trials) + len(s.failed)} trials)" for s in result.systems]
    return systems + [e.name for e in result.estimates if e.system is None]


def _read_sources(
    sources: Sequence[JobSource], stamp: str, report: ProgressCallback
) -> list[Trajectory]:
    """Read each trajectory, reporting the reading share of the bar."""
    trajectories = []
    for k, source in enumerate(sources):
        report(f"reading {source.name}", _READ * k / len(sources))
        trajectories.append(source.read(stamp=stamp))
    return trajectories


def _run_trajectories(job: TrajectoryJob, report: ProgressCallback) -> EvaluationResult:
    """Read the reference and the estimates, evaluate, and measure the map if one is given."""
    sources = [job.reference, *job.estimates]
    (reference,) = _read_sources([job.reference], job.stamp, report)
    estimates: list[Trajectory] = []
    systems: list[str | None] = []
    failed: list[FailedTrial] = []
    for k, source in enumerate(job.estimates):
        report(f"reading {source.name}", _READ * (k + 1) / len(sources))
        if source.system is None:
            estimates.append(source.read(stamp=job.stamp))
            systems.append(None)
            continue
        try:  # a trial that cannot be read failed; the other trials go on
            estimates.append(source.read(stamp=job.stamp))
        except LocevalError as err:
            from loceval.assessment.trials import FailedTrial  # noqa: PLC0415  (trials only)

            failed.append(FailedTrial(source.name, source.system, err.code, str(err)))
            continue
        systems.append(source.system)
    result = evaluate(
        reference,
        estimates,
        job.config,
        inputs=[dict(s.provenance) for s in sources],
        progress=_evaluating(report),
        systems=systems,
        failed_trials=failed,
    )
    if job.baseline is not None:
        from loceval.results.baseline import compare_with_baseline  # noqa: PLC0415

        report("comparing with the baseline", _EVALUATE)
        result = replace(result, baseline=compare_with_baseline(result, job.baseline))
    if job.map is not None:
        from service.jobs.mapjob import measure_map  # noqa: PLC0415  (CAD libraries)

        report("measuring the map", _EVALUATE)
        result = replace(result, map=measure_map(result, job.map))
    return result


def _run_ranging(job: RangingJob, report: ProgressCallback) -> EvaluationResult:
    """Read the reference and the ranges; position the tag; evaluate ranges and positions."""
    from loceval.radio_evaluation import evaluate_radio  # noqa: PLC0415

    (reference,) = _read_sources([job.reference], job.stamp, report)
    report("reading the ranges", _READ / 2)
    return evaluate_radio(
        reference,
        job.ranging.read(stamp=job.stamp),
        job.ranging.config,
        job.config,
        inputs=[dict(job.reference.provenance), *map(dict, job.ranging.provenance)],
        progress=_evaluating(report),
    )


def _evaluating(report: ProgressCallback) -> ProgressCallback:
    """Return the progress callback of the evaluation step: its share of the bar.

    The evaluation's own last stage, ``done``, is not the job's end (the files are still to
    be written), so it is not passed on: ``done`` is reported once, at 100 %.
    """

    def evaluating(stage: str, fraction: float) -> None:
        if stage != "done":
            report(stage, _READ + (_EVALUATE - _READ) * fraction)

    return evaluating


def is_control_points(spec: SourceSpec) -> bool:
    """Return whether a source is a control-point survey (named so, or sniffed as one)."""
    if spec.format is not None:
        return spec.format is TrajectoryFormat.POINTS
    try:
        return sniff_format(spec.path) is TrajectoryFormat.POINTS
    except LocevalError:
        return False  # the trajectory reader reports the file with its own message


def _run_checkpoints(
    job: ControlPointJob, out_dir: Path | None, report: ProgressCallback
) -> CheckpointEvaluation:
    """Read the survey, the visits and the estimates; score; write the artifacts."""
    from loceval.checkpoint_evaluation import evaluate_control_points  # noqa: PLC0415
    from loceval.readers.points import read_control_points  # noqa: PLC0415

    report(f"reading {job.reference.name}", 0.0)
    points = read_control_points(job.reference.spec.path)
    if job.reference.display_path is not None:
        points = replace(points, source=f"points:{job.reference.display_path}")
    visits = None
    if job.visits is not None:
        visits = _read_visits(job.visits.spec, points, job)
    estimates = []
    for k, source in enumerate(job.estimates):
        report(f"reading {source.name}", _READ * (k + 1) / (len(job.estimates) + 1))
        estimates.append(source.read(stamp=job.stamp))
    inputs = [dict(s.provenance) for s in (job.reference, *job.estimates)]
    if job.visits is not None:
        inputs.append(dict(job.visits.provenance))

    evaluating = _evaluating(report)
    result = evaluate_control_points(
        points,
        estimates,
        job.config,
        job.checkpoints,
        visits=visits,
        reference_name=job.reference.name,
        inputs=inputs,
        progress=evaluating,
    )
    if out_dir is not None and job.export is not None:
        from exporters.checkpoints import write_checkpoint_artifacts  # noqa: PLC0415

        report("writing", _EVALUATE)
        title = f"{result.reference_name} vs {', '.join(e.name for e in result.estimates)}"
        export = replace(job.export, title=title)
        write_checkpoint_artifacts(result, out_dir, export, names=job.artifact_names())
    report("done", 1.0)
    return result


def _read_visits(spec: SourceSpec, points: ControlPoints, job: ControlPointJob) -> Visits:
    """Read a visits table, or the arrivals on a bag topic (``run.bag@/arrivals``)."""
    try:
        fmt = spec.format or sniff_format(spec.path)
    except LocevalError:
        fmt = None  # the visits reader says what is wrong with the file
    if fmt is not TrajectoryFormat.BAG:
        from loceval.readers.points import read_visits  # noqa: PLC0415

        return read_visits(spec.path, points)
    if not spec.selector:
        msg = (
            f"{spec.path.name!r} is a bag; name the topic of arrivals after '@', e.g. "
            f"{spec.path.name}@/arrivals (std_msgs/String or geometry_msgs/PointStamped)."
        )
        raise InputError(msg, option="visits")
    from loceval.readers.rosbag import StampSource  # noqa: PLC0415
    from loceval.readers.rosbag.arrivals import read_bag_arrivals  # noqa: PLC0415

    return read_bag_arrivals(
        spec.path,
        spec.selector,
        points,
        hold_s=job.checkpoints.stop_min_s,
        stamp=StampSource(job.stamp),
    )


def default_name(spec: SourceSpec) -> str:
    """Return a source's default name: its selector (bags, Motive) or the file's stem."""
    if spec.selector and spec.format in {TrajectoryFormat.BAG, TrajectoryFormat.MOTIVE, None}:
        return spec.selector
    return spec.path.stem


def unique_names(names: Sequence[str]) -> list[str]:
    """Number repeated names: ``["a", "a"] -> ["a", "a (2)"]``."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f"{name} ({seen[name]})")
    return out


def file_provenance(
    role: str, spec: SourceSpec, *, sha256: str | None = None, size: int | None = None
) -> dict[str, object]:
    """Return the input record of a source: file, format, selector, SHA-256 and size.

    With both ``sha256`` and ``size`` given the file is not looked at (a bag read where it
    is stored has no local file).
    """
    path = spec.path
    info: dict[str, object] = {
        "role": role,
        "path": str(path),
        "file": path.name,
        "format": spec.format.value if spec.format else None,
        "selector": spec.selector,
    }
    if sha256 is not None and size is not None:
        info.update(sha256=sha256, bytes=size)
    elif path.is_file():
        if sha256 is None:
            with path.open("rb") as fh:  # read into one reused buffer: no fresh memory per block
                sha256 = hashlib.file_digest(fh, "sha256").hexdigest()
        info["sha256"] = sha256
        info["bytes"] = path.stat().st_size
    return info
