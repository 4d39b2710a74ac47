"""The ``loceval`` command line: evaluate, inspect, demo.

A :class:`~loceval.errors.LocevalError` prints its message and exits 1 (bad input, no
traceback); anything else is a bug: the traceback is printed and the exit code is 2.
Libraries for reports and CAD files are imported only when ``--out`` asks for them.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from loceval import __version__
from loceval.alignment import AlignMethod
from loceval.association import AssociationMethod
from loceval.errors import InputError, LocevalError
from loceval.evaluation import EvaluationConfig, EvaluationResult, Tolerance
from loceval.geometry import SimilarityTransform
from loceval.metrics import DEFAULT_THRESHOLDS_M, ErrorSeries, ErrorStats, RPEUnit
from loceval.readers import SourceSpec, TrajectoryFormat, parse_source, read_trajectory
from loceval.trajectory import Trajectory
from service.pipeline import (
    Job,
    JobSource,
    build_config,
    build_export_options,
    config_from_options,
    default_name,
    device_offset,
    file_provenance,
    offset_or_none,
    run_job,
    unique_names,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from exporters.options import ExportOptions
    from service.jobs import Runtime
    from service.settings import Settings

__all__ = ["main"]

EXIT_INPUT = 1
EXIT_BUG = 2


class _Parser(argparse.ArgumentParser):
    """argparse that exits 1 on a usage error: a bad option is bad input, not a bug."""

    def error(self, message: str) -> NoReturn:
        missing = re.fullmatch(r"argument (--[\w-]+).*: expected one argument", message)
        if missing:
            # argparse takes "-1e6" or "-0.1,0.2" for an option unless glued to its flag.
            flag = missing.group(1)
            message += f"; for a value that starts with '-' write {flag}=VALUE"
        self.print_usage(sys.stderr)
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:  # noqa: PLR0915  (one flat list of flags)
    """Return the argument parser of every subcommand."""
    parser = _Parser(prog="loceval", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"loceval {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    ev = sub.add_parser(
        "evaluate",
        help="evaluate estimates against a reference",
        description=(
            "Evaluate one or more estimated trajectories against a reference. A source is "
            "[FORMAT:]PATH[@SELECTOR]: tum:gt.txt, kitti:poses.txt@times=times.txt, "
            "motive:take.csv@RigidBody, run.mcap@/amcl_pose, run.bag@tf:map:base_link."
        ),
    )
    ev.add_argument("reference", help="the ground truth source")
    ev.add_argument("estimates", nargs="+", metavar="estimate", help="estimate sources")
    ev.add_argument(
        "--name", action="append", default=[], help="estimate name, once per estimate in order"
    )
    ev.add_argument("--reference-name", default=None, help="name of the reference")
    ev.add_argument(
        "--format",
        choices=[f.value for f in TrajectoryFormat],
        default=None,
        help="format of sources without a FORMAT: prefix (default: sniffed from content)",
    )
    ev.add_argument(
        "--stamp",
        choices=["header", "receive"],
        default="header",
        help="bags: stamps from the message header (default) or the bag's receive time",
    )
    ev.add_argument(
        "--associate",
        choices=[m.value for m in AssociationMethod],
        default=AssociationMethod.INTERPOLATE.value,
    )
    ev.add_argument("--max-dt", type=float, default=0.01, metavar="S", help="nearest: max dt")
    ev.add_argument(
        "--max-gap", type=float, default=0.1, metavar="S", help="longest reference gap bridged"
    )
    ev.add_argument(
        "--time-offset", type=float, default=0.0, metavar="S", help="added to estimate stamps"
    )
    ev.add_argument(
        "--align", choices=[m.value for m in AlignMethod], default=AlignMethod.SE3.value
    )
    ev.add_argument(
        "--align-first", default=None, metavar="N|Ns", help="align on the first N poses or seconds"
    )
    ev.add_argument(
        "--calibrate-at",
        type=float,
        default=None,
        metavar="S",
        help="--align calibrate: seconds after the first matched pose",
    )
    ev.add_argument(
        "--offset",
        default=None,
        metavar='"x y z qx qy qz qw"',
        help="rigid body -> sensor offset applied to the reference",
    )
    ev.add_argument(
        "--device",
        type=Path,
        default=None,
        metavar="FILE",
        help="URDF (or a bag with /tf_static) giving the device offset",
    )
    ev.add_argument("--device-from", default=None, metavar="LINK", help="the rigid body's link")
    ev.add_argument("--device-to", default=None, metavar="LINK", help="the sensor's link")
    ev.add_argument("--rpe-delta", type=float, default=1.0, metavar="D")
    ev.add_argument("--rpe-unit", choices=[u.value for u in RPEUnit], default=RPEUnit.FRAMES.value)
    ev.add_argument("--rpe-all-pairs", action="store_true", help="every pose starts an RPE pair")
    ev.add_argument(
        "--thresholds",
        default=",".join(f"{t:g}" for t in DEFAULT_THRESHOLDS_M),
        metavar="M,M,...",
        help="distances for the share-within figures",
    )
    ev.add_argument("--tolerance", default=None, metavar="M@PCT", help="verdict, e.g. 0.10@95")
    ev.add_argument("--worst", type=int, default=10, metavar="N", help="greatest errors listed")
    ev.add_argument("--json", action="store_true", help="print the result as JSON")
    ev.add_argument("--out", type=_folder, default=None, metavar="DIR", help="write artifacts here")
    ev.add_argument(
        "--formats",
        default=None,
        metavar="NAME,...",
        help="artifacts to write with --out (default: all)",
    )
    ev.add_argument("--units", choices=["mm", "cm", "m"], default="mm", help="CAD units")
    ev.add_argument(
        "--site", default=None, metavar='"tx ty tz yaw_deg"', help="evaluation -> model frame"
    )
    ev.add_argument("--site-matrix", type=Path, default=None, metavar="FILE", help="4x4 matrix")
    ev.add_argument(
        "--simplify", type=float, default=0.001, metavar="M", help="CAD polyline tolerance"
    )
    ev.add_argument("--building", type=Path, default=None, metavar="FILE", help="mesh for glTF")
    ev.set_defaults(handler=_cmd_evaluate)

    ins = sub.add_parser("inspect", help="list what a recording holds")
    ins.add_argument("path", help="a bag, bag directory, zip, MCAP or trajectory file")
    ins.add_argument("--json", action="store_true", help="print the inspection as JSON")
    ins.set_defaults(handler=_cmd_inspect)

    demo = sub.add_parser(
        "demo", help="write a synthetic recording and evaluate it (no data needed)"
    )
    demo.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR")
    demo.set_defaults(handler=_cmd_demo)

    report = sub.add_parser(
        "report",
        help="one summary report over many recordings (as a schedule run makes it)",
        description=(
            "Evaluate each recording with the same template and write one summary report "
            "(summary.html, summary.pdf): a row per recording, a trend per system, the "
            "systems side by side, and the repeatability of the reference paths."
        ),
    )
    report.add_argument(
        "--datasets", nargs="+", required=True, type=Path, metavar="FILE", help="recordings"
    )
    report.add_argument(
        "--template",
        required=True,
        type=Path,
        metavar="FILE",
        help='JSON: {"reference": {"selector": ...}, "estimates": [...], "options": {...}}',
    )
    report.add_argument("--out", required=True, type=_folder, metavar="DIR")
    report.add_argument("--title", default="Summary report", help="the report's title")
    report.set_defaults(handler=_cmd_report)

    serve = sub.add_parser(
        "serve",
        help="start the HTTP service with its queue consumer (settings: LOCEVAL_* variables)",
    )
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on")
    serve.add_argument("--port", type=int, default=8000, help="port to listen on")
    serve.add_argument(
        "--no-consumer",
        action="store_true",
        help="do not run jobs in this process (run `loceval worker` processes instead)",
    )
    serve.set_defaults(handler=_cmd_serve)

    worker = sub.add_parser("worker", help="run queue consumers only (scale-out)")
    worker.set_defaults(handler=_cmd_worker)

    keys = sub.add_parser("keys", help="create or revoke API keys")
    keys_sub = keys.add_subparsers(dest="keys_command", required=True, parser_class=_Parser)
    create = keys_sub.add_parser("create", help="create a key and print it (shown only once)")
    create.add_argument("--project", required=True, help="the project (created if new)")
    create.set_defaults(handler=_cmd_keys_create)
    revoke = keys_sub.add_parser("revoke", help="revoke a key")
    revoke.add_argument("key", help="the key, or its first 12 characters")
    revoke.set_defaults(handler=_cmd_keys_revoke)
    return parser


def _folder(text: str) -> Path:
    """Return the --out folder; an empty name is a usage error."""
    if not text.strip():
        msg = "needs a folder name, e.g. --out results/run1"
        raise argparse.ArgumentTypeError(msg)
    return Path(text)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args))
    except LocevalError as err:
        print(f"loceval: error: {err}", file=sys.stderr)  # noqa: T201
        return EXIT_INPUT
    except KeyboardInterrupt:
        return 130
    except Exception:  # noqa: BLE001  (the documented bug path: traceback, exit 2)
        traceback.print_exc()
        print(  # noqa: T201
            "loceval: internal error; this is a bug, please report it with the traceback above.",
            file=sys.stderr,
        )
        return EXIT_BUG


# --- evaluate -------------------------------------------------------------------------


def _cmd_evaluate(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    default_format = TrajectoryFormat(args.format) if args.format else None
    if args.name and len(args.name) != len(args.estimates):
        msg = (
            f"Give --name once per estimate: {len(args.estimates)} estimates but "
            f"{len(args.name)} names."
        )
        raise InputError(msg)
    export = _export_options(args) if args.out is not None else None
    ref_spec = parse_source(args.reference, default_format=default_format)
    est_specs = [parse_source(s, default_format=default_format) for s in args.estimates]
    names = args.name or unique_names([default_name(s) for s in est_specs])
    job = Job(
        reference=JobSource(
            ref_spec,
            args.reference_name or default_name(ref_spec),
            file_provenance("reference", ref_spec),
        ),
        estimates=[
            JobSource(spec, name, file_provenance("estimate", spec))
            for spec, name in zip(est_specs, names, strict=True)
        ],
        config=config,
        stamp=args.stamp,
        export=export,
        formats=_formats(args.formats),
    )
    result = run_job(job, args.out)
    if args.json:
        print(json.dumps(result.to_dict(), indent=2, allow_nan=False))  # noqa: T201
    else:
        print(format_tables(result))  # noqa: T201
        if args.out is not None:
            print(f"\nArtifacts written to {args.out}")  # noqa: T201
    return 0


def config_from_args(args: argparse.Namespace) -> EvaluationConfig:
    """Build the evaluation options from parsed CLI arguments.

    Raises:
        InputError: an option's value cannot be used.
    """
    try:
        thresholds = [float(t) for t in args.thresholds.split(",") if t.strip()]
    except ValueError:
        msg = (
            f"--thresholds takes metres separated by commas like 0.05,0.1, got {args.thresholds!r}."
        )
        raise InputError(msg) from None
    return build_config(
        association=args.associate,
        max_dt_s=args.max_dt,
        max_gap_s=args.max_gap,
        time_offset_s=args.time_offset,
        align=args.align,
        align_first=args.align_first,
        calibrate_at_s=args.calibrate_at,
        reference_offset=_device_offset(args),
        rpe_delta=args.rpe_delta,
        rpe_unit=args.rpe_unit,
        rpe_all_pairs=args.rpe_all_pairs,
        thresholds_m=thresholds,
        tolerance=args.tolerance,
        worst=args.worst,
    )


def _device_offset(args: argparse.Namespace) -> SimilarityTransform | None:
    if args.device is None:
        if args.device_from or args.device_to:
            msg = "--device-from and --device-to need --device FILE (a URDF or a bag)."
            raise InputError(msg)
        return offset_or_none(args.offset)
    if args.offset:
        msg = "Give the device offset either with --offset or with --device, not both."
        raise InputError(msg)
    if not (args.device_from and args.device_to):
        msg = (
            "--device needs --device-from LINK (the rigid body) and --device-to LINK "
            "(the sensor), e.g. --device-from rigid_body --device-to camera_link."
        )
        raise InputError(msg)
    return device_offset(args.device, from_link=args.device_from, to_link=args.device_to)


def _export_options(args: argparse.Namespace) -> ExportOptions:
    """Check the artifact options before the evaluation runs, so bad ones fail fast."""
    if args.site and args.site_matrix:
        msg = "Give the site transform either with --site or with --site-matrix, not both."
        raise InputError(msg)
    return build_export_options(
        units=args.units,
        site=args.site,
        site_matrix=args.site_matrix,
        simplify_m=args.simplify,
        building=args.building,
        evaluation_id=args.out.resolve().name,
    )


def _formats(text: str | None) -> list[str] | None:
    if not text:
        return None
    return [n.strip() for n in text.split(",") if n.strip()]


# --- tables ---------------------------------------------------------------------------


_ROWS = (("RMSE", "rmse"), ("MEAN", "mean"), ("MEDIAN", "median"), ("STD", "std"),
         ("MIN", "min"), ("MAX", "max"))  # fmt: skip


def format_tables(result: EvaluationResult) -> str:
    """Return the framework paper's Tables 1-2 layout: one column per estimate."""
    ref = result.reference
    head = f"Reference {ref.name!r}: {len(ref)} poses, {ref.duration_s:.1f} s, "
    lines = [head + f"{ref.length_m:.1f} m ({ref.source})"]
    for e in result.estimates:
        scale = e.alignment.transform
        lines.append(
            f"  {e.name}: {len(e.association)} of {len(e.estimate)} poses matched, "
            f"aligned {e.alignment.method.value}"
            + ("" if scale.is_rigid else f" (scale {scale.scale:.4f})")
        )
    for title, stats, unit in _sections(result):
        lines += ["", title, _row("error metric", [e.name for e in result.estimates])]
        for label, key in _ROWS:
            cells = ["-" if s is None else f"{getattr(s, key):.3f} {unit}" for s in stats]
            lines.append(_row(label, cells))
    lines += ["", "Share of poses within (ATE)"]
    for t in result.config.thresholds_m:
        shares = [f"{e.within[t] * 100:.1f} %" for e in result.estimates]
        lines.append(_row(f"<= {t:g} m", shares))
    drifts = [_stats(e.drift) for e in result.estimates]
    if any(d is not None for d in drifts):
        cells = ["-" if d is None else f"{d.mean:.2f} %" for d in drifts]
        lines.append(_row("drift (mean)", cells))
    lines += [f"\n{e.name}: {e.verdict.summary}" for e in result.estimates if e.verdict]
    warnings = [("reference", w) for w in result.reference_warnings] + [
        (e.name, w) for e in result.estimates for w in e.warnings
    ]
    if warnings:
        lines += ["", "Warnings", *(f"  {who}: {w}" for who, w in warnings)]
    return "\n".join(lines)


