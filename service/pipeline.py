"""One evaluation job, run the same way by the CLI and by the service's queue.

:func:`run_job` reads the sources, evaluates and writes the artifacts; the option builders
turn the front doors' inputs (argparse flags, the HTTP options document) into the core's
:class:`~loceval.evaluation.EvaluationConfig` and the exporters' ``ExportOptions``, so a
value means the same thing, and fails with the same message, on both.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from loceval.alignment import AlignMethod, AlignWindow
from loceval.association import AssociationMethod
from loceval.errors import InputError
from loceval.evaluation import (
    EvaluationConfig,
    EvaluationResult,
    ProgressCallback,
    Tolerance,
    evaluate,
    parse_offset,
)
from loceval.geometry import SimilarityTransform
from loceval.metrics import RPEUnit
from loceval.readers import SourceSpec, TrajectoryFormat, read_trajectory
from loceval.trajectory import Trajectory

if TYPE_CHECKING:
    from exporters.options import ExportOptions

__all__ = [
    "Job",
    "JobSource",
    "build_config",
    "build_export_options",
    "config_from_options",
    "default_name",
    "device_offset",
    "export_from_options",
    "file_provenance",
    "offset_or_none",
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
    """

    spec: SourceSpec
    name: str
    provenance: Mapping[str, object] = field(default_factory=dict)
    display_path: str | None = None

    def read(self, *, stamp: str) -> Trajectory:
        """Read the trajectory, naming the file by ``display_path`` when given."""
        trajectory = read_trajectory(self.spec, name=self.name, stamp=stamp)
        if self.display_path is None:
            return trajectory
        path, shown = str(self.spec.path), self.display_path
        return replace(
            trajectory,
            source=trajectory.source.replace(path, shown),
            warnings=tuple(w.replace(path, shown) for w in trajectory.warnings),
        )


@dataclass(frozen=True, slots=True)
class Job:
    """Everything one evaluation needs.

    Attributes:
        reference: the ground truth.
        estimates: the systems under evaluation.
        config: the core's options.
        stamp: bags: ``header`` or ``receive`` stamps.
        export: artifact options; None writes no artifacts.
        formats: the artifacts to write (None: all).
    """

    reference: JobSource
    estimates: Sequence[JobSource]
    config: EvaluationConfig
    stamp: str = "header"
    export: ExportOptions | None = None
    formats: Sequence[str] | None = None


def run_job(
    job: Job, out_dir: Path | None, progress: ProgressCallback | None = None
) -> EvaluationResult:
    """Read, evaluate and (with ``out_dir`` and ``job.export``) write the artifacts.

    Args:
        job: the job.
        out_dir: the artifact folder, written all or nothing; None writes nothing.
        progress: called with (stage, overall fraction done).

    Returns:
        The evaluation result.

    Raises:
        LocevalError: bad input (reader, association, alignment, metric or export errors).
    """
    report = progress or (lambda _stage, _fraction: None)
    sources = [job.reference, *job.estimates]
    trajectories = []
    for k, source in enumerate(sources):
        report(f"reading {source.name}", _READ * k / len(sources))
        trajectories.append(source.read(stamp=job.stamp))

    def evaluating(stage: str, fraction: float) -> None:
        report(stage, _READ + (_EVALUATE - _READ) * fraction)

    result = evaluate(
        trajectories[0],
        trajectories[1:],
        job.config,
        inputs=[dict(s.provenance) for s in sources],
        progress=evaluating,
    )
    if out_dir is not None and job.export is not None:
        from exporters import write_artifacts  # noqa: PLC0415

        def writing(stage: str, fraction: float) -> None:
            report(stage, _EVALUATE + (1.0 - _EVALUATE) * fraction)

        title = f"{result.reference.name} vs {', '.join(e.name for e in result.estimates)}"
        names = None
        if job.formats is not None:
            names = list(dict.fromkeys(["result.json", *job.formats]))
        write_artifacts(
            result, out_dir, replace(job.export, title=title), names=names, progress=writing
        )
    report("done", 1.0)
    return result


def build_config(
    *,
    association: str = "interpolate",
    max_dt_s: float = 0.01,
    max_gap_s: float = 0.1,
    time_offset_s: float = 0.0,
    align: str = "se3",
    align_first: str | None = None,
    calibrate_at_s: float | None = None,
    reference_offset: SimilarityTransform | None = None,
    rpe_delta: float = 1.0,
    rpe_unit: str = "frames",
    rpe_all_pairs: bool = False,
    thresholds_m: Sequence[float] | None = None,
    tolerance: str | None = None,
    worst: int = 10,
) -> EvaluationConfig:
    """Return the core's options from the front doors' values (CLI defaults).

    Raises:
        InputError: a value cannot be used (the message names it).
    """
    defaults = EvaluationConfig()
    return EvaluationConfig(
        association=AssociationMethod(association),
        max_dt_s=max_dt_s,
        max_gap_s=max_gap_s,
        time_offset_s=time_offset_s,
        align=AlignMethod(align),
        align_first=AlignWindow.parse(align_first),
        calibrate_at_s=calibrate_at_s,
        reference_offset=reference_offset,
        rpe_delta=rpe_delta,
        rpe_unit=RPEUnit(rpe_unit),
        rpe_all_pairs=rpe_all_pairs,
        thresholds_m=defaults.thresholds_m if thresholds_m is None else tuple(thresholds_m),
        tolerance=Tolerance.parse(tolerance) if tolerance else None,
        worst_count=worst,
    )


