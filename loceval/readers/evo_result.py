"""evo's result zips (``evo_ape``/``evo_rpe --save_results``, ``loceval ape/rpe`` too).

The layout, learnt from zips evo 1.38.1 wrote: ``info.json`` (``title``, ``ref_name``,
``est_name``, ``label``), ``stats.json`` (``rmse``, ``mean``, ``median``, ``std``, ``min``,
``max``, ``sse``) and NumPy ``.npy`` arrays with one value per error (``error_array``,
``timestamps``, ``seconds_from_start``, ``distances``, ``distances_from_start``), plus
``alignment_transformation_sim3`` when aligned. loceval's zips add ``loceval.json``.
Arrays are read without pickles.
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loceval.core.arrays import FloatArray, StampsNs
from loceval.errors import InputError

__all__ = ["ResultZip", "is_result_zip", "read_result_zip"]

_METRES = ("translation part", "point distance")
"""Pose relations whose errors are distances in metres (the others are angles or unit-less)."""

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

    @property
    def settings(self) -> str:
        """Return the title's other lines in one (``for delta = 1 (frames) ...; (with ...)``)."""
        lines = (line.strip() for line in str(self.info.get("title", "")).split("\n")[1:])
        return "; ".join(
            line[1:-1] if line.startswith("(") and line.endswith(")") else line
            for line in lines
            if line
        )

    @property
    def metric(self) -> str | None:
        """Return ``"ape"`` or ``"rpe"`` from the title, or None when it names neither."""
        head = self.title.strip().upper()
        return next((m.lower() for m in ("APE", "RPE") if head.startswith(m)), None)

    @property
    def unit(self) -> str:
        """Return the errors' unit from the label (``APE (m)``: ``m``), or "" without one."""
        label = str(self.info.get("label", ""))
        return label[label.find("(") + 1 : label.rfind(")")].strip() if "(" in label else ""

    @property
    def translation_m(self) -> bool:
        """Return whether the errors are metres (pose relation trans_part or point_distance)."""
        head = self.title.lower()
        return any(f"w.r.t. {words} (m)" in head for words in _METRES)

    @property
    def first_stamp_s(self) -> float | None:
        """Return the first error's stamp (``timestamps[0]``, seconds), or None without one."""
        stamps = self.arrays.get("timestamps")
        if stamps is None or stamps.ndim != 1 or stamps.size == 0:
            return None
        finite = stamps[np.isfinite(stamps)]
        return float(finite.min()) if finite.size else None

    def error_series(self) -> tuple[StampsNs, FloatArray] | None:
        """Return the errors and their stamps, both sorted by time, or None without them.

        Returns:
            ``(stamps_ns, errors)``, (N,) each: ``timestamps`` (seconds, rounded to the
            nanosecond) and ``error_array``; None when the zip lacks either, their lengths
            differ, or a value is not finite.
        """
        errors = self.arrays.get("error_array")
        stamps = self.arrays.get("timestamps")
        if errors is None or stamps is None or errors.ndim != 1 or errors.shape != stamps.shape:
            return None
        if not (np.isfinite(errors).all() and np.isfinite(stamps).all()):
            return None
        stamps_ns = np.round(stamps * 1e9).astype(np.int64)
        order = np.argsort(stamps_ns, kind="stable")
        return stamps_ns[order], errors[order]


def is_result_zip(path: Path) -> bool:
    """Return whether ``path`` is a zip holding ``info.json`` and ``stats.json`` at its root."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
    except (zipfile.BadZipFile, OSError):
        return False
    return {"info.json", "stats.json"} <= names


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
        msg = (
            f"{where} is not a zip ({err}); give a result zip of evo_ape, evo_rpe or "
            "loceval ape/rpe."
        )
        raise InputError(msg) from None
    with archive:
        names = set(archive.namelist())
        missing = [n for n in ("info.json", "stats.json") if n not in names]
        if missing:
            msg = (
                f"{where} lacks {', '.join(missing)}: it is not a result zip of evo_ape, "
                "evo_rpe or loceval ape/rpe."
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