def _sections(result: EvaluationResult) -> list[tuple[str, list[ErrorStats | None], str]]:
    est = result.estimates
    cfg = result.config
    sections: list[tuple[str, list[ErrorStats | None], str]] = [
        ("Absolute Trajectory Error (ATE)", [e.ate_translation.stats for e in est], "m")
    ]
    if any(e.ate_rotation is not None for e in est):
        sections.append(("ATE rotation", [_stats(e.ate_rotation) for e in est], "deg"))
    unit = cfg.rpe_unit.value
    if cfg.rpe_unit is RPEUnit.FRAMES and cfg.rpe_delta == 1:
        unit = "frame"
    rpe_title = f"Relative Pose Error (RPE, delta {cfg.rpe_delta:g} {unit})"
    sections.append((rpe_title, [e.rpe_translation.stats for e in est], "m"))
    if any(e.rpe_rotation is not None for e in est):
        sections.append(("RPE rotation", [_stats(e.rpe_rotation) for e in est], "deg"))
    return sections


def _stats(series: ErrorSeries | None) -> ErrorStats | None:
    return None if series is None else series.stats


def _row(label: str, cells: Sequence[str]) -> str:
    return f"{label:<14}" + "".join(f"{c:>16}" for c in cells)


# --- inspect --------------------------------------------------------------------------


