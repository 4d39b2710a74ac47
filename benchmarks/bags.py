"""Benchmark: extract a tf chain from a large ROS 2 MCAP bag full of camera images.

Run by hand (generation of the >= 2 GB bag takes a minute or two and is reused):

    .venv/bin/python -m benchmarks.bags [--workdir benchmarks/_work] [--seconds 160]

The bag holds /tf at 120 Hz (map->odom and odom->base_link in one TFMessage), /tf_static
(base_link->camera_link) and a 640x480 rgb8 sensor_msgs/msg/Image at 15 Hz. The benchmark
reports, in the same warm page-cache state:

- the wall time of ``cat BAG > /dev/null`` (best of three),
- the time of ``read_bag_trajectory(BAG, "tf:map:base_link")`` measured inside a child
  process (best of three) and the child's whole wall time including interpreter start and
  imports, with their ratios to ``cat``,
- the child's peak RSS (``resource.getrusage(RUSAGE_CHILDREN)``),
- the time of ``inspect_recording(BAG)``.

Targets: extraction < 1.5x the ``cat`` time and peak RSS < 300 MB.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from loceval.inspection import inspect_recording
from loceval.readers.rosbag import read_bag_trajectory

IMAGE_HZ = 15
TF_HZ = 120
WIDTH, HEIGHT = 640, 480
TARGET_RATIO = 1.5
TARGET_RSS_MB = 300.0
_NS = 1_000_000_000
_START_NS = 1_700_000_000 * _NS


def generate_bag(path: Path, *, seconds: float) -> Path:
    """Write the benchmark MCAP bag directory at ``path`` and return the .mcap file."""
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    types = typestore.types
    header_t, time_t = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    vec_t, quat_t = types["geometry_msgs/msg/Vector3"], types["geometry_msgs/msg/Quaternion"]
    transform_t = types["geometry_msgs/msg/Transform"]
    stamped_t, tf_t = types["geometry_msgs/msg/TransformStamped"], types["tf2_msgs/msg/TFMessage"]
    image_t = types["sensor_msgs/msg/Image"]

    def stamped(
        stamp_ns: int, parent: str, child: str, xyz: tuple[float, ...], yaw: float
    ) -> object:
        sec, nanosec = divmod(stamp_ns, _NS)
        return stamped_t(
            header=header_t(stamp=time_t(sec=sec, nanosec=nanosec), frame_id=parent),
            child_frame_id=child,
            transform=transform_t(
                translation=vec_t(x=xyz[0], y=xyz[1], z=xyz[2]),
                rotation=quat_t(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
            ),
        )

    # One serialized image, written again and again with its stamp patched: generation is
    # then bound by disk speed, not by serialization.
    pixels = np.arange(WIDTH * HEIGHT * 3, dtype=np.uint64).astype(np.uint8)
    image = image_t(
        header=header_t(stamp=time_t(sec=0, nanosec=0), frame_id="camera_link"),
        height=HEIGHT,
        width=WIDTH,
        encoding="rgb8",
        is_bigendian=0,
        step=WIDTH * 3,
        data=pixels,
    )
    image_bytes = bytearray(typestore.serialize_cdr(image, image_t.__msgtype__))
    writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
    with writer:
        tf_conn = writer.add_connection("/tf", tf_t.__msgtype__, typestore=typestore)
        static_conn = writer.add_connection("/tf_static", tf_t.__msgtype__, typestore=typestore)
        image_conn = writer.add_connection(
            "/camera/image_raw", image_t.__msgtype__, typestore=typestore
        )
        static = tf_t(transforms=[stamped(_START_NS, "base_link", "camera_link", (0.2, 0, 0.3), 0)])
        writer.write(static_conn, _START_NS, typestore.serialize_cdr(static, tf_t.__msgtype__))
        n_tf = int(seconds * TF_HZ)
        tf_stamps = _START_NS + (np.arange(n_tf) * _NS) // TF_HZ
        image_stamps = _START_NS + (np.arange(int(seconds * IMAGE_HZ)) * _NS) // IMAGE_HZ
        next_image = 0
        for k, stamp in enumerate(tf_stamps.tolist()):
            while next_image < image_stamps.size and image_stamps[next_image] <= stamp:
                image_ns = int(image_stamps[next_image])
                sec, nanosec = divmod(image_ns, _NS)
                image_bytes[4:12] = sec.to_bytes(4, "little") + nanosec.to_bytes(4, "little")
                writer.write(image_conn, image_ns, bytes(image_bytes))
                next_image += 1
            t = k / TF_HZ
            msg = tf_t(
                transforms=[
                    stamped(stamp, "map", "odom", (0.001 * t, 0.0005 * t, 0.0), 0.0002 * t),
                    stamped(
                        stamp,
                        "odom",
                        "base_link",
                        (5 * math.cos(0.1 * t), 5 * math.sin(0.1 * t), 0.0),
                        0.1 * t + math.pi / 2,
                    ),
                ]
            )
            writer.write(tf_conn, stamp, typestore.serialize_cdr(msg, tf_t.__msgtype__))
    return path / f"{path.name}.mcap"


def _child_extract(bag: Path) -> None:
    """Run in the child process: extract the chain, print timing and pose count as JSON."""
    start = time.perf_counter()
    trajectory = read_bag_trajectory(bag, "tf:map:base_link")
    elapsed = time.perf_counter() - start
    print(json.dumps({"seconds": elapsed, "poses": len(trajectory)}))


def _time_cat(bag: Path) -> float:
    start = time.perf_counter()
    with Path("/dev/null").open("wb") as sink:
        subprocess.run(["cat", str(bag)], stdout=sink, check=True)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    """Generate the bag when missing, then measure and print the figures."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.bags", description=__doc__)
    parser.add_argument("--workdir", type=Path, default=Path("benchmarks/_work"))
    parser.add_argument("--seconds", type=float, default=160.0, help="recording length")
    parser.add_argument("--child-extract", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_extract is not None:
        _child_extract(args.child_extract)
        return 0

    bag_dir = args.workdir / f"tf_images_{int(args.seconds)}s"
    bag = bag_dir / f"{bag_dir.name}.mcap"
    if not bag.is_file():
        args.workdir.mkdir(parents=True, exist_ok=True)
        print(f"generating {bag} ...", flush=True)
        start = time.perf_counter()
        generate_bag(bag_dir, seconds=args.seconds)
        print(f"  generated in {time.perf_counter() - start:.1f} s", flush=True)
    size_gb = bag.stat().st_size / 1e9
    print(f"bag: {bag} ({size_gb:.2f} GB)")

    _time_cat(bag)  # warm the page cache
    cat_s = min(_time_cat(bag) for _ in range(3))

    runs = []
    for _ in range(3):
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "benchmarks.bags", "--child-extract", str(bag)],
            capture_output=True,
            text=True,
            check=True,
        )
        wall = time.perf_counter() - start
        runs.append((json.loads(done.stdout), wall))
    peak_rss_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    call_s = min(r[0]["seconds"] for r in runs)
    wall_s = min(r[1] for r in runs)

    start = time.perf_counter()
    inspection = inspect_recording(bag)
    inspect_s = time.perf_counter() - start

    print(f"cat > /dev/null:               {cat_s:8.3f} s")
    print(f"read_bag_trajectory (call):    {call_s:8.3f} s  ratio {call_s / cat_s:5.2f}x")
    print(f"child process (wall, imports): {wall_s:8.3f} s  ratio {wall_s / cat_s:5.2f}x")
    print(f"poses: {runs[0][0]['poses']}")
    print(f"peak RSS (children):           {peak_rss_mb:8.1f} MB")
    print(
        f"inspect_recording:             {inspect_s:8.3f} s  ({len(inspection.candidates)} sources)"
    )
    ok_time = call_s / cat_s < TARGET_RATIO
    ok_rss = peak_rss_mb < TARGET_RSS_MB
    print(f"target time < {TARGET_RATIO}x: {'met' if ok_time else 'MISSED'}")
    print(f"target RSS < {TARGET_RSS_MB:.0f} MB: {'met' if ok_rss else 'MISSED'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
