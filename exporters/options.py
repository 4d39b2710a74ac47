"""Options shared by the exporters: model placement for CAD files, report settings.

The user-facing ones (units, site, simplification, building) are declared with the other
options in :data:`loceval.options.OPTIONS`; :class:`Units` is re-exported from there.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Final

from exporters.errors import ExportOptionsError
from loceval.core.display import display_text
from loceval.core.geometry import SimilarityTransform
from loceval.options import Units, UpAxis, choice_default, number_default

__all__ = ["ExportOptions", "FrontDoor", "Units", "UpAxis"]

_CRS_NAME: Final = re.compile(r"[A-Za-z][A-Za-z0-9_.-]*:[A-Za-z0-9_.-]+")

_DEFAULT_UNITS = Units(choice_default("units"))


class FrontDoor(StrEnum):
    """Which front door made the files: the report names an option the way it does.

    ``cli``: ``loceval evaluate`` (flags such as ``--tolerance``); ``service``: the web page
    and the HTTP API (the page's fields and the API's ``options.*`` keys).
    """

    CLI = "cli"
    SERVICE = "service"


@dataclass(frozen=True, slots=True)
class ExportOptions:
    """How an evaluation becomes files.

    Attributes:
        units: output length units of CAD files.
        site: maps the evaluation frame (the reference's frame, REP 103 Z-up metres) onto
            the building model's coordinates (metres); identity by default.
        simplify_m: largest deviation, in metres, that polyline simplification may
            introduce (0 keeps every vertex).
        building: a building model (OBJ/PLY/STL/GLB/IFC) to put in the glTF scene, if any.
        building_up: the up axis of a mesh building (OBJ, PLY, STL, GLB): ``format`` (the
            default) follows the file format (Y for GLB, Z for the others), ``z`` or
            ``y`` override it.
        evaluation_id: the id named in every file's metadata.
        title: a human title for reports and file metadata.
        templates_dir: where the report templates live (``templates/`` by default).
        crs: the projected coordinate reference system the site transform places the
            evaluation in (``"EPSG:25832"``), if any; the IFC then carries the site
            transform as its map conversion.
        front_door: the front door that made the files (how the report names options).
        fail_on: the gate's conditions (``fail``, ``undecided``, ``worse``): ``junit.xml``
            counts an undecided verdict as a failure only when ``undecided`` is one, and
            ``summary.md`` states the gate.
    """

    units: Units = _DEFAULT_UNITS
    site: SimilarityTransform = field(default_factory=SimilarityTransform.identity)
    simplify_m: float = number_default("simplify_m")
    building: Path | None = None
    evaluation_id: str = "local"
    title: str = "loceval evaluation"
    templates_dir: Path | None = None
    crs: str | None = None
    building_up: UpAxis = UpAxis.FORMAT
    front_door: FrontDoor = FrontDoor.CLI
    fail_on: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        """Make the title plain one-line text; check that the CRS reads ``AUTHORITY:CODE``.

        Raises:
            ExportOptionsError: a CRS that is not of the form ``EPSG:25832``.
        """
        # The title is shown in reports, CAD metadata and layer names: plain one-line text.
        object.__setattr__(self, "title", display_text(self.title))
        if self.crs is not None and not _CRS_NAME.fullmatch(self.crs):
            msg = (
                f"The coordinate reference system {self.crs!r} is not of the form "
                f"AUTHORITY:CODE; give it as, for example, 'EPSG:25832'."
            )
            raise ExportOptionsError(msg, option="crs")