def _cmd_inspect(args: argparse.Namespace) -> int:
    spec = parse_source(args.path)
    from loceval.readers import sniff_format  # noqa: PLC0415

    fmt = sniff_format(spec.path)
    if fmt is TrajectoryFormat.BAG:
        from loceval.inspection import format_inspection, inspect_recording  # noqa: PLC0415

        inspection = inspect_recording(spec.path)
        if args.json:
            print(json.dumps(inspection.to_dict(), indent=2))  # noqa: T201
        else:
            print(format_inspection(inspection))  # noqa: T201
        return 0
    trajectory = read_trajectory(spec)
    summary = _trajectory_summary(trajectory, fmt)
    if args.json:
        print(json.dumps(summary, indent=2))  # noqa: T201
    else:
        for key, value in summary.items():
            print(f"{key:>14}: {value}")  # noqa: T201
    return 0


def _trajectory_summary(trajectory: Trajectory, fmt: TrajectoryFormat) -> dict[str, object]:
    return {
        "format": fmt.value,
        "source": trajectory.source,
        "poses": len(trajectory),
        "start_s": int(trajectory.stamps_ns[0]) / 1e9,
        "end_s": int(trajectory.stamps_ns[-1]) / 1e9,
        "duration_s": trajectory.duration_s,
        "length_m": trajectory.length_m,
        "rate_hz": trajectory.rate_hz,
        "orientation": trajectory.has_orientation,
        "warnings": list(trajectory.warnings),
    }


