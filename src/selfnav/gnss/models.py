"""Per-satellite measurement models for a tightly coupled filter: predicted pseudorange and
range rate (Doppler) with their Jacobians. Pure, vectorized (leading dimensions broadcast),
SI units, ECEF unless a name says otherwise.

Pseudorange of a satellite at ``r^s`` (ECEF at transmit time, satellite clock, group delay
and atmosphere already applied by the caller) seen from ``r`` with receiver clock bias ``b``
(m)::

    ρ = |r^s − r| + (Ω/c)(x^s y − y^s x) + b                                              (1)

the Earth-rotation (Sagnac) term to first order, as RTKLIB's ``geodist`` (within 2 mm of the
exact rotation of :func:`selfnav.gnss.spp.sagnac_rotate`). Range rate with receiver velocity
``v``, satellite velocity ``v^s``, receiver clock drift ``d`` (m/s) and satellite clock drift
``d^s`` (m/s)::

    ρ̇ = u·(v^s − v) + (Ω/c)(v^s_x y + x^s v_y − v^s_y x − y^s v_x) + d − d^s,
    u = (r^s − r)/|r^s − r|                                                               (2)

the time derivative of (1). (RTKLIB's ``resdop`` writes the rotation term with the opposite
sign, ``(Ω/c)(v^s_y x + y^s v_x − v^s_x y − x^s v_y)``: up to 6 mm/s, twice the term; the
test checks (2) against a numerical derivative of (1).) A Doppler D (Hz) on carrier λ is ``ρ̇ = −λ D``. Jacobians (exact
derivatives of (1), (2))::

    ∂ρ/∂r = −uᵀ + (Ω/c)(−y^s, x^s, 0),   ∂ρ/∂b = 1
    ∂ρ̇/∂r = −(Δv − u (u·Δv))ᵀ / |r^s − r| + (Ω/c)(−v^s_y, v^s_x, 0),   Δv = v^s − v
    ∂ρ̇/∂v = −uᵀ + (Ω/c)(−y^s, x^s, 0),   ∂ρ̇/∂d = 1

:func:`ecef_to_enu_jacobian` and :func:`ecef_to_geodetic_jacobian` turn the position (and
velocity) columns into ENU metres or (lat, lon, h) errors for a filter whose state is not ECEF.
"""
from __future__ import annotations

import numpy as np

from selfnav.earth import OMEGA_EARTH, WGS84, enu_rotation, radii

C_LIGHT = 299_792_458.0


def pseudorange_model(r_rx_ecef, clock_bias_m, sat_ecef):
    """Predicted pseudorange (1) and its Jacobian.

    Parameters
    ----------
    r_rx_ecef : (..., 3) m, receiver position
    clock_bias_m : (...) m, receiver clock bias ``c·δt`` (of the satellite's system)
    sat_ecef : (..., 3) m, satellite position at transmit time

    Returns
    -------
    rho : (...) m
    H : (..., 4) ``∂ρ/∂(x, y, z, b)``
    """
    r = np.asarray(r_rx_ecef, float)
    s = np.asarray(sat_ecef, float)
    d = s - r
    rng = np.linalg.norm(d, axis=-1)
    u = d / rng[..., None]
    k = OMEGA_EARTH / C_LIGHT
    rho = rng + k * (s[..., 0] * r[..., 1] - s[..., 1] * r[..., 0]) + np.asarray(clock_bias_m)
    H = np.empty(np.broadcast_shapes(u.shape, np.shape(rho) + (3,))[:-1] + (4,))
    H[..., 0] = -u[..., 0] - k * s[..., 1]
    H[..., 1] = -u[..., 1] + k * s[..., 0]
    H[..., 2] = -u[..., 2]
    H[..., 3] = 1.0
    return rho, H


def doppler_model(r_rx_ecef, v_rx_ecef, clock_drift_mps, sat_ecef, sat_vel_ecef,
                  sat_clock_drift_mps=0.0):
    """Predicted range rate (2) (m/s; the Doppler is ``−ρ̇/λ``) and its Jacobian.

    Parameters
    ----------
    r_rx_ecef, v_rx_ecef : (..., 3) receiver position (m) and velocity (m/s)
    clock_drift_mps : (...) receiver clock drift ``c·δṫ``, m/s
    sat_ecef, sat_vel_ecef : (..., 3) satellite position and velocity at transmit time
    sat_clock_drift_mps : (...) satellite clock drift ``c·δṫ^s`` (removed), m/s

    Returns
    -------
    rate : (...) m/s
    H : (..., 7) ``∂ρ̇/∂(x, y, z, vx, vy, vz, d)``
    """
    r = np.asarray(r_rx_ecef, float)
    v = np.asarray(v_rx_ecef, float)
    s = np.asarray(sat_ecef, float)
    vs = np.asarray(sat_vel_ecef, float)
    d = s - r
    rng = np.linalg.norm(d, axis=-1)
    u = d / rng[..., None]
    dv = vs - v
    udv = np.sum(u * dv, axis=-1)
    k = OMEGA_EARTH / C_LIGHT
    rate = (udv + k * (vs[..., 0] * r[..., 1] + s[..., 0] * v[..., 1] - vs[..., 1] * r[..., 0]
                       - s[..., 1] * v[..., 0])
            + np.asarray(clock_drift_mps) - np.asarray(sat_clock_drift_mps))
    dr = -(dv - u * udv[..., None]) / rng[..., None]
    H = np.empty(u.shape[:-1] + (7,))
    H[..., 0] = dr[..., 0] - k * vs[..., 1]
    H[..., 1] = dr[..., 1] + k * vs[..., 0]
    H[..., 2] = dr[..., 2]
    H[..., 3] = -u[..., 0] - k * s[..., 1]
    H[..., 4] = -u[..., 1] + k * s[..., 0]
    H[..., 5] = -u[..., 2]
    H[..., 6] = 1.0
    return rate, H


def ecef_to_enu_jacobian(H_ecef, lat, lon):
    """Columns ``∂/∂(x, y, z)`` (the last axis, length 3) to ``∂/∂(E, N, U)`` at ``lat, lon``
    (rad): ``H_enu = H_ecef C_e^nᵀ`` since ``δr_ecef = C_e^nᵀ δr_enu``. Use it for the position
    columns and, with the same rotation, for the velocity columns."""
    C = enu_rotation(lat, lon)                         # (..., 3, 3) ECEF -> ENU
    return np.einsum("...j,...ij->...i", np.asarray(H_ecef, float), C)


def ecef_to_geodetic_jacobian(H_ecef, lat, lon, h=0.0):
    """Columns ``∂/∂(x, y, z)`` to ``∂/∂(lat, lon, h)`` (rad, rad, m):
    ``δE = (R_N + h) cos φ δλ``, ``δN = (R_M + h) δφ``, ``δU = δh``."""
    He = ecef_to_enu_jacobian(H_ecef, lat, lon)
    rm, rn = radii(np.asarray(lat, float), h, WGS84)
    out = np.empty_like(He)
    out[..., 0] = He[..., 1] * rm
    out[..., 1] = He[..., 0] * rn * np.cos(lat)
    out[..., 2] = He[..., 2]
    return out
