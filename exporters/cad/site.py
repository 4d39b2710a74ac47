"""CAD placement options: units, the site transform (words, matrix or file), and their checks.

Shared by every CAD exporter through :mod:`exporters.cad.placement`, which re-exports these names.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Final

import numpy as np

from exporters.errors import ExportOptionsError
from exporters.options import ExportOptions, Units
from loceval.core.geometry import SimilarityTransform
from loceval.core.rotation import Rotation
from loceval.errors import InputError
from loceval.trajectory import MAX_COORDINATE_M

SITE_FORMAT: Final = '"tx ty tz yaw_deg"'
MAX_YAW_DEG: Final = 360.0
"""Largest site yaw magnitude, degrees (a turn; more is a typo)."""
SCALE_RANGE: Final = (1e-6, 1e6)
"""Smallest and largest scale of a site matrix (units are a separate option)."""
_AXES: Final = ("tx", "ty", "tz")
BUILDING_SUFFIXES: Final = (".obj", ".ply", ".stl", ".glb", ".ifc", ".dxf")
"""Building model formats accepted (read by :mod:`exporters.cad.building`; a DXF is a floor
plan)."""

# --- options -------------------------------------------------------------------------------


def parse_units(text: str) -> Units:
    """Parse the CAD units (``mm``, ``cm`` or ``m``).

    Raises:
        ExportOptionsError: another unit.
    """
    try:
        return Units(text.strip().lower())
    except ValueError:
        choices = ", ".join(u.value for u in Units)
        msg = f"The CAD units must be one of {choices}, got {text!r}."
        raise ExportOptionsError(msg, option="units") from None


def parse_site(text: str) -> SimilarityTransform:
    """Parse a site ``"tx ty tz yaw_deg"`` into the evaluation-frame -> model transform.

    The translation is in metres (model coordinates of the evaluation frame's origin) and
    the yaw is a rotation about Z in degrees, counter-clockwise seen from above. ``"tx ty
    tz"`` alone means no rotation. Commas may separate the numbers.

    Raises:
        ExportOptionsError: not three or four finite numbers, a translation beyond
            ±:data:`~loceval.trajectory.MAX_COORDINATE_M` metres or a yaw beyond ±360°.
    """
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        values = []
    if len(values) not in (3, 4) or not all(math.isfinite(v) for v in values):
        msg = (
            f"The site transform takes {SITE_FORMAT} (metres, degrees about Z), for example "
            f'"512340.0 5403210.5 112.3 37.5", got {text!r}.'
        )
        raise ExportOptionsError(msg, option="site")
    _check_translation(values[:3], option="site", what="The site transform")
    yaw_deg = values[3] if len(values) == 4 else 0.0
    if abs(yaw_deg) > MAX_YAW_DEG:
        msg = (
            f"The site transform's yaw must be within ±{MAX_YAW_DEG:g} degrees, got "
            f"{yaw_deg:g}; give the yaw as an angle of one turn at most, in degrees."
        )
        raise ExportOptionsError(msg, option="site")
    rotation = Rotation.from_euler("z", np.array(yaw_deg), degrees=True).as_matrix()
    return SimilarityTransform(rotation, np.array(values[:3]), 1.0)


def read_site_matrix(path: Path) -> SimilarityTransform:
    """Read a 4x4 evaluation-frame -> model matrix from a text or JSON file.

    Accepted forms, all row-major ``[[sR, t], [0, 0, 0, 1]]`` with ``t`` in metres: 16
    numbers in a text file (whitespace, comma or semicolon separated, ``#`` comments), or a
    JSON array of 4 rows, a flat JSON array of 16, or a JSON object with either under
    ``"matrix"``. A uniform scale is allowed; shear, reflection and singular matrices are not.

    Raises:
        ExportOptionsError: the file is unreadable or the matrix is not a similarity transform.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        msg = f"Cannot read the site matrix file {str(path)!r} ({err}); check the path."
        raise ExportOptionsError(msg, option="site_matrix") from err
    return site_from_values(_matrix_numbers(text), where=f"the site matrix file {str(path)!r}")


def site_from_values(values: Sequence[float] | None, *, where: str) -> SimilarityTransform:
    """Return the site transform of 16 row-major numbers (see :func:`read_site_matrix`).

    Args:
        values: the numbers, or None when they could not be read.
        where: names the matrix in messages (``"the site matrix file 'site.txt'"``).

    Raises:
        ExportOptionsError: not 16 finite numbers, not a similarity transform, a
            translation beyond ±:data:`~loceval.trajectory.MAX_COORDINATE_M` metres or a
            scale outside :data:`SCALE_RANGE`.
    """
    if values is None or len(values) != 16 or not all(math.isfinite(v) for v in values):
        msg = (
            f"{where[0].upper()}{where[1:]} must hold 16 numbers (a 4x4 row-major "
            "matrix, or JSON [[...], [...], [...], [...]]); check its contents."
        )
        raise ExportOptionsError(msg, option="site_matrix")
    matrix = np.array(values, dtype=np.float64).reshape(4, 4)
    if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0]) and np.allclose(
        matrix[:, 3], [0.0, 0.0, 0.0, 1.0]
    ):
        msg = (
            f"The matrix of {where} looks column-major (glTF/three.js order); "
            "write it row by row with the translation in the last column."
        )
        raise ExportOptionsError(msg, option="site_matrix")
    det = float(np.linalg.det(matrix[:3, :3]))
    if abs(det) < 1e-12:
        msg = f"The matrix of {where} is singular (det={det:.3g}); check its values."
        raise ExportOptionsError(msg, option="site_matrix")
    _check_translation(list(matrix[:3, 3]), option="site_matrix", what=f"The matrix of {where}")
    try:
        transform = SimilarityTransform.from_matrix(matrix)
    except InputError as err:
        msg = (
            f"The matrix of {where} is not a rotation with uniform scale and a "
            f"translation ({err}); check its values."
        )
        raise ExportOptionsError(msg, option="site_matrix") from err
    low, high = SCALE_RANGE
    if not low <= transform.scale <= high:
        msg = (
            f"The matrix of {where} scales by {transform.scale:.6g}, outside {low:g} to "
            f"{high:g}; give a rotation and translation in metres (the CAD units are an "
            "option of their own)."
        )
        raise ExportOptionsError(msg, option="site_matrix")
    return transform


