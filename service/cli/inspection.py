"""``loceval inspect``: what any input holds, from the core's one ``inspect()``.

Bags list their topics, tf tree and selectors; a Motive take lists its rigid bodies; a
trajectory file describes its one trajectory; a URDF its links and joints. ``--json`` prints
the same document the service stores for an upload.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from service.cli.output import emit

if TYPE_CHECKING:
    import argparse

__all__ = ["run_inspect"]


def run_inspect(args: argparse.Namespace) -> int:
    """Describe an input, as text or JSON."""
    from loceval.inspection import inspect, render_inspection_text  # noqa: PLC0415

    inspection = inspect(args.path)
    if args.json:
        print(json.dumps(inspection.to_dict(), indent=2))  # noqa: T201
    else:
        emit(render_inspection_text(inspection))
    return 0
