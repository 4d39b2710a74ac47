"""Device offsets from URDF files: the fixed joints between two links.

The framework paper (sect. 3.3.2) describes the tracked device in URDF: the offset from the
motion-capture rigid body's origin to the localization system's origin (e.g. a camera
centre) is a chain of fixed joints. :func:`read_urdf_offset` composes that chain, walking
up from ``from_link`` to the common ancestor and down to ``to_link``. :func:`read_urdf` is
the one parse of a URDF file (the inspection of an uploaded device file uses it too).

A joint's ``<origin xyz="x y z" rpy="r p y"/>`` is the pose of its child link in its parent
link; ``rpy`` are fixed-axis roll, pitch, yaw, so ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loceval.core.arrays import FloatArray
from loceval.core.geometry import SimilarityTransform
from loceval.core.rotation import Rotation
from loceval.errors import ReaderError

__all__ = ["UrdfJoint", "UrdfRobot", "read_urdf", "read_urdf_joints", "read_urdf_offset"]

_FORBIDDEN = re.compile(r"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
_XACRO_NS = "http://www.ros.org/wiki/xacro"
_MAX_LISTED = 60


@dataclass(frozen=True, slots=True, eq=False)
class UrdfJoint:
    """One joint of a URDF robot at its zero position.

    Attributes:
        name: joint name.
        joint_type: ``fixed``, ``revolute``, ``continuous``, ``prismatic``, ``floating`` or
            ``planar``.
        parent: parent link name.
        child: child link name.
        transform: pose of the child link in the parent link (``T_parent_child``).
    """

    name: str
    joint_type: str
    parent: str
    child: str
    transform: SimilarityTransform


@dataclass(frozen=True, slots=True, eq=False)
class UrdfRobot:
    """A parsed URDF file.

    Attributes:
        name: the ``<robot name>``, or ``""`` when it has none.
        links: link names in file order, then links only named by joints.
        joints: the joints in file order.
    """

    name: str
    links: tuple[str, ...]
    joints: tuple[UrdfJoint, ...]


def read_urdf(urdf: Path) -> UrdfRobot:
    """Parse a URDF file into its robot name, links and joints.

    Args:
        urdf: path of a ``.urdf`` file (plain XML; expand ``.xacro`` files first).

    Returns:
        The robot.

    Raises:
        ReaderError: the file is missing, not UTF-8, holds a DOCTYPE or ENTITY
            declaration, is not well-formed XML, is not a URDF ``<robot>``, still holds
            xacro macros, or has a joint with a missing or malformed field.
    """
    try:
        raw = urdf.read_bytes()
    except FileNotFoundError as err:
        msg = f"URDF file {str(urdf)!r} does not exist; check the path."
        raise ReaderError(msg) from err
    except OSError as err:
        msg = f"URDF file {str(urdf)!r} cannot be read ({err.strerror}); check the permissions."
        raise ReaderError(msg) from err
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        msg = f"URDF file {str(urdf)!r} is not UTF-8 text; save it as UTF-8."
        raise ReaderError(msg) from err
    if _FORBIDDEN.search(text):
        msg = (
            f"URDF file {str(urdf)!r} holds a DOCTYPE or ENTITY declaration, which is "
            "refused for safety; remove it (URDF does not need one)."
        )
        raise ReaderError(msg)
    # An XML declaration naming another encoding would contradict the decoded text.
    text = re.sub(r"^\s*<\?xml[^>]*\?>", "", text, count=1)
    try:
        root = ET.fromstring(text)  # noqa: S314 (DOCTYPE/ENTITY rejected above)
    except ET.ParseError as err:
        msg = f"URDF file {str(urdf)!r} is not well-formed XML ({err}); fix the file."
        raise ReaderError(msg) from err
    if any(el.tag.startswith(f"{{{_XACRO_NS}}}") for el in root.iter()):
        msg = (
            f"URDF file {str(urdf)!r} still holds xacro macros; expand it first with "
            "'xacro FILE.urdf.xacro > FILE.urdf'."
        )
        raise ReaderError(msg)
    if root.tag != "robot":
        msg = (
            f"URDF file {str(urdf)!r} is XML but not a URDF (root element {root.tag!r}, "
            "expected 'robot'); pass the robot's URDF."
        )
        raise ReaderError(msg)
    joints = tuple(_parse_joint(el, urdf) for el in root.findall("joint"))
    named = [el.get("name", "") for el in root.findall("link")]
    links = dict.fromkeys(x for x in named if x)
    links.update(dict.fromkeys(x for j in joints for x in (j.parent, j.child)))
    return UrdfRobot(root.get("name", ""), tuple(links), joints)


def read_urdf_joints(urdf: Path) -> tuple[tuple[str, ...], tuple[UrdfJoint, ...]]:
    """Parse a URDF file into its link names and joints.

    Args:
        urdf: path of a ``.urdf`` file (plain XML; expand ``.xacro`` files first).

    Returns:
        The link names (sorted, including links only named by joints) and the joints.

    Raises:
        ReaderError: the file cannot be parsed (see :func:`read_urdf`).
    """
    robot = read_urdf(urdf)
    return tuple(sorted(robot.links)), robot.joints


def read_urdf_offset(urdf: Path, *, from_link: str, to_link: str) -> SimilarityTransform:
    """Return the fixed transform between two links of a URDF file.

    The result is ``T_from_to``: it maps ``to_link`` coordinates into ``from_link``
    coordinates, i.e. it is the pose of ``to_link`` in ``from_link``. With ``from_link``
    the motion-capture rigid body and ``to_link`` the camera, it is the device offset that
    :meth:`loceval.trajectory.Trajectory.with_body_offset` applies.

    Args:
        urdf: path of the URDF file.
        from_link: the link the offset is expressed in.
        to_link: the link whose pose is returned.

    Returns:
        The rigid transform (scale 1).

    Raises:
        ReaderError: the file cannot be parsed (see :func:`read_urdf_joints`), a link is
            not in the file, the links are not connected, or a joint on the path is not
            fixed.
    """
    links, joints = read_urdf_joints(urdf)
    for role, link in (("from_link", from_link), ("to_link", to_link)):
        if link not in links:
            msg = (
                f"Link {link!r} ({role}) is not in URDF file {str(urdf)!r}; links in the "
                f"file: {_listing(links)}; pass one of them."
            )
            raise ReaderError(msg)
    parent_joint: dict[str, UrdfJoint] = {}
    for joint in joints:
        if joint.child in parent_joint:
            msg = (
                f"Link {joint.child!r} is the child of two joints "
                f"({parent_joint[joint.child].name!r} and {joint.name!r}) in URDF file "
                f"{str(urdf)!r}; a URDF must be a tree, fix the file."
            )
            raise ReaderError(msg)
        parent_joint[joint.child] = joint
    up = _path_to_root(from_link, parent_joint, urdf)
    down = _path_to_root(to_link, parent_joint, urdf)
    up_links = [from_link] + [j.parent for j in up]
    down_links = [to_link] + [j.parent for j in down]
    common = next((x for x in down_links if x in set(up_links)), None)
    if common is None:
        msg = (
            f"Links {from_link!r} and {to_link!r} are not connected by joints in URDF file "
            f"{str(urdf)!r} (roots {up_links[-1]!r} and {down_links[-1]!r}); pick links of "
            "one tree."
        )
        raise ReaderError(msg)
    up_path = up[: up_links.index(common)]
    down_path = down[: down_links.index(common)]
    moving = [j for j in (*up_path, *down_path) if j.joint_type != "fixed"]
    if moving:
        names = ", ".join(f"{j.name!r} ({j.joint_type})" for j in moving)
        msg = (
            f"The path from {from_link!r} to {to_link!r} in URDF file {str(urdf)!r} passes "
            f"non-fixed joints {names}, whose offset depends on the joint state; describe "
            "the device with fixed joints."
        )
        raise ReaderError(msg)
    result = SimilarityTransform.identity()
    for joint in up_path:
        result = result.compose(joint.transform.inverse())
    for joint in reversed(down_path):
        result = result.compose(joint.transform)
    return result


def _path_to_root(link: str, parent_joint: dict[str, UrdfJoint], urdf: Path) -> list[UrdfJoint]:
    """Return the joints from ``link`` up to its tree's root."""
    path: list[UrdfJoint] = []
    seen = {link}
    while (joint := parent_joint.get(link)) is not None:
        if joint.parent in seen:
            msg = (
                f"The joints of URDF file {str(urdf)!r} form a loop through link "
                f"{joint.parent!r}; a URDF must be a tree, fix the file."
            )
            raise ReaderError(msg)
        path.append(joint)
        seen.add(joint.parent)
        link = joint.parent
    return path


