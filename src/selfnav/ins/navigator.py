"""The causal INS/GNSS navigator: :class:`Navigator` (DESIGN §9, §10; issues 18, 19).

One class, fed as the data arrive::

    nav = Navigator()                                 # the defaults of ``selfnav navigate``
    for each sample:   state = nav.add_imu(t, gyro_rad_s, accel_m_s2)       -> NavState
    for each fix:      decision = nav.add_fix(t, lat_deg, lon_deg, h_m)    -> FixDecision
    (wheel speed:      nav.add_odometer(t, speed_mps); magnetometer: nav.add_magnetometer)

Everything it outputs at time ``T`` depends on data up to ``T`` only; :func:`selfnav.navigate`
and the command line are loops over this class (``--smooth`` is the one step that looks ahead,
and says so). Inside, in order:

1. **Start-up** (:mod:`selfnav.ins.startup`): IMU samples and fixes are buffered until a start
   can be made from the past — the noise measured at rest, a run of healthy fixes, the
   in-motion alignment — then the buffer is replayed to catch up (rows start from then).
2. **Time**: the IMU stamps plus the time offset (applied + the filter's estimate) are true
   time; fixes, wheel speed and magnetometer samples are queued by true time and processed
   when the IMU reaches them, against the state at that instant (the lead of under one IMU
   sample is in the measurement model). Wheel speed and the magnetometer come on the IMU's
   clock (one logger): they are queued at their stamp plus the offset and compared with the
   INS at their own stamp, so the offset's error does not enter them. A fix that arrives
   after the IMU has passed it is processed at once, against the state extrapolated back.
3. **Epochs**: every ``vehicle.aid_step`` the vehicle constraints (NHC or ZUPT), the road aid;
   each fix through the fault-hypothesis bank (:mod:`selfnav.ins.hypotheses`), which decides
   (:class:`~selfnav.ins.policy.FixDecision`) and may reset the filter to a dead-reckoning
   reference; the GNSS velocity on its own gate; trusted fixes drive the noise scale
   (:class:`~selfnav.ins.calibrate.NoiseAdapter`).
4. **Rows** at a regular rate (``out_rate_hz``): the state at the last IMU sample at or before
   each row time, moved to that time (first order, under one sample), at the antenna when the
   lever arm is estimated, with σ, status and protection level.
"""
from __future__ import annotations

import collections
import heapq
import math
from dataclasses import dataclass, field, replace

import numpy as np

from selfnav import attitude as att
from selfnav.correlation import ar1_factor_of_time
from selfnav.earth import offset_to_geodetic
from selfnav.errors import SelfnavError
from selfnav.ins.calibrate import NoiseAdapter, vibration_level, vibration_scale
from selfnav.ins.config import FilterConfig
from selfnav.ins.ekf import (IBA, IBG, IP, IR, IV, PACK, PACK_SIZE, InsGnssFilter, apply_error,
                             output_covariance, pack_state, rts_smooth)
from selfnav.ins.headings import heading_hypotheses, split_heading
from selfnav.ins.hypotheses import FaultBank
from selfnav.ins.measurements import (ForwardSpeed, Heading, LevelRoad, NhcCheck, NonHolonomic,
                                      PositionFix,
                                      RunVelocity, VelocityFix, WheelSpeed, ZeroRate,
                                      ZeroVelocity, vehicle_velocity)
from selfnav.ins.policy import FixDecision, FixStatus, NavStatus, chi2_gate
from selfnav.ins.startup import StartUp
from selfnav.types import Trajectory
from selfnav.units import G0, wrap_pi

#: rows per second of the output (``--out-rate``): a car's 10 Hz
DEFAULT_OUT_RATE_HZ = 10.0

_KIND_FIX, _KIND_AID, _KIND_HEADING, _KIND_ODO = 0, 1, 2, 3
_STATUS_CODE = {s: i for i, s in enumerate(NavStatus)}
_PACK_LEVER = PACK["lever"]          # (a row's first 21 packed values: pos, vel, C, b_g, b_a)
assert PACK["ba"].stop == 21


@dataclass(frozen=True)
class NavState:
    """The navigator's state at one instant (degrees at the edge, DESIGN §2).

    Attributes
    ----------
    t : float
        True time, s.
    lat_deg, lon_deg, h_m : float
        WGS-84 position of the output point (the antenna when the lever arm is estimated).
    velocity_enu : (3,) m/s
    roll_deg, pitch_deg, heading_deg : float
    sigma_h_m : float
        Horizontal position σ (root sum of the East and North variances), m.
    status : NavStatus
    protection_level_m : float
        Horizontal protection level at the configured integrity risk, m.
    sigma_enu_m : (3,)
    decisions : tuple of FixDecision
        Decisions made while processing the call that returned this state (fixes queued
        earlier reach their decision here).
    """

    t: float
    lat_deg: float
    lon_deg: float
    h_m: float
    velocity_enu: np.ndarray
    roll_deg: float
    pitch_deg: float
    heading_deg: float
    sigma_h_m: float
    status: NavStatus
    protection_level_m: float = float("nan")
    sigma_enu_m: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    decisions: tuple = ()


@dataclass
class _Fix:
    t: float
    lat: float
    lon: float
    h: float
    sigma_h: float
    sigma_v: float
    velocity_n: np.ndarray | None
    sigma_vel: float
    sigma_vel_up: float
    quality: int | None
    index: int


@dataclass
class NavigatorResult:
    """Everything a run produced (the rows, their σ and status, the fix log, the episodes).

    ``trajectory`` and the per-row arrays are at the output rows; ``fix_log`` has one entry
    per fix (``t, status, reason, nis_h, nis_v, nis_vel, excluded``); ``stats`` the counts the
    command line prints.
    """

    trajectory: Trajectory
    sigma_enu: np.ndarray
    sigma_vel: np.ndarray
    sigma_att: np.ndarray
    status: np.ndarray
    protection_level: np.ndarray
    fix_log: dict
    episodes: list
    stats: dict
    smoothed: bool = False
    gyro_bias: np.ndarray | None = None    # (N, 3) rad/s, the estimate at each row
    accel_bias: np.ndarray | None = None   # (N, 3) m/s²

    @property
    def sigma_h(self) -> np.ndarray:
        return np.hypot(self.sigma_enu[:, 0], self.sigma_enu[:, 1])


def _still(w_blk, f_blk, flt, veh, widen: bool | str = False):
    """ZUPT detector on one aiding block: small rates, steady |f|, no horizontal acceleration
    (in each half of the block: a brake that turns into a pull-away inside one block keeps
    ``|f|`` and its mean is level).

    An IMU cannot tell rest from constant velocity, so the caller also asks for a slow INS.
    The rates and the levelled specific force are bias-corrected. ``widen``: what the filter
    does not know of its biases and tilt (3σ) widens the bounds — a consumer part 1.4° off in
    tilt and 0.5 °/s in yaw bias reads 0.14 m/s² and 0.6 °/s at rest. The zero angular-rate
    update takes the widened test (a straight cruise taken for rest turns no more than a stop);
    the zero-velocity update does not: at 0.5 m/s² of bound, a cruise at 5.6 m/s whose INS
    speed a Gauss–Markov fix window had dragged under 1 m/s was clamped to rest.
    ``widen="gyro"`` widens the rate bound only (the zero-velocity update's test).
    """
    if len(w_blk) < 3:
        return False
    slack_w = slack_f = 0.0
    if widen:
        d = flt.P.diagonal()
        slack_w = 3.0 * math.sqrt(max(d[IBG]))
    if widen is True:
        # the tilt (the attitude's first two) and the horizontal accelerometer biases
        slack_f = 3.0 * math.sqrt(9.81**2 * max(d[IP][:2]) + max(d[IBA][:2]))
    if not (np.max(np.linalg.norm(w_blk, axis=1)) < veh.zupt_gyro + slack_w
            and np.std(np.linalg.norm(f_blk, axis=1)) < veh.zupt_accel):
        return False
    # each half of the block level on its own (the block's mean, between them, is then too):
    # a brake that turns into a pull-away inside the block keeps |f| and averages to level
    h = len(f_blk) // 2
    C_bn = flt.ins.C_nb.T
    return max(math.hypot(*(C_bn @ half.mean(0))[:2]) for half in (f_blk[:h], f_blk[h:])) \
        < veh.zupt_accel_h + slack_f


def _speed_sigma(flt) -> float:
    """σ of the INS's horizontal speed, m/s."""
    return float(np.sqrt(max(flt.P[3, 3] + flt.P[4, 4], 0.0)))


def _braked_speed_bound(flt, veh) -> float:
    """The INS speed under which a still run braked into is rest: ``zupt_speed_sigmas`` of
    its speed σ, at most ``zupt_speed_cap``, at least ``zupt_speed``."""
    return max(veh.zupt_speed, min(veh.zupt_speed_sigmas * _speed_sigma(flt),
                                   veh.zupt_speed_cap))


def set_course_heading(flt, cov_v, sigma_course):
    """``flt``'s velocity and heading covariance for a heading taken from the course of its
    velocity (:func:`selfnav.ins.course.course_heading_covariance`): the horizontal velocity
    block and its correlation with ``ψ_U``, uncorrelated with the rest."""
    from selfnav.ins.course import course_heading_covariance

    C, cv, var = course_heading_covariance(flt.ins.velocity_n, cov_v, sigma_course)
    P = flt.P
    for k in (3, 4, 8):
        P[k, :] = 0.0
        P[:, k] = 0.0
    P[3:5, 3:5] = C
    P[3:5, 8] = P[8, 3:5] = cv
    P[8, 8] = var


def initial_filter(cfg: FilterConfig, init: dict, time_offset_applied: float = 0.0):
    """The error-state filter of a start ``init`` (true time ``t``, ``lat, lon, h, velocity_n,
    C_nb``; optionally ``sigmas`` (position, velocity, attitude σ triples), ``gyro_bias`` and
    its σ (or its 3×3 covariance ``gyro_bias_cov``), ``tilt_bias_map``: levelled on biased
    accelerometers, tilt and horizontal bias are one error,
    :func:`selfnav.ins.align.levelling_map`)."""
    flt = InsGnssFilter(cfg, float(init["t"]) - time_offset_applied, init["lat"], init["lon"],
                        init["h"], init["velocity_n"], init["C_nb"],
                        time_offset_applied=time_offset_applied)
    if "sigmas" in init:
        sp, sv, sa = init["sigmas"]
        flt.P[IR, IR] = np.diag(np.square(sp))
        flt.P[IV, IV] = np.diag(np.square(sv))
        flt.P[IP, IP] = np.diag(np.square(sa))
    if "course_cov" in init:
        # the heading was taken from the course of the velocity: one error, not two
        set_course_heading(flt, init["course_cov"], cfg.init.course_heading_sigma)
    if "tilt_bias_map" in init:
        A = np.asarray(init["tilt_bias_map"], dtype=float)
        Pb = flt.P[IBA, IBA].copy()
        flt.P[IP, IP] += A @ Pb @ A.T
        flt.P[IP, IBA] = A @ Pb
        flt.P[IBA, IP] = (A @ Pb).T
    if "gyro_bias" in init:
        flt.bg = np.array(init["gyro_bias"], dtype=float)
        flt.P[IBG, IBG] = (np.asarray(init["gyro_bias_cov"], float) if "gyro_bias_cov" in init
                           else np.diag(np.square(init["gyro_bias_sigma"])))
    if flt.layout.toff is not None:
        i = flt.layout.toff.start
        share = float(np.hypot(*np.asarray(init["velocity_n"], float)[:2]) * np.sqrt(flt.P[i, i]))
        if share > math.sqrt(max(flt.P[0, 0], flt.P[1, 1])):
            # the offset's share of the start's error is larger than the fixes' own: the
            # fixes that follow will see it (RTK: drive_0708); below (a 10 m receiver) the
            # correlation only opened a path for the road aid's along-track corrections into
            # the offset (simulated drives 2 → 114 m RMS, 3.9 → 10.7 m; stop 32)
            set_stamp_time(flt, init["velocity_n"], init.get("acceleration_n"))
    return flt


