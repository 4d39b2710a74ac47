"""Tests for loceval.readers.urdf: device offsets from fixed joints."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from loceval.errors import ReaderError
from loceval.readers.urdf import read_urdf, read_urdf_joints, read_urdf_offset


def rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def homogeneous(rotation: np.ndarray, xyz: tuple[float, float, float]) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = xyz
    return m


DEVICE = """<?xml version="1.0"?>
<robot name="device">
  <link name="base"/>
  <link name="rigid_body"/>
  <link name="mount"/>
  <link name="camera"/>
  <link name="wheel"/>
  <joint name="base_to_body" type="fixed">
    <parent link="base"/>
    <child link="rigid_body"/>
    <origin xyz="0.1 -0.05 0.3" rpy="0.2 -0.4 1.1"/>
  </joint>
  <joint name="base_to_mount" type="fixed">
    <parent link="base"/>
    <child link="mount"/>
    <origin xyz="0.25 0 0.1" rpy="0 0 1.5707963267948966"/>
  </joint>
  <joint name="mount_to_camera" type="fixed">
    <parent link="mount"/>
    <child link="camera"/>
    <origin xyz="0 0.02 0.04" rpy="-1.5707963267948966 0 -1.5707963267948966"/>
  </joint>
  <joint name="base_to_wheel" type="continuous">
    <parent link="base"/>
    <child link="wheel"/>
    <origin xyz="0 0.2 0"/>
    <axis xyz="0 1 0"/>
  </joint>
</robot>
"""


@pytest.fixture
def device(tmp_path: Path) -> Path:
    path = tmp_path / "device.urdf"
    path.write_text(DEVICE)
    return path


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "robot.urdf"
    path.write_text(text)
    return path


def test_rpy_is_fixed_axis_roll_pitch_yaw(device):
    """A joint's rpy gives R = Rz(yaw) Ry(pitch) Rx(roll) and its xyz the translation."""
    offset = read_urdf_offset(device, from_link="base", to_link="rigid_body")
    np.testing.assert_allclose(offset.rotation, rz(1.1) @ ry(-0.4) @ rx(0.2), atol=1e-12)
    np.testing.assert_allclose(offset.translation, [0.1, -0.05, 0.3], atol=1e-12)
    assert offset.scale == 1.0


def test_offset_up_and_down_the_tree(device):
    """rigid_body -> camera goes up to base and down through mount, known analytically."""
    t_base_body = homogeneous(rz(1.1) @ ry(-0.4) @ rx(0.2), (0.1, -0.05, 0.3))
    t_base_mount = homogeneous(rz(math.pi / 2), (0.25, 0.0, 0.1))
    t_mount_camera = homogeneous(rz(-math.pi / 2) @ rx(-math.pi / 2), (0.0, 0.02, 0.04))
    expected = np.linalg.inv(t_base_body) @ t_base_mount @ t_mount_camera
    offset = read_urdf_offset(device, from_link="rigid_body", to_link="camera")
    np.testing.assert_allclose(offset.as_matrix(), expected, atol=1e-12)


