"""The course of a run of fixes and the heading at its centre (DESIGN §10).

A vehicle's in-motion start (:func:`selfnav.ins.align.init_from_gnss`,
:func:`selfnav.ins.anystart.init_anywhere`) takes its heading from the course of a line fitted
through a window of fixes. :func:`centre_state` turns the line's mean velocity into the one at
the window's centre with the IMU's shape of the motion inside it;
:func:`course_heading_covariance` is the covariance of a heading that *is* that velocity's
course; :func:`window_gyro_bias` takes the gyro biases about the level axes from the window's
mean rate (a road vehicle's tilt changes by its road's grade at most).
"""
from __future__ import annotations

import numpy as np


#: the share of the line's course-to-heading turn (:func:`centre_state`) left in the heading
#: σ: the gyro bias and the forward axis are approximations
TURN_SIGMA_SHARE = 0.5


def centre_state(imu, t_fix, t0, coef, w=None):
    """Position and velocity at ``t0`` from a straight line fitted through fixes at ``t_fix``
    and the IMU's shape of the motion between them.

    A line through the fixes gives a weighted *mean* of the velocities driven: a car that
    accelerates and brakes within the window shows its mean speed (a 17 s window over a
    2 m/s² peak: 5.7 m/s slow at σ 1 m/s, its 10 m fixes passing the line test), one that
    turns a corner a mean of its headings (16.7° off at 8 m/s). The IMU knows the shape:
    with ``z = N + iE`` and the heading ψ clockwise from North, ``v(τ) = (s0 + Δs(τ))
    e^{i(ψ0 + δψ(τ))}`` — ``δψ`` the gyros' turn about the specific force (gravity, whatever
    the mounting) from ``t0``, ``Δs`` the forward specific force less its mean, integrated
    (the body moves along its forward axis: gravity along a pitched axis, the bias and a
    constant acceleration go with the mean). The positions are then ``z0 + e^{iψ0}(s0 G1(t) +
    G2(t))`` with ``G1 = ∫ e^{iδψ}``, ``G2 = ∫ Δs e^{iδψ}`` from ``t0``, and the fit's slope
    ``S = e^{iψ0}(s0 A + B)`` (``A``, ``B`` the same fit of ``G1``, ``G2``): ``|s0 A + B| =
    |S|`` gives the speed, the phase the heading, the intercept the position.

    Parameters
    ----------
    imu : ImuData (body RFU, true time)
    t_fix : (N,) the fixes' times, s
    t0 : the time of the line's intercept (the window's centre), s
    coef : (2, 2) the fit's intercept and slope rows, columns East and North, m and m/s
    w : (N,) the fit's weights (default equal)

    Returns
    -------
    (p_en, v_en, turn) or None
        Position and velocity at ``t0`` (East, North) and the heading less the line's course
        (rad); None when the IMU does not cover the fixes or no speed solves it.
    """
    t_fix = np.asarray(t_fix, float)
    j0 = int(np.searchsorted(imu.t, t_fix[0]))
    j1 = int(np.searchsorted(imu.t, t_fix[-1], side="right"))
    if j1 - j0 < 3 or imu.t[j0] > t_fix[0] + 0.1 or imu.t[j1 - 1] < t_fix[-1] - 0.1:
        return None
    ti = imu.t[j0:j1]
    dt = np.diff(ti)

    def at(t, x):                                            # np.interp, complex too
        return np.interp(t, ti, x.real) + 1j * np.interp(t, ti, x.imag)

    def integral(x):                                         # from t0
        out = np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * dt)])
        return out - at(t0, out)

    up = imu.f_ib_b[j0:j1].mean(axis=0)
    rate = imu.omega_ib_b[j0:j1] @ (up / np.linalg.norm(up))
    dpsi = -integral(rate).real                              # clockwise, zero at t0
    a = imu.f_ib_b[j0:j1, 1] - imu.f_ib_b[j0:j1, 1].mean()
    ds = integral(a).real                                    # zero at t0: s0 is its speed
    e = np.exp(1j * dpsi)
    g1, g2 = integral(e), integral(ds * e)
    tt = t_fix - t0
    A_ls = np.column_stack([np.ones_like(tt), tt])
    sw = np.ones_like(tt) if w is None else np.sqrt(np.asarray(w, float))
    pinv = np.linalg.pinv(A_ls * sw[:, None]) * sw[None, :]  # rows: intercept, slope
    G = pinv @ np.column_stack([at(t_fix, g1), at(t_fix, g2)])
    (i1, i2), (A, B) = G[0], G[1]
    S = coef[1, 1] + 1j * coef[1, 0]
    # |s0 A + B|² = |S|²: the larger root (a speed, not its mirror)
    qa, qb, qc = abs(A) ** 2, 2.0 * (A * np.conj(B)).real, abs(B) ** 2 - abs(S) ** 2
    disc = qb * qb - 4.0 * qa * qc
    if qa <= 0.0 or disc < 0.0:
        return None
    s0 = (-qb + np.sqrt(disc)) / (2.0 * qa)
    if s0 < 0.0:
        return None
    rot = S / (s0 * A + B)                                   # e^{iψ0}
    rot = rot / abs(rot)
    z0 = (coef[0, 1] + 1j * coef[0, 0]) - rot * (s0 * i1 + i2)
    v = s0 * rot
    turn = float(np.angle(rot) - np.angle(S)) if abs(S) > 0 else 0.0
    turn = float((turn + np.pi) % (2.0 * np.pi) - np.pi)
    return np.array([z0.imag, z0.real]), np.array([v.imag, v.real]), turn


