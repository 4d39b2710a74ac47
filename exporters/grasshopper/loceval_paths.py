# ruff: noqa: INP001  (a Grasshopper script pasted into Rhino, not a module of the package)
"""loceval paths: the trajectories of a loceval evaluation as Grasshopper polylines.

Rhino 8 Script component (Python 3). Reads paths.3dm.json, written by
`loceval evaluate --out DIR`, from a file path or an http(s) URL.

Inputs:
    source: str - path or URL of paths.3dm.json
Outputs:
    curves: polyline curves, reference first, scaled to the document's units
    names: trajectory names
    colours: display colours (ground truth cyan, then magenta, green, ...)
    layers: Rhino layer paths, loceval::<evaluation>::<trajectory>
    info: evaluation id, units, simplification tolerance and deviation
"""

import json
import urllib.request
from pathlib import Path

import Rhino
import System.Drawing

UNIT_SYSTEMS = {
    "mm": Rhino.UnitSystem.Millimeters,
    "cm": Rhino.UnitSystem.Centimeters,
    "m": Rhino.UnitSystem.Meters,
}


def load(source: str) -> dict:
    """Return the JSON document at a path or URL."""
    if source.startswith(("http://", "https://")):
        with urllib.request.urlopen(source, timeout=60) as response:  # noqa: S310
            return json.loads(response.read().decode("utf-8"))
    with Path(source).open(encoding="utf-8") as stream:
        return json.load(stream)


def document_scale(units: str) -> float:
    """Return the factor from the file's units to the active document's units."""
    doc = Rhino.RhinoDoc.ActiveDoc
    if doc is None:
        return 1.0
    return Rhino.RhinoMath.UnitScale(UNIT_SYSTEMS[units], doc.ModelUnitSystem)


source = globals().get("source")  # the component's input
curves, names, colours, layers, info = [], [], [], [], ""
if source:
    document = load(str(source).strip())
    if document.get("format") != "loceval.paths.3dm.json":
        message = f"{source} is not a loceval paths.3dm.json document"
        raise ValueError(message)
    scale = Rhino.Geometry.Transform.Scale(
        Rhino.Geometry.Point3d.Origin, document_scale(document["units"])
    )
    for path in document["paths"]:
        curve = Rhino.Runtime.CommonObject.FromJSON(json.dumps(path["curve"]))
        curve.Transform(scale)
        curves.append(curve)
        names.append(path["name"])
        colours.append(System.Drawing.Color.FromArgb(*path["color"]))
        layers.append(path["layer"])
    meta = document["metadata"]
    info = (
        f"evaluation {meta['evaluation_id']} | file units {meta['units']} | simplified "
        f"within {meta['simplify_tolerance_m']} m (max deviation {meta['max_deviation_m']:.6f} m)"
    )
