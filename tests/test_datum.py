"""Datum transforms (DESIGN §5, §7) against pyproj and the regression point."""
import numpy as np
import pytest
from pyproj import Transformer
from pyproj.transformer import TransformerGroup

from selfnav import datum as D
from selfnav.earth import KRASOVSKY, PZ90, WGS84, ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from selfnav.errors import SelfnavError

# A grid over the territory where SK-42 is used (Kaliningrad to Chukotka, Caucasus to Arctic).
LAT, LON = (g.ravel() for g in np.meshgrid(np.arange(42.0, 78.0, 4.0),
                                            np.arange(20.0, 181.0, 16.0)))
H = np.linspace(-50.0, 3000.0, LAT.size)

EPSG5044 = "urn:ogc:def:coordinateOperation:EPSG::5044"


def _full_5044_pipeline():
    """EPSG:5044 as PROJ gives it, minus the push/pop that keeps the height unchanged."""
    t = Transformer.from_pipeline(EPSG5044)
    assert t.description == "Pulkovo 1942 to WGS 84 (20)"
    d = t.definition if t.definition.startswith("+") else t.to_proj4()
    assert "convention=coordinate_frame" in d
    # the operation's own parameters are the DESIGN §7 row (EPSG pinned)
    for tok in ("x=23.57", "y=-140.95", "z=-79.8", "rx=0", "ry=-0.35", "rz=-0.79", "s=-0.22"):
        assert tok in d, tok
    return t


def _enu(lat, lon):
    """(N, 3, 3) ECEF -> ENU matrices (earth.enu_rotation is per point)."""
    return np.stack([enu_rotation(a, b) for a, b in zip(np.atleast_1d(lat), np.atleast_1d(lon))])


def _horizontal_m(lat1, lon1, lat2, lon2, ell):
    d = geodetic_to_ecef(lat2, lon2, 0.0, ell) - geodetic_to_ecef(lat1, lon1, 0.0, ell)
    return np.linalg.norm(np.einsum("nij,nj->ni", _enu(lat1, lon1), d)[:, :2], axis=1)


def test_parameter_table_is_design_table():
    rows = {(p.source, p.target): p for p in D.PARAMETER_SETS}
    assert len(rows) == 5
    p = rows[("sk42", "pz90.11")]
    assert (p.dx, p.dy, p.dz, p.wx, p.wy, p.wz, p.m) == (23.557, -140.844, -79.778, -0.0023,
                                                         -0.34646, -0.79421, -0.228)
    assert p.standard.startswith("GOST 32453") and p.year == 2017
    p = rows[("pz90", "wgs84")]
    assert (p.dx, p.dy, p.dz, p.wz, p.m, p.year) == (-1.08, -0.27, -0.90, -0.16, -0.12, 2001)
    assert D.ellipsoid_of("SK-42") is KRASOVSKY and D.ellipsoid_of("PZ-90.11") is PZ90
    assert D.ellipsoid_of("wgs84") is WGS84


def test_gost_matrix_convention():
    # rotation about z by +wz (coordinate frame): the frame turns, a point on x gets y = -wz x
    p = D.HelmertParams("a", "b", 0, 0, 0, 0, 0, 1.0, 0, "test", 0)
    y = D.helmert(np.array([1e7, 0.0, 0.0]), p)
    assert y[1] == pytest.approx(-1e7 * D.ARCSEC, rel=1e-12)
    assert D.SK42_TO_WGS84.to_towgs84() == "23.57,-140.95,-79.8,-0.0,0.35,0.79,-0.22"


