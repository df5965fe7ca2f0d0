"""Running the INS/GNSS filter: the epochs, the outlier defence, streaming and batch use.

:class:`StreamingNavigator` takes IMU samples and GNSS fixes as they arrive (``add_imu``,
``add_gnss``) and processes every epoch once the IMU stream has passed it: the aiding epochs
(non-holonomic constraint or zero-velocity update, a road constraint), the GNSS fixes, any
heading measurements and odometer samples (``add_odometer``), in the order (time, kind). :func:`run_filter` is the batch call: it
feeds a whole record through the same class, so both give identical results.

Each fix, in this order (DESIGN §7, §10):

1. **Its own consistency** (:class:`~selfnav.ins.guard.FixChain`): linked to the previous fix
   through the GNSS velocity, and *anchored* when that chain reaches back to a used fix.
2. **Against the INS**: a soft χ² gate on the horizontal part (up to ``soft_gate × gate``
   with R inflated, Huber-like) and a separate one on the height; the window test (its
   displacement from the previous fixes must agree with the INS displacement); the shadow
   dead reckoning (:class:`~selfnav.ins.guard.DeadReckoningGuard`).
3. **Who is wrong**: an anchored fix the INS rejects is evidence against the INS: its
   covariance is widened until the fix fits and the fix is used (the gate is not widened).
   Otherwise a rejected fix counts towards *suspect* mode: the filter dead-reckons, uses white
   outliers with their own robust scale (``degraded``), and re-acquires when a window of
   fixes is self-consistent and moves like the dead reckoning.
4. **The consistent parts**: the horizontal and vertical parts are accepted separately, and
   the GNSS velocity (where the file has it) has its own gate: a fix whose position is
   rejected may still give a good height or velocity.
5. **Noise from the data**: trusted fixes drive the process-noise scale
   (:class:`~selfnav.ins.calibrate.NoiseAdapter`).

Every fix is logged (status, reason, NIS): :attr:`FilterResult.fix_log`.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav.earth import enu_offset, offset_to_geodetic
from selfnav.errors import SelfnavError
from selfnav.ins.align import init_from_gnss
from selfnav.ins.calibrate import NoiseAdapter
from selfnav.ins.config import CHI2_1_999, CHI2_2_999, FilterConfig
from selfnav.ins.ekf import (IBA, IBG, IP, IR, IV, PACK, InsGnssFilter, nis, pack_state,
                             rts_smooth, unpack_states)
from selfnav.ins.guard import (DeadReckoningGuard, FixChain, kinematic_consistent,
                               track_agrees, white_scale, window_consistent)
from selfnav.types import GnssData, Trajectory
from selfnav.units import G0

#: per-fix status codes of the fix log and the solution rows
STATUS = {-1: "before-init", 0: "rejected", 1: "used", 2: "used-h", 3: "used-v",
          4: "degraded", 5: "suspect"}
#: a solution row more than this many seconds after the last fix has GNSS status "none"
STATUS_HOLD_S = 2.0


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
    fix_status: np.ndarray        # 1 accepted (any part), 0 rejected, -1 before initialisation
    innovations: np.ndarray       # (M, 3) ENU, m (NaN before init)
    nis: np.ndarray
    mode: np.ndarray              # per fix: 0 normal, 1 suspect
    smoothed: bool = False
    stats: dict = field(default_factory=dict)
    mounting: np.ndarray | None = None   # (N, 2) IMU pitch, yaw to the vehicle, rad
    lever_arm: np.ndarray | None = None  # (N, 3) IMU → antenna, body RFU, m
    time_offset: np.ndarray | None = None  # (N,) residual IMU time offset, s
    gnss_status: np.ndarray | None = None  # (N,) str: the last fix's status at each row
    fix_log: dict | None = None   # per fix: t, status, reason, nis_h, nis_v, nis_vel, anchored
    odometer_scale: np.ndarray | None = None  # (N,) odometer scale-factor error estimate

    @property
    def sigma_h(self) -> np.ndarray:
        """Horizontal position σ (root sum of the East and North variances), m."""
        return np.hypot(self.sigma_enu[:, 0], self.sigma_enu[:, 1])


def _still(imu_w, imu_f, C_nb, veh):
    """ZUPT detector on one aiding block: small rates, steady |f|, no horizontal acceleration.

    An IMU cannot tell rest from constant velocity, so the caller also asks for a slow INS.
    """
    if len(imu_w) < 3:
        return False
    f_n = C_nb.T @ imu_f.mean(0)
    return (np.max(np.linalg.norm(imu_w, axis=1)) < veh.zupt_gyro
            and np.std(np.linalg.norm(imu_f, axis=1)) < veh.zupt_accel
            and np.hypot(f_n[0], f_n[1]) < veh.zupt_accel_h)


@dataclass
class _Fix:
    t: float
    lat: float
    lon: float
    h: float
    sigma_h: float
    sigma_v: float
    sigma_file: float
    velocity_n: np.ndarray | None
    sigma_vel: float
    quality: int | None


class StreamingNavigator:
    """Streaming INS/GNSS filter (see the module docstring).

    Parameters
    ----------
    cfg : FilterConfig
    init : dict
        ``t, lat, lon, h, velocity_n, C_nb`` and optionally ``sigmas`` (position, velocity,
        attitude σ triples) or ``P``, ``gyro_bias`` and ``gyro_bias_sigma``.
    road_aid : callable, optional
        ``road_aid(t, flt) -> None | dict`` (see :func:`run_filter`).
    record : bool
        Keep every epoch for :meth:`result`.
    smoother : bool
        Also keep what the RTS smoother needs (covariances, transitions, corrections); without
        it only the state and the error-state variances are kept (faster, less memory).

    Notes
    -----
    Fixes must be added before the IMU stream passes their time stamp (a late fix is applied
    at the next epoch, which batch processing would not do).
    """

    def __init__(self, cfg: FilterConfig, init: dict, *, road_aid=None, record: bool = True,
                 smoother: bool = True):
        self.cfg = cfg
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
        if "tilt_bias_map" in init:
            # levelled on biased accelerometers: tilt and horizontal bias are one error
            # (:func:`selfnav.ins.align.levelling_map`)
            A = np.asarray(init["tilt_bias_map"], dtype=float)
            Pb = flt.P[IBA, IBA].copy()
            flt.P[IP, IP] += A @ Pb @ A.T
            flt.P[IP, IBA] = A @ Pb
            flt.P[IBA, IP] = (A @ Pb).T
        if "gyro_bias" in init:
            flt.bg = np.array(init["gyro_bias"], dtype=float)
            flt.P[IBG, IBG] = np.diag(np.square(init["gyro_bias_sigma"]))
        flt.q_scale = float(init.get("q_scale", 1.0))
        self.flt = flt
        self.t0 = t0
        self.road_aid = road_aid
        self.record = record
        self.smoother = smoother
        self._n_aid = 1
        self._events = []          # heap of (t, kind, seq, k)
        self._seq = 0
        self._buf_t, self._buf_w, self._buf_f, self._buf_dt = [], [], [], []
        self._t_last = None
        self.fixes: list[_Fix] = []
        self.log = {k: [] for k in ("t", "status", "reason", "nis_h", "nis_v", "nis_vel",
                                    "anchored")}
        self.innov, self.mode = [], []
        self.headings = []
        self.odometer = []         # (speed m/s, σ or None) of each odometer sample
        self._t_odo = -np.inf
        self.rec = {k: [] for k in ("t", "state", "P", "Pm", "Phi", "dx", "brk", "q")}
        self._reset = False        # the state was replaced at this epoch (smoother break)
        self._widened = None       # covariance added at this epoch without a measurement
        self.suspect = False
        self.rejections = self.streak = self.degraded = self.reacq = self.ins_widened = 0
        self.sus, self.win = [], []
        self.disp = np.zeros(3)  # INS displacement by propagation only, ENU m
        robust = cfg.outliers.robust
        self.guard = DeadReckoningGuard(cfg) if (robust and cfg.shadows.use_shadows) else None
        self.chain = FixChain() if robust else None
        self.adapter = NoiseAdapter(cfg.shadows.sigma_scale) if cfg.imu.adapt else None
        self._block = None         # the last IMU block (t, dθ, dv) for the shadows
        self._still = False
        self._drag = None          # shadow that rejected a fix the filter accepted
        self._t_suspect = None
        self._guarded = False
        self._last_used = False
        self._last_status = (-np.inf, -1)   # (t, code) of the last fix processed
        self._lost_since = None    # fixes fit one track but not the INS since this time
        self.reinits = 0

    # ------------------------------------------------------------------ input
    def add_gnss(self, t, lat, lon, h, sigma_h=np.nan, velocity_n=None, *, sigma_v=np.nan,
                 sigma_vel=np.nan, quality=None):
        """A fix (rad, rad, m; σ horizontal per axis and vertical, m; ENU velocity and its σ
        per axis, m/s; the receiver's quality flag). Returns its index."""
        g = self.cfg.gnss
        s = sigma_h if np.isfinite(sigma_h) else g.default_sigma
        if g.sigma_h is not None:
            s = g.sigma_h
        s = max(s, g.sigma_floor)
        if g.sigma_v is not None:
            sv = g.sigma_v
        elif np.isfinite(sigma_v):
            sv = max(sigma_v, g.sigma_floor * g.vertical_ratio)
        else:
            sv = g.vertical_ratio * s
        svel = max(sigma_vel if np.isfinite(sigma_vel) else g.velocity_sigma, g.velocity_floor)
        vel = None
        if velocity_n is not None and np.all(np.isfinite(np.asarray(velocity_n)[:2])):
            vel = np.asarray(velocity_n, dtype=float)
        k = len(self.fixes)
        s_file = sigma_h if np.isfinite(sigma_h) else g.default_sigma
        self.fixes.append(_Fix(float(t), float(lat), float(lon), float(h), s, sv, s_file, vel, svel,
                               None if quality is None else int(quality)))
        for key, v in (("t", float(t)), ("status", -1), ("reason", "before initialisation"),
                       ("nis_h", np.nan), ("nis_v", np.nan), ("nis_vel", np.nan),
                       ("anchored", False)):
            self.log[key].append(v)
        self.innov.append(np.full(3, np.nan))
        self.mode.append(0)
        if t > self.t0:
            self._push(t, 0, k)
        return k

    def add_heading(self, t, heading, sigma):
        """A true-heading measurement (rad), e.g. magnetic heading plus declination."""
        self.headings.append((float(heading), float(sigma)))
        if t > self.t0:
            self._push(t, 2, len(self.headings) - 1)

    def add_odometer(self, t, speed, sigma=None):
        """A wheel-speed sample (forward speed at the rear axle, m/s; σ default
        ``vehicle.odometer_sigma``), needs ``states.odometer``. Samples closer than
        ``vehicle.odometer_step`` to the previous one are skipped."""
        if t <= self.t0 or t - self._t_odo < self.cfg.vehicle.odometer_step - 1e-9:
            return
        if self.flt.layout.odo is None:
            raise SelfnavError("odometer samples need the scale-factor state (states.odometer)")
        self._t_odo = float(t)
        self.odometer.append((float(speed), sigma))
        self._push(t, 3, len(self.odometer) - 1)

    def _push(self, t, kind, k):
        heapq.heappush(self._events, (float(t), kind, self._seq, k))
        self._seq += 1

    def add_imu(self, t, omega_ib_b, f_ib_b):
        """IMU samples (scalar time or arrays): rates and specific force, mean over the
        interval ending at ``t``. Processes every epoch the stream has now passed."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        w = np.atleast_2d(np.asarray(omega_ib_b, dtype=float))
        f = np.atleast_2d(np.asarray(f_ib_b, dtype=float))
        prev = self._t_last
        dt = np.diff(np.concatenate([[t[0] - (t[1] - t[0] if len(t) > 1 else 0.01)
                                      if prev is None else prev], t]))
        if np.any(dt <= 0):
            raise SelfnavError("IMU samples must have increasing times")
        keep = t > self.t0
        t, w, f, dt = t[keep], w[keep], f[keep], dt[keep]
        if not len(t):
            self._t_last = None if prev is None else prev
            return
        i = 0
        while True:
            te = self._next_event_time()
            if te >= t[-1]:
                break
            j = int(np.searchsorted(t, te, side="right"))
            self._append(t[i:j], w[i:j], f[i:j], dt[i:j])
            i = j
            self._process_next()
        self._append(t[i:], w[i:], f[i:], dt[i:])
        self._t_last = float(t[-1])

    def _append(self, t, w, f, dt):
        if len(t):
            self._buf_t.append(t)
            self._buf_w.append(w)
            self._buf_f.append(f)
            self._buf_dt.append(dt)

    def _next_event_time(self):
        ta = self.t0 + self.cfg.vehicle.aid_step * self._n_aid
        return min(ta, self._events[0][0]) if self._events else ta

    def finish(self):
        """Process the epochs up to the last IMU sample and propagate to it."""
        if self._t_last is None:
            return
        while True:
            te = self._next_event_time()
            if te > self._t_last + 1e-9:
                break
            self._process_next()
        if self._buf_t:
            self._predict()
            self._store(self._t_last, self.flt.P.copy(), np.zeros(self.flt.nx))

    # ------------------------------------------------------------------ epochs
    def _predict(self):
        flt = self.flt
        t = np.concatenate(self._buf_t)
        w = np.concatenate(self._buf_w)
        f = np.concatenate(self._buf_f)
        dt = np.concatenate(self._buf_dt)
        self._buf_t, self._buf_w, self._buf_f, self._buf_dt = [], [], [], []
        s = flt.ins.state_array()
        p0 = (s[0], s[1], s[2])
        dth, dv = w * dt[:, None], f * dt[:, None]
        flt.predict(t, dth, dv)
        self._block = (t, dth, dv)
        self.disp += enu_offset(*p0, s[0], s[1], s[2])
        return w, f

    def _store(self, te, Pm, dx):
        if not self.record:
            self.flt.take_transition()
            self._widened, self._reset = None, False
            return
        r = self.rec
        r["t"].append(te)
        r["state"].append(pack_state(self.flt))
        r["q"].append(self._row_status(te))
        if not self.smoother:
            r["P"].append(np.diag(self.flt.P).copy())
            self._widened, self._reset = None, False
            return
        r["P"].append(self.flt.P.copy())
        # covariance added without a measurement is process noise: part of the prior
        r["Pm"].append(Pm if self._widened is None else Pm + self._widened)
        self._widened = None
        r["Phi"].append(self.flt.take_transition())
        r["dx"].append(dx)
        r["brk"].append(self._reset)
        self._reset = False

    def _row_status(self, te):
        if self.suspect:
            return 5
        t_fix, code = self._last_status
        return code if te - t_fix <= STATUS_HOLD_S else -2

    def _process_next(self):
        cfg = self.cfg
        ta = self.t0 + cfg.vehicle.aid_step * self._n_aid
        if self._events and (self._events[0][0], self._events[0][1]) < (ta, 1):
            te, kind, _, k = heapq.heappop(self._events)
        else:
            te, kind, k = ta, 1, -1
            self._n_aid += 1
        flt = self.flt
        if self._buf_t:
            w_blk, f_blk = self._predict()
        else:
            w_blk = f_blk = np.zeros((0, 3))
        Pm = flt.P.copy() if self.smoother else None
        dx = np.zeros(flt.nx)
        veh = cfg.vehicle
        if kind == 1:
            # still IMU *and* a slow INS: constant velocity also looks still to an IMU
            v_max = max(veh.zupt_speed,
                        veh.zupt_speed_sigmas * float(np.sqrt(flt.P[3, 3] + flt.P[4, 4])))
            self._still = bool(veh.zupt and np.linalg.norm(flt.ins.velocity_n) < v_max
                               and _still(w_blk - flt.bg, f_blk - flt.ba, flt.ins.C_nb, veh))
        if self.guard is not None and self._block is not None:
            self.guard.predict(*self._block, self._still)
            self._block = None
        if kind == 1:
            if self._still:
                dx = flt.update_zupt()
            elif veh.nhc:
                dx = flt.update_nhc()
            if self.road_aid is not None:
                meas = self.road_aid(te, flt)
                if meas is not None:
                    dx = dx + flt.update_road(**meas)
        elif kind == 2:
            dx = flt.update_heading(*self.headings[k])
        elif kind == 3:
            dx = flt.update_odometer(*self.odometer[k])
        else:
            dx = self._fix(k)
        if self.guard is not None:
            self.guard.maintain(te, flt, trusted=not self.suspect and self.rejections == 0,
                                suspect=self.suspect)
        self._store(te, Pm, dx)

    # ------------------------------------------------------------------ one fix
    def _chain(self, k):
        """(linked, anchored) of fix k against the previous fixes (GNSS only)."""
        fx = self.fixes[k]
        if self.chain is None:
            return False, False
        p = enu_offset(self.fixes[0].lat, self.fixes[0].lon, 0.0, fx.lat, fx.lon, 0.0)
        v = None if fx.velocity_n is None else fx.velocity_n[:2]
        out = self.chain.add(fx.t, p[:2], v, fx.sigma_file, fx.sigma_vel, self._last_used,
                             fx.quality)
        return out

    def _log(self, k, code, reason, **vals):
        self.log["status"][k] = code
        self.log["reason"][k] = reason
        for key, v in vals.items():
            self.log[key][k] = v
        self._last_status = (self.fixes[k].t, code)

    def _fix(self, k):
        flt, cfg, fx = self.flt, self.cfg, self.fixes[k]
        out = cfg.outliers
        linked, anchored = self._chain(k)
        r, H = flt.position_residual(fx.lat, fx.lon, fx.h)
        self.innov[k] = -r
        veto = getattr(self.road_aid, "fix_veto", None)
        veto = veto(fx.t, fx.lat, fx.lon, fx.sigma_file, flt) if veto is not None else None
        if veto:
            return self._vetoed(k, veto)
        R = np.diag([fx.sigma_h**2, fx.sigma_h**2, fx.sigma_v**2])
        S = H @ flt.P @ H.T + R
        nis_h = float(r[:2] @ np.linalg.solve(S[:2, :2], r[:2]))
        nis_v = float(r[2] ** 2 / S[2, 2])
        dx = np.zeros(flt.nx)
        reason = ""
        # soft gate: a fix a little beyond the χ² gate is used with R inflated by NIS/gate
        # (Huber-like): real model errors are not Gaussian, outliers of 200 m are far beyond
        soft = out.robust and np.hypot(r[0], r[1]) <= max(out.soft_gate_max_m,
                                                          out.soft_gate_sigmas * fx.sigma_h)
        gate_h = CHI2_2_999 * (out.soft_gate if soft else 1.0)
        ok = nis_h <= gate_h
        if not ok:
            reason = f"χ² gate (NIS {nis_h:.3g})"
        ok_v = nis_v <= CHI2_1_999 * (out.soft_gate if soft else 1.0)
        guard = self.guard
        if guard is not None:
            guard.last_chi2 = []
        shadow_rej = None if (guard is None or self.suspect) else guard.rejects(
            fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, self._shadow_scale())
        win_ok = True
        if out.robust:
            self.win = (self.win + [(k, self.disp.copy())])[-out.window:]
            s_vel = float(np.sqrt(np.trace(flt.P[IV, IV]) / 3.0)) + out.window_vel_floor
            if self.suspect:
                ok, reason, dx = self._suspect_fix(k, r, H, R, ok, s_vel)
            elif len(self.win) > 1:
                win_ok = window_consistent(self.win, self.fixes, s_vel, s_acc=self._s_acc(flt))
                if ok and not win_ok:
                    ok, reason = False, "window test"
            if not self.suspect and shadow_rej is not None:
                # a fix the dead reckoning cannot explain; if the filter took it, it is
                # being dragged (guard)
                self._drag = shadow_rej if ok else self._drag
                if ok:
                    reason = "shadow dead reckoning"
                ok = False
        # who is wrong: fixes that agree with each other and with their own velocity back to
        # a used fix are evidence against the INS — widen the INS, not the gate
        if not ok and anchored and out.robust:
            self._widen_to_fit(r, H, R, k)
            ok, reason = True, "INS widened (fixes anchored by their velocity)"
            self.suspect = False
            self._drag = None
            self.sus = []
        self.mode[k] = int(self.suspect)
        vals = dict(nis_h=nis_h, nis_v=nis_v, anchored=bool(anchored))
        if ok:
            trusted = anchored or not self.suspect
            if self.adapter is not None and trusted:
                self._adapt(fx, nis_h)
            rows = [0, 1, 2] if ok_v else [0, 1]
            Rk = R * max(1.0, nis_h / CHI2_2_999)
            dx = flt.kalman(r[rows], H[rows], Rk[np.ix_(rows, rows)])
            code = 1 if ok_v else 2
            self._log(k, code, reason or ("" if ok_v else "height rejected"), **vals)
            self.rejections = self.streak = 0
            self.suspect = False
            self.sus = []
            self._drag = None
            self._last_used = True
        else:
            self._last_used = False
            self.rejections += 1
            if ok_v and not self.suspect and not np.any(dx):
                # the horizontal part is rejected, the height agrees: use the height alone
                # (not while dead-reckoning: a drifting receiver's height drifts too)
                dx = flt.kalman(r[2:], H[2:], R[2:, 2:])
                self._log(k, 3, reason, **vals)
            elif np.any(dx):
                self._log(k, 4, reason or "degraded (white outliers, robust scale)", **vals)
            else:
                self._log(k, 0, reason or "rejected", **vals)
            if out.robust and self.rejections >= out.suspect_after and not self.suspect:
                self._enter_suspect(fx.t)
        if fx.velocity_n is not None and cfg.gnss.use_velocity:
            dx = dx + self._velocity(k)
        return dx

    def _vetoed(self, k, reason):
        """A fix the road aid objects to (:meth:`selfnav.roads.aid.EkfRoadAid.fix_veto`):
        rejected like one the gates reject, and it may neither re-acquire nor re-initialise."""
        out = self.cfg.outliers
        if out.robust:
            self.win = (self.win + [(k, self.disp.copy())])[-out.window:]
        self._last_used = False
        self.rejections += 1
        self.streak = 0
        self._lost_since = None       # the map holds the INS: not lost
        self._log(k, 0, reason)
        if out.robust and self.rejections >= out.suspect_after and not self.suspect:
            self._enter_suspect(self.fixes[k].t)
        self.mode[k] = int(self.suspect)
        return np.zeros(self.flt.nx)

    def _velocity(self, k):
        """The fix's velocity, gated on its own (a position outlier may carry a good velocity)."""
        flt, fx = self.flt, self.fixes[k]
        v = fx.velocity_n
        r, H = flt.velocity_residual(v if np.isfinite(v[2]) else np.r_[v[:2], 0.0])
        rows = [0, 1, 2] if np.isfinite(v[2]) else [0, 1]
        R = np.eye(len(rows)) * fx.sigma_vel**2
        if np.isfinite(v[2]):
            R[2, 2] = (fx.sigma_vel * self.cfg.gnss.vertical_ratio) ** 2
        q = nis(flt.P, H[rows], R, r[rows])
        self.log["nis_vel"][k] = q
        gate = (CHI2_1_999 + CHI2_2_999) if len(rows) == 3 else CHI2_2_999
        if q > gate:
            return np.zeros(flt.nx)
        return flt.kalman(r[rows], H[rows], R)

    def _widen_to_fit(self, r, H, R, k):
        """Raise the position/velocity/attitude covariance until fix ``k`` passes the gate."""
        flt = self.flt
        d = r[:2]
        S = (H @ flt.P @ H.T)[:2, :2] + R[:2, :2]
        q = float(d @ np.linalg.solve(S, d))
        target = 0.5 * CHI2_2_999
        if q > target:
            k_up = q / target
            add = np.zeros_like(flt.P)
            for sl in (IR, IV, IP):
                add[sl, sl] = flt.P[sl, sl] * (k_up - 1.0)
            flt.P += add
            self._widened = add if self._widened is None else self._widened + add
        self.ins_widened += 1
        if self.adapter is not None:
            self.adapter.on_fix(flt, q, 2)

    def _adapt(self, fx, nis_h):
        ad = self.adapter
        ad.on_fix(self.flt, nis_h, 2)
        if self.guard is not None:
            for c in self.guard.last_chi2:      # this fix against each mature shadow
                ad.on_shadow(c, 2)

    def _shadow_scale(self):
        return (self.cfg.shadows.sigma_scale if self.adapter is None
                else self.adapter.shadow_scale)

    def _enter_suspect(self, t):
        flt, guard = self.flt, self.guard
        self.suspect = True
        self._t_suspect = t
        # the strict re-acquisition protects a converged filter with a dead-reckoning
        # reference; one that never got there (started inside an outlier window) may
        # itself be the lost one: the window test alone takes GNSS back, as before
        self._guarded = guard is not None and bool(guard.shadows_mature(t))
        if guard is not None:
            # dragged before the rejections began? back to the shadow it left
            drag = self._drag or guard.dragged(t, flt, self._shadow_scale())
            if drag is not None and guard.reset_to(drag, flt):
                self.win = []
                self._reset = True
            else:
                add = guard.widen(t, flt)
                if add is not None:
                    self._widened = add if self._widened is None else self._widened + add
            self._drag = None

    @staticmethod
    def _s_acc(flt):
        """Horizontal acceleration error σ the covariance allows, m/s²: a levelling error
        (g ψ_E, g ψ_N) and the accelerometer bias. Large just after an in-motion alignment
        with a pessimistic prior; centimetres per s² once converged."""
        P = flt.P
        g = G0
        tilt = g * g * 0.5 * (P[IP, IP][0, 0] + P[IP, IP][1, 1])
        bias = np.trace(P[IBA, IBA]) / 3.0
        return float(np.sqrt(max(tilt + bias, 0.0)))

    def _suspect_fix(self, k, r, H, R, ok, s_vel):
        """A fix in suspect mode: re-acquire, or use white outliers with their robust scale."""
        flt, cfg, fx = self.flt, self.cfg, self.fixes[k]
        out = cfg.outliers
        reason = "" if ok else "χ² gate while dead-reckoning"
        dx = np.zeros(flt.nx)
        self.sus = [x for x in self.sus + [(fx.t, -r)] if x[0] > fx.t - out.degraded_window]
        win_ok = (len(self.win) >= out.window
                  and window_consistent(self.win, self.fixes, s_vel, trend=self._guarded))
        self.streak = self.streak + 1 if win_ok else 0
        # no dead-reckoning reference when it went suspect, or an outage longer than any
        # outlier episode: a self-consistent run is taken back as before the guard
        long_out = not self._guarded or fx.t - self._t_suspect > cfg.shadows.max_suspect
        if win_ok and not long_out:
            # a smooth drift is self-consistent too: it must also move like the dead
            # reckoning and sit within its uncertainty (the gate) to be taken back
            run = self.sus[-(self.streak + out.window - 1):]
            moves = track_agrees([x[0] for x in run], [x[1][:2] for x in run], fx.sigma_h,
                                 flt.P[3:5, 3:5], cfg.shadows.fit_sigma)
            # outside the dead reckoning's uncertainty only after a long run that moves like
            # it (the dead reckoning itself may be lost): a drift changes its rate
            long_run = moves and run[-1][0] - run[0][0] >= cfg.shadows.reacq_run
            if not moves:
                reason = "moves unlike the dead reckoning"
            win_ok = moves and (ok or long_run)
        elif not win_ok:
            reason = reason or "window test while dead-reckoning"
        # the INS itself lost? the recent fixes fit one smooth track by themselves, but not the
        # INS displacement, for reinit_after seconds: re-initialise from them — unless a
        # dead-reckoning reference (a mature shadow when it went suspect) says that smooth track
        # is a drift (then only after an outage longer than any outlier episode)
        if long_out and not win_ok and len(self.win) >= out.window and self._fixes_smooth(fx.t):
            self._lost_since = fx.t if self._lost_since is None else self._lost_since
            if fx.t - self._lost_since >= out.reinit_after and self._reinit(fx.t):
                return True, "INS lost: re-initialised from the fixes", np.zeros(flt.nx)
        else:
            self._lost_since = None
        if win_ok and not ok and self.streak >= out.window:
            # a long run of self-consistent fixes that the dead reckoning cannot explain: its
            # drift exceeded P. After a long dead reckoning the velocity and heading are as
            # suspect as the position: start them again from the run; else widen P
            if long_out and fx.t - self._t_suspect > out.reinit_after \
                    and self._fixes_smooth(fx.t) and self._reinit(fx.t):
                self.reacq += 1
                return True, "re-acquired: re-initialised from the fixes", np.zeros(flt.nx)
            add = np.zeros_like(flt.P)
            add[IR, IR] = np.diag(r * r)
            flt.P += add
            self._widened = add if self._widened is None else self._widened + add
            self.reacq += 1
            return True, "re-acquired (P widened to the offset)", dx
        if not win_ok:
            # degraded mode: white outliers still carry information. Their scale from
            # fix-to-fix differences (which cancel the slow dead-reckoning drift) against
            # their scale about the median: equal for white noise, much smaller for a
            # drifting (correlated) error, which is not used.
            s_eff = white_scale(self.sus, out)
            if s_eff is not None and s_eff > out.degraded_min_ratio * fx.sigma_h:
                R_d = np.diag([s_eff**2, s_eff**2, (1.5 * s_eff) ** 2])
                if nis(flt.P, H, R_d, r) <= out.gate:
                    dx = flt.kalman(r, H, R_d)
                    self.degraded += 1
            return False, reason, dx
        return ok, reason, dx

    def _recent(self, t, span):
        fx = [f for f in self.fixes[max(0, len(self.fixes) - 400):] if t - span <= f.t <= t]
        p = np.array([enu_offset(self.fixes[0].lat, self.fixes[0].lon, self.fixes[0].h,
                                 f.lat, f.lon, f.h) for f in fx]) if fx else np.zeros((0, 3))
        return fx, p

    def _fixes_smooth(self, t):
        fx, p = self._recent(t, self.cfg.outliers.reinit_span)
        return len(fx) >= 6 and kinematic_consistent([f.t for f in fx], p[:, :2],
                                                     [f.sigma_h for f in fx])

    def _reinit(self, t):
        """Position, velocity and heading from the recent fixes (a line fit); roll, pitch and
        the sensor estimates kept; the covariance of what was reset opened up."""
        flt, cfg = self.flt, self.cfg
        fx, p = self._recent(t, cfg.outliers.reinit_span)
        tt = np.array([f.t for f in fx]) - t
        A = np.column_stack([np.ones(len(tt)), tt])
        coef, *_ = np.linalg.lstsq(A, p, rcond=None)
        s = float(np.max([f.sigma_h for f in fx]))
        cov = np.linalg.inv(A.T @ A) * s * s
        v = coef[1]
        speed = float(np.hypot(v[0], v[1]))
        sv = float(np.sqrt(cov[1, 1]))
        if speed < max(cfg.init.min_speed, 4.0 * sv):
            return False          # the course is not known yet: wait for motion
        f0 = self.fixes[0]
        lat, lon, h = offset_to_geodetic(f0.lat, f0.lon, f0.h, coef[0])
        roll, pitch, _ = att.euler_from_dcm_nb(flt.ins.C_nb)
        heading = float(np.arctan2(v[0], v[1]))
        flt.ins.set_state(lat=float(lat), lon=float(lon), h=float(h),
                          velocity_n=np.array([v[0], v[1], 0.0]),
                          C_nb=att.dcm_nb_from_euler(roll, pitch, heading))
        P = flt.P
        old = P.copy()
        for sl in (IR, IV, IP):
            P[sl, :] = 0.0
            P[:, sl] = 0.0
        P[IR, IR] = np.diag([cov[0, 0], cov[0, 0], (cfg.gnss.vertical_ratio * s) ** 2 * 2])
        P[IV, IV] = np.diag([sv * sv, sv * sv, 1.0])
        P[IP, IP] = np.diag([np.radians(3.0) ** 2, np.radians(3.0) ** 2,
                             (sv / speed) ** 2 + np.radians(5.0) ** 2])
        self._reset = True
        self.suspect = False
        self.win, self.sus = [], []
        self.streak = self.rejections = 0
        self._lost_since = None
        self.reinits += 1
        if self.guard is not None:
            self.guard.shadows = []
        del old
        return True

    # ------------------------------------------------------------------ output
    def result(self, smooth: bool = False) -> "FilterResult":
        """The recorded epochs as a :class:`FilterResult` (RTS-smoothed on request)."""
        r = self.rec
        t = np.asarray(r["t"])
        states = np.asarray(r["state"])
        Ps = np.asarray(r["P"])
        smoothed = False
        if smooth and not self.smoother:
            raise SelfnavError("this navigator kept no smoother record (smoother=False)")
        if smooth and len(t) > 2:
            states, Ps = rts_smooth(states, Ps, np.asarray(r["Pm"]), np.asarray(r["Phi"]),
                                    np.asarray(r["dx"]), self.flt.layout,
                                    np.asarray(r["brk"], bool))
            smoothed = True
        # several epochs can share a time (a fix and an aiding epoch): keep the last state
        last = np.r_[np.diff(t) > 1e-6, True] if len(t) else np.zeros(0, bool)
        t, states, Ps = t[last], states[last], Ps[last]
        q = np.asarray(r["q"], int)[last] if len(r["q"]) else np.zeros(0, int)
        traj, sig = unpack_states(t, states, Ps)
        lay = self.flt.layout
        st = np.asarray(self.log["status"], int)
        codes = {**STATUS, -2: "none"}
        stats = {"fixes": len(st), "accepted": int(np.sum(st >= 1) - np.sum(st == 4)),
                 "rejected": int(np.sum((st == 0) | (st == 4))),
                 "before_init": int(np.sum(st == -1)),
                 "height_only": int(np.sum(st == 3)), "horizontal_only": int(np.sum(st == 2)),
                 "reacquisitions": self.reacq, "degraded_updates": self.degraded,
                 "shadow_resets": 0 if self.guard is None else self.guard.alarms,
                 "ins_widened": self.ins_widened, "reinitialisations": self.reinits,
                 "noise_scale": float(self.flt.q_scale),
                 "bias_noise_scale": float(self.flt.bias_scale),
                 "shadow_sigma_scale": float(self._shadow_scale()),
                 "shadow_variance_ratio": (None if self.adapter is None or not self.adapter.dr_samples
                                           else float(self.adapter.dr_ratio))}
        fix_log = {k: np.asarray(v) for k, v in self.log.items()}
        fix_log["status"] = np.array([STATUS[c] for c in st], dtype=object)
        return FilterResult(
            traj, sig[:, IR], sig[:, IV], sig[:, IP], states[:, PACK["bg"]],
            states[:, PACK["ba"]], np.asarray(self.log["t"]), np.where(st >= 1, 1, np.minimum(st, 0)),
            np.asarray(self.innov).reshape(-1, 3), np.asarray(self.log["nis_h"]),
            np.asarray(self.mode, int), smoothed, stats,
            states[:, PACK["mu"]] if lay.mu is not None else None,
            states[:, PACK["lever"]] if lay.lever is not None else None,
            states[:, PACK["toff"]][:, 0] if lay.toff is not None else None,
            np.array([codes[c] for c in q], dtype=object), fix_log,
            states[:, PACK["odo"]][:, 0] if lay.odo is not None else None)


def concatenate_results(results) -> FilterResult:
    """One :class:`FilterResult` from the results of consecutive segments (an IMU gap between
    each): epochs and fixes joined in time order, the counts summed."""
    if len(results) == 1:
        return results[0]

    def cat(name):
        xs = [getattr(r, name) for r in results]
        return None if any(x is None for x in xs) else np.concatenate(xs)

    tr = [r.trajectory for r in results]
    traj = Trajectory(np.concatenate([x.t for x in tr]), np.concatenate([x.lat for x in tr]),
                      np.concatenate([x.lon for x in tr]), np.concatenate([x.h for x in tr]),
                      np.concatenate([x.velocity_n for x in tr]),
                      np.concatenate([x.C_nb for x in tr]), tr[0].source)
    stats = {}
    for r in results:
        for k, v in r.stats.items():
            stats[k] = stats[k] + v if k in stats and isinstance(v, (int, float)) else v
    log = {k: np.concatenate([r.fix_log[k] for r in results]) for k in results[0].fix_log}
    return FilterResult(traj, cat("sigma_enu"), cat("sigma_vel"), cat("sigma_att"),
                        cat("gyro_bias"), cat("accel_bias"), cat("fix_t"), cat("fix_status"),
                        cat("innovations"), cat("nis"), cat("mode"), results[0].smoothed, stats,
                        cat("mounting"), cat("lever_arm"), cat("time_offset"),
                        cat("gnss_status"), log, cat("odometer_scale"))


def output_trajectory(res: FilterResult, *, antenna: bool = False) -> Trajectory:
    """The trajectory at true time: the INS state of stamp ``t`` is the truth at ``t + ε̂``
    (the estimated residual time offset), so each row's position is moved back by
    ``v^n ε̂``; with ``antenna`` it is the GNSS antenna's, ``+ C_b^n l̂`` (the estimated lever
    arm at each epoch). Velocity and attitude are the IMU's."""
    tr = res.trajectory
    d = np.zeros((len(tr.t), 3))
    if antenna and res.lever_arm is not None:
        d += np.einsum("nji,nj->ni", tr.C_nb, res.lever_arm)      # C_bn l = C_nbᵀ l
    if res.time_offset is not None:
        d -= tr.velocity_n * res.time_offset[:, None]
    if not np.any(d):
        return tr
    lat, lon, h = offset_to_geodetic(tr.lat, tr.lon, tr.h, d)
    return Trajectory(tr.t, lat, lon, h, tr.velocity_n, tr.C_nb,
                      tr.source + (" (antenna)" if antenna else ""))


def fixes_sigma(gnss: GnssData, cfg: FilterConfig) -> np.ndarray:
    """The horizontal σ the filter believes for each fix (file σ or default, override, floor)."""
    n = len(gnss.t)
    s = gnss.sigma_m if gnss.sigma_m is not None else np.full(n, np.nan)
    s = np.where(np.isfinite(s), s, cfg.gnss.default_sigma)
    if cfg.gnss.sigma_h is not None:
        s = np.full(n, cfg.gnss.sigma_h)
    return np.maximum(s, cfg.gnss.sigma_floor)


def run_filter(imu, gnss: GnssData, cfg: FilterConfig | None = None, *, init=None,
               smooth: bool = False, heading=None, road_aid=None, progress=None,
               odometer=None) -> "FilterResult":
    """Run the loosely coupled filter over a whole record (batch call).

    Parameters
    ----------
    imu : ImuData
        Rates (mean over each interval ending at ``t``) in body RFU.
    gnss : GnssData
    cfg : FilterConfig
    init : dict, optional
        ``lat, lon, h, velocity_n, C_nb, t`` to start from (e.g. truth or a static alignment);
        default: the in-motion alignment from the first trusted fixes (:func:`init_from_gnss`).
    smooth : bool
        Run the RTS smoother backwards over the stored epochs.
    heading : (t, heading_rad, sigma_rad), optional
        Heading measurements (magnetometer + declination).
    road_aid : callable, optional
        Called at every aiding epoch as ``road_aid(t, flt)`` with the
        :class:`~selfnav.ins.ekf.InsGnssFilter`; returns ``None`` or a dict of
        :meth:`~selfnav.ins.ekf.InsGnssFilter.update_road` arguments (a map matcher that knows
        which road the vehicle is on).
    progress : callable(fraction), optional
    odometer : OdometerData, optional
        Wheel speed on the IMU's clock (needs ``cfg.states.odometer``).
    """
    cfg = cfg or FilterConfig()
    n = len(gnss.t)
    if init is None:
        init = init_from_gnss(imu, gnss, cfg, fixes_sigma(gnss, cfg))
    nav = StreamingNavigator(cfg, init, road_aid=road_aid, smoother=smooth)

    def col(x, k):
        return np.nan if x is None else x[k]

    for k in range(n):
        nav.add_gnss(gnss.t[k], gnss.lat[k], gnss.lon[k], gnss.h[k], col(gnss.sigma_m, k),
                     None if gnss.velocity_n is None else gnss.velocity_n[k],
                     sigma_v=col(gnss.sigma_v_m, k), sigma_vel=col(gnss.sigma_vel_mps, k),
                     quality=None if gnss.quality is None else gnss.quality[k])
    if heading is not None:
        for k in range(len(heading[0])):
            nav.add_heading(heading[0][k], heading[1][k], heading[2][k])
    if odometer is not None:
        for t_o, v_o in zip(odometer.t.tolist(), odometer.speed_mps.tolist()):
            nav.add_odometer(t_o, v_o)
    chunks = np.array_split(np.arange(len(imu.t)), max(1, len(imu.t) // 20000))
    for c, idx in enumerate(chunks):
        nav.add_imu(imu.t[idx], imu.omega_ib_b[idx], imu.f_ib_b[idx])
        if progress is not None:
            progress((c + 1) / len(chunks))
    nav.finish()
    return nav.result(smooth)
