"""Selectors are checked against the upload's stored inspection when the evaluation is sent.

A tf chain with a frame the bag lacks, a topic that is not in the bag or a rigid body that
is not in the take is a 422 at once, and nothing is queued (before, the job failed later).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests import bagfactory
from tests.service._api_fixtures import Api, assert_problem, tum_pair

CHEAP = {"formats": ["result.json"]}


@pytest.fixture
def truth_id(api: Api, rng: np.random.Generator, tmp_path: Path) -> str:
    """The id of an uploaded TUM reference (200 poses, 100 Hz)."""
    return str(api.dataset("truth.txt", tum_pair(rng, tmp_path)[0])["id"])


@pytest.fixture
def bag_id(api: Api, rng: np.random.Generator, tmp_path: Path) -> str:
    """A bag with /pose, the tree map -> base_link and a separate tree rig -> tracker."""
    poses = bagfactory.random_poses(rng, 50, dt_ns=20_000_000)
    records = [
        *bagfactory.pose_records("/pose", bagfactory.POSE, poses),
        *bagfactory.tf_records(bagfactory.link_transforms("map", "base_link", poses)),
        *bagfactory.tf_records(bagfactory.link_transforms("rig", "tracker", poses)),
    ]
    bag = bagfactory.write_bag(tmp_path / "run.bag", records, fmt="rosbag1")
    return str(api.dataset("run.bag", bag.read_bytes())["id"])


@pytest.mark.parametrize(
    ("selector", "detail"),
    [
        ("tf:world:base_link", r"'run\.bag' has no tf frame 'world'; its tf frames are: "),
        ("tf:map:camera", r"has no tf frame 'camera'"),
        (
            "tf:map:tracker",
            r"'map' and 'tracker' are in separate trees \(rooted at 'map' and 'rig'\)",
        ),
        ("tf:map", r"'tf:map' is not a tf chain; write tf:PARENT:CHILD"),
        ("tf:map:base_link:x", r"is not a tf chain"),
        ("/odom", r"has no topic '/odom'; its trajectory sources are: /pose"),
    ],
)
def test_bag_selector_refused_at_submit(
    api: Api, truth_id: str, bag_id: str, selector: str, detail: str
) -> None:
    """An unreadable bag selector is a 422 naming the frame or topic; nothing is queued."""
    body = {
        "reference": {"dataset_id": truth_id},
        "estimates": [{"dataset_id": bag_id, "selector": selector}],
        "options": CHEAP,
    }
    problem = assert_problem(api.evaluate(body), 422, type_="input.invalid", detail=detail)
    assert "estimate dataset" in problem["detail"]
    assert api.evaluation_count() == 0


def test_readable_tf_chain_is_accepted(api: Api, bag_id: str) -> None:
    """tf:map:base_link on the same bag passes the check and the evaluation runs."""
    body = {
        "reference": {"dataset_id": bag_id, "selector": "/pose"},
        "estimates": [{"dataset_id": bag_id, "selector": "tf:map:base_link"}],
        "options": CHEAP,
    }
    evaluation = api.evaluate(body).json()
    assert evaluation["status"] == "succeeded", evaluation
    assert api.evaluation_count() == 1


@pytest.mark.public_data
def test_motive_body_not_in_take(api: Api, truth_id: str, public_data: Path) -> None:
    """A rigid body the take does not hold is a 422 listing the take's bodies."""
    take = api.dataset("take.csv", (public_data / "motive_take_sample.csv").read_bytes())
    body = {
        "reference": {"dataset_id": truth_id},
        "estimates": [{"dataset_id": take["id"], "selector": "Helmet"}],
        "options": CHEAP,
    }
    assert_problem(api.evaluate(body), 422, detail=r"holds the rigid bodies .*; choose one")
    assert api.evaluation_count() == 0


@pytest.mark.public_data
def test_nav2_world_chain_refused_at_once(api: Api, truth_id: str, public_data: Path) -> None:
    """nav2_turtlebot.mcap has no 'world': tf:world:base_link is a 422, not a 202 that fails."""
    bag = api.dataset("nav2.mcap", (public_data / "nav2_turtlebot.mcap").read_bytes())
    body = {
        "reference": {"dataset_id": truth_id},
        "estimates": [{"dataset_id": bag["id"], "selector": "tf:world:base_link"}],
        "options": CHEAP,
    }
    assert_problem(
        api.evaluate(body),
        422,
        detail=r"has no tf frame 'world'; its tf frames are: map, base_link, left_wheel, "
        r"odom, right_wheel, base_footprint, .* and 22 more\.$",
    )
    assert api.evaluation_count() == 0
