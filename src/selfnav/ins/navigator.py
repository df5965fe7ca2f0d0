"""Running the INS/GNSS filter: initialisation, the outlier defence, streaming and batch use.

:class:`StreamingNavigator` takes IMU samples and GNSS fixes as they arrive (``add_imu``,
``add_gnss``) and processes every epoch once the IMU stream has passed it: the aiding epochs
(non-holonomic constraint or zero-velocity update, a road constraint), the GNSS fixes and any
heading measurements, in the order (time, kind). :func:`run_filter` is the batch call: it
feeds a whole record through the same class, so both give identical results.

The outlier defence (DESIGN §7; see :mod:`selfnav.ins.ekf`): each fix passes a soft χ² gate
(up to ``soft_gate × gate`` with R inflated, Huber-like) *and* the window test: its
displacement from the previous fix must agree with the INS displacement by propagation
(``disp``; the corrections of updates are not motion). After ``suspect_after`` rejections the
filter is *suspect*: it dead-reckons, uses white outliers with their own robust scale
(``degraded``), and re-acquires when a window of fixes is self-consistent.
"""
from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np

from selfnav.earth import enu_offset
from selfnav.ins.align import init_from_gnss
from selfnav.ins.config import FilterConfig
from selfnav.ins.guard import DeadReckoningGuard, track_agrees, white_scale, window_consistent
from selfnav.ins.ekf import (IBG, IP, IR, IV, InsGnssFilter, pack_state,
                         rts_smooth, unpack_states)
from selfnav.errors import SelfnavError
from selfnav.types import GnssData
from selfnav.types import Trajectory

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
    mounting: np.ndarray | None = None   # (N, 2) IMU pitch, yaw to the vehicle, rad (mount_states)



def _still(imu_w, imu_f, C_nb, cfg):
    """ZUPT detector on one aiding block: small rates, steady |f|, no horizontal acceleration.

    An IMU cannot tell rest from constant velocity, so the caller also asks for a slow INS.
    """
    if len(imu_w) < 3:
        return False
    f_n = C_nb.T @ imu_f.mean(0)
    return (np.max(np.linalg.norm(imu_w, axis=1)) < cfg.vehicle.zupt_gyro
            and np.std(np.linalg.norm(imu_f, axis=1)) < cfg.vehicle.zupt_accel
            and np.hypot(f_n[0], f_n[1]) < cfg.vehicle.zupt_accel_h)


class _FixStore:
    """The fixes seen so far (lists indexed like the input)."""

    def __init__(self):
        self.t, self.lat, self.lon, self.h, self.vel = [], [], [], [], []


