"""A tf tree in numpy: links recorded over time, and chains composed through them.

A recording's tf data is a forest of links ``parent -> child``; each link is either dynamic
(published on ``/tf``, many stamped samples) or static (``/tf_static``, one transform that
holds at every time). :func:`compose_chain` returns the poses of ``child`` in ``parent``
through the tree, up from ``parent`` to the lowest common ancestor and down to ``child``.

Time model: every dynamic link of the chain is interpolated (linear translation, SLERP
rotation) at the stamps of the chain's *fastest* dynamic link; static links are applied
once. A pose where some dynamic link has no data is dropped and counted, never
extrapolated. A dynamic link has data at time ``t`` when ``t`` is one of its stamps or lies
between two consecutive stamps no more than the link's max gap apart. The default max gap
(``max_gap_ns=None``) is per link: the larger of :data:`DEFAULT_MIN_GAP_NS` (0.1 s) and
:data:`GAP_INTERVAL_FACTOR` (3) times the link's median sample interval. So a 120 Hz
motion-capture link may bridge up to 0.1 s of lost tracking, and a 10 Hz SLAM ``map -> odom``
link may miss two updates, but a longer outage drops the poses that fall in it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from loceval.core.arrays import BoolArray, FloatArray, StampsNs
from loceval.core.geometry import SimilarityTransform, slerp_pairs
from loceval.core.quantities import ARROW, ARROW_BACK
from loceval.errors import ReaderError

__all__ = [
    "DEFAULT_MIN_GAP_NS",
    "GAP_INTERVAL_FACTOR",
    "ChainStep",
    "ComposedChain",
    "TfBuffer",
    "TfLink",
    "compose_chain",
    "compose_static_chain",
    "describe_chain",
    "find_chain",
]

DEFAULT_MIN_GAP_NS = 100_000_000
"""Smallest default max gap of a dynamic link: 0.1 s."""
GAP_INTERVAL_FACTOR = 3.0
"""Default max gap of a dynamic link, in multiples of its median sample interval."""
_MAX_LISTED_FRAMES = 60


@dataclass(frozen=True, slots=True, eq=False)
class TfLink:
    """One ``parent -> child`` link of a tf tree, over time.

    On construction samples with NaN, inf or a zero quaternion are dropped (and counted),
    the rest are sorted by stamp (stable), samples with a repeated stamp are dropped (the
    first one is kept) and the quaternions are normalized.

    Attributes:
        parent: parent frame id (no leading slash).
        child: child frame id.
        stamps_ns: (M,) int64 nanoseconds, strictly increasing after construction.
        translations_xyz: (M, 3) float64 translation of ``child`` in ``parent``, metres.
        quat_xyzw: (M, 4) float64 unit quaternions x y z w, rotation of ``child`` in
            ``parent``.
        is_static: the link was published on ``/tf_static``; its last sample holds at
            every time.
        message_count: samples received, including dropped duplicates.
        invalid_count: samples dropped for NaN, inf or a zero quaternion.
    """

    parent: str
    child: str
    stamps_ns: StampsNs
    translations_xyz: FloatArray
    quat_xyzw: FloatArray
    is_static: bool = False
    message_count: int = field(default=-1)
    invalid_count: int = field(default=0, init=False)

    def __post_init__(self) -> None:
        """Copy, sort, de-duplicate and check the samples."""
        stamps = np.array(self.stamps_ns, dtype=np.int64).reshape(-1)
        translations = np.array(self.translations_xyz, dtype=np.float64)
        quats = np.array(self.quat_xyzw, dtype=np.float64)
        m = stamps.shape[0]
        if m == 0 or translations.shape != (m, 3) or quats.shape != (m, 4):
            msg = (
                f"tf link {self.parent!r} {ARROW} {self.child!r} needs (M,) stamps with M >= 1, "
                f"(M, 3) translations and (M, 4) quaternions, got {stamps.shape!r}, "
                f"{translations.shape!r} and {quats.shape!r}; pass one row per sample."
            )
            raise ReaderError(msg)
        norms = np.linalg.norm(quats, axis=1)
        valid = np.isfinite(translations).all(axis=1) & np.isfinite(quats).all(axis=1)
        valid &= norms >= 1e-9
        invalid = int(m - valid.sum())
        if invalid == m:
            msg = (
                f"tf link {self.parent!r} {ARROW} {self.child!r} holds only NaN, inf or zero-"
                "quaternion samples; fix the publisher or pick a chain without this link."
            )
            raise ReaderError(msg)
        if invalid:
            # A glitching publisher loses those samples, not the whole recording's tf.
            stamps, translations, quats, norms = (
                stamps[valid],
                translations[valid],
                quats[valid],
                norms[valid],
            )
        quats = quats / norms[:, None]
        if m > 1 and not (np.diff(stamps) > 0).all():
            order = np.argsort(stamps, kind="stable")
            stamps, translations, quats = stamps[order], translations[order], quats[order]
            keep = np.concatenate(([True], np.diff(stamps) != 0))
            stamps, translations, quats = stamps[keep], translations[keep], quats[keep]
        for array in (stamps, translations, quats):
            array.flags.writeable = False
        object.__setattr__(self, "stamps_ns", stamps)
        object.__setattr__(self, "translations_xyz", translations)
        object.__setattr__(self, "quat_xyzw", quats)
        object.__setattr__(self, "message_count", max(int(self.message_count), m))
        object.__setattr__(self, "invalid_count", invalid)

    def __len__(self) -> int:
        """Return the number of distinct samples."""
        return int(self.stamps_ns.shape[0])

    @property
    def name(self) -> str:
        """Return ``"parent → child"``."""
        return f"{self.parent} {ARROW} {self.child}"

    @property
    def median_interval_ns(self) -> int:
        """Median time between samples in nanoseconds (0 for a single sample)."""
        if len(self) < 2:
            return 0
        return int(np.median(np.diff(self.stamps_ns)))

    @property
    def rate_hz(self) -> float:
        """Median sample rate in Hz (0 for static links and single samples)."""
        interval = self.median_interval_ns
        if self.is_static or interval <= 0:
            return 0.0
        return 1e9 / interval

    def default_max_gap_ns(self) -> int:
        """Return the default max gap: max(0.1 s, 3 x the median sample interval)."""
        return max(DEFAULT_MIN_GAP_NS, int(GAP_INTERVAL_FACTOR * self.median_interval_ns))

    def covers(self, stamps_ns: StampsNs, *, max_gap_ns: int | None = None) -> BoolArray:
        """Return where the link has data, without extrapolation.

        Args:
            stamps_ns: (N,) int64 query stamps.
            max_gap_ns: longest interval between two samples that is interpolated across;
                None for :meth:`default_max_gap_ns`.

        Returns:
            (N,) True where a stamp is a sample stamp or lies between two samples that are
            at most ``max_gap_ns`` apart; all True for a static link.
        """
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        if self.is_static:
            return np.ones(stamps.shape[0], dtype=bool)
        s = self.stamps_ns
        if s.shape[0] == 1:
            out: BoolArray = stamps == s[0]
            return out
        gap = self.default_max_gap_ns() if max_gap_ns is None else max_gap_ns
        i = np.searchsorted(s, stamps, side="right") - 1
        in_range = (i >= 0) & (stamps <= s[-1])
        i = np.clip(i, 0, s.shape[0] - 2)
        t0, t1 = s[i], s[i + 1]
        covered: BoolArray = in_range & (((t1 - t0) <= gap) | (stamps == t0) | (stamps == t1))
        return covered

    def at(self, stamps_ns: StampsNs) -> tuple[FloatArray, FloatArray]:
        """Return the link interpolated at stamps it covers (see :meth:`covers`).

        Args:
            stamps_ns: (N,) int64 stamps inside the link's time range.

        Returns:
            (N, 3) translations (linear interpolation) and (N, 4) quaternions x y z w
            (SLERP); for a static link the last sample repeated.
        """
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        n = stamps.shape[0]
        if self.is_static or len(self) == 1:
            return (
                np.repeat(self.translations_xyz[-1:], n, axis=0),
                np.repeat(self.quat_xyzw[-1:], n, axis=0),
            )
        s = self.stamps_ns
        i = np.clip(np.searchsorted(s, stamps, side="right") - 1, 0, s.shape[0] - 2)
        t0, t1 = s[i], s[i + 1]
        # Stamps that are samples (the chain's fastest link, synchronized publishers) are
        # returned as recorded; only the others are interpolated.
        index = np.where(stamps == t1, i + 1, i)
        translations: FloatArray = self.translations_xyz[index]
        quats: FloatArray = self.quat_xyzw[index]
        between = np.flatnonzero((stamps != t0) & (stamps != t1))
        if between.size:
            j, u0, u1 = i[between], t0[between], t1[between]
            # Integer differences first: float64 cannot hold epoch nanoseconds exactly.
            weights = np.clip((stamps[between] - u0).astype(np.float64) / (u1 - u0), 0.0, 1.0)
            p0, p1 = self.translations_xyz[j], self.translations_xyz[j + 1]
            translations[between] = p0 + (p1 - p0) * weights[:, None]
            quats[between] = slerp_pairs(self.quat_xyzw[j], self.quat_xyzw[j + 1], weights)
        return translations, quats


class ChainStep(NamedTuple):
    """One link of a chain, walked forwards (parent to child) or inverted."""

    link: TfLink
    inverted: bool


class ComposedChain(NamedTuple):
    """Poses of a chain's child frame in its parent frame.

    A tuple ``(stamps_ns, positions_xyz, quat_xyzw, dropped)`` so callers may unpack it.
    """

    stamps_ns: StampsNs
    """(N,) int64 stamps of the fastest dynamic link where every link has data."""
    positions_xyz: FloatArray
    """(N, 3) positions of the child frame in the parent frame, metres."""
    quat_xyzw: FloatArray
    """(N, 4) orientations of the child frame in the parent frame."""
    dropped: int
    """Stamps of the fastest link dropped because another link had no data there."""


@dataclass(frozen=True, slots=True, eq=False)
class TfBuffer:
    """The links of a recording's tf data.

    Attributes:
        links: every ``parent -> child`` link, in any order; at most one per pair.
    """

    links: tuple[TfLink, ...]
    _by_child: dict[str, tuple[TfLink, ...]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        """Index the links by child frame and reject repeated pairs."""
        links = tuple(self.links)
        by_child: dict[str, list[TfLink]] = {}
        seen: set[tuple[str, str]] = set()
        for link in links:
            pair = (link.parent, link.child)
            if pair in seen:
                msg = f"tf link {link.name!r} was given twice; merge its samples into one TfLink."
                raise ReaderError(msg)
            seen.add(pair)
            by_child.setdefault(link.child, []).append(link)
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "_by_child", {k: tuple(v) for k, v in by_child.items()})

    def frames(self) -> tuple[str, ...]:
        """Return every frame id that appears in a link, sorted."""
        return tuple(sorted({f for link in self.links for f in (link.parent, link.child)}))

    def link(self, parent: str, child: str) -> TfLink | None:
        """Return the ``parent -> child`` link, or None."""
        return next((x for x in self._by_child.get(child, ()) if x.parent == parent), None)

    def parent_links(self, child: str) -> tuple[TfLink, ...]:
        """Return the links whose child is ``child`` (more than one is a broken tree)."""
        return self._by_child.get(child, ())

    def roots(self) -> tuple[str, ...]:
        """Return the frames that have no parent, sorted."""
        return tuple(f for f in self.frames() if f not in self._by_child)

    def root_of(self, frame: str) -> str:
        """Return the root of the tree that holds ``frame``.

        Raises:
            ReaderError: a frame on the way up has two parents, or the links form a loop.
        """
        return _ancestors(self, frame)[-1]

    def describe_frames(self) -> str:
        """Return the frames as a comma-separated list for error messages."""
        return _listing(self.frames())


def find_chain(buffer: TfBuffer, parent: str, child: str) -> tuple[ChainStep, ...]:
    """Return the links from ``parent`` to ``child``: up to their common ancestor, then down.

    Args:
        buffer: the recording's links.
        parent: frame the poses are to be expressed in (leading slash ignored).
        child: frame whose poses are wanted (leading slash ignored).

    Returns:
        The steps in order; ``T_parent_child`` is the product of the steps' transforms
        (each inverted step contributes the inverse of its link). Empty when
        ``parent == child``.

    Raises:
        ReaderError: a frame is not in the buffer, the two frames are in different trees,
            a frame has two parents, or the links form a loop.
    """
    parent, child = parent.lstrip("/"), child.lstrip("/")
    frames = set(buffer.frames())
    for role, frame in (("parent", parent), ("child", child)):
        if frame not in frames:
            msg = (
                f"The {role} frame {frame!r} is not in the recording's tf data; frames in "
                f"the bag: {buffer.describe_frames()}; type tf:PARENT:CHILD with two of them."
            )
            raise ReaderError(msg)
    up = _ancestors(buffer, parent)
    down = _ancestors(buffer, child)
    common = next((f for f in down if f in set(up)), None)
    if common is None:
        msg = (
            f"No tf path from {parent!r} to {child!r}: {parent!r} is in the tree rooted at "
            f"{up[-1]!r} and {child!r} in the tree rooted at {down[-1]!r}, and nothing links "
            f"them; pick two frames of one tree (frames: {buffer.describe_frames()}) or "
            "record the missing transform."
        )
        raise ReaderError(msg)
    ups = [ChainStep(buffer.parent_links(f)[0], inverted=True) for f in up[: up.index(common)]]
    downs = [
        ChainStep(buffer.parent_links(f)[0], inverted=False)
        for f in reversed(down[: down.index(common)])
    ]
    return (*ups, *downs)


def describe_chain(steps: tuple[ChainStep, ...]) -> str:
    """Return a chain as ``"map → odom → base_link"`` (``←`` marks an inverted link)."""
    if not steps:
        return "(identity)"
    first = steps[0]
    parts = [first.link.child if first.inverted else first.link.parent]
    for step in steps:
        if step.inverted:
            parts.append(f"{ARROW_BACK} {step.link.parent}")
        else:
            parts.append(f"{ARROW} {step.link.child}")
    return " ".join(parts)


def compose_chain(
    buffer: TfBuffer, parent: str, child: str, *, max_gap_ns: int | None = None
) -> ComposedChain:
    """Compose the poses of ``child`` in ``parent`` through the tf tree.

    Each dynamic link is interpolated at the stamps of the chain's fastest dynamic link
    (highest median rate; on a tie the one with more samples); static links are applied
    once. Stamps where a dynamic link has no data (outside its time range, or inside a gap
    longer than its max gap) are dropped and counted, never extrapolated.

    Args:
        buffer: the recording's links.
        parent: frame the poses are expressed in.
        child: frame whose poses are wanted.
        max_gap_ns: longest interval between two samples of a dynamic link that is
            interpolated across; None for the per-link default (see the module docstring).

    Returns:
        The composed poses and the number of dropped stamps.

    Raises:
        ReaderError: no chain links the frames (see :func:`find_chain`), or every link of
            the chain is static (read it with :func:`compose_static_chain`).
    """
    steps = find_chain(buffer, parent, child)
    dynamic = [s.link for s in steps if not s.link.is_static]
    if not dynamic:
        msg = (
            f"The tf chain {describe_chain(steps)!r} has no dynamic link (every link is on "
            "/tf_static), so it is a fixed offset, not a trajectory; read it as a device "
            "offset or pick a chain that moves."
        )
        raise ReaderError(msg)
    fastest = max(dynamic, key=lambda x: (x.rate_hz, len(x)))
    stamps = fastest.stamps_ns
    keep = np.ones(stamps.shape[0], dtype=bool)
    for link in dynamic:
        if link is not fastest:
            keep &= link.covers(stamps, max_gap_ns=max_gap_ns)
    kept = stamps[keep]
    dropped = int(stamps.shape[0] - kept.shape[0])
    n = kept.shape[0]
    if n == 0:
        return ComposedChain(kept, np.zeros((0, 3)), np.zeros((0, 4)), dropped)
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    translation = np.zeros((n, 3))
    for step in steps:
        step_t, step_q = step.link.at(kept)
        if step.inverted:
            step_q = _quat_conjugate(step_q)
            step_t = -_quat_rotate(step_q, step_t)
        # T_a_c = T_a_b · T_b_c: t_a_c = t_a_b + R_a_b t_b_c, R_a_c = R_a_b R_b_c.
        translation = translation + _quat_rotate(quats, step_t)
        quats = _quat_multiply(quats, step_q)
    quats /= np.linalg.norm(quats, axis=1)[:, None]
    return ComposedChain(kept, translation, quats, dropped)


def compose_static_chain(buffer: TfBuffer, parent: str, child: str) -> SimilarityTransform:
    """Return the fixed transform ``T_parent_child`` through static links only.

    Args:
        buffer: the recording's links.
        parent: the frame the result maps into.
        child: the frame the result maps from.

    Returns:
        The rigid transform that maps ``child`` coordinates into ``parent`` coordinates.

    Raises:
        ReaderError: no chain links the frames, or a link of the chain is dynamic.
    """
    steps = find_chain(buffer, parent, child)
    moving = [s.link.name for s in steps if not s.link.is_static]
    if moving:
        msg = (
            f"The tf chain {describe_chain(steps)!r} holds dynamic links ({', '.join(moving)}) "
            "that are on /tf, not /tf_static, so it is no fixed offset; read it as a "
            "trajectory with tf:PARENT:CHILD instead."
        )
        raise ReaderError(msg)
    result = SimilarityTransform.identity()
    for step in steps:
        t = SimilarityTransform.from_pose(step.link.translations_xyz[-1], step.link.quat_xyzw[-1])
        result = result.compose(t.inverse() if step.inverted else t)
    return result


def _quat_multiply(a: FloatArray, b: FloatArray) -> FloatArray:
    """Hamilton product of matching rows of (N, 4) x y z w quaternions (rotation a then b)."""
    ax, ay, az, aw = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    bx, by, bz, bw = b[:, 0], b[:, 1], b[:, 2], b[:, 3]
    out: FloatArray = np.stack(
        (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ),
        axis=1,
    )
    return out


def _quat_conjugate(q: FloatArray) -> FloatArray:
    """Inverse of (N, 4) unit quaternions."""
    out: FloatArray = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return out


def _quat_rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate (N, 3) vectors by matching (N, 4) unit quaternions."""
    u, w = q[:, :3], q[:, 3:]
    t = 2.0 * np.cross(u, v)
    out: FloatArray = v + w * t + np.cross(u, t)
    return out


def _ancestors(buffer: TfBuffer, frame: str) -> list[str]:
    """Return ``[frame, parent, grandparent, ..., root]``."""
    chain = [frame]
    seen = {frame}
    while links := buffer.parent_links(chain[-1]):
        if len(links) > 1:
            parents = sorted(x.parent for x in links)
            msg = (
                f"Frame {chain[-1]!r} has {len(links)} parents in the recording's tf data "
                f"({', '.join(map(repr, parents))}), but tf allows one; fix the publishers "
                "or pick a chain that avoids this frame."
            )
            raise ReaderError(msg)
        parent = links[0].parent
        if parent in seen:
            msg = (
                f"The tf links form a loop through {parent!r} ({f' {ARROW} '.join(reversed(chain))}"
                "); fix the publishers so that the frames form a tree."
            )
            raise ReaderError(msg)
        chain.append(parent)
        seen.add(parent)
    return chain


def _listing(frames: tuple[str, ...]) -> str:
    if len(frames) <= _MAX_LISTED_FRAMES:
        return ", ".join(frames)
    rest = len(frames) - _MAX_LISTED_FRAMES
    return f"{', '.join(frames[:_MAX_LISTED_FRAMES])} and {rest} more"
