"""A source's selector checked against its dataset's stored inspection, before queueing.

A topic, a ``tf:PARENT:CHILD`` chain or a rigid body that the upload's inspection did not
find is refused at once, naming what the dataset holds, instead of failing in the job.
"""

from __future__ import annotations

from typing import Any

from loceval.errors import InputError
from service.db import Dataset
from service.schemas.evaluations import SourceRef

__all__ = ["check_selector"]


def _check_survey(fmt: object, label: str, role: str) -> None:
    """Control points are a reference only; a visits table is an option, not a source."""
    if fmt == "visits":
        msg = f"{label} is a visits table, not a trajectory; give its id as the visits option."
        raise InputError(msg)
    if fmt == "points" and role != "reference":
        msg = f"{label} holds control points, not a trajectory; give it as the reference."
        raise InputError(msg)


def check_selector(dataset: Dataset, ref: SourceRef, role: str) -> None:
    """Fail now when a source's selector cannot name a trajectory of its uploaded dataset.

    Raises:
        InputError: the dataset is no trajectory in this role (a URDF, ranges, an evo
            result, control points as an estimate), or its selector names nothing in it.
    """
    inspection: dict[str, Any] = dataset.inspection
    fmt = inspection.get("format")
    label = f"The {role} dataset {dataset.name!r}"
    if fmt == "urdf":
        msg = f"{label} is a URDF, not a trajectory; use it as the device offset."
        raise InputError(msg)
    if fmt == "ranges":
        msg = f"{label} is a radio ranges table, not a trajectory; use it in POST /ranging."
        raise InputError(msg)
    if inspection.get("kind") == "evo_result":
        msg = f"{label} is an evo result (figures, not poses); compare it with `loceval res`."
        raise InputError(msg)
    _check_survey(fmt, label, role)
    sources = inspection.get("sources", [])
    selectors = [s.get("selector") for s in sources]
    if fmt == "bag":
        _check_bag_selector(inspection, ref, label, selectors)
        return
    if fmt == "motive":
        if ref.selector is None and len(selectors) == 1:
            return
        if ref.selector not in selectors:
            listed = ", ".join(str(s) for s in selectors)
            msg = f"{label} holds the rigid bodies {listed}; choose one as selector."
            raise InputError(msg)
        return
    if ref.selector is not None:
        msg = f"{label} is a {fmt} file with one trajectory; leave its selector empty (null)."
        raise InputError(msg)


def _check_bag_selector(
    inspection: dict[str, Any], ref: SourceRef, label: str, selectors: list[Any]
) -> None:
    """Fail now when a bag's selector is missing, names no topic, or an impossible tf chain."""
    topics = {t.get("name") for t in inspection.get("topics", [])}
    if ref.selector is None:
        listed = ", ".join(str(s) for s in selectors[:12]) or "none found"
        msg = f"{label} is a bag; choose a selector (a pose topic or tf:PARENT:CHILD): {listed}."
        raise InputError(msg)
    if ref.selector.startswith("tf:"):
        _check_tf_chain(inspection.get("tf_tree", []), ref.selector, label)
    elif ref.selector not in topics:
        listed = ", ".join(str(s) for s in selectors[:12]) or "none found"
        msg = f"{label} has no topic {ref.selector!r}; its trajectory sources are: {listed}."
        raise InputError(msg)


def _check_tf_chain(tree: list[dict[str, Any]], selector: str, label: str) -> None:
    """Fail now when a ``tf:PARENT:CHILD`` selector names a frame the bag's tf tree lacks.

    The stored inspection's ``tf_tree`` lists every frame with its parent (``""`` for a
    root); a chain can be read when both frames are in it and share a root. Whether the
    chain's stamps overlap is left to the job (it reads the transforms).

    Raises:
        InputError: the selector is malformed, names an unknown frame, or joins two trees.
    """
    parts = selector.split(":")
    if len(parts) != len(("tf", "parent", "child")) or not parts[1] or not parts[2]:
        msg = (
            f"{label}: {selector!r} is not a tf chain; write tf:PARENT:CHILD, "
            "e.g. tf:map:base_link."
        )
        raise InputError(msg)
    parents = {str(f.get("frame")): str(f.get("parent") or "") for f in tree}
    frames = _frame_list(tree)
    for frame in parts[1:]:
        if frame not in parents:
            msg = f"{label} has no tf frame {frame!r}; its tf frames are: {frames}."
            raise InputError(msg)
    roots = [_tf_root(parents, frame) for frame in parts[1:]]
    if roots[0] != roots[1]:
        msg = (
            f"{label}: the tf frames {parts[1]!r} and {parts[2]!r} are in separate trees "
            f"(rooted at {roots[0]!r} and {roots[1]!r}); choose two frames of one tree."
        )
        raise InputError(msg)


_LISTED_FRAMES = 12
"""Frames named in a message: the roots and moving frames first, the rest counted."""


def _frame_list(tree: list[dict[str, Any]]) -> str:
    """Return the tree's frames for a message: roots, then moving frames, then static ones."""
    ordered = sorted(
        tree,
        key=lambda f: (bool(f.get("parent")), bool(f.get("static")), str(f.get("frame"))),
    )
    names = [str(f.get("frame")) for f in ordered]
    if not names:
        return "none"
    if len(names) <= _LISTED_FRAMES:
        return ", ".join(names)
    return f"{', '.join(names[:_LISTED_FRAMES])} and {len(names) - _LISTED_FRAMES} more"


def _tf_root(parents: dict[str, str], frame: str) -> str:
    """Return the root above ``frame`` (a loop ends at the frame seen twice)."""
    seen = {frame}
    while parents.get(frame):
        frame = parents[frame]
        if frame in seen:
            break
        seen.add(frame)
    return frame