def test_sk42_to_wgs84_matches_epsg5044_below_1mm():
    t = _full_5044_pipeline()
    lat_p, lon_p, h_p = t.transform(LAT, LON, H)
    lat, lon, h = D.convert(np.radians(LAT), np.radians(LON), H, "sk42", "wgs84")
    assert np.max(np.abs(np.degrees(lat) - lat_p)) * 111e3 < 1e-3
    hor = _horizontal_m(lat, lon, np.radians(lat_p), np.radians(lon_p), WGS84)
    assert hor.max() < 1e-3
    # PROJ's 5044 keeps the height (push/pop): recompute it with the same operation, 3-D
    full = Transformer.from_pipeline(
        "+proj=pipeline +step +proj=axisswap +order=2,1 +step +proj=unitconvert +xy_in=deg "
        "+xy_out=rad +step +proj=cart +ellps=krass +step " + D.SK42_TO_WGS84.to_proj_helmert()
        + " +step +inv +proj=cart +ellps=WGS84 +step +proj=unitconvert +xy_in=rad +xy_out=deg "
        "+step +proj=axisswap +order=2,1")
    _, _, h_full = full.transform(LAT, LON, H)
    assert np.max(np.abs(h - h_full)) < 1e-3


def test_moscow_regression_point():
    lat, lon, h = D.convert(np.radians(55.7558), np.radians(37.6173), 0.0, "sk42", "wgs84")
    # DESIGN §7 prints 8 decimals of a degree (1.1 mm) and the height to 1 mm
    assert np.degrees(lat) == pytest.approx(55.75584266, abs=1e-8)
    assert np.degrees(lon) == pytest.approx(37.61542548, abs=1e-8)
    assert h == pytest.approx(4.547, abs=1e-3)
    # and back
    lat0, lon0, h0 = D.convert(lat, lon, h, "wgs84", "sk42")
    assert np.degrees(lat0) == pytest.approx(55.7558, abs=1e-11)
    assert np.degrees(lon0) == pytest.approx(37.6173, abs=1e-11)
    assert h0 == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("convention", ["coordinate_frame", "position_vector"])
def test_pz9011_against_custom_pyproj_pipeline(convention):
    """GOST 32453 WGS-84 -> PZ-90.11 as a PROJ Helmert step in either convention (signs
    converted for position_vector) agrees with selfnav in geodetic coordinates, 3-D."""
    p = D.WGS84_TO_PZ9011
    pipe = ("+proj=pipeline +step +proj=axisswap +order=2,1 +step +proj=unitconvert +xy_in=deg "
            "+xy_out=rad +step +proj=cart +ellps=WGS84 +step " + p.to_proj_helmert(convention)
            + " +step +inv +proj=cart +a=6378136 +rf=298.25784 +step +proj=unitconvert "
            "+xy_in=rad +xy_out=deg +step +proj=axisswap +order=2,1")
    t = Transformer.from_pipeline(pipe)
    lat_p, lon_p, h_p = t.transform(LAT, LON, H)
    lat, lon, h = D.convert(np.radians(LAT), np.radians(LON), H, "wgs84", "pz90.11")
    hor = _horizontal_m(lat, lon, np.radians(lat_p), np.radians(lon_p), PZ90)
    assert hor.max() < 1e-3
    assert np.max(np.abs(h - h_p)) < 1e-3
    # the inverse direction through PROJ's inverse step
    X = geodetic_to_ecef(np.radians(LAT), np.radians(LON), H, PZ90)
    inv = Transformer.from_pipeline("+proj=pipeline +step +inv " + p.to_proj_helmert(convention))
    Y = np.column_stack(inv.transform(X[:, 0], X[:, 1], X[:, 2]))
    assert np.max(np.abs(Y - D.convert_ecef(X, "pz90.11", "wgs84"))) < 1e-3


@pytest.mark.parametrize("p", D.PARAMETER_SETS, ids=lambda p: f"{p.source}->{p.target}")
def test_every_set_against_proj_helmert_position_vector(p):
    """Each GOST set, converted to PROJ's position-vector convention (rotations negated),
    reproduces selfnav's coordinate-frame Helmert in ECEF, both directions."""
    X = geodetic_to_ecef(np.radians(LAT), np.radians(LON), H, D.ellipsoid_of(p.source))
    fwd = Transformer.from_pipeline("+proj=pipeline +step " + p.to_proj_helmert("position_vector"))
    Y = np.column_stack(fwd.transform(X[:, 0], X[:, 1], X[:, 2]))
    assert np.max(np.abs(Y - D.helmert(X, p))) < 1e-3
    inv = Transformer.from_pipeline("+proj=pipeline +step +inv "
                                    + p.to_proj_helmert("position_vector"))
    Z = np.column_stack(inv.transform(Y[:, 0], Y[:, 1], Y[:, 2]))
    assert np.max(np.abs(Z - D.helmert(Y, p, inverse=True))) < 1e-3


