"""The command line on recordings: bags, tf chains, device offsets, inspection."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from service.cli import main
from tests import bagfactory as bf

EVO = json.loads((Path(__file__).parents[2] / "data" / "evo_1.38.1.json").read_text())["cases"]


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, object]:
    assert main(list(argv)) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)  # type: ignore[no-any-return]


@pytest.mark.public_data
def test_ros1_bag_topics_agree_with_evo(
    public_data: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """ROS_example.bag@groundtruth vs @ORB-SLAM and @S-PTAM give evo's ATE (evo_ape bag ... -a)."""
    bag = public_data / "ROS_example.bag"
    doc = _json(
        capsys, "evaluate", f"{bag}@groundtruth", f"{bag}@ORB-SLAM", f"{bag}@S-PTAM",
        "--associate", "nearest", "--max-dt", "0.01", "--json",
    )  # fmt: skip
    estimates = doc["estimates"]
    assert isinstance(estimates, list)
    for est, key in zip(estimates, ("bag_orb_ape_se3", "bag_sptam_ape_se3"), strict=True):
        ate = est["ate"]["translation_m"]
        assert ate["n"] == EVO[key]["n"]
        assert ate["rmse"] == pytest.approx(EVO[key]["rmse"], rel=1e-4), EVO[key]["command"]
        assert ate["max"] == pytest.approx(EVO[key]["max"], rel=1e-4)


@pytest.mark.public_data
def test_nav2_sources_evaluate(public_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """nav2_turtlebot.mcap: /amcl_pose against the tf chain map->base_link and /odom."""
    mcap = public_data / "nav2_turtlebot.mcap"
    sources = [f"{mcap}@/amcl_pose", f"{mcap}@tf:map:base_link", f"{mcap}@/odom"]
    sparse = _json(capsys, "evaluate", *sources, "--json")
    # AMCL publishes about once a second: its gaps are judged against its own rate
    # (issue 12), so interpolating it at the estimates' stamps keeps most of them.
    matched = [e["matched"] for e in sparse["estimates"]]  # type: ignore[index]
    poses = [e["poses"] for e in sparse["estimates"]]  # type: ignore[index]
    assert all(m > 0.9 * p for m, p in zip(matched, poses, strict=True)), (matched, poses)
    doc = _json(
        capsys, "evaluate", *sources, "--associate", "nearest", "--max-dt", "0.05", "--json"
    )
    reference = doc["reference"]
    assert isinstance(reference, dict)
    assert reference["poses"] == 135
    tf_chain, odom = doc["estimates"]  # type: ignore[misc]
    assert tf_chain["name"] == "tf:map:base_link"
    assert tf_chain["matched"] > 100
    # AMCL's map->odom correction is part of the tf chain, so it tracks AMCL far better.
    assert tf_chain["ate"]["translation_m"]["rmse"] < odom["ate"]["translation_m"]["rmse"]


@pytest.mark.public_data
def test_inspect_a_bag(public_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """inspect lists topics, the tf tree and ready-to-type selectors."""
    doc = _json(capsys, "inspect", str(public_data / "nav2_turtlebot.mcap"), "--json")
    selectors = json.dumps(doc)
    assert "/amcl_pose" in selectors
    assert "tf:map:base_link" in selectors
    assert main(["inspect", str(public_data / "nav2_turtlebot.mcap")]) == 0
    assert "/amcl_pose" in capsys.readouterr().out


def test_inspect_a_text_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """inspect on a TUM file reports its format, poses and time range."""
    path = tmp_path / "gt.txt"
    t = np.arange(10) * 0.1
    np.savetxt(path, np.column_stack([t, t, 0 * t, 0 * t, 0 * t, 0 * t, 0 * t, 1 + 0 * t]))
    doc = _json(capsys, "inspect", str(path), "--json")
    assert doc["format"] == "tum"
    assert doc["poses"] == 10


def test_unknown_topic_lists_what_is_there(
    tmp_path: Path, rng: np.random.Generator, capsys: pytest.CaptureFixture[str]
) -> None:
    """A topic that is not in the bag: exit 1 and the message lists the bag's topics."""
    poses = bf.random_poses(rng, 20, dt_ns=50_000_000)
    bag = bf.write_bag(
        bf.bag_path(tmp_path, "mcap"), bf.pose_records("/gt", bf.POSE, poses), fmt="mcap"
    )
    assert main(["evaluate", f"{bag}@/gt", f"{bag}@/slam"]) == 1
    err = capsys.readouterr().err
    assert "/slam" in err
    assert "/gt" in err
    assert "Traceback" not in err


URDF = """<?xml version="1.0"?>
<robot name="handheld">
  <link name="rigid_body"/>
  <link name="mount"/>
  <link name="camera_link"/>
  <joint name="body_to_mount" type="fixed">
    <parent link="rigid_body"/><child link="mount"/>
    <origin xyz="0.10 0 0.05" rpy="0 0 1.5707963267948966"/>
  </joint>
  <joint name="mount_to_camera" type="fixed">
    <parent link="mount"/><child link="camera_link"/>
    <origin xyz="0.02 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"""


def test_urdf_device_offset_gives_the_true_answer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Markers' rigid body vs a camera 0.10 m ahead, 0.05 m up, 0.02 m left: offset ATE = 0."""
    n = 300
    t = np.arange(n) * 0.01
    body_xyz = np.stack([np.cos(t), np.sin(2 * t), 0.1 * t], 1)
    body = Rotation.from_euler("xyz", np.stack([0.1 * t, 0.2 * np.sin(t), t], 1))
    # The camera's pose: rigid body -> mount (0.1, 0, 0.05, yaw 90°) -> camera (0.02, 0, 0).
    cam_xyz = body_xyz + body.apply([0.10, 0.02, 0.05])
    cam = body * Rotation.from_euler("z", 90, degrees=True)
    ref, est = tmp_path / "body.tum", tmp_path / "camera.tum"
    np.savetxt(ref, np.column_stack([t, body_xyz, body.as_quat()]), fmt="%.12f")
    np.savetxt(est, np.column_stack([t, cam_xyz, cam.as_quat()]), fmt="%.12f")
    urdf = tmp_path / "device.urdf"
    urdf.write_text(URDF)
    common = ["evaluate", str(ref), str(est), "--align", "none", "--json"]
    without = _json(capsys, *common)
    with_offset = _json(
        capsys, *common, "--device", str(urdf), "--device-from", "rigid_body",
        "--device-to", "camera_link",
    )  # fmt: skip
    ate = lambda doc: doc["estimates"][0]["ate"]  # noqa: E731
    assert ate(without)["translation_m"]["max"] > 0.1
    assert ate(with_offset)["translation_m"]["max"] < 1e-9
    assert ate(with_offset)["rotation_deg"]["max"] < 1e-6
    assert main([*common, "--device", str(urdf), "--device-from", "rigid_body",
                 "--device-to", "lens"]) == 1  # fmt: skip
    assert "lens" in capsys.readouterr().err


def test_a_bag_with_only_its_magic_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An MCAP file cut right after its magic bytes: exit 1, 'truncated', no traceback."""
    bag = tmp_path / "cut.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n")
    for argv in (["inspect", str(bag)], ["evaluate", f"{bag}@/a", f"{bag}@/b"]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert "truncated" in err
        assert "Traceback" not in err