def course_heading_covariance(velocity_n, cov_v, sigma_course):
    """Covariance of a start whose heading is the course of its velocity (DESIGN §10).

    Heading ``H = atan2(v_E, v_N)`` of the velocity ``v`` (ENU, horizontal covariance
    ``cov_v``): ``δv = δs u + s δc w`` (``u`` along, ``w = (cos H, −sin H)`` across, ``s`` the
    speed), so the course error is ``δc = w·δv / s`` and the heading error
    ``ψ_U = δc − β`` with ``β`` the vehicle's own heading about its course (slip, the IMU's
    yaw on the vehicle; σ ``sigma_course``). Returns ``(P_vv, P_vψ, P_ψψ)``: the 2×2
    velocity block, its column with ``ψ_U`` and ``ψ_U``'s variance. Set independent, the
    heading and the velocity's direction — one measurement — look like two, and the
    non-holonomic constraint (the body moves along its heading) "learns" the heading from
    their difference: the start's heading σ then shrank 3× in 20 s while its error stayed
    (simulated drives, 13° at σ 4°)."""
    v = np.asarray(velocity_n, float)[:2]
    s = max(float(np.hypot(*v)), 1e-6)
    w = np.array([v[1], -v[0]]) / s
    C = np.asarray(cov_v, float)
    cv = C @ w / s
    return C, cv, float(w @ C @ w) / s**2 + float(sigma_course) ** 2


def window_gyro_bias(omega_ib_b, f_mean_b, duration, tilt_change_sigma, prior_sigma,
                     speed=0.0):
    """The gyro biases about the level axes from a window of driving (DESIGN §10).

    A vehicle's tilt over a window of ``duration`` seconds changes by no more than its road
    does (the grade and the cross-slope at the two ends), so the mean rate about the level
    axes — those perpendicular to the mean specific force ``f_mean_b``, gravity in a
    straight constant-speed window — is their bias plus ``Δtilt / duration``. That
    measurement (σ ``tilt_change_sigma / duration`` with the samples' own scatter) is fused
    with the prior (``prior_sigma`` per axis, mean zero); about the vertical the mean rate is
    the turn of the heading and the prior stays. A window that turns (mean rate ``ω`` about
    the vertical at ``speed``) tilts the mean specific force off the vertical by its
    centripetal acceleration, ``v ω / g``, and leaks ``v ω² / g`` of the turn into the level
    axes: that goes into the σ (drive_0708 circled 255° in a window of 10 m fixes that
    passed the line test: a 2.1 °/s leak). Returns the bias (body, rad/s) and its 3×3
    covariance.
    """
    w = np.asarray(omega_ib_b, float)
    u = np.asarray(f_mean_b, float)
    g = float(np.linalg.norm(u))
    u = u / g
    level = np.eye(3) - np.outer(u, u)
    z = level @ w.mean(axis=0)
    w_up = float(u @ w.mean(axis=0))
    leak = float(speed) * w_up**2 / g
    s2 = (float(tilt_change_sigma) / float(duration)) ** 2 + leak**2 + float(
        np.max(np.var(w, axis=0))) / len(w)
    p2 = float(prior_sigma) ** 2
    k = p2 / (p2 + s2)
    return k * z, level * (k * s2) + np.outer(u, u) * p2