def config_from_options(
    options: Mapping[str, Any], *, reference_offset: SimilarityTransform | None = None
) -> EvaluationConfig:
    """Return the core's options from an options document (``POST /evaluations``).

    Raises:
        InputError: a value cannot be used.
    """
    return build_config(
        association=options.get("association", "interpolate"),
        max_dt_s=options.get("max_dt_s", 0.01),
        max_gap_s=options.get("max_gap_s", 0.1),
        time_offset_s=options.get("time_offset_s", 0.0),
        align=options.get("align", "se3"),
        align_first=options.get("align_first"),
        calibrate_at_s=options.get("calibrate_at_s"),
        reference_offset=reference_offset,
        rpe_delta=options.get("rpe_delta", 1.0),
        rpe_unit=options.get("rpe_unit", "frames"),
        rpe_all_pairs=options.get("rpe_all_pairs", False),
        thresholds_m=options.get("thresholds_m"),
        tolerance=options.get("tolerance"),
        worst=options.get("worst", 10),
    )


def export_from_options(options: Mapping[str, Any], *, evaluation_id: str = "") -> ExportOptions:
    """Return the artifact options from an options document.

    Raises:
        InputError: a value cannot be used.
    """
    matrix = options.get("site_matrix")
    return build_export_options(
        units=options.get("units", "mm"),
        site=options.get("site"),
        site_matrix=None if matrix is None else [float(v) for row in matrix for v in row],
        simplify_m=options.get("simplify_m", 0.001),
        evaluation_id=evaluation_id,
    )


def device_offset(
    path: Path, *, from_link: str, to_link: str, offset: str | None = None
) -> SimilarityTransform:
    """Return the rigid body -> sensor offset from a URDF or from a bag's ``/tf_static``.

    Raises:
        InputError: an ``offset`` is given as well, or a link is not named.
        ReaderError: the file cannot be read or the links are not connected.
    """
    if offset:
        msg = "Give the device offset either as an offset or from a device file, not both."
        raise InputError(msg)
    if not (from_link and to_link):
        msg = (
            "A device file needs the rigid body's link and the sensor's link, e.g. "
            "from rigid_body to camera_link."
        )
        raise InputError(msg)
    if path.suffix.lower() in {".urdf", ".xml"}:
        from loceval.urdf import read_urdf_offset  # noqa: PLC0415

        return read_urdf_offset(path, from_link=from_link, to_link=to_link)
    from loceval.readers.rosbag import read_bag_static_transform  # noqa: PLC0415

    return read_bag_static_transform(path, from_link, to_link)


def offset_or_none(offset: str | None) -> SimilarityTransform | None:
    """Parse an ``"x y z qx qy qz qw"`` offset; None when not given."""
    return parse_offset(offset) if offset else None


def build_export_options(
    *,
    units: str = "mm",
    site: str | None = None,
    site_matrix: Path | Sequence[float] | None = None,
    simplify_m: float = 0.001,
    building: Path | None = None,
    evaluation_id: str = "",
) -> ExportOptions:
    """Return the artifact options, checked before the evaluation runs so bad ones fail fast.

    Raises:
        InputError: both ``site`` and ``site_matrix``, or an option's value cannot be used.
    """
    from exporters import ExportOptions  # noqa: PLC0415
    from exporters.placement import (  # noqa: PLC0415
        check_options,
        parse_site,
        parse_units,
        read_site_matrix,
        site_from_values,
    )

    if site and site_matrix is not None:
        msg = "Give the site transform either as a site or as a site matrix, not both."
        raise InputError(msg)
    transform = SimilarityTransform.identity()
    if site:
        transform = parse_site(site)
    elif isinstance(site_matrix, Path):
        transform = read_site_matrix(site_matrix)
    elif site_matrix is not None:
        transform = site_from_values(list(site_matrix), where="the site matrix")
    options = ExportOptions(
        units=parse_units(units),
        site=transform,
        simplify_m=simplify_m,
        building=building,
        evaluation_id=evaluation_id,
    )
    check_options(options)
    return options


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


def file_provenance(role: str, spec: SourceSpec, *, sha256: str | None = None) -> dict[str, object]:
    """Return the input record of a source: file, format, selector and SHA-256."""
    path = spec.path
    info: dict[str, object] = {
        "role": role,
        "path": str(path),
        "file": path.name,
        "format": spec.format.value if spec.format else None,
        "selector": spec.selector,
    }
    if path.is_file():
        if sha256 is None:
            digest = hashlib.sha256()
            with path.open("rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    digest.update(chunk)
            sha256 = digest.hexdigest()
        info["sha256"] = sha256
        info["bytes"] = path.stat().st_size
    return info