# --- demo -----------------------------------------------------------------------------


def _cmd_demo(args: argparse.Namespace) -> int:
    from service.demo import write_demo_recording  # noqa: PLC0415

    try:
        inputs = write_demo_recording(args.out / "inputs")
    except OSError as err:
        msg = f"Cannot write the demo into {str(args.out)!r} ({err.strerror}); name a folder."
        raise InputError(msg) from err
    argv = [
        "evaluate",
        str(inputs["reference"]),
        str(inputs["RTAB-Map"]),
        str(inputs["ISAAC"]),
        "--name",
        "RTAB-Map",
        "--name",
        "ISAAC",
        "--reference-name",
        "OptiTrack",
        "--tolerance",
        "0.10@95",
        "--out",
        str(args.out / "evaluation"),
    ]
    return main(argv)


# --- report -----------------------------------------------------------------------------


def _cmd_report(args: argparse.Namespace) -> int:
    import datetime as dt  # noqa: PLC0415

    from exporters.summary import SummaryInput, SummaryRun, render_summary  # noqa: PLC0415

    template = _read_template(args.template)
    options = template["options"]
    config = config_from_options(options, reference_offset=offset_or_none(options.get("offset")))
    runs = []
    for path in args.datasets:
        recorded = (
            dt.datetime.fromtimestamp(path.stat().st_mtime, dt.UTC)
            if path.exists()
            else (dt.datetime.now(dt.UTC))
        )
        job = _template_job(path, template, config)
        try:
            result = run_job(job, None)
        except LocevalError as err:
            runs.append(SummaryRun(path.name, recorded, "failed", error=str(err)))
            continue
        runs.append(
            SummaryRun.from_result(
                result.to_dict(),
                dataset=path.name,
                recorded_at=recorded,
                reference_xyz=result.reference.positions_xyz,
            )
        )
    tolerance = options.get("tolerance")
    summary = SummaryInput(
        title=args.title,
        generated_at=dt.datetime.now(dt.UTC),
        selection=f"the {len(args.datasets)} recordings named on the command line",
        runs=runs,
        tolerance=Tolerance.parse(tolerance) if tolerance else None,
    )
    from service.settings import Settings  # noqa: PLC0415

    html, pdf = render_summary(summary, templates_dir=Settings().templates_dir)
    _write_all(args.out, {"summary.html": html, "summary.pdf": pdf})
    for run in runs:
        figures = ", ".join(
            f"{name} ATE {fig.ate_rmse_m:.3f} m" if fig.ate_rmse_m is not None else name
            for name, fig in run.systems.items()
        )
        print(f"{run.dataset}: {run.status}" + (f" ({run.error})" if run.error else f", {figures}"))  # noqa: T201
    print(f"\nSummary written to {args.out}")  # noqa: T201
    return 0