def _parse_joint(element: ET.Element, urdf: Path) -> UrdfJoint:
    name = element.get("name", "")
    joint_type = element.get("type", "")
    parent_el, child_el = element.find("parent"), element.find("child")
    parent = "" if parent_el is None else parent_el.get("link", "")
    child = "" if child_el is None else child_el.get("link", "")
    if not (name and joint_type and parent and child):
        msg = (
            f"Joint {name!r} in URDF file {str(urdf)!r} lacks a name, type, parent link or "
            "child link; complete it."
        )
        raise ReaderError(msg)
    origin = element.find("origin")
    xyz = _vector(origin, "xyz", name, urdf)
    rpy = _vector(origin, "rpy", name, urdf)
    # URDF rpy is fixed-axis (extrinsic) x-y-z: R = Rz(yaw) Ry(pitch) Rx(roll).
    rotation = Rotation.from_euler("xyz", rpy).as_matrix()
    return UrdfJoint(name, joint_type, parent, child, SimilarityTransform(rotation, xyz))


def _vector(origin: ET.Element | None, key: str, joint: str, urdf: Path) -> FloatArray:
    text = None if origin is None else origin.get(key)
    if text is None:
        return np.zeros(3)
    try:
        values = np.array([float(x) for x in text.split()], dtype=np.float64)
    except ValueError as err:
        msg = (
            f"Joint {joint!r} in URDF file {str(urdf)!r} has origin {key}={text!r}, not three "
            "numbers; fix the value."
        )
        raise ReaderError(msg) from err
    if values.shape != (3,) or not np.isfinite(values).all():
        msg = (
            f"Joint {joint!r} in URDF file {str(urdf)!r} has origin {key}={text!r}, not three "
            "finite numbers; fix the value."
        )
        raise ReaderError(msg)
    return values


def _listing(names: tuple[str, ...]) -> str:
    if len(names) <= _MAX_LISTED:
        return ", ".join(names)
    return f"{', '.join(names[:_MAX_LISTED])} and {len(names) - _MAX_LISTED} more"
