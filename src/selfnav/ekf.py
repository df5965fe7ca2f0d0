"""Loosely coupled INS/GNSS error-state Kalman filter, RTS smoother and outlier defence (DESIGN §5, §7).

The nominal state is carried by the strapdown mechanization (:class:`selfnav.strapdown.Strapdown`,
seed 004 fast loop); the filter estimates its errors

    δx = [δr (ENU, m), δv (ENU, m/s), ψ (rad), δb_g (rad/s), δb_a (m/s²)]        (15 states)

with ``δ(·) = estimated − true`` and the attitude error ``C̃_b^n = (I − [ψ]) C_b^n``. Error
dynamics (psi-angle form, Groves ch. 14, simplified to what a MEMS or tactical IMU needs)::

    δṙ = δv,                       plus  δv̇_U += (2g/R) δr_U (the unstable vertical channel)
    δv̇ = f^n × ψ − (2ω_ie + ω_en) × δv − C_b^n δb_a
    ψ̇ = −ω_in × ψ + C_b^n δb_g
    δḃ = −δb/τ + w                 (τ = ∞ by default: a turn-on constant plus a random walk
                                    whose density matches the bias instability)

Aiding: GNSS position with lever arm, GNSS velocity, non-holonomic constraint (a car does not
slide sideways or jump), zero-velocity updates when the IMU is still, magnetometer heading.

**Outliers nothing flags** (seed 004: up to 5 min at 200 m σ; DESIGN §7). A χ² innovation gate
alone fails: while it rejects, P grows, and after a minute or two every outlier passes. selfnav
keeps the gate and adds a window test that P cannot weaken: consecutive fixes must agree with
each other *through the INS displacement* (short-term INS displacement is accurate to
centimetres even when its absolute position has drifted). After a run of rejections the filter
is in *suspect* mode: it dead-reckons (INS + vehicle constraints) and re-acquires only when a
window of fixes is internally consistent at the nominal σ and its common offset is consistent
with the dead-reckoning uncertainty. At start-up the same test (with a bounded-acceleration
motion model instead of the INS) chooses the first trusted fixes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav.earth import OMEGA_EARTH, WGS84, normal_gravity, radii
from selfnav.errors import SelfnavError
from selfnav.io.gnss import GnssData
from selfnav.simulate.trajectory import Trajectory
from selfnav.strapdown import Strapdown

NX = 15
IR, IV, IP, IBG, IBA = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15)
ISG, ISA = slice(15, 18), slice(18, 21)   # scale-factor errors (option)
CHI2_3_999 = 16.266
CHI2_2_999 = 13.816
CHI2_1_999 = 10.828


@dataclass
class FilterConfig:
    """Noise model and options of :class:`InsGnssFilter` (SI units).

    Defaults suit a consumer/industrial MEMS IMU on a car; :meth:`for_grade` gives others.
    """

    arw: float = np.radians(0.3) / 60.0          # gyro white noise, rad/√s
    vrw: float = 1e-3                            # accel white noise, (m/s)/√s
    gyro_bias_sigma: float = np.radians(0.05)    # initial/steady gyro bias σ, rad/s
    accel_bias_sigma: float = 0.05               # m/s²
    gyro_bias_tau: float = np.inf                # s; inf: random constant + random walk
    accel_bias_tau: float = np.inf
    gyro_bias_instability: float = np.radians(10.0) / 3600.0   # steady-state GM σ, rad/s
    accel_bias_instability: float = 5e-4                        # m/s²
    instability_tau: float = 100.0               # correlation time of the bias instability, s
    init_pos_sigma: float = 10.0
    init_vel_sigma: float = 0.5
    init_att_sigma: tuple = (np.radians(2.0), np.radians(2.0), np.radians(10.0))
    lever_arm_b: np.ndarray = field(default_factory=lambda: np.zeros(3))   # IMU -> antenna, RFU
    gnss_sigma_h: float | None = None            # override the file's sigma, m
    gnss_sigma_v: float | None = None
    gnss_sigma_floor: float = 0.1                # smallest σ believed: unmodelled timing, lever arm
    use_gnss_velocity: bool = False
    gnss_vel_sigma: float = 0.1
    nhc: bool = True                             # non-holonomic constraint (wheeled vehicle)
    nhc_sigma: float = 0.3                       # m/s, lateral and vertical body velocity
    zupt: bool = True
    zupt_sigma: float = 0.02
    zupt_speed: float = 1.0                      # the INS speed must be below this, m/s
    zupt_accel_h: float = 0.1                    # horizontal specific force below this, m/s²
    zupt_gyro: float = np.radians(1.0)           # |ω - mean| threshold over a window, rad/s
    zupt_accel: float = 0.15                     # std of |f| over the window, m/s²
    cov_step: float = 0.2                        # covariance propagation sub-step, s
    aid_step: float = 0.2                        # NHC / ZUPT update interval, s
    robust: bool = True                          # window consistency test and dead reckoning
    gate: float = CHI2_3_999                     # χ² gate on each fix (3 dof)
    soft_gate: float = 10.0                      # with robust: up to soft_gate × gate, R inflated
    degraded_window: float = 20.0                # s of suspect fixes to judge their noise
    degraded_min: int = 8                        # at least this many fixes
    window: int = 6                              # fixes in the consistency window
    suspect_after: int = 2                       # consecutive rejections before suspect mode
    max_accel: float = 5.0                       # start-up motion model, m/s²
    min_init_speed: float = 2.0                  # heading from the GNSS course above this, m/s
    vertical: str = "free"
    scale_factors: bool = False                  # add gyro and accel scale-factor states (21)
    gyro_sf_sigma: float = 0.01
    accel_sf_sigma: float = 0.01

    @classmethod
    def for_grade(cls, grade: str, **kw) -> "FilterConfig":
        """Noise settings for a sensor grade (navigation, tactical, industrial, consumer)."""
        g = grade.lower()
        if g == "consumer-car":
            # a consumer MEMS on a car roof (rtklibexplorer drive_0708): vibration and mounting
            # raise the effective noise: VRW ×5, ARW ×3, bias instability ×10 over the
            # datasheet-based consumer preset; the outage drift of that drive is then within
            # its predicted 3σ (tests/test_ekf_realdata.py)
            base = cls.for_grade("consumer")
            d = dict(vrw=base.vrw * 5, arw=base.arw * 3,
                     gyro_bias_instability=base.gyro_bias_instability * 10,
                     accel_bias_instability=base.accel_bias_instability * 10,
                     scale_factors=True)
            d.update(kw)
            return cls.for_grade("consumer", **d)
        presets = {
            "navigation": dict(arw=np.radians(0.002) / 60, vrw=5e-6, gyro_bias_sigma=np.radians(0.01) / 3600,
                               accel_bias_sigma=5e-4, gyro_bias_instability=np.radians(0.003) / 3600,
                               accel_bias_instability=1e-4, instability_tau=3600),
            "tactical": dict(arw=np.radians(0.012) / 60, vrw=1.2e-3, gyro_bias_sigma=np.radians(2.0) / 3600,
                             accel_bias_sigma=0.01, gyro_bias_instability=np.radians(0.05) / 3600,
                             accel_bias_instability=5e-4, instability_tau=300),
            "industrial": dict(arw=np.radians(0.15) / 60, vrw=2e-4, gyro_bias_sigma=np.radians(0.05),
                               accel_bias_sigma=0.02, gyro_bias_instability=np.radians(2.0) / 3600,
                               accel_bias_instability=1e-4, instability_tau=100),
            "consumer": dict(arw=np.radians(0.007), vrw=180e-6 * 9.80665, gyro_bias_sigma=np.radians(1.0),
                             accel_bias_sigma=0.2, gyro_bias_instability=np.radians(10.0) / 3600,
                             accel_bias_instability=5e-4, instability_tau=30),
        }
        if g not in presets:
            raise SelfnavError(f"unknown grade '{grade}' (use {', '.join(presets)} or consumer-car)")
        d = presets[g]
        d.update(kw)
        return cls(**d)


@dataclass
class FilterResult:
    """Output of :func:`run_filter` (and of the smoother)."""

    trajectory: Trajectory
    sigma_enu: np.ndarray         # (N, 3) position σ, m
    sigma_vel: np.ndarray         # (N, 3)
    sigma_att: np.ndarray         # (N, 3) rad (ψ E, N, U)
    gyro_bias: np.ndarray         # (N, 3)
    accel_bias: np.ndarray        # (N, 3)
    fix_t: np.ndarray             # GNSS epochs seen
    fix_status: np.ndarray        # 1 accepted, 0 rejected, -1 before initialisation
    innovations: np.ndarray       # (M, 3) ENU, m (NaN before init)
    nis: np.ndarray
    mode: np.ndarray              # per fix: 0 normal, 1 suspect
    smoothed: bool = False
    stats: dict = field(default_factory=dict)


def _skew(v):
    """Skew matrix of one 3-vector (fast path of :func:`selfnav.attitude.skew`)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _rot(rv):
    """``exp([rv])`` for one rotation vector (Rodrigues)."""
    th2 = rv @ rv
    K = _skew(rv)
    if th2 < 1e-12:
        return np.eye(3) + K + 0.5 * (K @ K)
    th = np.sqrt(th2)
    return np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / th2 * (K @ K)