def _read_template(path: Path) -> dict[str, Any]:
    from pydantic import ValidationError  # noqa: PLC0415

    from service.schemas import EvaluationTemplate  # noqa: PLC0415

    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"Cannot read the template {str(path)!r} ({err}); check the path."
        raise InputError(msg) from err
    try:
        template = EvaluationTemplate.model_validate_json(text)
    except ValidationError as err:
        where = "; ".join(
            f"{'.'.join(str(p) for p in e['loc']) or 'template'}: {e['msg']}"
            for e in err.errors()[:5]
        )
        msg = f"The template {str(path)!r} is not valid: {where}."
        raise InputError(msg) from None
    return template.model_dump(mode="json")


def _template_job(path: Path, template: dict[str, Any], config: EvaluationConfig) -> Job:
    def source(entry: dict[str, Any], role: str) -> JobSource:
        spec = SourceSpec(None, path, entry.get("selector"))
        name = entry.get("name") or default_name(spec)
        return JobSource(spec, name, file_provenance(role, spec))

    return Job(
        reference=source(template["reference"], "reference"),
        estimates=[source(e, "estimate") for e in template["estimates"]],
        config=config,
        stamp=template["options"].get("stamp", "header"),
    )


def _write_all(out: Path, files: dict[str, bytes]) -> None:
    """Write the files into ``out`` through temporary names: each appears whole or not at all."""
    try:
        out.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            partial = out / f".{name}.partial"
            partial.write_bytes(data)
            partial.replace(out / name)
    except OSError as err:
        msg = f"Cannot write into {str(out)!r} ({err.strerror}); name a folder you can write to."
        raise InputError(msg) from err


