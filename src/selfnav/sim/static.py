"""Static and multi-position IMU records (seed 000 §3), exact at rest, with optional errors.

At rest ``ω_ib^b = C_n^b Ω_n(φ)`` and ``f^b = C_n^b (0, 0, γ(φ, h))`` (seed 000 (2.2)-(2.3)).
A *disturbed* rest (people moving in a vehicle, wind on a mast) is a small rotation ``β(t)``
about navigation-frame axes, ``C_b^n(t) = exp([β(t)]) C_b^n(0)``; its exact rate is
``ω_nb^n = J_l(β) β̇`` with the left Jacobian of SO(3), so that gyros and accelerometers agree.
"""
from __future__ import annotations

import numpy as np

from selfnav import attitude as att
from selfnav.earth import earth_rate_n, normal_gravity
from selfnav.types import ImuData


def _left_jacobian(a):
    """Left Jacobian of SO(3): ``ω_nav = J_l(β) β̇`` for ``C = exp([β]) C0``."""
    th2 = np.sum(a * a, axis=-1)
    th = np.sqrt(th2)
    small = th < 1e-5
    ths = np.where(small, 1.0, th)
    c1 = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(ths)) / ths**2)
    c2 = np.where(small, 1.0 / 6.0 - th2 / 120.0, (ths - np.sin(ths)) / ths**3)
    K = att.skew(a)
    return np.eye(3) + c1[..., None, None] * K + c2[..., None, None] * (K @ K)


def rocking(t, amplitude=np.radians(0.05), period=3.0, drift=np.radians(0.2), rng=None):
    """A disturbance ``β(t)`` and its rate: oscillations about East and North plus a tilt drift.

    Parameters
    ----------
    t : (N,) s
    amplitude : rad, of the oscillation about each horizontal axis
    period : s, of the oscillation
    drift : rad, total tilt change over the record (linear, about a random horizontal axis)
    """
    rng = np.random.default_rng(rng)
    T = t[-1] - t[0]
    ph = rng.uniform(0, 2 * np.pi, 2)
    w0 = 2 * np.pi / period
    ax = rng.normal(size=2)
    ax /= np.linalg.norm(ax)
    tau = t - t[0]
    a = np.zeros((len(t), 3))
    ad = np.zeros((len(t), 3))
    for k in range(2):
        a[:, k] = amplitude * np.sin(w0 * tau + ph[k]) + drift * ax[k] * tau / T
        ad[:, k] = amplitude * w0 * np.cos(w0 * tau + ph[k]) + drift * ax[k] / T
    return a, ad


def static_imu(lat, duration, dt=0.01, *, roll=0.0, pitch=0.0, heading=0.0, h=0.0,
               arw=0.0, vrw=0.0, gyro_bias=(0.0, 0.0, 0.0), accel_bias=(0.0, 0.0, 0.0),
               disturbance=None, seed=None) -> ImuData:
    """Simulated IMU at rest.

    Parameters
    ----------
    lat : float
        Latitude, rad.
    duration, dt : float
        Record length and sample interval, s.
    roll, pitch, heading : float
        Attitude of the unit, rad (DESIGN §2 convention).
    arw : float or (3,)
        Gyro white noise density (angle random walk), rad/√s.
    vrw : float or (3,)
        Accelerometer white noise density (velocity random walk), (m/s)/√s.
    gyro_bias, accel_bias : (3,)
        Constant biases in body axes, rad/s and m/s².
    disturbance : callable, optional
        ``f(t) -> (β, β̇)`` small rotation about nav axes (see :func:`rocking`).
    seed : int, optional
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt))
    t = dt * np.arange(1, n + 1)
    C0 = att.dcm_nb_from_euler(roll, pitch, heading)
    om_n = earth_rate_n(lat)
    g_n = np.array([0.0, 0.0, float(normal_gravity(lat, h))])
    if disturbance is None:
        w = np.tile(C0 @ om_n, (n, 1))
        f = np.tile(C0 @ g_n, (n, 1))
    else:
        a, ad = disturbance(t)
        C_nb = C0 @ np.swapaxes(att.rotvec_to_dcm(a), -1, -2)  # (exp[β] C0^T)^T
        w_nb_n = np.einsum("nij,nj->ni", _left_jacobian(a), ad)
        w = C_nb @ om_n + np.einsum("nij,nj->ni", C_nb, w_nb_n)
        f = C_nb @ g_n
    w = w + np.asarray(gyro_bias) + rng.normal(size=(n, 3)) * np.asarray(arw) / np.sqrt(dt)
    f = f + np.asarray(accel_bias) + rng.normal(size=(n, 3)) * np.asarray(vrw) / np.sqrt(dt)
    return ImuData(t, w, f, source="simulated static", meta={
        "simulated": True, "lat_deg": np.degrees(lat), "h0_m": h, "roll_deg": np.degrees(roll),
        "pitch_deg": np.degrees(pitch), "heading_deg": np.degrees(heading)})


def multiposition_imu(lat, headings, dwell, dt=0.01, *, roll=0.0, pitch=0.0, h=0.0, arw=0.0,
                      vrw=0.0, gyro_bias=(0.0, 0.0, 0.0), accel_bias=(0.0, 0.0, 0.0),
                      seed=None) -> ImuData:
    """Simulated multi-position record: the unit turned about the local vertical (seed 000 §3).

    Each position keeps the tilt ``(roll, pitch)`` of the mounting and takes a heading from
    ``headings`` (rad); the turns themselves are not recorded (the ``position`` column says
    which samples belong together). Biases are the same in every position.
    """
    rng = np.random.default_rng(seed)
    parts = []
    t0 = 0.0
    for k, hdg in enumerate(headings):
        p = static_imu(lat, dwell, dt, roll=roll, pitch=pitch, heading=hdg, h=h, arw=arw, vrw=vrw,
                       gyro_bias=gyro_bias, accel_bias=accel_bias, seed=rng.integers(2**63))
        p.t = p.t + t0
        p.position = np.full(len(p), k)
        t0 = p.t[-1] + 10.0  # ten seconds to turn the unit
        parts.append(p)
    return ImuData(
        np.concatenate([p.t for p in parts]), np.concatenate([p.omega_ib_b for p in parts]),
        np.concatenate([p.f_ib_b for p in parts]), None,
        np.concatenate([p.position for p in parts]), source="simulated multi-position",
        meta={"simulated": True, "lat_deg": np.degrees(lat), "h0_m": h})