def _enu_offset(lat0, lon0, h0, lat, lon, h):
    """ENU metres of (lat, lon, h) relative to (lat0, lon0, h0), small-offset form."""
    rm, rn = radii(lat0, h0)
    return np.array([(lon - lon0) * rn * np.cos(lat0), (lat - lat0) * rm, h - h0])


class InsGnssFilter:
    """Error-state EKF on top of a strapdown INS, with streaming ``predict``/``update_*`` calls.

    Most users call :func:`run_filter`; this class is the streaming interface (feed IMU blocks
    and fixes as they arrive).
    """

    def __init__(self, cfg: FilterConfig, t0, lat, lon, h, velocity_n, C_nb, *, ellipsoid=WGS84):
        self.cfg = cfg
        self.ins = Strapdown(lat, lon, h, velocity_n, C_nb, t=t0, ellipsoid=ellipsoid,
                             vertical=cfg.vertical)
        self.nx = 21 if cfg.scale_factors else NX
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.sg = np.zeros(3)
        self.sa = np.zeros(3)
        P = np.zeros((self.nx, self.nx))
        P[IR, IR] = np.eye(3) * cfg.init_pos_sigma**2
        P[IV, IV] = np.eye(3) * cfg.init_vel_sigma**2
        P[IP, IP] = np.diag(np.square(cfg.init_att_sigma))
        P[IBG, IBG] = np.eye(3) * cfg.gyro_bias_sigma**2
        P[IBA, IBA] = np.eye(3) * cfg.accel_bias_sigma**2
        if cfg.scale_factors:
            P[ISG, ISG] = np.eye(3) * cfg.gyro_sf_sigma**2
            P[ISA, ISA] = np.eye(3) * cfg.accel_sf_sigma**2
        self.P = P
        self._f_n = np.array([0.0, 0.0, 9.8])
        self._w_b = np.zeros(3)
        self._f_b = np.array([0.0, 0.0, 9.8])
        self._Phi_acc = np.eye(self.nx)  # transition since the last stored epoch (smoother)
        self._n_corr = 0
        self._I = np.eye(self.nx)

    # ------------------------------------------------------------------ model
    def _F(self, f_n, dt):
        cfg = self.cfg
        lat, h = self.ins.lat, self.ins.h
        v = self.ins.velocity_n
        rm, rn = radii(lat, h)
        w_ie = np.array([0.0, OMEGA_EARTH * np.cos(lat), OMEGA_EARTH * np.sin(lat)])
        w_en = np.array([-v[1] / rm, v[0] / rn, v[0] * np.tan(lat) / rn])
        C_bn = self.ins.C_nb.T
        F = np.zeros((self.nx, self.nx))
        F[IR, IV] = np.eye(3)
        F[IV, IP] = _skew(f_n)
        F[IV, IV] = -_skew(2 * w_ie + w_en)
        F[IV, IBA] = -C_bn
        g = float(normal_gravity(lat, h))
        F[5, 2] = 2.0 * g / (np.sqrt(rm * rn))
        F[IP, IP] = -_skew(w_ie + w_en)
        F[IP, IBG] = C_bn
        F[IBG, IBG] = -np.eye(3) / cfg.gyro_bias_tau
        F[IBA, IBA] = -np.eye(3) / cfg.accel_bias_tau
        if cfg.scale_factors:
            # corrected rate (ω̃ − b)/(1 + s): its error is −(δb + diag(ω) δs)
            F[IP, ISG] = C_bn * self._w_b[None, :]
            F[IV, ISA] = -C_bn * self._f_b[None, :]
        return F

    def _Q(self, dt):
        cfg = self.cfg
        q = np.zeros(self.nx)
        q[IV] = cfg.vrw**2
        q[IP] = cfg.arw**2
        q[IBG] = 2 * cfg.gyro_bias_instability**2 / cfg.instability_tau
        q[IBA] = 2 * cfg.accel_bias_instability**2 / cfg.instability_tau
        return np.diag(q * dt)

    # ------------------------------------------------------------------ propagation
    def predict(self, t, dtheta, dv):
        """Mechanize a block of IMU increments (bias-corrected) and propagate the covariance.

        Returns the block's :class:`~selfnav.simulate.trajectory.Trajectory`.
        """
        t = np.asarray(t, dtype=float)
        if len(t) == 0:
            return None
        dt = np.diff(np.concatenate([[self.ins.t], t]))
        dth = (dtheta - self.bg * dt[:, None]) / (1.0 + self.sg)
        dvb = (dv - self.ba * dt[:, None]) / (1.0 + self.sa)
        tr = self.ins.run(t, dth, dvb)
        T = float(t[-1] - (t[0] - dt[0]))
        f_b = dvb.sum(0) / T
        self._f_b = f_b
        self._f_n = tr.C_nb[-1].T @ f_b
        self._w_b = dth.sum(0) / T
        nsub = max(1, int(np.ceil(T / self.cfg.cov_step)))
        F = self._F(self._f_n, T)
        h = T / nsub
        Phi = np.eye(self.nx) + F * h + 0.5 * (F @ F) * h * h
        Q = self._Q(h)
        for _ in range(nsub):
            self.P = Phi @ self.P @ Phi.T + Q
            self._Phi_acc = Phi @ self._Phi_acc
        return tr

    # ------------------------------------------------------------------ updates
    def _correct(self, dx):
        ins = self.ins
        lat, h = ins.lat, ins.h
        rm, rn = radii(lat, h)
        C_bn = _rot(dx[IP]) @ ins.C_nb.T
        self._n_corr += 1
        if self._n_corr % 100 == 0:  # rotations keep it orthonormal; clean rounding now and then
            C_bn = att.orthonormalize(C_bn)
        ins.set_state(lat=lat - dx[1] / rm, lon=ins.lon - dx[0] / (rn * np.cos(lat)),
                      h=h - dx[2], velocity_n=ins.velocity_n - dx[IV], C_nb=C_bn.T, check=False)
        self.bg -= dx[IBG]  # δb = estimated − true
        self.ba -= dx[IBA]
        if self.nx > NX:
            self.sg -= dx[ISG]
            self.sa -= dx[ISA]

    def _kalman(self, r, H, R):
        S = H @ self.P @ H.T + R
        K = np.linalg.solve(S, H @ self.P).T
        dx = K @ r
        IKH = self._I - K @ H
        self.P = IKH @ self.P @ IKH.T + K @ R @ K.T
        self._correct(dx)
        return dx

    def position_residual(self, lat, lon, h):
        """``h(x̃) − z`` in ENU metres and its H for a GNSS fix at the antenna."""
        ins = self.ins
        C_bn = ins.C_nb.T
        l_n = C_bn @ self.cfg.lever_arm_b
        z = _enu_offset(ins.lat, ins.lon, ins.h, lat, lon, h)
        r = l_n - z
        H = np.zeros((3, self.nx))
        H[:, IR] = np.eye(3)
        H[:, IP] = _skew(l_n)
        return r, H

    def update_position(self, lat, lon, h, sigma_h, sigma_v, *, gate=None):
        """GNSS position update with χ² gating; returns ``(accepted, nis, residual)``."""
        r, H = self.position_residual(lat, lon, h)
        R = np.diag([sigma_h**2, sigma_h**2, sigma_v**2])
        S = H @ self.P @ H.T + R
        nis = float(r @ np.linalg.solve(S, r))
        if gate is not None and nis > gate:
            return False, nis, r
        self._kalman(r, H, R)
        return True, nis, r

    def update_velocity(self, velocity_n, sigma):
        H = np.zeros((3, self.nx))
        H[:, IV] = np.eye(3)
        r = self.ins.velocity_n - np.asarray(velocity_n)
        R = np.eye(3) * sigma**2
        S = H @ self.P @ H.T + R
        if float(r @ np.linalg.solve(S, r)) > CHI2_3_999:
            return np.zeros(self.nx)
        return self._kalman(r, H, R)

    def update_nhc(self):
        """Non-holonomic constraint: body lateral (x) and vertical (z) velocity are zero."""
        C_nb = self.ins.C_nb
        v = self.ins.velocity_n
        vb = C_nb @ v
        H = np.zeros((2, self.nx))
        H[:, IV] = C_nb[[0, 2]]
        H[:, IP] = -C_nb[[0, 2]] @ _skew(v)
        R = np.eye(2) * self.cfg.nhc_sigma**2
        return self._kalman(vb[[0, 2]], H, R)

    def update_zupt(self):
        H = np.zeros((3, self.nx))
        H[:, IV] = np.eye(3)
        return self._kalman(self.ins.velocity_n, H, np.eye(3) * self.cfg.zupt_sigma**2)

    def update_heading(self, heading, sigma):
        """True heading (rad), e.g. magnetic heading plus declination (seed 004 (12))."""
        _, _, hdg = att.euler_from_dcm_nb(self.ins.C_nb)
        r = np.array([np.angle(np.exp(1j * (hdg - heading)))])
        H = np.zeros((1, self.nx))
        H[0, 8] = 1.0  # ψ_U raises the computed heading (C̃ = (I − [ψ]) C)
        S = H @ self.P @ H.T + sigma**2
        if float(r @ r / S[0, 0]) > CHI2_1_999:
            return np.zeros(self.nx)
        return self._kalman(r, H, np.array([[sigma**2]]))

    def take_transition(self):
        Phi = self._Phi_acc
        self._Phi_acc = np.eye(self.nx)
        return Phi


