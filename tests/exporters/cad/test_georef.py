"""Georeferencing of the CAD files: DXF GEODATA, the .3dm EarthAnchorPoint, UTM to lat/lon."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from scipy.integrate import quad

from exporters.cad.georef import crs_definition, utm_to_lat_lon, utm_zone
from exporters.cad.placement import parse_site, place_evaluation
from exporters.options import ExportOptions, Units
from loceval.evaluation import EvaluationResult

ezdxf = pytest.importorskip("ezdxf")
rhino3dm = pytest.importorskip("rhino3dm")

from exporters.cad import dxf, rhino  # noqa: E402  (after the importorskip of its libraries)

SITE = "512340.0 5403210.5 112.3 30"
"""A site in ETRS89 / UTM zone 32N (Stuttgart area), yaw 30 degrees."""


def northing_on_central_meridian(lat_deg: float, inv_f: float) -> float:
    """Return k0 times the meridian arc to ``lat_deg`` (numerical quadrature, independent)."""
    f = 1.0 / inv_f
    e2 = f * (2.0 - f)
    arc, _ = quad(
        lambda t: 6378137.0 * (1 - e2) / (1 - e2 * math.sin(t) ** 2) ** 1.5,
        0.0,
        math.radians(lat_deg),
        epsabs=1e-9,
    )
    return 0.9996 * arc


def test_utm_zones() -> None:
    """EPSG codes of UTM zones are recognised, other CRSs are not."""
    zone = utm_zone("EPSG:25832")
    assert zone is not None
    assert (zone.zone, zone.north, zone.datum, zone.central_meridian_deg) == (
        32,
        True,
        "ETRS89",
        9.0,
    )
    south = utm_zone("epsg:32733")
    assert south is not None
    assert (south.zone, south.north, south.central_meridian_deg) == (33, False, 15.0)
    assert utm_zone("EPSG:31467") is None  # Gauss-Krüger zone 3: not UTM
    assert utm_zone(None) is None


@pytest.mark.parametrize("lat_deg", [0.0, 12.5, 48.137, 71.0])
def test_inverse_on_the_central_meridian(lat_deg: float) -> None:
    """On the central meridian the Northing is k0 times the meridian arc (quadrature)."""
    zone = utm_zone("EPSG:25832")
    assert zone is not None
    northing = northing_on_central_meridian(lat_deg, 298.257222101)
    lat, lon, convergence = utm_to_lat_lon(500000.0, northing, zone)
    assert lat == pytest.approx(lat_deg, abs=1e-9)  # 1e-9 degrees ~ 0.1 mm
    assert lon == pytest.approx(9.0, abs=1e-12)
    assert convergence == pytest.approx(0.0, abs=1e-12)


# Reference figures from PROJ, independent of our series: pyproj 3.7 in a scratch venv,
# Transformer.from_crs("EPSG:25832", "EPSG:4326", always_xy=True).transform(E, N) for latitude
# and longitude, Proj("EPSG:25832").get_factors(lon, lat).meridian_convergence for the last.
PROJ_REFERENCE = [
    (512340.0, 5403210.5, 48.78177219722457, 9.167979092305405, 0.12635492521225436),
    (300000.0, 5000000.0, 45.125153848711875, 6.456876510190135, -1.802778816385707),
    (699999.0, 7500000.0, 67.54752888848142, 13.696356092758135, 4.341777538453608),
    (500000.0, 10000.0, 0.09047313620772447, 9.0, 0.0),
]


@pytest.mark.parametrize(("easting", "northing", "lat", "lon", "convergence"), PROJ_REFERENCE)
def test_inverse_matches_proj(
    easting: float, northing: float, lat: float, lon: float, convergence: float
) -> None:
    """Latitude and longitude equal PROJ's to 1e-9 degrees (0.1 mm), grid north to 1e-5 deg."""
    zone = utm_zone("EPSG:25832")
    assert zone is not None
    got = utm_to_lat_lon(easting, northing, zone)
    assert got[0] == pytest.approx(lat, abs=1e-9)
    assert got[1] == pytest.approx(lon, abs=1e-9)
    assert got[2] == pytest.approx(convergence, abs=1e-5)


