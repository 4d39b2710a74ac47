"""``loceval ranging``: the ranges per anchor, and the positions solved from them, evaluated.

The parsed arguments hold the options under the table's keys, so they go to the same
builders as the API's options (:mod:`service.jobs.options`); the job is run by
:func:`service.jobs.runner.run_job` like an evaluation, with its radio inputs.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from loceval.readers import SourceSpec, TrajectoryFormat, parse_source
from service.cli.evaluate import export_options, gate_exit
from service.cli.output import emit
from service.cli.progress import terminal_progress
from service.jobs.options import (
    artifact_names,
    config_from_options,
    ranging_from_options,
)
from service.jobs.runner import (
    JobSource,
    RangingJob,
    RangingSources,
    default_name,
    file_provenance,
    run_job,
)

if TYPE_CHECKING:
    import argparse

    from loceval.radio.ranging import RangingResult

__all__ = ["format_ranging_table", "run_ranging"]


def run_ranging(args: argparse.Namespace) -> int:
    """Evaluate the ranges and the solvers' positions; print tables or JSON; write artifacts."""
    ranging = ranging_from_options(args)
    config = config_from_options(args, front_door="cli")
    export = export_options(args)
    default_format = TrajectoryFormat(args.format) if args.format else None
    ref_spec = parse_source(args.reference, default_format=default_format)
    ranges_spec = parse_source(args.ranges)
    anchors_spec = SourceSpec(None, Path(args.anchors))
    job = RangingJob(
        reference=JobSource(
            ref_spec,
            args.reference_name or default_name(ref_spec),
            file_provenance("reference", ref_spec),
        ),
        config=config,
        stamp=args.stamp,
        export=export,
        formats=artifact_names(args.formats),
        ranging=RangingSources(
            anchors=anchors_spec.path,
            ranges=ranges_spec,
            config=ranging,
            provenance=(
                file_provenance("anchors", anchors_spec),
                file_provenance("ranges", ranges_spec),
            ),
        ),
    )
    with terminal_progress(quiet=args.json) as progress:
        result = run_job(job, args.out, progress)
    if args.json:
        from exporters.cad.jsondoc import finite_json  # noqa: PLC0415

        document = result.to_dict()
        print(finite_json(document))  # noqa: T201
        return gate_exit(result, args, document=document)
    from service.cli.tables import format_tables  # noqa: PLC0415

    if result.ranging is not None:
        emit(format_ranging_table(result.ranging))
        emit("")
    emit(format_tables(result))
    if args.out is not None:
        emit(f"\nArtifacts written to {args.out}")
    return gate_exit(result, args)


def format_ranging_table(ranging: RangingResult) -> str:
    """Return the per-anchor table of the ranging errors (measured minus true), metres."""
    head = (
        f"{'anchor':<12} {'n':>7} {'bias':>8} {'std':>8} {'RMSE':>8} {'MAE':>8} "
        f"{'max|e|':>8} {'outl.':>7}"
    )
    lines = [f"Ranging errors (outliers: |error| > {ranging.outlier_threshold_m:g} m)", head]
    rows = [(a.id, a.stats) for a in ranging.anchors] + [("overall", ranging.overall)]
    lines.extend(
        f"{name[:12]:<12} {s.n:>7} {s.bias_m:>8.3f} {s.std_m:>8.3f} {s.rmse_m:>8.3f} "
        f"{s.mae_m:>8.3f} {s.max_abs_m:>8.3f} {s.outlier_share * 100:>6.1f}%"
        for name, s in rows
    )
    if ranging.unused_anchors:
        lines.append(f"never heard: {', '.join(ranging.unused_anchors)}")
    lines.extend(f"warning: {w}" for w in ranging.warnings)
    return "\n".join(lines)