def _still(imu_w, imu_f, C_nb, cfg):
    """ZUPT detector on one aiding block: small rates, steady |f|, no horizontal acceleration.

    An IMU cannot tell rest from constant velocity, so the caller also asks for a slow INS.
    """
    if len(imu_w) < 3:
        return False
    f_n = C_nb.T @ imu_f.mean(0)
    return (np.max(np.linalg.norm(imu_w, axis=1)) < cfg.zupt_gyro
            and np.std(np.linalg.norm(imu_f, axis=1)) < cfg.zupt_accel
            and np.hypot(f_n[0], f_n[1]) < cfg.zupt_accel_h)


def _consistent_run(p, t, sig, cfg):
    """True if positions ``p`` (W, 2) at times ``t`` fit bounded speed and acceleration.

    Second differences ``p_{k+1} − 2p_k + p_{k−1}`` must stay below ``a_max Δt² + 3·√6 σ``:
    white outliers of 200 m break that at once (start-up, DESIGN §7).
    """
    dt = np.diff(t)
    if np.any(dt > 5.0) or np.any(dt <= 0):
        return False
    v = np.diff(p, axis=0) / dt[:, None]
    if np.any(np.linalg.norm(v, axis=1) > 70.0 + 3 * np.sqrt(2) * np.max(sig) / dt.min()):
        return False
    acc = np.linalg.norm(np.diff(v, axis=0), axis=1)
    return bool(np.all(acc < cfg.max_accel * dt.max() + 3 * np.sqrt(6) * np.max(sig) / dt.min()))


