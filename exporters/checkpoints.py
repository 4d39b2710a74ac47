"""The artifacts of an evaluation against control points: result, errors.csv, report, CAD.

The names are those of :data:`exporters.ARTIFACTS` (so the service lists and serves them):
``result.json``, ``errors.csv``, ``report.html``, ``report.pdf``, and ``paths.dxf``,
``paths.3dm``, ``paths.3dm.json`` and ``paths.glb``, which here hold the control points, the
measured positions and the error lines (:mod:`exporters.cad.dxf_points`,
:mod:`exporters.cad.rhino_points`, :mod:`exporters.cad.gltf_points`); ``paths.ifc`` is not written
for control points.

``errors.csv`` has one row per visit of every estimate::

    estimate,id,t_start_s,t_end_s,samples,spread_m,x_m,y_m,z_m,
    surveyed_x_m,surveyed_y_m,surveyed_z_m,error_m,error_h_m,error_v_m,used_for_alignment

(``x_m..z_m``: the aligned median position over the visit; ``error_v_m`` signed, measured
minus surveyed height). The files are written into a staging folder and moved into place
together, as :func:`exporters.write_artifacts` does for a trajectory evaluation.
"""

from __future__ import annotations

import csv
import io
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Final

from exporters.cad.jsondoc import finite_json
from exporters.errors import ExportError, ExportOptionsError
from exporters.options import ExportOptions
from loceval.checkpoint_evaluation import CheckpointEvaluation, errors_table

__all__ = [
    "CHECKPOINT_ARTIFACTS",
    "checkpoint_errors_csv",
    "checkpoint_result_json",
    "write_checkpoint_artifacts",
]

CHECKPOINT_ARTIFACTS: Final = (
    "result.json",
    "errors.csv",
    "report.html",
    "report.pdf",
    "paths.dxf",
    "paths.3dm",
    "paths.3dm.json",
    "paths.glb",
)
"""The artifacts an evaluation against control points writes."""


def checkpoint_result_json(evaluation: CheckpointEvaluation, options: ExportOptions) -> bytes:
    """Return the ``--json`` document, with the evaluation id, as UTF-8 bytes."""
    document = {"evaluation_id": options.evaluation_id, **evaluation.to_dict()}
    return (finite_json(document, indent=2) + "\n").encode()


def checkpoint_errors_csv(evaluation: CheckpointEvaluation) -> bytes:
    """Return ``errors.csv``: one row per visit (floats in full precision, repr)."""
    header, rows = errors_table(evaluation)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    writer.writerows([str(c).lower() if isinstance(c, bool) else c for c in row] for row in rows)
    return out.getvalue().encode()


def _render_cad(
    evaluation: CheckpointEvaluation, options: ExportOptions, wanted: list[str]
) -> dict[str, bytes]:
    """Render the wanted CAD files: the points, measured positions and error lines."""
    out: dict[str, bytes] = {}
    if "paths.dxf" in wanted:
        from exporters.cad.dxf_points import export_points_dxf  # noqa: PLC0415

        out["paths.dxf"] = export_points_dxf(evaluation, options)
    if "paths.3dm" in wanted or "paths.3dm.json" in wanted:
        from exporters.cad.rhino_points import export_points_3dm, export_points_3dm_json  # noqa: PLC0415

        if "paths.3dm" in wanted:
            out["paths.3dm"] = export_points_3dm(evaluation, options)
        if "paths.3dm.json" in wanted:
            out["paths.3dm.json"] = export_points_3dm_json(evaluation, options)
    if "paths.glb" in wanted:
        from exporters.cad.gltf_points import export_points_glb  # noqa: PLC0415

        out["paths.glb"] = export_points_glb(evaluation, options)
    return out


def _render(
    evaluation: CheckpointEvaluation, options: ExportOptions, wanted: list[str]
) -> dict[str, bytes]:
    """Render every wanted artifact (the report's HTML and PDF share one pass)."""
    out: dict[str, bytes] = {}
    if "result.json" in wanted:
        out["result.json"] = checkpoint_result_json(evaluation, options)
    if "errors.csv" in wanted:
        out["errors.csv"] = checkpoint_errors_csv(evaluation)
    out.update(_render_cad(evaluation, options, wanted))
    if "report.html" in wanted or "report.pdf" in wanted:
        from exporters.report.checkpoints import render_checkpoint_report  # noqa: PLC0415

        html, pdf = render_checkpoint_report(evaluation, options, pdf="report.pdf" in wanted)
        if "report.html" in wanted:
            out["report.html"] = html
        if pdf is not None:
            out["report.pdf"] = pdf
    return out


def write_checkpoint_artifacts(
    evaluation: CheckpointEvaluation,
    out_dir: Path,
    options: ExportOptions,
    *,
    names: Iterable[str] | None = None,
) -> list[Path]:
    """Write the control-point artifacts into ``out_dir``, all or nothing.

    Args:
        evaluation: the evaluation.
        out_dir: the destination folder (created if missing).
        options: the export options (the evaluation id).
        names: the artifacts to write (default: all of :data:`CHECKPOINT_ARTIFACTS`).

    Returns:
        The paths written.

    Raises:
        ExportOptionsError: an artifact that control points do not have (yet).
        ExportError: the folder cannot be written.
    """
    wanted = list(CHECKPOINT_ARTIFACTS if names is None else dict.fromkeys(names))
    other = [n for n in wanted if n not in CHECKPOINT_ARTIFACTS]
    if other:
        msg = (
            f"An evaluation against control points writes {', '.join(CHECKPOINT_ARTIFACTS)}, "
            f"not {other[0]!r}; leave it out of the artifact names."
        )
        raise ExportOptionsError(msg, option="formats")
    out_dir = out_dir.resolve()
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
        staging = out_dir.parent / f".{out_dir.name}.partial-points"
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        try:
            for name, data in _render(evaluation, options, wanted).items():
                (staging / name).write_bytes(data)
            out_dir.mkdir(exist_ok=True)
            for name in wanted:
                (staging / name).replace(out_dir / name)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    except OSError as err:
        msg = (
            f"Cannot write the artifacts into {str(out_dir)!r} ({err.strerror}); check the "
            "free space and permissions, or name another folder."
        )
        raise ExportError(msg) from err
    return [out_dir / name for name in wanted]
