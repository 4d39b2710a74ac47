"""Inspect a URDF file: the robot's links and joints (it holds no trajectory)."""

from __future__ import annotations

from loceval.inspection.model import Inspection, JointInspection
from loceval.readers import SourceSpec
from loceval.readers.urdf import read_urdf

__all__ = ["inspect_urdf"]


def inspect_urdf(spec: SourceSpec) -> Inspection:
    """Describe a URDF file: robot name, links in file order, joints.

    Args:
        spec: the URDF file (no selector or options are used).

    Returns:
        The inspection (kind and format ``urdf``, no sources).

    Raises:
        ReaderError: the file is not a readable URDF (see :func:`loceval.readers.urdf.read_urdf`).
    """
    robot = read_urdf(spec.path)
    return Inspection(
        path=str(spec.path),
        kind="urdf",
        format="urdf",
        sources=(),
        robot=robot.name,
        links=robot.links,
        joints=tuple(
            JointInspection(j.name, j.joint_type, j.parent, j.child) for j in robot.joints
        ),
    )
