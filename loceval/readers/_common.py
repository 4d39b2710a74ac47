"""What every reader does once it has raw arrays: validate, normalize, sort, de-duplicate.

A repeated stamp is dropped (the first pose kept) unless the reading runs inside
:func:`keeping_duplicate_stamps`: evo's command lines (``loceval ape``/``rpe``) keep every
pose as evo does, each repeat then stamped 1 ns after the pose before it so that a
trajectory's stamps stay strictly increasing (issue 44: EuRoC's V102 estimate repeats 4
stamps, and evo's statistics count those poses).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextvars import ContextVar

import numpy as np

from loceval.core.arrays import FloatArray, IntArray, StampsNs
from loceval.core.norms import row_norms
from loceval.errors import ReaderError
from loceval.trajectory import MAX_COORDINATE_M, MIN_POSES, Trajectory

__all__ = [
    "QUAT_NORM_TOLERANCE",
    "build_trajectory",
    "keeping_duplicate_stamps",
    "seconds_to_ns",
]

QUAT_NORM_TOLERANCE = 1e-3
"""Quaternions whose norm is within this of 1 are normalized; others are rejected."""


_KEEP_DUPLICATES: ContextVar[bool] = ContextVar("loceval_keep_duplicate_stamps", default=False)


@contextlib.contextmanager
def keeping_duplicate_stamps() -> Iterator[None]:
    """Within it, readers keep a pose whose stamp repeats the one before (as evo does).

    Each repeat is stamped 1 ns after the pose before it (the second of three equal stamps
    1 ns later, the third 2 ns) and a warning says so; where that would reach the next
    distinct stamp, the repeats are dropped as usual.
    """
    token = _KEEP_DUPLICATES.set(True)
    try:
        yield
    finally:
        _KEEP_DUPLICATES.reset(token)


def seconds_to_ns(seconds: FloatArray) -> StampsNs:
    """Convert float seconds to int64 nanoseconds, rounding to the nearest nanosecond."""
    out: StampsNs = np.rint(np.asarray(seconds, dtype=np.float64) * 1e9).astype(np.int64)
    return out


def build_trajectory(
    stamps_ns: StampsNs,
    positions_xyz: FloatArray,
    quat_xyzw: FloatArray | None,
    *,
    where: str,
    line_numbers: IntArray | None = None,
    name: str = "",
    source: str = "",
    frame_id: str = "",
    child_frame_id: str = "",
    warnings: tuple[str, ...] = (),
    cov6: FloatArray | None = None,
    information: tuple[str, ...] = (),
) -> Trajectory:
    """Turn raw reader arrays into a :class:`Trajectory`.

    Rejects NaN/inf and bad quaternions naming the line, normalizes quaternions within
    :data:`QUAT_NORM_TOLERANCE`, sorts unsorted stamps and drops duplicate stamps (both
    reported as warnings), and requires at least :data:`MIN_POSES` poses.

    Args:
        stamps_ns: (N,) int64 nanoseconds, in file order.
        positions_xyz: (N, 3) metres.
        quat_xyzw: (N, 4) quaternions x y z w, or None.
        where: the file (or topic) named in messages.
        line_numbers: (N,) 1-based line (or message) numbers for messages; defaults to 1..N.
        name: trajectory name.
        source: source selector.
        frame_id: frame of the poses.
        child_frame_id: frame whose poses these are.
        warnings: warnings the reader already collected.
        information: how the reader made it, not a warning (the tf chain it composed);
            the trajectory's ``notes``.
        cov6: (N, 6, 6) per-pose covariances, or None; sorted and deduplicated with the
            poses.

    Returns:
        The validated trajectory.

    Raises:
        ReaderError: no poses at all (an empty or header-only file), a value is NaN/inf, a
            quaternion is not unit, or fewer than three poses.
    """
    n = int(stamps_ns.shape[0])
    if n == 0:
        msg = (
            f"{where} holds no poses (no data rows or messages: it is empty, or only a header "
            "or comments); export the recording again, or name the file or topic that "
            "holds the poses."
        )
        raise ReaderError(msg)
    lines = np.arange(1, n + 1) if line_numbers is None else line_numbers
    notes = list(warnings)
    _reject_nonfinite(positions_xyz, lines, where=where, what="position")
    if float(np.abs(positions_xyz).max()) > MAX_COORDINATE_M:  # (the rows only when one is)
        huge = np.flatnonzero(np.abs(positions_xyz).max(axis=1) > MAX_COORDINATE_M)
        i = int(huge[0])
        msg = (
            f"{where}, line {int(lines[i])}: a position is beyond ±{MAX_COORDINATE_M:g} m "
            f"({huge.size} such rows), which is no site's coordinate; check the units and "
            "the column order."
        )
        raise ReaderError(msg)
    if quat_xyzw is not None:
        _reject_nonfinite(quat_xyzw, lines, where=where, what="quaternion")
        with np.errstate(over="ignore"):  # a 1e308 component: norm inf, refused below
            norms = row_norms(quat_xyzw)
        bad = np.flatnonzero(np.abs(norms - 1.0) > QUAT_NORM_TOLERANCE)
        if bad.size:
            i = int(bad[0])
            msg = (
                f"{where}, line {int(lines[i])}: quaternion has norm {norms[i]:.6g}, not 1 "
                f"({bad.size} such rows); check the column order (x y z w) and the format."
            )
            raise ReaderError(msg)
        quat_xyzw = quat_xyzw / norms[:, None]
    stamps_ns, positions_xyz, quat_xyzw, cov6 = _sorted_unique(
        stamps_ns, positions_xyz, quat_xyzw, cov6, where=where, notes=notes
    )
    if stamps_ns.shape[0] < MIN_POSES:
        msg = (
            f"{where}: {stamps_ns.shape[0]} poses, but at least {MIN_POSES} are needed; "
            "check that the file or topic holds the whole recording."
        )
        raise ReaderError(msg)
    return Trajectory(
        stamps_ns=stamps_ns,
        positions_xyz=positions_xyz,
        quat_xyzw=quat_xyzw,
        name=name,
        source=source,
        frame_id=frame_id,
        child_frame_id=child_frame_id,
        warnings=tuple(notes),
        cov6=cov6,
        notes=information,
    )


def _sorted_unique(
    stamps_ns: StampsNs,
    positions_xyz: FloatArray,
    quat_xyzw: FloatArray | None,
    cov6: FloatArray | None,
    *,
    where: str,
    notes: list[str],
) -> tuple[StampsNs, FloatArray, FloatArray | None, FloatArray | None]:
    """Sort the poses by stamp and drop repeated stamps (first kept), noting both."""
    n = int(stamps_ns.shape[0])
    if n > 1 and not (np.diff(stamps_ns) >= 0).all():
        order = np.argsort(stamps_ns, kind="stable")
        stamps_ns, positions_xyz = stamps_ns[order], positions_xyz[order]
        quat_xyzw = None if quat_xyzw is None else quat_xyzw[order]
        cov6 = None if cov6 is None else cov6[order]
        notes.append(f"{where}: stamps were not in order; {n} poses sorted by time.")
    if n > 1:
        keep = np.concatenate(([True], np.diff(stamps_ns) != 0))
        dropped = int(n - keep.sum())
        if dropped and _KEEP_DUPLICATES.get():
            nudged = _nudged(stamps_ns, keep)
            if nudged is not None:
                notes.append(
                    f"{where}: {dropped} {'pose repeats' if dropped == 1 else 'poses repeat'} "
                    "the stamp of the pose before; kept as evo keeps them (each stamped 1 ns "
                    "after the one before)."
                )
                return nudged, positions_xyz, quat_xyzw, cov6
        if dropped:
            stamps_ns, positions_xyz = stamps_ns[keep], positions_xyz[keep]
            quat_xyzw = None if quat_xyzw is None else quat_xyzw[keep]
            cov6 = None if cov6 is None else cov6[keep]
            notes.append(
                f"{where}: {dropped} {'pose' if dropped == 1 else 'poses'} with a duplicate "
                "stamp dropped (first one kept)."
            )
    return stamps_ns, positions_xyz, quat_xyzw, cov6


def _nudged(stamps_ns: StampsNs, first: np.ndarray) -> StampsNs | None:
    """Stamp each repeat 1 ns after the pose before it; None if that reaches the next stamp.

    Args:
        stamps_ns: (N,) sorted stamps with repeats.
        first: (N,) True where a stamp differs from the one before (a run of repeats starts).
    """
    index = np.arange(stamps_ns.shape[0])
    run_start = np.maximum.accumulate(np.where(first, index, 0))
    nudged: StampsNs = stamps_ns + (index - run_start)
    return nudged if bool((np.diff(nudged) > 0).all()) else None


def _reject_nonfinite(values: FloatArray, lines: IntArray, *, where: str, what: str) -> None:
    if np.isfinite(values).all():  # the rows are looked for only when one is bad
        return
    bad_rows = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if bad_rows.size:
        i = int(bad_rows[0])
        msg = (
            f"{where}, line {int(lines[i])}: {what} is NaN or inf ({bad_rows.size} such rows); "
            "remove those rows or re-export the file."
        )
        raise ReaderError(msg)