class StreamingNavigator:
    """Streaming INS/GNSS filter (see the module docstring).

    Parameters
    ----------
    cfg : FilterConfig
    init : dict
        ``t, lat, lon, h, velocity_n, C_nb`` and optionally ``sigmas`` (position, velocity,
        attitude σ triples) or ``P``.
    road_aid : callable, optional
        ``road_aid(t, flt) -> None | dict`` (see :func:`run_filter`).
    record : bool
        Keep every epoch for :meth:`result` (and the smoother).

    Notes
    -----
    Fixes must be added before the IMU stream passes their time stamp (a late fix is applied
    at the next epoch, which batch processing would not do).
    """

    def __init__(self, cfg: FilterConfig, init: dict, *, road_aid=None, record: bool = True):
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
        if "gyro_bias" in init:
            flt.bg = np.array(init["gyro_bias"], dtype=float)
            flt.P[IBG, IBG] = np.diag(np.square(init["gyro_bias_sigma"]))
        self.flt = flt
        self.t0 = t0
        self.road_aid = road_aid
        self.record = record
        self._n_aid = 1
        self._events = []          # heap of (t, kind, seq, k)
        self._seq = 0
        self._buf_t, self._buf_w, self._buf_f, self._buf_dt = [], [], [], []
        self._t_last = None
        self.fixes = _FixStore()
        self.sig_h, self.sig_v = [], []
        self.status, self.innov, self.nis, self.mode = [], [], [], []
        self.headings = []
        self.rec = {k: [] for k in ("t", "state", "P", "Pm", "Phi", "dx", "brk")}
        self._reset = False        # the state was replaced at this epoch (smoother break)
        self._widened = None       # covariance added at this epoch without a measurement
        self.suspect = False
        self.rejections = self.streak = self.degraded = self.reacq = 0
        self.sus, self.win = [], []
        self.disp = np.zeros(3)  # INS displacement by propagation only, ENU m
        self.guard = DeadReckoningGuard(cfg) if (cfg.outliers.robust and cfg.shadows.use_shadows) else None
        self._block = None         # the last IMU block (t, dθ, dv) for the shadows
        self._still = False
        self._drag = None          # shadow that rejected a fix the filter accepted
        self._t_suspect = None
        self._guarded = False

    # ------------------------------------------------------------------ input
    def add_gnss(self, t, lat, lon, h, sigma_h=np.nan, velocity_n=None):
        """A fix (rad, rad, m; σ horizontal per axis, m). Returns its index."""
        cfg = self.cfg
        s = sigma_h if np.isfinite(sigma_h) else 5.0
        if cfg.gnss.sigma_h is not None:
            s = cfg.gnss.sigma_h
        s = max(s, cfg.gnss.sigma_floor)
        k = len(self.fixes.t)
        f = self.fixes
        f.t.append(float(t))
        f.lat.append(float(lat))
        f.lon.append(float(lon))
        f.h.append(float(h))
        f.vel.append(None if velocity_n is None else np.asarray(velocity_n, dtype=float))
        self.sig_h.append(s)
        self.sig_v.append(cfg.gnss.sigma_v if cfg.gnss.sigma_v is not None else 1.5 * s)
        self.status.append(-1)
        self.innov.append(np.full(3, np.nan))
        self.nis.append(np.nan)
        self.mode.append(0)
        if t > self.t0:
            self._push(t, 0, k)
        return k

    def add_heading(self, t, heading, sigma):
        """A true-heading measurement (rad), e.g. magnetic heading plus declination."""
        self.headings.append((float(heading), float(sigma)))
        if t > self.t0:
            self._push(t, 2, len(self.headings) - 1)

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
        p0 = (flt.ins.lat, flt.ins.lon, flt.ins.h)
        flt.predict(t, w * dt[:, None], f * dt[:, None])
        self._block = (t, w * dt[:, None], f * dt[:, None])
        self.disp += enu_offset(*p0, flt.ins.lat, flt.ins.lon, flt.ins.h)
        return w, f

    def _store(self, te, Pm, dx):
        if not self.record:
            self.flt.take_transition()
            self._widened, self._reset = None, False
            return
        r = self.rec
        r["t"].append(te)
        r["state"].append(pack_state(self.flt))
        r["P"].append(self.flt.P.copy())
        # covariance added without a measurement is process noise: part of the prior
        r["Pm"].append(Pm if self._widened is None else Pm + self._widened)
        self._widened = None
        r["Phi"].append(self.flt.take_transition())
        r["dx"].append(dx)
        r["brk"].append(self._reset)
        self._reset = False

    def _process_next(self):
        ta = self.t0 + self.cfg.vehicle.aid_step * self._n_aid
        if self._events and (self._events[0][0], self._events[0][1]) < (ta, 1):
            te, kind, _, k = heapq.heappop(self._events)
        else:
            te, kind, k = ta, 1, -1
            self._n_aid += 1
        flt, cfg = self.flt, self.cfg
        if self._buf_t:
            w_blk, f_blk = self._predict()
        else:
            w_blk = f_blk = np.zeros((0, 3))
        Pm = flt.P.copy()
        dx = np.zeros(flt.nx)
        if kind == 1:
            # still IMU *and* a slow INS: constant velocity also looks still to an IMU
            v_max = max(cfg.vehicle.zupt_speed, cfg.vehicle.zupt_speed_sigmas * float(np.sqrt(flt.P[3, 3] + flt.P[4, 4])))
            self._still = bool(cfg.vehicle.zupt and np.linalg.norm(flt.ins.velocity_n) < v_max
                               and _still(w_blk - flt.bg, f_blk - flt.ba, flt.ins.C_nb, cfg))
        if self.guard is not None and self._block is not None:
            self.guard.predict(*self._block, self._still)
            self._block = None
        if kind == 1:
            if self._still:
                dx = flt.update_zupt()
            elif cfg.vehicle.nhc:
                dx = flt.update_nhc()
            if self.road_aid is not None:
                meas = self.road_aid(te, flt)
                if meas is not None:
                    dx = dx + flt.update_road(**meas)
        elif kind == 2:
            dx = flt.update_heading(*self.headings[k])
        else:
            dx = self._fix(k)
        if self.guard is not None:
            self.guard.maintain(te, flt, trusted=not self.suspect and self.rejections == 0,
                                suspect=self.suspect)
        self._store(te, Pm, dx)

    def _fix(self, k):
        flt, cfg, fx = self.flt, self.cfg, self.fixes
        sh, sv_ = self.sig_h, self.sig_v
        r, H = flt.position_residual(fx.lat[k], fx.lon[k], fx.h[k])
        self.innov[k] = -r
        R = np.diag([sh[k] ** 2, sh[k] ** 2, sv_[k] ** 2])
        nis = float(r @ np.linalg.solve(H @ flt.P @ H.T + R, r))
        self.nis[k] = nis
        dx = np.zeros(flt.nx)
        # soft gate: a fix a little beyond the χ² gate is used with R inflated by NIS/gate
        # (Huber-like): real model errors are not Gaussian, outliers of 200 m are far beyond
        soft = cfg.outliers.robust and np.hypot(r[0], r[1]) <= max(cfg.outliers.soft_gate_max_m, 3.0 * sh[k])
        ok = nis <= cfg.outliers.gate * (cfg.outliers.soft_gate if soft else 1.0)
        guard = self.guard
        shadow_rej = None if (guard is None or self.suspect) else guard.rejects(
            fx.t[k], fx.lat[k], fx.lon[k], fx.h[k], sh[k], cfg.shadows.sigma_scale)
        if cfg.outliers.robust:
            # window test: displacements between fixes against the INS displacement, which stays
            # accurate when the absolute INS position has drifted (P cannot weaken it)
            self.win = (self.win + [(k, self.disp.copy())])[-cfg.outliers.window:]
            s_vel = float(np.sqrt(np.trace(flt.P[IV, IV]) / 3.0)) + 0.2
            if self.suspect:
                self.sus = [x for x in self.sus + [(fx.t[k], -r)]
                            if x[0] > fx.t[k] - cfg.outliers.degraded_window]
                win_ok = (len(self.win) >= cfg.outliers.window
                          and window_consistent(self.win, fx, sh, sv_, s_vel,
                                                 trend=self._guarded))
                self.streak = self.streak + 1 if win_ok else 0
                # no dead-reckoning reference when it went suspect, or an outage longer than
                # any outlier episode: a self-consistent run is taken back as before the guard
                long_out = not self._guarded or fx.t[k] - self._t_suspect > cfg.shadows.max_suspect
                if win_ok and not long_out:
                    # a smooth drift is self-consistent too: it must also move like the dead
                    # reckoning and sit within its uncertainty (the gate) to be taken back
                    run = self.sus[-(self.streak + cfg.outliers.window - 1):]
                    moves = track_agrees([x[0] for x in run], [x[1][:2] for x in run], sh[k],
                                         flt.P[3:5, 3:5], cfg.shadows.fit_sigma)
                    # outside the dead reckoning's uncertainty only after a long run that moves
                    # like it (the dead reckoning itself may be lost): a drift changes its rate
                    long_run = moves and run[-1][0] - run[0][0] >= cfg.shadows.reacq_run
                    win_ok = moves and (ok or long_run)
                if win_ok and not ok and self.streak >= cfg.outliers.window:
                    # a long run of self-consistent fixes that the dead reckoning cannot
                    # explain: its drift exceeded P; re-acquire by widening P to the offset
                    flt.P[IR, IR] += np.diag(r * r)
                    ok = True
                    self.reacq += 1
                elif not win_ok:
                    ok = False
                    # degraded mode: white outliers still carry information. Their scale from
                    # fix-to-fix differences (which cancel the slow dead-reckoning drift) against
                    # their scale about the median: equal for white noise, much smaller for a
                    # drifting (correlated) error, which is not used.
                    s_eff = white_scale(self.sus, cfg)
                    if s_eff is not None and s_eff > 3.0 * sh[k]:
                        R_d = np.diag([s_eff**2, s_eff**2, (1.5 * s_eff) ** 2])
                        if float(r @ np.linalg.solve(H @ flt.P @ H.T + R_d, r)) <= cfg.outliers.gate:
                            dx = flt._kalman(r, H, R_d)
                            self.degraded += 1
            elif len(self.win) > 1:
                ok = ok and window_consistent(self.win, fx, sh, sv_, s_vel)
            if not self.suspect and shadow_rej is not None:
                # a fix the dead reckoning cannot explain; if the filter took it, it is
                # being dragged (drguard)
                self._drag = shadow_rej if ok else self._drag
                ok = False
        self.mode[k] = int(self.suspect)
        if ok:
            dx = flt._kalman(r, H, R * max(1.0, nis / cfg.outliers.gate))
            self.status[k] = 1
            self.rejections = self.streak = 0
            self.suspect = False
            self.sus = []
            self._drag = None
        else:
            self.status[k] = 0
            self.rejections += 1
            if cfg.outliers.robust and self.rejections >= cfg.outliers.suspect_after and not self.suspect:
                self.suspect = True
                self._t_suspect = fx.t[k]
                # the strict re-acquisition protects a converged filter with a dead-reckoning
                # reference; one that never got there (started inside an outlier window) may
                # itself be the lost one: the window test alone takes GNSS back, as before
                self._guarded = guard is not None and bool(guard.shadows_mature(fx.t[k]))
                if guard is not None:
                    # dragged before the rejections began? back to the shadow it left
                    drag = self._drag or guard.dragged(fx.t[k], flt, cfg.shadows.sigma_scale)
                    if drag is not None and guard.reset_to(drag, flt):
                        self.win = []
                        self._reset = True
                    else:
                        self._widened = guard.widen(fx.t[k], flt)
                    self._drag = None
        if ok and cfg.gnss.use_velocity and fx.vel[k] is not None:
            dx = dx + flt.update_velocity(fx.vel[k], cfg.gnss.velocity_sigma)
        return dx

    # ------------------------------------------------------------------ output
    def result(self, smooth: bool = False) -> "FilterResult":
        """The recorded epochs as a :class:`FilterResult` (RTS-smoothed on request)."""
        r = self.rec
        t = np.asarray(r["t"])
        states = np.asarray(r["state"])
        Ps = np.asarray(r["P"])
        smoothed = False
        if smooth and len(t) > 2:
            states, Ps = rts_smooth(states, Ps, np.asarray(r["Pm"]), np.asarray(r["Phi"]),
                              np.asarray(r["dx"]), np.asarray(r["brk"], bool))
            smoothed = True
        # several epochs can share a time (a fix and an aiding epoch): keep the last state
        last = np.r_[t[1:] != t[:-1], True] if len(t) else np.zeros(0, bool)
        t, states, Ps = t[last], states[last], Ps[last]
        traj, sig, bg, ba, mount = unpack_states(t, states, Ps)
        st = np.asarray(self.status, int)
        stats = {"fixes": len(st), "accepted": int(np.sum(st == 1)),
                 "rejected": int(np.sum(st == 0)), "before_init": int(np.sum(st == -1)),
                 "reacquisitions": self.reacq, "degraded_updates": self.degraded,
                 "shadow_resets": 0 if self.guard is None else self.guard.alarms}
        return FilterResult(traj, sig[:, IR], sig[:, IV], sig[:, IP], bg, ba,
                            np.asarray(self.fixes.t), st, np.asarray(self.innov).reshape(-1, 3),
                            np.asarray(self.nis), np.asarray(self.mode, int), smoothed, stats,
                            mount if self.cfg.states.mount_states else None)


