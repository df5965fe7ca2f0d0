"""Earth model: ellipsoids, normal gravity, radii of curvature, Earth rate, geodetic <-> ECEF.

Implements DESIGN §2 (constants) and §7 (gravity). Everything is SI and radians; arrays broadcast.

References
----------
NIMA TR8350.2 (WGS-84), eq. 4-1 (Somigliana) and 4-3 (height term);
GOST 32453-2017 (PZ-90.11); Krasovsky 1940 ellipsoid (SK-42).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Earth rotation rate, rad/s (WGS-84 / PZ-90.11 value, DESIGN §2).
OMEGA_EARTH = 7.292115e-5


@dataclass(frozen=True)
class Ellipsoid:
    """Reference ellipsoid with the normal-gravity constants of its datum.

    Attributes
    ----------
    name : str
    a : float
        Semi-major axis, m.
    inv_f : float
        Inverse flattening.
    gamma_e, gamma_p : float
        Normal gravity at the equator and at the pole, m/s^2 (Somigliana).
    gm : float
        Geocentric gravitational constant, m^3/s^2 (for the height term).
    omega : float
        Rotation rate, rad/s.
    """

    name: str
    a: float
    inv_f: float
    gamma_e: float
    gamma_p: float
    gm: float = 3.986004418e14
    omega: float = OMEGA_EARTH

    # derived constants, computed once (the filters read them at every epoch)
    f: float = field(init=False, repr=False)
    b: float = field(init=False, repr=False)
    e2: float = field(init=False, repr=False)        # first eccentricity squared
    k_somigliana: float = field(init=False, repr=False)
    m: float = field(init=False, repr=False)         # ω² a² b / GM (TR8350.2)

    def __post_init__(self):
        f = 1.0 / self.inv_f
        b = self.a * (1.0 - f)
        for name, value in (("f", f), ("b", b), ("e2", f * (2.0 - f)),
                            ("k_somigliana", (b * self.gamma_p) / (self.a * self.gamma_e) - 1.0),
                            ("m", self.omega**2 * self.a**2 * b / self.gm)):
            object.__setattr__(self, name, value)


WGS84 = Ellipsoid("WGS-84", 6378137.0, 298.257223563, 9.7803253359, 9.8321849378)
# PZ-90.11: gamma_e from GOST 32453 (DESIGN §2); gamma_p is not in the digest, so the WGS-84
# value stands in (the two normal fields differ by well under 1 mGal at the pole).
PZ90 = Ellipsoid("PZ-90.11", 6378136.0, 298.25784, 9.78032836, 9.8321849378)
# Krasovsky 1940 is a geometric datum here (SK-42 coordinates); its gravity constants are WGS-84's.
KRASOVSKY = Ellipsoid("Krasovsky 1940", 6378245.0, 298.3, 9.7803253359, 9.8321849378)

#: The seed 004 (4) rounded Somigliana constants (reads 18-33 mGal low; DESIGN §7).
SEED004_GAMMA_E = 9.780
SEED004_GAMMA_P = 9.832


def normal_gravity(lat, h=0.0, ellipsoid: Ellipsoid = WGS84, *, seed_constants: bool = False):
    """Normal gravity magnitude, m/s^2.

    Somigliana's closed form on the ellipsoid (TR8350.2 eq. 4-1; seed 004 (4)) with the
    second-order height term of TR8350.2 eq. 4-3.

    Parameters
    ----------
    lat : array_like
        Geodetic latitude, rad.
    h : array_like
        Height above the ellipsoid, m.
    ellipsoid : Ellipsoid
    seed_constants : bool
        Use seed 004's rounded gamma_e = 9.780, gamma_p = 9.832 (for reproducing the seed only).
    """
    lat = np.asarray(lat, dtype=float)
    h = np.asarray(h, dtype=float)
    ell = ellipsoid
    ge, gp = (SEED004_GAMMA_E, SEED004_GAMMA_P) if seed_constants else (ell.gamma_e, ell.gamma_p)
    k = (ell.b * gp) / (ell.a * ge) - 1.0
    s2 = np.sin(lat) ** 2
    g0 = ge * (1.0 + k * s2) / np.sqrt(1.0 - ell.e2 * s2)
    # TR8350.2 eq. 4-3
    corr = 1.0 - 2.0 / ell.a * (1.0 + ell.f + ell.m - 2.0 * ell.f * s2) * h + 3.0 / ell.a**2 * h**2
    return g0 * corr


def radii(lat, h=0.0, ellipsoid: Ellipsoid = WGS84):
    """Meridian and prime-vertical radii of curvature plus height, m.

    Returns ``(R_phi, R_lambda)`` as in seed 004 §3, fast-loop step 2:
    ``R_phi = a(1-e^2)/(1-e^2 sin^2 phi)^{3/2} + h``, ``R_lambda = a/(1-e^2 sin^2 phi)^{1/2} + h``.
    """
    lat = np.asarray(lat, dtype=float)
    e2 = ellipsoid.e2
    w = np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    rn = ellipsoid.a / w
    rm = ellipsoid.a * (1.0 - e2) / w**3
    return rm + h, rn + h


def earth_rate_n(lat, omega: float = OMEGA_EARTH):
    """Earth rate in the ENU navigation frame, ``(0, Ω cos φ, Ω sin φ)`` (seed 000 (1.5))."""
    lat = np.asarray(lat, dtype=float)
    z = np.zeros_like(lat)
    return np.stack([z, omega * np.cos(lat), omega * np.sin(lat)], axis=-1)


def transport_rate_n(lat, velocity_n, h=0.0, ellipsoid: Ellipsoid = WGS84):
    """``ω_en^n = (−v_N/R_φ, v_E/R_λ, v_E tan φ / R_λ)`` in ENU for a velocity over the
    ellipsoid, rad/s (..., 3) (seed 004 (6))."""
    lat = np.asarray(lat, dtype=float)
    velocity_n = np.asarray(velocity_n, dtype=float)
    r_phi, r_lam = radii(lat, h, ellipsoid)
    ve, vn = velocity_n[..., 0], velocity_n[..., 1]
    return np.stack([-vn / r_phi, ve / r_lam, ve * np.tan(lat) / r_lam], axis=-1)


def nav_rate_n(lat, velocity_n, h=0.0, ellipsoid: Ellipsoid = WGS84):
    """Absolute rate of the ENU navigation frame ``ω_in^n = ω_ie^n + ω_en^n``, rad/s (..., 3)
    (seed 002 (1): ``(−φ̇, (Ω + λ̇) cos φ, (Ω + λ̇) sin φ)``)."""
    return earth_rate_n(lat, ellipsoid.omega) + transport_rate_n(lat, velocity_n, h, ellipsoid)


def geodetic_to_ecef(lat, lon, h=0.0, ellipsoid: Ellipsoid = WGS84):
    """Geodetic (rad, rad, m) to ECEF (m), shape ``(..., 3)``."""
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    h = np.asarray(h, dtype=float)
    e2 = ellipsoid.e2
    rn = ellipsoid.a / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    x = (rn + h) * np.cos(lat) * np.cos(lon)
    y = (rn + h) * np.cos(lat) * np.sin(lon)
    z = (rn * (1.0 - e2) + h) * np.sin(lat)
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def ecef_to_geodetic(xyz, ellipsoid: Ellipsoid = WGS84, *, iterations: int = 5):
    """ECEF (m) to geodetic ``(lat, lon, h)`` (rad, rad, m) by fixed-point iteration.

    Seed 004 notes that the inverse needs iteration; five iterations of the Bowring-started
    update reach well below a micrometre for terrestrial heights.
    """
    xyz = np.asarray(xyz, dtype=float)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    a, e2 = ellipsoid.a, ellipsoid.e2
    b = ellipsoid.b
    ep2 = (a**2 - b**2) / b**2
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    # Bowring's initial value
    th = np.arctan2(z * a, p * b)
    lat = np.arctan2(z + ep2 * b * np.sin(th) ** 3, p - e2 * a * np.cos(th) ** 3)
    for _ in range(iterations):
        rn = a / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
        h = np.where(np.abs(np.cos(lat)) > 1e-9, p / np.maximum(np.cos(lat), 1e-300) - rn,
                     np.abs(z) / np.maximum(np.abs(np.sin(lat)), 1e-300) - rn * (1 - e2))
        lat = np.arctan2(z, p * (1.0 - e2 * rn / (rn + h)))
    rn = a / np.sqrt(1.0 - e2 * np.sin(lat) ** 2)
    cl = np.cos(lat)
    h = np.where(np.abs(cl) > 1e-9, p / np.where(np.abs(cl) > 1e-9, cl, 1.0) - rn,
                 np.abs(z) - rn * (1 - e2))
    return lat, lon, h


def enu_rotation(lat, lon):
    """``C_e^n`` (ECEF -> ENU; rows are the East, North, Up unit vectors in ECEF).

    Scalars give one (3, 3) matrix, arrays a stack (..., 3, 3).
    """
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    z = np.zeros(np.broadcast(lat, lon).shape)
    return np.stack([np.stack(np.broadcast_arrays(-so, co, z), -1),
                     np.stack(np.broadcast_arrays(-sl * co, -sl * so, cl), -1),
                     np.stack(np.broadcast_arrays(cl * co, cl * so, sl), -1)], axis=-2)


def ecef_to_enu(xyz, lat0, lon0, h0=0.0, ellipsoid: Ellipsoid = WGS84):
    """ECEF points (..., 3) to exact tangent-plane ENU metres at (lat0, lon0, h0)."""
    r0 = geodetic_to_ecef(lat0, lon0, h0, ellipsoid)
    return (np.asarray(xyz, dtype=float) - r0) @ enu_rotation(lat0, lon0).T


def geodetic_to_enu(lat, lon, h, lat0, lon0, h0=0.0, ellipsoid: Ellipsoid = WGS84):
    """Exact tangent-plane ENU metres (..., 3) of geodetic points at (lat0, lon0, h0)."""
    return ecef_to_enu(geodetic_to_ecef(lat, lon, h, ellipsoid), lat0, lon0, h0, ellipsoid)


def enu_to_geodetic(enu, lat0, lon0, h0=0.0, ellipsoid: Ellipsoid = WGS84):
    """Tangent-plane ENU metres (..., 3) at (lat0, lon0, h0) back to geodetic (lat, lon, h)."""
    r0 = geodetic_to_ecef(lat0, lon0, h0, ellipsoid)
    return ecef_to_geodetic(r0 + np.asarray(enu, dtype=float) @ enu_rotation(lat0, lon0),
                            ellipsoid)


_SCALAR = (float, int, np.floating)


def enu_offset(lat0, lon0, h0, lat, lon, h, ellipsoid: Ellipsoid = WGS84):
    """ENU metres of (lat, lon, h) from (lat0, lon0, h0), small-offset form (curvature radii
    at the origin; exact to ~1e-7 relative over a few km). Arrays broadcast to (..., 3); all
    scalars give a (3,) array by a fast path (the filter calls this at every epoch)."""
    S = _SCALAR
    if isinstance(lat0, S) and isinstance(lon0, S) and isinstance(h0, S) \
            and isinstance(lat, S) and isinstance(lon, S) and isinstance(h, S):
        s2 = math.sin(lat0) ** 2
        w = math.sqrt(1.0 - ellipsoid.e2 * s2)
        rn = ellipsoid.a / w + h0
        rm = ellipsoid.a * (1.0 - ellipsoid.e2) / (w * w * w) + h0
        dlon = lon - lon0
        if abs(dlon) > math.pi:                 # across ±180° (wrapped only then: exact otherwise)
            dlon -= 2.0 * math.pi * round(dlon / (2.0 * math.pi))
        return np.array([dlon * rn * math.cos(lat0), (lat - lat0) * rm, h - h0])
    rm, rn = radii(lat0, h0, ellipsoid)
    dlon = np.asarray(lon) - lon0
    dlon = np.where(np.abs(dlon) > np.pi, dlon - 2.0 * np.pi * np.round(dlon / (2.0 * np.pi)), dlon)
    return np.stack(np.broadcast_arrays(dlon * rn * np.cos(lat0),
                                        (np.asarray(lat) - lat0) * rm,
                                        np.asarray(h) - h0), axis=-1)


def offset_to_geodetic(lat0, lon0, h0, enu, ellipsoid: Ellipsoid = WGS84):
    """Inverse of :func:`enu_offset`: (lat, lon, h) of ENU offsets (..., 3) from the origin
    (a fast path for a scalar origin and one offset: the navigator's every output)."""
    if isinstance(lat0, float) and isinstance(h0, float) and np.shape(enu) == (3,):
        w = math.sqrt(1.0 - ellipsoid.e2 * math.sin(lat0) ** 2)
        rn = ellipsoid.a / w + h0
        rm = ellipsoid.a * (1.0 - ellipsoid.e2) / (w * w * w) + h0
        e, n, u = float(enu[0]), float(enu[1]), float(enu[2])
        return lat0 + n / rm, lon0 + e / (rn * math.cos(lat0)), h0 + u
    rm, rn = radii(lat0, h0, ellipsoid)
    enu = np.asarray(enu, dtype=float)
    return (lat0 + enu[..., 1] / rm, lon0 + enu[..., 0] / (rn * np.cos(lat0)), h0 + enu[..., 2])
