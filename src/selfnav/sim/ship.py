"""A ship at sea: straight course, slowly varying speed, roll/pitch/yaw oscillations (simulated).

Used by the moving-base method (seed 002/003, DESIGN §4) and by the ``simulate ship`` scenario.
The attitude is given analytically, so the body rates are exact:

    ω_ib^b = ω_nb^b + C_n^b (ω_ie^n + ω_en^n)

with ``ω_nb^b`` from the Euler-angle rates by seed 002 (6) (ψ = −heading,
:func:`selfnav.attitude.euler_rates_to_body`) and ``ω_in^n = ω_ie^n + ω_en^n`` from
:func:`selfnav.earth.nav_rate_n`. These are *instantaneous* rates; the simulator's IMU files
(:func:`selfnav.sim.inverse.imu_from_trajectory`) hold interval means.
"""
from __future__ import annotations

import numpy as np

from selfnav import attitude as att
from selfnav import earth
from selfnav.earth import radii
from selfnav.types import Trajectory


def ship_trajectory(duration=1800.0, dt=0.01, lat0=np.radians(45.0), lon0=np.radians(30.0), *,
                    speed=6.0, speed_amp=1.0, speed_period=600.0, course_deg=30.0,
                    roll_amp_deg=5.0, pitch_amp_deg=2.0, yaw_amp_deg=5.0,
                    roll_period=9.0, pitch_period=6.5, yaw_period=15.0, h=0.0,
                    seed=None) -> Trajectory:
    """Simulated ship track.

    Parameters
    ----------
    duration, dt : s
    lat0, lon0 : rad, start position (WGS-84)
    speed, speed_amp, speed_period : m/s, m/s, s — speed ``speed + speed_amp sin(2πt/T)``
        (default 5–7 m/s)
    course_deg : track angle, clockwise from North (negative for westward tracks)
    roll_amp_deg, pitch_amp_deg, yaw_amp_deg : amplitudes of the sinusoidal oscillations; the
        heading oscillates about the course
    roll_period, pitch_period, yaw_period : s
    seed : random phases of the oscillations (``None`` gives fixed phases 0.3, 1.1, 2.0 rad)

    Returns
    -------
    Trajectory
        With the analytic ``ω_nb^b`` attached as ``traj.omega_nb_b`` (used by
        :func:`exact_body_rates`).
    """
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    if seed is None:
        ph = np.array([0.3, 1.1, 2.0])
    else:
        ph = np.random.default_rng(seed).uniform(0, 2 * np.pi, 3)
    w = 2 * np.pi / np.array([roll_period, pitch_period, yaw_period])
    amp = np.radians([roll_amp_deg, pitch_amp_deg, yaw_amp_deg])
    course = np.radians(course_deg)
    roll = amp[0] * np.sin(w[0] * t + ph[0])
    pitch = amp[1] * np.sin(w[1] * t + ph[1])
    heading = course + amp[2] * np.sin(w[2] * t + ph[2])
    rates = amp * w * np.cos(w * t[:, None] + ph)
    spd = speed + speed_amp * np.sin(2 * np.pi * t / speed_period)
    v = np.stack([spd * np.sin(course), spd * np.cos(course), np.zeros(n)], axis=-1)
    # position: integrate φ̇ = v_N / R_φ, λ̇ = v_E / (R_λ cos φ)
    def deriv(phi, vel):
        r_phi, r_lam = radii(phi, h)
        return vel[1] / r_phi, vel[0] / (r_lam * np.cos(phi))

    # fixed-point trapezoid on the whole grid: R_φ changes by < 1e-9 relative per step, so three
    # passes converge to the trapezoid solution (error ~ dt² φ⃛, far below 1e-12 rad)
    phi = np.full(n, float(lat0))
    for _ in range(3):
        dphi, dlam = deriv(phi, v.T)
        phi = lat0 + np.concatenate([[0.0], np.cumsum(0.5 * dt * (dphi[1:] + dphi[:-1]))])
    dphi, dlam = deriv(phi, v.T)
    lat = phi
    lon = lon0 + np.concatenate([[0.0], np.cumsum(0.5 * dt * (dlam[1:] + dlam[:-1]))])
    C_nb = att.dcm_nb_from_euler(roll, pitch, heading)
    traj = Trajectory(t, lat, lon, np.full(n, float(h)), v, C_nb,
                      source=f"simulated ship: {speed - speed_amp:g}-{speed + speed_amp:g} m/s, "
                             f"course {course_deg:g} deg, roll/pitch/yaw ±{roll_amp_deg:g}/"
                             f"{pitch_amp_deg:g}/{yaw_amp_deg:g} deg")
    traj.omega_nb_b = att.euler_rates_to_body(roll, pitch, rates[:, 0], rates[:, 1], rates[:, 2])
    return traj


def _numeric_omega_nb_b(traj: Trajectory):
    """``ω_nb^b`` by a 5-point central difference of the rotation (error ~ dt⁴)."""
    C_bn = np.swapaxes(traj.C_nb, -1, -2)
    t = traj.t
    n = len(t)
    out = np.zeros((n, 3))
    dt = np.diff(t)
    h = float(np.median(dt))
    if not np.allclose(dt, h, rtol=1e-6) or n < 5:
        raise ValueError("numeric body rates need a uniform grid of at least 5 samples")
    # rotation vectors of C_bn[k]^T C_bn[k+j] (body frame) for j = -2..2
    def rv(j):
        a = np.clip(np.arange(n) + j, 0, n - 1)
        return att.dcm_to_rotvec(traj.C_nb @ C_bn[a]), a - np.arange(n)

    r_m2, s_m2 = rv(-2)
    r_m1, s_m1 = rv(-1)
    r_p1, s_p1 = rv(1)
    r_p2, s_p2 = rv(2)
    out = (r_m2 - 8 * r_m1 + 8 * r_p1 - r_p2) / (12 * h)
    # ends: one-sided first differences
    for k in (0, 1):
        out[k] = att.dcm_to_rotvec(traj.C_nb[k] @ C_bn[k + 1]) / h
    for k in (n - 2, n - 1):
        out[k] = att.dcm_to_rotvec(traj.C_nb[k - 1] @ C_bn[k]) / h
    return out


def exact_body_rates(traj: Trajectory):
    """Exact gyro rates ``ω_ib^b`` (N, 3) for a trajectory (no sensor errors).

    ``ω_ib^b = ω_nb^b + C_n^b (ω_ie^n + ω_en^n)``. ``ω_nb^b`` is the analytic one attached by
    :func:`ship_trajectory`, else a 5-point numerical derivative of the attitude.
    """
    w_nb = getattr(traj, "omega_nb_b", None)
    if w_nb is None:
        w_nb = _numeric_omega_nb_b(traj)
    return w_nb + np.einsum("nij,nj->ni", traj.C_nb, nav_rate_n(traj))


def nav_rate_n(traj: Trajectory):
    """True ``ω_in^n = ω_ie^n + ω_en^n`` along a trajectory (N, 3), ENU."""
    return earth.nav_rate_n(traj.lat, traj.velocity_n, traj.h)