def set_stamp_time(flt, velocity_n, acceleration_n=None):
    """``flt``'s covariance for a start taken from the GNSS at a fix's time: its position
    and velocity carry the IMU time offset's error, ``δr = v δτ``, ``δv = a δτ`` (the
    fixes' model has ``H_τ = −v``, ``−a``: an INS started on the track at the wrong time is
    where the vehicle was ``δτ`` away). Without the correlation the first fixes, which agree
    with a start built from them whatever the offset, look like evidence of a small offset —
    drive_0708 with its IMU stamps 0.3 s off had the offset's σ at 0.06 s 3 s after the
    start, held there by the forward lever arm's prior alone."""
    i = flt.layout.toff.start
    J = np.zeros(flt.nx)
    J[IR] = np.asarray(velocity_n, float)
    if acceleration_n is not None:
        J[IV] = np.asarray(acceleration_n, float)
    c = flt.P[:, i].copy()
    flt.P += np.outer(J, c) + np.outer(c, J) + float(flt.P[i, i]) * np.outer(J, J)


class Navigator:
    """The causal INS/GNSS(/map) navigator (module docstring).

    Parameters
    ----------
    config : FilterConfig, optional
        The full configuration; default :func:`selfnav.ins.config.navigator_config` with the
        keywords below (the defaults of ``selfnav navigate``).
    grade, lever_arm_m, nhc_lever_m, nhc, imu_time_offset_s, odometer, platform :
        As :func:`selfnav.ins.config.navigator_config`.
    road_aid : optional
        A map aid (:class:`selfnav.roads.aid.EkfRoadAid`): ``start_check(imu, gnss, cfg, start=)``,
        ``add_fix(t, lat, lon, sigma)``, ``__call__(t, flt) -> measurement | None`` at every
        aiding epoch. :func:`selfnav.navigate` builds it from ``roads``.
    init : dict, optional
        A start state (``t`` true time, ``lat, lon, h`` rad/m, ``velocity_n``, ``C_nb``,
        ``sigmas``): no alignment.
    out_rate_hz : float
        Output rows per second (:data:`DEFAULT_OUT_RATE_HZ`); 0: a row at every IMU sample.
    smoother : bool
        Keep what the RTS smoother needs (covariances, transitions): :meth:`result` can then
        smooth (more memory).
    map : RoadGraph or path, optional
        The road map (OSM ``.osm.pbf`` / ``.osm``, or a read graph): the road aid of
        ``selfnav navigate --map`` is built on it (instead of ``road_aid``).
    """

    def __init__(self, config: FilterConfig | None = None, *, grade: str = "auto",
                 lever_arm_m=None, nhc_lever_m=None, nhc: bool | None = None,
                 imu_time_offset_s: float | None = None, odometer: bool = False,
                 road_aid=None, init: dict | None = None,
                 out_rate_hz: float = DEFAULT_OUT_RATE_HZ, smoother: bool = False,
                 map=None, platform: str = "auto"):
        from selfnav.ins.config import navigator_config

        if map is not None:                 # a road graph or its file: the road aid of --map
            if road_aid is not None:
                raise SelfnavError("give the road map as map= or road_aid=, not both")
            from selfnav.roads.aid import EkfRoadAid
            from selfnav.roads.graph import RoadGraph, read_roads

            road_aid = EkfRoadAid(map if isinstance(map, RoadGraph) else read_roads(map))

        if config is None:
            config = navigator_config(grade, lever_arm_m=lever_arm_m, nhc_lever_m=nhc_lever_m,
                                      nhc=nhc, imu_time_offset_s=imu_time_offset_s,
                                      odometer=odometer, platform=platform)
        if not out_rate_hz >= 0:
            raise SelfnavError(f"the output rate must be >= 0 Hz, got {out_rate_hz}")
        self.cfg = config
        self.offset_applied = float(imu_time_offset_s or 0.0)
        self.road_aid = road_aid
        self.out_dt = 1.0 / out_rate_hz if out_rate_hz > 0 else 0.0
        self.smoother = smoother
        self.flt: InsGnssFilter | None = None
        self.bank: FaultBank | None = None
        self.nhc_check = NhcCheck()     # does the platform move along its nose?
        self.startup = StartUp(config, time_offset_applied=self.offset_applied,
                               start_check=None if road_aid is None else road_aid.start_check)
        self._given_init = init
        self._events = []
        self._seq = 0
        self._t_prev_stamp = None
        self._dt_prev = None
        self.fixes: list[_Fix] = []
        self.log = {k: [] for k in ("t", "status", "reason", "nis_h", "nis_v", "nis_vel",
                                    "excluded")}
        self._decisions = []
        self._rows = []
        self._rec = {k: [] for k in ("t", "state", "P", "Pm", "Phi", "dx", "brk")}
        self._reset_flag = False
        self._t_last_fused = -np.inf
        self._ins_vouched = False
        self._t_last_fix = -np.inf
        self._fix_dt = []
        self._fix_dt_median = 0.0
        self._blk_w, self._blk_f, self._blk_span = [], [], 0.0
        self._still = False
        self._rest = False                 # ... and rest known: the zero-velocity update
        self._braked_to_rest = False
        self._t_grade = -np.inf
        self._pace = collections.deque()      # (t, forward speed) while the fixes are used
        self._t_pace = -np.inf
        self._fwd_hist = collections.deque(maxlen=10)   # forward accelerations, one per block
        # (slow and widened still?, mean rate) of the last blocks: a zero rate judged through
        # the widened test may need them all so and their rates one bias (zaru_steady_s)
        self._rate_hist = collections.deque(maxlen=1)
        self._imu_still = False
        self._still_from_braking = False
        self._acc = [0.0, np.zeros(3), np.zeros(3)]
        self._Pm = None
        self._dx = None
        self._next_row = None
        self._catching_up = False
        self.adapter = None
        self.vib_reference = None
        self._gate_v = chi2_gate(1, config.integrity.p_false_alarm)
        self._gate_vel2 = chi2_gate(2, config.integrity.p_false_alarm)
        self._gate_vel3 = chi2_gate(3, config.integrity.p_false_alarm)
        self._heading_t = -np.inf
        self._declination = None
        self.magcal = None                 # the magnetometer's fit (selfnav.ins.magcal)
        self._gyro_yaw = 0.0               # the raw gyros' heading change since then, rad
        self.start_info = {}
        self.counts = {"reinitialisations": 0, "degraded": 0, "time_offset_resets": 0,
                       "magnetometer_updates": 0, "magnetometer_refused": 0,
                       "magnetometer_bounds": 0,
                       "pace_priors": 0}
        self._hist = []
        self._t_toff = -np.inf
        self._debug = False
        self._cfg0 = config
        self._episodes_done = []
        self._segments = []
        self._last_flt = None
        self._odo_warned = False
        self._dt_nominal = None
        self.restarts = []
        self._hyp = None               # the heading hypotheses of a start (selfnav.ins.headings)
        self._collapsed_id = None      # the name of the hypothesis the last sum collapsed to

    # ================================================================== input
    def add_imu(self, t, gyro_rad_s, accel_m_s2) -> NavState:
        """IMU sample(s): the rates (rad/s) and specific force (m/s²), body RFU, mean over
        the interval ending at stamp ``t`` (scalar or arrays). Returns the state after it."""
        self._add_imu(t, gyro_rad_s, accel_m_s2)
        return self._state_now()

    def _add_imu(self, t, gyro_rad_s, accel_m_s2):
        """:meth:`add_imu` without the state it returns (the batch run, :func:`feed`, reads
        the rows instead: with a start's heading hypotheses the state is the whole sum's; a
        simulated rover with 20 Hz fixes took 67 CPU s with it, 30 without)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        w = np.atleast_2d(np.asarray(gyro_rad_s, dtype=float))
        f = np.atleast_2d(np.asarray(accel_m_s2, dtype=float))
        if w.shape != (len(t), 3) or f.shape != (len(t), 3):
            raise SelfnavError("IMU samples need three rates and three specific forces each")
        if not (np.isfinite(t).all() and np.isfinite(w).all() and np.isfinite(f).all()):
            raise SelfnavError("IMU samples must be finite numbers (NaN or inf given)")
        prev = self._t_prev_stamp
        first = (t[1] - t[0]) if len(t) > 1 else (self._dt_prev or 0.01)
        dt = np.diff(np.concatenate([[t[0] - first if prev is None else prev], t]))
        if np.any(dt <= 0):
            raise SelfnavError(f"IMU samples must have increasing times (at {t[np.argmin(dt)]:.6f} s)")
        # a gap the INS cannot bridge: start again after it (no row stands inside a gap)
        if not self._dt_nominal:           # the nominal step from the first three steps seen
            self._dt_first = (getattr(self, "_dt_first", []) + list(dt[:3]))[:3]
        nominal = self._dt_nominal if self._dt_nominal else float(np.median(self._dt_first))
        gap = np.flatnonzero(dt > self.cfg.vehicle.max_imu_gap_samples * nominal)
        if len(gap) and (prev is not None or gap[0] > 0):
            g = int(gap[0])
            if g:
                self._add_imu(t[:g], w[:g], f[:g])
            self._restart(f"IMU gap of {dt[g]:.3f} s before {t[g]:.3f} s")
            self._t_prev_stamp = float(t[g]) - nominal
            return self._add_imu(t[g:], w[g:], f[g:])
        self._t_prev_stamp = float(t[-1])
        self._decisions = []
        if not self._dt_nominal and len(self._dt_first) >= 3:
            self._dt_nominal = nominal
        self._dt_prev = float(dt[-1])
        i = 0
        while self.flt is None and i < len(t):
            # start attempts at a fixed grid of true time: the same whatever the chunking
            st = self.startup
            if self._given_init is not None:
                # a given start: at the first sample at or after its time
                t0 = float(self._given_init["t"]) - self.offset_applied
                j = max(i + 1, min(len(t), i + int(np.searchsorted(t[i:], t0 - 1e-12))))
                st.add_imu(t[i:j], w[i:j], f[i:j])
                i = j
                self._maybe_start()
                continue
            # the attempt grid is kept between calls: one sample a call reaches a grid point
            # with the first sample past it, as a chunk does (real stamps are never on it)
            if st.grid is None:
                st.grid = st.next_attempt(t[i] + self.offset_applied)
            grid = st.grid
            j = i + int(np.searchsorted(t[i:] + self.offset_applied, grid - 1e-12, side="left")) + 1
            j = min(j, len(t))
            st.add_imu(t[i:j], w[i:j], f[i:j])
            i = j
            if st.t_imu >= grid - 1e-9:
                st.grid = st.next_attempt(st.t_imu + 1e-9)
                self._maybe_start()
        if i < len(t):
            self._feed(t[i:], w[i:], f[i:], dt[i:])

    def add_fix(self, t, lat_deg, lon_deg, h_m, sigma_m=None, velocity_enu=None,
                quality=None, *, sigma_v_m=None, sigma_vel_mps=None) -> FixDecision:
        """A GNSS fix at true time ``t``: WGS-84 degrees and ellipsoidal height; σ horizontal
        per axis (None: the configuration's default), vertical, velocity ENU m/s and its σ,
        the receiver's quality flag. Returns the decision — ``pending`` when the IMU has not
        reached ``t`` yet (the decision then comes with a later :class:`NavState`)."""
        g = self.cfg.gnss
        vals = [float(t), float(lat_deg), float(lon_deg), float(h_m)]
        if not all(np.isfinite(vals)):
            raise SelfnavError(f"a GNSS fix needs finite time, latitude, longitude and height "
                               f"(got {vals})")
        if not (-90.0 <= vals[1] <= 90.0 and -180.0 <= vals[2] <= 360.0):
            raise SelfnavError(f"GNSS fix at {vals[0]:.3f} s: latitude/longitude {vals[1]}, "
                               f"{vals[2]} are not degrees")
        s_file = g.default_sigma if sigma_m is None or not np.isfinite(sigma_m) else float(sigma_m)
        s = max(g.sigma_h if g.sigma_h is not None else s_file, g.sigma_floor)
        if g.sigma_v is not None:
            sv = g.sigma_v
        elif sigma_v_m is not None and np.isfinite(sigma_v_m):
            sv = max(float(sigma_v_m), g.sigma_floor * g.vertical_ratio)
        else:
            sv = g.vertical_ratio * s
        svel = max(sigma_vel_mps if sigma_vel_mps is not None and np.isfinite(sigma_vel_mps)
                   else g.velocity_sigma, g.velocity_floor)
        vel = None
        if velocity_enu is not None:
            v = np.asarray(velocity_enu, dtype=float).reshape(-1)
            if v.size == 2:
                v = np.r_[v, np.nan]
            if v.size == 3 and np.all(np.isfinite(v[:2])):
                vel = v
        fx = _Fix(vals[0], math.radians(vals[1]), math.radians(vals[2]), vals[3], s, sv, vel,
                  svel, svel * g.vertical_ratio, None if quality is None else int(quality),
                  len(self.fixes))
        if self.fixes and fx.t > self.fixes[-1].t:
            self._fix_dt.append(fx.t - self.fixes[-1].t)
            self._fix_dt = self._fix_dt[-20:]
            srt = sorted(self._fix_dt)
            self._fix_dt_median = 0.5 * (srt[(len(srt) - 1) // 2] + srt[len(srt) // 2])
        self.fixes.append(fx)
        for key, val in (("t", fx.t), ("status", FixStatus.PENDING), ("reason", ""),
                         ("nis_h", np.nan), ("nis_v", np.nan), ("nis_vel", np.nan),
                         ("excluded", False)):
            self.log[key].append(val)
        if self.flt is None:
            self.startup.add_fix(fx)
            self.log["status"][fx.index] = FixStatus.ALIGNING
            self.log["reason"][fx.index] = "before the start"
            return FixDecision(fx.t, FixStatus.ALIGNING, "before the start")
        if fx.t <= self.flt.t_true + 1e-9:
            # late: the IMU has passed it — processed now, against the state extrapolated back
            self._decisions = []
            self._propagate_to_now()
            self._Pm = self.flt.P.copy() if self.smoother else None
            self._dx = np.zeros(self.flt.nx)
            self._process_fix(fx)
            self._record_epoch()
            return self._decisions[-1]
        self._push(fx.t, _KIND_FIX, fx)
        return FixDecision(fx.t, FixStatus.PENDING, "waiting for the IMU to reach its time")

    def add_odometer(self, t, speed_mps, sigma=None):
        """A wheel-speed sample (forward speed at the rear axle, m/s) stamped ``t`` on the
        IMU's clock, as :meth:`add_imu`'s samples are (wheel speed and IMU logged together);
        σ default ``vehicle.odometer_sigma``. Samples closer than ``vehicle.odometer_step``
        are thinned."""
        t = float(t) + self.offset_applied
        if self.flt is None:
            self.startup.odometer.append((t, float(speed_mps), sigma))
            return
        self._push_odometer(t, float(speed_mps), sigma)

    def add_magnetometer(self, t, mag_b):
        """A magnetometer sample (body RFU, any unit) stamped ``t`` on the IMU's clock (a
        column of the IMU's rows): before the start, the start's heading where the course
        gives none (:mod:`selfnav.ins.anystart`); after it, with ``vehicle.use_magnetometer``,
        a heading measurement (tilt-compensated, IGRF declination) at most
        ``vehicle.mag_step`` apart."""
        veh = self.cfg.vehicle
        t = float(t) + self.offset_applied
        if t - self._heading_t < veh.mag_step - 1e-9:
            return
        if self.flt is None:       # the start's heading (selfnav.ins.anystart), updates or not
            self._heading_t = t
            self.startup.magnetometer.append((t, np.asarray(mag_b, float)))
            return
        if not veh.use_magnetometer:
            return
        self._heading_t = t
        self._push_imu_clock(t, _KIND_HEADING, (t, np.asarray(mag_b, dtype=float)))

    def _push_imu_clock(self, t, kind, payload):
        """Queue a sample stamped on the IMU's clock (``t``: stamp plus the applied offset):
        due when the INS reaches its stamp — the stamp plus the offset estimated now — so the
        offset's error shifts it as it shifts the IMU and does not enter its model."""
        self._push(t + self.flt.time_offset, kind, payload)

    def _push_odometer(self, t, speed, sigma):
        if self.flt.layout.odo is None:
            if not self._odo_warned:
                import warnings

                from selfnav.errors import SelfnavWarning

                warnings.warn("wheel speed arrived after the start: the navigator has no "
                              "odometer state (give the first samples before the start, or "
                              "odometer=True)", SelfnavWarning, stacklevel=3)
                self._odo_warned = True
            return
        last = getattr(self, "_t_odo", -np.inf)
        if t - last < self.cfg.vehicle.odometer_step - 1e-9:
            return
        self._t_odo = t
        # the model extrapolates from wherever the INS is when it comes due to its stamp
        self._push_imu_clock(t, _KIND_ODO, (speed, sigma, t - self.offset_applied))

    def _push(self, t, kind, payload):
        heapq.heappush(self._events, (float(t), kind, self._seq, payload))
        self._seq += 1

    # ================================================================== start
    def _maybe_start(self):
        st = self.startup
        if self._given_init is not None:
            init, cfg = dict(self._given_init), self.cfg
            if st.t_imu < init["t"]:
                return
            from selfnav.ins.startup import Start
            start = Start(init, cfg)
        else:
            start = st.try_start()
            if start is None:
                return
        self._start(start)

    def _restart(self, why):
        """Back to the start-up stage (an IMU gap): the rows stop until a new start."""
        if self.flt is not None:
            self.finish()
            self.restarts.append(why)
            self._segments.append((self._rec, self.flt.layout))
            self._rec = {k: [] for k in self._rec}
            self._last_flt = self.flt
            self._episodes_done += self.bank.episodes
            self.bank = None
        self.flt = None
        self.cfg = self._cfg0
        self.startup = StartUp(self.cfg, time_offset_applied=self.offset_applied,
                               start_check=None if self.road_aid is None else
                               self.road_aid.start_check)
        self._events = []
        self._given_init = None
        self._acc = [0.0, np.zeros(3), np.zeros(3)]
        self._blk_w, self._blk_f, self._blk_span = [], [], 0.0
        self._fwd_hist.clear()
        self._rate_hist.clear()
        self._imu_still = self._still_from_braking = self._braked_to_rest = False
        self._hyp = None
        self._collapsed_id = None
        if self.magcal is not None:
            self.magcal.new_stretch()      # the gyros' heading has a gap

    def _start(self, start):
        st = self.startup
        init = start.init
        cfg = start.cfg
        gn = st.gnss()
        has_vel = len(gn) > 0 and gn.velocity_n is not None
        cfg = cfg.updated(velocity_lag=bool(has_vel and cfg.gnss.use_velocity
                                            and cfg.states.velocity_lag),
                          odometer=bool(cfg.states.odometer or st.odometer))
        notes = list(start.notes)
        if init.get("off_map"):
            notes.append("the fixes lie where the map has no roads: started without its check")
        if init.get("fallback") and cfg.vehicle.platform == "auto":
            # the car's start found no car (issue 20): a slow platform's constraints
            notes.append(f"slow platform: {init['fallback']} (--platform says which)")
            import warnings

            from selfnav.errors import SelfnavWarning

            warnings.warn(f"started as a platform slower than a car ({init['fallback']}): "
                          f"the sideways constraint keeps a mounting-yaw state, zero-velocity "
                          f"updates only below 0.1 m/s (--platform car|pedestrian|rover|boat|"
                          f"drone|aircraft says which)", SelfnavWarning, stacklevel=3)
        self.cfg = cfg
        self.start_info = {"t": float(init["t"]), "measured": start.measured,
                           "notes": notes, "attempts": st.attempts,
                           "kind": init.get("start_kind", "course"),
                           "heading_source": init.get("heading_source", "course"),
                           "platform": cfg.vehicle.platform, "nhc": bool(cfg.vehicle.nhc)}
        prior = str(self.startup.cfg.imu.grade)
        if start.notes and not prior.startswith("auto"):
            import warnings

            from selfnav.errors import SelfnavWarning

            warnings.warn(f"the IMU is noisier than the '{prior}' preset says "
                          f"({'; '.join(start.notes)}): using the measured noise",
                          SelfnavWarning, stacklevel=3)
        t0_stamp = float(init["t"]) - self.offset_applied
        flt = initial_filter(cfg, init, self.offset_applied)
        flt.track_transition = self.smoother
        flt.q_scale = cfg.adaptation.q_scale0
        self.flt = flt
        self.adapter = NoiseAdapter(cfg.adaptation, cfg.integrity.p_false_alarm) if cfg.imu.adapt else None
        # the vibration at rest, or the white noise the model assumes, is the reference
        t_buf = st.imu().t if st.imu_t else np.zeros(0)
        # (a start on one buffered sample has no step: the median of none was NaN, and so the
        # reference, with a numpy warning — tests/test_odometer.py's streamed start)
        dt_imu = float(np.median(np.diff(t_buf))) if len(t_buf) > 1 else 0.01
        ms = start.measured
        if ms is not None and ms.vibration is not None:
            self.vib_reference = ms.vibration
        else:
            self.vib_reference = (cfg.imu.arw**2 / dt_imu, cfg.imu.vrw**2 / dt_imu)
        if not cfg.adaptation.vibration:
            self.vib_reference = None
        self.bank = FaultBank(cfg, self.adapter)
        self.bank.sum_choice_differs = self._sum_choice_differs
        if self.road_aid is not None and hasattr(self.road_aid, "track_evidence"):
            self.bank.road_aid = self.road_aid
        self._ins_vouched = False
        t0 = float(init["t"])
        self.bank.restart(t0)
        # a heading outside the filter's linear range: a Gaussian sum until the fixes resolve it
        self._hyp = split_heading(flt, cfg)
        if self._hyp is not None:
            self.flt = self._hyp.filters[self._hyp.best]
            self.start_info["heading_hypotheses"] = self._hyp.spawned
        self._n_aid = int(math.floor(t0 / cfg.vehicle.aid_step)) + 1
        self._next_row = self._row_after(t0)
        if self.road_aid is not None:
            self.road_aid.on_start(t0, flt)
        # catch up: the buffered stream after the start, through the normal epochs
        imu = st.imu()
        # the fixes the alignment used are in the start state already: taken again as if
        # independent of it, they made the start's heading σ shrink without its error. The
        # start holds a share ``w`` of their information (its σ widened k-fold: w = 1/k²);
        # where the IMU cannot bridge the window's second half — its horizontal gyro biases'
        # tilt turns gravity into a velocity error ½ g σ_bg T² beyond the start's velocity
        # σ — the fixes after the start's time are fused with the rest, σ / √(1 − w): left
        # out, a consumer IMU (1 °/s) dead-reckoned 8 s of 10 m fixes, came out tens of
        # degrees tilted and a clean drive ended 600 m RMS off. Where it can (industrial, or
        # an RTK window of a second) they stay out: fused again they were the simulated
        # campaigns' worse choice (4 → 8 of 40 drives beyond p95 3σ, seed 2)
        t_used = max(t0, float(init.get("t_used", t0)))
        share = float(init.get("fix_share", 1.0))
        P0 = flt.P
        s_bg = math.sqrt(max(P0[IBG.start, IBG.start], P0[IBG.start + 1, IBG.start + 1]))
        s_v = math.sqrt(0.5 * (P0[3, 3] + P0[4, 4]))
        if 0.5 * flt.gravity(flt.ins.lat, flt.ins.h) * s_bg * (t_used - t0) ** 2 <= s_v:
            share = 1.0
        for fx in st.fixes:
            if fx.t > t_used:
                self._push(fx.t, _KIND_FIX, fx)
            elif fx.t > t0 and share < 1.0:
                k = 1.0 / math.sqrt(1.0 - share)
                self._push(fx.t, _KIND_FIX, replace(fx, sigma_h=fx.sigma_h * k,
                                                    sigma_v=fx.sigma_v * k,
                                                    sigma_vel=fx.sigma_vel * k,
                                                    sigma_vel_up=fx.sigma_vel_up * k))
            else:
                self.log["status"][fx.index] = FixStatus.ALIGNING
                self.log["reason"][fx.index] = "used by the alignment"
        for (t_o, v_o, s_o) in st.odometer:
            if t_o > t0:
                self._push_odometer(t_o, v_o, s_o)
        for (t_m, m_b) in st.magnetometer:
            if t_m > t0 and cfg.vehicle.use_magnetometer:
                self._push_imu_clock(t_m, _KIND_HEADING, (t_m, m_b))
        k = imu.t > t0_stamp + 1e-12
        self._catching_up = True
        if k.any():
            tt = imu.t[k]
            dts = np.diff(np.concatenate([[t0_stamp], tt]))
            self._feed(tt, imu.omega_ib_b[k], imu.f_ib_b[k], dts)
        self._catching_up = False
        self._next_row = self._row_after(self.flt.t_true)
        self.startup = None

    # ================================================================== the stream
    def _row_after(self, t):
        """The first row time after ``t`` (the grid of ``out_dt``), or None (every sample)."""
        if not self.out_dt:
            return None
        k = math.floor(t / self.out_dt + 1e-9) + 1
        return k * self.out_dt

    def _next_event(self):
        ta = self._n_aid * self.cfg.vehicle.aid_step
        if self._events and (self._events[0][0], self._events[0][1]) < (ta, _KIND_AID):
            return self._events[0][0]
        return ta

    def _feed(self, t, w, f, dt):
        """Mechanize IMU samples (stamps ``t``), processing every event and row they pass."""
        flt = self.flt
        i, n = 0, len(t)
        while i < n:
            tau = t[i:] + (flt.time_offset_applied + flt.time_offset)
            # up to and including the first sample that reaches the next event
            j = min(n, i + int(np.searchsorted(tau, self._next_event() - 1e-12, side="left")) + 1)
            self._mechanize(t[i:j], w[i:j], f[i:j], dt[i:j], tau[:j - i])
            i = j
            while self._next_event() <= flt.t_true + 1e-9:
                self._process_next()
                flt = self.flt
            if self.out_dt == 0.0 and not self._catching_up:
                self._emit_row(flt.t_true)

    def _mechanize(self, t, w, f, dt, tau):
        flt = self.flt
        rows = self._next_row is not None and not self._catching_up
        if rows:
            # rows before these samples: from the state now (after its events)
            while self._next_row < tau[0] - 1e-9:
                self._emit_row(self._next_row)
                self._next_row = self._row_after(self._next_row)
        dth, dv = w * dt[:, None], f * dt[:, None]
        if self._hyp is not None:
            # every heading hypothesis follows the IMU (each keeps its own sums)
            sth, sdv, states = self._hyp.mechanize(t, dth, dv, dt, rows, self._m_index())
        else:
            sth, sdv, states = flt.mechanize(t, dth, dv, dt, states=rows)
            a = self._acc
            a[0] += float(dt.sum())
            a[1] += sth
            a[2] += sdv
        self._blk_w.append(w - flt.bg)
        self._blk_f.append(f - flt.ba)
        self._blk_span += float(dt.sum())
        if self.magcal is not None:
            # the raw gyros' heading change (clockwise, their bias in: a constant bias is a
            # straight drift, which the magnetometer's fit through the turns solves for)
            self._gyro_yaw -= float((flt.ins.C_nb.T @ dth.sum(axis=0))[2])
        self.bank.on_imu(t, dth, dv, dt)
        if flt.layout.toff is not None:
            self._hist.append((t, w, f))
        if rows:
            # rows strictly before the last sample: from the sample at or before each; a row
            # at the last sample waits for its events
            pos, vel, C = states
            while self._next_row < tau[-1] - 1e-9:
                T = self._next_row
                k = int(np.searchsorted(tau, T + 1e-9, side="right")) - 1
                self._emit_row(T, tau[k], pos[k], vel[k], C[k])
                self._next_row = self._row_after(T)

    def _steady_rate(self, veh) -> bool:
        """The aiding blocks of the last ``zaru_steady_s`` were all slow and passed the widened
        stillness test, and their mean rates lie within ``zupt_gyro`` of their mean: one
        constant bias (a single block: always)."""
        h = self._rate_hist
        if len(h) < h.maxlen or not all(b[0] for b in h):
            return False
        m = np.array([b[1] for b in h])
        return float(np.max(np.linalg.norm(m - m.mean(axis=0), axis=1))) <= veh.zupt_gyro

    def _nhc_adapts(self) -> bool:
        return self.cfg.vehicle.platform.startswith("auto") and self.road_aid is None

    def _nhc_scale(self) -> np.ndarray:
        """The non-holonomic constraint's σ over the configured ones (lateral, vertical):
        what :class:`NhcCheck` finds the platform needs, for an ``auto`` platform without a
        road map — a named platform keeps its profile's, and a road map says the platform is
        a road vehicle, whose large lateral innovations are GNSS faults it follows, not a
        sway (on the 100 map drives of master seed 2 and 103 the check widened 17 and 23
        drives, nearly all inside such windows: 5 better, 9 worse on 103)."""
        if not self._nhc_adapts():
            return np.ones(2)
        if self.bank is not None:
            self.bank.nhc_scale = self.nhc_check.scale
        return self.nhc_check.scale

    def _filters(self):
        """The filters every measurement goes to: ``M``, or every heading hypothesis."""
        return [self.flt] if self._hyp is None else self._hyp.filters

    def _m_index(self) -> int:
        return self._hyp.filters.index(self.flt)

    def _propagate_to_now(self):
        """The covariance to the last mechanized sample."""
        if self._hyp is not None:
            self._hyp.propagate()
            return
        a = self._acc
        if a[0] > 0:
            self.flt.propagate(a[0], a[1], a[2])
        self._acc = [0.0, np.zeros(3), np.zeros(3)]

    # ------------------------------------------------------------------ events
    def _process_next(self):
        flt, cfg = self.flt, self.cfg
        ta = self._n_aid * cfg.vehicle.aid_step
        if self._events and (self._events[0][0], self._events[0][1]) < (ta, _KIND_AID):
            te, kind, _, payload = heapq.heappop(self._events)
        else:
            te, kind, payload = ta, _KIND_AID, None
            self._n_aid += 1
        self._propagate_to_now()
        self._Pm = flt.P.copy() if self.smoother else None
        self._dx = np.zeros(flt.nx)
        if kind == _KIND_AID:
            self._aid_epoch(te)
        elif kind == _KIND_FIX:
            self._process_fix(payload)
        elif kind == _KIND_HEADING:
            self._heading(payload)
        elif kind == _KIND_ODO:
            speed, sigma, stamp = payload
            s = cfg.vehicle.odometer_sigma if sigma is None else float(sigma)
            for f in self._filters():
                m = WheelSpeed(speed, s, stamp).model(f)
                q = f.nis(m)
                dx = f.update(m, max(1.0, q / self._gate_v))
                if f is flt:
                    self._dx = self._dx + dx
        if self.bank.episode is not None and self._dx.any() and self.flt is flt:
            self.bank.on_correction(self._dx, flt)
        self._record_epoch()

    def _warn_slip(self, t):
        import warnings

        from selfnav.errors import SelfnavWarning

        ch, veh = self.nhc_check, self.cfg.vehicle
        if ch.scale[0] > 1.0:
            why = (f"the platform slips sideways — the sideways constraint's innovations are "
                   f"{ch.seen[1]:.2f} m/s RMS over the last 30 s against its σ "
                   f"{veh.nhc_sigma:g} (a car leaves a fifth of it): its σ follows them, up to "
                   f"{ch.widen:g}× (a hull yawing in the waves: --platform boat; --no-nhc drops "
                   f"it)")
        else:
            why = (f"the vertical constraint's innovations are {ch.seen[3]:.2f} m/s RMS over "
                   f"the last 30 s against its σ {veh.nhc_sigma_up or veh.nhc_sigma:g}: its σ "
                   f"follows them, up to {ch.widen:g}× (an IMU pitched on the vehicle: "
                   f"--imu-mount; a platform that pitches or heaves)")
        warnings.warn(f"at {t:.0f} s: {why}", SelfnavWarning, stacklevel=4)

    def _aid_epoch(self, te):
        flt, veh = self.flt, self.cfg.vehicle
        w_blk = np.concatenate(self._blk_w) if self._blk_w else np.zeros((0, 3))
        f_blk = np.concatenate(self._blk_f) if self._blk_f else np.zeros((0, 3))
        span = self._blk_span
        self._blk_w, self._blk_f, self._blk_span = [], [], 0.0
        # the IMU still (its rate bound widened by what the filter does not know of its gyro
        # biases: a consumer part's 2 °/s turn-on bias hid every stop from the absolute bound)
        imu_still = bool(veh.zupt) and _still(w_blk, f_blk, flt, veh, widen="gyro")
        if imu_still and not self._imu_still:
            # a still run entered from braking is a stop; from speeding up, a cruise (an IMU
            # cannot tell a cruise from rest). A braking to rest lasts until the car stands:
            # one that eased off before the run (a slow turn, then a cruise) is not a stop
            fwd = np.asarray(self._fwd_hist, float)
            n_last = max(1, int(round(veh.zupt_brake_last_s / veh.aid_step)))
            self._still_from_braking = bool(len(fwd) and fwd.mean() < -veh.zupt_brake_accel)
            self._braked_to_rest = bool(self._still_from_braking
                                        and fwd[-n_last:].mean() < -veh.zupt_brake_accel)
        elif not imu_still and len(f_blk):
            # along the nose, gravity removed with the INS's pitch (its heading may be anything
            # at a start). The verdict holds until the next still run begins: after a stop,
            # a slow pull-away that turns no more than a stop keeps the zero-rate update
            self._fwd_hist.append(float(f_blk[:, 1].mean()) - flt.gravity(
                flt.ins.lat, flt.ins.h) * flt.ins.C_nb[1, 2])
        self._imu_still = imu_still
        # after a braking, rest is what the INS's speed allows within its σ: a stop the INS
        # reached at 2-4 m/s (its velocity that far off) was never updated
        v_max = _braked_speed_bound(flt, veh) if self._still_from_braking else veh.zupt_speed
        speed = float(np.linalg.norm(flt.ins.velocity_n))
        slow = bool(veh.zupt and speed < v_max)
        self._still = slow and imu_still
        self._rest = self._still and self._rest_known(speed, flt, veh)
        # a zero rate judged still only through the widened test (the rates within what the
        # filter does not know of its gyro biases): on a slow platform the INS slow and the
        # IMU so still for ``zaru_steady_s``, the rates one bias (constant within the rate
        # bound). A simulated boat in waves (defaults, seed 40), whose INS a fix had slowed to
        # a crawl for a second while it sailed at 1.1 m/s, took a slow turn and the waves'
        # roll for a bias: the z gyro bias "measured" to 0.86 °/s at σ 0.04 °/s, the heading
        # turned 160° in three minutes, the fixes refused as a drag, 80 m RMS
        wide = slow and bool(veh.zaru) and _still(w_blk, f_blk, flt, veh, widen=True)
        n_steady = max(1, int(round(veh.zaru_steady_s / veh.aid_step)))
        if self._rate_hist.maxlen != n_steady:
            self._rate_hist = collections.deque(self._rate_hist, maxlen=n_steady)
        self._rate_hist.append((wide, w_blk.mean(axis=0) if len(w_blk) else np.zeros(3)))
        zaru = veh.zaru and (self._still or (wide and self._steady_rate(veh)))
        self.bank.judged(self._still)
        if self.vib_reference is not None:
            kv = vibration_scale(vibration_level(w_blk, f_blk), self.vib_reference,
                                 self.cfg.adaptation.vibration_cap)
            for f in self._filters() + [r.flt for r in self.bank.carried]:
                f.vibration = kv
        for f in self._filters():
            dx = np.zeros(f.nx)
            if zaru:
                # a block judged still only through wide gyro-bias σ may be a platform rocking
                # at a few °/s (a boat in waves, simulated): a zero rate 300σ from the filter's
                # belief is motion, not a bias — taken, it moved the velocity by 6 m/s and the
                # mounting yaw by 70° in one update. A still IMU at rest (a stop) is taken
                # whatever the innovation: a bias learnt wrong is measured there
                m = ZeroRate(w_blk + (flt.bg - f.bg), veh.zaru_sigma, span).model(f)
                if self._still or f.nis(m) <= self._gate_vel3:
                    dx = f.update(m)
            if self._rest:
                dx = dx + f.update(ZeroVelocity(veh.zupt_sigma).model(f))
            elif veh.nhc:
                sig = np.array([veh.nhc_sigma, veh.nhc_sigma_up or veh.nhc_sigma])
                m = NonHolonomic(*(sig * self._nhc_scale())).model(f)
                if f is flt and self._status(te) is NavStatus.GNSS and self.nhc_check.add(
                        te, m.r, sig, np.einsum("ij,jk,ik->i", m.H, f.P, m.H)) \
                        and self._nhc_scale().max() > 1.0:
                    self._warn_slip(te)     # (a platform the user named: the JSON says it)
                dx = dx + f.update(m)
            elif not zaru:
                continue
            if f is flt:
                self._dx = self._dx + dx
        if (veh.grade_sigma is not None and self.road_aid is None and not self._still
                and te - self._t_grade >= 1.0 - 1e-9):
            # a car drives on roads: the level-road prior (the road aid gives its own), each
            # second 1/grade_corr_s of a grade's information (a hill lasts tens of seconds)
            self._t_grade = te
            prior = LevelRoad.at_speed(veh.grade_sigma, np.hypot(*flt.ins.velocity_n[:2]),
                                       veh.grade_corr_s)
            for f in self._filters():
                dx = f.update(prior.model(f))
                if f is flt:
                    self._dx = self._dx + dx
        if veh.speed_hold and not self._still:
            w_z = abs(float(w_blk[:, 2].mean()) - flt.bg[2]) if len(w_blk) else 0.0
            self._hold_pace(te, imu_still, w_z)
        self.bank.on_outage(te, self._t_last_fix)
        if self.road_aid is not None:
            self.road_aid.dead_reckoning = (self.bank.episode is not None
                                            or te - self._t_last_fused > self.cfg.integrity.outage_s)
            # once a dead reckoning of this start stood the fixes' test, its heading is vouched
            # for until a restart (a reference that ages out in a long window does not undo it)
            self._ins_vouched = self._ins_vouched or bool(self.bank.mature(te))
            self.road_aid.ins_vouched = self._ins_vouched
            self.road_aid.hypotheses = None if self._hyp is None else self._hyp.filters
            if self._hyp is None:
                m = self.road_aid(te, flt)
                if m is not None:
                    self._dx = self._dx + m
            else:
                # the map's cloud follows M; its constraints go to every heading hypothesis
                meas = self.road_aid.constraints(te, flt)
                for f in self._filters():
                    dx = self.road_aid.apply(meas, f)
                    if f is flt:
                        self._dx = self._dx + dx
        if self._hyp is not None:
            # no references or time-offset search until resolved; the map's witnesses only
            self.bank.maintain(te, flt, resolving=True, source=self._hyp.snapshot)
            return
        self.bank.maintain(te, flt)
        if flt.layout.toff is not None:
            self._check_time_offset(te)

    def _rest_known(self, speed, flt, veh) -> bool:
        """May a still, slow block take the zero-velocity update (σ ``zupt_sigma``)? An IMU
        cannot tell rest from a cruise, and the update makes the filter sure of rest: taken on
        a cruise, it collapses the velocity and (through their correlation) the position σ
        onto a lie. So the INS must know it is slow — its speed below ``zupt_speed`` with a
        speed σ within ``zupt_sigma_max`` (simulated campaign drive 8952012862136796095: a
        dead reckoning through a Gauss–Markov window whose INS speed drifted to 1.0 m/s at
        σ 2.7 m/s while the car cruised at 2.8 m/s, clamped to rest: σ_h 75 → 17 m, 200 m off)
        — or the still run must have been braked into, up to its start, at a speed within
        ``zupt_speed_sigmas`` σ of rest (at most ``zupt_speed_cap``: a stop the INS reached
        at 2–4 m/s; not a car that slowed in a turn and cruised on at 2.8 m/s, clamped to
        rest a second after its start, 3704056357717984369: 60 m off at σ 4 m)."""
        if self._braked_to_rest and speed < _braked_speed_bound(flt, veh):
            return True
        return speed < veh.zupt_speed and (veh.zupt_sigma_max is None
                                           or _speed_sigma(flt) <= veh.zupt_sigma_max)

    def _hold_pace(self, te, imu_still, w_z):
        """``vehicle.speed_hold``: while the fixes are used, learn the pace (the INS's forward
        speed at the NHC point); once they stop — and while the IMU is not still — hold the
        platform to it, once a second, with the pace's own spread as σ (inflated for its
        correlation in time). A walker's 10 s outage otherwise ends 9-25 m off on a 2° pitch
        error (simulated, seeds 30-33): the pace bounds the along-track velocity the pitch
        drives, and the filter sees the pitch through it. The pace is held only in the motion
        it was learnt in: not while the platform turns faster than it did then (a skid-steer
        rover slows to a crawl in its turns on the spot)."""
        flt, veh = self.flt, self.cfg.vehicle
        if te - self._t_last_fused <= 1.5 * max(self._fix_dt_median, veh.aid_step):
            vv, _ = vehicle_velocity(flt)
            self._pace.append((te, float(vv[1]), w_z))
            while self._pace and self._pace[0][0] < te - veh.speed_hold_window_s:
                self._pace.popleft()
            return
        if imu_still or te - self._t_pace < 1.0 - 1e-9 or len(self._pace) < 10:
            return
        if te - self._pace[-1][0] > veh.speed_hold_max_s:
            return                          # a pace from long ago says nothing of now
        turns = np.array([p[2] for p in self._pace])
        if w_z > max(float(np.percentile(turns, 95)), veh.speed_hold_turn):
            return
        self._t_pace = te
        tp = np.array([p[0] for p in self._pace])
        v = np.array([p[1] for p in self._pace])
        pace = float(np.median(v))
        sigma = max(float(np.std(v)), veh.speed_hold_floor)
        # how fast the pace itself wandered while it was learnt: the spread of its changes
        # over ``speed_hold_corr_s``, as a random walk carried over the outage so far (a
        # city car's speed, which brakes and pulls away, is soon no pace at all)
        lag = int(np.searchsorted(tp, tp[0] + veh.speed_hold_corr_s))
        if 0 < lag < len(v):
            # on the pace smoothed over 2 s: a walker's steps swing its speed by 12 % twice a
            # second, which is no change of pace
            n2 = max(1, int(np.searchsorted(tp, tp[0] + 2.0)))
            vs = np.convolve(v, np.ones(n2) / n2, mode="same")
            dv = vs[lag:] - vs[:-lag]
            walk = float(np.sqrt(np.mean(dv * dv) / veh.speed_hold_corr_s))
            sigma = math.hypot(sigma, walk * math.sqrt(te - tp[-1]))
        sigma *= math.sqrt(ar1_factor_of_time(1.0, veh.speed_hold_corr_s))
        prior = ForwardSpeed(pace, sigma)
        self.counts["pace_priors"] += 1
        for f in self._filters():
            dx = f.update(prior.model(f))
            if f is flt:
                self._dx = self._dx + dx

    def _check_time_offset(self, t):
        """The IMU time offset from the past, re-estimated (:func:`estimate_time_offset`: the
        gyro heading against the GNSS course, a search robust to where the filter's state
        went) every ``time_offset_check_s`` while the filter is unsure of it. The search is
        precise for a shift (±0.3 s recovered to 2 ms) but not accurate (on the first half of
        drive_0708 it is 0.08 s from the whole drive's answer, which the filter finds): it
        acquires, the filter refines — where they disagree by more than
        ``time_offset_coarse_s`` (and both σ), the state is moved to the search's value with
        that σ, and the position and velocity σ opened by what the old offset made them
        absorb (the linearised state alone, 0.3 s off, stalled halfway on drive_0708: the
        offset, a lever arm along the car and the velocity lag look alike)."""
        st, flt = self.cfg.states, self.flt
        if t - self._t_toff < st.time_offset_check_s - 1e-9:
            return
        self._t_toff = t
        i = flt.layout.toff.start
        if not self._hist:
            return
        t_min = t - st.time_offset_window_s
        # the window by sample, not by the blocks the samples came in (the same search
        # whether the IMU is fed a sample or a second at a time); kept as one block, and
        # kept to the window also while the offset is settled (hours of IMU otherwise)
        tt = np.concatenate([h[0] for h in self._hist])
        keep = tt >= t_min - flt.time_offset_applied
        self._hist = [(tt[keep], np.concatenate([h[1] for h in self._hist])[keep],
                       np.concatenate([h[2] for h in self._hist])[keep])]
        s_cur = float(np.sqrt(max(flt.P[i, i], 0.0)))
        if s_cur < st.time_offset_settled_s:
            return
        from selfnav.ins.calibrate import estimate_time_offset, shift_velocity
        from selfnav.types import GnssData, ImuData

        tt = self._hist[0][0] + flt.time_offset_applied
        imu = ImuData(tt, self._hist[0][1], self._hist[0][2])
        # only fixes the navigator fused (a drag's fixes would pull the search with them)
        fx = [f for f in self.fixes if t_min <= f.t <= t
              and FixStatus(self.log["status"][f.index]).fused and not self.log["excluded"][f.index]]
        if len(fx) < 30:
            return
        vel = None
        if all(f.velocity_n is not None for f in fx):
            vel = np.array([f.velocity_n for f in fx])
        g = GnssData(np.array([f.t for f in fx]), np.array([f.lat for f in fx]),
                     np.array([f.lon for f in fx]), np.array([f.h for f in fx]),
                     np.array([f.sigma_h for f in fx]), vel)
        if vel is not None and flt.layout.vlag is not None:
            g = shift_velocity(g, flt.velocity_lag)
        est = estimate_time_offset(imu, g)
        if est is None:
            return
        tau_mid, s_tau = est
        # the search's offset holds for the middle of its window; the clock drift carries it
        # to now
        age = t - float(np.mean([f.t for f in fx]))
        tau = tau_mid + flt.clock_drift * age
        if flt.layout.tdrift is not None:
            # ... and carries its σ too: an unsettled drift (after a reset) is no witness
            k = flt.layout.tdrift.start
            s_tau = float(np.hypot(s_tau, math.sqrt(max(flt.P[k, k], 0.0)) * age))
        d = tau - flt.time_offset
        if self._debug:
            print(f"toff check t={t:.1f} est {tau:+.4f}±{s_tau:.4f} state {flt.time_offset:+.4f}±{s_cur:.4f} drift {flt.clock_drift*1e6:.0f} ppm")
        if abs(d) > max(st.time_offset_coarse_s, 3.0 * np.hypot(s_tau, s_cur)):
            # the offset is the hardware's, not a hypothesis': the references take it too
            for f in [flt] + [r.flt for r in self.bank.carried]:
                d_f = tau - f.time_offset
                f.time_offset = tau
                f.P[i, :] = 0.0
                f.P[:, i] = 0.0
                f.P[i, i] = max(s_tau, st.time_offset_coarse_s) ** 2
                f.reprior("lever", "vlag", "tdrift")
                v, a = f.ins.velocity_n, f.acceleration_n
                w_z = float((f.ins.C_nb.T @ f.omega_b)[2])
                # the fixes had pulled the INS to where the old offset put the vehicle: under
                # the new one it is d_f s further along (not moved, the next fixes pulled the
                # offset back — drive_0708 0.25 s off: 0.16 s of a 0.18 s reset undone in
                # 30 s, 0.53 m RMS)
                f.advance(d_f)
                for k in range(3):
                    f.P[k, k] += (v[k] * d_f) ** 2
                    f.P[3 + k, 3 + k] += (a[k] * d_f) ** 2
                f.P[8, 8] += (w_z * d_f) ** 2
            self._reset_flag = True
            self.counts["time_offset_resets"] += 1
        elif abs(d) > 3.0 * np.hypot(s_tau, s_cur):
            # closer than the search's accuracy but beyond both σ: the state's σ is not honest
            # (the clock drift had absorbed the difference: drive_0708 with its IMU stamps
            # 0.25 s off, 87 ms at a σ of 10 ms and −2100 ppm) — the state keeps its value and
            # the filter refines it from a σ that covers the difference, the drift from its prior
            for f in [flt] + [r.flt for r in self.bank.carried]:
                f.P[i, :] = 0.0
                f.P[:, i] = 0.0
                f.P[i, i] = s_cur ** 2 + d * d
                f.reprior("tdrift")
            self._reset_flag = True        # P changed outside the model: the smoother breaks

    def _heading(self, payload):
        """A magnetometer reading: its heading (tilt-compensated with the INS's roll and pitch,
        IGRF declination) corrected by the offset fitted from the turns so far
        (:class:`selfnav.ins.magcal.HardIronFit`, ``vehicle.mag_calibrate``: the circle
        of the readings, or the turns the gyros measured), σ from that fit; until the fit is
        trusted the raw reading only bounds the heading (:meth:`_heading_bound`).

        While heading hypotheses run, the reading weighs them (its likelihood in each, the
        innovation counted up to the gate, as a fix does) and corrects only those it is within
        the gate of. After them, a reading outside the χ² gate is refused (reopening the
        heading to ten refused readings in a row, tried, let a simulated drone's magnetometer,
        11° off while it manoeuvred, overrule a heading the fixes held to 1°)."""
        from selfnav.sensors import magnetic_heading

        t, mag_b = payload
        flt, veh = self.flt, self.cfg.vehicle
        roll, pitch, _ = att.euler_from_dcm_nb(flt.ins.C_nb)
        if self._declination is None:
            from selfnav.sensors import declination_inclination, earth_field_n

            dec, inc = declination_inclination(earth_field_n(flt.ins.lat, flt.ins.lon, flt.ins.h))
            self._declination, self._inclination = float(dec), float(inc)
        if veh.mag_calibrate:
            if self.magcal is None:
                from selfnav.ins.magcal import HardIronFit

                self.magcal = HardIronFit(self._inclination)
            self.magcal.add(t, mag_b, roll, pitch, self._gyro_yaw,
                            float((flt.ins.C_nb.T @ flt.bg)[2]))
            est = self.magcal.heading(mag_b, roll, pitch, self._declination)
            if est is None:
                self._heading_bound(float(magnetic_heading(mag_b, roll, pitch,
                                                           self._declination)))
                return
            hdg, sigma = est
            # what is left of the deviation after the fit (soft iron, tilt) changes with the
            # heading, slowly: each reading counts for what its share of ``mag_corr_s`` adds
            sigma *= math.sqrt(ar1_factor_of_time(max(veh.mag_step, 1e-3), veh.mag_corr_s))
        else:
            hdg = float(magnetic_heading(mag_b, roll, pitch, self._declination))
            sigma = veh.mag_heading_sigma
        if self._hyp is not None:
            def fuse(f):
                m = Heading(hdg, sigma).model(f)
                S = float((m.H @ f.P @ m.H.T + m.R)[0, 0])
                q = float(m.r[0] ** 2 / S)
                if q <= self._gate_v:
                    dx = f.update(m)
                    if f is flt:
                        self._dx = self._dx + dx
                        self.counts["magnetometer_updates"] += 1
                return q, S, q <= self._gate_v

            self._hyp.on_fix(fuse, gate=self._gate_v)
            return
        m = Heading(hdg, sigma).model(flt)
        if flt.nis(m) > self._gate_v:
            self.counts["magnetometer_refused"] += 1
            return
        self.counts["magnetometer_updates"] += 1
        self._dx = self._dx + flt.update(m)

    def _heading_bound(self, hdg):
        """An uncalibrated magnetometer's heading ``hdg``: its error is the platform's iron, a
        bias that does not average out (the same reading at the same heading), so it bounds
        the heading and does not refine it — σ_b = ``MAG_START_FLOOR_DEG`` (the start's
        floor for the same reading). A filter whose heading σ has grown beyond σ_b is brought
        back to exactly σ_b (``R = σ_b² P / (P − σ_b²)``, posterior variance σ_b²); one within
        it is left alone. Heading hypotheses are weighed by the latest reading at σ_b, in
        place of the reading before (weighed by each reading, they were weighed by the same
        bias again and again: a simulated rover's heading went from 8° to 19° RMS). (A
        simulated boat on a straight course, industrial gyros under the consumer
        prior, no turn to calibrate on: its heading wandered 100° off in four minutes while
        the magnetometer stayed within 5°.)"""
        from selfnav.ins.anystart import MAG_START_FLOOR_DEG

        s_b2 = math.radians(MAG_START_FLOOR_DEG) ** 2

        if self._hyp is not None:
            q = []
            for f in self._hyp.filters:
                S = float(f.P[8, 8]) + s_b2
                r = float(Heading(hdg, 1.0).model(f).r[0])
                q.append(-0.5 * min(r * r / S, self._gate_v) - 0.5 * math.log(S))
            self._hyp.set_evidence("magnetometer", q)
            return
        f = self.flt
        P = float(f.P[8, 8])
        if P <= s_b2:
            return
        m = Heading(hdg, 1.0).model(f)
        if float(m.r[0] ** 2 / (P + s_b2)) > self._gate_v:
            return
        m.R[0, 0] = s_b2 * P / (P - s_b2)
        self._dx = self._dx + f.update(m)
        self.counts["magnetometer_bounds"] += 1

    # ------------------------------------------------------------------ one fix
    def _process_fix(self, fx: _Fix):
        flt, cfg = self.flt, self.cfg
        self._t_last_fix = fx.t
        m = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, fx.sigma_v).model(flt)
        mh = m.rows([0, 1])
        S3 = m.H @ flt.P @ m.H.T + m.R
        nis_v = float(m.r[2] ** 2 / S3[2, 2])
        if self._fix_dt:
            self.bank.fix_dt = self._fix_dt_median
        if self._hyp is not None:
            # judged against the whole sum: M with the sum's covariance about it (M's own is
            # one hypothesis' — narrower than what the navigator knows)
            judge_flt = flt.copy()
            judge_flt.P = self._hyp.covariance_about(self._m_index())
            mh = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h,
                             fx.sigma_v).model(judge_flt).rows([0, 1])
            v = self.bank.judge(judge_flt, mh, fx.t, (fx.lat, fx.lon))
        else:
            v = self.bank.judge(flt, mh, fx.t, (fx.lat, fx.lon))
        if v.reset_sum is not None:
            self._restore_sum(v.reset_sum, v.excluded_since)
            self._log(fx, v.status, v.reason, v.nis, nis_v, np.nan)
            return
        if self._hyp is not None:
            # the heading hypotheses: the bank judges the fix on M (its χ² gate and its
            # episodes: outliers while the heading is resolved); a plain "used" goes into
            # every hypothesis, anything more (a restart, a run's velocity) to M alone
            plain = (v.reset_to is None and v.reinit_from is None and v.widen is None
                     and v.run_velocity is None and v.add_R is None)
            if plain and v.apply:
                self._hypotheses_fix(fx)
                return
            if plain:
                self._log(fx, v.status, v.reason, v.nis, nis_v, np.nan)
                return
            self._collapse_hypotheses(fx.t)
            flt = self.flt
            m = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, fx.sigma_v).model(flt)
        if v.reset_to is not None:
            self._reset_to(v.reset_to, v.excluded_since)
            m = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, fx.sigma_v).model(self.flt)
            flt = self.flt
        status, reason = v.status, v.reason
        if v.reinit_from is not None:
            self._reinit_from(v.reinit_from, fx)
            self._log(fx, status, reason, v.nis, np.nan, np.nan)
            return
        if v.widen is not None:
            # the INS-fault hypothesis won: its position σ opened to the offset of the run
            d = np.asarray(v.widen, float)
            add = np.zeros_like(flt.P)
            add[0:2, 0:2] = np.outer(d, d) + np.eye(2) * float(d @ d)
            flt.P += add
            m = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, fx.sigma_v).model(flt)
            self.counts["reinitialisations"] += 1
        if v.run_velocity is not None:
            # the run that ended the episode also measured the velocity: after a long dead
            # reckoning M's is as stale as its position
            vel, cov = v.run_velocity
            self._dx = self._dx + flt.update(RunVelocity(vel, cov).model(flt))
            m = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, fx.sigma_v).model(flt)
        if v.add_R is not None:
            m.R[:2, :2] += v.add_R
        if v.apply:
            if nis_v <= self._gate_v and v.add_R is None:
                self._dx = self._dx + flt.update(m)
            else:
                # the fault's variance is horizontal: a fix fused with it gives no height
                self._dx = self._dx + flt.update(m.rows([0, 1]))
                status = FixStatus.DEGRADED
                if nis_v > self._gate_v:
                    reason = ((reason + "; " if reason else "")
                              + f"height rejected (NIS {nis_v:.3g})")
            self._t_last_fused = fx.t
            if self.adapter is not None and self.bank.episode is None \
                    and self.adapter.on_fix(flt, v.nis, 2,
                                            may_reopen=not self.bank.mature(fx.t)):
                self.bank.covariance_reopened(fx.t)
            if self.road_aid is not None:
                # the map's cloud takes the fixes the navigator takes, as it takes them (a
                # fault's fixes fed to it led it to other roads, and the filter after it)
                s_h = fx.sigma_h if v.add_R is None else math.sqrt(fx.sigma_h**2 + v.add_R[0, 0])
                self.road_aid.add_fix(fx.t, fx.lat, fx.lon, s_h)
        nis_vel = np.nan
        if fx.velocity_n is not None and cfg.gnss.use_velocity:
            mv = VelocityFix(fx.t, fx.velocity_n, fx.sigma_vel, fx.sigma_vel_up).model(flt)
            nis_vel = flt.nis(mv)
            gate = self._gate_vel3 if len(mv.r) == 3 else self._gate_vel2
            if nis_vel <= gate and not v.apply and self.bank.episode is not None \
                    and self.bank.velocity_moves_with_fault(-mv.r, mv.H @ flt.P @ mv.H.T + mv.R):
                # the positions refused and the velocity moving with them: part of the fault
                reason = (reason + "; " if reason else "") + \
                    "velocity refused: it moves with the refused positions"
            elif nis_vel <= gate and (v.apply or self.bank.episode is not None):
                self._dx = self._dx + flt.update(mv)
        self._log(fx, status, reason, v.nis, nis_v, nis_vel)

    def _fuse_plain(self, f, fx):
        """A fix into one filter with its own χ² gates (no bank): ``(horizontal NIS, det of
        its covariance, used, vertical NIS, velocity NIS)``."""
        m = PositionFix(fx.t, fx.lat, fx.lon, fx.h, fx.sigma_h, fx.sigma_v).model(f)
        S3 = m.H @ f.P @ m.H.T + m.R
        Sh = S3[:2, :2]
        nis = float(m.r[:2] @ np.linalg.solve(Sh, m.r[:2]))
        nis_v = float(m.r[2] ** 2 / S3[2, 2])
        used = nis <= self._hyp.gate
        nis_vel = np.nan
        dx = np.zeros(f.nx)
        if used:
            dx = dx + f.update(m if nis_v <= self._gate_v else m.rows([0, 1]))
            if fx.velocity_n is not None and self.cfg.gnss.use_velocity:
                mv = VelocityFix(fx.t, fx.velocity_n, fx.sigma_vel, fx.sigma_vel_up).model(f)
                nis_vel = f.nis(mv)
                if nis_vel <= (self._gate_vel3 if len(mv.r) == 3 else self._gate_vel2):
                    dx = dx + f.update(mv)
        if f is self.flt:
            self._dx = self._dx + dx
        return nis, float(np.linalg.det(Sh)), used, nis_v, nis_vel

    def _hypotheses_fix(self, fx):
        """A fix while the start's heading is a Gaussian sum (:mod:`selfnav.ins.headings`):
        into every hypothesis, the weights, the best one is ``M``; collapsed once resolved."""
        hyp, m_old = self._hyp, self.flt
        info = {}

        def fuse(f):
            nis, det, used, nis_v, nis_vel = self._fuse_plain(f, fx)
            info[id(f)] = (nis, used, nis_v, nis_vel)
            return nis, det, used

        hyp.on_fix(fuse)
        hyp.prune()
        self.flt = hyp.filters[hyp.best]
        if self.flt is not m_old:
            # M is another hypothesis now: its innovations so far were another filter's (the
            # bank's and the reopening test's), and the smoother's record breaks here
            self.bank.forget_innovations()
            if self.adapter is not None:
                self.adapter.forget()
            self._reset_flag = True
        nis, used, nis_v, nis_vel = info[id(self.flt)]
        reopen = None
        if used:
            self._t_last_fused = fx.t
            if self.road_aid is not None:
                self.road_aid.add_fix(fx.t, fx.lat, fx.lon, fx.sigma_h)
            if self.adapter is not None and self.bank.episode is None \
                    and not self.bank.mature(fx.t):
                # the best hypothesis' innovations tested as M's are: a sum none of whose
                # hypotheses is near the truth (a start given 41° off at σ 4.5°, split into
                # 49 along its heading and yaw bias) is as overconfident as one filter
                reopen = self.adapter.reopen_factor(nis, 2)
        w = float(np.max(hyp.weights))
        why = (f"heading hypotheses: {len(hyp.filters)} left, the best at "
               f"{np.degrees(hyp.deltas[hyp.best]):+.0f}° holds {w:.2f}")
        self._log(fx, FixStatus.USED if used else FixStatus.REJECTED,
                  why if used else f"χ² gate (NIS {nis:.3g}); {why}", nis, nis_v, nis_vel)
        if reopen is not None:
            # collapsed (the sum's spread in its covariance), then reopened as M would be
            self._collapse_hypotheses(fx.t)
            self.flt.P *= reopen
            self.bank.covariance_reopened(fx.t)
        elif hyp.resolved(fx.t):
            self._collapse_hypotheses(fx.t)

    def _collapse_hypotheses(self, t):
        """The heading resolved (or given up on): M is the best hypothesis with the covariance
        of the whole sum about it; the fault bank's clock of healthy fixes starts now."""
        hyp = self._hyp
        self.start_info["heading_resolved_s"] = float(t)
        self.start_info["heading_resolved_weight"] = float(np.max(hyp.weights))
        self._collapsed_id = int(hyp.ids[hyp.best])
        self.flt = hyp.collapse()
        self._hyp = None
        self._reset_flag = True
        self.bank.forget_innovations()
        if self.bank.t_healthy is not None:
            self.bank.t_healthy = max(self.bank.t_healthy, float(t))

    def _reinit_from(self, track, fx):
        """The GNSS branch won (:meth:`selfnav.ins.hypotheses.FaultBank._ins_lost`): position
        and velocity from the fixes of ``track`` (a quadratic through them, at the last),
        heading from their course (a car moves along its body's forward axis), roll, pitch
        and the sensor estimates kept; the covariance of what was restarted opened as at a
        start; the references dropped (they dead-reckoned from the lost INS)."""
        flt, cfg = self.flt, self.cfg
        tt = np.array([f.t for f in track]) - track[-1].t
        A = np.column_stack([np.ones_like(tt), tt, tt * tt])
        P = np.array([f.p for f in track])
        coef, *_ = np.linalg.lstsq(A, P, rcond=None)
        s_fix = float(np.median([f.sigma for f in track]))
        Ni = np.linalg.inv(A.T @ A)
        s_p, s_v = s_fix * np.sqrt(Ni[0, 0]), s_fix * np.sqrt(Ni[1, 1])
        v = coef[1]
        speed = float(np.hypot(*v))
        origin = self.bank.episode_origin
        lat, lon, _ = offset_to_geodetic(origin[0], origin[1], 0.0,
                                         np.array([coef[0][0], coef[0][1], 0.0]))
        # the state is at the IMU's time, the track's last fix a lead earlier
        lead = flt.t_true - track[-1].t
        lat, lon, _ = offset_to_geodetic(float(lat), float(lon), 0.0,
                                         np.array([v[0] * lead, v[1] * lead, 0.0]))
        roll, pitch, hdg_ins = att.euler_from_dcm_nb(flt.ins.C_nb)
        hdg = float(np.arctan2(v[0], v[1]))
        Pm = flt.P
        flt.ins.set_state(lat=float(lat), lon=float(lon), h=float(fx.h))
        Pm[IR, :] = 0.0
        Pm[:, IR] = 0.0
        Pm[IR, IR] = np.diag([s_p**2 * 4, s_p**2 * 4, fx.sigma_v**2])
        # the other side: only the position was lost (velocity, attitude and sensor
        # estimates as the INS has them)
        kept = flt.copy()
        flt.ins.set_state(velocity_n=np.array([v[0], v[1], 0.0]),
                          C_nb=att.dcm_nb_from_euler(roll, pitch, hdg))
        for sl in (IV, IP):
            Pm[sl, :] = 0.0
            Pm[:, sl] = 0.0
        Pm[IV, IV] = np.diag([(2 * s_v) ** 2, (2 * s_v) ** 2, 1.0])
        att_s = cfg.init.att_sigma
        Pm[IP, IP] = np.diag([att_s[0] ** 2, att_s[1] ** 2, att_s[2] ** 2])
        # the heading is the course of the fixes' velocity: one error with its cross part
        set_course_heading(flt, np.eye(2) * (2 * s_v) ** 2, att_s[2])
        self.bank.restart(fx.t)
        self._ins_vouched = False
        self._reset_flag = True
        self._t_last_fused = fx.t
        self.counts["reinitialisations"] += 1
        # a course from noisy fixes: a heading outside the filter's range is split again;
        # beside it, the INS's own heading and velocity — a course fitted through a stop is
        # reversed, and its σ does not know (simulated drive 4462764194648164540: 105° off
        # at σ 3°, then 300 s of dead reckoning 500–800 m off, issue 18) — at equal odds:
        # the fixes that follow weigh the two
        hyp = split_heading(flt, cfg)
        if cfg.init.heading_split_sigma is not None:
            hyp = hyp or heading_hypotheses(flt, cfg, split=False)
            hyp.join(kept, 0.5, float(wrap_pi(hdg_ins - hdg)))
        self._hyp = hyp
        if self._hyp is not None:
            self.flt = self._hyp.filters[self._hyp.best]

    def _log(self, fx, status, reason, nis_h, nis_v, nis_vel):
        k = fx.index
        self.log["status"][k] = status
        self.log["reason"][k] = reason
        self.log["nis_h"][k] = nis_h
        self.log["nis_v"][k] = nis_v
        self.log["nis_vel"][k] = nis_vel
        self._decisions.append(FixDecision(fx.t, status, reason, nis_h))

    def _sum_choice_differs(self, fb_hyp, t_from) -> bool:
        """Does the start's heading sum as the bank's fallback holds it (from before a drag
        found since ``t_from``) hold another hypothesis best than the one ``M`` is now — and
        was the sum still undecided when the drag began? (One that had decided before it
        decided on clean fixes: going back undid that; simulated odometer drives of seed 103
        and 2, 1863593681399775698 3.3 → 18.9 m, 2200301185186493838 3.5 → 6.1 m.)"""
        if self._hyp is None and self.start_info.get("heading_resolved_s", np.inf) < t_from:
            return False
        now = (int(self._hyp.ids[self._hyp.best]) if self._hyp is not None
               else self._collapsed_id)
        return now is None or int(fb_hyp.ids[fb_hyp.best]) != now

    def _restore_sum(self, hyp, since):
        """The start's heading sum as the bank's fallback carried it since ``since`` (a drag
        found that began before any reference): ``M`` its best hypothesis again."""
        new = hyp.snapshot()
        for f in new.filters:
            self._as_m(f)
        self._hyp = new
        self.flt = new.filters[new.best]
        self._reset_flag = True
        self._exclude_since(since)

    def _reset_to(self, ref_flt, since):
        """``M`` becomes a copy of a dead-reckoning reference (a fault since ``since``)."""
        # the reference was last moved at its own step: bring it to M's sample
        self.flt = self._as_m(ref_flt.copy())
        self._reset_flag = True
        self._exclude_since(since)

    def _as_m(self, f):
        """``f`` made ready to stand for ``M``: its transitions kept for the smoother, and the
        noise scales ``M`` carries now (the hardware's, learnt since ``f`` was branched)."""
        f.track_transition = self.smoother
        f.q_scale, f.bias_scale = self.flt.q_scale, self.flt.bias_scale
        return f

    def _exclude_since(self, since):
        """The fused fixes after ``since`` are marked excluded (a fault since then)."""
        if since is not None:
            for k in range(len(self.fixes) - 1, -1, -1):
                if self.log["t"][k] <= since:
                    break
                if FixStatus(self.log["status"][k]).fused:
                    self.log["excluded"][k] = True

    # ------------------------------------------------------------------ rows
    def _status(self, t) -> NavStatus:
        ep = self.bank.episode if self.bank is not None else None
        if ep is not None and ep.kind != "outage":
            return NavStatus.SUSPECT
        hold = max(self.cfg.integrity.outage_s,
                   2.5 * self._fix_dt_median if self._fix_dt else 0.0)
        return NavStatus.GNSS if t - self._t_last_fused <= hold else NavStatus.DEAD_RECKONING

    def _rows_from(self, tau, states):
        """Rows of the grid passed by the samples at true times ``tau`` (their states)."""
        pos, vel, C = states
        while self._next_row is not None and tau[-1] >= self._next_row - 1e-9:
            T = self._next_row
            k = int(np.searchsorted(tau, T + 1e-9, side="right")) - 1
            if k < 0:
                # the row lies before this block: the state before it (already current)
                self._emit_row(T)
            else:
                self._emit_row(T, tau[k], pos[k], vel[k], C[k])
            self._next_row = self._row_after(T)

    def _emit_row(self, T, tau=None, pos=None, vel=None, C_nb=None):
        flt = self.flt
        if tau is None:
            tau, pos, vel, C_nb = (flt.t_true, np.array([flt.ins.lat, flt.ins.lon, flt.ins.h]),
                                   flt.ins.velocity_n, flt.ins.C_nb)
            if self._hyp is not None:          # the heading hypotheses' mean
                pos, vel = self._hyp.mean_point()
        st = np.zeros(PACK_SIZE)
        st[:21] = np.concatenate((pos, vel, np.asarray(C_nb).reshape(9), flt.bg, flt.ba))
        st[_PACK_LEVER] = flt.lever_b
        dt_row = T - tau
        P = flt.P
        sig = np.sqrt(np.maximum(P.diagonal()[:9], 0.0))
        if self._hyp is None:
            C_out = output_covariance(P, flt.layout, C_nb, vel, flt.lever_b)
        else:      # the whole Gaussian sum about its mean
            C_out = self._hyp.output_covariance()
        C_out = self._vouched(C_out)
        sig[IR] = np.sqrt(np.maximum(np.diag(C_out), 0.0))
        self._rows.append((T, dt_row, st, sig,
                           _STATUS_CODE[self._status(T)],
                           self.bank.protection_level(flt, T, C_out[:2, :2]),
                           len(self._rec["t"]) - 1 if self.smoother else -1,
                           len(self._segments), flt.layout.lever is not None))

    def _vouched(self, C_out):
        """The output covariance with the horizontal block the fault bank can vouch for
        (:meth:`~selfnav.ins.hypotheses.FaultBank.doubt`)."""
        C_m = C_out[:2, :2]
        C_h = self.bank.doubt(C_m)
        if self.road_aid is not None and hasattr(self.road_aid, "doubt"):
            C_h = self.road_aid.doubt(C_h)
        if C_h is C_m:
            return C_out
        C_out = C_out.copy()
        C_out[:2, :2] = C_h
        return C_out

    def _record_epoch(self):
        if not self.smoother:
            if self._reset_flag:
                self._reset_flag = False
            return
        flt, r = self.flt, self._rec
        r["t"].append(flt.t_true)
        r["state"].append(pack_state(flt))
        r["P"].append(flt.P.copy())
        r["Pm"].append(self._Pm if self._Pm is not None else flt.P.copy())
        r["Phi"].append(flt.take_transition())
        r["dx"].append(self._dx.copy())
        r["brk"].append(self._reset_flag)
        self._reset_flag = False

    # ================================================================== output
    def _state_now(self) -> NavState:
        if self.flt is None:
            nan = float("nan")
            return NavState(self.startup.t_imu if self.startup else nan, nan, nan, nan,
                            np.full(3, np.nan), nan, nan, nan, nan, NavStatus.ALIGNING,
                            decisions=tuple(self._decisions))
        flt = self.flt
        lat, lon, h = flt.ins.lat, flt.ins.lon, flt.ins.h
        vel = flt.ins.velocity_n
        C_nb = flt.ins.C_nb
        if self._hyp is not None:              # the heading hypotheses' mean
            (lat, lon, h), vel = self._hyp.mean_point()
        if flt.layout.lever is not None:
            lat, lon, h = offset_to_geodetic(float(lat), float(lon), float(h),
                                             C_nb.T @ flt.lever_b)
        roll, pitch, hdg = att.euler_from_dcm_nb(C_nb)
        if self._hyp is None:
            C_out = output_covariance(flt.P, flt.layout, C_nb, flt.ins.velocity_n, flt.lever_b)
        else:
            C_out = self._hyp.output_covariance()
        C_out = self._vouched(C_out)
        s = np.sqrt(np.maximum(C_out.diagonal(), 0.0))
        t = flt.t_true
        return NavState(t, math.degrees(float(lat)), math.degrees(float(lon)), float(h),
                        vel, math.degrees(roll), math.degrees(pitch),
                        math.degrees(hdg) % 360.0, math.hypot(s[0], s[1]),
                        self._status(t), self.bank.protection_level(flt, t, C_out[:2, :2]), s,
                        tuple(self._decisions))

    @property
    def state(self) -> NavState:
        """The current state (:class:`NavState`)."""
        return self._state_now()

    @property
    def started(self) -> bool:
        return self.flt is not None

    def finish(self):
        """End of the stream: the epochs up to the last IMU sample, the open episode closed."""
        if self.flt is None:
            return
        while self._next_event() <= self.flt.t_true + 1e-9:
            self._process_next()
        t = self.flt.t_true
        while self._next_row is not None and self._next_row <= t + 1e-9:
            self._emit_row(self._next_row)
            self._next_row = self._row_after(self._next_row)
        for te, kind, _, payload in self._events:
            if kind == _KIND_FIX:
                self.log["reason"][payload.index] = "after the last IMU sample"
        if self._hyp is not None:
            self.flt = self._hyp.collapse()
            self._hyp = None
        self.bank.finish(t)

    def result(self, smooth: bool = False) -> NavigatorResult:
        """The rows as a :class:`NavigatorResult`; ``smooth``: RTS-smoothed (needs
        ``smoother=True``; uses the whole record — post-processing, not real time). Each
        stretch between IMU gaps is smoothed on its own."""
        last = self.flt or self._last_flt
        if last is None:
            why = self.startup.last_error if self.startup is not None else "no data"
            raise SelfnavError(f"the navigator never started: {why}")
        if smooth and not self.smoother:
            raise SelfnavError("this navigator kept no smoother record (smoother=False)")
        rows = self._rows
        n = len(rows)
        T = np.array([r[0] for r in rows])
        dtr = np.array([r[1] for r in rows])
        st = np.array([r[2] for r in rows]).reshape(n, PACK_SIZE)
        sig = np.array([r[3] for r in rows]).reshape(n, 9)
        code = np.array([r[4] for r in rows], int)
        pl = np.array([r[5] for r in rows])
        ep_idx = np.array([r[6] for r in rows], int)
        seg = np.array([r[7] for r in rows], int)
        lever = np.array([r[8] for r in rows], bool)
        smoothed = False
        segments = self._segments + ([(self._rec, self.flt.layout)] if self.flt is not None
                                     else [])
        if smooth and n:
            for s_id, (rec, lay) in enumerate(segments):
                if len(rec["t"]) <= 2:
                    continue
                _, Ps, eps = rts_smooth(np.asarray(rec["state"]), np.asarray(rec["P"]),
                                        np.asarray(rec["Pm"]), np.asarray(rec["Phi"]),
                                        np.asarray(rec["dx"]), lay,
                                        np.asarray(rec["brk"], bool), return_errors=True)
                t_rec = np.asarray(rec["t"])
                for i in np.flatnonzero((seg == s_id) & (ep_idx >= 0)):
                    k = ep_idx[i]
                    e = eps[k].copy()
                    e[IR] += e[IV] * (T[i] - dtr[i] - t_rec[k])
                    st[i] = apply_error(st[i], e, lay)
                    sig[i] = np.sqrt(np.maximum(np.diag(Ps[k])[:9], 0.0))
                    C_out = output_covariance(Ps[k], lay, st[i, PACK["C"]].reshape(3, 3),
                                              st[i, PACK["vel"]], st[i, PACK["lever"]])
                    sig[i, IR] = np.sqrt(np.maximum(np.diag(C_out), 0.0))
            smoothed = True
        # the row time: first order from the sample's state (under one IMU sample)
        vel = st[:, PACK["vel"]]
        C = st[:, PACK["C"]].reshape(n, 3, 3)
        d = vel * dtr[:, None]
        d[lever] += np.einsum("nji,nj->ni", C[lever], st[lever][:, PACK["lever"]])
        lat, lon, h = offset_to_geodetic(st[:, 0], st[:, 1], st[:, 2], d) if n else (
            st[:, 0], st[:, 1], st[:, 2])
        traj = Trajectory(T, np.asarray(lat), np.asarray(lon), np.asarray(h), vel, C,
                          "selfnav navigator" + (" (antenna)" if last.layout.lever
                                                 is not None else ""))
        names = list(NavStatus)
        status = np.array([str(names[c]) for c in code], dtype=object)
        log = {k: np.asarray(v, dtype=object if k in ("status", "reason") else None)
               for k, v in self.log.items()}
        log["status"] = np.array([str(FixStatus(s)) for s in self.log["status"]], dtype=object)
        bank_eps = self.bank.episodes if self.bank is not None else []
        return NavigatorResult(traj, sig[:, IR], sig[:, IV], sig[:, IP], status, pl, log,
                               [e.to_dict() for e in self._episodes_done + bank_eps],
                               self.stats(), smoothed, st[:, PACK["bg"]], st[:, PACK["ba"]])

    def stats(self) -> dict:
        """The counts and estimates of the run (what ``--json`` prints)."""
        st = [FixStatus(s) for s in self.log["status"]]
        counts = {s.value: 0 for s in FixStatus}
        for s in st:
            counts[s.value] += 1
        flt = self.flt or self._last_flt
        out = {"fixes": len(st), "fix_status": counts,
               "fixes_excluded_later": int(np.sum(self.log["excluded"])),
               "start_s": self.start_info.get("t"),
               "start_attempts": self.start_info.get("attempts"),
               "start_kind": self.start_info.get("kind"),
               "start_heading": self.start_info.get("heading_source"),
               "heading_hypotheses": self.start_info.get("heading_hypotheses", 0),
               "platform": self.start_info.get("platform", self.cfg.vehicle.platform),
               "nhc": self.start_info.get("nhc", bool(self.cfg.vehicle.nhc)),
               "episodes": len(self._episodes_done) + (len(self.bank.episodes) if self.bank else 0),
               "resets_to_dead_reckoning": self.bank.alarms if self.bank else 0,
               "recoveries": self.bank.recoveries if self.bank else 0,
               "reinitialisations": self.counts["reinitialisations"],
               "time_offset_resets": self.counts["time_offset_resets"],
               "restarts": list(self.restarts)}
        if self.cfg.vehicle.use_magnetometer:
            mc = self.magcal
            out["magnetometer"] = {
                "updates": self.counts["magnetometer_updates"],
                "refused": self.counts["magnetometer_refused"],
                "bounds": self.counts["magnetometer_bounds"],
                "calibrated": bool(mc is not None and mc.ready),
                "heading_sigma_deg": (math.degrees(mc.sigma) if mc is not None and mc.ready
                                      else None),
                "calibrated_from": None if mc is None else mc.source,
                "calibrated_s": None if mc is None else mc.t_ready,
                "offset_levelled": (None if mc is None or mc.centre is None
                                    else [float(x) for x in mc.centre])}
        if self.cfg.vehicle.speed_hold:
            out["pace_priors"] = self.counts["pace_priors"]
        rc = getattr(self.road_aid, "counts", None)
        if rc is not None:
            # the map's constraints taken (selfnav.roads.aid): road lines, corner legs and arcs,
            # level-road priors, corner fixes — and the corner fixes of the fault bank's
            # map-aided dead reckonings (``dr_corner``)
            out["road_constraints"] = {k: int(v) for k, v in rc.items()}
        md = getattr(self.road_aid, "map_doubt", None)
        if md is not None:
            # the map's doubt (selfnav.roads.doubt): seconds the reported σ was held to the
            # solution's offset from the roads running its way, the largest, the first look
            out["map_doubt"] = {"seconds": round(float(md.seconds), 1),
                                "largest_m": round(float(md.largest_m), 1),
                                "first_s": md.first_s,
                                "spans": [[round(a, 1), None if b is None else round(b, 1),
                                           round(d, 1)] for a, b, d in md.spans]}
        if flt is not None:
            out.update({
                "imu_time_offset_s": flt.time_offset_applied + flt.time_offset,
                "imu_time_offset_sigma_s": (float(np.sqrt(flt.P[flt.layout.toff, flt.layout.toff][0, 0]))
                                            if flt.layout.toff is not None else 0.0),
                "lever_arm_m": [float(x) for x in flt.lever_b],
                "position_of": "antenna" if flt.layout.lever is not None else "imu",
                "noise_scale": float(flt.q_scale),
                "covariance_reopenings": 0 if self.adapter is None else self.adapter.reopenings,
                "states": int(flt.nx)})
            if self.cfg.vehicle.nhc:
                ch = self.nhc_check
                out["nhc_check"] = {"largest_sigma_mps": float(ch.largest),
                                    "largest_rms_mps": float(ch.largest_rms),
                                    "slip_seen_s": None if ch.seen is None else ch.seen[0],
                                    "largest_widening": [float(x) for x in (
                                        ch.largest_scale if self._nhc_adapts() else (1, 1))]}
            if flt.layout.tdrift is not None:
                j = flt.layout.tdrift.start
                out["imu_clock_drift_ppm"] = 1e6 * float(flt.clock_drift)
                out["imu_clock_drift_sigma_ppm"] = 1e6 * float(np.sqrt(max(flt.P[j, j], 0.0)))
            if flt.layout.vlag is not None:
                out["gnss_velocity_lag_s"] = float(flt.velocity_lag)
            if flt.layout.odo is not None:
                out["odometer_scale_factor"] = float(flt.odo_scale)
                j = flt.layout.odo.start
                out["odometer_scale_factor_sigma"] = float(np.sqrt(max(flt.P[j, j], 0.0)))
            if flt.layout.mu is not None:
                out["mounting_deg"] = [float(x) for x in np.degrees(flt.mu)]
        return out


