"""Loosely coupled INS/GNSS error-state Kalman filter, RTS smoother and outlier defence (DESIGN §5, §7).

The nominal state is carried by the strapdown mechanization (:class:`selfnav.strapdown.Strapdown`,
seed 004 fast loop); the filter estimates its errors

    δx = [δr (ENU, m), δv (ENU, m/s), ψ (rad), δb_g (rad/s), δb_a (m/s²)]        (15 states)
         [+ δs_g, δs_a (scale factors, 6)] [+ δμ (IMU pitch and yaw to the vehicle, 2)]

with ``δ(·) = estimated − true`` and the attitude error ``C̃_b^n = (I − [ψ]) C_b^n``. Error
dynamics (psi-angle form, Groves ch. 14, simplified to what a MEMS or tactical IMU needs)::

    δṙ = δv,                       plus  δv̇_U += (2g/R) δr_U (the unstable vertical channel)
    δv̇ = f^n × ψ − (2ω_ie + ω_en) × δv − C_b^n δb_a
    ψ̇ = −ω_in × ψ + C_b^n δb_g
    δḃ = −δb/τ + w                 (τ = ∞ by default: a turn-on constant plus a random walk
                                    whose density matches the bias instability)

Aiding: GNSS position with lever arm, GNSS velocity, non-holonomic constraint (a car does not
slide sideways or jump), zero-velocity updates when the IMU is still, magnetometer heading.

The non-holonomic constraint holds in the *vehicle* frame at a point that does not slip
sideways (the rear-axle centre), not at the IMU: ``v_v = C_vb (C_bn^T v^n + ω_b × l_nhc)``
with ``C_vb = exp([μ×])``, μ = (pitch, 0, yaw) of the IMU relative to the vehicle (small angles,
positive nose-up and to the left). Unmodelled, a 0.5° mounting pitch makes the NHC tilt the INS
by 0.5° while GNSS is out (a g·0.5° = 0.09 m/s² along-track error), and a 1.5 m lever turns
a 0.5 rad/s parking turn into 0.75 m/s of "side slip"; ``mount_states`` estimates μ,
``nhc_lever_b`` gives the lever.

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
from selfnav.io.gnss import GnssData  # noqa: F401  (re-exported)
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
    nhc_sigma_up: float | None = None            # m/s, vertical if it differs from lateral
    zupt: bool = True
    zupt_sigma: float = 0.02
    zupt_speed: float = 1.0                      # the INS speed must be below this, m/s
    zupt_speed_sigmas: float = 0.0               # … or below this many velocity σ (dead reckoning)
    zupt_accel_h: float = 0.1                    # horizontal specific force below this, m/s²
    zupt_gyro: float = np.radians(1.0)           # |ω - mean| threshold over a window, rad/s
    zupt_accel: float = 0.15                     # std of |f| over the window, m/s²
    cov_step: float = 0.2                        # covariance propagation sub-step, s
    aid_step: float = 0.2                        # NHC / ZUPT update interval, s
    robust: bool = True                          # window consistency test and dead reckoning
    gate: float = CHI2_3_999                     # χ² gate on each fix (3 dof)
    soft_gate: float = 10.0                      # with robust: up to soft_gate × gate, R inflated,
    soft_gate_max_m: float = 3.0                 # … for innovations below this or 3σ only
    degraded_window: float = 20.0                # s of suspect fixes to judge their noise
    degraded_min: int = 15                       # at least this many fixes
    window: int = 6                              # fixes in the consistency window
    suspect_after: int = 2                       # consecutive rejections before suspect mode
    max_accel: float = 5.0                       # start-up motion model, m/s²
    dr_guard: bool = True                        # with robust: shadow dead reckoning (drguard)
    dr_branch: float = 30.0                      # s between shadows
    dr_max_age: float = 90.0                     # s a shadow lives while GNSS is trusted
    dr_min_age: float = 5.0                      # s before a shadow tests fixes
    dr_step: float = 1.0                         # s between shadow updates
    dr_att_sigma: float = np.radians(0.5)        # branch only when every attitude σ is below
    dr_sigma_scale: float = 2.0                  # shadow σ inflation (EKF dead reckoning is optimistic)
    dr_gate: float = 18.421                      # χ²₂(0.9999) of a fix against a shadow
    dr_fit_sigma: float = 0.5                    # m/s: re-acquire after a run this sure of its speed
    dr_max_suspect: float = 330.0                # s after which any consistent run re-acquires
    dr_reacq_run: float = 20.0                   # s of fixes moving like the dead reckoning that
                                                 # re-acquire outside its uncertainty
    min_init_speed: float = 5.0                  # heading from the GNSS course above this, m/s
    vertical: str = "free"
    scale_factors: bool = False                  # add gyro and accel scale-factor states (21)
    mount_states: bool = False                   # estimate the IMU pitch/yaw to the vehicle (+2)
    mount_rad: tuple = (0.0, 0.0)                # known (initial) mounting pitch, yaw, rad
    mount_sigma: float = np.radians(2.0)         # its initial σ
    nhc_lever_b: np.ndarray = field(default_factory=lambda: np.zeros(3))  # IMU -> rear axle, RFU
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
            # consumer MEMS: 1 % scale factors (BMI160 sheet) are estimated (21 states)
            "consumer": dict(arw=np.radians(0.007), vrw=180e-6 * 9.80665, gyro_bias_sigma=np.radians(1.0),
                             accel_bias_sigma=0.2, gyro_bias_instability=np.radians(10.0) / 3600,
                             accel_bias_instability=5e-4, instability_tau=30, scale_factors=True,
                             # a weaker NHC while the 1 °/s gyro biases leave the heading loose:
                             # at 0.3 m/s it held a wrong heading on a simulated stop-and-go drive
                             nhc_sigma=0.5),
        }
        if g not in presets:
            raise SelfnavError(f"unknown grade '{grade}' (use {', '.join(presets)} or consumer-car)")
        d = presets[g]
        d.update(kw)
        return cls(**d)


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
        self.imt = slice(self.nx, self.nx + 2) if cfg.mount_states else None
        self.nx += 2 if cfg.mount_states else 0
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.sg = np.zeros(3)
        self.sa = np.zeros(3)
        self.mu = np.array(cfg.mount_rad, dtype=float)   # IMU pitch, yaw relative to the vehicle
        P = np.zeros((self.nx, self.nx))
        P[IR, IR] = np.eye(3) * cfg.init_pos_sigma**2
        P[IV, IV] = np.eye(3) * cfg.init_vel_sigma**2
        P[IP, IP] = np.diag(np.square(cfg.init_att_sigma))
        P[IBG, IBG] = np.eye(3) * cfg.gyro_bias_sigma**2
        P[IBA, IBA] = np.eye(3) * cfg.accel_bias_sigma**2
        if cfg.scale_factors:
            P[ISG, ISG] = np.eye(3) * cfg.gyro_sf_sigma**2
            P[ISA, ISA] = np.eye(3) * cfg.accel_sf_sigma**2
        if cfg.mount_states:
            P[self.imt, self.imt] = np.eye(2) * cfg.mount_sigma**2
        self.P = P
        self._f_n = np.array([0.0, 0.0, 9.8])
        self._w_b = np.zeros(3)
        self._f_b = np.array([0.0, 0.0, 9.8])
        self._Phi_acc = np.eye(self.nx)  # transition since the last stored epoch (smoother)
        self._n_corr = 0
        self._I = np.eye(self.nx)
        self._I3 = np.eye(3)

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
        F[0, 3] = F[1, 4] = F[2, 5] = 1.0
        F[IV, IP] = _skew(f_n)
        F[IV, IV] = -_skew(2 * w_ie + w_en)
        F[IV, IBA] = -C_bn
        g = float(normal_gravity(lat, h))
        F[5, 2] = 2.0 * g / (np.sqrt(rm * rn))
        F[IP, IP] = -_skew(w_ie + w_en)
        F[IP, IBG] = C_bn
        if np.isfinite(cfg.gyro_bias_tau):
            F[IBG, IBG] = -self._I3 / cfg.gyro_bias_tau
        if np.isfinite(cfg.accel_bias_tau):
            F[IBA, IBA] = -self._I3 / cfg.accel_bias_tau
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
        Phi = self._I + F * h + 0.5 * (F @ F) * h * h
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
        if self.cfg.scale_factors:
            self.sg -= dx[ISG]
            self.sa -= dx[ISA]
        if self.imt is not None:
            self.mu -= dx[self.imt]

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
        """Non-holonomic constraint: the vehicle's lateral and vertical velocity are zero.

        At the point ``nhc_lever_b`` (rear-axle centre) and in the vehicle frame rotated from
        the IMU's by the mounting angles μ (estimated with ``mount_states``)::

            v_v = exp([μ×]) (C_nb v^n + ω_b × l),    z = (v_v,R, v_v,U) = 0
            ∂v_v/∂δv = C_vb C_nb,  ∂v_v/∂ψ = −C_vb C_nb [v^n×],  ∂v_v/∂δμ = −[v_v×] (cols x, z)
        """
        C_nb = self.ins.C_nb
        v = self.ins.velocity_n
        vv = C_nb @ v
        C_vn = C_nb
        lever = self.cfg.nhc_lever_b
        if lever[0] or lever[1] or lever[2]:
            vv = vv + _skew(self._w_b) @ lever
        if self.imt is not None or self.mu[0] or self.mu[1]:
            C_vb = _rot(np.array([self.mu[0], 0.0, self.mu[1]]))
            C_vn = C_vb @ C_nb
            vv = C_vb @ vv
        H = np.zeros((2, self.nx))
        H[:, IV] = C_vn[[0, 2]]
        H[:, IP] = -C_vn[[0, 2]] @ _skew(v)
        if self.imt is not None:
            H[:, self.imt] = -_skew(vv)[[0, 2]][:, [0, 2]]
        cfg = self.cfg
        s_up = cfg.nhc_sigma if cfg.nhc_sigma_up is None else cfg.nhc_sigma_up
        R = np.diag([cfg.nhc_sigma**2, s_up**2])
        return self._kalman(vv[[0, 2]], H, R)

    def update_road(self, normal_n, offset, sigma, heading=None, sigma_heading=None):
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

        Returns the error-state correction (gated at χ² 0.999).
        """
        rows, res, var = [], [], []
        h = np.zeros(self.nx)
        h[0:2] = normal_n
        rows.append(h)
        res.append(offset)
        var.append(sigma**2)
        if heading is not None:
            _, _, hdg = att.euler_from_dcm_nb(self.ins.C_nb)
            h2 = np.zeros(self.nx)
            h2[8] = 1.0
            rows.append(h2)
            res.append(float(np.angle(np.exp(1j * (hdg - heading)))))
            var.append(sigma_heading**2)
        H = np.array(rows)
        r = np.array(res)
        R = np.diag(var)
        S = H @ self.P @ H.T + R
        if float(r @ np.linalg.solve(S, r)) > (CHI2_2_999 if len(r) == 2 else CHI2_1_999):
            return np.zeros(self.nx)
        return self._kalman(r, H, R)

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


