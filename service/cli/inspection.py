"""``loceval inspect``: what a recording holds (bags) or what a trajectory file is.

Moved unchanged from the single-module CLI; the core's one ``inspect()`` will replace it.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from loceval.readers import TrajectoryFormat, parse_source, read_trajectory

if TYPE_CHECKING:
    import argparse

    from loceval.trajectory import Trajectory

__all__ = ["run_inspect"]


def run_inspect(args: argparse.Namespace) -> int:
    """List what a recording holds, as tables or JSON."""
    spec = parse_source(args.path)
    from loceval.readers import sniff_format  # noqa: PLC0415

    fmt = sniff_format(spec.path)
    if fmt is TrajectoryFormat.BAG:
        from loceval.inspection import format_inspection, inspect_recording  # noqa: PLC0415

        inspection = inspect_recording(spec.path)
        if args.json:
            print(json.dumps(inspection.to_dict(), indent=2))  # noqa: T201
        else:
            print(format_inspection(inspection))  # noqa: T201
        return 0
    trajectory = read_trajectory(spec)
    summary = _trajectory_summary(trajectory, fmt)
    if args.json:
        print(json.dumps(summary, indent=2))  # noqa: T201
    else:
        for key, value in summary.items():
            print(f"{key:>14}: {value}")  # noqa: T201
    return 0


def _trajectory_summary(trajectory: Trajectory, fmt: TrajectoryFormat) -> dict[str, object]:
    return {
        "format": fmt.value,
        "source": trajectory.source,
        "poses": len(trajectory),
        "start_s": int(trajectory.stamps_ns[0]) / 1e9,
        "end_s": int(trajectory.stamps_ns[-1]) / 1e9,
        "duration_s": trajectory.duration_s,
        "length_m": trajectory.length_m,
        "rate_hz": trajectory.rate_hz,
        "orientation": trajectory.has_orientation,
        "warnings": list(trajectory.warnings),
    }
