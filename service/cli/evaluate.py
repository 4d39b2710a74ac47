"""``loceval evaluate`` and ``loceval demo``: read, evaluate, print, write the artifacts.

The parsed arguments hold the options under the table's keys, so they go to the same
builders as the API's options (:mod:`service.jobs.options`).
"""

from __future__ import annotations

import sys
from collections.abc import Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING

from loceval.errors import InputError
from loceval.evaluation import EvaluationResult
from loceval.readers import TrajectoryFormat, parse_source
from service.cli.output import emit
from service.cli.parser import EXIT_GATE, check_names, systems_of
from service.cli.progress import terminal_progress
from service.jobs.mapjob import map_source
from service.jobs.options import (
    artifact_names,
    check_device_choice,
    checkpoints_from_options,
    config_from_options,
    device_offset,
    export_from_options,
    fail_on_from_options,
    is_auto,
)
from service.jobs.runner import (
    JobSource,
    default_name,
    evaluation_job,
    file_provenance,
    run_job,
    unique_names,
)

if TYPE_CHECKING:
    import argparse

    from exporters.options import ExportOptions
    from loceval.assessment.baseline import Baseline
    from loceval.checkpoint_evaluation import CheckpointEvaluation
    from loceval.core.geometry import SimilarityTransform
    from loceval.readers import SourceSpec

__all__ = ["export_options", "gate_exit", "run_demo", "run_evaluate"]


def export_options(args: argparse.Namespace) -> ExportOptions | None:
    """Return the export options of a command writing into ``--out`` (None without it).

    The folder's name is the evaluation id the artifacts carry.
    """
    if args.out is None:
        return None
    return export_from_options(
        args,
        front_door="cli",
        evaluation_id=args.out.resolve().name,
        building=args.building,
    )


def run_evaluate(args: argparse.Namespace) -> int:
    """Evaluate the estimates against the reference; print tables or JSON; write artifacts."""
    config = config_from_options(args, front_door="cli", device_transform=_device_file_offset(args))
    default_format = TrajectoryFormat(args.format) if args.format else None
    check_names(args)
    systems = systems_of(args)
    export = export_options(args)
    plan = export
    if args.map is not None and plan is None:  # --json without --out still needs the plan
        plan = export_from_options(args, front_door="cli", building=args.building)
    the_map = map_source(args.map, plan, estimate=args.map_estimate, clutter_m=args.clutter_m)
    ref_spec = parse_source(args.reference, default_format=default_format)
    est_specs = [parse_source(s, default_format=default_format) for s in args.estimates]
    names = args.name or unique_names([default_name(s) for s in est_specs])
    # The checksums are computed in a thread while the files are read (hashlib and file
    # reads release the GIL); the evaluation reads the records after the files.
    with (
        ThreadPoolExecutor(max_workers=1) as hashing,
        terminal_progress(quiet=args.json) as progress,
    ):

        def provenance(role: str, spec: SourceSpec) -> Mapping[str, object]:
            return _PendingProvenance(hashing.submit(file_provenance, role, spec))

        job = evaluation_job(
            reference=JobSource(
                ref_spec,
                args.reference_name or default_name(ref_spec),
                provenance("reference", ref_spec),
            ),
            estimates=[
                JobSource(spec, name, provenance("estimate", spec), system=system)
                for spec, name, system in zip(est_specs, names, systems, strict=True)
            ],
            config=config,
            stamp=args.stamp,
            export=export,
            formats=artifact_names(args.formats),
            visits=_visits_source(args.visits),
            checkpoints=checkpoints_from_options(args),
            the_map=the_map,
            baseline=_baseline(args),
        )
        result = run_job(job, args.out, progress)
    if isinstance(result, EvaluationResult) and args.building is not None:
        from exporters.cad.spaces import placed_on_building  # noqa: PLC0415  (CAD libraries)

        # the stretches' rooms and the building's warnings, as result.json has them
        placed = export or export_from_options(args, front_door="cli", building=args.building)
        result = placed_on_building(result, placed)
    document = None
    if args.json:
        from exporters.cad.jsondoc import finite_json  # noqa: PLC0415

        document = result.to_dict()
        print(finite_json(document))  # noqa: T201
    elif isinstance(result, EvaluationResult):
        from service.cli.tables import format_tables  # noqa: PLC0415

        emit(format_tables(result))
    else:
        from service.cli.tables import format_checkpoint_tables  # noqa: PLC0415

        emit(format_checkpoint_tables(result))
    if not args.json and args.out is not None:
        emit(f"\nArtifacts written to {args.out}")
    return gate_exit(result, args, document=document)


