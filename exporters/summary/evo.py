"""An evo result zip as one run of a summary: evo's own figure, marked as evo's.

A team's archive of ``evo_ape``/``evo_rpe --save_results`` zips joins the runs loceval
evaluates: each zip is one run of one system. Its RMSE goes into the ATE column (APE) or
the RPE column (RPE) when its errors are distances in metres (pose relation
``trans_part`` or ``point_distance``); a rotation or unit-less result has no place in
columns of metres, so the run shows no figure and its note says what the zip holds. The
figures are evo's as it computed them (its association, its alignment); evo writes no
confidence interval and judges no tolerance, so neither is shown, and the note says so
rather than inventing one.
"""

from __future__ import annotations

import datetime as dt
from pathlib import PurePosixPath

from exporters.summary.model import SummaryRun, SystemFigures
from loceval.readers.evo_result import ResultZip

__all__ = ["evo_summary_run", "evo_system_name"]


def evo_system_name(result: ResultZip) -> str:
    """Return the system's name as loceval would give it: a topic as is, a file by its stem.

    loceval names an estimate by its selector (a bag's topic) or its file's stem; evo keeps
    the topic or the path it was given. Taking the stem of a path makes ``orb.txt`` of an
    evo archive the same system as ``orb.txt`` evaluated by loceval.
    """
    raw = str(result.info.get("est_name", "")).strip()
    if not raw:
        return result.path.stem
    if raw.startswith("/tf:"):
        return raw  # evo's tf chain (/tf:map.base_link)
    last = PurePosixPath(raw.replace("\\", "/")).name
    if raw.startswith("/") and not PurePosixPath(last).suffix:
        return raw  # a topic (/odom), as loceval names a bag's source
    return PurePosixPath(last).stem or raw


def _number(value: float | None) -> str:
    return "—" if value is None else f"{value:.6g}"


def evo_summary_run(
    result: ResultZip,
    *,
    dataset: str,
    recorded_at: dt.datetime,
    recorded_at_is_upload: bool = False,
    name: str | None = None,
) -> SummaryRun:
    """Return a succeeded summary run holding an evo result's RMSE, its source marked evo.

    Args:
        result: the zip as read (:func:`loceval.readers.evo_result.read_result_zip`).
        dataset: the dataset's name in the report.
        recorded_at: when the run was recorded (its first error stamp when it is a date,
            else its upload time), aware.
        recorded_at_is_upload: ``recorded_at`` is the upload time.
        name: the system's name in the report (default :func:`evo_system_name`).

    Returns:
        The run, ``source="evo"``, with one system; its ``source_note`` says what the
        figure is and that evo gives no interval or verdict.
    """
    system = name or evo_system_name(result)
    rmse = result.stats.get("rmse")
    metric = result.metric
    errors = result.arrays.get("error_array")
    matched = None if errors is None else int(errors.size)
    in_metres = result.translation_m and metric is not None and rmse is not None
    figures = SystemFigures(
        ate_rmse_m=rmse if in_metres and metric == "ape" else None,
        rpe_rmse_m=rmse if in_metres and metric == "rpe" else None,
        matched=matched,
        verdict=None,
    )
    what = result.title or "no title"
    how = f", {result.settings}" if result.settings else ""
    if in_metres:
        column = "ATE" if metric == "ape" else "RPE"
        placed = f"its RMSE {_number(rmse)} m is shown as {system}'s {column}"
    else:
        placed = (
            f"RMSE {_number(rmse)} {result.unit or 'without a unit'}: not a translation "
            "error in metres, so it is in neither "
            "the ATE nor the RPE column"
        )
    note = (
        f"evo result: {what}{how}; {placed}. Computed by evo with its own association and "
        "alignment; evo gives no confidence interval and no verdict, so none is shown."
    )
    return SummaryRun(
        dataset=dataset,
        recorded_at=recorded_at,
        status="succeeded",
        systems={system: figures},
        recorded_at_is_upload=recorded_at_is_upload,
        source="evo",
        source_note=note,
    )
