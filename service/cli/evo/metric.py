"""``loceval ape`` and ``loceval rpe``: evo's command lines run on loceval's pipeline.

The format word and its arguments become loceval sources, evo's flags the options of
:class:`~loceval.evaluation.EvaluationConfig` (nearest stamp within ``--t_max_diff``,
``--t_offset``, the alignment and its window), and :func:`loceval.evaluation.evaluate`
matches, aligns and assesses. The pose relation's errors are then measured by
:mod:`loceval.relations` on the matched, aligned poses, the RPE pairs chosen by
:func:`loceval.relations.evo_pairs`. The figures are printed as evo prints them, followed
by loceval's 95 % intervals and notes.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from loceval.errors import InputError
from loceval.evaluation import EvaluationConfig, evaluate
from loceval.metrics.relations import (
    PoseRelation,
    ape_series,
    evo_pairs,
    rpe_series,
    scale_only,
)
from loceval.readers import SourceSpec, TrajectoryFormat, keeping_duplicate_stamps
from loceval.registration.alignment import AlignMethod, AlignWindow
from loceval.registration.association import AssociationMethod
from loceval.registration.stamps import match_nearest_seconds
from service.cli.evo.runs import EvoRun
from service.cli.output import emit
from service.jobs.runner import JobSource, file_provenance

if TYPE_CHECKING:
    import argparse

    from loceval.core.arrays import IntArray
    from loceval.evaluation import EstimateResult
    from loceval.trajectory import Trajectory

__all__ = ["run_ape", "run_rpe"]

_NS_PER_S = 1_000_000_000

_RELATION_TITLES = {
    PoseRelation.TRANS_PART: "translation part (m)",
    PoseRelation.ROT_PART: "rotation part (unit-less)",
    PoseRelation.ANGLE_DEG: "rotation angle in degrees (deg)",
    PoseRelation.ANGLE_RAD: "rotation angle in radians (rad)",
    PoseRelation.FULL: "full transformation (unit-less)",
    PoseRelation.POINT_DISTANCE: "point distance (m)",
}
"""evo's words for the relations in the title of its statistics."""

_DELTA_WORDS = {"f": "frames", "d": "deg", "r": "rad", "m": "m"}

STAT_ORDER = ("max", "mean", "median", "min", "rmse", "sse", "std")
"""The statistics evo prints, in its order."""


def run_ape(args: argparse.Namespace) -> int:
    """``loceval ape FORMAT REF EST [evo flags]``."""
    return _report(_run(args, rpe=False), args)


def run_rpe(args: argparse.Namespace) -> int:
    """``loceval rpe FORMAT REF EST [evo flags]``."""
    return _report(_run(args, rpe=True), args)


def _sources(args: argparse.Namespace) -> tuple[JobSource, JobSource]:
    """Return the reference and the estimate named by the format word and its arguments."""
    fmt = args.evo_format
    if fmt in {"bag", "bag2", "mcap"}:
        path = Path(args.bag)
        refs = (args.ref_topic, args.est_topic)
        specs = [SourceSpec(TrajectoryFormat.BAG, path, _selector(topic)) for topic in refs]
        names = list(refs)
    else:
        formats = {
            "tum": (TrajectoryFormat.TUM, TrajectoryFormat.TUM),
            "kitti": (TrajectoryFormat.KITTI, TrajectoryFormat.KITTI),
            # evo's euroc: the ground truth CSV of the dataset and an estimate in TUM format.
            "euroc": (TrajectoryFormat.EUROC, TrajectoryFormat.TUM),
        }[fmt]
        paths = (Path(args.ref_file), Path(args.est_file))
        specs = [SourceSpec(f, p) for f, p in zip(formats, paths, strict=True)]
        names = [p.name for p in paths]  # the reports' names; evo's zips keep the paths
    return (
        JobSource(specs[0], names[0], file_provenance("reference", specs[0])),
        JobSource(specs[1], names[1], file_provenance("estimate", specs[1])),
    )


def _evo_names(args: argparse.Namespace) -> tuple[str, str]:
    """Return the names evo gives the two trajectories: the topics, or the paths as given."""
    if args.evo_format in {"bag", "bag2", "mcap"}:
        return args.ref_topic, args.est_topic
    return args.ref_file, args.est_file


def _selector(topic: str) -> str:
    """Return loceval's selector of evo's topic: ``/tf:map.base_link`` is ``tf:map:base_link``."""
    head, colon, frames = topic.partition(":")
    if colon and head.strip("/") == "tf" and "." in frames:
        parent, _, child = frames.partition(".")
        return f"tf:{parent}:{child}"
    return topic


