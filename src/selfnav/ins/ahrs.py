"""Attitude from gyros, accelerometers and a magnetometer (an AHRS).

**Start** (the pieces live in :mod:`selfnav.ins.rest`, shared with the navigators; each works
on whatever window of samples it is given, so that it is causal):

* :func:`find_still` — stillness relative to the record's own noise floor (the quietest
  windows), not to absolute thresholds: a consumer IMU's stop is found although its noise is
  a hundred times a tactical unit's, and a gyro bias of 1 °/s does not count as motion (only
  the *variation* is tested, and the window means must agree with each other);
* :func:`level_at_rest` — roll and pitch from the mean specific force (DESIGN §2:
  ``up_b = (−sin γ cos θ, sin θ, cos γ cos θ)``), gyro bias from the mean rate, each with a σ
  that keeps the accelerometer bias (indistinguishable from tilt at rest: ``δθ = b_a/g``) and
  the unknown horizontal Earth rate;
* :func:`heading_from_magnetometer` — tilt-compensated heading
  (:func:`selfnav.sensors.magnetic_heading`, ``H = D + atan2(−m_x, m_y)`` of the levelled
  field) with a σ from the field's noise, the tilt σ through the inclination
  (``δH ≈ tan I · δθ``), the declination σ and a disturbance floor;
  :func:`declination_at` gives IGRF-14's declination.

**Filter** (:class:`Ahrs`): a 9-state error-state Kalman filter — attitude error ``φ`` in the
navigation frame (``C_b^n = (I + [φ×]) Ĉ_b^n``), gyro bias, accelerometer bias. The nominal
attitude is propagated sample by sample with the rate's rotation exponential (and the Earth
rate where the latitude is known); every ``1/update_hz`` s the mean of ``Ĉ_b^n (f_b − b̂_a)``
over the interval is compared with gravity (horizontal components,
``z = g [e_U×] φ + (Ĉ_b^n δb_a)_h``), with a noise that grows with the specific force's own
variation over the interval and with ``||f| − g|`` (a hand shaking the unit is not a tilt), and
the azimuth of the horizontal field ``Ĉ_b^n m_b`` with the declination
(``δa = φ_U − m_U (m_E φ_E + m_N φ_N)/B_h²``). One ``update(t, ω, f, m)`` per IMU row; a batch
run is that loop (:meth:`Ahrs.run`). Until it has started (still window found, or
``max_wait_s`` passed) it buffers the rows and then replays them, so everything it outputs
uses only the rows up to that time.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav import sensors
from selfnav.earth import earth_rate_n
from selfnav.types import ImuData

G0 = 9.80665
#: Smallest gyro noise density the filter assumes, rad/√s (a quantised gyro at rest can show
#: almost none; 0.0005 °/s/√Hz is a good tactical unit's).
GYRO_NOISE_FLOOR = math.radians(0.0005)


from selfnav.ins.rest import (IGRF_DECLINATION_SIGMA_DEG, MAG_FLOOR_DEG,  # noqa: F401
                              Levelling, Stillness, median_interval, declination_at, find_still,
                              heading_from_magnetometer, level_at_rest)

#: Correlation time given to the gyro scale/misalignment errors' attitude drift, s.
SCALE_CORRELATION_S = 1.0
#: Memory of the motion level the accelerometer updates allow for, s.
MOTION_TAU_S = 2.0
#: White noise of one magnetometer heading update, deg (the constant part is a state).
MAG_WHITE_DEG = 0.5
#: Correlation time of the field's azimuth error, s.
MAG_ERROR_TAU_S = 60.0
#: Largest difference of the measured and the expected (IGRF) dip that passes, deg.
MAX_DIP_MISMATCH_DEG = 5.0


# =========================================================================== the filter
@dataclass
class AhrsConfig:
    """Noise model and start-up settings of :class:`Ahrs` (SI, rad).

    Attributes
    ----------
    grade : sensor grade of :data:`selfnav.sensors.GRADES` for every value not given
    gyro_noise : rad/√s (rate noise density); None: measured at rest, else the grade's
    gyro_bias_sigma : rad/s, turn-on bias σ when no rest is found (grade's)
    gyro_bias_rw : rad/s/√s, bias random walk (from the grade's instability and time constant)
    accel_noise : m/s²/√Hz; accel_bias_sigma : m/s² (grade's); accel_bias_rw : m/s²/√s
    accel_motion_sigma : m/s², floor of the unmodelled acceleration in one update
    update_hz : accelerometer and magnetometer updates per second
    declination : rad (0: magnetic heading); sigma_declination : rad
    lat : rad or None (Earth rate removed where known)
    mag_floor_deg : σ of the measured field's azimuth error, deg (residual iron,
        disturbances: a constant state, considered, with a 60 s time constant)
    inclination : rad, the expected dip (IGRF) or None: a measured dip further than
        :data:`MAX_DIP_MISMATCH_DEG` from it raises the floor to the mismatch, with a warning
    use_mag : bool
    window_s, min_still_s, max_wait_s : start: stillness windows, the shortest rest that
        levels, the longest wait for one before starting in motion
    moving_tilt_sigma : rad, tilt σ of a start in motion
    gyro_scale_sigma : scale-factor and misalignment σ of the gyros (grade's): a turn of θ
        leaves ``σ θ`` of attitude error, modelled as process noise ``(σ |ω|)² · 1 s`` per s
    estimate_accel_bias : bool
        False (default): the accelerometer bias is a *considered* state (Schmidt–Kalman): its
        uncertainty is in every covariance (the tilt σ never falls below what the bias
        allows) but it is not estimated; with only gravity and a magnetometer it is hardly
        observable, and estimating it lets it wander along the tilt–bias null space (on the
        PX4 handheld log: 0.27 m/s², 1.1° of roll, in a minute at rest). True: estimated.
    """

    grade: str = "consumer"
    gyro_noise: float | None = None
    gyro_bias_sigma: float | None = None
    gyro_bias_rw: float | None = None
    accel_noise: float | None = None
    accel_bias_sigma: float | None = None
    accel_bias_rw: float | None = None
    accel_motion_sigma: float = 0.05
    update_hz: float = 10.0
    declination: float = 0.0
    sigma_declination: float = 0.0
    lat: float | None = None
    mag_floor_deg: float = MAG_FLOOR_DEG
    inclination: float | None = None
    use_mag: bool = True
    window_s: float = 0.25
    min_still_s: float = 0.75
    max_wait_s: float = 5.0
    moving_tilt_sigma: float = math.radians(10.0)
    estimate_accel_bias: bool = False
    gyro_scale_sigma: float | None = None

    def resolved(self) -> "AhrsConfig":
        """A copy with every ``None`` filled from the grade."""
        g = sensors.imu_grade(self.grade)
        gy, ac = g.gyro, g.accel
        out = AhrsConfig(**{k: getattr(self, k) for k in self.__dataclass_fields__})

        def rw(tr):
            tau = float(getattr(tr, "bias_tau", 0.0) or 0.0)
            bi = float(np.max(np.atleast_1d(getattr(tr, "bias_instability", 0.0))))
            rrw = float(np.max(np.atleast_1d(getattr(tr, "random_walk", 0.0) or 0.0)))
            gm = bi * math.sqrt(2.0 / tau) if tau > 0 else 0.0
            return math.hypot(gm, rrw)

        if out.gyro_noise is None:
            out.gyro_noise = float(np.max(np.atleast_1d(gy.white)))
        if out.gyro_bias_sigma is None:
            out.gyro_bias_sigma = float(np.max(np.atleast_1d(gy.bias)))
        if out.gyro_bias_rw is None:
            out.gyro_bias_rw = max(rw(gy), 1e-7)
        if out.accel_noise is None:
            out.accel_noise = float(np.max(np.atleast_1d(ac.white)))
        if out.accel_bias_sigma is None:
            # the bias and the cross-axis misalignment of gravity: both tilt a level unit
            out.accel_bias_sigma = math.hypot(float(np.max(np.atleast_1d(ac.bias))),
                                              float(np.max(np.atleast_1d(ac.misalignment)))
                                              * G0)
        if out.gyro_scale_sigma is None:
            out.gyro_scale_sigma = math.hypot(float(np.max(np.atleast_1d(gy.scale_factor))),
                                              float(np.max(np.atleast_1d(gy.misalignment))))
        if out.accel_bias_rw is None:
            out.accel_bias_rw = max(rw(ac), 1e-6)
        return out


@dataclass
class AhrsState:
    """What :meth:`Ahrs.update` returns: ``t``, ``C_nb`` (NaN before the start), the 1σ of
    roll, pitch and heading (rad), the biases and whether the filter has started."""

    t: float
    C_nb: np.ndarray
    sigma_rph: np.ndarray
    gyro_bias_b: np.ndarray
    accel_bias_b: np.ndarray
    started: bool


@dataclass
class AhrsResult:
    """A batch run (:meth:`Ahrs.run`): per IMU row ``t``, ``C_nb`` (NaN before the start),
    ``sigma_rph`` (N, 3) rad, the biases, and ``info`` (how it started: ``start`` ``"rest"``
    or ``"moving"``, ``t_start``, the levelling, the initial heading and σ, ``mag_updates``,
    ``accel_updates``)."""

    t: np.ndarray
    C_nb: np.ndarray
    sigma_rph: np.ndarray
    gyro_bias_b: np.ndarray
    accel_bias_b: np.ndarray
    info: dict = field(default_factory=dict)
    source: str = ""

    def euler(self):
        """``roll, pitch, heading`` (N,) rad."""
        return att.euler_from_dcm_nb(self.C_nb)

    def columns(self, step: int = 1) -> dict:
        """The attitude file's columns (DESIGN §6) plus σ, in degrees: every ``step``-th row
        from the start on."""
        ok = np.all(np.isfinite(self.C_nb.reshape(len(self.t), 9)), axis=1)
        idx = np.flatnonzero(ok)[::max(1, int(step))]
        r, p, h = att.euler_from_dcm_nb(self.C_nb[idx])
        s = np.degrees(self.sigma_rph[idx])
        return {"t": self.t[idx], "roll_deg": np.degrees(r), "pitch_deg": np.degrees(p),
                "heading_deg": np.degrees(h), "sigma_roll_deg": s[:, 0],
                "sigma_pitch_deg": s[:, 1], "sigma_heading_deg": s[:, 2]}


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _exp(rv):
    return att.rotvec_to_dcm3(rv)


class Ahrs:
    """Error-state attitude filter (module docstring): one :meth:`update` per IMU row.

    Parameters
    ----------
    config : AhrsConfig, optional
    """

    N = 10

    def __init__(self, config: AhrsConfig | None = None):
        config = config or AhrsConfig()
        self._gyro_noise_given = config.gyro_noise
        self.cfg = config.resolved()
        self.started = False
        self._buf: list = []
        self.C_bn = np.full((3, 3), np.nan)
        self.bg = np.zeros(3)
        self.ba = np.zeros(3)
        self.P = np.zeros((self.N, self.N))
        self.t = float("nan")
        self.info: dict = {"mag_updates": 0, "accel_updates": 0}
        self._acc = None
        self._last_dt = None
        self._mag_ref = None
        self._om_ie_n = None if self.cfg.lat is None else earth_rate_n(self.cfg.lat)
        self._mag_floor = self.cfg.mag_floor_deg
        self._zmean = None
        self._zvar = 0.0

    # ------------------------------------------------------------------ start
    def _try_start(self, final: bool = False) -> bool:
        buf = self._buf
        if len(buf) < 4:
            return False
        t = np.array([b[0] for b in buf])
        span = t[-1] - t[0]
        if span < self.cfg.min_still_s and not final:
            return False
        w = np.array([b[1] for b in buf])
        f = np.array([b[2] for b in buf])
        st = find_still(t, w, f, window_s=self.cfg.window_s)
        runs = st.stretches(t, self.cfg.min_still_s)
        dt = median_interval(t)
        mags = [b[3] for b in buf]
        have_mag = self.cfg.use_mag and all(m is not None for m in mags)
        if runs:
            i, j = runs[-1]                       # the latest rest: the least to replay
            lev = level_at_rest(f[i:j], w[i:j], dt=dt, accel_bias_sigma=self.cfg.accel_bias_sigma,
                                lat=self.cfg.lat)
            roll, pitch, s_tilt = lev.roll, lev.pitch, lev.sigma_roll
            bg, s_bg = lev.gyro_bias_b, np.maximum(lev.sigma_gyro_bias, 1e-7)
            start = "rest"
            meas = lev.gyro_noise * math.sqrt(dt)    # this unit's noise, measured at rest
            if self._gyro_noise_given is None and np.isfinite(meas) and meas > 0:
                self.cfg.gyro_noise = max(meas, GYRO_NOISE_FLOOR)
            k0 = j
            self.info["levelling"] = lev.to_dict()
            self._g = float(np.linalg.norm(lev.f_mean_b))
        elif final or span >= self.cfg.max_wait_s:
            i = max(0, len(buf) - max(4, int(round(1.0 / max(dt, 1e-6)))))
            j = len(buf)
            fm = f[i:j].mean(axis=0)
            up = fm / np.linalg.norm(fm)
            pitch = math.asin(max(-1.0, min(1.0, up[1])))
            roll = math.atan2(-up[0], up[2])
            s_tilt = self.cfg.moving_tilt_sigma
            bg = np.zeros(3)
            s_bg = np.full(3, self.cfg.gyro_bias_sigma)
            start = "moving"
            k0 = j
            self._g = G0
        else:
            return False
        self._mag_floor = self.cfg.mag_floor_deg
        if have_mag:
            self._check_inclination(np.array(mags[i:j]).mean(axis=0), roll, pitch)
            hd, s_h = heading_from_magnetometer(
                np.array(mags[i:j]), roll, pitch, declination=self.cfg.declination,
                sigma_tilt=s_tilt, sigma_declination=self.cfg.sigma_declination,
                floor_deg=self._mag_floor)
        else:
            hd, s_h = 0.0, math.pi
        self.C_bn = att.dcm_bn_from_euler(roll, pitch, hd)
        self.bg = np.array(bg, dtype=float)
        self.ba = np.zeros(3)
        P = np.zeros((self.N, self.N))
        # tilt: nav-frame E, N (the levelled tilt σ), heading about U
        P[0, 0] = P[1, 1] = s_tilt ** 2
        P[2, 2] = s_h ** 2
        P[3:6, 3:6] = np.diag(np.asarray(s_bg, float) ** 2)
        P[6:9, 6:9] = np.eye(3) * self.cfg.accel_bias_sigma ** 2
        # state 9: the azimuth error of the measured field (residual iron, declination): a
        # constant the updates cannot average away; the magnetic start heading carries it
        s_e = math.hypot(math.radians(self._mag_floor), self.cfg.sigma_declination)
        P[9, 9] = s_e ** 2
        if have_mag:
            P[2, 9] = P[9, 2] = -s_e ** 2
        if start == "rest":
            # at rest the tilt and the horizontal accelerometer bias are one unknown: the
            # levelled f_n = C_bn (f_true + b_a) is exactly up: z = 0 in _accel_update's model
            # gives φ_E = −(C_bn b_a)_N / g, φ_N = (C_bn b_a)_E / g
            Ch = self.C_bn[:2]
            J = np.zeros((2, 3))
            J[0] = -Ch[1] / self._g
            J[1] = Ch[0] / self._g
            Pb = P[6:9, 6:9]
            noise_tilt = (lev.accel_noise / math.sqrt(lev.samples) / self._g) ** 2
            P[0:2, 0:2] = J @ Pb @ J.T + np.eye(2) * noise_tilt
            P[0:2, 6:9] = J @ Pb
            P[6:9, 0:2] = (J @ Pb).T
        self.P = P
        self.started = True
        self.t = float(t[k0 - 1])
        self.info.update({"start": start, "t_start": self.t, "initial_heading_deg":
                          math.degrees(hd % (2 * math.pi)),
                          "initial_heading_sigma_deg": math.degrees(s_h),
                          "heading_source": "magnetometer" if have_mag else "none"})
        rest = buf[k0:]
        self._buf = []
        self._acc = None
        for row in rest:                         # replay: causal, only past rows
            self._step(*row)
        return True

    def _check_inclination(self, m_b, roll, pitch):
        """A dip far from the expected one: wrong axes, calibration or a disturbed field."""
        Rt = np.swapaxes(att.frame_rotation(1, roll) @ att.frame_rotation(0, pitch), -1, -2)
        ml = Rt @ np.asarray(m_b, float)
        dip = math.atan2(-ml[2], math.hypot(ml[0], ml[1]))
        self.info["measured_inclination_deg"] = math.degrees(dip)
        if self.cfg.inclination is None:
            return
        d = math.degrees(abs(dip - self.cfg.inclination))
        self.info["expected_inclination_deg"] = math.degrees(self.cfg.inclination)
        if d > MAX_DIP_MISMATCH_DEG:
            self._mag_floor = max(self._mag_floor, min(d, 90.0))
            from selfnav.errors import warn

            warn(f"the magnetometer's field dips {math.degrees(dip):.1f}° where IGRF says "
                 f"{math.degrees(self.cfg.inclination):.1f}°: its axes, calibration or "
                 f"surroundings are wrong; the magnetic heading σ is raised to {self._mag_floor:.0f}°")

    # ------------------------------------------------------------------ per sample
    def update(self, t: float, omega_b, f_b, mag_b=None) -> AhrsState:
        """One IMU row (interval means ending at ``t``, body RFU): propagate, and update from
        gravity and the magnetometer every ``1/update_hz`` s. Returns the state at ``t``."""
        row = (float(t), np.asarray(omega_b, float), np.asarray(f_b, float),
               None if mag_b is None else np.asarray(mag_b, float))
        if not self.started:
            self._buf.append(row)
            if not self._try_start():
                return AhrsState(row[0], np.full((3, 3), np.nan), np.full(3, np.nan),
                                 self.bg.copy(), self.ba.copy(), False)
        else:
            self._step(*row)
        return self.state()

    def state(self) -> AhrsState:
        return AhrsState(self.t, self.C_bn.T.copy(), self.sigma_rph(), self.bg.copy(),
                         self.ba.copy(), self.started)

    def sigma_rph(self) -> np.ndarray:
        """1σ of roll, pitch, heading (rad) from the nav-frame attitude covariance."""
        if not self.started:
            return np.full(3, np.nan)
        fwd = self.C_bn[:, 1]
        hd = math.atan2(fwd[0], fwd[1])
        c, s = math.cos(hd), math.sin(hd)
        T = np.array([[s, c], [c, -s]])            # rows: forward axis (roll), right axis (pitch)
        Pt = T @ self.P[0:2, 0:2] @ T.T
        return np.sqrt(np.array([Pt[0, 0], Pt[1, 1], self.P[2, 2]]))

    def _step(self, t, w, f, m):
        dt = t - self.t if np.isfinite(self.t) else 0.0
        if not dt > 0:
            dt = self._last_dt or 0.0
        if dt > 1.0:                               # a gap: the attitude is not known across it
            dt = 1.0
        self._last_dt = dt
        cfg = self.cfg
        wc = w - self.bg
        C = self.C_bn @ _exp(wc * dt)
        if self._om_ie_n is not None:
            C = _exp(-self._om_ie_n * dt) @ C
        self.C_bn = C
        # covariance: φ' = −C δb_g,  δb_a random walk
        F = np.eye(self.N)
        F[0:3, 3:6] = -C * dt
        Q = np.zeros((self.N, self.N))
        Q[0:3, 0:3] = np.eye(3) * (cfg.gyro_noise ** 2 + (cfg.gyro_scale_sigma * float(
            np.linalg.norm(wc))) ** 2 * SCALE_CORRELATION_S) * dt
        Q[3:6, 3:6] = np.eye(3) * cfg.gyro_bias_rw ** 2 * dt
        Q[6:9, 6:9] = np.eye(3) * cfg.accel_bias_rw ** 2 * dt
        Q[9, 9] = (math.radians(self._mag_floor) ** 2 * 2.0 / MAG_ERROR_TAU_S) * dt
        self.P = F @ self.P @ F.T + Q
        self.t = t
        # accumulate for the next update
        if self._acc is None:
            self._acc = {"t0": t - dt, "n": 0, "fn": np.zeros(3), "fn2": np.zeros(3),
                         "fnorm": 0.0, "C": np.zeros((3, 3)), "mn": [], "wmax": 0.0}
        a = self._acc
        fc = f - self.ba
        fn = C @ fc
        a["n"] += 1
        a["fn"] += fn
        a["fn2"] += fn * fn
        a["fnorm"] += float(np.linalg.norm(f))
        a["C"] += C
        a["wmax"] = max(a["wmax"], float(np.linalg.norm(wc)))
        if m is not None and cfg.use_mag and np.all(np.isfinite(m)):
            a["mn"].append(C @ m)
        if t - a["t0"] >= 1.0 / cfg.update_hz - 1e-9:
            self._accel_update(a)
            if a["mn"]:
                self._mag_update(a)
            self._acc = None

    # ------------------------------------------------------------------ updates
    def _correct(self, dx):
        self.C_bn = _exp(dx[0:3]) @ self.C_bn
        self.bg = self.bg + dx[3:6]
        self.ba = self.ba + dx[6:9]

    def _kalman(self, H, r, R, frozen=()):
        P = self.P
        S = H @ P @ H.T + R
        nis = float(r @ np.linalg.solve(S, r))
        dof = len(r)
        gate = {1: 10.8, 2: 13.8}.get(dof, 16.3)    # 99.9 %
        if nis > gate:                          # robust: inflate R until the NIS is at the gate
            R = R + (nis / gate - 1.0) * S
            S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T
        if not self.cfg.estimate_accel_bias:
            K[6:9] = 0.0                        # Schmidt: the bias is considered, not estimated
        K[9] = 0.0                              # the field's azimuth error: considered
        for i in frozen:
            K[i] = 0.0
        dx = K @ r
        IKH = np.eye(self.N) - K @ H
        self.P = IKH @ P @ IKH.T + K @ R @ K.T
        self._correct(dx)
        return nis

    def _accel_update(self, a):
        n = a["n"]
        fn = a["fn"] / n
        var = np.maximum(a["fn2"] / n - fn * fn, 0.0)
        g = self._g
        z = fn[:2]
        Cm = a["C"] / n
        H = np.zeros((2, self.N))
        H[0, 1] = -g                               # [e_U×] φ: (−φ_N, φ_E)
        H[1, 0] = g
        H[:, 6:9] = Cm[:2]
        dev = abs(a["fnorm"] / n - g)
        # the unit's own accelerations: their scatter from update to update over the last
        # MOTION_TAU_S (a walker's steps, a hand's shake), not only within one interval; a
        # constant tilt error shifts the mean, not the scatter
        w = min(1.0, (n * (self._last_dt or 0.01)) / MOTION_TAU_S)
        if self._zmean is None:
            self._zmean, self._zvar = z.copy(), 0.0
        d = z - self._zmean
        self._zmean = self._zmean + w * d
        self._zvar = (1.0 - w) * (self._zvar + w * float(d @ d) / 2.0)
        s_motion2 = (self.cfg.accel_motion_sigma ** 2 + float(var[:2].mean()) + (2.0 * dev) ** 2
                     + self._zvar)
        s_noise2 = self.cfg.accel_noise ** 2 / max(n * (self._last_dt or 0.01), 1e-9)
        R = np.eye(2) * (s_motion2 + s_noise2)
        self._kalman(H, z, R)
        self.info["accel_updates"] += 1

    def _mag_update(self, a):
        mn = np.array(a["mn"]).mean(axis=0)
        bh2 = mn[0] ** 2 + mn[1] ** 2
        if not bh2 > 0:
            return
        norm = float(np.linalg.norm(mn))
        if self._mag_ref is None:
            self._mag_ref = norm
        dev = abs(norm / self._mag_ref - 1.0)
        self._mag_ref = 0.99 * self._mag_ref + 0.01 * norm
        az = math.atan2(mn[0], mn[1])
        y = (az - self.cfg.declination + math.pi) % (2 * math.pi) - math.pi
        H = np.zeros((1, self.N))
        H[0, 0] = -mn[2] * mn[0] / bh2
        H[0, 1] = -mn[2] * mn[1] / bh2
        H[0, 2] = 1.0
        H[0, 9] = 1.0
        # white part of one update; a field whose strength changed is disturbed: its σ grows
        # with the change (the constant part is state 9)
        s2 = math.radians(MAG_WHITE_DEG) ** 2 + math.radians(self._mag_floor) ** 2 * (
            dev / 0.02) ** 2
        # the estimated frame reads the field at D + Hφ: y = Hφ + noise
        # the magnetometer corrects the heading (and the gyro biases) only: its tilt terms are
        # in S, but a disturbed field must not tilt the attitude (the tilt is gravity's)
        self._kalman(H, np.array([y]), np.array([[s2]]), frozen=(0, 1))
        self.info["mag_updates"] += 1

    # ------------------------------------------------------------------ batch
    def run(self, imu: ImuData, progress=None) -> AhrsResult:
        """Every row of ``imu`` through :meth:`update` (the batch is the loop)."""
        n = len(imu)
        C = np.full((n, 3, 3), np.nan)
        S = np.full((n, 3), np.nan)
        BG = np.full((n, 3), np.nan)
        BA = np.full((n, 3), np.nan)
        mag = imu.mag_b
        started_at = None
        for k in range(n):
            st = self.update(imu.t[k], imu.omega_ib_b[k], imu.f_ib_b[k],
                             None if mag is None else mag[k])
            if st.started:
                if started_at is None:
                    started_at = k
                    # the rows replayed at the start: their own states were not kept; the
                    # first output is at the row that completed the start
                C[k] = st.C_nb
                S[k] = st.sigma_rph
                BG[k] = st.gyro_bias_b
                BA[k] = st.accel_bias_b
            if progress is not None and k % 20000 == 0:
                progress(k / max(n, 1))
        if not self.started and len(self._buf):
            self._try_start(final=True)
        return AhrsResult(imu.t.copy(), C, S, BG, BA, dict(self.info), imu.source)


def run_ahrs(imu: ImuData, config: AhrsConfig | None = None) -> AhrsResult:
    """:class:`Ahrs` over a whole record."""
    return Ahrs(config).run(imu)