def gate_exit(
    result: EvaluationResult | CheckpointEvaluation,
    args: argparse.Namespace,
    *,
    document: Mapping[str, object] | None = None,
) -> int:
    """Judge the gate of ``--fail-on``, print its line last, and return the exit code.

    The code is 0, or :data:`~service.cli.parser.EXIT_GATE` (3) when a condition holds;
    without ``--fail-on`` nothing is printed. The line goes to stdout after the tables, and
    to stderr with ``--json`` (stdout then holds only the document).

    Args:
        result: the evaluation.
        args: the parsed arguments (``fail_on``, ``json``).
        document: ``result.to_dict()`` when it is already made.
    """
    if not fail_on_from_options(args):
        return 0
    return document_gate_exit(document or result.to_dict(), args)


def document_gate_exit(document: Mapping[str, object], args: argparse.Namespace) -> int:
    """Judge ``--fail-on`` on a result document (``loceval submit``'s too); as :func:`gate_exit`."""
    fail_on = fail_on_from_options(args)
    if not fail_on:
        return 0
    from loceval.results.document import read_result  # noqa: PLC0415
    from loceval.results.gate import judge_gate  # noqa: PLC0415

    gate = judge_gate(read_result(document), fail_on)
    sys.stdout.flush()  # the line comes last, after everything printed before it
    emit(gate.line(), file=sys.stderr if args.json else None)
    return 0 if gate.passed else EXIT_GATE


def _baseline(args: argparse.Namespace) -> Baseline | None:
    """Return the baseline ``--baseline`` names, read (None without one)."""
    if args.baseline is None:
        return None
    from service.jobs.baseline import read_baseline  # noqa: PLC0415

    return read_baseline(args.baseline)


class _PendingProvenance(Mapping[str, object]):
    """A source's input record whose checksum is still being computed in a thread.

    Reading it waits for the record (and raises what computing it raised).
    """

    def __init__(self, future: Future[dict[str, object]]) -> None:
        self._future = future

    def __getitem__(self, key: str) -> object:
        return self._future.result()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._future.result())

    def __len__(self) -> int:
        return len(self._future.result())


def _visits_source(visits: str) -> JobSource | None:
    """Return the visits table named by ``--visits`` (None for ``auto``: find the stops)."""
    if visits.strip().lower() == "auto":
        return None
    spec = parse_source(visits)  # a table, or a bag topic of arrivals: run.bag@/arrivals
    return JobSource(spec, spec.path.stem, file_provenance("visits", spec))


def _device_file_offset(args: argparse.Namespace) -> SimilarityTransform | None:
    """Return the offset read from ``--device FILE`` between its two links (None without one).

    The CLI's own rules of ``--device-from`` and ``--device-to``; that ``--offset`` is not
    given too is :func:`~service.jobs.options.check_device_choice`'s, checked first.
    """
    check_device_choice(vars(args), front_door="cli")
    if is_auto(args.device):
        if args.device_from or args.device_to:
            msg = "--device auto estimates the offset; --device-from and --device-to need a file."
            raise InputError(msg)
        return None
    if args.device is None:
        if args.device_from or args.device_to:
            msg = "--device-from and --device-to need --device FILE (a URDF or a bag)."
            raise InputError(msg)
        return None
    if not (args.device_from and args.device_to):
        msg = (
            "--device needs --device-from LINK (the rigid body) and --device-to LINK "
            "(the sensor), e.g. --device-from rigid_body --device-to camera_link."
        )
        raise InputError(msg)
    return device_offset(args.device, from_link=args.device_from, to_link=args.device_to)


def run_demo(args: argparse.Namespace) -> int:
    """Write a synthetic recording and evaluate it as ``loceval evaluate`` would."""
    from service.cli import main  # noqa: PLC0415
    from service.cli.demo import write_demo_recording  # noqa: PLC0415

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