def _lever_arm_n(self):
    return self.ins.C_nb.T @ self.cfg.lever_arm_b


InsGnssFilter.lever_arm_n = _lever_arm_n


def _pack(flt):
    s = flt.ins
    return np.concatenate([[s.lat, s.lon, s.h], s.velocity_n, s.C_nb.reshape(9), flt.bg, flt.ba,
                           flt.sg, flt.sa, flt.mu])


def _unpack(t, states, Ps):
    C = states[:, 6:15].reshape(-1, 3, 3)
    traj = Trajectory(t, states[:, 0], states[:, 1], states[:, 2], states[:, 3:6], C,
                      source="selfnav ekf")
    sig = np.sqrt(np.maximum(np.diagonal(Ps, axis1=1, axis2=2), 0.0))
    return traj, sig, states[:, 15:18], states[:, 18:21], states[:, 27:29]


def _apply_error(state, dx):
    """Remove an error-state estimate from a packed nominal state.

    The layout is told by the length of ``dx``: 15 (+6 scale factors) (+2 mounting angles).
    """
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
    if len(dx) >= 21:
        out[21:24] = state[21:24] - dx[ISG]
        out[24:27] = state[24:27] - dx[ISA]
    if len(dx) in (NX + 2, 23):
        out[27:29] = state[27:29] - dx[-2:]
    return out


