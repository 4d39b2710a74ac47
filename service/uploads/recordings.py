"""Recognise an uploaded recording and list the trajectories it holds.

The inspection (:func:`loceval.inspection.inspect`, the same the command line prints) is
stored with the dataset, so the web page and API clients can offer the sources
(``selector``) without reading the file again. Text trajectories are read fully, so a
corrupt file is refused at upload with the reader's message, not at evaluation.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath
from typing import TYPE_CHECKING, Any

from exporters.cad.site import BUILDING_SUFFIXES
from loceval.errors import LocevalError, ReaderError
from loceval.inspection import URDF_SUFFIXES, inspect

if TYPE_CHECKING:
    from loceval.readers.rosbag import RemoteFile

__all__ = ["inspect_remote_upload", "inspect_upload"]


def inspect_upload(path: Path, filename: str) -> dict[str, Any]:
    """Return the kind of an uploaded file and the trajectory sources in it.

    Args:
        path: the file on disk.
        filename: the name the client gave (a ``.urdf`` or ``.xml`` suffix marks a URDF).

    Returns:
        :meth:`loceval.inspection.Inspection.to_dict` without the server path: ``kind``,
        ``format``, ``sources`` and ``warnings``, plus for bags the topics and tf tree,
        for files with one trajectory its summary, and for URDF the robot, links and
        joints. Server paths in the texts are replaced by ``filename``.

    Raises:
        ReaderError: the file is empty or not a recording loceval can read (the message
            says what was expected).
    """
    if path.stat().st_size == 0:
        msg = f"{filename!r} is empty; upload the recording itself."
        raise ReaderError(msg)
    if Path(filename).suffix.lower() in BUILDING_SUFFIXES:
        return _inspect_building(path, filename)
    if Path(filename).suffix.lower() == ".zip" and _holds_map_yaml(path):
        return _inspect_map(path)
    if Path(filename).suffix.lower() == ".zip":
        from service.uploads.evo_results import inspect_result_zip  # noqa: PLC0415

        found = inspect_result_zip(path, filename)
        if found is not None:
            return found
    kind = "urdf" if Path(filename).suffix.lower() in URDF_SUFFIXES else None
    inspection = inspect(path, kind=kind).to_dict()
    inspection.pop("path", None)
    server_path = str(path)
    if isinstance(inspection.get("source"), str):
        inspection["source"] = str(inspection["source"]).replace(server_path, filename)
    warnings = inspection.get("warnings")
    if isinstance(warnings, list):
        inspection["warnings"] = [str(w).replace(server_path, filename) for w in warnings]
    return inspection


def inspect_remote_upload(file: RemoteFile, filename: str) -> dict[str, Any]:
    """Inspect an MCAP file or ROS 1 bag in the object store by ranged reads (no copy).

    The same description :func:`inspect_upload` gives for the file; only its index, tf
    messages and pose topics' first and last messages are fetched where its MCAP index
    allows.

    Raises:
        ReaderError: the file is empty or not a bag loceval can read.
    """
    from loceval.inspection.bag import inspect_bag_file  # noqa: PLC0415

    if file.size == 0:
        msg = f"{filename!r} is empty; upload the recording itself."
        raise ReaderError(msg)
    inspection = inspect_bag_file(file).to_dict()
    inspection.pop("path", None)
    return inspection


def _holds_map_yaml(path: Path) -> bool:
    """Whether a zip holds a YAML that is not a ROS 2 bag's metadata (a map_server map)."""
    import zipfile  # noqa: PLC0415

    try:
        with zipfile.ZipFile(path) as archive:
            names = [PurePosixPath(n).name for n in archive.namelist()]
    except (zipfile.BadZipFile, OSError):
        return False
    yamls = [n for n in names if n.lower().endswith((".yaml", ".yml"))]
    return bool(yamls) and "metadata.yaml" not in names


def _inspect_map(path: Path) -> dict[str, Any]:
    """Read an uploaded map zip (map_server's YAML and image) once, so a broken one is refused."""
    from loceval.maps import read_map  # noqa: PLC0415

    grid = read_map(str(path))
    rows, cols = grid.shape
    return {
        "kind": "map",
        "format": "map",
        "sources": [],
        "warnings": [],
        "map": {"width": cols, "height": rows, "resolution_m": grid.resolution_m},
    }


def _inspect_building(path: Path, filename: str) -> dict[str, Any]:
    """Read a building model or DXF floor plan once, so a broken one is refused at upload.

    Mesh units are not stored in OBJ, PLY or STL files: they are read as metres here; the
    evaluation reads the model again in its own units and up axis.
    """
    from exporters.cad.building import BuildingModel, read_underlay  # noqa: PLC0415  (CAD libraries)
    from exporters.options import Units, UpAxis  # noqa: PLC0415

    try:
        model = read_underlay(path, units=Units.M, up=UpAxis.Z)
    except LocevalError as err:
        msg = str(err).replace(str(path), filename)
        raise ReaderError(msg) from err
    suffix = Path(filename).suffix.lower().lstrip(".")
    out: dict[str, Any] = {"kind": "building", "format": suffix, "sources": [], "warnings": []}
    if isinstance(model, BuildingModel):
        out |= {
            "vertices": len(model.vertices_m),
            "faces": len(model.faces),
            "crs": model.crs,
            "georeferenced": model.site is not None,
        }
    else:
        out |= {"segments": len(model.segments_m), "crs": None, "georeferenced": False}
    return out