def test_pz90_2001_matches_epsg_pz90_to_wgs84_2():
    ops = [t for t in TransformerGroup(4922, 4978).transformers
           if t.description.startswith("Conversion from PZ-90 (geocentric)")
           and "PZ-90 to WGS 84 (2)" in t.description]
    assert ops, "EPSG 'PZ-90 to WGS 84 (2)' missing from this PROJ database"
    X = geodetic_to_ecef(np.radians(LAT), np.radians(LON), H, PZ90)
    Y = np.column_stack(ops[0].transform(X[:, 0], X[:, 1], X[:, 2]))
    assert np.max(np.abs(Y - D.convert_ecef(X, "pz90", "wgs84"))) < 1e-3


def test_gost_signs_copied_into_towgs84_are_metres_off():
    """The convention matters: GOST (coordinate-frame) signs put unchanged into +towgs84
    (position vector) rotate the wrong way; the error is 2 (1+m) W X, tens of metres."""
    wrong = Transformer.from_crs(
        "+proj=longlat +ellps=krass +towgs84=23.57,-140.95,-79.80,0,-0.35,-0.79,-0.22 +type=crs",
        "EPSG:4979", always_xy=True)
    right = Transformer.from_crs(
        f"+proj=longlat +ellps=krass +towgs84={D.SK42_TO_WGS84.to_towgs84()} +type=crs",
        "EPSG:4979", always_xy=True)
    h0 = np.zeros_like(LAT)
    lat, lon, h = D.convert(np.radians(LAT), np.radians(LON), h0, "sk42", "wgs84")
    xr, yr, _ = right.transform(LON, LAT, h0)
    assert _horizontal_m(lat, lon, np.radians(yr), np.radians(xr), WGS84).max() < 1e-3
    xw, yw, hw = wrong.transform(LON, LAT, h0)
    # PROJ's 2-D CRS keeps h = 0: compare with our 3-D result at the same h via ECEF of both
    err = geodetic_to_ecef(np.radians(yw), np.radians(xw), hw) - geodetic_to_ecef(lat, lon, hw)
    X = geodetic_to_ecef(np.radians(LAT), np.radians(LON), h0, KRASOVSKY)
    p = D.SK42_TO_WGS84
    W = (p.matrix() / (1 + p.m * D.PPM) - np.eye(3))
    predicted = -2.0 * (1 + p.m * D.PPM) * X @ W.T
    # horizontal part of the error equals the predicted one (height is held by PROJ's 2-D CRS)
    E = _enu(lat, lon)
    e_enu = np.einsum("nij,nj->ni", E, err)[:, :2]
    p_enu = np.einsum("nij,nj->ni", E, predicted)[:, :2]
    assert np.max(np.abs(e_enu - p_enu)) < 0.01
    e3 = np.linalg.norm(predicted, axis=1)
    # |W X| vanishes where X is along the rotation axis w (near 66° N, 90° E, where the
    # mistake costs only ~2 m) and reaches 2 |w| a ~ 53 m far from it
    axis = -np.array([p.wx, p.wy, p.wz]) / np.linalg.norm([p.wx, p.wy, p.wz])
    assert np.degrees(np.arcsin(axis[2])) == pytest.approx(66.1, abs=0.1)
    assert e3.max() < 2 * np.linalg.norm([p.wx, p.wy, p.wz]) * D.ARCSEC * 6.4e6
    assert np.median(e3) > 20.0
    # Moscow: 24 m
    i = np.argmin(np.hypot(LAT - 56.0, LON - 36.0))
    assert 15.0 < e3[i] < 35.0


