"""A map topic over time: every OccupancyGrid message judged, the last in full.

The bags are written here with rosbags: a map that grows more wrong as the run goes on
(scale 1.000, 0.995, 0.990, 0.985 of the plan, published at 10, 20, 30, 40 s) after an
empty first message (no wall yet), 2 cm cells. The known scales (0, -0.5, -1, -1.5 %)
come back as ``scale_error_pct`` within 0.05 % (measured -0.000, -0.510, -1.003,
-1.496 %: the cells' quantisation, each wall snapped by up to half a cell, 1 cm, at up to
10 m from the centre; 5 cm cells gave errors up to 0.09 %); the empty message is listed
with its reason, and a topic of more messages than the limit is subsampled with a note.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from loceval.core.geometry import SimilarityTransform
from loceval.errors import InputError
from loceval.maps import OccupancyGrid, evaluate_map_source
from loceval.readers.rosbag.grid import kept_indices
from tests.mapfactory import Distortion, draw_map, office_plan, write_map_bag

NS = 1_000_000_000
SCALES = (1.000, 0.995, 0.990, 0.985)
T0_NS = 5 * NS  # the reference's first stamp: the history's times are seconds since it


@pytest.fixture(scope="module", name="plan")
def _plan() -> np.ndarray:
    return office_plan()


@pytest.fixture(scope="module", name="bag")
def _bag(tmp_path_factory: pytest.TempPathFactory, plan: np.ndarray) -> Path:
    """An empty first map at 5 s, then maps 0, 0.5, 1 and 1.5 % short at 10-40 s."""
    rng = np.random.default_rng(11)
    grids = [
        (10 * (k + 1), draw_map(plan, Distortion(scale=s), resolution_m=0.02, rng=rng))
        for k, s in enumerate(SCALES)
    ]
    empty = OccupancyGrid(np.full(grids[0][1].shape, -1, dtype=np.int8), 0.02, source="gen")
    return write_map_bag(tmp_path_factory.mktemp("maps"), [(5, empty), *grids])


def test_each_message_is_judged_and_the_drift_shows(bag: Path, plan: np.ndarray) -> None:
    """history: the empty map with its reason, then the known scale of each message."""
    found = evaluate_map_source(
        f"{bag}@/map", plan, SimilarityTransform.identity(), t0_ns=T0_NS, display="run@/map"
    )
    assert found.source == "run@/map"
    assert [s.index for s in found.history] == [0, 1, 2, 3, 4]
    assert found.history_note is None
    first, *judged = found.history
    assert first.note is not None
    assert "no occupied cell" in first.note
    assert first.placed_rmse_m is None
    assert [s.t_s for s in found.history] == [0.0, 5.0, 15.0, 25.0, 35.0]
    pct = [s.scale_error_pct for s in judged]
    np.testing.assert_allclose(pct, [(s - 1) * 100 for s in SCALES], atol=0.05)
    # the last message is the map judged in full: its snapshot is its figures
    assert judged[-1].similarity_rmse_m == found.similarity[1].rmse
    assert found.scale_error_pct == judged[-1].scale_error_pct
    # a shrinking map placed as it is drifts away from the plan: the placed RMSE grows
    placed = [s.placed_rmse_m for s in judged]
    assert placed == sorted(placed)  # type: ignore[type-var]
    doc = found.to_dict()
    assert len(doc["history"]) == 5  # type: ignore[arg-type]
    assert doc["history"][0]["note"] == first.note  # type: ignore[index]


def test_a_long_topic_is_subsampled_with_a_note(bag: Path, plan: np.ndarray) -> None:
    """Past the limit, evenly spread messages (first and last kept) and a note saying so."""
    found = evaluate_map_source(f"{bag}@/map", plan, SimilarityTransform.identity(), max_messages=3)
    assert [s.index for s in found.history] == [0, 2, 4]
    assert found.history_note is not None
    assert "5 map messages; 3 of them" in found.history_note
    assert found.history[-1].t_s is None  # no reference time given


def test_kept_indices_keep_the_last() -> None:
    """All when few; evenly spread with the first and the last; the last alone for 1."""
    assert kept_indices(4, 30).tolist() == [0, 1, 2, 3]
    assert kept_indices(100, 5).tolist() == [0, 25, 50, 74, 99]
    assert kept_indices(100, 1).tolist() == [99]


def test_a_topic_whose_last_map_is_empty_is_refused(tmp_path: Path, plan: np.ndarray) -> None:
    """The last message is the map judged: an empty last map is the evaluation's error."""
    good = draw_map(plan, Distortion(), resolution_m=0.05, rng=np.random.default_rng(1))
    empty = OccupancyGrid(np.full(good.shape, -1, dtype=np.int8), 0.05, source="gen")
    bag = write_map_bag(tmp_path, [(1, good), (2, empty)])
    with pytest.raises(InputError, match="no occupied cell"):
        evaluate_map_source(f"{bag}@/map", plan, SimilarityTransform.identity())


def test_a_map_file_has_no_history(tmp_path: Path, plan: np.ndarray) -> None:
    """map.yaml is one map: no history, no note."""
    from tests.mapfactory import write_map_server

    grid = draw_map(plan, Distortion(scale=0.99), resolution_m=0.05, rng=np.random.default_rng(2))
    yaml = write_map_server(tmp_path, grid)
    found = evaluate_map_source(str(yaml), plan, SimilarityTransform.identity())
    assert found.history == ()
    assert found.to_dict()["history"] == []
