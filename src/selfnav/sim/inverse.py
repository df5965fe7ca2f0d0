"""Exact inverse strapdown: error-free gyro and accelerometer increments from a trajectory.

The trajectory samples are joined by smooth curves: a cubic spline of ``(φ, λ, h)`` and a cubic
spline of the attitude quaternion (normalised on evaluation, so it is a rotation everywhere and
passes through every sample). Along that continuous motion the sensors see, in the ENU
mechanization of :mod:`selfnav.ins.strapdown` (seed 004 (2), (4), (6)–(10))::

    V_E = (R_λ) cos φ λ̇,   V_N = R_φ φ̇,   V_U = ḣ                      (R_φ, R_λ include h)
    ω_en^n = (-V_N/R_φ, V_E/R_λ, V_E tan φ / R_λ),   ω_ie^n = Ω (0, cos φ, sin φ)
    f^n = V̇ + (2 ω_ie^n + ω_en^n) × V + (0, 0, γ(φ, h))                  (seed 004 (8), inverted)
    ω_ib^b = ω_nb^b + C_n^b (ω_ie^n + ω_en^n),   q̇ = ½ q ⊗ (0, ω_nb^b)

and the increments ``Δθ_k = ∫ω_ib^b dt``, ``Δv_k = ∫f^b dt`` over each output interval are
integrated by Gauss-Legendre quadrature of the continuous signals. They are what an ideal
integrating IMU outputs; they carry the coning and sculling of the motion, so a strapdown
integrator with coning and sculling corrections returns the trajectory (the approach of the
reference simulator pyins, independently written).
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from selfnav import attitude as att
from selfnav.earth import WGS84, Ellipsoid, normal_gravity
from selfnav.types import ImuData
from selfnav.types import Trajectory

CHUNK = 65536


def _quat_to_C_nb(q):
    """``C_n^b`` from unit quaternions of ``C_b^n`` (scalar first), preallocated (fast)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    C = np.empty((len(q), 3, 3))
    C[:, 0, 0] = 1 - 2 * (y * y + z * z)
    C[:, 1, 1] = 1 - 2 * (x * x + z * z)
    C[:, 2, 2] = 1 - 2 * (x * x + y * y)
    C[:, 1, 0] = 2 * (x * y - w * z)   # transposed C_b^n
    C[:, 0, 1] = 2 * (x * y + w * z)
    C[:, 2, 0] = 2 * (x * z + w * y)
    C[:, 0, 2] = 2 * (x * z - w * y)
    C[:, 2, 1] = 2 * (y * z - w * x)
    C[:, 1, 2] = 2 * (y * z + w * x)
    return C


def _continuous_quat(C_nb):
    q = att.dcm_to_quat(np.swapaxes(C_nb, -1, -2))  # represents C_b^n
    flip = np.sum(q[1:] * q[:-1], axis=1) < 0
    sign = np.concatenate([[1.0], np.cumprod(np.where(flip, -1.0, 1.0))])
    return q * sign[:, None]


