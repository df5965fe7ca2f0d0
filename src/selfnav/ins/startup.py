"""The navigator's start-up stage: from power-on to the first state, from the past only.

Until it can start, the navigator buffers what arrives (IMU samples, fixes, wheel speed) in a
:class:`StartUp`. At every fix (at most once per ``retry_s`` of data) it tries to start on
what it has — never on anything later:

1. **Noise at rest** (:func:`selfnav.ins.calibrate.calibrated_config`) on the still segments
   of the buffer: the preset is a prior, the measured white noise wins.
2. **The start state** (:func:`selfnav.ins.align.robust_init`): a run of fixes that look
   healthy without an INS, then the first straight constant-speed window of fixes after it
   (heading from the course), roll and pitch levelled in the last still second before; with a
   map, the fixes around that start must lie on roads that run their way
   (:func:`selfnav.roads.aid.start_on_roads` — passed in as ``start_check``, so this module
   does not depend on the map). A window must be *complete* in the buffer: the start it gives
   is the one any later run of the same data gives at the same moment.
3. The navigator then replays the buffer from the start time to now through the normal epochs
   (no rows are emitted for that stretch: they were not available in real time).

A state given by another navigator (``--init``) starts at once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from selfnav.errors import SelfnavError
from selfnav.ins import calibrate
from selfnav.ins.align import fix_sigmas, robust_init
from selfnav.ins.anystart import any_start, displaced, moving_seconds, recent_speed
from selfnav.ins.config import SLOW_PLATFORM, FilterConfig
from selfnav.types import GnssData, ImuData


@dataclass
class Start:
    """What the start-up found: the initial state (``t`` true time, ``lat, lon, h,
    velocity_n, C_nb`` and σ, as :class:`selfnav.ins.align.init_from_gnss` gives), the
    configuration with the measured noise, what was measured and the notes on it."""

    init: dict
    cfg: FilterConfig
    measured: calibrate.MeasuredNoise | None = None
    notes: list = field(default_factory=list)


class StartUp:
    """Buffers of the stream before the start (module docstring).

    Parameters
    ----------
    cfg : FilterConfig
    time_offset_applied : float
        Added to the IMU stamps to get true time (the reader's and the user's offset), s.
    start_check : callable, optional
        ``start_check(imu, gnss, cfg, start=) -> dict | None``: the start (``start(imu,
        gnss)``, this stage's own) checked by the map; it must use only the data it is given.
    max_buffer_s : float
        Seconds of data kept before the start (older samples are dropped).
    retry_s : float
        Seconds of data between two start attempts.
    """

    def __init__(self, cfg: FilterConfig, *, time_offset_applied: float = 0.0,
                 start_check=None, max_buffer_s: float = 600.0, retry_s: float = 1.0):
        self.cfg = cfg
        self.offset = float(time_offset_applied)
        self.start_check = start_check
        self.max_buffer_s = max_buffer_s
        self.retry_s = retry_s
        self.imu_t, self.imu_w, self.imu_f = [], [], []
        self.fixes = []            # _Fix objects (true time)
        self.odometer = []         # (t, speed, sigma)
        self.magnetometer = []     # (t, mag_b)
        self.last_error = "no GNSS fix yet"
        self.attempts = 0
        self.grid = None           # true time of the next start attempt (navigator's)

    # ------------------------------------------------------------------ input
    def add_imu(self, t, w, f):
        self.imu_t.append(np.asarray(t, float))
        self.imu_w.append(np.asarray(w, float))
        self.imu_f.append(np.asarray(f, float))

    def add_fix(self, fix):
        self.fixes.append(fix)

    @property
    def t_imu(self) -> float:
        """True time of the last buffered IMU sample (−inf before the first)."""
        return float(self.imu_t[-1][-1]) + self.offset if self.imu_t else -np.inf

    def imu(self) -> ImuData:
        """The buffered IMU samples (stamps as given)."""
        if not self.imu_t:
            return ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
        t = np.concatenate(self.imu_t)
        w = np.concatenate(self.imu_w)
        f = np.concatenate(self.imu_f)
        self.imu_t, self.imu_w, self.imu_f = [t], [w], [f]
        return ImuData(t, w, f, source="start-up buffer")

    def gnss(self, t_max=np.inf) -> GnssData:
        """The buffered fixes up to true time ``t_max`` as GNSS data (true time)."""
        fx = [f for f in self.fixes if f.t <= t_max]
        n = len(fx)
        vel = None
        if fx and all(f.velocity_n is not None for f in fx):
            vel = np.array([f.velocity_n for f in fx])
        return GnssData(np.array([f.t for f in fx]), np.array([f.lat for f in fx]),
                        np.array([f.lon for f in fx]), np.array([f.h for f in fx]),
                        np.array([f.sigma_h for f in fx]) if n else np.zeros(0), vel,
                        source="start-up buffer")

    def _trim(self):
        if not self.imu_t:
            return
        t_end = self.t_imu
        cut = t_end - self.max_buffer_s
        imu = self.imu()
        keep = imu.t + self.offset >= cut
        if not keep.all():
            self.imu_t, self.imu_w, self.imu_f = [imu.t[keep]], [imu.omega_ib_b[keep]], \
                [imu.f_ib_b[keep]]
            self.fixes = [f for f in self.fixes if f.t >= cut]
            self.odometer = [o for o in self.odometer if o[0] >= cut]
            self.magnetometer = [m for m in self.magnetometer if m[0] >= cut]

    # ------------------------------------------------------------------ the attempt
    def next_attempt(self, t) -> float:
        """The true time of the next start attempt at or after ``t`` (a grid of ``retry_s``)."""
        return (np.floor(t / self.retry_s - 1e-9) + 1.0) * self.retry_s

    def try_start(self) -> Start | None:
        """A start from the buffer, or None (not yet: :attr:`last_error` says why)."""
        t_now = self.t_imu
        self._trim()
        gnss = self.gnss(t_now)
        if len(gnss) < 10:
            self.last_error = f"{len(gnss)} GNSS fixes so far: not enough to start"
            return None
        imu = self.imu()
        if len(imu) < 10:
            self.last_error = "too few IMU samples"
            return None
        self.attempts += 1
        # the IMU on the true time base for the start (stamps + the applied offset)
        imu_true = imu.shifted(self.offset)
        cfg, measured, notes = calibrate.calibrated_config(self.cfg, imu_true, gnss)

        def start(imu_, gnss_):
            if cfg.init.any_start == "now":
                return any_start(imu_, gnss_, cfg, self.magnetometer)
            try:
                return robust_init(imu_, gnss_, cfg=cfg, require_healthy=True)
            except SelfnavError as e:
                # a platform that moves but never gives the car's straight fast run
                init_, cfg_ = self._fallback(imu_, gnss_, cfg, e)
                return dict(init_, start_cfg=cfg_)

        try:
            if self.start_check is not None:            # the same start, checked on the map
                init = self.start_check(imu_true, gnss, cfg, start=start)
            else:
                init = start(imu_true, gnss)
        except SelfnavError as e:
            self.last_error = str(e)
            return None
        if init is None:
            self.last_error = "no start on the map's roads yet"
            return None
        init = dict(init)
        cfg = init.pop("start_cfg", cfg)
        if (("gyro_bias" not in init or init.get("gyro_bias_from") == "window")
                and measured is not None and measured.gyro_bias is not None):
            # a stop in the buffer measured the gyro bias (the Earth rate in its σ); the start
            # in motion has not (its own look back is 30 s: drive_0708 crept for 18 s after
            # its stop) and would begin from the grade's prior — a consumer part's 1 °/s —
            # or from its window's level axes alone
            init.pop("gyro_bias_cov", None)
            init.pop("gyro_bias_from", None)
            init["gyro_bias"] = np.asarray(measured.gyro_bias, float)
            init["gyro_bias_sigma"] = np.full(3, math.hypot(measured.gyro_bias_sigma,
                                                            cfg.imu.gyro_bias_instability))
        return Start(init, cfg, measured, notes)

    def _fallback(self, imu, gnss, cfg, error):
        """The start of any platform (``any_start="fallback"``) once the fixes have shown
        ``any_start_motion_s`` of motion and moved beyond their noise within 30 s, slower
        than ``any_start_speed`` (a walker, a robot, a boat, a car in a jam); else
        ``error`` again. A platform moving fast waits for the car's straight run; one at rest
        (a car about to drive, a walker holding the unit) waits for motion."""
        if cfg.init.any_start != "fallback":
            raise error
        sig = fix_sigmas(gnss, cfg.gnss.sigma_floor)
        moved = moving_seconds(gnss, sig)
        if moved < cfg.init.any_start_motion_s:
            raise error
        speed = recent_speed(gnss, sig)
        if speed >= cfg.init.any_start_speed or not displaced(gnss, sig):
            raise error
        if cfg.vehicle.platform.startswith("auto"):
            # what the user set by name stands (the NHC, the magnetometer, the pace, ...)
            keep = set(cfg.vehicle.user_set)
            cfg = cfg.updated(**{k: v for k, v in SLOW_PLATFORM.items() if k not in keep})
        init = any_start(imu, gnss, cfg, self.magnetometer)
        init["fallback"] = (f"{moved:.0f} s of motion at {speed:.1f} m/s without a straight "
                            f"run faster than {cfg.init.min_speed:g} m/s")
        return init, cfg

__all__ = ["Start", "StartUp"]
