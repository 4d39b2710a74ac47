"""Georeferencing of the CAD files: the DXF GEODATA object and the .3dm EarthAnchorPoint.

The CAD files hold model coordinates: the evaluation frame mapped by the site transform
into the projected CRS (Eastings, Northings, height), scaled to the output units. So the
drawing's own axes are the map grid: east is +x, grid north is +y. When the options name
a CRS (``crs``, or an IFC building's own), the files say so:

- DXF: a GEODATA object of the *local grid* kind; the design point is the site
  translation in drawing units and the reference point the same point in CRS metres
  (Eastings, Northings), north is +y (grid north), and the coordinate system definition is
  a MapGuide XML dictionary naming the EPSG code (with the full Transverse Mercator
  parameters for the UTM codes EPSG:326zz/327zz (WGS 84) and EPSG:258zz (ETRS89)).
- .3dm: the EarthAnchorPoint's model base point is the placement's base point; for the
  UTM codes its latitude and longitude are computed here (Krüger's series to n^4, exact
  to well under a millimetre within a zone) and its model north is true north (grid north turned by
  the meridian convergence); for another CRS the latitude and longitude stay unset (no
  projection library is installed) and the description says so.

ETRS89 and WGS 84 latitudes/longitudes are taken as equal (they differ by under a metre).
"""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING, Any, Final

import numpy as np

if TYPE_CHECKING:
    from ezdxf.document import Drawing

    from exporters.cad.placement import Placement

__all__ = [
    "UtmZone",
    "add_geodata",
    "crs_definition",
    "set_earth_anchor",
    "utm_to_lat_lon",
    "utm_zone",
]

_A_M: Final = 6378137.0
"""Semi-major axis of GRS 80 and WGS 84, metres."""
_INV_F: Final = {"WGS84": 298.257223563, "ETRS89": 298.257222101}
_K0: Final = 0.9996
_FALSE_EASTING_M: Final = 500000.0
_FALSE_NORTHING_SOUTH_M: Final = 10000000.0
_EPSG: Final = re.compile(r"EPSG:(\d+)", flags=re.IGNORECASE)


class UtmZone:
    """A UTM zone of a known EPSG code: zone number, hemisphere and datum."""

    __slots__ = ("datum", "epsg", "north", "zone")

    def __init__(self, epsg: int, zone: int, *, north: bool, datum: str) -> None:
        """Record the zone (1-60), the hemisphere and the datum (``WGS84`` or ``ETRS89``)."""
        self.epsg = epsg
        self.zone = zone
        self.north = north
        self.datum = datum

    @property
    def central_meridian_deg(self) -> float:
        """Longitude of the zone's central meridian, degrees."""
        return 6.0 * self.zone - 183.0

    @property
    def name(self) -> str:
        """A human name, e.g. ``ETRS89 / UTM zone 32N``."""
        return f"{self.datum} / UTM zone {self.zone}{'N' if self.north else 'S'}"


def utm_zone(crs: str | None) -> UtmZone | None:
    """Return the UTM zone of ``EPSG:326zz``, ``EPSG:327zz`` or ``EPSG:258zz``, else None."""
    match = _EPSG.fullmatch(crs or "")
    if match is None:
        return None
    code = int(match.group(1))
    if 32601 <= code <= 32660:
        return UtmZone(code, code - 32600, north=True, datum="WGS84")
    if 32701 <= code <= 32760:
        return UtmZone(code, code - 32700, north=False, datum="WGS84")
    if 25828 <= code <= 25838:
        return UtmZone(code, code - 25800, north=True, datum="ETRS89")
    return None


def utm_to_lat_lon(
    easting_m: float, northing_m: float, zone: UtmZone
) -> tuple[float, float, float]:
    """Invert the UTM projection (Krüger's series to the fourth order in n, after Karney).

    Args:
        easting_m: Easting, metres (with the false easting).
        northing_m: Northing, metres (with the false northing in the south).
        zone: the UTM zone.

    Returns:
        ``(latitude_deg, longitude_deg, convergence_deg)``; the convergence is the angle
        from true north to grid north, positive when grid north lies east of true north.
    """
    f = 1.0 / _INV_F[zone.datum]
    n = f / (2.0 - f)
    big_a = _A_M / (1.0 + n) * (1.0 + n**2 / 4.0 + n**4 / 64.0)
    beta = np.array(
        [  # Karney (2011), eq. 36, to n^4
            n / 2 - 2 * n**2 / 3 + 37 * n**3 / 96 - n**4 / 360,
            n**2 / 48 + n**3 / 15 - 437 * n**4 / 1440,
            17 * n**3 / 480 - 37 * n**4 / 840,
            4397 * n**4 / 161280,
        ]
    )
    delta = np.array(
        [  # conformal latitude -> latitude, to n^4
            2 * n - 2 * n**2 / 3 - 2 * n**3 + 116 * n**4 / 45,
            7 * n**2 / 3 - 8 * n**3 / 5 - 227 * n**4 / 45,
            56 * n**3 / 15 - 136 * n**4 / 35,
            4279 * n**4 / 630,
        ]
    )
    false_northing = 0.0 if zone.north else _FALSE_NORTHING_SOUTH_M
    xi = (northing_m - false_northing) / (_K0 * big_a)
    eta = (easting_m - _FALSE_EASTING_M) / (_K0 * big_a)
    j = np.arange(1, 5)
    xi_p = xi - float(np.sum(beta * np.sin(2 * j * xi) * np.cosh(2 * j * eta)))
    eta_p = eta - float(np.sum(beta * np.cos(2 * j * xi) * np.sinh(2 * j * eta)))
    chi = math.asin(math.sin(xi_p) / math.cosh(eta_p))
    lat = chi + float(np.sum(delta * np.sin(2 * j * chi)))
    dlon = math.atan2(math.sinh(eta_p), math.cos(xi_p))
    convergence = math.atan(math.tan(dlon) * math.sin(lat))
    return (
        math.degrees(lat),
        zone.central_meridian_deg + math.degrees(dlon),
        math.degrees(convergence),
    )


