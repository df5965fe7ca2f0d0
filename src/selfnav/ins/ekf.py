"""Loosely coupled INS/GNSS error-state Kalman filter and RTS smoother (DESIGN §5, §7).

The nominal state is carried by the strapdown mechanization (:class:`selfnav.ins.strapdown.Strapdown`,
seed 004 fast loop); the filter estimates its errors

    δx = [δr (ENU, m), δv (ENU, m/s), ψ (rad), δb_g (rad/s), δb_a (m/s²)]        (15 states)
         [+ δs_g, δs_a]   gyro and accelerometer scale factors (6)
         [+ δμ]           IMU pitch and yaw relative to the vehicle (2)
         [+ δl]           IMU → antenna lever arm, body RFU, m (3)
         [+ δε]           IMU time offset, s (1)
         [+ δk]           odometer scale factor (1)

with ``δ(·) = estimated − true`` and the attitude error ``C̃_b^n = (I − [ψ]) C_b^n``. Which
optional blocks exist is the :class:`StateLayout` of the configuration. Error dynamics
(psi-angle form, Groves ch. 14, simplified to what a MEMS or tactical IMU needs)::

    δṙ = δv,                       plus  δv̇_U += (2g/R) δr_U (the unstable vertical channel)
    δv̇ = f^n × ψ − (2ω_ie + ω_en) × δv − C_b^n (δb_a + diag(f_b) δs_a)
    ψ̇ = −ω_in × ψ + C_b^n (δb_g + diag(ω_b) δs_g)
    δḃ = −δb/τ + w                 (τ = ∞ by default: a turn-on constant plus a random walk
                                    whose density matches the bias instability)
    δμ̇ = δl̇ = δε̇ = δk̇ = 0 (+ a small random walk)

The process noise is ``λ Q`` with ``λ`` the noise scale that :mod:`selfnav.ins.calibrate`
adapts to the data (1 for a trusted noise model).

**GNSS position** at the antenna, with the time offset: the IMU stamps plus ``ε`` are true
time, so the INS state of stamp ``t`` is the truth at ``t + ε``; the fix at ``t_k`` is
compared with the INS shifted back by ``ε̂``::

    h(x) = r_INS − v^n ε̂ + C_b^n l̂,   ∂h/∂δr = I, ∂h/∂ψ = [C_b^n l̂ ×], ∂h/∂δl = C_b^n,
                                      ∂h/∂δε = −v^n

**GNSS velocity** at the antenna: ``v^n + C_b^n (ω_b × l̂)``.

**Odometer** (wheel speed): the forward speed in the vehicle frame at the NHC point (rear
axle), scaled by ``1 + k``: ``h(x) = (1 + k̂) v_v,F`` (see the NHC below for ``v_v``),
``∂h/∂δk = v_v,F``.

The non-holonomic constraint holds in the *vehicle* frame at a point that does not slip
sideways (the rear-axle centre), not at the IMU: ``v_v = C_vb (C_bn^T v^n + ω_b × l_nhc)``
with ``C_vb = exp([μ×])``, μ = (pitch, 0, yaw) of the IMU relative to the vehicle (small angles,
positive nose-up and to the left). Unmodelled, a 0.5° mounting pitch makes the NHC tilt the INS
by 0.5° while GNSS is out (a g·0.5° = 0.09 m/s² along-track error), and a 1.5 m lever turns
a 0.5 rad/s parking turn into 0.75 m/s of "side slip".

The covariance propagation and the Joseph-form update are numba kernels: the filter is a
Python loop over epochs (5 Hz aiding, the GNSS rate), and each epoch is a few compiled calls.
The outlier defence that decides which fixes to use lives in :mod:`selfnav.ins.guard` and
:mod:`selfnav.ins.navigator`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from selfnav import attitude as att
from selfnav.attitude import rotvec_to_dcm3, skew3
from selfnav.earth import OMEGA_EARTH, WGS84, enu_offset, radii
from selfnav.ins.config import CHI2_1_999, CHI2_2_999, CHI2_3_999, FilterConfig
from selfnav.ins.strapdown import Strapdown
from selfnav.types import Trajectory

NX = 15
IR, IV, IP, IBG, IBA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)

#: packed nominal state (the smoother's record): lat, lon, h, v(3), C_nb(9), b_g(3), b_a(3),
#: s_g(3), s_a(3), μ(2), l(3), ε(1), k(1)
PACK = dict(pos=slice(0, 3), vel=slice(3, 6), C=slice(6, 15), bg=slice(15, 18),
            ba=slice(18, 21), sg=slice(21, 24), sa=slice(24, 27), mu=slice(27, 29),
            lever=slice(29, 32), toff=slice(32, 33), odo=slice(33, 34))
PACK_SIZE = 34


@dataclass(frozen=True)
class StateLayout:
    """Where each optional error-state block sits (``None``: not estimated)."""

    nx: int
    sg: slice | None = None
    sa: slice | None = None
    mu: slice | None = None
    lever: slice | None = None
    toff: slice | None = None
    odo: slice | None = None

    @classmethod
    def of(cls, cfg: FilterConfig) -> "StateLayout":
        n = NX
        blocks = {}
        for name, size, on in (("sg", 3, cfg.states.scale_factors),
                               ("sa", 3, cfg.states.scale_factors),
                               ("mu", 2, cfg.states.mount_states),
                               ("lever", 3, cfg.states.lever_arm),
                               ("toff", 1, cfg.states.time_offset),
                               ("odo", 1, cfg.states.odometer)):
            if on:
                blocks[name] = slice(n, n + size)
                n += size
        return cls(n, **blocks)

    def blocks(self):
        """``(name, slice)`` of the optional blocks present."""
        return [(k, getattr(self, k)) for k in ("sg", "sa", "mu", "lever", "toff", "odo")
                if getattr(self, k) is not None]


# ------------------------------------------------------------------------ compiled kernels
@numba.njit(cache=True)
def _propagate_cov(P, Phi, q, nsub, Phi_acc):  # pragma: no cover - compiled
    """``nsub`` steps of ``P ← Φ P Φᵀ + diag(q)``; ``Φ_acc ← Φ^nsub Φ_acc``."""
    for _ in range(nsub):
        P[:, :] = Phi @ P @ Phi.T
        for i in range(P.shape[0]):
            P[i, i] += q[i]
        Phi_acc[:, :] = Phi @ Phi_acc
    # keep it symmetric against rounding
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s


@numba.njit(cache=True)
def _joseph(P, H, R, r):  # pragma: no cover - compiled
    """Kalman update in Joseph form, in place on ``P``; returns the error estimate ``dx``."""
    PHt = P @ H.T
    S = H @ PHt + R
    K = np.linalg.solve(S, PHt.T).T
    dx = K @ r
    IKH = -K @ H
    for i in range(IKH.shape[0]):
        IKH[i, i] += 1.0
    P[:, :] = IKH @ P @ IKH.T + K @ R @ K.T
    return dx


@numba.njit(cache=True)
def _nis(P, H, R, r):  # pragma: no cover - compiled
    """Normalised innovation squared ``rᵀ (H P Hᵀ + R)⁻¹ r``."""
    S = H @ P @ H.T + R
    return float(r @ np.linalg.solve(S, r))


@numba.njit(cache=True)
def _skew_into(M, r0, c0, x, y, z, k):  # pragma: no cover - compiled
    """``M[r0:r0+3, c0:c0+3] = k [v×]``."""
    M[r0, c0] = 0.0
    M[r0, c0 + 1] = -k * z
    M[r0, c0 + 2] = k * y
    M[r0 + 1, c0] = k * z
    M[r0 + 1, c0 + 1] = 0.0
    M[r0 + 1, c0 + 2] = -k * x
    M[r0 + 2, c0] = -k * y
    M[r0 + 2, c0 + 1] = k * x
    M[r0 + 2, c0 + 2] = 0.0


@numba.njit(cache=True)
def _fill_F(F, s, f_n, w_b, f_b, a, e2, g, omega, inv_tau_g, inv_tau_a, isg, isa):  # pragma: no cover
    """The error dynamics matrix (module docstring) at strapdown state ``s`` (lat, lon, h,
    v(3), C_bn row-major(9)); ``isg``/``isa`` the first index of the scale-factor blocks or -1."""
    F[:, :] = 0.0
    lat, h = s[0], s[2]
    ve, vn = s[3], s[4]
    sl = np.sin(lat)
    w = np.sqrt(1.0 - e2 * sl * sl)
    rn = a / w + h
    rm = a * (1.0 - e2) / (w * w * w) + h
    cl = np.cos(lat)
    wie_n, wie_u = omega * cl, omega * sl
    wen_e, wen_n, wen_u = -vn / rm, ve / rn, ve * np.tan(lat) / rn
    F[0, 3] = 1.0
    F[1, 4] = 1.0
    F[2, 5] = 1.0
    _skew_into(F, 3, 6, f_n[0], f_n[1], f_n[2], 1.0)
    _skew_into(F, 3, 3, wen_e, 2.0 * wie_n + wen_n, 2.0 * wie_u + wen_u, -1.0)
    _skew_into(F, 6, 6, wen_e, wie_n + wen_n, wie_u + wen_u, -1.0)
    for i in range(3):
        for j in range(3):
            c = s[6 + 3 * i + j]          # C_bn[i, j]
            F[3 + i, 12 + j] = -c
            F[6 + i, 9 + j] = c
            if isg >= 0:
                F[6 + i, isg + j] = c * w_b[j]
                F[3 + i, isa + j] = -c * f_b[j]
        F[9 + i, 9 + i] = -inv_tau_g
        F[12 + i, 12 + i] = -inv_tau_a
    F[5, 2] = 2.0 * g / np.sqrt(rm * rn)


@numba.njit(cache=True)
def _propagate(P, Phi_acc, F, q, h, nsub):  # pragma: no cover - compiled
    """``Φ = I + F h + ½ (F h)²`` and ``nsub`` steps of ``P ← Φ P Φᵀ + diag(q)``."""
    n = F.shape[0]
    Fh = F * h
    Phi = Fh + 0.5 * (Fh @ Fh)
    for i in range(n):
        Phi[i, i] += 1.0
    _propagate_cov(P, Phi, q, nsub, Phi_acc)


@numba.njit(cache=True)
def _correct_nav(s, dx, a, e2, renorm):  # pragma: no cover - compiled
    """Remove the navigation part of an error estimate from the strapdown state ``s`` in
    place: position (ENU m → lat, lon, h), velocity, attitude ``C̃_b^n ← exp([ψ]) C̃_b^n``."""
    lat, h = s[0], s[2]
    sl = np.sin(lat)
    w = np.sqrt(1.0 - e2 * sl * sl)
    rn = a / w + h
    rm = a * (1.0 - e2) / (w * w * w) + h
    s[0] = lat - dx[1] / rm
    s[1] = s[1] - dx[0] / (rn * np.cos(lat))
    s[2] = h - dx[2]
    s[3] -= dx[3]
    s[4] -= dx[4]
    s[5] -= dx[5]
    x, y, z = dx[6], dx[7], dx[8]
    th2 = x * x + y * y + z * z
    if th2 < 1e-12:
        a1, b1 = 1.0, 0.5
    else:
        th = np.sqrt(th2)
        a1, b1 = np.sin(th) / th, (1.0 - np.cos(th)) / th2
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    Rm = np.eye(3) + a1 * K + b1 * (K @ K)
    C = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = s[6 + 3 * i + j]
    C = Rm @ C
    if renorm:   # rotations keep it orthonormal; clean the rounding now and then
        U, _, Vt = np.linalg.svd(C)
        C = U @ Vt
    for i in range(3):
        for j in range(3):
            s[6 + 3 * i + j] = C[i, j]


@numba.njit(cache=True)
def _nhc_rows(s, w_b, lever, mu, mu_col, nx):  # pragma: no cover - compiled
    """Residual and Jacobian of the non-holonomic constraint (:meth:`InsGnssFilter.update_nhc`)
    at strapdown state ``s``; ``mu_col`` the first column of the mounting block or -1."""
    C_nb = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C_nb[i, j] = s[6 + 3 * j + i]          # transpose of C_bn
    v = s[3:6]
    vv = C_nb @ v
    vv[0] += w_b[1] * lever[2] - w_b[2] * lever[1]
    vv[1] += w_b[2] * lever[0] - w_b[0] * lever[2]
    vv[2] += w_b[0] * lever[1] - w_b[1] * lever[0]
    C_vn = C_nb
    if mu_col >= 0 or mu[0] != 0.0 or mu[1] != 0.0:
        x, z = mu[0], mu[1]
        th2 = x * x + z * z
        if th2 < 1e-12:
            a1, b1 = 1.0, 0.5
        else:
            th = np.sqrt(th2)
            a1, b1 = np.sin(th) / th, (1.0 - np.cos(th)) / th2
        K = np.array([[0.0, -z, 0.0], [z, 0.0, -x], [0.0, x, 0.0]])
        C_vb = np.eye(3) + a1 * K + b1 * (K @ K)
        C_vn = C_vb @ C_nb
        vv = C_vb @ vv
    H = np.zeros((2, nx))
    r = np.empty(2)
    Sv = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    for a, row in enumerate((0, 2)):
        r[a] = vv[row]
        for j in range(3):
            H[a, 3 + j] = C_vn[row, j]
        hp = -(C_vn[row] @ Sv)
        for j in range(3):
            H[a, 6 + j] = hp[j]
    if mu_col >= 0:
        # -[v_v×] restricted to rows (x, z) and columns (x, z)
        H[0, mu_col] = 0.0
        H[0, mu_col + 1] = -vv[1]
        H[1, mu_col] = vv[1]
        H[1, mu_col + 1] = 0.0
    return r, H


@numba.njit(cache=True)
def _compensate(dtheta, dv, dt, bg, ba, sg, sa):  # pragma: no cover - compiled
    """Bias- and scale-corrected increments ``(Δθ − b_g Δt)/(1 + s_g)`` (same for Δv) and
    their sums."""
    n = dtheta.shape[0]
    dth = np.empty((n, 3))
    dvb = np.empty((n, 3))
    sth = np.zeros(3)
    sdv = np.zeros(3)
    for k in range(n):
        for j in range(3):
            a = (dtheta[k, j] - bg[j] * dt[k]) / (1.0 + sg[j])
            b = (dv[k, j] - ba[j] * dt[k]) / (1.0 + sa[j])
            dth[k, j] = a
            dvb[k, j] = b
            sth[j] += a
            sdv[j] += b
    return dth, dvb, sth, sdv


def nis(P, H, R, r) -> float:
    """Normalised innovation squared of residual ``r`` (``H P Hᵀ + R``)."""
    return float(_nis(P, np.ascontiguousarray(H), np.ascontiguousarray(R), np.asarray(r, float)))


class InsGnssFilter:
    """Error-state EKF on top of a strapdown INS, with streaming ``predict``/``update_*`` calls.

    Most users call :func:`selfnav.ins.run_filter`; this class is the streaming interface
    (feed IMU blocks and measurements as they arrive).

    Attributes
    ----------
    q_scale : float
        ``λ``, the scale of the process noise (adapted by :mod:`selfnav.ins.calibrate`).
    bias_scale : float
        ``λ_b``, a further scale of the slowly varying part (bias instability, lever arm,
        time offset and mounting random walks), which a still segment cannot measure.
    bg, ba, sg, sa, mu, lever_b, time_offset, odo_scale :
        The estimated sensor errors, mounting angles, lever arm (body RFU, m), residual
        IMU time offset (s, added to the IMU stamps) and odometer scale-factor error.
    """

    def __init__(self, cfg: FilterConfig, t0, lat, lon, h, velocity_n, C_nb, *, ellipsoid=WGS84):
        self.cfg = cfg
        self.ins = Strapdown(lat, lon, h, velocity_n, C_nb, t=t0, ellipsoid=ellipsoid,
                             vertical=cfg.vertical)
        self.layout = lay = StateLayout.of(cfg)
        self.nx = lay.nx
        self.imt = lay.mu          # kept for callers that test for the mounting block
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.sg = np.zeros(3)
        self.sa = np.zeros(3)
        self.mu = np.array(cfg.states.mount_rad, dtype=float)
        self.lever_b = np.array(cfg.gnss.lever_arm_b, dtype=float).reshape(3)
        self.time_offset = 0.0
        self.odo_scale = 0.0
        self.q_scale = 1.0
        self.bias_scale = 1.0
        imu = cfg.imu
        P = np.zeros((self.nx, self.nx))
        P[IR, IR] = np.eye(3) * cfg.init.pos_sigma**2
        P[IV, IV] = np.eye(3) * cfg.init.vel_sigma**2
        P[IP, IP] = np.diag(np.square(cfg.init.att_sigma))
        P[IBG, IBG] = np.eye(3) * imu.gyro_bias_sigma**2
        P[IBA, IBA] = np.eye(3) * imu.accel_bias_sigma**2
        if lay.sg is not None:
            P[lay.sg, lay.sg] = np.eye(3) * imu.gyro_sf_sigma**2
            P[lay.sa, lay.sa] = np.eye(3) * imu.accel_sf_sigma**2
        if lay.mu is not None:
            P[lay.mu, lay.mu] = np.eye(2) * cfg.states.mount_sigma**2
        if lay.lever is not None:
            P[lay.lever, lay.lever] = np.eye(3) * cfg.states.lever_arm_sigma**2
        if lay.toff is not None:
            P[lay.toff, lay.toff] = cfg.states.time_offset_sigma**2
        if lay.odo is not None:
            P[lay.odo, lay.odo] = cfg.states.odometer_scale_sigma**2
        self.P = P
        self._f_n = np.array([0.0, 0.0, 9.8])
        self._w_b = np.zeros(3)
        self._f_b = np.array([0.0, 0.0, 9.8])
        self._Phi_acc = np.eye(self.nx)  # transition since the last stored epoch (smoother)
        self._n_corr = 0
        self._Fbuf = np.zeros((self.nx, self.nx))
        self._nhc_lever = np.asarray(cfg.vehicle.nhc_lever_b, dtype=float).reshape(3).copy()
        self._grav = (self.ins.ellipsoid.k_somigliana, self.ins.ellipsoid.m)
        q = self._q_density()
        self._q_white = np.zeros(self.nx)
        self._q_white[IV] = q[IV]
        self._q_white[IP] = q[IP]
        # the geometry and timing of the installation (mounting, lever arm, time offset,
        # odometer scale) are not IMU noise: λ does not scale them (a λ pumped up by a
        # diverging start let the time offset jump by seconds in one update)
        self._q_fixed = np.zeros(self.nx)
        for sl in (lay.mu, lay.lever, lay.toff, lay.odo):
            if sl is not None:
                self._q_fixed[sl] = q[sl]
        self._q_slow = q - self._q_white - self._q_fixed

    # ------------------------------------------------------------------ model
    def _q_density(self):
        """Diagonal process-noise density (per second) at ``λ = 1``."""
        cfg, lay = self.cfg, self.layout
        imu = cfg.imu
        q = np.zeros(self.nx)
        q[IV] = imu.vrw**2
        q[IP] = imu.arw**2
        q[IBG] = 2 * imu.gyro_bias_instability**2 / imu.instability_tau
        q[IBA] = 2 * imu.accel_bias_instability**2 / imu.instability_tau
        if lay.lever is not None:
            q[lay.lever] = cfg.states.lever_arm_rw**2
        if lay.toff is not None:
            q[lay.toff] = cfg.states.time_offset_rw**2
        if lay.mu is not None:
            q[lay.mu] = cfg.states.mount_rw**2
        if lay.odo is not None:
            q[lay.odo] = cfg.states.odometer_scale_rw**2
        return q

    def _F(self):
        """The error dynamics matrix at the current state (:func:`_fill_F`)."""
        cfg, lay = self.cfg, self.layout
        s = self.ins.state_array()
        g = self._gravity(s[0], s[2])
        imu = cfg.imu
        _fill_F(self._Fbuf, s, self._f_n, self._w_b, self._f_b, self.ins.ellipsoid.a,
                self.ins.ellipsoid.e2, g, OMEGA_EARTH,
                0.0 if not np.isfinite(imu.gyro_bias_tau) else 1.0 / imu.gyro_bias_tau,
                0.0 if not np.isfinite(imu.accel_bias_tau) else 1.0 / imu.accel_bias_tau,
                -1 if lay.sg is None else lay.sg.start, -1 if lay.sa is None else lay.sa.start)
        return self._Fbuf

    def _gravity(self, lat, h):
        """Normal gravity (scalar fast path of :func:`selfnav.earth.normal_gravity`,
        Somigliana with the TR8350.2 height term)."""
        e, s2 = self.ins.ellipsoid, math.sin(lat) ** 2
        k, m = self._grav
        g0 = e.gamma_e * (1.0 + k * s2) / math.sqrt(1.0 - e.e2 * s2)
        return g0 * (1.0 - 2.0 / e.a * (1.0 + e.f + m - 2.0 * e.f * s2) * h + 3.0 / e.a**2 * h * h)

    # ------------------------------------------------------------------ propagation
    def predict(self, t, dtheta, dv, dt=None):
        """Mechanize a block of IMU increments (bias-corrected) and propagate the covariance.

        ``dt`` are the interval lengths (default: from ``t`` and the state time).
        """
        t = np.asarray(t, dtype=float)
        if len(t) == 0:
            return None
        if dt is None:
            dt = np.diff(np.concatenate([[self.ins.t], t]))
        dt = np.ascontiguousarray(dt, dtype=float)
        dth, dvb, sth, sdv = _compensate(np.ascontiguousarray(dtheta, dtype=float),
                                         np.ascontiguousarray(dv, dtype=float), dt, self.bg,
                                         self.ba, self.sg, self.sa)
        C_nb = self.ins.advance(t, dt, dth, dvb)
        T = float(dt.sum())
        f_b = sdv / T
        self._f_b = f_b
        self._f_n = C_nb.T @ f_b
        self._w_b = sth / T
        self.propagate_covariance(T)
        return C_nb

    def propagate_covariance(self, T):
        """Covariance over ``T`` seconds at the current state (sub-steps of ``cov_step``)."""
        nsub = max(1, int(math.ceil(T / self.cfg.cov_step)))
        h = T / nsub
        q = (self._q_white + self.bias_scale * self._q_slow) * (self.q_scale * h) + self._q_fixed * h
        _propagate(self.P, self._Phi_acc, self._F(), q, h, nsub)

    # ------------------------------------------------------------------ updates
    def _correct(self, dx):
        lay = self.layout
        self._n_corr += 1
        _correct_nav(self.ins.state_array(), dx, self.ins.ellipsoid.a, self.ins.ellipsoid.e2,
                     self._n_corr % 100 == 0)
        self.bg -= dx[IBG]  # δb = estimated − true
        self.ba -= dx[IBA]
        if lay.sg is not None:
            self.sg -= dx[lay.sg]
            self.sa -= dx[lay.sa]
        if lay.mu is not None:
            self.mu -= dx[lay.mu]
        if lay.lever is not None:
            self.lever_b -= dx[lay.lever]
        if lay.toff is not None:
            self.time_offset -= float(dx[lay.toff.start])
        if lay.odo is not None:
            self.odo_scale -= float(dx[lay.odo.start])

    def kalman(self, r, H, R):
        """Apply a measurement (residual ``h(x̃) − z``, Jacobian ``H``, noise ``R``) and correct
        the nominal state; returns the error estimate removed."""
        dx = _joseph(self.P, np.ascontiguousarray(H, dtype=float),
                     np.ascontiguousarray(R, dtype=float), np.asarray(r, dtype=float))
        self._correct(dx)
        return dx

    def _gated(self, r, H, R, gate):
        if nis(self.P, H, R, r) > gate:
            return np.zeros(self.nx)
        return self.kalman(r, H, R)

    def position_residual(self, lat, lon, h):
        """``h(x̃) − z`` in ENU metres and its H for a GNSS fix at the antenna (module
        docstring: lever arm and time offset)."""
        ins, lay = self.ins, self.layout
        C_bn = ins.C_nb.T
        l_n = C_bn @ self.lever_b
        z = enu_offset(ins.lat, ins.lon, ins.h, lat, lon, h)
        v = ins.velocity_n
        r = l_n - v * self.time_offset - z
        H = np.zeros((3, self.nx))
        H[0, 0] = H[1, 1] = H[2, 2] = 1.0
        H[:, IP] = skew3(l_n)
        if lay.lever is not None:
            H[:, lay.lever] = C_bn
        if lay.toff is not None:
            H[:, lay.toff.start] = -v
        return r, H

    def velocity_residual(self, velocity_n):
        """``h(x̃) − z`` (ENU m/s) and H for a GNSS velocity at the antenna."""
        ins, lay = self.ins, self.layout
        C_bn = ins.C_nb.T
        v_lever = C_bn @ np.cross(self._w_b, self.lever_b)
        r = ins.velocity_n + v_lever - np.asarray(velocity_n, dtype=float)
        H = np.zeros((3, self.nx))
        H[0, 3] = H[1, 4] = H[2, 5] = 1.0
        H[:, IP] = skew3(v_lever)
        if lay.lever is not None:
            H[:, lay.lever] = C_bn @ skew3(self._w_b)
        return r, H

    def update_position(self, lat, lon, h, sigma_h, sigma_v, *, gate=None):
        """GNSS position update with χ² gating; returns ``(accepted, nis, residual)``."""
        r, H = self.position_residual(lat, lon, h)
        R = np.diag([sigma_h**2, sigma_h**2, sigma_v**2])
        q = nis(self.P, H, R, r)
        if gate is not None and q > gate:
            return False, q, r
        self.kalman(r, H, R)
        return True, q, r

    def update_velocity(self, velocity_n, sigma, gate=CHI2_3_999):
        """GNSS velocity update (χ² gated); returns the correction (zeros if gated out)."""
        r, H = self.velocity_residual(velocity_n)
        return self._gated(r, H, np.eye(3) * sigma**2, gate)

    def update_nhc(self):
        """Non-holonomic constraint: the vehicle's lateral and vertical velocity are zero.

        At the point ``nhc_lever_b`` (rear-axle centre) and in the vehicle frame rotated from
        the IMU's by the mounting angles μ (estimated with ``mount_states``)::

            v_v = exp([μ×]) (C_nb v^n + ω_b × l),    z = (v_v,R, v_v,U) = 0
            ∂v_v/∂δv = C_vb C_nb,  ∂v_v/∂ψ = −C_vb C_nb [v^n×],  ∂v_v/∂δμ = −[v_v×] (cols x, z)
        """
        veh = self.cfg.vehicle
        mu_col = -1 if self.layout.mu is None else self.layout.mu.start
        r, H = _nhc_rows(self.ins.state_array(), self._w_b, self._nhc_lever, self.mu, mu_col,
                         self.nx)
        s_up = veh.nhc_sigma if veh.nhc_sigma_up is None else veh.nhc_sigma_up
        return self.kalman(r, H, np.diag([veh.nhc_sigma**2, s_up**2]))

    def vehicle_velocity(self):
        """Velocity at the NHC point (rear axle) in the vehicle frame (NHC docstring) and
        ``C_vn``: ``(v_v, C_vn)``."""
        C_nb = self.ins.C_nb
        vv = C_nb @ self.ins.velocity_n
        C_vn = C_nb
        lever = self._nhc_lever
        if lever[0] or lever[1] or lever[2]:
            vv = vv + np.cross(self._w_b, lever)
        if self.layout.mu is not None or self.mu[0] or self.mu[1]:
            C_vb = rotvec_to_dcm3(np.array([self.mu[0], 0.0, self.mu[1]]))
            C_vn = C_vb @ C_nb
            vv = C_vb @ vv
        return vv, C_vn

    def update_odometer(self, speed, sigma=None):
        """Odometer (wheel speed): the forward speed at the rear axle in the vehicle frame,
        scaled by ``1 + k`` (module docstring; the scale-factor state with
        ``states.odometer``)::

            h = (1 + k̂) v_v,F,   ∂h/∂δv = (1 + k̂) C_vn[F],   ∂h/∂ψ = −(1 + k̂) C_vn[F] [v^n×],
            ∂h/∂δk = v_v,F,      ∂h/∂δμ = −(1 + k̂) [v_v×][F] (pitch, yaw)

        ``sigma`` (m/s; default ``vehicle.odometer_sigma``) is inflated by NIS/gate beyond the
        χ² gate (Huber-like: wheel slip, a wrong scale at the start) rather than the sample
        dropped. Returns the error-state correction.
        """
        vv, C_vn = self.vehicle_velocity()
        lay = self.layout
        g = 1.0 + self.odo_scale
        H = np.zeros((1, self.nx))
        H[0, IV] = g * C_vn[1]
        H[0, IP] = -g * C_vn[1] @ skew3(self.ins.velocity_n)
        if lay.mu is not None:
            H[0, lay.mu] = -g * skew3(vv)[1, [0, 2]]
        if lay.odo is not None:
            H[0, lay.odo.start] = vv[1]
        s = self.cfg.vehicle.odometer_sigma if sigma is None else float(sigma)
        R = np.array([[s * s]])
        r = np.array([g * vv[1] - float(speed)])
        q = nis(self.P, H, R, r)
        if q > CHI2_1_999:
            R = R * (q / CHI2_1_999)
        return self.kalman(r, H, R)

    def update_road(self, normal_n, offset, sigma, heading=None, sigma_heading=None, *,
                    along_n=None, along_offset=None, sigma_along=None, gate=True):
        """Road constraint: the vehicle is on the road centre line (and heads along it).

        Parameters
        ----------
        normal_n : (2,) unit horizontal normal of the road at the foot point, ENU
        offset : float
            Signed distance of the INS position from the centre line along ``normal_n``, m.
        sigma : float
            σ of the true offset (half a lane, or the road's width), m.
        heading, sigma_heading : float, optional
            Road direction of travel (rad, clockwise from North) and its σ.
        along_n, along_offset, sigma_along : optional
            A position along the road too (a corner the map places,
            :mod:`selfnav.roads.corners`): unit direction, signed offset of the INS from it
            along that direction (m) and its σ.
        gate : bool
            χ² gate (0.999) on the whole update; False for a constraint whose caller has
            judged it by other means.

        Returns the error-state correction.
        """
        rows, res, var = [], [], []
        h = np.zeros(self.nx)
        h[0:2] = normal_n
        rows.append(h)
        res.append(offset)
        var.append(sigma**2)
        if along_n is not None:
            h1 = np.zeros(self.nx)
            h1[0:2] = along_n
            rows.append(h1)
            res.append(along_offset)
            var.append(sigma_along**2)
        if heading is not None:
            _, _, hdg = att.euler_from_dcm_nb(self.ins.C_nb)
            h2 = np.zeros(self.nx)
            h2[8] = 1.0
            rows.append(h2)
            res.append(float(np.angle(np.exp(1j * (hdg - heading)))))
            var.append(sigma_heading**2)
        if not gate:
            return self.kalman(np.array(res), np.array(rows), np.diag(var))
        return self._gated(np.array(res), np.array(rows), np.diag(var),
                           {1: CHI2_1_999, 2: CHI2_2_999}.get(len(res), CHI2_3_999))

    def update_zupt(self):
        H = np.zeros((3, self.nx))
        H[0, 3] = H[1, 4] = H[2, 5] = 1.0
        return self.kalman(self.ins.velocity_n, H, np.eye(3) * self.cfg.vehicle.zupt_sigma**2)

    def update_heading(self, heading, sigma):
        """True heading (rad), e.g. magnetic heading plus declination (seed 004 (12))."""
        _, _, hdg = att.euler_from_dcm_nb(self.ins.C_nb)
        r = np.array([np.angle(np.exp(1j * (hdg - heading)))])
        H = np.zeros((1, self.nx))
        H[0, 8] = 1.0  # ψ_U raises the computed heading (C̃ = (I − [ψ]) C)
        return self._gated(r, H, np.array([[sigma**2]]), CHI2_1_999)

    def lever_arm_n(self):
        """The antenna lever arm in ENU, m."""
        return self.ins.C_nb.T @ self.lever_b

    def take_transition(self):
        Phi = self._Phi_acc
        self._Phi_acc = np.eye(self.nx)
        return Phi


# ------------------------------------------------------------------------ smoother
def pack_state(flt) -> np.ndarray:
    """The nominal state and sensor estimates of a filter as one row (:data:`PACK`)."""
    s = flt.ins
    return np.concatenate([[s.lat, s.lon, s.h], s.velocity_n, s.C_nb.reshape(9), flt.bg, flt.ba,
                           flt.sg, flt.sa, flt.mu, flt.lever_b, [flt.time_offset],
                           [flt.odo_scale]])


def unpack_states(t, states, Ps):
    """Trajectory and per-epoch σ of the error states from packed rows."""
    C = states[:, PACK["C"]].reshape(-1, 3, 3)
    traj = Trajectory(t, states[:, 0], states[:, 1], states[:, 2], states[:, PACK["vel"]], C,
                      source="selfnav ekf")
    var = Ps if Ps.ndim == 2 else np.diagonal(Ps, axis1=1, axis2=2)   # variances or covariances
    return traj, np.sqrt(np.maximum(var, 0.0))


def apply_error(state, dx, layout: StateLayout):
    """Remove an error-state estimate ``dx`` from a packed nominal state."""
    lat, lon, h = state[0], state[1], state[2]
    rm, rn = radii(lat, h)
    out = state.copy()
    out[0] = lat - dx[1] / rm
    out[1] = lon - dx[0] / (rn * np.cos(lat))
    out[2] = h - dx[2]
    out[PACK["vel"]] = state[PACK["vel"]] - dx[IV]
    C_nb = state[PACK["C"]].reshape(3, 3)
    C_bn = att.rotvec_to_dcm(dx[IP]) @ C_nb.T
    out[PACK["C"]] = att.orthonormalize(C_bn).T.reshape(9)
    out[PACK["bg"]] = state[PACK["bg"]] - dx[IBG]
    out[PACK["ba"]] = state[PACK["ba"]] - dx[IBA]
    for name, sl in layout.blocks():
        out[PACK[name]] = state[PACK[name]] - dx[sl]
    return out


def rts_smooth(states, P_plus, P_minus, Phi, updates, layout: StateLayout, breaks=None):
    """Rauch–Tung–Striebel smoother in error-state form over the stored epochs.

    Epoch k holds the corrected nominal state x̃⁺_k with covariance P⁺_k; ``Phi[k]`` carries the
    error from epoch k−1 to k, ``P_minus[k]`` is the covariance before epoch k's update and
    ``updates[k]`` the error estimate that update removed. With a reset after every update the
    filtered error of x̃⁺_k is zero, and the smoothed one is
    ``ε_k = A_k (updates[k+1] + ε_{k+1})``, ``A_k = P⁺_k Φ_{k+1}ᵀ (P⁻_{k+1})⁻¹`` (the error of
    the propagated state at k+1 is what its update removed plus what the smoother adds).

    ``breaks[k]``: epoch k's state was *replaced* (a reset to a dead-reckoning shadow,
    :mod:`selfnav.ins.guard`), not updated; nothing is carried back across it.
    """
    n = len(states)
    out = states.copy()
    Ps = P_plus.copy()
    nx = updates.shape[1]
    eps_next = np.zeros(nx)
    for k in range(n - 2, -1, -1):
        if breaks is not None and breaks[k + 1]:
            eps_next = np.zeros(nx)
            continue
        Pm = P_minus[k + 1]
        A = np.linalg.solve(Pm.T, (P_plus[k] @ Phi[k + 1].T).T).T
        eps = A @ (updates[k + 1] + eps_next)
        Ps[k] = P_plus[k] + A @ (Ps[k + 1] - Pm) @ A.T
        out[k] = apply_error(states[k], eps, layout)
        eps_next = eps
    return out, Ps


__all__ = ["InsGnssFilter", "StateLayout", "NX", "IR", "IV", "IP", "IBG", "IBA", "PACK",
           "pack_state", "unpack_states", "apply_error", "rts_smooth", "nis"]
