"""What a window of driving tells a vehicle's in-motion start (DESIGN §10).

A vehicle's in-motion start (:func:`selfnav.ins.align.init_from_gnss`,
:func:`selfnav.ins.anystart.init_anywhere`) takes its heading from the course of a line fitted
through a window of fixes: :func:`course_heading_covariance` is the covariance of a heading
that *is* that velocity's course. :func:`window_gyro_bias` takes the gyro biases about the
level axes from the window's mean rate (a road vehicle's tilt changes by its road's grade at
most).
"""
from __future__ import annotations

import numpy as np


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
