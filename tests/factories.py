"""Test data builders: smooth random trajectories and writers for the text formats.

Writers take a :class:`~loceval.trajectory.Trajectory` and produce the file a real tool
would: exact decimal stamps, shortest round-trip floats (``repr``), and the format's own
conventions (EuRoC's w-first quaternions, KITTI's 3x4 matrices, Motive's Y-up world).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from loceval.trajectory import Trajectory

T0_NS = 1_700_000_000 * 10**9
"""A plausible epoch start (2023-11-14) for synthetic stamps."""

ROVER_URDF = """<?xml version="1.0"?>
<robot name="rover">
  <link name="rigid_body"/>
  <link name="camera_link"/>
  <joint name="mount" type="fixed">
    <parent link="rigid_body"/>
    <child link="camera_link"/>
    <origin xyz="0.1 0.0 0.25" rpy="0 0 0"/>
  </joint>
</robot>
"""
"""A device file: the rigid body and a camera 0.1 m ahead of it and 0.25 m up (no rotation)."""

MOTIVE_START = "2019-09-18 04.30.02.695 PM"
"""A Capture Start Time as Motive writes it."""

MOTIVE_START_NS = 1_568_824_202_695_000_000
""":data:`MOTIVE_START` read as UTC, in epoch nanoseconds."""

_Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_MOTIVE_LENGTH = {"Meters": 1.0, "Centimeters": 0.01, "Millimeters": 0.001}


def make_trajectory(
    rng: np.random.Generator,
    n: int = 200,
    dt_ns: int = 10_000_000,
    *,
    t0_ns: int = T0_NS,
    orientation: bool = True,
    planar: bool = False,
    name: str = "truth",
    frame_id: str = "map",
) -> Trajectory:
    """Return a smooth random 3D trajectory: sums of sines a few metres across.

    Args:
        rng: the seeded generator (the ``rng`` fixture).
        n: number of poses.
        dt_ns: interval between poses in nanoseconds.
        t0_ns: first stamp.
        orientation: whether to include orientations (smooth roll, pitch and yaw).
        planar: keep z at 0 (for position-only x, y sources).
        name: the trajectory's name.
        frame_id: the frame of the poses.
    """
    t = np.arange(n) * (dt_ns / 1e9)
    freq = rng.uniform(0.05, 0.4, (3, 3))
    amp = rng.uniform(0.5, 3.0, (3, 3)) * np.array([[1.0], [1.0], [0.2]])
    phase = rng.uniform(0.0, 2.0 * np.pi, (3, 3))
    positions = np.stack(
        [(amp[k] * np.sin(2 * np.pi * freq[k] * t[:, None] + phase[k])).sum(1) for k in range(3)],
        axis=1,
    )
    if planar:
        positions[:, 2] = 0.0
    quat = None
    if orientation:
        angles = np.stack(
            [
                0.3 * np.sin(0.2 * t + phase[0, 0]),
                0.2 * np.sin(0.3 * t + phase[0, 1]),
                0.5 * t + phase[0, 2],
            ],
            axis=1,
        )
        quat = Rotation.from_euler("xyz", angles).as_quat()
    stamps = t0_ns + np.arange(n, dtype=np.int64) * np.int64(dt_ns)
    return Trajectory(stamps, positions, quat, name=name, frame_id=frame_id)


def perturb(
    trajectory: Trajectory,
    rng: np.random.Generator,
    *,
    sigma_m: float = 0.01,
    sigma_rad: float = 0.005,
) -> Trajectory:
    """Return the trajectory with Gaussian noise on positions and (small) rotations."""
    positions = trajectory.positions_xyz + rng.normal(0.0, sigma_m, trajectory.positions_xyz.shape)
    quat = trajectory.quat_xyzw
    if quat is not None:
        noise = Rotation.from_rotvec(rng.normal(0.0, sigma_rad, (len(trajectory), 3)))
        quat = (Rotation.from_quat(quat) * noise).as_quat()
    return replace(trajectory, positions_xyz=positions, quat_xyzw=quat)


def seconds_text(stamp_ns: int) -> str:
    """Return nanoseconds as an exact decimal number of seconds, e.g. ``1700000000.010000000``."""
    sign = "-" if stamp_ns < 0 else ""
    whole, frac = divmod(abs(int(stamp_ns)), 10**9)
    return f"{sign}{whole}.{frac:09d}"


def write_tum(
    path: Path, trajectory: Trajectory, *, header: bool = True, columns: int | None = None
) -> Path:
    """Write ``t x y z qx qy qz qw`` lines (``t x y z`` without orientations).

    Args:
        path: the file to write.
        trajectory: what to write.
        header: start with a ``#`` comment line, as TUM's own files do.
        columns: 8, 4 or 3 to force a width (3 writes ``t x y``); None picks 8 or 4.
    """
    width = columns or (8 if trajectory.quat_xyzw is not None else 4)
    lines = ["# timestamp tx ty tz qx qy qz qw"] if header else []
    for i, stamp in enumerate(trajectory.stamps_ns):
        values = list(trajectory.positions_xyz[i][: 3 if width >= 4 else 2])
        if width == 8:
            assert trajectory.quat_xyzw is not None
            values += list(trajectory.quat_xyzw[i])
        lines.append(" ".join([seconds_text(int(stamp)), *(repr(float(v)) for v in values)]))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_euroc(path: Path, trajectory: Trajectory, *, extra_columns: bool = True) -> Path:
    """Write a EuRoC ground-truth CSV: ns stamps, position, w-first quaternion, velocities."""
    assert trajectory.quat_xyzw is not None
    header = (
        "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],"
        "q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
    )
    if extra_columns:
        header += ",v_RS_R_x [m s^-1],v_RS_R_y [m s^-1],v_RS_R_z [m s^-1]"
    lines = [header]
    for i, stamp in enumerate(trajectory.stamps_ns):
        x, y, z = trajectory.positions_xyz[i]
        qx, qy, qz, qw = trajectory.quat_xyzw[i]
        cells = [str(int(stamp)), *(repr(float(v)) for v in (x, y, z, qw, qx, qy, qz))]
        if extra_columns:
            cells += ["0.1", "-0.2", "0.3"]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_kitti(path: Path, trajectory: Trajectory, *, times_path: Path | None = None) -> Path:
    """Write KITTI poses (3x4 ``[R|t]`` row by row) and optionally a times file (seconds)."""
    assert trajectory.quat_xyzw is not None
    matrices = np.zeros((len(trajectory), 3, 4))
    matrices[:, :, :3] = Rotation.from_quat(trajectory.quat_xyzw).as_matrix()
    matrices[:, :, 3] = trajectory.positions_xyz
    path.write_text("\n".join(" ".join(repr(float(v)) for v in m.ravel()) for m in matrices) + "\n")
    if times_path is not None:
        times_path.write_text("\n".join(seconds_text(int(s)) for s in trajectory.stamps_ns) + "\n")
    return path


def write_csv(
    path: Path,
    trajectory: Trajectory,
    *,
    names: Mapping[str, str] | None = None,
    delimiter: str = ",",
    time_unit: str = "s",
    length_scale: float = 1.0,
) -> Path:
    """Write a CSV with a header row.

    Args:
        path: the file to write.
        trajectory: what to write.
        names: header name per key (``t x y z qx qy qz qw``); keys left out are not
            written, so ``{"t": ..., "x": ..., "y": ...}`` writes a planar position-only file.
            Defaults to the plain key names (all eight, or four without orientations).
        delimiter: the cell delimiter.
        time_unit: ``s`` (exact decimal seconds) or ``ms``/``us``/``ns`` (integers).
        length_scale: positions are divided by this (0.001 writes millimetres).
    """
    keys = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")
    if names is None:
        used = keys if trajectory.quat_xyzw is not None else keys[:4]
        names = {key: key for key in used}
    per_unit = {"s": 1, "ms": 10**6, "us": 10**3, "ns": 1}[time_unit]
    lines = [delimiter.join(names.values())]
    for i, stamp in enumerate(trajectory.stamps_ns):
        cells = []
        for key in names:
            if key == "t":
                cells.append(
                    seconds_text(int(stamp)) if time_unit == "s" else str(int(stamp) // per_unit)
                )
            elif key in {"x", "y", "z"}:
                value = trajectory.positions_xyz[i]["xyz".index(key)] / length_scale
                cells.append(repr(float(value)))
            else:
                assert trajectory.quat_xyzw is not None
                cells.append(repr(float(trajectory.quat_xyzw[i]["xyzw".index(key[1])])))
        lines.append(delimiter.join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def write_motive(
    path: Path,
    bodies: Mapping[str, Trajectory],
    *,
    length_units: str = "Meters",
    up_axis: str = "y",
    capture_start: str = MOTIVE_START,
    lost: Mapping[str, Sequence[int]] | None = None,
    rotation_type: str = "Quaternion",
    extra_meta: Mapping[str, str] | None = None,
    markers: bool = True,
    rotations: bool = True,
) -> Path:
    """Write an OptiTrack Motive 1.23 CSV export of rigid bodies that share frame stamps.

    The poses (REP 103, Z-up) are written in Motive's Y-up world unless ``up_axis="z"``, so
    reading the file back gives the input. ``Time (Seconds)`` counts from the first stamp.

    Args:
        path: the file to write.
        bodies: rigid body name -> trajectory; all with the same stamps.
        length_units: ``Meters``, ``Centimeters`` or ``Millimeters`` (or anything, to test
            rejection).
        up_axis: ``y`` (Motive's default) or ``z``.
        capture_start: the ``Capture Start Time`` value.
        lost: rigid body name -> frame indices written as empty cells (tracking lost).
        rotation_type: ``Quaternion``, or e.g. ``XYZ`` to write Euler angles instead.
        extra_meta: more ``key,value`` pairs for the first line (e.g. ``Up Axis``).
        markers: also write a Rigid Body Marker and a Marker column set per body, which the
            reader must ignore.
        rotations: write the rotation columns (False: position-only bodies).
    """
    stamps = next(iter(bodies.values())).stamps_ns
    scale = _MOTIVE_LENGTH.get(length_units, 1.0)
    to_motive = _Y_UP_TO_Z_UP.T if up_axis == "y" else np.eye(3)
    meta = {
        "Format Version": "1.23",
        "Take Name": "synthetic",
        "Take Notes": "",
        "Capture Frame Rate": "100.000000",
        "Export Frame Rate": "100.000000",
        "Capture Start Time": capture_start,
        "Total Frames in Take": str(len(stamps)),
        "Total Exported Frames": str(len(stamps)),
        "Rotation Type": rotation_type,
        "Length Units": length_units,
        "Coordinate Space": "Global",
        **(extra_meta or {}),
    }
    types, names, ids, quantities, axes = [], [], [], [], []
    columns: list[np.ndarray] = []
    lost_rows: list[set[int]] = []
    for number, (body, trajectory) in enumerate(bodies.items()):
        gone = set((lost or {}).get(body, ()))
        positions = trajectory.positions_xyz @ to_motive.T / scale
        rotation = Rotation.from_matrix(to_motive) * Rotation.from_quat(trajectory.quat_xyzw)
        if rotation_type == "Quaternion":
            rot_values, rot_axes = rotation.as_quat(), ["X", "Y", "Z", "W"]
        else:
            rot_values, rot_axes = rotation.as_euler("xyz", degrees=True), ["X", "Y", "Z"]
        blocks = [("Rigid Body", body, "Rotation", rot_axes, rot_values)] if rotations else []
        blocks += [
            ("Rigid Body", body, "Position", ["X", "Y", "Z"], positions),
            ("Rigid Body", body, "Mean Marker Error", [""], np.full((len(stamps), 1), 1e-4)),
        ]
        if markers:
            marker = positions + 0.05
            blocks += [
                ("Rigid Body Marker", f"{body}:Marker1", "Position", ["X", "Y", "Z"], marker),
                ("Marker", f"{body}:Marker1", "Position", ["X", "Y", "Z"], marker),
            ]
        for kind, label, quantity, block_axes, values in blocks:
            for j, axis in enumerate(block_axes):
                types.append(kind)
                names.append(label)
                ids.append(f'"{number + 1}"')
                quantities.append(quantity)
                axes.append(axis)
                columns.append(values[:, j])
                lost_rows.append(gone if kind == "Rigid Body" else set())
    lines = [
        ",".join(f"{key},{value}" for key, value in meta.items()),
        "",
        ",Type," + ",".join(types),
        ",Name," + ",".join(names),
        ",ID," + ",".join(ids),
        ",," + ",".join(quantities),
        "Frame,Time (Seconds)," + ",".join(axes),
    ]
    times = (stamps - stamps[0]) / 1e9
    for i, time_s in enumerate(times):
        cells = [
            "" if i in lost_rows[c] else f"{float(columns[c][i]):.9g}" for c in range(len(columns))
        ]
        lines.append(f"{i},{float(time_s):.9g}," + ",".join(cells))
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return path


def assert_trajectories_close(
    actual: Trajectory,
    expected: Trajectory,
    *,
    atol_m: float = 1e-9,
    atol_ns: int = 0,
    atol_rad: float = 1e-9,
) -> None:
    """Assert equal length, stamps within ``atol_ns``, positions and orientations close.

    Orientations are compared as rotations (q and -q are the same).
    """
    assert len(actual) == len(expected), (len(actual), len(expected))
    np.testing.assert_allclose(actual.stamps_ns, expected.stamps_ns, rtol=0, atol=atol_ns)
    np.testing.assert_allclose(actual.positions_xyz, expected.positions_xyz, rtol=0, atol=atol_m)
    assert (actual.quat_xyzw is None) == (expected.quat_xyzw is None)
    if actual.quat_xyzw is not None and expected.quat_xyzw is not None:
        delta = Rotation.from_quat(actual.quat_xyzw).inv() * Rotation.from_quat(expected.quat_xyzw)
        np.testing.assert_allclose(delta.magnitude(), 0.0, rtol=0, atol=atol_rad)


def write_large_tum(path: Path, size_bytes: int, rng: np.random.Generator) -> Path:
    """Write a TUM trajectory of about ``size_bytes`` (a random walk at 100 Hz), by numpy.

    For uploads large enough to be cut midway; each call's bytes differ (the walk is random).
    """
    n = max(10, size_bytes // 96)
    stamps = 1_700_000_000.0 + np.arange(n) * 0.01
    positions = np.cumsum(rng.normal(0.0, 0.01, size=(n, 3)), axis=0)
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    np.savetxt(path, np.column_stack([stamps, positions, quats]), fmt="%.9f")
    return path
