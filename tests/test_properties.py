"""Round trips as properties (hypothesis): attitude conventions, geodetic <-> ECEF <-> ENU, datums.

Each property is an identity the package must keep for *any* input in its domain, not only the
values of the example tests.
"""
import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from selfnav import attitude as att
from selfnav import datum
from selfnav.earth import (KRASOVSKY, PZ90, WGS84, ecef_to_enu, ecef_to_geodetic, enu_offset,
                           enu_to_geodetic, geodetic_to_ecef, geodetic_to_enu, offset_to_geodetic)

angles = st.floats(-np.pi, np.pi, allow_nan=False)
pitches = st.floats(-1.5, 1.5, allow_nan=False)           # away from the pitch singularity
lats = st.floats(-1.55, 1.55, allow_nan=False)
lons = st.floats(-np.pi, np.pi, allow_nan=False)
heights = st.floats(-500.0, 9000.0, allow_nan=False)
small = st.floats(-2000.0, 2000.0, allow_nan=False)
rotvecs = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3)
SETTINGS = settings(max_examples=60, deadline=None)


@SETTINGS
@given(angles, pitches, angles)
def test_euler_dcm_round_trip(roll, pitch, heading):
    C = att.dcm_nb_from_euler(roll, pitch, heading)
    assert np.allclose(C @ C.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(C), 1.0)
    r, p, h = att.euler_from_dcm_nb(C)
    assert np.allclose(att.dcm_nb_from_euler(r, p, h), C, atol=1e-12)
    # DESIGN §2: the second row is the forward axis in ENU
    assert np.allclose(C[1], [np.cos(pitch) * np.sin(heading), np.cos(pitch) * np.cos(heading),
                              np.sin(pitch)], atol=1e-12)


@SETTINGS
@given(rotvecs)
def test_rotation_vector_quaternion_dcm_round_trip(rv):
    rv = np.asarray(rv)
    C = att.rotvec_to_dcm(rv)
    assert np.allclose(att.rotvec_to_dcm3(rv), C, atol=1e-12)
    assert np.allclose(att.quat_to_dcm(att.dcm_to_quat(C)), C, atol=1e-10)
    back = att.rotvec_to_dcm(att.dcm_to_rotvec(C))
    assert np.allclose(back, C, atol=1e-9)


@SETTINGS
@given(lats, lons, heights)
def test_geodetic_ecef_round_trip(lat, lon, h):
    for ell in (WGS84, PZ90, KRASOVSKY):
        la, lo, hh = ecef_to_geodetic(geodetic_to_ecef(lat, lon, h, ell), ell)
        assert abs(la - lat) < 1e-11 and abs(np.angle(np.exp(1j * (lo - lon)))) < 1e-11
        assert abs(hh - h) < 1e-5


@SETTINGS
@given(st.floats(-1.4, 1.4), lons, heights, small, small, small)
@example(0.25, 0.0, 0.0, 2e-06, 0.0, 0.0)     # a wrap of every longitude difference lost 1 nm here
@example(0.0, 2.0, 0.0, 1.6274195003235498e-09, 0.0, 0.0)   # 1 ulp of longitude: 2.8 nm
def test_enu_round_trips(lat0, lon0, h0, e, n, u):
    enu = np.array([e, n, u])
    la, lo, hh = enu_to_geodetic(enu, lat0, lon0, h0)
    assert np.allclose(geodetic_to_enu(la, lo, hh, lat0, lon0, h0), enu, atol=1e-6)
    xyz = geodetic_to_ecef(la, lo, hh)
    assert np.allclose(ecef_to_enu(xyz, lat0, lon0, h0), enu, atol=1e-6)
    # the small-offset form and its inverse agree exactly with each other (to the resolution
    # of a float64 angle at the Earth's radius: one ulp of a 2 rad longitude is 2.8 nm) ...
    la2, lo2, h2 = offset_to_geodetic(lat0, lon0, h0, enu)
    assert np.allclose(enu_offset(lat0, lon0, h0, la2, lo2, h2), enu, atol=1e-8)
    # ... and with the exact tangent plane to its curvature error, ~ d (d (1 + |tan φ|) + |u|) / R
    d = np.hypot(e, n)
    tol = 0.01 + d * (d * (1.0 + abs(np.tan(lat0))) + abs(u)) / 6.3e6
    assert np.allclose(enu_offset(lat0, lon0, h0, la, lo, hh)[:2], enu[:2], atol=tol)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.7, 1.3), st.floats(0.3, 1.2), st.floats(-100.0, 3000.0),
       st.sampled_from(["sk42", "pz90", "pz90.11"]))
def test_datum_round_trip(lat, lon, h, other):
    """WGS-84 → other → WGS-84 returns the point (the Helmert sets are inverted exactly)."""
    la, lo, hh = datum.convert(lat, lon, h, "wgs84", other)
    back = datum.convert(la, lo, hh, other, "wgs84")
    assert abs(back[0] - lat) < 1e-10 and abs(back[1] - lon) < 1e-10 and abs(back[2] - h) < 1e-3