def feed(nav: Navigator, imu, gnss=None, *, odometer=None, progress=None,
         chunk: int = 2000) -> Navigator:
    """Feed whole records to a navigator in the real-time order — the batch run of
    :func:`selfnav.navigate` — and finish it.

    Each fix, wheel-speed and magnetometer sample (the IMU's ``mag_b`` columns) is handed over
    just before the first IMU sample whose stamp reaches its time, as the loop of
    docs/realtime.md does sample by sample; between them the IMU goes in chunks of at most
    ``chunk`` samples (the chunking does not change the result: one sample a call gives the
    same rows). ``progress(fraction)`` is called after each chunk.
    """
    n = len(imu.t)
    off = nav.offset_applied
    ts = np.asarray(imu.t, float) + off
    ng = 0 if gnss is None else len(gnss.t)
    no = 0 if odometer is None else len(odometer.t)
    mag = getattr(imu, "mag_b", None)
    mag_step = max(1, int(round(nav.cfg.vehicle.mag_step / imu.dt))) if mag is not None and n > 1 else 0

    def col(x, i):
        return None if x is None else x[i]

    # (the IMU sample each arrives before, order, kind, index)
    arrivals = []
    if ng:
        arrivals += [(int(i), 0, k) for k, i in
                     enumerate(np.searchsorted(ts, np.asarray(gnss.t, float), side="left"))]
    if no:
        arrivals += [(int(i), 1, k) for k, i in
                     enumerate(np.searchsorted(ts, np.asarray(odometer.t, float) + off,
                                               side="left"))]
    if mag_step:
        arrivals += [(int(i), 2, int(i)) for i in range(0, n, mag_step)]
    arrivals.sort()
    a = 0
    i0 = 0
    while i0 < n or a < len(arrivals):
        while a < len(arrivals) and arrivals[a][0] <= i0:
            _, kind, k = arrivals[a]
            if kind == 0:
                nav.add_fix(gnss.t[k], math.degrees(gnss.lat[k]), math.degrees(gnss.lon[k]),
                            gnss.h[k], col(gnss.sigma_m, k), col(gnss.velocity_n, k),
                            col(gnss.quality, k), sigma_v_m=col(gnss.sigma_v_m, k),
                            sigma_vel_mps=col(gnss.sigma_vel_mps, k))
            elif kind == 1:
                nav.add_odometer(odometer.t[k], odometer.speed_mps[k])
            else:
                nav.add_magnetometer(imu.t[k], mag[k])
            a += 1
        if i0 >= n:
            break
        i1 = min(n, i0 + chunk, arrivals[a][0] if a < len(arrivals) else n)
        nav._add_imu(imu.t[i0:i1], imu.omega_ib_b[i0:i1], imu.f_ib_b[i0:i1])
        i0 = i1
        if progress is not None:
            progress(i1 / n)
    nav.finish()
    return nav


__all__ = ["Navigator", "NavState", "NavigatorResult", "DEFAULT_OUT_RATE_HZ", "feed",
           "initial_filter"]
