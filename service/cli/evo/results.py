"""evo's result zip: written by ``loceval ape/rpe --save_results``, read by ``loceval res``.

The layout was learnt from zips evo 1.38.1 wrote (``tests/data/evo_results/``): a zip of
``info.json`` (``title``, ``ref_name``, ``est_name``, ``label``), ``stats.json`` (``rmse``,
``mean``, ``median``, ``std``, ``min``, ``max``, ``sse``) and NumPy ``.npy`` arrays, one
value per error: ``error_array``, ``timestamps`` (seconds; for RPE the pair's second
pose), ``seconds_from_start``, ``distances`` (the path along the estimate) and
``distances_from_start`` (the path along the reference), and
``alignment_transformation_sim3`` (4x4) when the estimate was aligned. loceval adds
``loceval.json`` (its version, options, intervals and notes); evo ignores it.

Arrays are written and read with :func:`numpy.save`/:func:`numpy.load` without pickles.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.errors import InputError
from loceval.readers.evo_result import ResultZip, read_result_zip

if TYPE_CHECKING:
    from service.cli.evo.runs import EvoRun

__all__ = ["ResultZip", "read_result_zip", "write_result_zip"]

_NS_PER_S = 1_000_000_000
_STATS = ("rmse", "mean", "median", "std", "min", "max", "sse")


def _npy(values: FloatArray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(values, dtype=np.float64), allow_pickle=False)
    return buffer.getvalue()


def _path_m(positions_xyz: FloatArray) -> FloatArray:
    steps = np.linalg.norm(np.diff(positions_xyz, axis=0), axis=1)
    out: FloatArray = np.concatenate([[0.0], np.cumsum(steps)])
    return out


def write_result_zip(run: EvoRun, path: Path) -> Path:
    """Write ``run`` as evo's result zip (``.zip`` added when missing); return its path.

    Raises:
        InputError: the file cannot be written.
    """
    target = path if path.suffix == ".zip" else path.with_name(path.name + ".zip")
    found = run.result.estimates[0]
    stats = run.series.stats
    stamps_ns = run.estimate.stamps_ns
    index = np.arange(len(stamps_ns))
    if run.metric == "rpe":
        index = run.pairs_second
    seconds = stamps_ns[index] / _NS_PER_S
    arrays = {
        "error_array": run.series.values,
        "seconds_from_start": seconds - stamps_ns[0] / _NS_PER_S,
        "timestamps": seconds,
        "distances_from_start": _path_m(run.reference.positions_xyz)[index],
        "distances": _path_m(run.estimate.positions_xyz)[index],
    }
    if found.alignment.poses_used > 0:
        arrays["alignment_transformation_sim3"] = found.alignment.transform.as_matrix()
    info = {
        "title": f"{run.title}\n{run.alignment_words}",
        "ref_name": run.ref_name,
        "est_name": run.est_name,
        "label": run.info["label"],
    }
    extra = {
        "loceval_version": run.result.loceval_version,
        "metric": run.metric,
        **{k: v for k, v in run.info.items() if k not in info},
        "options": run.result.config.to_dict(),
        "n": stats.n,
        "stamps_ns": [int(s) for s in run.series.stamps_ns],
        "notes": [*run.result.reference_warnings, *found.warnings],
    }
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(target, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("info.json", json.dumps(info))
            archive.writestr("stats.json", json.dumps({k: getattr(stats, k) for k in _STATS}))
            for name, values in arrays.items():
                archive.writestr(f"{name}.npy", _npy(values))
            archive.writestr("loceval.json", json.dumps(extra))
    except OSError as err:
        msg = f"Cannot write the results to {str(target)!r} ({err.strerror}); name a writable file."
        raise InputError(msg) from err
    return target
