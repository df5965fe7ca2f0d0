"""IGRF-14 shipped with the package: the field model every install uses (no optional extra)."""
import datetime as dt

import numpy as np
import pytest

from selfnav import igrf
from selfnav.sensors import declination_inclination, earth_field_n

#: (lat, lon, h) and IGRF declination, deg (2025.0; the issue's figures for Kotka and Moscow)
SITES = {"Kotka": ((60.47, 26.95, 0.0), 11.0), "Moscow": ((55.7558, 37.6173, 150.0), 11.9),
         "Helsinki": ((60.17, 24.94, 0.0), 10.2)}


def test_declination_within_one_degree_of_igrf_at_the_issues_sites():
    for name, ((la, lo, h), d_ref) in SITES.items():
        b = earth_field_n(np.radians(la), np.radians(lo), h)      # default model: IGRF-14
        d = np.degrees(declination_inclination(b)[0])
        assert abs(d - d_ref) < 1.0, (name, d)
        # the tilted dipole (the old fallback) is tens of degrees off there
        dd = np.degrees(declination_inclination(earth_field_n(np.radians(la), np.radians(lo), h,
                                                              model="dipole"))[0])
        assert abs(dd - d_ref) > 20.0


def test_agrees_with_the_independent_ppigrf_package():
    ppigrf = pytest.importorskip("ppigrf")
    rng = np.random.default_rng(5)
    lat = rng.uniform(-89.0, 89.0, 40)
    lon = rng.uniform(-180.0, 180.0, 40)
    h = rng.uniform(-100.0, 20000.0, 40)
    for date in (dt.datetime(1995, 6, 1), dt.datetime(2025, 1, 1), dt.datetime(2028, 3, 15)):
        b = igrf.igrf_enu(np.radians(lat), np.radians(lon), h, date)
        be, bn, bu = ppigrf.igrf(lon, lat, h / 1000.0, date)
        ref = np.column_stack([np.ravel(be), np.ravel(bn), np.ravel(bu)])
        # nT, of a field of 20 000-65 000 nT (ppigrf interpolates in days, selfnav in decimal
        # years: 0.2 nT apart in 2028 at secular variations of ~100 nT/yr)
        np.testing.assert_allclose(b, ref, atol=0.5)
        d = np.degrees(np.arctan2(b[:, 0], b[:, 1]) - np.arctan2(ref[:, 0], ref[:, 1]))
        assert np.abs(d).max() < 0.01


def test_schmidt_legendre_low_degrees_analytic():
    th = np.linspace(0.1, 3.0, 7)
    P, dP = igrf.legendre_schmidt(th, 2)
    c, s = np.cos(th), np.sin(th)
    np.testing.assert_allclose(P[1, 0], c)
    np.testing.assert_allclose(P[1, 1], s)
    np.testing.assert_allclose(P[2, 0], 1.5 * c * c - 0.5)
    np.testing.assert_allclose(P[2, 1], np.sqrt(3) * c * s)
    np.testing.assert_allclose(P[2, 2], np.sqrt(3) / 2 * s * s)
    np.testing.assert_allclose(dP[2, 0], -3 * c * s)
    np.testing.assert_allclose(dP[2, 2], np.sqrt(3) * s * c)


def test_dates_outside_the_model_are_refused():
    from selfnav.errors import SelfnavError

    with pytest.raises(SelfnavError, match="IGRF-14 covers 1900-2030"):
        igrf.igrf_enu(0.5, 0.5, 0.0, 2040.0)


def test_core_install_needs_no_optional_package(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "ppigrf", None)   # as after `pip install .`
    b = earth_field_n(np.radians(60.47), np.radians(26.95), 0.0)
    assert abs(np.degrees(declination_inclination(b)[0]) - 11.0) < 1.0