def test_inverse_is_symmetric_and_converges() -> None:
    """East and west of the central meridian mirror each other; grid north leans east there."""
    zone = utm_zone("EPSG:32632")
    assert zone is not None
    east = utm_to_lat_lon(512340.0, 5403210.5, zone)
    west = utm_to_lat_lon(487660.0, 5403210.5, zone)
    assert east[0] == pytest.approx(west[0], abs=1e-12)
    assert east[1] - 9.0 == pytest.approx(9.0 - west[1], abs=1e-12)
    # 12.34 km east at 48.8°: about 0.1666° of longitude (12340 m / (cos 48.8° * 111.2 km))
    assert east[1] - 9.0 == pytest.approx(
        12340.0 / (math.cos(math.radians(48.8)) * 111_200.0), rel=0.01
    )
    assert east[0] == pytest.approx(48.78, abs=0.01)
    assert (
        0.0 < east[2] == pytest.approx((east[1] - 9.0) * math.sin(math.radians(east[0])), rel=1e-3)
    )
    southern = utm_zone("EPSG:32733")
    assert southern is not None
    assert utm_to_lat_lon(500000.0, 10000000.0, southern)[:2] == pytest.approx((0.0, 15.0))


def test_dxf_geodata(two_estimates: EvaluationResult) -> None:
    """With a CRS the DXF has a GEODATA object: the site translation, grid north, the EPSG code."""
    options = ExportOptions(site=parse_site(SITE), crs="EPSG:25832", units=Units.MM)
    doc = ezdxf.read(io.StringIO(dxf.export_dxf(two_estimates, options).decode()))
    geodata = doc.modelspace().get_geodata()
    assert geodata is not None
    assert geodata.get_crs() == (25832, True)
    assert "Transverse Mercator" in geodata.coordinate_system_definition
    assert geodata.dxf.coordinate_type == geodata.LOCAL_GRID
    np.testing.assert_allclose(geodata.dxf.design_point, [512340000.0, 5403210500.0, 112300.0])
    np.testing.assert_allclose(list(geodata.dxf.reference_point)[:2], [512340.0, 5403210.5])
    np.testing.assert_allclose(list(geodata.dxf.north_direction)[:2], [0.0, 1.0])
    assert geodata.dxf.horizontal_unit_scale == pytest.approx(0.001)
    auditor = doc.audit()
    assert not auditor.has_errors
    plain = ezdxf.read(io.StringIO(dxf.export_dxf(two_estimates, ExportOptions()).decode()))
    assert plain.modelspace().get_geodata() is None


def test_crs_definition_of_another_crs() -> None:
    """A CRS that is not UTM is named by its EPSG alias only."""
    text = crs_definition("EPSG:31467")
    assert '<Alias id="31467" type="CoordinateSystem">' in text
    assert "Transverse Mercator" not in text


def test_3dm_earth_anchor(two_estimates: EvaluationResult) -> None:
    """With a UTM CRS the .3dm EarthAnchorPoint holds the base point's latitude/longitude."""
    options = ExportOptions(site=parse_site(SITE), crs="EPSG:25832")
    placement = place_evaluation(two_estimates, options)
    model = rhino3dm.File3dm.FromByteArray(rhino.export_3dm(two_estimates, options))
    anchor = model.Settings.EarthAnchorPoint
    base = placement.base_point_m
    zone = utm_zone("EPSG:25832")
    assert zone is not None
    # utm_to_lat_lon is checked against PROJ above (test_inverse_matches_proj).
    lat, lon, convergence = utm_to_lat_lon(float(base[0]), float(base[1]), zone)
    assert anchor.EarthBasepointLatitude == pytest.approx(lat, abs=1e-12)
    assert anchor.EarthBasepointLongitude == pytest.approx(lon, abs=1e-12)
    assert anchor.EarthBasepointElevation == pytest.approx(base[2])
    assert 48.7 < lat < 48.9
    assert 9.1 < lon < 9.2
    mb = anchor.ModelBasePoint
    np.testing.assert_allclose([mb.X, mb.Y, mb.Z], base * 1000.0)  # millimetres by default
    north = anchor.ModelNorth
    assert math.degrees(math.atan2(-north.X, north.Y)) == pytest.approx(convergence)
    assert "EPSG:25832" in anchor.Description
    other = ExportOptions(site=parse_site(SITE), crs="EPSG:31467")
    unknown = rhino3dm.File3dm.FromByteArray(rhino.export_3dm(two_estimates, other))
    assert not unknown.Settings.EarthAnchorPoint.EarthLocationIsSet()
    assert "not set" in unknown.Settings.EarthAnchorPoint.Description