def run_filter(imu, gnss: GnssData, cfg: FilterConfig | None = None, *, init=None,
               smooth: bool = False, heading=None, road_aid=None, progress=None) -> "FilterResult":
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
    """
    cfg = cfg or FilterConfig()
    n = len(gnss.t)
    sig_file = gnss.sigma_m if gnss.sigma_m is not None else np.full(n, np.nan)
    if init is None:
        s = np.where(np.isfinite(sig_file), sig_file, 5.0)
        if cfg.gnss.sigma_h is not None:
            s = np.full(n, cfg.gnss.sigma_h)
        init = init_from_gnss(imu, gnss, cfg, np.maximum(s, cfg.gnss.sigma_floor))
    nav = StreamingNavigator(cfg, init, road_aid=road_aid)
    for k in range(n):
        nav.add_gnss(gnss.t[k], gnss.lat[k], gnss.lon[k], gnss.h[k], sig_file[k],
                     None if gnss.velocity_n is None else gnss.velocity_n[k])
    if heading is not None:
        for k in range(len(heading[0])):
            nav.add_heading(heading[0][k], heading[1][k], heading[2][k])
    chunks = np.array_split(np.arange(len(imu.t)), max(1, len(imu.t) // 20000))
    for c, idx in enumerate(chunks):
        nav.add_imu(imu.t[idx], imu.omega_ib_b[idx], imu.f_ib_b[idx])
        if progress is not None:
            progress((c + 1) / len(chunks))
    nav.finish()
    return nav.result(smooth)
