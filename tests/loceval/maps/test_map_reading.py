"""Reading maps: map_server YAML with PGM or PNG, a zip of both, a bag topic; bad maps."""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np
import pytest

from loceval.errors import InputError, ReaderError
from loceval.maps import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, read_map
from tests.mapfactory import write_map_server


def _grid() -> OccupancyGrid:
    """A 30 x 40 grid: unknown border, free inside, an occupied wall and a corner mark."""
    states = np.full((30, 40), UNKNOWN, dtype=np.int8)
    states[2:-2, 2:-2] = FREE
    states[10, 5:30] = OCCUPIED
    states[0, 0] = OCCUPIED  # row 0 is the origin's row: it must stay at the bottom
    return OccupancyGrid(states, 0.05, (-1.5, 2.0), 0.0, source="t")


@pytest.mark.parametrize("suffix", [".pgm", ".png"])
def test_map_server_pair_round_trips(tmp_path: Path, suffix: str) -> None:
    """States, resolution and origin come back; the image's top row is the far edge."""
    grid = _grid()
    found = read_map(str(write_map_server(tmp_path, grid, suffix=suffix)))
    np.testing.assert_array_equal(found.states, grid.states)
    assert found.resolution_m == 0.05
    assert found.origin_xy == (-1.5, 2.0)
    centre = found.cell_centres(np.array([0]), np.array([0]))
    np.testing.assert_allclose(centre, [[-1.475, 2.025]])


def test_negate_and_thresholds_are_read(tmp_path: Path) -> None:
    """negate: 1 reads white as occupied; grey between the thresholds is unknown."""
    width, height = 3, 1
    (tmp_path / "m.pgm").write_bytes(b"P2\n3 1\n255\n0 128 255\n")
    (tmp_path / "m.yaml").write_text(
        "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 1\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.2\n",
        encoding="utf-8",
    )
    found = read_map(str(tmp_path / "m.yaml"))
    assert found.shape == (height, width)
    assert found.states.tolist() == [[FREE, UNKNOWN, OCCUPIED]]


def test_a_zip_of_the_pair_is_read(tmp_path: Path) -> None:
    """A zip holding the YAML and the image in a folder reads like the pair."""
    yaml = write_map_server(tmp_path / "src", _grid())
    zipped = tmp_path / "map.zip"
    with zipfile.ZipFile(zipped, "w") as archive:
        archive.write(yaml, "floor2/map.yaml")
        archive.write(tmp_path / "src" / "map.pgm", "floor2/map.pgm")
    np.testing.assert_array_equal(read_map(str(zipped)).states, _grid().states)


def test_a_yaw_turns_the_cells() -> None:
    """origin yaw 90°: the first column runs along +y of the map frame."""
    grid = OccupancyGrid(_grid().states, 0.1, (1.0, 1.0), math.pi / 2)
    centres = grid.cell_centres(np.array([0, 0]), np.array([0, 1]))
    np.testing.assert_allclose(centres, [[0.95, 1.05], [0.95, 1.15]], atol=1e-12)
    rows, cols, inside = grid.cell_of(centres)
    assert rows.tolist() == [0, 0]
    assert cols.tolist() == [0, 1]
    assert inside.all()