def _window(trajectory: Trajectory, start_s: float | None, end_s: float | None) -> Trajectory:
    """Keep the poses stamped within ``[start_s, end_s]`` (evo's --t_start, --t_end)."""
    if start_s is None and end_s is None:
        return trajectory
    seconds = trajectory.stamps_ns / _NS_PER_S
    keep = (seconds >= (start_s if start_s is not None else -float("inf"))) & (
        seconds <= (end_s if end_s is not None else float("inf"))
    )
    if int(keep.sum()) < 3:
        msg = (
            f"--t_start/--t_end keep {int(keep.sum())} poses of {trajectory.name!r} "
            f"(it spans {seconds[0]:.3f} to {seconds[-1]:.3f} s); widen the window."
        )
        raise InputError(msg)
    return trajectory.select(keep)


def _alignment(args: argparse.Namespace) -> tuple[AlignMethod, str]:
    """Return the core's alignment method for evo's flags and evo's words for it."""
    if args.align_origin and args.align:
        msg = "-a/--align and --align_origin exclude each other (as in evo); give one."
        raise InputError(msg)
    if args.sync_method != "nearest_time":
        msg = (
            f"--sync_method {args.sync_method} is not supported by loceval ape/rpe: they match "
            "the nearest stamps (nearest_time); loceval evaluate interpolates the reference "
            "at the estimate's stamps (--associate interpolate)."
        )
        raise InputError(msg)
    if args.align_origin:
        return AlignMethod.ORIGIN, "(with origin alignment)"
    if args.align and args.correct_scale:
        return AlignMethod.SIM3, "(with Sim(3) Umeyama alignment)"
    if args.align:
        return AlignMethod.SE3, "(with SE(3) Umeyama alignment)"
    if args.correct_scale:
        return AlignMethod.NONE, "(scale corrected)"
    return AlignMethod.NONE, "(not aligned)"


def _config(args: argparse.Namespace, method: AlignMethod) -> EvaluationConfig:
    n_to_align = int(args.n_to_align)
    if n_to_align == 0 or n_to_align < -1:
        msg = f"--n_to_align takes a number of poses (at least 1, or -1 for all), got {n_to_align}."
        raise InputError(msg)
    window = AlignWindow(poses=n_to_align) if n_to_align > 0 else AlignWindow()
    if method is AlignMethod.NONE or method is AlignMethod.ORIGIN:
        window = AlignWindow()
    if not args.t_max_diff > 0:
        msg = f"--t_max_diff must be a positive number of seconds, got {args.t_max_diff!r}."
        raise InputError(msg)
    # The poses are matched before (evo's way) and carry the same stamps once the time
    # offset is added: the core's nearest matching then pairs them as they are.
    return EvaluationConfig(
        association=AssociationMethod.NEAREST,
        max_dt_s=args.t_max_diff,
        time_offset_s=args.t_offset,
        align=method,
        align_first=window,
    )


def _matched(
    reference: Trajectory, estimate: Trajectory, args: argparse.Namespace
) -> tuple[Trajectory, Trajectory, str]:
    """Match the poses as evo does; return them stamped alike, and a note on the unmatched."""
    ref_idx, est_idx = match_nearest_seconds(
        reference.stamps_ns, estimate.stamps_ns, max_dt_s=args.t_max_diff, offset_s=args.t_offset
    )
    if est_idx.size < 3:
        msg = (
            f"Only {est_idx.size} of {len(estimate)} poses of {estimate.name!r} have a pose of "
            f"{reference.name!r} within --t_max_diff {args.t_max_diff:g} s (with --t_offset "
            f"{args.t_offset:g} s); check that both record the same run in the same clock, "
            "or give --t_offset."
        )
        raise InputError(msg)
    # The shorter side's poses are matched once each: its stamps stamp both, the
    # estimate's without the time offset (the core adds it again).
    by_estimate = len(reference) >= len(estimate)
    offset_ns = round(args.t_offset * _NS_PER_S)
    stamps = estimate.stamps_ns[est_idx] if by_estimate else reference.stamps_ns[ref_idx]
    if not by_estimate:
        stamps = stamps - offset_ns

    def picked(trajectory: Trajectory, index: IntArray, shift_ns: int) -> Trajectory:
        quats = trajectory.quat_xyzw
        return replace(
            trajectory,
            stamps_ns=stamps + shift_ns,
            positions_xyz=trajectory.positions_xyz[index],
            quat_xyzw=None if quats is None else quats[index],
            cov6=None if trajectory.cov6 is None else trajectory.cov6[index],
            warnings=(),
        )

    ref, est = picked(reference, ref_idx, offset_ns), picked(estimate, est_idx, 0)
    shorter, side = (estimate, "estimate") if by_estimate else (reference, "reference")
    unmatched = len(shorter) - est_idx.size
    note = ""
    if unmatched:
        other = "reference" if by_estimate else "estimate"
        note = (
            f"{unmatched} of {len(shorter)} {side} poses have no {other} pose within "
            f"{args.t_max_diff:g} s and were not evaluated."
        )
    return ref, est, note