def _rts(states, P_plus, P_minus, Phi, updates, breaks=None):
    """Rauch–Tung–Striebel smoother in error-state form over the stored epochs.

    Epoch k holds the corrected nominal state x̃⁺_k with covariance P⁺_k; ``Phi[k]`` carries the
    error from epoch k−1 to k, ``P_minus[k]`` is the covariance before epoch k's update and
    ``updates[k]`` the error estimate that update removed. With a reset after every update the
    filtered error of x̃⁺_k is zero, and the smoothed one is
    ``ε_k = A_k (updates[k+1] + ε_{k+1})``, ``A_k = P⁺_k Φ_{k+1}ᵀ (P⁻_{k+1})⁻¹`` (the error of
    the propagated state at k+1 is what its update removed plus what the smoother adds).

    ``breaks[k]``: epoch k's state was *replaced* (a reset to a dead-reckoning shadow,
    :mod:`selfnav.drguard`), not updated; nothing is carried back across it.
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
        out[k] = _apply_error(states[k], eps)
        eps_next = eps
    return out, Ps


__all__ = ["FilterConfig", "InsGnssFilter", "GnssData"]

# The batch and streaming drivers live in selfnav.insgnss (built on this module): resolved
# lazily so that either module can be imported first.
def __getattr__(name):
    if name in ("FilterResult", "StreamingNavigator", "init_from_gnss", "run_filter"):
        from selfnav import insgnss

        return getattr(insgnss, name)
    raise AttributeError(f"module 'selfnav.ekf' has no attribute '{name}'")
