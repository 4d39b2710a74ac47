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
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from loceval._typing import FloatArray
from loceval.errors import InputError

if TYPE_CHECKING:
    from service.cli.evo.runs import EvoRun

__all__ = ["ResultZip", "read_result_zip", "write_result_zip"]

_NS_PER_S = 1_000_000_000
_STATS = ("rmse", "mean", "median", "std", "min", "max", "sse")
_MAX_MEMBER_BYTES = 1 << 30
"""Largest member read from a zip (a result holds a few arrays of floats)."""


@dataclass(frozen=True, slots=True, eq=False)
class ResultZip:
    """One result zip as read: evo's or loceval's.

    Attributes:
        path: the file.
        info: ``info.json``.
        stats: ``stats.json`` (the seven statistics).
        arrays: the ``.npy`` arrays by name (``error_array``, ``timestamps``, ...).
        loceval: ``loceval.json`` when loceval wrote the zip, else empty.
    """

    path: Path
    info: dict[str, object]
    stats: dict[str, float]
    arrays: dict[str, FloatArray] = field(default_factory=dict)
    loceval: dict[str, object] = field(default_factory=dict)

    @property
    def title(self) -> str:
        """Return the title's first line (``APE w.r.t. translation part (m)``)."""
        return str(self.info.get("title", "")).split("\n", 1)[0]


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


def _member(archive: zipfile.ZipFile, name: str, where: str) -> bytes:
    info = archive.getinfo(name)
    if info.file_size > _MAX_MEMBER_BYTES:
        msg = f"{where}: {name} is {info.file_size} bytes, more than a result holds."
        raise InputError(msg)
    return archive.read(name)


def read_result_zip(path: Path) -> ResultZip:
    """Read a result zip written by evo_ape/evo_rpe or by loceval ape/rpe.

    Raises:
        InputError: the file is missing, not a zip, or lacks ``info.json``/``stats.json``,
            or an array is not a float array of one value per error.
    """
    where = str(path)
    try:
        archive = zipfile.ZipFile(path)
    except FileNotFoundError:
        msg = f"No such result zip: {where!r}."
        raise InputError(msg) from None
    except (zipfile.BadZipFile, OSError) as err:
        msg = f"{where} is not a zip ({err}); give a zip written by --save_results."
        raise InputError(msg) from None
    with archive:
        names = set(archive.namelist())
        missing = [n for n in ("info.json", "stats.json") if n not in names]
        if missing:
            msg = (
                f"{where} lacks {', '.join(missing)}: it is not a result zip of evo_ape, "
                "evo_rpe or loceval ape/rpe (--save_results)."
            )
            raise InputError(msg)
        try:
            info = json.loads(_member(archive, "info.json", where))
            raw = json.loads(_member(archive, "stats.json", where))
            stats = {k: float(raw[k]) for k in _STATS if k in raw}
            extra = (
                json.loads(_member(archive, "loceval.json", where))
                if "loceval.json" in names
                else {}
            )
        except (ValueError, TypeError) as err:
            msg = f"{where}: info.json or stats.json is not valid JSON of a result ({err})."
            raise InputError(msg) from None
        arrays = {}
        for name in sorted(n for n in names if n.endswith(".npy") and "/" not in n):
            try:
                array = np.load(io.BytesIO(_member(archive, name, where)), allow_pickle=False)
            except ValueError as err:
                msg = f"{where}: {name} is not a NumPy array without pickles ({err})."
                raise InputError(msg) from None
            if array.dtype.kind not in "fiu":
                msg = f"{where}: {name} holds {array.dtype}, not numbers."
                raise InputError(msg)
            arrays[name.removesuffix(".npy")] = np.asarray(array, dtype=np.float64)
    if not isinstance(info, dict) or not stats:
        msg = f"{where}: info.json or stats.json holds no result."
        raise InputError(msg)
    return ResultZip(path=path, info=info, stats=stats, arrays=arrays, loceval=extra)