def crs_definition(crs: str) -> str:
    """Return a MapGuide coordinate system dictionary (as AutoCAD's GEODATA holds) for ``crs``.

    A UTM code gets its Transverse Mercator parameters; any other ``EPSG:<code>`` only its
    name and EPSG alias (enough for ezdxf's ``get_crs`` and for a user to pick the system).
    """
    match = _EPSG.fullmatch(crs)
    code = match.group(1) if match else "0"
    zone = utm_zone(crs)
    name = zone.name if zone is not None else crs
    projection = ""
    if zone is not None:
        parameters = (
            ("Longitude of natural origin", "degree", zone.central_meridian_deg),
            ("Latitude of natural origin", "degree", 0.0),
            ("Scale factor at natural origin", "unity", _K0),
            ("False easting", "Meter", _FALSE_EASTING_M),
            ("False northing", "Meter", 0.0 if zone.north else _FALSE_NORTHING_SOUTH_M),
        )
        values = "".join(
            f"<ParameterValue><OperationParameterId>{p}</OperationParameterId>"
            f'<Value uom="{u}">{v:g}</Value></ParameterValue>\n'
            for p, u, v in parameters
        )
        projection = (
            "<Conversion>\n<Projection>\n<OperationMethodId>Transverse Mercator"
            f"</OperationMethodId>\n{values}</Projection>\n</Conversion>\n"
            f"<DatumId>{zone.datum}</DatumId>\n"
        )
    return (
        '<?xml version="1.0" encoding="UTF-16" standalone="no" ?>\n'
        '<Dictionary version="1.0" xmlns="http://www.osgeo.org/mapguide/coordinatesystem">\n'
        f'<ProjectedCoordinateSystem id="{name}">\n<Name>{name}</Name>\n{projection}'
        '<Axis uom="Meter">\n'
        "<CoordinateSystemAxis><AxisOrder>1</AxisOrder><AxisName>Easting</AxisName>"
        "<AxisAbbreviation>E</AxisAbbreviation><AxisDirection>East</AxisDirection>"
        "</CoordinateSystemAxis>\n"
        "<CoordinateSystemAxis><AxisOrder>2</AxisOrder><AxisName>Northing</AxisName>"
        "<AxisAbbreviation>N</AxisAbbreviation><AxisDirection>North</AxisDirection>"
        "</CoordinateSystemAxis>\n</Axis>\n</ProjectedCoordinateSystem>\n"
        f'<Alias id="{code}" type="CoordinateSystem">\n<ObjectId>{name}</ObjectId>\n'
        "<Namespace>EPSG Code</Namespace>\n</Alias>\n</Dictionary>\n"
    )


def add_geodata(doc: Drawing, placement: Placement) -> None:
    """Add the GEODATA object of a placement with a CRS (nothing without one).

    The design point is the site translation in drawing units, the reference point the
    same point in CRS metres; north is the drawing's +y (the drawing is in grid axes).
    """
    if placement.crs is None:
        return
    origin_m = placement.site.translation
    geodata = doc.modelspace().new_geodata()
    geodata.setup_local_grid(
        design_point=tuple(origin_m * placement.units.per_metre),
        reference_point=(float(origin_m[0]), float(origin_m[1])),
        north_direction=(0.0, 1.0),
        crs=crs_definition(placement.crs),
    )


def set_earth_anchor(anchor: Any, placement: Placement, rhino: Any) -> str:  # noqa: ANN401
    """Set a rhino3dm EarthAnchorPoint's base point and, for a UTM CRS, its latitude/longitude.

    Args:
        anchor: ``File3dm.Settings.EarthAnchorPoint`` (assign it back afterwards).
        placement: the placed paths (base point, units, CRS).
        rhino: the ``rhino3dm`` module (passed in so this module does not import it).

    Returns:
        A sentence for the anchor's description: what the anchor holds.
    """
    base_m = placement.base_point_m
    anchor.ModelBasePoint = rhino.Point3d(*placement.base_point.tolist())
    zone = utm_zone(placement.crs)
    if zone is None:
        if placement.crs is None:
            return "No coordinate reference system is known, so no latitude/longitude."
        return (
            f"The base point's latitude/longitude in {placement.crs} are not set: only UTM "
            "codes are converted (no projection library is installed)."
        )
    lat, lon, convergence = utm_to_lat_lon(float(base_m[0]), float(base_m[1]), zone)
    anchor.EarthBasepointLatitude = lat
    anchor.EarthBasepointLongitude = lon
    anchor.EarthBasepointElevation = float(base_m[2])
    gamma = math.radians(convergence)  # true north is grid north turned back by it
    anchor.ModelNorth = rhino.Vector3d(-math.sin(gamma), math.cos(gamma), 0.0)
    anchor.ModelEast = rhino.Vector3d(math.cos(gamma), math.sin(gamma), 0.0)
    return (
        f"Latitude/longitude of the base point from {placement.crs} ({zone.name}); "
        f"model north is true north, {convergence:+.4f} degrees from grid north."
    )