@pytest.mark.parametrize("p", D.PARAMETER_SETS, ids=lambda p: f"{p.source}->{p.target}")
def test_exact_inverse_round_trip(p):
    X = geodetic_to_ecef(np.radians(LAT), np.radians(LON), H, D.ellipsoid_of(p.source))
    Y = D.helmert(X, p)
    assert np.max(np.abs(D.helmert(Y, p, inverse=True) - X)) < 1e-6  # exact: nanometres
    # the standards' sign-flipped reverse set is first order: sub-millimetre, not exact
    flip = np.linalg.norm(D.helmert(Y, p.reversed()) - X, axis=1)
    assert flip.max() < 1e-3
    if abs(p.dx) > 10:
        assert flip.max() > 1e-4  # |w x dX| ~ 0.5 mm: visibly not the exact inverse


def test_every_pair_round_trips_in_geodetic():
    for a in D.DATUMS:
        for b in D.DATUMS:
            lat, lon, h = D.convert(np.radians(LAT), np.radians(LON), H, a, b)
            lat2, lon2, h2 = D.convert(lat, lon, h, b, a)
            assert np.max(np.abs(lat2 - np.radians(LAT))) * 6.4e6 < 1e-6
            assert np.max(np.abs(np.angle(np.exp(1j * (lon2 - np.radians(LON)))))) * 6.4e6 < 1e-6
            assert np.max(np.abs(h2 - H)) < 1e-6


def test_paths():
    assert D.transform_path("sk42", "sk42") == []
    assert D.transform_path("SK-42", "WGS-84") == [(D.SK42_TO_WGS84, False)]
    assert D.transform_path("wgs84", "sk42") == [(D.SK42_TO_WGS84, True)]
    assert D.transform_path("PZ-90", "PZ-90.11") == [(D.PZ90_TO_WGS84, False),
                                                     (D.WGS84_TO_PZ9011, False)]
    # the two GOST 32453 SK-42 sets are consistent through WGS-84 to a few micrometres
    X = geodetic_to_ecef(np.radians(LAT), np.radians(LON), H, KRASOVSKY)
    via = D.helmert(D.helmert(X, D.SK42_TO_PZ9011), D.WGS84_TO_PZ9011, inverse=True)
    assert np.max(np.linalg.norm(via - D.convert_ecef(X, "sk42", "wgs84"), axis=1)) < 1e-3 + 0.02
    with pytest.raises(SelfnavError, match="unknown datum"):
        D.datum_key("nad27")


def test_seed_case_pz90_ecef_to_sk42_geodetic():
    """Seed 004: GNSS in PZ-90 ECEF, output SK-42 latitude and longitude. Round trip and
    agreement with the two-step path through WGS-84 (2001 sets) to the sets' consistency."""
    lat0, lon0, h0 = np.radians(55.7558), np.radians(37.6173), 150.0
    X_pz = D.geodetic_to_ecef_in(lat0, lon0, h0, "sk42", "pz90")
    lat, lon, h = D.ecef_to_geodetic_in(X_pz, "pz90", "sk42")
    assert abs(lat - lat0) * 6.4e6 < 1e-6 and abs(lon - lon0) * 6.4e6 < 1e-6
    assert abs(h - h0) < 1e-6
    # SK-42 -> PZ-90 -> WGS-84 (2001) versus SK-42 -> WGS-84 (2017): within the 2001 sets' metre
    X_w = D.helmert(X_pz, D.PZ90_TO_WGS84)
    direct = D.convert_ecef(geodetic_to_ecef(lat0, lon0, h0, KRASOVSKY), "sk42", "wgs84")
    assert 0.1 < np.linalg.norm(X_w - direct) < 2.0
    # and ecef_to_geodetic is the iterative inverse on the Krasovsky ellipsoid
    back = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h, KRASOVSKY), KRASOVSKY)
    assert abs(back[0] - lat) < 1e-14