# --- service ----------------------------------------------------------------------------


def _cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn  # noqa: PLC0415

    from service.auth import bootstrap  # noqa: PLC0415
    from service.jobs import create_runtime  # noqa: PLC0415
    from service.main import create_app  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    settings = _settings(get_settings)
    runtime = _open_runtime(create_runtime, settings)
    with runtime.sessions() as session:
        key = bootstrap(session)
    if key is not None:
        print(f"API key for project 'default' (shown once): {key}", flush=True)  # noqa: T201
    app = create_app(settings, runtime=runtime, consumer=not args.no_consumer)
    print(  # noqa: T201
        f"loceval {__version__}: http://{args.host}:{args.port}/ (data in "
        f"{settings.data_dir.resolve()}, queue {settings.queue_url})",
        flush=True,
    )
    uvicorn.run(app, host=args.host, port=args.port, log_level="info", access_log=False)
    return 0


def _cmd_worker(_args: argparse.Namespace) -> int:
    import signal  # noqa: PLC0415
    import threading  # noqa: PLC0415

    from service.jobs import create_runtime, recover  # noqa: PLC0415
    from service.schedules import tick  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    settings = _settings(get_settings)
    runtime = _open_runtime(create_runtime, settings)
    if settings.queue_url == "immediate":
        msg = "LOCEVAL_QUEUE_URL=immediate runs jobs inside requests; a worker needs a queue."
        raise InputError(msg)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    consumer = runtime.start_consumer()
    recover(runtime)
    tick(runtime)
    print(  # noqa: T201
        f"loceval worker: {settings.workers} threads on queue {settings.queue_url}", flush=True
    )
    stop.wait()
    runtime.stop_consumer(consumer)
    runtime.close()
    return 0


def _cmd_keys_create(args: argparse.Namespace) -> int:
    from service.auth import create_key  # noqa: PLC0415
    from service.jobs import create_runtime  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    runtime = _open_runtime(create_runtime, _settings(get_settings))
    with runtime.sessions() as session:
        print(create_key(session, args.project))  # noqa: T201
    runtime.close()
    return 0


def _cmd_keys_revoke(args: argparse.Namespace) -> int:
    from service.auth import revoke_key  # noqa: PLC0415
    from service.jobs import create_runtime  # noqa: PLC0415
    from service.settings import get_settings  # noqa: PLC0415

    runtime = _open_runtime(create_runtime, _settings(get_settings))
    with runtime.sessions() as session:
        revoke_key(session, args.key)
    runtime.close()
    print("Key revoked.")  # noqa: T201
    return 0


def _settings(get: Callable[[], Settings]) -> Settings:
    from pydantic import ValidationError  # noqa: PLC0415

    try:
        return get()
    except ValidationError as err:
        problems = "; ".join(
            f"LOCEVAL_{'_'.join(str(p) for p in e['loc']).upper()}: {e['msg']}"
            for e in err.errors()
        )
        msg = f"Bad service settings: {problems}."
        raise InputError(msg) from None


def _open_runtime(create: Callable[[Settings], Runtime], settings: Settings) -> Runtime:
    from sqlalchemy.exc import SQLAlchemyError  # noqa: PLC0415

    try:
        return create(settings)
    except SQLAlchemyError as err:
        msg = (
            f"Cannot open the database {settings.resolved_database_url!r} "
            f"({type(err).__name__}: {str(err).splitlines()[0]}); check LOCEVAL_DATABASE_URL."
        )
        raise InputError(msg) from err
    except OSError as err:
        msg = (
            f"Cannot use the data directory {str(settings.data_dir)!r} ({err.strerror}); "
            "check LOCEVAL_DATA_DIR."
        )
        raise InputError(msg) from err


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
