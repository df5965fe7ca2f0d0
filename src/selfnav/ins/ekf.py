"""Loosely coupled INS/GNSS error-state Kalman filter and RTS smoother (DESIGN §5, §7).

The nominal state is carried by the strapdown mechanization (:class:`selfnav.ins.strapdown.Strapdown`,
seed 004 fast loop); the filter estimates its errors

    δx = [δr (ENU, m), δv (ENU, m/s), ψ (rad), δb_g (rad/s), δb_a (m/s²)]        (15: the core)
         [+ δs_g, δs_a]   gyro and accelerometer scale factors (3 + 3)
         [+ δM_g, δM_a]   gyro and accelerometer axis misalignment / non-orthogonality, the
                          off-diagonal elements (6 + 6)
         [+ δμ]           IMU pitch and yaw relative to the vehicle (2)
         [+ δl]           IMU → antenna lever arm, body RFU, m (3)
         [+ δε]           IMU time offset, s (1)
         [+ δλ_v]         lag of the GNSS velocity behind its position, s (1)
         [+ δk]           odometer scale factor (1)
         [+ δb_r, δḃ_r]   GNSS receiver clock bias (m) and drift (m/s), tight coupling (2)
         [+ δb_s]         the receiver's clock offsets of further constellations, m (4)

with ``δ(·) = estimated − true`` and the attitude error ``C̃_b^n = (I − [ψ]) C_b^n``. Which
optional blocks exist is the :class:`StateLayout` of the configuration. The sensor model
(what the simulator of :mod:`selfnav.sensors` draws, and what a MEMS datasheet lists) is

    ω̃ = (I + S_g + M_g) ω + b_g + noise,     f̃ = (I + S_a + M_a) f + b_a + noise

(``S`` diagonal scale factors, ``M`` off-diagonal misalignment); the filter compensates
``ω̂ = (I + Ŝ_g + M̂_g)⁻¹ (ω̃ − b̂_g)``. Error dynamics (psi-angle form, Groves ch. 14,
simplified to what a MEMS or tactical IMU needs)::

    δṙ = δv,                       plus  δv̇_U += (2g/R) δr_U (the unstable vertical channel)
    δv̇ = f^n × ψ − (2ω_ie + ω_en) × δv − C_b^n (δb_a + (δS_a + δM_a) f_b)
    ψ̇ = −ω_in × ψ + C_b^n (δb_g + (δS_g + δM_g) ω_b)
    δḃ = −δb/τ + w                 (τ = ∞ by default: a turn-on constant plus a random walk
                                    whose density matches the bias instability)
    δṡ = δṀ = δμ̇ = δl̇ = δε̇ = δλ̇_v = δk̇ = 0 (+ a small random walk)
    δḃ_r = δḃ_r (the drift carries the bias; both random walks, Groves 2013 (9.149))

An unmodelled 1 % misalignment turns a 90° corner into 0.9° of tilt (DESIGN §10: replays of
captured drives dead-reckoned at 25–45σ); with the states the covariance grows with every turn
while GNSS is out, as the error does.

The process noise is ``λ Q`` with ``λ`` the noise scale that :mod:`selfnav.ins.calibrate`
adapts to the data (1 for a trusted noise model).

**Covariance propagation** exploits the structure: only the 15 core states have dynamics;
the others are constants (plus random walks) that enter the core through ``F_cp``::

    Φ = [[Φ_cc, Φ_cp], [0, I]],  Φ_cc = I + F_cc h + ½ (F_cc h)²,  Φ_cp = (I h + ½ F_cc h²) F_cp

so ``Φ P Φᵀ`` costs O(15·n²) instead of O(n³) (40 states: ten times fewer operations).
**Updates** use the Joseph form written at O(m n²):
``P ← P − K H P − (K H P)ᵀ + K S Kᵀ`` (symmetric and positive for any gain).

The measurement models (GNSS position and velocity with the lever arm, time offset and
velocity lag; the vehicle constraints; wheel speed; heading; roads) are the objects of
:mod:`selfnav.ins.measurements`; this module applies them (:meth:`InsGnssFilter.update`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH, WGS84, radii
from selfnav.kernels import inv3
from selfnav.ins.config import FilterConfig
from selfnav.ins.strapdown import Strapdown
from selfnav.types import Trajectory

NX = 15
#: blocks of the kinematic history :meth:`InsGnssFilter.back` integrates over (each an aiding
#: step or less: seconds of it)
KINEMATIC_BLOCKS = 64
IR, IV, IP, IBG, IBA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
#: the off-diagonal elements of a misalignment matrix, in the order of its six states
OFFDIAG = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))

#: optional error-state blocks: (name, size) in their order in the state vector
BLOCKS = (("sg", 3), ("sa", 3), ("mg", 6), ("ma", 6), ("mu", 2), ("lever", 3), ("toff", 1),
          ("tdrift", 1), ("vlag", 1), ("odo", 1), ("clk", 2),
          ("isb", 4))


def _pack_layout():
    out = dict(pos=slice(0, 3), vel=slice(3, 6), C=slice(6, 15), bg=slice(15, 18),
               ba=slice(18, 21))
    n = 21
    for name, size in BLOCKS:
        out[name] = slice(n, n + size)
        n += size
    return out, n


#: packed nominal state (the smoother's record): lat, lon, h, v(3), C_nb(9), b_g(3), b_a(3),
#: then every optional block of :data:`BLOCKS` (present or not)
PACK, PACK_SIZE = _pack_layout()


@dataclass(frozen=True)
class StateLayout:
    """Where each optional error-state block sits (``None``: not estimated)."""

    nx: int
    sg: slice | None = None
    sa: slice | None = None
    mg: slice | None = None
    ma: slice | None = None
    mu: slice | None = None
    lever: slice | None = None
    toff: slice | None = None
    tdrift: slice | None = None
    vlag: slice | None = None
    odo: slice | None = None
    clk: slice | None = None
    isb: slice | None = None

    @classmethod
    def of(cls, cfg: FilterConfig) -> "StateLayout":
        st = cfg.states
        on = {"sg": st.scale_factors, "sa": st.scale_factors, "mg": st.misalignment,
              "ma": st.misalignment, "mu": st.mount_states, "lever": st.lever_arm,
              "toff": st.time_offset, "tdrift": st.time_offset and st.clock_drift,
              "vlag": st.velocity_lag, "odo": st.odometer, "clk": st.receiver_clock,
              "isb": st.receiver_clock and st.inter_system}
        n = NX
        blocks = {}
        for name, size in BLOCKS:
            if on[name]:
                blocks[name] = slice(n, n + size)
                n += size
        return cls(n, **blocks)

    def blocks(self):
        """``(name, slice)`` of the optional blocks present."""
        return [(k, getattr(self, k)) for k, _ in BLOCKS if getattr(self, k) is not None]


# ------------------------------------------------------------------------ compiled kernels
@numba.njit(cache=True)
def _propagate_block(P, Phi_acc, Fcc, Fcp, q, h, nsub, track, i_toff,
                     i_drift):  # pragma: no cover - compiled
    """``nsub`` steps of ``P ← Φ P Φᵀ + diag(q)`` for the block-structured Φ (module
    docstring); with ``track`` also ``Φ_acc ← Φ^nsub Φ_acc`` (the smoother's transition).
    With ``i_drift ≥ 0`` the clock drift then carries the time offset over the whole span:
    ``δτ ← δτ + T δτ̇``, a shear of ``P`` (and of ``Φ_acc``) that commutes with the block
    transition (no other state depends on ``δτ``)."""
    n = P.shape[0]
    nc = Fcc.shape[0]
    npar = n - nc
    Fh = Fcc * h
    Phicc = Fh + 0.5 * (Fh @ Fh)
    G = 0.5 * h * Fh                 # ½ F h²
    for i in range(nc):
        Phicc[i, i] += 1.0
        G[i, i] += h
    Phicp = G @ Fcp if npar > 0 else np.zeros((nc, 0))
    for _ in range(nsub):
        Pcc = np.ascontiguousarray(P[:nc, :nc])
        newPcc = Phicc @ Pcc @ Phicc.T
        if npar > 0:
            Pcp = np.ascontiguousarray(P[:nc, nc:])
            Ppp = np.ascontiguousarray(P[nc:, nc:])
            A = Phicc @ Pcp
            B = Phicp @ Ppp
            C = A @ Phicp.T
            newPcc += C + C.T + B @ Phicp.T
            newPcp = A + B
            P[:nc, nc:] = newPcp
            P[nc:, :nc] = newPcp.T
        P[:nc, :nc] = newPcc
        for i in range(n):
            P[i, i] += q[i]
        if track:
            Acc = np.ascontiguousarray(Phi_acc[:nc, :nc])
            Phi_acc[:nc, :nc] = Phicc @ Acc
            if npar > 0:
                Acp = np.ascontiguousarray(Phi_acc[:nc, nc:])
                Phi_acc[:nc, nc:] = Phicc @ Acp + Phicp
    for i in range(n):
        for j in range(i + 1, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s
    if i_drift >= 0:
        T = h * nsub
        for k in range(n):
            P[i_toff, k] += T * P[i_drift, k]
        for k in range(n):
            P[k, i_toff] += T * P[k, i_drift]
        if track:
            for k in range(n):
                Phi_acc[i_toff, k] += T * Phi_acc[i_drift, k]


@numba.njit(cache=True)
def _correct_blocks(dx, bg, ba, sg, sa, mg, ma, mu, lever, isg, isa, img, ima, imu,
                    ilev):  # pragma: no cover - compiled
    """``x ← x − δx`` of the sensor and installation blocks in place (the columns of the
    optional ones, -1 when absent)."""
    for k in range(3):
        bg[k] -= dx[9 + k]
        ba[k] -= dx[12 + k]
    if isg >= 0:
        for k in range(3):
            sg[k] -= dx[isg + k]
            sa[k] -= dx[isa + k]
    if img >= 0:
        for k in range(6):
            mg[k] -= dx[img + k]
            ma[k] -= dx[ima + k]
    if imu >= 0:
        for k in range(2):
            mu[k] -= dx[imu + k]
    if ilev >= 0:
        for k in range(3):
            lever[k] -= dx[ilev + k]


@numba.njit(cache=True)
def _q_step(q_white, q_slow, q_fixed, bias_scale, q_scale, h, vib_class, kg,
            ka):  # pragma: no cover - compiled
    """The process noise of one sub-step of ``h`` s: ``(q_w + λ_b q_s) λ h + q_f h`` (λ does
    not scale the installation's random walks ``q_f``), times the vibration factor of the
    state's sensor (:meth:`InsGnssFilter._vib_classes`)."""
    n = q_white.shape[0]
    q = np.empty(n)
    lh = q_scale * h
    for i in range(n):
        v = (q_white[i] + bias_scale * q_slow[i]) * lh + q_fixed[i] * h
        if vib_class[i] == 1:
            v *= kg
        elif vib_class[i] == 2:
            v *= ka
        q[i] = v
    return q


@numba.njit(cache=True)
def _joseph(P, H, R, r):  # pragma: no cover - compiled
    """Kalman update in Joseph form at O(m n²), in place on ``P``; returns ``dx``."""
    PHt = P @ H.T
    S = H @ PHt + R
    K = np.linalg.solve(S, PHt.T).T
    dx = K @ r
    KHP = K @ PHt.T
    KSK = K @ S @ K.T
    n = P.shape[0]
    for i in range(n):
        for j in range(i, n):
            v = P[i, j] - KHP[i, j] - KHP[j, i] + KSK[i, j]
            w = P[j, i] - KHP[j, i] - KHP[i, j] + KSK[j, i]
            s = 0.5 * (v + w)
            P[i, j] = s
            P[j, i] = s
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
def _fill_F(Fcc, Fcp, s, f_n, w_b, f_b, a, e2, g, omega, inv_tau_g, inv_tau_a, isg, isa,
            img, ima):  # pragma: no cover - compiled
    """The error dynamics (module docstring) at strapdown state ``s`` (lat, lon, h, v(3),
    C_bn row-major(9)): the core block ``Fcc`` (15×15) and its coupling ``Fcp`` to the
    parameter states; ``isg, isa, img, ima`` the first column (within the parameters) of the
    scale-factor and misalignment blocks, or -1."""
    Fcc[:, :] = 0.0
    Fcp[:, :] = 0.0
    lat, h = s[0], s[2]
    ve, vn = s[3], s[4]
    sl = np.sin(lat)
    w = np.sqrt(1.0 - e2 * sl * sl)
    rn = a / w + h
    rm = a * (1.0 - e2) / (w * w * w) + h
    cl = np.cos(lat)
    wie_n, wie_u = omega * cl, omega * sl
    wen_e, wen_n, wen_u = -vn / rm, ve / rn, ve * np.tan(lat) / rn
    Fcc[0, 3] = 1.0
    Fcc[1, 4] = 1.0
    Fcc[2, 5] = 1.0
    _skew_into(Fcc, 3, 6, f_n[0], f_n[1], f_n[2], 1.0)
    _skew_into(Fcc, 3, 3, wen_e, 2.0 * wie_n + wen_n, 2.0 * wie_u + wen_u, -1.0)
    _skew_into(Fcc, 6, 6, wen_e, wie_n + wen_n, wie_u + wen_u, -1.0)
    for i in range(3):
        for j in range(3):
            c = s[6 + 3 * i + j]          # C_bn[i, j]
            Fcc[3 + i, 12 + j] = -c
            Fcc[6 + i, 9 + j] = c
            if isg >= 0:
                Fcp[6 + i, isg + j] = c * w_b[j]
                Fcp[3 + i, isa + j] = -c * f_b[j]
        Fcc[9 + i, 9 + i] = -inv_tau_g
        Fcc[12 + i, 12 + i] = -inv_tau_a
    if img >= 0:
        # δω = δM_g ω_b: the state (r, c) of M enters body axis r with ω_c
        k = 0
        for r in range(3):
            for c in range(3):
                if r == c:
                    continue
                for i in range(3):
                    cir = s[6 + 3 * i + r]
                    Fcp[6 + i, img + k] = cir * w_b[c]
                    Fcp[3 + i, ima + k] = -cir * f_b[c]
                k += 1
    Fcc[5, 2] = 2.0 * g / np.sqrt(rm * rn)


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
def _compensate(dtheta, dv, dt, bg, ba, Tg_inv, Ta_inv):  # pragma: no cover - compiled
    """Sensor-error-corrected increments ``T_g⁻¹ (Δθ − b_g Δt)`` (same for Δv, module
    docstring) and their sums."""
    n = dtheta.shape[0]
    dth = np.empty((n, 3))
    dvb = np.empty((n, 3))
    sth = np.zeros(3)
    sdv = np.zeros(3)
    for k in range(n):
        a0 = dtheta[k, 0] - bg[0] * dt[k]
        a1 = dtheta[k, 1] - bg[1] * dt[k]
        a2 = dtheta[k, 2] - bg[2] * dt[k]
        b0 = dv[k, 0] - ba[0] * dt[k]
        b1 = dv[k, 1] - ba[1] * dt[k]
        b2 = dv[k, 2] - ba[2] * dt[k]
        for j in range(3):
            x = Tg_inv[j, 0] * a0 + Tg_inv[j, 1] * a1 + Tg_inv[j, 2] * a2
            y = Ta_inv[j, 0] * b0 + Ta_inv[j, 1] * b1 + Ta_inv[j, 2] * b2
            dth[k, j] = x
            dvb[k, j] = y
            sth[j] += x
            sdv[j] += y
    return dth, dvb, sth, sdv


def nis(P, H, R, r) -> float:
    """Normalised innovation squared of residual ``r`` (``H P Hᵀ + R``)."""
    return float(_nis(P, np.ascontiguousarray(H), np.ascontiguousarray(R), np.asarray(r, float)))


@numba.njit(cache=True)
def _sensor_matrix(scale, offdiag, where):  # pragma: no cover - compiled
    """``I + S + M`` with the off-diagonal elements at ``where`` (:data:`OFFDIAG`)."""
    T = np.eye(3)
    for i in range(3):
        T[i, i] += scale[i]
    for k in range(where.shape[0]):
        T[where[k, 0], where[k, 1]] += offdiag[k]
    return T


@numba.njit(cache=True)
def _sensor_matrix_inv(scale, offdiag, where):  # pragma: no cover - compiled
    """``(I + S + M)⁻¹`` (a correction's path: one call each)."""
    return inv3(_sensor_matrix(scale, offdiag, where))


_OFFDIAG = np.array(OFFDIAG, dtype=np.int64)


def sensor_matrix(scale, offdiag) -> np.ndarray:
    """``I + S + M`` of a sensor triad from its scale factors (3,) and the six off-diagonal
    misalignment elements in the order of :data:`OFFDIAG`."""
    return _sensor_matrix(np.asarray(scale, float).reshape(3),
                          np.asarray(offdiag, float).reshape(6), _OFFDIAG)


class InsGnssFilter:
    """Error-state EKF on top of a strapdown INS: ``predict`` with IMU blocks, ``update`` with
    measurement objects (:mod:`selfnav.ins.measurements`).

    Attributes
    ----------
    q_scale : float
        ``λ``, the scale of the process noise (adapted by :mod:`selfnav.ins.calibrate`).
    bias_scale : float
        ``λ_b``, a further scale of the slowly varying part (bias instability, lever arm,
        time offset and mounting random walks), which a still segment cannot measure.
    bg, ba, sg, sa, mg, ma, mu, lever_b, time_offset, clock_drift, velocity_lag, odo_scale :
        The estimated sensor errors (biases, scale factors, misalignment), mounting angles,
        lever arm (body RFU, m), IMU time offset (s, added to the IMU stamps) and its drift
        (s/s), GNSS velocity lag (s) and odometer scale-factor error.
    time_offset_applied : float
        The part of the IMU time offset applied outside the filter (reader and user), s:
        the true time of the state is ``ins.t + time_offset_applied + time_offset``.
    """

    def __init__(self, cfg: FilterConfig, t0, lat, lon, h, velocity_n, C_nb, *, ellipsoid=WGS84,
                 time_offset_applied: float = 0.0):
        self.cfg = cfg
        self.ins = Strapdown(lat, lon, h, velocity_n, C_nb, t=t0, ellipsoid=ellipsoid,
                             vertical=cfg.vertical)
        self.layout = lay = StateLayout.of(cfg)
        self.nx = lay.nx
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.sg = np.zeros(3)
        self.sa = np.zeros(3)
        self.mg = np.zeros(6)
        self.ma = np.zeros(6)
        self.mu = np.array(cfg.states.mount_rad, dtype=float)
        self.lever_b = np.array(cfg.gnss.lever_arm_b, dtype=float).reshape(3)
        self.time_offset = 0.0
        self.clock_drift = 0.0
        self.time_offset_applied = float(time_offset_applied)
        self.velocity_lag = 0.0
        self.odo_scale = 0.0
        #: GNSS receiver clock bias (m) and drift (m/s), with ``states.receiver_clock``
        self.rx_clock = 0.0
        self.rx_drift = 0.0
        #: clock offsets of further constellations against the reference one, m
        self.rx_isb = np.zeros(4)
        self.q_scale = 1.0
        self.bias_scale = 1.0
        #: (gyro, accelerometer) process-noise factors from the vibration the IMU feels now
        #: (:func:`selfnav.ins.calibrate.vibration_scale`)
        self.vibration = (1.0, 1.0)
        imu, st = cfg.imu, cfg.states
        P = np.zeros((self.nx, self.nx))
        P[IR, IR] = np.eye(3) * cfg.init.pos_sigma**2
        P[IV, IV] = np.eye(3) * cfg.init.vel_sigma**2
        P[IP, IP] = np.diag(np.square(cfg.init.att_sigma))
        P[IBG, IBG] = np.eye(3) * imu.gyro_bias_sigma**2
        P[IBA, IBA] = np.eye(3) * imu.accel_bias_sigma**2
        prior = self.prior_sigma()
        for name, sl in lay.blocks():
            P[sl, sl] = np.eye(sl.stop - sl.start) * prior[name] ** 2
        self.P = P
        self._f_n = np.array([0.0, 0.0, 9.8])
        self._kin = []                     # the last blocks: (T s, mean acceleration ENU)
        self._w_b = np.zeros(3)
        self._f_b = np.array([0.0, 0.0, 9.8])
        self._Phi_acc = np.eye(self.nx)  # transition since the last stored epoch (smoother)
        self.track_transition = True
        self._n_corr = 0
        self._Fcc = np.zeros((NX, NX))
        self._Fcp = np.zeros((NX, self.nx - NX))
        self._grav = (self.ins.ellipsoid.k_somigliana, self.ins.ellipsoid.m)

        def col(sl):
            return -1 if sl is None else sl.start - NX

        # the constant arguments of :func:`_fill_F`
        self._F_args = (self.ins.ellipsoid.a, self.ins.ellipsoid.e2,
                        0.0 if not np.isfinite(imu.gyro_bias_tau) else 1.0 / imu.gyro_bias_tau,
                        0.0 if not np.isfinite(imu.accel_bias_tau) else 1.0 / imu.accel_bias_tau,
                        col(lay.sg), col(lay.sa), col(lay.mg), col(lay.ma))
        self.nhc_lever_b = np.asarray(cfg.vehicle.nhc_lever_b, dtype=float).reshape(3).copy()
        self._sensor_inv()
        q = self._q_density()
        self._q_white = np.zeros(self.nx)
        self._q_white[IV] = q[IV]
        self._q_white[IP] = q[IP]
        # the geometry and timing of the installation (mounting, lever arm, time offset,
        # velocity lag, odometer scale) are not IMU noise: λ does not scale them
        self._q_fixed = np.zeros(self.nx)
        for sl in (lay.mu, lay.lever, lay.toff, lay.tdrift, lay.vlag, lay.odo, lay.clk, lay.isb):
            if sl is not None:
                self._q_fixed[sl] = q[sl]
        self._q_slow = q - self._q_white - self._q_fixed
        self._vib_class = self._vib_classes()
        self._block_cols = tuple(-1 if sl is None else sl.start
                                 for sl in (lay.sg, lay.sa, lay.mg, lay.ma, lay.mu, lay.lever))

    # ------------------------------------------------------------------ model
    def _q_density(self):
        """Diagonal process-noise density (per second) at ``λ = 1``."""
        cfg, lay = self.cfg, self.layout
        imu, st = cfg.imu, cfg.states
        q = np.zeros(self.nx)
        q[IV] = imu.vrw**2
        q[IP] = imu.arw**2
        q[IBG] = 2 * imu.gyro_bias_instability**2 / imu.instability_tau
        q[IBA] = 2 * imu.accel_bias_instability**2 / imu.instability_tau
        for sl, rw in ((lay.lever, st.lever_arm_rw), (lay.toff, st.time_offset_rw),
                       (lay.tdrift, st.clock_drift_rw),
                       (lay.mu, st.mount_rw), (lay.odo, st.odometer_scale_rw),
                       (lay.vlag, st.velocity_lag_rw)):
            if sl is not None:
                q[sl] = rw**2
        if lay.clk is not None:
            q[lay.clk] = (st.receiver_clock_rw**2, st.receiver_drift_rw**2)
        if lay.isb is not None:
            q[lay.isb] = st.inter_system_rw**2
        return q

    def _sensor_inv(self):
        self._Tg_inv = _sensor_matrix_inv(self.sg, self.mg, _OFFDIAG)
        self._Ta_inv = _sensor_matrix_inv(self.sa, self.ma, _OFFDIAG)

    def _vib_classes(self):
        """Which vibration factor scales each state's noise: 1 the gyro's (attitude and gyro
        errors), 2 the accelerometer's (velocity and accelerometer errors), 0 none."""
        c = np.zeros(self.nx, dtype=np.int64)
        lay = self.layout
        for sl in (IP, IBG, lay.sg, lay.mg):
            if sl is not None:
                c[sl] = 1
        for sl in (IV, IBA, lay.sa, lay.ma):
            if sl is not None:
                c[sl] = 2
        return c

    def white_velocity_density(self) -> np.ndarray:
        """The velocity random-walk density the filter propagates now, (m/s)²/s per axis
        (the noise scale and the vibration factor included)."""
        return self._q_white[IV] * self.q_scale * self.vibration[1]

    def acceleration_sigma(self) -> float:
        """Horizontal acceleration error σ the covariance allows, m/s²: the specific force
        against the attitude error (``|f^n × ψ|``) and the accelerometer bias."""
        f = self._f_n
        Pp = self.P[IP, IP]
        # the horizontal rows of [f×]ψ: E = f_N ψ_U − f_U ψ_N, N = f_U ψ_E − f_E ψ_U
        A = np.array([[0.0, -f[2], f[1]], [f[2], 0.0, -f[0]]])
        var = float(np.trace(A @ Pp @ A.T)) / 2.0 + float(np.trace(self.P[IBA, IBA])) / 3.0
        return float(np.sqrt(max(var, 0.0)))

    @property
    def t_true(self) -> float:
        """True time of the state: the IMU stamp plus the whole time offset, s."""
        return self.ins.t + self.time_offset_applied + self.time_offset

    @property
    def acceleration_n(self) -> np.ndarray:
        """Kinematic acceleration of the last IMU block, ENU m/s² (specific force plus
        gravity; the Coriolis terms are below what it is used for)."""
        s = self.ins.state_array()
        return self._f_n - np.array([0.0, 0.0, self.gravity(s[0], s[2])])

    @property
    def omega_b(self) -> np.ndarray:
        """Bias-corrected body rate of the last IMU block, rad/s."""
        return self._w_b

    def _F(self):
        """The error dynamics at the current state (:func:`_fill_F`)."""
        s = self.ins.state_array()
        a, e2, inv_tau_g, inv_tau_a, isg, isa, img, ima = self._F_args
        _fill_F(self._Fcc, self._Fcp, s, self._f_n, self._w_b, self._f_b, a, e2,
                self.gravity(s[0], s[2]), OMEGA_EARTH, inv_tau_g, inv_tau_a, isg, isa, img, ima)
        return self._Fcc, self._Fcp

    def gravity(self, lat, h):
        """Normal gravity (scalar fast path of :func:`selfnav.earth.normal_gravity`,
        Somigliana with the TR8350.2 height term)."""
        e, s2 = self.ins.ellipsoid, math.sin(lat) ** 2
        k, m = self._grav
        g0 = e.gamma_e * (1.0 + k * s2) / math.sqrt(1.0 - e.e2 * s2)
        return g0 * (1.0 - 2.0 / e.a * (1.0 + e.f + m - 2.0 * e.f * s2) * h + 3.0 / e.a**2 * h * h)

    # ------------------------------------------------------------------ propagation
    def mechanize(self, t, dtheta, dv, dt, *, states: bool = False):
        """Advance the nominal state over IMU increments (sensor errors compensated); returns
        the sums of the compensated increments ``(Σ Δθ, Σ Δv)`` for :meth:`propagate` and,
        with ``states``, every new state ``(pos, vel, C_nb)`` (else None)."""
        dth, dvb, sth, sdv = _compensate(np.ascontiguousarray(dtheta, dtype=float),
                                         np.ascontiguousarray(dv, dtype=float),
                                         np.ascontiguousarray(dt, dtype=float), self.bg,
                                         self.ba, self._Tg_inv, self._Ta_inv)
        out = self.ins.advance(np.asarray(t, float), np.ascontiguousarray(dt, dtype=float),
                               dth, dvb, states=states)
        return sth, sdv, (out if states else None)

    def propagate(self, T, sth, sdv):
        """Covariance over the last ``T`` seconds of mechanized increments (sums ``sth``,
        ``sdv``): the block's mean rate and specific force set the error dynamics."""
        if T <= 0.0:
            return
        f_b = sdv / T
        self._f_b = f_b
        self._f_n = self.ins.state_array()[6:15].reshape(3, 3) @ f_b     # C_bn f^b
        self._w_b = sth / T
        self._kin.append((float(T), self.acceleration_n))
        if len(self._kin) > KINEMATIC_BLOCKS:
            del self._kin[0]
        self.propagate_covariance(T)

    def back(self, d):
        """How far the nominal state was ``d`` s ago (``d`` ≥ 0, up to the span of the last
        :data:`KINEMATIC_BLOCKS` blocks; beyond it the oldest block's acceleration holds):
        ``(Δr, Δv)`` ENU with ``r(t − d) = r − Δr``, ``v(t − d) = v − Δv``, integrated over
        the blocks' mean accelerations — what a fix or velocity ``d`` s old is compared with
        (a receiver's latency, the velocity lag): one block's acceleration times ``d``
        (first order) carries that block's noise and misses a turn or a brake."""
        v = self.ins.velocity_n
        dv = np.zeros(3)
        dr = np.zeros(3)
        left = float(d)
        a = self.acceleration_n
        for T, a in reversed(self._kin):
            if left <= 0.0:
                break
            h = min(T, left)
            # over h s before the point reached so far: v there is v − dv
            dr += (v - dv) * h - 0.5 * a * h * h
            dv += a * h
            left -= h
        if left > 0.0:
            dr += (v - dv) * left - 0.5 * a * left * left
            dv += a * left
        return dr, dv

    def advance(self, d):
        """Move the nominal state ``d`` s along its motion — position by ``v d``, velocity by
        ``a d``, attitude by the body's rotation ``ω d`` — the covariance untouched: the
        state that fixes made under one time offset, expressed under an offset ``d`` s
        later."""
        dx = np.zeros(self.nx)
        dx[IR] = -self.ins.velocity_n * d
        dx[IV] = -self.acceleration_n * d
        # C_bn ← exp([ψ]) C_bn (_correct_nav): the rotation over d, in navigation axes
        dx[IP] = (self.ins.C_nb.T @ self.omega_b) * d
        self._correct(dx)

    def predict(self, t, dtheta, dv, dt=None):
        """Mechanize a block of IMU increments and propagate the covariance over it."""
        t = np.asarray(t, dtype=float)
        if len(t) == 0:
            return None
        if dt is None:
            dt = np.diff(np.concatenate([[self.ins.t], t]))
        sth, sdv, _ = self.mechanize(t, dtheta, dv, dt)
        self.propagate(float(np.sum(dt)), sth, sdv)
        return self.ins.C_nb

    def propagate_covariance(self, T):
        """Covariance over ``T`` seconds at the current state (sub-steps of ``cov_step``)."""
        nsub = max(1, int(math.ceil(T / self.cfg.cov_step - 1e-9)))
        h = T / nsub
        q = _q_step(self._q_white, self._q_slow, self._q_fixed, self.bias_scale, self.q_scale, h,
                    self._vib_class, self.vibration[0], self.vibration[1])
        Fcc, Fcp = self._F()
        lay = self.layout
        if lay.tdrift is not None:
            # the clock drift carries the time offset: δτ ← δτ + T δτ̇ (and its covariance,
            # in the kernel)
            i, j = lay.toff.start, lay.tdrift.start
            self.time_offset += self.clock_drift * T
        else:
            i = j = -1
        _propagate_block(self.P, self._Phi_acc, Fcc, Fcp, q, h, nsub, self.track_transition,
                         i, j)
        if lay.clk is not None:
            # the receiver's drift carries its clock: δb_r ← δb_r + T δḃ_r (a shear, as the
            # IMU clock's in the kernel)
            i = lay.clk.start
            self.rx_clock += self.rx_drift * T
            self.P[i, :] += T * self.P[i + 1, :]
            self.P[:, i] += T * self.P[:, i + 1]
            if self.track_transition:
                self._Phi_acc[i, :] += T * self._Phi_acc[i + 1, :]

    # ------------------------------------------------------------------ updates
    def _correct(self, dx):
        lay = self.layout
        self._n_corr += 1
        _correct_nav(self.ins.state_array(), dx, self.ins.ellipsoid.a, self.ins.ellipsoid.e2,
                     self._n_corr % 100 == 0)
        # δb = estimated − true: every sensor and installation block ``x ← x − δx``
        _correct_blocks(dx, self.bg, self.ba, self.sg, self.sa, self.mg, self.ma, self.mu,
                        self.lever_b, *self._block_cols)
        if lay.sg is not None or lay.mg is not None:
            self._sensor_inv()
        if lay.toff is not None:
            self.time_offset -= float(dx[lay.toff.start])
        if lay.tdrift is not None:
            self.clock_drift -= float(dx[lay.tdrift.start])
        if lay.vlag is not None:
            self.velocity_lag -= float(dx[lay.vlag.start])
        if lay.odo is not None:
            self.odo_scale -= float(dx[lay.odo.start])
        if lay.clk is not None:
            self.rx_clock -= float(dx[lay.clk.start])
            self.rx_drift -= float(dx[lay.clk.start + 1])
        if lay.isb is not None:
            self.rx_isb -= dx[lay.isb]
        if self.cfg.states.installation_bound is not None:
            self._hold_installation()

    def _hold_installation(self):
        """The installation's states held within ``states.installation_bound`` prior σ of their
        prior (StatesConfig): a physical bound, not a statistical one."""
        st, lay = self.cfg.states, self.layout
        k = st.installation_bound
        for block, name, sigma in ((lay.toff, "time_offset", st.time_offset_sigma),
                                   (lay.tdrift, "clock_drift", st.clock_drift_sigma),
                                   (lay.vlag, "velocity_lag", st.velocity_lag_sigma),
                                   (lay.odo, "odo_scale", st.odometer_scale_sigma)):
            if block is not None:          # the prior is zero
                setattr(self, name, min(max(getattr(self, name), -k * sigma), k * sigma))
        if lay.lever is not None:
            c = np.asarray(self.cfg.gnss.lever_arm_b, dtype=float).reshape(3)
            b = k * st.lever_arm_sigma
            # np.clip's own arithmetic without its wrapper (called at every correction)
            np.minimum(np.maximum(self.lever_b, c - b, out=self.lever_b), c + b,
                       out=self.lever_b)

    def kalman(self, r, H, R):
        """Apply a measurement (residual ``h(x̃) − z``, Jacobian ``H``, noise ``R``) and correct
        the nominal state; returns the error estimate removed."""
        dx = _joseph(self.P, np.ascontiguousarray(H, dtype=float),
                     np.ascontiguousarray(R, dtype=float), np.asarray(r, dtype=float))
        self._correct(dx)
        return dx

    def update(self, m, inflate: float = 1.0):
        """Apply a measurement object (``m.r``, ``m.H``, ``m.R``), its noise times
        ``inflate``; returns the error estimate removed."""
        return self.kalman(m.r, m.H, m.R * inflate if inflate != 1.0 else m.R)

    def nis(self, m) -> float:
        """Normalised innovation squared of a measurement object."""
        return nis(self.P, m.H, m.R, m.r)

    def take_transition(self):
        Phi = self._Phi_acc
        self._Phi_acc = np.eye(self.nx)
        return Phi

    def prior_sigma(self) -> dict:
        """The prior σ of each parameter block by name (:meth:`StateLayout.blocks`)."""
        imu, st = self.cfg.imu, self.cfg.states
        return {"sg": imu.gyro_sf_sigma, "sa": imu.accel_sf_sigma, "mg": imu.gyro_mis_sigma,
                "ma": imu.accel_mis_sigma, "mu": st.mount_sigma, "lever": st.lever_arm_sigma,
                "toff": st.time_offset_sigma, "tdrift": st.clock_drift_sigma,
                "vlag": st.velocity_lag_sigma,
                "odo": st.odometer_scale_sigma,
                "clk": np.array([st.receiver_clock_sigma, st.receiver_drift_sigma]),
                "isb": st.inter_system_sigma}

    def set_receiver_drift_rw(self, rw: float) -> None:
        """The receiver clock's frequency random walk, m/s/√s, from now on (learnt from the
        data: :class:`selfnav.ins.tight.ClockNoise`)."""
        self._q_fixed[self.layout.clk.start + 1] = float(rw) ** 2

    def reprior(self, *names):
        """Return the named parameter blocks (``"lever"``, ``"vlag"``, ...; ``"bg"``, ``"ba"``,
        the biases) to their prior σ with no correlation with the rest, the installation's
        (lever arm, lag, mounting, odometer scale) to their configured values too (the
        sensor errors keep theirs: the prior is centred on zero) — what was learnt there is
        no longer trusted (an IMU time offset found far from the state had been absorbed by
        the lever arm along the car and the velocity lag, which look alike)."""
        prior = self.prior_sigma()
        imu = self.cfg.imu
        core = {"bg": (IBG, imu.gyro_bias_sigma), "ba": (IBA, imu.accel_bias_sigma)}
        for name, sl in [(n, s) for n, s in self.layout.blocks()] + [(n, v[0]) for n, v
                                                                     in core.items()]:
            if name not in names:
                continue
            sigma = core[name][1] if name in core else prior[name]
            self.P[sl, :] = 0.0
            self.P[:, sl] = 0.0
            self.P[sl, sl] = np.eye(sl.stop - sl.start) * sigma ** 2
            if name == "lever":
                self.lever_b = np.array(self.cfg.gnss.lever_arm_b, dtype=float).reshape(3)
            elif name == "vlag":
                self.velocity_lag = 0.0
            elif name == "mu":
                self.mu = np.array(self.cfg.states.mount_rad, dtype=float)
            elif name == "odo":
                self.odo_scale = 0.0
            elif name == "tdrift":          # it had absorbed the offset error the reset finds
                self.clock_drift = 0.0

    def copy(self) -> "InsGnssFilter":
        """An independent copy (state, covariance, sensor estimates), e.g. a dead-reckoning
        branch (:mod:`selfnav.ins.hypotheses`)."""
        import copy as _copy

        out = _copy.copy(self)
        out.ins = _copy.deepcopy(self.ins)
        for name in ("P", "bg", "ba", "sg", "sa", "mg", "ma", "mu", "lever_b", "_f_n", "_w_b",
                     "_f_b", "_Tg_inv", "_Ta_inv", "rx_isb"):
            setattr(out, name, np.array(getattr(self, name), dtype=float, copy=True))
        out._Fcc = np.zeros_like(self._Fcc)
        out._Fcp = np.zeros_like(self._Fcp)
        out._Phi_acc = np.eye(self.nx)
        out._kin = list(self._kin)
        out.track_transition = False
        return out


# ------------------------------------------------------------------------ smoother
@numba.njit(cache=True)
def _output_cov(P, C_bn, lever_b, v, lever_col, toff_col):  # pragma: no cover - compiled
    """``H P Hᵀ`` of :func:`output_covariance` (columns: position, attitude and lever arm when
    ``lever_col ≥ 0``, the time offset when ``toff_col ≥ 0``)."""
    cols = np.empty(10, np.int64)
    H = np.zeros((3, 10))
    k = 0
    for i in range(3):
        cols[k] = i
        H[i, k] = 1.0
        k += 1
    if lever_col >= 0:
        l_n = C_bn @ lever_b
        S = np.array([[0.0, -l_n[2], l_n[1]], [l_n[2], 0.0, -l_n[0]], [-l_n[1], l_n[0], 0.0]])
        for j in range(3):
            cols[k] = 6 + j
            for i in range(3):
                H[i, k] = S[i, j]
            k += 1
        for j in range(3):
            cols[k] = lever_col + j
            for i in range(3):
                H[i, k] = C_bn[i, j]
            k += 1
    if toff_col >= 0:
        cols[k] = toff_col
        for i in range(3):
            H[i, k] = -v[i]
        k += 1
    out = np.zeros((3, 3))
    for a in range(3):
        for b in range(a, 3):
            acc = 0.0
            for p in range(k):
                hp = H[a, p]
                if hp == 0.0:
                    continue
                for q in range(k):
                    acc += hp * P[cols[p], cols[q]] * H[b, q]
            out[a, b] = acc
            out[b, a] = acc
    return out


def output_covariance(P, layout: "StateLayout", C_nb, velocity_n, lever_b) -> np.ndarray:
    """ENU covariance (3×3, m²) of the point a row reports, at the row's true time: the
    antenna ``r + C_b^n l`` when the lever arm is estimated, else the IMU (DESIGN §10).

    Its error is what a GNSS fix there would see, :class:`selfnav.ins.measurements.PositionFix`'s
    ``H``: ``δr + [C_b^n l ×] ψ + C_b^n δl − v δε`` — the position σ alone leaves out the
    lever arm's and the time offset's (at 15 m/s a 0.2 s offset σ is 3 m, with 10 m fixes
    the offset is that loose)."""
    lay = layout
    if lay.lever is None and lay.toff is None:
        return P[:3, :3]
    return _output_cov(P, np.ascontiguousarray(np.asarray(C_nb, float).T),
                       np.asarray(lever_b, float).reshape(3),
                       np.asarray(velocity_n, float).reshape(3),
                       -1 if lay.lever is None else lay.lever.start,
                       -1 if lay.toff is None else lay.toff.start)


def pack_state(flt) -> np.ndarray:
    """The nominal state and sensor estimates of a filter as one row (:data:`PACK`)."""
    s = flt.ins
    return np.concatenate([[s.lat, s.lon, s.h], s.velocity_n, s.C_nb.reshape(9), flt.bg, flt.ba,
                           flt.sg, flt.sa, flt.mg, flt.ma, flt.mu, flt.lever_b,
                           [flt.time_offset], [flt.clock_drift], [flt.velocity_lag],
                           [flt.odo_scale], [flt.rx_clock, flt.rx_drift], flt.rx_isb])


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


def rts_smooth(states, P_plus, P_minus, Phi, updates, layout: StateLayout, breaks=None, *,
               return_errors: bool = False):
    """Rauch–Tung–Striebel smoother in error-state form over the stored epochs.

    Epoch k holds the corrected nominal state x̃⁺_k with covariance P⁺_k; ``Phi[k]`` carries the
    error from epoch k−1 to k, ``P_minus[k]`` is the covariance before epoch k's update and
    ``updates[k]`` the error estimate that update removed. With a reset after every update the
    filtered error of x̃⁺_k is zero, and the smoothed one is
    ``ε_k = A_k (updates[k+1] + ε_{k+1})``, ``A_k = P⁺_k Φ_{k+1}ᵀ (P⁻_{k+1})⁻¹`` (the error of
    the propagated state at k+1 is what its update removed plus what the smoother adds).

    ``breaks[k]``: epoch k's state was *replaced* (a reset to a dead-reckoning branch,
    :mod:`selfnav.ins.hypotheses`), not updated; nothing is carried back across it.
    ``return_errors``: also the smoothed error of each epoch's filtered state (N, nx).
    """
    n = len(states)
    out = states.copy()
    Ps = P_plus.copy()
    nx = updates.shape[1]
    eps_next = np.zeros(nx)
    errors = np.zeros((n, nx))
    for k in range(n - 2, -1, -1):
        if breaks is not None and breaks[k + 1]:
            eps_next = np.zeros(nx)
            continue
        Pm = P_minus[k + 1]
        A = np.linalg.solve(Pm.T, (P_plus[k] @ Phi[k + 1].T).T).T
        eps = A @ (updates[k + 1] + eps_next)
        Ps[k] = P_plus[k] + A @ (Ps[k + 1] - Pm) @ A.T
        out[k] = apply_error(states[k], eps, layout)
        errors[k] = eps
        eps_next = eps
    return (out, Ps, errors) if return_errors else (out, Ps)


__all__ = ["InsGnssFilter", "StateLayout", "NX", "IR", "IV", "IP", "IBG", "IBA", "PACK",
           "OFFDIAG", "pack_state", "unpack_states", "apply_error", "rts_smooth", "nis",
           "sensor_matrix"]
