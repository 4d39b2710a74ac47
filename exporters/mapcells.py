"""``map_cells.csv``: every wall cell of the robot's map and its distance to the plan.

One row per wall cell (an occupied cell with a free 4-neighbour): its centre as placed on
the plan (evaluation frame, metres), its distance to the nearest plan wall as placed and
after the best similarity fit, and whether it is clutter (farther than the clutter distance
after the fit: not in the plan). Without a map the file holds the header and a comment.
The rows are formatted in one vectorised pass, not cell by cell.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from exporters.options import ExportOptions
from loceval.evaluation import EvaluationResult

__all__ = ["MAP_CELLS_COLUMNS", "export_map_cells_csv"]

MAP_CELLS_COLUMNS: Final = ("x_m", "y_m", "distance_m", "fitted_distance_m", "clutter")
"""The header of ``map_cells.csv``."""


def export_map_cells_csv(result: EvaluationResult, options: ExportOptions) -> bytes:
    """Return the map's wall cells as CSV (UTF-8).

    Args:
        result: the evaluation; ``result.map`` holds the cells when a map was measured.
        options: unused (the cells are in the evaluation frame, metres).
    """
    del options
    header = ",".join(MAP_CELLS_COLUMNS) + "\n"
    found = result.map
    if found is None:
        return (header + "# no map was measured (give a map and a building plan)\n").encode()
    columns = (
        (found.cells_xy[:, 0], "%.4f,"),
        (found.cells_xy[:, 1], "%.4f,"),
        (found.distance_m, "%.5f,"),
        (found.fitted_distance_m, "%.5f,"),
    )
    body = np.where(found.clutter, "1\n", "0\n").astype(object)
    for values, fmt in reversed(columns):  # one pass per column, each over every cell
        body = np.char.mod(fmt, values).astype(object) + body
    return (header + "".join(body.tolist())).encode()