def _check_translation(values: Sequence[float], *, option: str, what: str) -> None:
    """Refuse a translation coordinate beyond any site (it would overflow the CAD output)."""
    for axis, value in zip(_AXES, values, strict=True):
        if abs(float(value)) > MAX_COORDINATE_M:
            msg = (
                f"{what} has {axis} = {float(value):g} m, beyond ±{MAX_COORDINATE_M:g} m, "
                "which is no site's coordinate; give the translation in metres."
            )
            raise ExportOptionsError(msg, option=option)


def _matrix_numbers(text: str) -> list[float] | None:
    stripped = text.strip()
    if stripped.startswith(("[", "{")):
        try:
            document = json.loads(stripped)
        except json.JSONDecodeError:
            return None
        if isinstance(document, dict):
            document = document.get("matrix")
        flat = np.asarray(document, dtype=object).reshape(-1).tolist() if document else []
        try:
            return [float(v) for v in flat]
        except (TypeError, ValueError):
            return None
    lines = (line.split("#", 1)[0] for line in text.splitlines())
    tokens = re.split(r"[\s,;]+", " ".join(lines).strip())
    try:
        return [float(t) for t in tokens if t]
    except ValueError:
        return None


def check_options(options: ExportOptions) -> None:
    """Check the placement options a user can get wrong (cheap: reads no file).

    Raises:
        ExportOptionsError: unknown units, a negative or non-finite simplification, or a
            building file that is missing or not an OBJ, PLY, STL or GLB.
    """
    parse_units(str(options.units))  # a plain string passed for Units must still be valid
    if not (math.isfinite(options.simplify_m) and options.simplify_m >= 0.0):
        msg = (
            f"The simplification tolerance must be zero or a positive number of metres, got "
            f"{options.simplify_m!r}; use 0 to keep every pose."
        )
        raise ExportOptionsError(msg, option="simplify_m")
    building = options.building
    if building is not None:
        if building.suffix.lower() not in BUILDING_SUFFIXES:
            kinds = ", ".join(s.lstrip(".").upper() for s in BUILDING_SUFFIXES)
            msg = (
                f"The building model {str(building)!r} is not a supported mesh; export it "
                f"as {kinds}."
            )
            raise ExportOptionsError(msg, option="building")
        if not building.is_file():
            msg = f"The building model {str(building)!r} does not exist; check the path."
            raise ExportOptionsError(msg, option="building")
