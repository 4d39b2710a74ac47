# ruff: noqa: INP001, UP020, UP031, ANN001, ANN201
# (a Grasshopper script, not a module; it runs under Python 3 AND IronPython 2.7)
"""loceval paths: the trajectories of a loceval evaluation as Grasshopper geometry.

Runs as it is in Rhino 8's Script component (Python 3) and in Rhino 7's GhPython
component (IronPython 2.7): no f-strings, no annotations, no pathlib. Reads
paths.3dm.json (format_version 2), written by `loceval evaluate --out DIR`, from a file
path or an http(s) URL.

Inputs:
    source: str - path or URL of paths.3dm.json
    bake: bool - True adds everything to the Rhino document on the named layers
Outputs:
    curves: polyline curves, one per continuous piece, reference first, document units
    names, colours, layers: per curve
    ate_curves, ate_colours, ate_layers: the estimates cut into ATE-coloured runs
    dots, dot_layers: text dots at the greatest errors and at each tracking loss (or the
        control point ids and error labels of an evaluation against control points)
    points, point_layers: control points and measured positions (control points only)
    info: evaluation, units, simplification tolerance and deviation, ATE legend
"""

import io
import json

import Rhino
import System.Drawing

try:  # Python 3 (Rhino 8)
    from urllib.request import urlopen
except ImportError:  # IronPython 2.7 (Rhino 7)
    from urllib2 import urlopen

UNIT_SYSTEMS = {
    "mm": Rhino.UnitSystem.Millimeters,
    "cm": Rhino.UnitSystem.Centimeters,
    "m": Rhino.UnitSystem.Meters,
}


def load(source):
    """Return the JSON document at a path or URL."""
    if source.startswith(("http://", "https://")):
        return json.loads(urlopen(source, timeout=60).read().decode("utf-8"))
    with io.open(source, encoding="utf-8") as stream:
        return json.load(stream)


def colour(rgb):
    """Return a System.Drawing colour of [r, g, b]."""
    return System.Drawing.Color.FromArgb(rgb[0], rgb[1], rgb[2])


def decode(encoded, scale):
    """Return the curve of a CommonObject.Encode() dict, scaled to the document's units."""
    curve = Rhino.Runtime.CommonObject.FromJSON(json.dumps(encoded))
    curve.Transform(scale)
    return curve


def layer_index(doc, full_path, rgb):
    """Return the index of a layer path such as loceval::Lab run::OptiTrack, making it."""
    index = doc.Layers.FindByFullPath(full_path, -1)
    if index >= 0:
        return index
    parent, _, name = full_path.rpartition("::")
    layer = Rhino.DocObjects.Layer()
    layer.Name = name
    layer.Color = colour(rgb)
    if parent:
        layer.ParentLayerId = doc.Layers[layer_index(doc, parent, [255, 255, 255])].Id
    return doc.Layers.Add(layer)


def bake_all(doc, items):
    """Add (geometry, name, layer path, rgb) items to the document on their layers."""
    for geometry, name, layer, rgb in items:
        attributes = Rhino.DocObjects.ObjectAttributes()
        attributes.Name = name
        attributes.LayerIndex = layer_index(doc, layer, rgb)
        attributes.ObjectColor = colour(rgb)
        attributes.ColorSource = Rhino.DocObjects.ObjectColorSource.ColorFromObject
        doc.Objects.Add(geometry, attributes)
    doc.Views.Redraw()


source = globals().get("source")  # the component's inputs
bake = globals().get("bake")
curves, names, colours, layers, info = [], [], [], [], ""
ate_curves, ate_colours, ate_layers, dots, dot_layers = [], [], [], [], []
points, point_layers = [], []
if source:
    document = load(str(source).strip())
    if document.get("format") != "loceval.paths.3dm.json" or document["format_version"] != 2:
        raise ValueError("%s is not a loceval paths.3dm.json document, version 2" % source)
    doc = Rhino.RhinoDoc.ActiveDoc
    factor = (
        1.0
        if doc is None
        else Rhino.RhinoMath.UnitScale(UNIT_SYSTEMS[document["units"]], doc.ModelUnitSystem)
    )
    scale = Rhino.Geometry.Transform.Scale(Rhino.Geometry.Point3d.Origin, factor)
    items = []
    path_colours = {path["name"]: path["color"] for path in document["paths"]}
    for path in document["paths"]:
        for encoded in path["curves"]:
            curves.append(decode(encoded, scale))
            names.append(path["name"])
            colours.append(colour(path["color"]))
            layers.append(path["layer"])
            items.append((curves[-1], path["name"], path["layer"], path["color"]))
        for run in path["ate"]:
            ate_curves.append(decode(run["curve"], scale))
            ate_colours.append(colour(run["color"]))
            ate_layers.append(path["ate_layer"])
            items.append((ate_curves[-1], path["name"] + " ATE", path["ate_layer"], run["color"]))
    for marker in document["markers"]:
        x, y, z = (factor * v for v in marker["position"])
        dots.append(Rhino.Geometry.TextDot(marker["label"], Rhino.Geometry.Point3d(x, y, z)))
        dot_layers.append(marker["layer"])
        rgb = path_colours[marker["path"]] if marker["kind"] == "worst" else [158, 158, 158]
        rgb = marker.get("color", rgb)
        items.append((dots[-1], marker["label"], marker["layer"], rgb))
    for point in document.get("points", []):  # control points and measured positions
        x, y, z = (factor * v for v in point["position"])
        points.append(Rhino.Geometry.Point(Rhino.Geometry.Point3d(x, y, z)))
        point_layers.append(point["layer"])
        items.append((points[-1], point["label"], point["layer"], point["color"]))
    if bake and doc is not None:
        bake_all(doc, items)
    meta = document["metadata"]
    info = "%s | file units %s | simplified within %s m (max deviation %.6f m) | ATE: %s" % (
        meta["title"],
        meta["units"],
        meta["simplify_tolerance_m"],
        meta["max_deviation_m"],
        ", ".join(b["label"] for b in document["ate_bins"]),
    )