def _gap_notes(reference: Trajectory) -> list[str]:
    """Return the note on the reference's tracking losses (gaps over 0.1 s), if any."""
    gaps = reference.tracking_losses(_NS_PER_S // 10)
    if not gaps:
        return []
    longest = max(b - a for a, b in gaps) / _NS_PER_S
    note = (
        f"The reference has {len(gaps)} {'gap' if len(gaps) == 1 else 'gaps'} longer than "
        f"0.1 s (tracking loss; longest {longest:.3f} s); estimate poses in them have no "
        "reference pose to match."
    )
    return [note]


def _offsets_of_full(
    found: EstimateResult,
    reference: Trajectory,
    estimate: Trajectory,
    args: argparse.Namespace,
    method: AlignMethod,
) -> EstimateResult:
    """Check the time offset on the whole recordings, not on the matched poses only.

    The core saw the poses evo's way of matching kept; the clock check needs the motion
    of both recordings, so it runs again on them and its notes replace the core's.
    """
    from loceval.calibration.offsets import check_offsets  # noqa: PLC0415  (scipy)

    full = check_offsets(
        reference,
        estimate,
        time_offset_s=args.t_offset,
        max_gap_s=0.1,
        with_scale=method is AlignMethod.SIM3 or bool(args.correct_scale),
    )
    dropped = set(() if found.offsets is None else found.offsets.warnings)
    kept = [w for w in found.warnings if w not in dropped]
    return replace(found, warnings=(*kept, *full.warnings), offsets=full)


def _run(args: argparse.Namespace, *, rpe: bool) -> EvoRun:
    relation = PoseRelation(args.pose_relation)
    ref_source, est_source = _sources(args)
    method, words = _alignment(args)
    config = _config(args, method)
    # evo's --t_start/--t_end select reference poses; estimate poses match them within
    # --t_max_diff (so one may lie just outside the window).
    with keeping_duplicate_stamps():  # evo keeps a pose whose stamp repeats; so do its commands
        reference = _window(ref_source.read(stamp="header"), args.t_start, args.t_end)
        estimate = est_source.read(stamp="header")
    matched_ref, matched_est, note = _matched(reference, estimate, args)
    if args.correct_scale and not args.align and not args.align_origin:
        matched_est = scale_only(matched_ref, matched_est, poses=config.align_first.poses)
    inputs = [dict(ref_source.provenance), dict(est_source.provenance)]
    result = evaluate(matched_ref, [matched_est], config, inputs=inputs)
    notes = [
        *reference.warnings,
        *estimate.warnings,
        *([note] if note else []),
        *_gap_notes(reference),
    ]
    # The core saw the matched poses only: its gaps are the estimate's; the full
    # reference's are named above.
    kept = [w for w in result.reference_warnings if not w.startswith("The reference has")]
    result = replace(result, reference_warnings=(*notes, *kept))
    found = _offsets_of_full(result.estimates[0], reference, estimate, args, method)
    result = replace(result, estimates=(found,))
    ref, est = found.reference, found.aligned
    ref_name, est_name = _evo_names(args)
    info: dict[str, object] = {"ref_name": ref_name, "est_name": est_name}
    pairs = None
    if rpe:
        pairs = evo_pairs(
            ref,
            est,
            delta=args.delta,
            unit=args.delta_unit,
            all_pairs=args.all_pairs,
            tolerance=args.delta_tol,
            from_reference=args.pairs_from_reference,
        )
        series = rpe_series(ref, est, relation, pairs)
        shown = f"{int(args.delta)}" if args.delta_unit == "f" else f"{args.delta!r}"
        delta = f"{shown} ({_DELTA_WORDS[args.delta_unit]})"
        pair_words = " using all pairs" if args.all_pairs else " using consecutive pairs"
        title = f"RPE w.r.t. {_RELATION_TITLES[relation]}\nfor delta = {delta}{pair_words}"
        info.update(delta=args.delta, delta_unit=args.delta_unit, all_pairs=args.all_pairs)
    else:
        series = ape_series(ref, est, relation)
        title = f"APE w.r.t. {_RELATION_TITLES[relation]}"
    if config.align_first.poses is not None and method is not AlignMethod.NONE:
        words += f" (aligned poses: {config.align_first.poses})"
    info.update(title=title, pose_relation=relation.value, label=_label(relation, rpe=rpe))
    return EvoRun(
        metric="rpe" if rpe else "ape",
        title=title,
        alignment_words=words,
        series=series,
        relation=relation,
        result=result,
        ref_name=ref_name,
        est_name=est_name,
        reference=ref,
        estimate=est,
        info=info,
        pairs=pairs,
        estimate_poses=len(estimate),
    )


def _label(relation: PoseRelation, *, rpe: bool) -> str:
    """Return evo's label of the error axis (``APE (m)``)."""
    unit = {"trans_part": "m", "point_distance": "m", "angle_deg": "deg", "angle_rad": "rad"}
    shown = unit.get(relation.value, "unit-less")
    return f"{'RPE' if rpe else 'APE'} ({shown})"


def format_stats(run: EvoRun) -> str:
    """Return evo's block: the title, the alignment line, then the seven statistics."""
    stats = run.series.stats
    values = {name: getattr(stats, name) for name in STAT_ORDER}
    lines = [run.title, run.alignment_words, ""]
    lines += [f"{name:>10}\t{values[name]:.6f}" for name in STAT_ORDER]
    return "\n".join(lines)


def format_additions(run: EvoRun) -> str:
    """Return what loceval adds: the matches, the 95 % intervals and the notes."""
    found = run.result.estimates[0]
    matched = len(found.association)
    summary = (
        f"loceval: {len(run.series)} errors from {matched} matched poses "
        f"({run.estimate_poses} in the estimate)."
    )
    lines = ["", summary]
    if len(run.series) >= 8:
        from loceval.assessment.uncertainty import interval_stats  # noqa: PLC0415  (scipy)

        found_ci = interval_stats(run.series.values)
        lines.append("95 % intervals (block bootstrap over the error series):")
        for name in ("rmse", "mean", "median"):
            lo, hi = found_ci.ci95[name]
            lines.append(f"{name:>10}\t{lo:.6f} .. {hi:.6f}")
        lines.append(f"{'n_eff':>10}\t{found_ci.n_effective:.0f}")
    notes = [*run.result.reference_warnings, *found.warnings]
    if notes:
        lines.append("Notes:")
        lines += [f"  - {note}" for note in notes]
    return "\n".join(lines)


def _report(run: EvoRun, args: argparse.Namespace) -> int:
    if not args.silent:
        emit(format_stats(run))
        emit(format_additions(run))
        if args.verbose:
            emit(_verbose(run))
    if args.save_results is not None:
        from service.cli.evo.results import write_result_zip  # noqa: PLC0415

        path = write_result_zip(run, args.save_results)
        if not args.silent:
            emit(f"Results written to {path}")
    if args.save_plot is not None:
        for path in _write_plots(run, args.save_plot):
            emit(f"Plot written to {path}", file=sys.stdout)
    if args.plot:
        path = _write_report(run)
        emit(f"Report written to {path}", file=sys.stdout)
    return 0


def _write_plots(run: EvoRun, save_plot: Path) -> tuple[Path, ...]:
    """Write evo's two figures at ``--save_plot`` (its suffix the format, as evo)."""
    from exporters.plots.evo import write_error_plots  # noqa: PLC0415  (matplotlib)

    return write_error_plots(
        save_plot,
        title=run.title,
        label=str(run.info["label"]),
        series=run.series,
        at_pose=run.pairs_second,
        reference=run.reference,
        estimate=run.estimate,
    )


def _verbose(run: EvoRun) -> str:
    alignment = run.result.estimates[0].alignment
    transform = alignment.transform
    rows = "\n".join("  " + " ".join(f"{v: .9f}" for v in row) for row in transform.rotation)
    return (
        f"Alignment ({alignment.method.value}, {alignment.poses_used} poses):\n"
        f"rotation:\n{rows}\ntranslation: "
        + " ".join(f"{v:.9f}" for v in transform.translation)
        + f"\nscale: {transform.scale:.9f}"
    )


def _write_report(run: EvoRun) -> Path:
    """Write loceval's report (``-p``: no window to show evo's plots in) in the cwd."""
    from exporters import ExportOptions, write_artifacts  # noqa: PLC0415

    folder = Path.cwd() / f"loceval_{run.metric}_report"
    title = f"{run.metric.upper()}: {run.result.reference.name} vs {run.result.estimates[0].name}"
    options = ExportOptions(evaluation_id=folder.name, title=title)
    written = write_artifacts(run.result, folder, options, names=["report.html"])
    return written[0]