def test_an_occupancy_grid_topic_is_read(tmp_path: Path) -> None:
    """The last nav_msgs/msg/OccupancyGrid of a ROS 2 bag topic, with origin and yaw."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    values = np.full((4, 5), -1, dtype=np.int8)
    values[1, 1:4] = 0
    values[2, 2] = 100
    yaw = 0.3

    def message(stamp_s: int, data: np.ndarray) -> object:
        header = types["std_msgs/msg/Header"](
            stamp=types["builtin_interfaces/msg/Time"](sec=stamp_s, nanosec=0), frame_id="map"
        )
        pose = types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=1.0, y=-2.0, z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
            ),
        )
        info = types["nav_msgs/msg/MapMetaData"](
            map_load_time=types["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
            resolution=0.05,
            width=5,
            height=4,
            origin=pose,
        )
        return types["nav_msgs/msg/OccupancyGrid"](header=header, info=info, data=data.ravel())

    bag = tmp_path / "run"
    with Writer(bag, version=9) as writer:
        conn = writer.add_connection("/map", "nav_msgs/msg/OccupancyGrid", typestore=store)
        first = message(1, np.zeros((4, 5), dtype=np.int8))
        writer.write(conn, 1_000_000_000, store.serialize_cdr(first, conn.msgtype))
        last = message(2, values)
        writer.write(conn, 2_000_000_000, store.serialize_cdr(last, conn.msgtype))
    found = read_map(f"{bag}@/map")
    assert found.states[2, 2] == OCCUPIED
    assert found.states[1, 1] == FREE
    assert found.states[0, 0] == UNKNOWN
    assert found.origin_xy == (1.0, -2.0)
    assert found.origin_yaw_rad == pytest.approx(yaw)
    assert found.stamp_ns == 2_000_000_000
    with pytest.raises(ReaderError, match=r"'/scan' is not in bag.*/map"):
        read_map(f"{bag}@/scan")


def test_a_pgm_that_does_not_match_its_header_is_refused(tmp_path: Path) -> None:
    """Fewer pixels than the header declares: the image does not belong to the map."""
    yaml = write_map_server(tmp_path, _grid())
    pgm = tmp_path / "map.pgm"
    pgm.write_bytes(pgm.read_bytes()[:-10])
    with pytest.raises(ReaderError, match="truncated or does not belong to this map"):
        read_map(str(yaml))


def test_a_huge_declared_size_is_refused_before_reading(tmp_path: Path) -> None:
    """A header declaring 10^10 cells is refused by its size, naming the limit."""
    yaml = write_map_server(tmp_path, _grid())
    (tmp_path / "map.pgm").write_bytes(b"P5\n100000 100000\n255\n\x00")
    with pytest.raises(InputError, match=r"100000 x 100000 cells .* more than the 100,000,000"):
        read_map(str(yaml))


@pytest.mark.parametrize(
    ("yaml_text", "match"),
    [
        ("image: map.pgm\n", "lacks resolution, origin"),
        ("image: map.pgm\nresolution: -1\norigin: [0, 0, 0]\n", "must be positive"),
        ("image: map.pgm\nresolution: 0.05\norigin: [0, 0]\n", r"origin must be \[x, y, yaw\]"),
        ("[1, 2\n", "not valid YAML"),
    ],
)
def test_a_bad_yaml_is_refused(tmp_path: Path, yaml_text: str, match: str) -> None:
    """Missing keys, a negative resolution, a short origin, broken YAML: ReaderError."""
    write_map_server(tmp_path, _grid())
    (tmp_path / "map.yaml").write_text(yaml_text, encoding="utf-8")
    with pytest.raises(ReaderError, match=match):
        read_map(str(tmp_path / "map.yaml"))


def test_an_image_of_another_kind_is_refused(tmp_path: Path) -> None:
    """A JPEG (or anything) named map.pgm: neither PGM nor PNG."""
    yaml = write_map_server(tmp_path, _grid())
    (tmp_path / "map.pgm").write_bytes(b"\xff\xd8\xff\xe0 not a map")
    with pytest.raises(ReaderError, match="neither a PGM"):
        read_map(str(yaml))


def test_a_source_that_is_no_map_is_refused(tmp_path: Path) -> None:
    """A text file, a missing file: InputError naming the accepted sources."""
    other = tmp_path / "notes.txt"
    other.write_text("x", encoding="utf-8")
    with pytest.raises(InputError, match="not a map_server YAML"):
        read_map(str(other))
    with pytest.raises(InputError, match="does not exist"):
        read_map(str(tmp_path / "nope.yaml"))