class TrajectorySpline:
    """Continuous position and attitude through the samples of a :class:`Trajectory`.

    Parameters
    ----------
    traj : Trajectory
    ellipsoid : Ellipsoid
        Geometry and normal gravity (WGS-84 by default, as the strapdown integrator).
    """

    def __init__(self, traj: Trajectory, ellipsoid: Ellipsoid = WGS84):
        self.traj = traj
        self.ell = ellipsoid
        t = np.asarray(traj.t, dtype=float)
        pos = np.column_stack([traj.lat, np.unwrap(traj.lon), traj.h])
        self.pos = CubicSpline(t, pos)
        self.att = CubicSpline(t, _continuous_quat(np.asarray(traj.C_nb, dtype=float)))
        self.t0, self.t1 = float(t[0]), float(t[-1])

    def kinematics(self, t, rates: bool = True) -> dict:
        """Position, velocity, acceleration, attitude and the true sensor rates at times ``t``.

        Returns
        -------
        dict: ``lat, lon, h`` (N,), ``velocity_n``, ``accel_n`` (N, 3), ``C_nb`` (N, 3, 3),
        ``omega_ib_b``, ``omega_nb_b``, ``f_ib_b`` (N, 3) — rad, m, s (the last three and
        ``accel_n`` only with ``rates``).
        """
        t = np.asarray(t, dtype=float)
        p, pd, pdd = self.pos(t), self.pos(t, 1), self.pos(t, 2)
        lat, lon, h = p[:, 0], p[:, 1], p[:, 2]
        dlat, dlon, dh = pd[:, 0], pd[:, 1], pd[:, 2]
        a, e2 = self.ell.a, self.ell.e2
        sl, cl = np.sin(lat), np.cos(lat)
        w = np.sqrt(1.0 - e2 * sl * sl)
        rn, rm = a / w, a * (1.0 - e2) / w**3
        drn = a * e2 * sl * cl / w**3
        drm = 3.0 * a * (1.0 - e2) * e2 * sl * cl / w**5
        R_lam, R_phi = rn + h, rm + h
        v = np.column_stack([R_lam * cl * dlon, R_phi * dlat, dh])
        acc = np.column_stack([
            ((drn * dlat + dh) * cl - R_lam * sl * dlat) * dlon + R_lam * cl * pdd[:, 1],
            (drm * dlat + dh) * dlat + R_phi * pdd[:, 0],
            pdd[:, 2]])
        q = self.att(t)
        nq2 = np.sum(q * q, axis=1)
        C_nb = _quat_to_C_nb(q / np.sqrt(nq2)[:, None])
        out = {"lat": lat, "lon": lon, "h": h, "velocity_n": v, "C_nb": C_nb}
        if not rates:
            return out
        om_ie = self.ell.omega * np.column_stack([np.zeros_like(lat), cl, sl])
        om_en = np.column_stack([-v[:, 1] / R_phi, v[:, 0] / R_lam, v[:, 0] * sl / cl / R_lam])
        g = normal_gravity(lat, h, self.ell)
        f_n = acc + np.cross(2.0 * om_ie + om_en, v)
        f_n[:, 2] += g
        qd = self.att(t, 1)
        w0, vq = q[:, :1], q[:, 1:]
        om_nb = 2.0 * (w0 * qd[:, 1:] - qd[:, :1] * vq - np.cross(vq, qd[:, 1:])) / nq2[:, None]
        om_ib = om_nb + np.einsum("nij,nj->ni", C_nb, om_ie + om_en)
        f_b = np.einsum("nij,nj->ni", C_nb, f_n)
        out.update({"accel_n": acc, "omega_ib_b": om_ib, "omega_nb_b": om_nb, "f_ib_b": f_b})
        return out

    def increments(self, t_out, t_start=None, nodes: int = 3):
        """``Δθ`` and ``Δv`` (N, 3) over ``[t_{k-1}, t_k]`` for the ends ``t_out`` (N,).

        ``t_start`` is the start of the first interval (``t_out[0] - (t_out[1] - t_out[0])``
        by default). Gauss-Legendre with ``nodes`` points per interval (3: exact for quintic
        signals; the splines are piecewise cubic in position and quaternion).
        """
        t_out = np.asarray(t_out, dtype=float)
        if t_start is None:
            t_start = t_out[0] - (t_out[1] - t_out[0])
        ends = np.concatenate([[t_start], t_out])
        x, wts = np.polynomial.legendre.leggauss(nodes)
        dth = np.empty((len(t_out), 3))
        dv = np.empty((len(t_out), 3))
        for i in range(0, len(t_out), CHUNK):
            a, b = ends[i:i + CHUNK + 1][:-1], ends[i + 1:i + CHUNK + 1]
            half = 0.5 * (b - a)
            tn = (0.5 * (a + b))[:, None] + half[:, None] * x[None, :]
            k = self.kinematics(tn.ravel())
            m = len(a)
            wq = (half[:, None] * wts[None, :])[..., None]
            dth[i:i + m] = np.sum(k["omega_ib_b"].reshape(m, nodes, 3) * wq, axis=1)
            dv[i:i + m] = np.sum(k["f_ib_b"].reshape(m, nodes, 3) * wq, axis=1)
        return dth, dv

    def trajectory(self, t, source=None) -> Trajectory:
        """The continuous motion sampled at ``t``: the truth that matches the increments."""
        k = self.kinematics(t, rates=False)
        return Trajectory(np.asarray(t, dtype=float), k["lat"], np.angle(np.exp(1j * k["lon"])),
                          k["h"], k["velocity_n"], k["C_nb"], source or self.traj.source)


def imu_from_trajectory(traj: Trajectory, dt: float | None = None, *, nodes: int = 3,
                        ellipsoid: Ellipsoid = WGS84, return_truth: bool = False):
    """Error-free IMU data along a trajectory (exact inverse strapdown).

    Parameters
    ----------
    traj : Trajectory
        Any sampling; it is splined (see :class:`TrajectorySpline`).
    dt : float, optional
        Output interval, s (the trajectory's median interval by default). Samples end at
        ``t0 + k dt``, ``k = 1..N``, within the trajectory span.
    return_truth : bool
        Also return the truth :class:`Trajectory` at ``t0, t0 + dt, ...`` (N + 1 samples: the
        initial state and the end of every interval), consistent with the spline.

    Returns
    -------
    ImuData
        ``omega_ib_b = Δθ/dt``, ``f_ib_b = Δv/dt`` (interval means), ``t`` at interval ends;
        ``meta["dtheta"]``, ``meta["dv"]`` hold the increments, ``meta["t0"]`` the start.
    """
    sp = TrajectorySpline(traj, ellipsoid)
    if dt is None:
        dt = float(np.median(np.diff(traj.t)))
    n = int(np.floor((sp.t1 - sp.t0) / dt + 1e-9))
    t = sp.t0 + dt * np.arange(1, n + 1)
    dth, dv = sp.increments(t, sp.t0, nodes)
    imu = ImuData(t, dth / dt, dv / dt, source=f"simulated, exact inverse strapdown of "
                  f"{traj.source}", meta={"simulated": True, "dtheta": dth, "dv": dv,
                                          "t0": sp.t0, "dt": dt})
    if return_truth:
        return imu, sp.trajectory(np.concatenate([[sp.t0], t]))
    return imu
