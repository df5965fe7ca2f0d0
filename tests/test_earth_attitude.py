"""Earth model and attitude convention against independent oracles (pyproj, scipy)."""
import numpy as np
import pytest
from pyproj import Transformer
from scipy.spatial.transform import Rotation

from selfnav import attitude as att
from selfnav import earth


def test_normal_gravity_reference_values():
    # WGS-84 normal gravity at the equator and pole (TR8350.2 table 3.4)
    assert earth.normal_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert earth.normal_gravity(np.pi / 2) == pytest.approx(9.8321849378, abs=1e-9)
    # free-air gradient about -0.3086 mGal/m near the surface
    g0, g1 = earth.normal_gravity(np.radians(45), [0.0, 100.0])
    assert (g1 - g0) / 100.0 == pytest.approx(-3.086e-6, rel=2e-3)


def test_seed_rounded_gravity_is_low():
    lat = np.radians(np.linspace(0, 90, 10))
    d = earth.normal_gravity(lat) - earth.normal_gravity(lat, seed_constants=True)
    assert np.all(d * 1e5 > 18) and np.all(d * 1e5 < 33)  # DESIGN §7: 18-33 mGal


@pytest.mark.parametrize("ell,crs", [(earth.WGS84, "EPSG:4979"), (earth.KRASOVSKY, None)])
def test_geodetic_ecef_round_trip_and_pyproj(ell, crs):
    rng = np.random.default_rng(0)
    lat = rng.uniform(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6, 500)
    lon = rng.uniform(-np.pi, np.pi, 500)
    h = rng.uniform(-500, 1e4, 500)
    xyz = earth.geodetic_to_ecef(lat, lon, h, ell)
    la, lo, hh = earth.ecef_to_geodetic(xyz, ell)
    assert np.max(np.abs(la - lat)) < 1e-12 and np.max(np.abs(hh - h)) < 1e-6
    assert np.max(np.abs(np.angle(np.exp(1j * (lo - lon))))) < 1e-12
    if crs:
        tr = Transformer.from_crs(crs, "EPSG:4978", always_xy=True)
        x, y, z = tr.transform(np.degrees(lon), np.degrees(lat), h)
        assert np.max(np.abs(np.column_stack([x, y, z]) - xyz)) < 1e-6


def test_radii_against_closed_forms():
    rm, rn = earth.radii(0.0)
    a, e2 = earth.WGS84.a, earth.WGS84.e2
    assert rn == pytest.approx(a) and rm == pytest.approx(a * (1 - e2))
    rm, rn = earth.radii(np.pi / 2)
    assert rm == pytest.approx(rn)  # at the pole both equal a^2/b


def test_dcm_convention_matches_seed_and_scipy():
    rng = np.random.default_rng(1)
    r, p, h = rng.uniform(-np.pi, np.pi, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(0, 2 * np.pi, 50)
    C = att.dcm_nb_from_euler(r, p, h)
    # orthonormal, right-handed
    assert np.allclose(C @ np.swapaxes(C, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(C), 1.0)
    # DESIGN §2 axis check: second row = forward axis in ENU
    fwd = np.stack([np.cos(p) * np.sin(h), np.cos(p) * np.cos(h), np.sin(p)], -1)
    assert np.allclose(C[:, 1, :], fwd, atol=1e-12)
    # seed 000 (2.1): element c13 = -sin(γ) cos(θ)
    assert np.allclose(C[:, 0, 2], -np.sin(r) * np.cos(p))
    # scipy: C_b^n = Rz(ψ) Rx(θ) Ry(γ) active, intrinsic 'ZXY', ψ = -heading
    Cs = Rotation.from_euler("ZXY", np.column_stack([-h, p, r])).as_matrix()
    assert np.allclose(np.swapaxes(C, -1, -2), Cs, atol=1e-12)
    # round trip
    r2, p2, h2 = att.euler_from_dcm_nb(C)
    assert np.allclose(p2, p) and np.allclose(np.cos(r2 - r), 1) and np.allclose(np.cos(h2 - h), 1)


def test_roll_right_side_down_positive():
    C = att.dcm_nb_from_euler(np.radians(10), 0.0, 0.0)
    right_axis_in_enu = C[0]
    assert right_axis_in_enu[2] < 0


def test_quaternion_rotvec_against_scipy():
    rng = np.random.default_rng(2)
    R = Rotation.random(100, random_state=3)
    rv = R.as_rotvec()
    q = att.rotvec_to_quat(rv)
    assert np.allclose(att.quat_to_dcm(q), R.as_matrix(), atol=1e-12)
    assert np.allclose(att.rotvec_to_dcm(rv), R.as_matrix(), atol=1e-12)
    qs = R.as_quat(scalar_first=True)
    qs *= np.sign(qs[:, :1])
    assert np.allclose(att.dcm_to_quat(R.as_matrix()), qs, atol=1e-12)
    assert np.allclose(att.dcm_to_rotvec(R.as_matrix()), rv, atol=1e-9)
    R2 = Rotation.random(100, random_state=4)
    prod = att.quat_multiply(att.dcm_to_quat(R.as_matrix()), att.dcm_to_quat(R2.as_matrix()))
    assert np.allclose(att.quat_to_dcm(prod), (R * R2).as_matrix(), atol=1e-12)
    v = rng.normal(size=(10, 3))
    u = rng.normal(size=(10, 3))
    assert np.allclose(att.skew(v) @ u[..., None], np.cross(v, u)[..., None])
    assert np.allclose(att.vee(att.skew(v)), v)


def test_orthonormalize_and_slerp():
    R = Rotation.random(5, random_state=5).as_matrix()
    noisy = R + 1e-4 * np.random.default_rng(6).normal(size=R.shape)
    Co = att.orthonormalize(noisy)
    assert np.allclose(Co @ np.swapaxes(Co, -1, -2), np.eye(3), atol=1e-12)
    assert np.max(np.abs(Co - R)) < 1e-3
    t = np.array([0.0, 1.0])
    C2 = np.stack([np.eye(3), att.rotvec_to_dcm(np.array([0, 0, 0.4]))])
    mid = att.slerp_dcm(t, C2, np.array([0.25]))
    assert np.allclose(mid[0], att.rotvec_to_dcm(np.array([0, 0, 0.1])), atol=1e-12)