def test_camera_optical_convention(device):
    """The optical rpy (-pi/2, 0, -pi/2) maps the camera's z axis to the mount's x axis."""
    offset = read_urdf_offset(device, from_link="mount", to_link="camera")
    np.testing.assert_allclose(offset.rotation @ [0, 0, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(offset.rotation @ [1, 0, 0], [0, -1, 0], atol=1e-12)


def test_reverse_offset_is_inverse(device):
    """camera -> rigid_body is the inverse of rigid_body -> camera."""
    forward = read_urdf_offset(device, from_link="rigid_body", to_link="camera")
    backward = read_urdf_offset(device, from_link="camera", to_link="rigid_body")
    np.testing.assert_allclose(backward.as_matrix(), np.linalg.inv(forward.as_matrix()), atol=1e-12)


def test_same_link_is_identity(device):
    """The offset of a link to itself is the identity."""
    offset = read_urdf_offset(device, from_link="camera", to_link="camera")
    np.testing.assert_allclose(offset.as_matrix(), np.eye(4))


def test_missing_origin_is_identity(tmp_path):
    """A joint without <origin> places the child on the parent."""
    path = write(
        tmp_path,
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j" type="fixed"><parent link="a"/><child link="b"/></joint></robot>',
    )
    np.testing.assert_allclose(
        read_urdf_offset(path, from_link="a", to_link="b").as_matrix(), np.eye(4)
    )


def test_non_fixed_joint_on_path_is_named(device):
    """A continuous joint between the links is refused, naming it and its type."""
    with pytest.raises(ReaderError, match=r"'base_to_wheel' \(continuous\)"):
        read_urdf_offset(device, from_link="camera", to_link="wheel")


def test_non_fixed_joint_elsewhere_is_fine(device, tmp_path):
    """Moving joints off the path do not matter: the offset is the one without them."""
    offset = read_urdf_offset(device, from_link="camera", to_link="rigid_body").as_matrix()
    wheel = DEVICE.index('  <joint name="base_to_wheel"')
    fixed_only = tmp_path / "fixed_only.urdf"
    fixed_only.write_text(DEVICE[:wheel] + DEVICE[DEVICE.index("</joint>", wheel) + 9 :])
    assert "continuous" not in fixed_only.read_text()
    expected = read_urdf_offset(fixed_only, from_link="camera", to_link="rigid_body").as_matrix()
    np.testing.assert_array_equal(offset, expected)
    assert not np.allclose(offset, np.eye(4))


def test_unknown_link_lists_links(device):
    """An unknown link names the links in the file."""
    with pytest.raises(ReaderError, match=r"'lidar'.*base, camera, mount, rigid_body, wheel"):
        read_urdf_offset(device, from_link="lidar", to_link="camera")


def test_disconnected_links(tmp_path):
    """Links of two separate trees are not connected."""
    path = write(
        tmp_path,
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/><link name="d"/>'
        '<joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>'
        '<joint name="j2" type="fixed"><parent link="c"/><child link="d"/></joint></robot>',
    )
    with pytest.raises(ReaderError, match="not connected"):
        read_urdf_offset(path, from_link="b", to_link="d")


def test_two_parents_rejected(tmp_path):
    """A link that is the child of two joints is not a tree."""
    path = write(
        tmp_path,
        '<robot name="r"><link name="a"/><link name="b"/><link name="c"/>'
        '<joint name="j1" type="fixed"><parent link="a"/><child link="c"/></joint>'
        '<joint name="j2" type="fixed"><parent link="b"/><child link="c"/></joint></robot>',
    )
    with pytest.raises(ReaderError, match=r"child of two joints \('j1' and 'j2'\)"):
        read_urdf_offset(path, from_link="a", to_link="c")


def test_loop_rejected(tmp_path):
    """Joints that form a loop are reported."""
    path = write(
        tmp_path,
        '<robot name="r"><link name="a"/><link name="b"/>'
        '<joint name="j1" type="fixed"><parent link="a"/><child link="b"/></joint>'
        '<joint name="j2" type="fixed"><parent link="b"/><child link="a"/></joint></robot>',
    )
    with pytest.raises(ReaderError, match="loop"):
        read_urdf_offset(path, from_link="a", to_link="b")


@pytest.mark.parametrize(
    "header",
    [
        '<!DOCTYPE robot [<!ENTITY x "boom">]>',
        '<!doctype robot SYSTEM "file:///etc/passwd">',
        '<!ENTITY lol "lol">',
    ],
)
def test_doctype_and_entities_refused(tmp_path, header):
    """DOCTYPE and ENTITY declarations are refused before parsing."""
    path = write(tmp_path, f'<?xml version="1.0"?>\n{header}\n<robot name="r"/>')
    with pytest.raises(ReaderError, match="DOCTYPE or ENTITY"):
        read_urdf_joints(path)


def test_xacro_refused(tmp_path):
    """Unexpanded xacro macros are refused with the command to expand them."""
    path = write(
        tmp_path,
        '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="w" value="1"/></robot>',
    )
    with pytest.raises(ReaderError, match="xacro"):
        read_urdf_joints(path)


def test_read_urdf_keeps_file_order(device, tmp_path):
    """read_urdf gives the robot's name, links in file order and joints in file order."""
    robot = read_urdf(device)
    assert robot.name == "device"
    assert robot.links == ("base", "rigid_body", "mount", "camera", "wheel")
    assert [j.name for j in robot.joints] == [
        "base_to_body",
        "base_to_mount",
        "mount_to_camera",
        "base_to_wheel",
    ]
    only_joint = write(
        tmp_path,
        '<robot><link name="b"/><joint name="j" type="fixed"><parent link="b"/>'
        '<child link="a"/></joint></robot>',
    )
    assert read_urdf(only_joint).links == ("b", "a")  # "a" is only named by the joint
    assert read_urdf(only_joint).name == ""


def test_not_a_robot_says_so(tmp_path):
    """A root element other than <robot> is XML but not a URDF."""
    with pytest.raises(ReaderError, match=r"XML but not a URDF \(root element 'html'"):
        read_urdf(write(tmp_path, "<html><body/></html>"))


def test_not_a_robot(tmp_path):
    """A root element other than <robot> is refused."""
    with pytest.raises(ReaderError, match="root element 'sdf'"):
        read_urdf_joints(write(tmp_path, '<sdf version="1.6"/>'))


def test_malformed_xml(tmp_path):
    """Broken XML is a ReaderError, not a ParseError."""
    with pytest.raises(ReaderError, match="not well-formed"):
        read_urdf_joints(write(tmp_path, '<robot name="r"><link name="a">'))


def test_missing_file(tmp_path):
    """A missing URDF file is a ReaderError naming the path."""
    with pytest.raises(ReaderError, match="does not exist"):
        read_urdf_joints(tmp_path / "nope.urdf")


def test_not_utf8(tmp_path):
    """A file that is not UTF-8 text is refused."""
    path = tmp_path / "robot.urdf"
    path.write_bytes(b'<robot name="\xff\xfe"/>')
    with pytest.raises(ReaderError, match="not UTF-8"):
        read_urdf_joints(path)


@pytest.mark.parametrize("xyz", ["1 2", "a b c", "1 2 nan"])
def test_bad_origin(tmp_path, xyz):
    """An origin that is not three finite numbers names the joint and the value."""
    path = write(
        tmp_path,
        '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="fixed">'
        f'<parent link="a"/><child link="b"/><origin xyz="{xyz}"/></joint></robot>',
    )
    with pytest.raises(ReaderError, match=rf"Joint 'j'.*xyz='{xyz}'"):
        read_urdf_joints(path)


def test_incomplete_joint(tmp_path):
    """A joint without a child link is refused."""
    path = write(
        tmp_path, '<robot name="r"><joint name="j" type="fixed"><parent link="a"/></joint></robot>'
    )
    with pytest.raises(ReaderError, match="Joint 'j'"):
        read_urdf_joints(path)


def test_joints_and_links_listed(device):
    """read_urdf_joints returns every link and joint with its type."""
    links, joints = read_urdf_joints(device)
    assert links == ("base", "camera", "mount", "rigid_body", "wheel")
    assert {j.name: j.joint_type for j in joints}["base_to_wheel"] == "continuous"