def _triad_nb(b1, b2, n1, n2):
    """``C_n^b`` with ``C_n^b n1 ∥ b1`` exactly and ``n2`` as close to ``b2`` as it can be."""
    def frame(u, w):
        u = u / np.linalg.norm(u)
        c = np.cross(u, w)
        c = c / np.linalg.norm(c)
        return np.column_stack([u, c, np.cross(u, c)])
    return frame(b1, b2) @ frame(n1, n2).T


def _still_before(imu, t_end, gnss=None, g=9.8, window=1.0, lookback=60.0):
    """Start index of the last still second within ``lookback`` s before ``t_end``, or None.

    Still: gyro norm below 1 °/s, |f| steady to 0.05 m/s² and within 0.1 m/s² of gravity (a
    constant acceleration is steady too), and the GNSS fixes around it not moving.
    """
    n = int(round(window / imu.dt))
    j1 = np.searchsorted(imu.t, t_end)
    j0 = np.searchsorted(imu.t, t_end - lookback)
    for j in range(j1 - n, j0 - 1, -max(n // 4, 1)):
        if j < 0:
            break
        w = imu.omega_ib_b[j:j + n]
        fn = np.linalg.norm(imu.f_ib_b[j:j + n], axis=1)
        if not (np.max(np.linalg.norm(w, axis=1)) < np.radians(1.0) and np.std(fn) < 0.05
                and abs(np.mean(fn) - g) < 0.1):
            continue
        if gnss is not None:
            m = (gnss.t >= imu.t[j] - 1.0) & (gnss.t <= imu.t[min(j + n, len(imu.t) - 1)] + 1.0)
            if m.sum() >= 2:
                d = _enu_offset(gnss.lat[m][0], gnss.lon[m][0], 0.0, gnss.lat[m][-1],
                                gnss.lon[m][-1], 0.0)
                span = gnss.t[m][-1] - gnss.t[m][0]
                sig = float(np.max(gnss.sigma_m[m])) if gnss.sigma_m is not None else 5.0
                if np.hypot(d[0], d[1]) > 0.5 * span + 3.0 * np.sqrt(2) * sig:
                    continue
        return j
    return None


def _init_from_gnss(imu, gnss: GnssData, cfg: FilterConfig, sig_h):
    """Initial state for a vehicle: the in-motion alignment.

    1. The first window of fixes that fit bounded speed and acceleration, moving fast enough
       that the course is known (speed above ``min_init_speed`` and four times its σ):
       position and velocity by a straight-line fit, heading from the course (a car moves
       along its body y axis).
    2. Roll and pitch: levelled from the last still second before it (if any), carried to
       the start time by the gyros (the rotation about the vertical is irrelevant there);
       otherwise from the specific force against the GNSS acceleration of a quadratic fit.
    """
    n = len(gnss.t)
    W = max(cfg.window, 3)
    lat0, lon0 = gnss.lat[0], gnss.lon[0]
    rm, rn = radii(lat0, 0.0)
    p = np.column_stack([(gnss.lon - lon0) * rn * np.cos(lat0), (gnss.lat - lat0) * rm, gnss.h])
    for k in range(n - W + 1):
        sl = slice(k, k + W)
        if cfg.robust and not _consistent_run(p[sl, :2], gnss.t[sl], sig_h[sl], cfg):
            continue
        # a straight-line fit gives the *mean* velocity: exact at the centre of the window for a
        # constant acceleration, so the filter starts at the centre time
        t0 = float(np.mean(gnss.t[sl]))
        tt = gnss.t[sl] - t0
        A = np.column_stack([np.ones(W), tt])
        coef, *_ = np.linalg.lstsq(A, p[sl], rcond=None)
        s = float(np.max(sig_h[sl]))
        cov = np.linalg.inv(A.T @ A) * s * s
        v0, sv = coef[1], float(np.sqrt(cov[1, 1]))
        if gnss.velocity_n is not None:
            v0 = np.array([np.interp(t0, gnss.t[sl], gnss.velocity_n[sl, i]) for i in range(3)])
            sv = cfg.gnss_vel_sigma
        speed = float(np.hypot(v0[0], v0[1]))
        if speed <= max(cfg.min_init_speed, 4.0 * sv):
            continue
        sp = float(np.sqrt(cov[0, 0]))
        lat = lat0 + coef[0, 1] / rm
        lon = lon0 + coef[0, 0] / (rn * np.cos(lat0))
        hdg = np.arctan2(v0[0], v0[1])
        j0 = _still_before(imu, t0, gnss, float(normal_gravity(lat, coef[0, 2])))
        if j0 is not None:
            nlev = int(round(1.0 / imu.dt))
            f_lev = imu.f_ib_b[j0:j0 + nlev].mean(0)
            roll0 = np.arctan2(-f_lev[0], f_lev[2])
            pitch0 = np.arctan2(f_lev[1], np.hypot(f_lev[0], f_lev[2]))
            C0 = att.dcm_nb_from_euler(roll0, pitch0, 0.0)
            j1 = np.searchsorted(imu.t, t0)
            from selfnav.latitude import _gyro_attitude
            dts = np.diff(imu.t[j0:j1 + 1], prepend=imu.t[j0] - imu.dt)
            q = _gyro_attitude(np.ascontiguousarray(imu.omega_ib_b[j0:j1 + 1]), dts)
            C_bn = C0.T @ att.quat_to_dcm(q[-1])
            roll, pitch, _ = att.euler_from_dcm_bn(C_bn)
            dur = imu.t[j1] - imu.t[j0]
            s_tilt = np.radians(0.3) + cfg.gyro_bias_sigma * dur
        else:
            # quadratic fit over twice the window for the acceleration
            sl2 = slice(max(0, k + W - 2 * W), k + W)
            t2 = gnss.t[sl2] - t0
            A2 = np.column_stack([np.ones(len(t2)), t2, 0.5 * t2 * t2])
            c2, *_ = np.linalg.lstsq(A2, p[sl2], rcond=None)
            sa = float(np.sqrt(np.linalg.inv(A2.T @ A2)[2, 2])) * s
            j = np.searchsorted(imu.t, t0)
            f_b = imu.f_ib_b[max(0, j - int(round(0.5 / imu.dt))):j + 1].mean(0)
            f_n = c2[2] + np.array([0.0, 0.0, float(normal_gravity(lat, coef[0, 2]))])
            Ct = _triad_nb(f_b, np.array([0.0, 1.0, 0.0]), f_n, v0 / np.linalg.norm(v0))
            roll, pitch, _ = att.euler_from_dcm_nb(Ct)
            s_tilt = np.hypot(sa, 0.3) / 9.8 + np.radians(1.0)
        s_hdg = np.arctan2(sv, speed) + np.radians(2.0)
        return dict(t=t0, lat=lat, lon=lon, h=coef[0, 2], velocity_n=v0,
                    C_nb=att.dcm_nb_from_euler(roll, pitch, hdg),
                    sigmas=([2 * sp, 2 * sp, 3 * sp], [2 * sv, 2 * sv, 2 * sv + 0.2],
                            [2 * s_tilt, 2 * s_tilt, 2 * s_hdg]))
    raise SelfnavError(f"no run of {W} mutually consistent GNSS fixes moving faster than "
                       f"{cfg.min_init_speed} m/s to start from (heading needs motion)")


def run_filter(imu, gnss: GnssData, cfg: FilterConfig | None = None, *, init=None,
               smooth: bool = False, heading=None, progress=None) -> FilterResult:
    """Run the loosely coupled filter over a whole record (batch call).

    Parameters
    ----------
    imu : ImuData
        Rates (mean over each interval ending at ``t``) in body RFU.
    gnss : GnssData
    cfg : FilterConfig
    init : dict, optional
        ``lat, lon, h, velocity_n, C_nb, t`` to start from (e.g. truth or a static alignment);
        default: the first trusted fixes, heading from the GNSS course, roll/pitch levelled.
    smooth : bool
        Run the RTS smoother backwards over the stored epochs.
    heading : (t, heading_rad, sigma_rad), optional
        Heading measurements (magnetometer + declination).
    progress : callable(fraction), optional
    """
    cfg = cfg or FilterConfig()
    t_imu = imu.t
    dt_imu = np.diff(np.concatenate([[t_imu[0] - imu.dt], t_imu]))
    dth_all = imu.omega_ib_b * dt_imu[:, None]
    dv_all = imu.f_ib_b * dt_imu[:, None]
    nfix = len(gnss.t)
    sig_file = gnss.sigma_m if gnss.sigma_m is not None else np.full(nfix, np.nan)
    sig_h = np.where(np.isfinite(sig_file), sig_file, 5.0)
    if cfg.gnss_sigma_h is not None:
        sig_h = np.full(nfix, cfg.gnss_sigma_h)
    sig_h = np.maximum(sig_h, cfg.gnss_sigma_floor)
    sig_v = np.full(nfix, cfg.gnss_sigma_v) if cfg.gnss_sigma_v is not None else 1.5 * sig_h

    # ---------------------------------------------------------------- initialisation
    if init is None:
        init = _init_from_gnss(imu, gnss, cfg, sig_h)
    t0 = float(init["t"])
    flt = InsGnssFilter(cfg, t0, init["lat"], init["lon"], init["h"], init["velocity_n"],
                        init["C_nb"])
    if "P" in init:
        flt.P = np.array(init["P"], dtype=float)
    elif "sigmas" in init:
        sp, sv, sa = init["sigmas"]
        flt.P[IR, IR] = np.diag(np.square(sp))
        flt.P[IV, IV] = np.diag(np.square(sv))
        flt.P[IP, IP] = np.diag(np.square(sa))

    # ---------------------------------------------------------------- epochs
    t_end = t_imu[-1]
    aid_times = np.arange(t0 + cfg.aid_step, t_end + 1e-9, cfg.aid_step)
    events = [(tt, 1, -1) for tt in aid_times]
    events += [(gnss.t[k], 0, k) for k in range(nfix) if t0 < gnss.t[k] <= t_end]
    if heading is not None:
        events += [(heading[0][k], 2, k) for k in range(len(heading[0])) if t0 < heading[0][k] <= t_end]
    events.sort()
    rec_t, rec_state, rec_P, rec_Pm, rec_Phi, rec_dx = [], [], [], [], [], []
    fix_status = -np.ones(nfix, int)
    innov = np.full((nfix, 3), np.nan)
    nis_all = np.full(nfix, np.nan)
    mode_all = np.zeros(nfix, int)
    i_imu = np.searchsorted(t_imu, t0, side="right")
    suspect = False
    rejections = 0
    streak = 0
    degraded = 0
    sus = []
    reacq = 0
    buf = []          # recent fixes: (k, z-position ENU relative to INS, INS position snapshot)
    last_acc = None   # last accepted fix: (t, lat, lon, h, ins lat, lon, h)

    # INS displacement accumulated by propagation only (ENU, m): the corrections of updates
    # are not motion, so the window test compares fixes with this
    disp = np.zeros(3)

    def ins_snapshot():
        return disp.copy()

    for ev_i, (te, kind, k) in enumerate(events):
        j = np.searchsorted(t_imu, te, side="right")
        if j > i_imu:
            p0 = (flt.ins.lat, flt.ins.lon, flt.ins.h)
            flt.predict(t_imu[i_imu:j], dth_all[i_imu:j], dv_all[i_imu:j])
            disp += _enu_offset(*p0, flt.ins.lat, flt.ins.lon, flt.ins.h)
            w_blk, f_blk = imu.omega_ib_b[i_imu:j], imu.f_ib_b[i_imu:j]
            i_imu = j
        else:
            w_blk = f_blk = np.zeros((0, 3))
        Pm = flt.P.copy()
        dx_total = np.zeros(flt.nx)
        if kind == 1:
            # still IMU *and* a slow INS: constant velocity also looks still to an IMU
            if (cfg.zupt and np.linalg.norm(flt.ins.velocity_n) < cfg.zupt_speed
                    and _still(w_blk - flt.bg, f_blk - flt.ba, flt.ins.C_nb, cfg)):
                dx_total = flt.update_zupt()
            elif cfg.nhc:
                dx_total = flt.update_nhc()
        elif kind == 2:
            dx_total = flt.update_heading(heading[1][k], heading[2][k])
        else:
            lat, lon, h = gnss.lat[k], gnss.lon[k], gnss.h[k]
            r, H = flt.position_residual(lat, lon, h)
            innov[k] = -r
            R = np.diag([sig_h[k] ** 2, sig_h[k] ** 2, sig_v[k] ** 2])
            S = H @ flt.P @ H.T + R
            nis = float(r @ np.linalg.solve(S, r))
            nis_all[k] = nis
            snap = ins_snapshot()
            # soft gate: a fix a little beyond the χ² gate is used with R inflated by NIS/gate
            # (Huber-like); real model errors are not Gaussian, outliers of 200 m are far beyond
            ok = nis <= cfg.gate * (cfg.soft_gate if cfg.robust else 1.0)
            if cfg.robust:
                # window test: displacements between fixes against the INS displacement, which
                # stays accurate when the absolute INS position has drifted (P cannot weaken it)
                buf.append((k, snap))
                buf = buf[-cfg.window:]
                sv = float(np.sqrt(np.trace(flt.P[IV, IV]) / 3.0)) + 0.2
                R_scale = 1.0
                if suspect:
                    sus.append((gnss.t[k], -r))
                    sus = [x for x in sus if x[0] > gnss.t[k] - cfg.degraded_window]
                    win_ok = len(buf) >= cfg.window and _window_consistent(buf, gnss, sig_h, sig_v, sv)
                    streak = streak + 1 if win_ok else 0
                    if win_ok and not ok and streak >= cfg.window:
                        # a long run of self-consistent fixes that the dead reckoning cannot
                        # explain: its drift exceeded P; re-acquire by widening P to the offset
                        flt.P[IR, IR] += np.diag(r * r)
                        ok = True
                        reacq += 1
                    elif win_ok:
                        pass
                    else:
                        ok = False
                        # degraded mode: white outliers still carry information. Their scale
                        # from fix-to-fix differences (which cancel the slow dead-reckoning
                        # drift) against their scale about the median: equal for white noise,
                        # much smaller for a drifting (correlated) error, which is not used.
                        s_eff = _white_scale(sus, cfg)
                        if s_eff is not None and s_eff > 3.0 * sig_h[k]:
                            R_d = np.diag([s_eff**2, s_eff**2, (1.5 * s_eff) ** 2])
                            S_d = H @ flt.P @ H.T + R_d
                            if float(r @ np.linalg.solve(S_d, r)) <= cfg.gate:
                                dx_total = flt._kalman(r, H, R_d)
                                degraded += 1
                else:
                    ok = ok and _disp_ok(buf[-2], buf[-1], gnss, sig_h, sig_v, sv) if len(buf) > 1 else ok
            mode_all[k] = int(suspect)
            if ok:
                R = np.diag([sig_h[k] ** 2, sig_h[k] ** 2, sig_v[k] ** 2]) * max(1.0, nis / cfg.gate)
                dx_total = flt._kalman(r, H, R)
                fix_status[k] = 1
                rejections = 0
                suspect = False
                streak = 0
                sus = []
            else:
                fix_status[k] = 0
                rejections += 1
                if cfg.robust and rejections >= cfg.suspect_after:
                    suspect = True
            if gnss.velocity_n is not None and cfg.use_gnss_velocity and ok:
                dxv = flt.update_velocity(gnss.velocity_n[k], cfg.gnss_vel_sigma)
                dx_total = dx_total + dxv
        rec_t.append(te)
        rec_state.append(_pack(flt))
        rec_P.append(flt.P.copy())
        rec_Pm.append(Pm)
        rec_Phi.append(flt.take_transition())
        rec_dx.append(dx_total)
        if progress is not None and ev_i % 200 == 0:
            progress(ev_i / len(events))
    if i_imu < len(t_imu):
        flt.predict(t_imu[i_imu:], dth_all[i_imu:], dv_all[i_imu:])
        rec_t.append(t_imu[-1])
        rec_state.append(_pack(flt))
        rec_P.append(flt.P.copy())
        rec_Pm.append(flt.P.copy())
        rec_Phi.append(flt.take_transition())
        rec_dx.append(np.zeros(flt.nx))
    rec_t = np.asarray(rec_t)
    states = np.asarray(rec_state)
    Ps = np.asarray(rec_P)
    smoothed = False
    if smooth and len(rec_t) > 2:
        states, Ps = _rts(states, Ps, np.asarray(rec_Pm), np.asarray(rec_Phi), np.asarray(rec_dx))
        smoothed = True
    traj, sig, bg, ba = _unpack(rec_t, states, Ps)
    acc = fix_status == 1
    stats = {"fixes": int(nfix), "accepted": int(acc.sum()), "rejected": int((fix_status == 0).sum()),
             "before_init": int((fix_status == -1).sum()), "reacquisitions": reacq,
             "degraded_updates": degraded}
    return FilterResult(traj, sig[:, IR], sig[:, IV], sig[:, IP], bg, ba, gnss.t, fix_status,
                        innov, nis_all, mode_all, smoothed, stats)


def _disp_ok(a, b, gnss, sig_h, sig_v, sv):
    """Fix b agrees with fix a through the INS displacement (χ², 3 dof, 0.999).

    ``sv`` is the INS velocity σ, m/s: the relative drift over the gap is ``sv·Δt``.
    """
    (ka, sa), (kb, sb) = a, b
    dz = _enu_offset(gnss.lat[ka], gnss.lon[ka], gnss.h[ka], gnss.lat[kb], gnss.lon[kb], gnss.h[kb])
    di = sb - sa  # INS displacement by propagation (see run_filter)
    dtt = gnss.t[kb] - gnss.t[ka]
    s2 = np.array([sig_h[ka] ** 2 + sig_h[kb] ** 2] * 2 + [sig_v[ka] ** 2 + sig_v[kb] ** 2]) + (sv * dtt) ** 2
    d = dz - di
    return float(np.sum(d * d / s2)) <= CHI2_3_999


def _white_scale(sus, cfg):
    """Robust per-axis scale of suspect innovations if they look white, else None.

    ``s_diff`` from fix-to-fix differences (÷√2) cancels a slow dead-reckoning drift;
    ``s_level`` is the spread about the median. White errors give s_diff ≈ s_level; a slowly
    drifting (Gauss–Markov) error gives s_diff ≪ s_level and its fixes are not averaged.
    """
    if len(sus) < cfg.degraded_min:
        return None
    v = np.array([x[1][:2] for x in sus])
    s_diff = 1.4826 * np.median(np.abs(np.diff(v, axis=0))) / np.sqrt(2.0)
    s_level = 1.4826 * np.median(np.abs(v - np.median(v, axis=0)))
    if s_level <= 0 or s_diff < 0.7 * s_level:
        return None
    return float(max(s_diff, s_level))


def _window_consistent(buf, gnss, sig_h, sig_v, sv):
    """All consecutive pairs in the window agree through the INS displacement."""
    return all(_disp_ok(buf[i], buf[i + 1], gnss, sig_h, sig_v, sv) for i in range(len(buf) - 1))


def _lever_arm_n(self):
    return self.ins.C_nb.T @ self.cfg.lever_arm_b


InsGnssFilter.lever_arm_n = _lever_arm_n


def _pack(flt):
    s = flt.ins
    return np.concatenate([[s.lat, s.lon, s.h], s.velocity_n, s.C_nb.reshape(9), flt.bg, flt.ba,
                           flt.sg, flt.sa])


def _unpack(t, states, Ps):
    C = states[:, 6:15].reshape(-1, 3, 3)
    traj = Trajectory(t, states[:, 0], states[:, 1], states[:, 2], states[:, 3:6], C,
                      source="selfnav ekf")
    sig = np.sqrt(np.maximum(np.diagonal(Ps, axis1=1, axis2=2), 0.0))
    return traj, sig, states[:, 15:18], states[:, 18:21]


def _apply_error(state, dx):
    """Remove an error-state estimate from a packed nominal state."""
    lat, lon, h = state[0], state[1], state[2]
    rm, rn = radii(lat, h)
    out = state.copy()
    out[0] = lat - dx[1] / rm
    out[1] = lon - dx[0] / (rn * np.cos(lat))
    out[2] = h - dx[2]
    out[3:6] = state[3:6] - dx[IV]
    C_nb = state[6:15].reshape(3, 3)
    C_bn = att.rotvec_to_dcm(dx[IP]) @ C_nb.T
    out[6:15] = att.orthonormalize(C_bn).T.reshape(9)
    out[15:18] = state[15:18] - dx[IBG]
    out[18:21] = state[18:21] - dx[IBA]
    if len(dx) > NX:
        out[21:24] = state[21:24] - dx[ISG]
        out[24:27] = state[24:27] - dx[ISA]
    return out


def _rts(states, P_plus, P_minus, Phi, updates):
    """Rauch–Tung–Striebel smoother in error-state form over the stored epochs.

    Epoch k holds the corrected nominal state x̃⁺_k with covariance P⁺_k; ``Phi[k]`` carries the
    error from epoch k−1 to k, ``P_minus[k]`` is the covariance before epoch k's update and
    ``updates[k]`` the error estimate that update removed. With a reset after every update the
    filtered error of x̃⁺_k is zero, and the smoothed one is
    ``ε_k = A_k (updates[k+1] + ε_{k+1})``, ``A_k = P⁺_k Φ_{k+1}ᵀ (P⁻_{k+1})⁻¹`` (the error of
    the propagated state at k+1 is what its update removed plus what the smoother adds).
    """
    n = len(states)
    out = states.copy()
    Ps = P_plus.copy()
    nx = updates.shape[1]
    eps_next = np.zeros(nx)
    for k in range(n - 2, -1, -1):
        Pm = P_minus[k + 1]
        A = np.linalg.solve(Pm.T, (P_plus[k] @ Phi[k + 1].T).T).T
        eps = A @ (updates[k + 1] + eps_next)
        Ps[k] = P_plus[k] + A @ (Ps[k + 1] - Pm) @ A.T
        out[k] = _apply_error(states[k], eps)
        eps_next = eps
    return out, Ps
