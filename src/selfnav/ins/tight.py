"""Tightly coupled INS/GNSS: the strapdown error-state filter updated by each satellite's
pseudorange and range rate (issue 23, part 3; docs/gnss.md).

The filter is :class:`selfnav.ins.ekf.InsGnssFilter` with the receiver clock bias and drift
as two more states (``states.receiver_clock``); the measurements are
:class:`selfnav.ins.measurements.Pseudoranges` and :class:`~selfnav.ins.measurements.RangeRates`
(the antenna's position and velocity, lever arm included, into each satellite's range). What
a loosely coupled filter cannot do, this one does: two or three satellites still correct the
INS along their lines of sight, where no fix exists.

Per epoch (:meth:`TightIns.add_epoch`), causal:

1. the INS is propagated to the epoch (:meth:`TightIns.add_imu`);
2. **each satellite is judged against the prediction**: its innovation
   ``ν_i = h_i(x̃) − ρ_i`` and variance ``S_i = H_i P H_iᵀ + R_i``; beyond the χ²₁ gate at
   ``alpha`` it is excluded (one test per satellite, independent of the others: the prior, not
   the other satellites, is the reference, so several faulty satellites are excluded at once);
3. **a receiver clock jump** (u-blox receivers step their clock by milliseconds) moves every
   pseudorange together: when most satellites fail and their innovations agree after their
   median is removed, the clock takes the median and its σ is reopened;
4. **no lock-out**: when most satellites fail but agree among themselves (their own
   least-squares fix passes its χ² test), the INS is what is wrong and its position and
   velocity covariance is reopened by the disagreement (:meth:`TightIns._reopen`);
5. the satellites kept update the filter in one joint update; then the range rates the same way.

Every constellation of the record is used: the reference clock is GPS's where there is GPS, the
others' offsets against it are states (``states.inter_system``). With ``platform="car"`` the
non-holonomic constraint and a level-road prior are applied between epochs, each only when its
χ² test passes (an IMU not along the car is not forced to be).

The pseudoranges' variance is the C/N0 model of :mod:`selfnav.gnss.raw` times a causal variance
factor (:class:`selfnav.gnss.fde.VarianceScale`) of the past post-fit residuals.

The receiver clock's frequency noise can be learnt from the past (:class:`ClockNoise`,
``learn_clock``; off by default: too noisy an estimate to trust, docs/gnss.md).

**Start** (:func:`start_tight`): the first epoch with a least-squares fix that passes its χ²
test (:func:`selfnav.gnss.raw.spp_raw`, causal per epoch). At rest (the fixes' Doppler speed
under ``rest_speed`` and the IMU still over ``rest_s``): levelling and gyrocompassing
(:func:`selfnav.ins.align.coarse_align`) when the gyros can (heading σ under
``max_gyrocompass_sigma``), else the heading from the Doppler course once the vehicle moves
(:func:`selfnav.ins.align.align_in_motion`); the clock bias and drift from the fix.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from selfnav.errors import SelfnavError
from selfnav.gnss.fde import VarianceScale
from selfnav.gnss.mixture import MixtureModel, ResidualCorrelation
from selfnav.gnss.raw import (C_LIGHT, CorrectedObservations, RawSppConfig, correct_observations,
                              spp_raw)
from selfnav.io.gnss_raw import BEIDOU, GALILEO, GLONASS, GPS, QZSS, RawGnss, sat_names
from selfnav.ins.align import align_in_motion, coarse_align
from selfnav.ins.config import PLATFORMS, FilterConfig
from selfnav.ins.ekf import IR, IV, InsGnssFilter
from selfnav.ins.measurements import LevelRoad, NonHolonomic, Pseudoranges, RangeRates
from selfnav.quantiles import chi2_ppf
from selfnav.types import ImuData

DEG = np.pi / 180.0
SYSTEM_LETTERS = {GPS: "G", GLONASS: "R", GALILEO: "E", BEIDOU: "C", QZSS: "J"}


@dataclass
class TightInsConfig:
    """Options of the tightly coupled INS/GNSS filter.

    Attributes
    ----------
    grade : the IMU's grade (:data:`selfnav.sensors.GRADES`): its error model is the filter's
    gnss : the raw observations' preparation (signals, corrections, C/N0 variance model); the
        code is not smoothed (the filter averages; a smoothed code is correlated over epochs)
    alpha : false-alarm probability of each satellite's innovation test
    doppler : use the range rates
    rest_speed : m/s, the fixes' Doppler speed under which a start may be at rest
    rest_s : s at rest before a start at rest (the gyrocompass averages over them)
    rest_rate : rad/s, the IMU's mean rate at rest is under this (not turning)
    max_gyrocompass_sigma : rad; a gyrocompass heading less sure than this is not used (the
        heading then comes from the course once moving)
    min_speed : m/s, the course gives the heading above this speed (start in motion)
    pos_sigma_floor : m, the least initial position σ (a least-squares fix's own σ is optimistic
        where its satellites share errors)
    reopen_s : s over which a position error found when the INS is reopened is taken to have
        grown (its velocity share)
    learn_clock : learn the receiver clock's frequency random walk from the past epochs'
        Doppler solutions (:class:`ClockNoise`), within ``drift_rw_bounds`` (m/s/√s); off by
        default: the Doppler solutions' noise (0.06–0.12 m/s per epoch on the simulated
        drives) hides a TCXO's 0.01 m/s/√s over minutes, the estimate often fell to the floor
        and a clock believed that stable made three satellites overconfident (RMS error/σ
        3.2 on one drive, docs/gnss.md); the configuration's TCXO figure stands
    mixture : each satellite's error a mixture of line of sight and delayed components
        (:class:`selfnav.gnss.mixture.MixtureModel`, fitted on the last ``tune_window`` s of
        post-fit residuals every ``tune_every`` s), the component chosen per satellite by its
        residual (max-mixture) — the odometry filter's model for reflected signals; with
        ``correlation`` its variances times the AR(1) inflation ``(1 + ρ)/(1 − ρ)`` of the
        line-of-sight residuals' lag-one correlation (at most ``max_inflation``)
    platform : ``"car"``: the non-holonomic constraint (every ``constraint_s`` while faster than
        ``constraint_speed`` m/s) and a level-road prior (:data:`selfnav.ins.config.PLATFORMS`'s
        car); anything else: no motion constraint (a walker, a boat or a drone slides sideways)
    multi_system : use every constellation (up to five), their clock offsets against the
        reference one (GPS where present) as states; else the most observed one alone
    filter : overrides of :class:`selfnav.ins.config.FilterConfig` fields by name
    """

    grade: str = "tactical"
    gnss: RawSppConfig = field(default_factory=lambda: RawSppConfig(smoothing_s=0.0))
    alpha: float = 1e-3
    doppler: bool = True
    rest_speed: float = 0.3
    rest_s: float = 30.0
    rest_rate: float = 1.0 * DEG
    max_gyrocompass_sigma: float = 10.0 * DEG
    min_speed: float = 3.0
    pos_sigma_floor: float = 5.0
    reopen_s: float = 10.0
    learn_clock: bool = False
    platform: str = "auto"
    mixture: bool = False
    tune_window: float = 60.0
    tune_every: float = 5.0
    correlation: bool = True
    max_inflation: float = 10.0
    constraint_s: float = 0.1
    constraint_speed: float = 1.0
    multi_system: bool = True
    drift_rw_bounds: tuple = (0.002, 1.0)
    filter: dict = field(default_factory=dict)


@dataclass
class EpochDecision:
    """What one epoch's satellites did: names used and excluded, the pseudorange innovations
    normalised by their σ (``z``, by name), a clock jump taken (m, 0 if none)."""

    t: float
    used: list
    excluded: list
    z: dict
    clock_jump_m: float = 0.0
    doppler_used: int = 0
    reopened: bool = False
    delayed: list = field(default_factory=list)


class TightIns:
    """The tightly coupled filter after its start: feed IMU samples and GNSS epochs in time
    order (:meth:`add_imu`, :meth:`add_epoch`); the state is :attr:`flt`."""

    def __init__(self, flt: InsGnssFilter, cfg: TightInsConfig):
        self.flt = flt
        self.cfg = cfg
        self.scale = VarianceScale()
        self._gate = float(chi2_ppf(1.0 - cfg.alpha, 1))
        self._t_last = flt.ins.t
        self._t_grade = -np.inf
        self._gate2 = float(chi2_ppf(1.0 - cfg.alpha, 2))
        self.nhc_refused = 0
        # a receiver's code can be decimetres good (the PSINS record's): the floors are low
        self.mixture = MixtureModel(sigma_los_min=0.1, sigma_los45_min=0.05) if cfg.mixture \
            else None
        self.correlation = ResidualCorrelation(cfg.tune_window, 2.5, cfg.max_inflation)
        self._tune_buf: list = []
        self._next_tune = -np.inf

    def add_imu(self, t, omega_b, f_b):
        """A block of IMU samples (stamps in GNSS time, rates and specific forces); with a
        car's constraints (``platform="car"``), in blocks of ``constraint_s`` each followed by
        the non-holonomic constraint while moving, and a level-road prior each second."""
        t = np.atleast_1d(np.asarray(t, float))
        if len(t) == 0:
            return
        omega_b, f_b = np.asarray(omega_b), np.asarray(f_b)
        if self.cfg.platform != "car":
            self._predict(t, omega_b, f_b)
            return
        edges = np.arange(self._t_last + self.cfg.constraint_s, t[-1], self.cfg.constraint_s)
        for block in np.split(np.arange(len(t)), np.searchsorted(t, edges, side="right")):
            if len(block) == 0:
                continue
            self._predict(t[block], omega_b[block], f_b[block])
            self._constrain()

    def _predict(self, t, omega_b, f_b):
        dt = np.diff(np.concatenate([[self._t_last], t]))
        self.flt.predict(t, omega_b * dt[:, None], f_b * dt[:, None], dt)
        self._t_last = float(t[-1])

    def _constrain(self):
        """A car on a road: no sideways or vertical slip at the rear axle while it moves
        (docs/ekf.md), and the road's grade each second (:class:`LevelRoad`)."""
        flt, veh = self.flt, self.flt.cfg.vehicle
        speed = float(np.hypot(*flt.ins.velocity_n[:2]))
        if speed < self.cfg.constraint_speed:
            return
        m = NonHolonomic(veh.nhc_sigma, veh.nhc_sigma_up or veh.nhc_sigma).model(flt)
        # a constraint the state refuses (a slip, or an IMU not along the car) is not forced
        if flt.nis(m) <= self._gate2:
            flt.update(m)
        else:
            self.nhc_refused += 1
        if veh.grade_sigma is not None and self._t_last - self._t_grade >= 1.0 - 1e-9:
            self._t_grade = self._t_last
            flt.update(LevelRoad.at_speed(veh.grade_sigma, speed, veh.grade_corr_s).model(flt))

    def _reopen(self, m, S) -> bool:
        """Most satellites refuse the prediction: if they agree among themselves (their own
        least-squares fix passes its χ² test), the INS is what is wrong — its position (and
        velocity) covariance is reopened by the disagreement, so the satellites are taken
        again rather than refused for ever (a filter that rejects on large innovations locks
        itself out)."""
        flt = self.flt
        cols = [0, 1, 2, flt.layout.clk.start]
        if flt.layout.isb is not None:
            cols += [flt.layout.isb.start + int(k) for k in np.unique(self._slot[self._slot >= 0])]
        try:
            dx, C, T, dof = _snapshot(m, cols)
        except np.linalg.LinAlgError:
            return False
        if dof < 1 or T > chi2_ppf(1.0 - self.cfg.alpha, dof):
            return False
        d = dx[:3]
        add = np.outer(d, d) + C[:3, :3]
        flt.P[IR, IR] += add
        flt.P[IV, IV] += add / self.cfg.reopen_s**2
        i = flt.layout.clk.start
        flt.P[i, i] += dx[3] ** 2 + C[3, 3]
        return True

    def _components(self, t, pr, sat, slot, cn0):
        """Max-mixture (:class:`selfnav.gnss.mixture.MixtureModel`, the odometry filter's): each
        satellite's component — line of sight or delayed — by its residual at the prediction;
        returns the pseudoranges less the chosen means, their variances, the components."""
        flt = self.flt
        m = Pseudoranges(t, pr, sat, np.ones(len(pr)), slot).model(flt)
        spread = np.einsum("ij,jk,ik->i", m.H, flt.P, m.H)
        w, mu, var = self.mixture.components(cn0)
        tot = var + spread[:, None]
        e = -m.r
        ll = np.log(w) - 0.5 * (np.log(tot) + (e[:, None] - mu) ** 2 / tot)
        comp = np.argmax(ll, axis=1)
        rows = np.arange(len(pr))
        return pr - mu[rows, comp], var[rows, comp], comp

    def _tune(self, t, pr, sat, slot, cn0):
        """The mixture learns from the post-fit residuals of the last ``tune_window`` s."""
        post = Pseudoranges(t, pr, sat, np.ones(len(pr)), slot).model(self.flt)
        self._tune_buf.append((t, -post.r, np.asarray(cn0, float)))
        while self._tune_buf and self._tune_buf[0][0] < t - self.cfg.tune_window:
            self._tune_buf.pop(0)
        if t >= self._next_tune:
            self.mixture.fit(np.concatenate([b[1] for b in self._tune_buf]),
                             np.concatenate([b[2] for b in self._tune_buf]))
            self._next_tune = t + self.cfg.tune_every

    def add_epoch(self, t, names, pr, sat, var, rate=None, sat_vel=None, sat_drift_mps=None,
                  rate_var=None, slot=None, cn0=None) -> EpochDecision:
        """One epoch's corrected pseudoranges (and range rates) at GNSS time ``t``; ``slot``
        the inter-system clock offset of each row (-1 or None: the reference constellation);
        ``cn0`` dBHz (the mixture's components)."""
        flt, cfg = self.flt, self.cfg
        names = np.asarray(names)
        s2 = self.scale.value() if len(self.scale.buf) >= self.scale.min_count else 1.0
        if slot is None or flt.layout.isb is None:
            slot = np.full(len(pr), -1)
        self._slot = slot = np.asarray(slot)
        pr_raw, comp = pr, None
        if self.mixture is not None:
            cn0 = np.full(len(pr), 35.0) if cn0 is None else np.where(np.isfinite(cn0), cn0,
                                                                        35.0)
            pr, var, comp = self._components(t, pr, sat, slot, cn0)
            # the mixture's σ is fitted to the residuals; errors correlated over epochs are
            # worth fewer independent ones (the AR(1) variance of a mean, as the odometry filter)
            s2 = self.correlation.inflation if cfg.correlation else 1.0
        m = Pseudoranges(t, pr, sat, var * s2, slot).model(flt)
        S = np.einsum("ij,jk,ik->i", m.H, flt.P, m.H) + np.diag(m.R)
        z = m.r / np.sqrt(S)
        ok = z**2 <= self._gate
        jump = 0.0
        if len(z) >= 3 and ok.sum() < len(z) / 2:
            # every satellite off together: a receiver clock step, if the rest then agree
            med = float(np.median(m.r))
            z2 = (m.r - med) / np.sqrt(S)
            if np.sum(z2**2 <= self._gate) > len(z) / 2:
                i = flt.layout.clk.start
                flt.rx_clock -= med
                flt.P[i, :] = 0.0
                flt.P[:, i] = 0.0
                flt.P[i, i] = (abs(med) / 3.0) ** 2 + flt.cfg.states.receiver_clock_sigma**2
                jump = -med
                m = Pseudoranges(t, pr, sat, var * s2, slot).model(flt)
                S = np.einsum("ij,jk,ik->i", m.H, flt.P, m.H) + np.diag(m.R)
                z = m.r / np.sqrt(S)
                ok = z**2 <= self._gate
        reopened = False
        if len(z) >= 5 and ok.sum() < len(z) / 2:
            reopened = self._reopen(m, S)
            if reopened:
                m = Pseudoranges(t, pr, sat, var * s2, slot).model(flt)
                S = np.einsum("ij,jk,ik->i", m.H, flt.P, m.H) + np.diag(m.R)
                z = m.r / np.sqrt(S)
                ok = z**2 <= self._gate
        used = np.flatnonzero(ok)
        if len(used):
            flt.update(m.rows(used))
            if self.mixture is not None:
                self._tune(t, pr_raw[used], sat[used], slot[used], cn0[used])
                post = Pseudoranges(t, pr[used], sat[used], var[used], slot[used]).model(flt)
                self.correlation.add(t, names[used], post.r / np.sqrt(var[used]),
                                     comp[used] == 0)
            else:
                post = Pseudoranges(t, pr[used], sat[used], var[used], slot[used]).model(flt)
                self.scale.add(post.r / np.sqrt(var[used]))
        dec = EpochDecision(float(t), names[used].tolist(), names[~ok].tolist(),
                            dict(zip(names.tolist(), np.round(z, 2).tolist())), jump,
                            reopened=reopened,
                            delayed=[] if comp is None else names[comp >= 1].tolist())
        if cfg.doppler and rate is not None:
            good = np.isfinite(rate) & ok
            if np.any(good):
                k = np.flatnonzero(good)
                mr = RangeRates(t, rate[k], sat[k], sat_vel[k], sat_drift_mps[k],
                                rate_var[k]).model(flt)
                Sr = np.einsum("ij,jk,ik->i", mr.H, flt.P, mr.H) + np.diag(mr.R)
                keep = np.flatnonzero(mr.r**2 / Sr <= self._gate)
                if len(keep):
                    flt.update(mr.rows(keep))
                dec.doppler_used = len(keep)
        return dec


class ClockNoise:
    """Causal estimate of the receiver clock's frequency random walk (m/s/√s) from the clock
    drifts of the epochs' Doppler least-squares solutions (independent of the filter): over the
    last ``window_s``, the differences of the drift at lags ``1`` and ``lag`` epochs have
    variances ``q Δt + 2σ²`` and ``q·lag·Δt + 2σ²`` (σ the solutions' noise): two robust
    variances (the median absolute deviation: a clock reset or a bad epoch does not count) give
    ``q``. A clock is what the receiver has, not what a datasheet says: a TCXO's random walk is
    0.01–0.2 m/s/√s, and with three satellites the difference is whether the clock is known."""

    def __init__(self, window_s: float = 240.0, lag: int = 30, min_count: int = 60):
        self.window_s, self.lag, self.min_count = window_s, lag, min_count
        self.t: list = []
        self.d: list = []

    def add(self, t: float, drift: float) -> None:
        if not np.isfinite(drift):
            return
        self.t.append(float(t))
        self.d.append(float(drift))
        while self.t and self.t[0] < t - self.window_s:
            self.t.pop(0)
            self.d.pop(0)

    def value(self):
        """The random walk, m/s/√s, or None while too few epochs are in."""
        if len(self.d) < self.min_count:
            return None
        t, d = np.asarray(self.t), np.asarray(self.d)
        out = []
        for lag in (1, self.lag):
            dd = d[lag:] - d[:-lag]
            dt = t[lag:] - t[:-lag]
            ok = dt < 1.5 * lag * np.median(np.diff(t))        # consecutive epochs only
            if ok.sum() < 10:
                return None
            mad = np.median(np.abs(dd[ok] - np.median(dd[ok])))
            out.append(((1.4826 * mad) ** 2, float(np.median(dt[ok]))))
        (v1, t1), (vl, tl) = out
        q = (vl - v1) / max(tl - t1, 1e-9)
        return float(np.sqrt(max(q, 0.0)))


def _snapshot(m, cols):
    """Least squares of one epoch's pseudoranges on the error-state columns ``cols``
    (position and clock) about the prediction: ``(δx, covariance, χ², dof)``."""
    A = m.H[:, cols]
    w = 1.0 / np.diag(m.R)
    N = A.T @ (A * w[:, None])
    dx = np.linalg.solve(N, A.T @ (w * m.r))
    res = m.r - A @ dx
    return dx, np.linalg.inv(N), float(np.sum(w * res**2)), len(m.r) - len(cols)


@dataclass
class TightInsResult:
    """Per GNSS epoch after the start: time, position (rad, m), ENU velocity, ``C_nb``, ENU
    position σ, receiver clock (m) and drift (m/s), satellites used; ``decisions`` the epochs'
    :class:`EpochDecision`; ``start`` how it started."""

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    velocity_n: np.ndarray
    C_nb: np.ndarray
    sigma_enu: np.ndarray
    clock_m: np.ndarray
    drift_mps: np.ndarray
    n_used: np.ndarray
    n_excluded: np.ndarray
    decisions: list
    start: dict
    stats: dict


def _imu_on_gnss_time(imu: ImuData, t_gnss) -> None:
    lo, hi = float(imu.t[0]), float(imu.t[-1])
    if hi < t_gnss[0] or lo > t_gnss[-1]:
        raise SelfnavError(f"{imu.source}: the IMU's stamps ({lo:.1f}–{hi:.1f} s) do not overlap "
                           f"the GNSS epochs ({t_gnss[0]:.1f}–{t_gnss[-1]:.1f} s, GPS time): "
                           "tight coupling needs the IMU stamped in GNSS time")


def _at_rest(imu: ImuData, spp, k: int, tcfg: TightInsConfig) -> bool:
    """At rest for ``rest_s`` up to epoch ``k``: every Doppler speed of the span under
    ``rest_speed`` (the satellites see centimetres per second where an idling engine shakes
    the accelerometers by 0.1–0.2 m/s²) and the IMU not turning (mean rate under
    ``rest_rate``)."""
    t = spp.spp.t
    span = (t > t[k] - tcfg.rest_s) & (t <= t[k])
    if t[k] - tcfg.rest_s < imu.t[0] or span.sum() < 0.8 * tcfg.rest_s / _interval(t):
        return False
    v = np.hypot(spp.velocity_enu[span, 0], spp.velocity_enu[span, 1])
    if not np.all(np.isfinite(v) & (v < tcfg.rest_speed)):
        return False
    sel = (imu.t > t[k] - tcfg.rest_s) & (imu.t <= t[k])
    return bool(np.linalg.norm(imu.omega_ib_b[sel].mean(axis=0)) < tcfg.rest_rate)


def _interval(t):
    return float(np.median(np.diff(t))) if len(t) > 1 else 1.0


def start_tight(imu: ImuData, spp, cfg: FilterConfig, tcfg: TightInsConfig, systems=None):
    """The first epoch the filter can start at and its filter (module docstring); returns
    ``(epoch index, InsGnssFilter, start dict)``."""
    res = spp.spp
    E = len(res.t)
    speed = np.hypot(spp.velocity_enu[:, 0], spp.velocity_enu[:, 1])
    vel_ok = np.isfinite(speed)
    fix_ok = res.valid & res.passed & (res.n_used >= 5)
    inside = (res.t >= imu.t[0]) & (res.t <= imu.t[-1])
    systems = list(res.systems) if systems is None else list(systems)
    cols = [int(np.flatnonzero(res.systems == x)[0]) if np.any(res.systems == x) else -1
            for x in systems]
    ref_ok = np.isfinite(res.clock[:, cols[0]]) if cols[0] >= 0 else np.zeros(E, bool)
    fix_ok = fix_ok & ref_ok
    sys_col = cols
    for k in range(E):
        if not (fix_ok[k] and inside[k] and vel_ok[k]):
            continue
        if speed[k] < tcfg.rest_speed and _at_rest(imu, spp, k, tcfg):
            sel = (imu.t > res.t[k] - tcfg.rest_s) & (imu.t <= res.t[k])
            win = ImuData(imu.t[sel], imu.omega_ib_b[sel], imu.f_ib_b[sel], source=imu.source)
            with warnings.catch_warnings():      # the latitude is the fix's, not the estimate's
                warnings.simplefilter("ignore")
                al = coarse_align(win, lat=float(res.lat[k]), h=float(res.h[k]))
            gyro_sigma = cfg.imu.gyro_bias_sigma / (7.292115e-5 * max(np.cos(res.lat[k]), 0.1))
            sig_head = float(np.hypot(al.sigma[2], gyro_sigma))
            if np.isfinite(sig_head) and sig_head <= tcfg.max_gyrocompass_sigma:
                return k, _filter(cfg, tcfg, res, spp, k, al.C_nb, np.zeros(3),
                                  np.array([al.sigma[0], al.sigma[1], sig_head]), 0.1,
                                  sys_col), {
                    "method": "at rest: levelling and gyrocompassing", "t": float(res.t[k]),
                    "heading_deg": float(np.degrees(al.heading)),
                    "sigma_heading_deg": float(np.degrees(sig_head))}
            continue
        if speed[k] >= tcfg.min_speed:
            good = vel_ok & fix_ok
            try:
                al = align_in_motion(imu, res.t[good], spp.velocity_enu[good], res.lat[good],
                                     res.h[good], min_speed=tcfg.min_speed,
                                     velocity_sigma=float(np.nanmax(spp.sigma_vel_enu[k, :2])))
            except SelfnavError:
                continue
            k2 = int(np.searchsorted(res.t, al.t))
            sig = np.where(np.isfinite(al.sigma), al.sigma, 5.0 * DEG)
            sig = np.maximum(sig, np.array([1.0, 1.0, 5.0]) * DEG)
            return k2, _filter(cfg, tcfg, res, spp, k2, al.C_nb, al.velocity_n, sig, 0.3,
                               sys_col), {
                "method": "in motion: the Doppler course", "t": float(res.t[k2]),
                "heading_deg": float(np.degrees(al.heading)),
                "sigma_heading_deg": float(np.degrees(sig[2]))}
    raise SelfnavError("no start: no epoch with a passing least-squares fix (5+ satellites) "
                       f"where the IMU was still for {tcfg.rest_s:g} s with gyros that can "
                       f"gyrocompass, or moved faster than {tcfg.min_speed:g} m/s")


def _filter(cfg, tcfg, res, spp, k, C_nb, v, att_sigma, vel_sigma, sys_col):
    sig_h = float(np.nanmax([res.sigma_m[k] * 3.0, tcfg.pos_sigma_floor]))
    c = cfg.updated(pos_sigma=sig_h, vel_sigma=vel_sigma, att_sigma=tuple(att_sigma))
    flt = InsGnssFilter(c, float(res.t[k]), float(res.lat[k]), float(res.lon[k]),
                        float(res.h[k]), v, C_nb)
    flt.P[2, 2] = (2.0 * sig_h) ** 2
    flt.rx_clock = float(res.clock[k, sys_col[0]])
    for i, c in enumerate(sys_col[1:]):
        if c >= 0 and np.isfinite(res.clock[k, c]):
            flt.rx_isb[i] = float(res.clock[k, c] - res.clock[k, sys_col[0]])
    d = spp.clock_drift[k]
    flt.rx_drift = float(d) if np.isfinite(d) else 0.0
    return flt


def run_tight_ins(imu: ImuData, raw: RawGnss, cfg: TightInsConfig | None = None, *,
                  progress=None) -> TightInsResult:
    """Tightly coupled INS/GNSS over a record (module docstring); causal."""
    tcfg = cfg or TightInsConfig()
    car = {"nhc": True, "grade_sigma": PLATFORMS["car"]["grade_sigma"]} \
        if tcfg.platform == "car" else {}
    fcfg = FilterConfig.for_grade(tcfg.grade, receiver_clock=True, velocity_lag=False,
                                  time_offset=False, **{**car, **tcfg.filter})
    corr: CorrectedObservations = correct_observations(raw, tcfg.gnss, carry_geometry=True)
    obs = corr.obs
    # the reference constellation: GPS where there is GPS, else the most observed; up to four
    # more with their clock offsets as states (``multi_system``)
    systems, counts = np.unique(obs.system, return_counts=True)
    order_sys = [int(x) for x in systems[np.argsort(-counts, kind="stable")]]
    ref = GPS if GPS in order_sys else order_sys[0]
    others = [x for x in order_sys if x != ref][:4] if tcfg.multi_system else []
    used_sys = [ref] + others
    if others:
        fcfg = fcfg.updated(inter_system=True)
    spp = spp_raw(raw, replace(tcfg.gnss, systems=tuple(used_sys)))
    _imu_on_gnss_time(imu, spp.spp.t)
    k0, flt, start = start_tight(imu, spp, fcfg, tcfg, used_sys)
    nav = TightIns(flt, tcfg)
    mine = np.isin(obs.system, used_sys)
    slot_all = np.full(len(obs), -1)
    for i, x in enumerate(others):
        slot_all[obs.system == x] = i
    names_all = sat_names(obs.system, obs.prn)
    rate_all, rate_var_all = corr.range_rate(tcfg.gnss)
    # rows at every epoch and, through gaps of the record, on the epochs' grid
    t_obs = np.unique(obs.t)
    step = _interval(t_obs)
    grid = flt.ins.t + step * np.arange(1, int((imu.t[-1] - flt.ins.t) / step) + 1)
    k = np.searchsorted(t_obs, grid)
    near = np.minimum(np.abs(grid - t_obs[np.clip(k - 1, 0, len(t_obs) - 1)]),
                      np.abs(grid - t_obs[np.clip(k, 0, len(t_obs) - 1)]))
    t_ep = np.union1d(t_obs, grid[near > 1e-3])
    t_ep = t_ep[(t_ep > flt.ins.t) & (t_ep <= imu.t[-1])]
    order = np.argsort(obs.t, kind="stable")
    ts = obs.t[order]
    out = {k: [] for k in ("t", "lat", "lon", "h", "v", "C", "sig", "clk", "drift", "nu", "nx")}
    decisions = []
    i_imu = int(np.searchsorted(imu.t, flt.ins.t, side="right"))
    clock = ClockNoise()
    i_spp = 0
    for n, te in enumerate(t_ep):
        while i_spp < len(spp.spp.t) and spp.spp.t[i_spp] <= te + 1e-6:
            clock.add(spp.spp.t[i_spp], spp.clock_drift[i_spp])
            i_spp += 1
        q = clock.value() if tcfg.learn_clock else None
        if q is not None:
            flt.set_receiver_drift_rw(float(np.clip(q, *tcfg.drift_rw_bounds)))
        j = int(np.searchsorted(imu.t, te, side="right"))
        if j > i_imu:
            nav.add_imu(imu.t[i_imu:j], imu.omega_ib_b[i_imu:j], imu.f_ib_b[i_imu:j])
            i_imu = j
        rows = order[np.searchsorted(ts, te, "left"):np.searchsorted(ts, te, "right")]
        rows = rows[mine[rows]]
        if len(rows) == 0:
            dec = EpochDecision(float(te), [], [], {})
        else:
            dec = nav.add_epoch(te, names_all[rows], corr.pr[rows], corr.sat[rows], corr.var[rows],
                                rate_all[rows], corr.sat_vel[rows],
                                C_LIGHT * corr.sat_drift[rows], rate_var_all[rows],
                                slot_all[rows], corr.obs.cn0[rows])
        decisions.append(dec)
        ins = flt.ins
        out["t"].append(te)
        out["lat"].append(ins.lat)
        out["lon"].append(ins.lon)
        out["h"].append(ins.h)
        out["v"].append(ins.velocity_n.copy())
        out["C"].append(ins.C_nb.copy())
        out["sig"].append(np.sqrt(np.maximum(np.diag(flt.P)[IR], 0.0)))
        out["clk"].append(flt.rx_clock)
        out["drift"].append(flt.rx_drift)
        out["nu"].append(len(dec.used))
        out["nx"].append(len(dec.excluded))
        if progress is not None and n % 50 == 0:
            progress(n + 1, len(t_ep))
    if progress is not None:
        progress(len(t_ep), len(t_ep))
    a = {k: np.asarray(v) for k, v in out.items()}
    q = clock.value()
    stats = {"start": start, "epochs": len(t_ep), "system": ref,
             "systems": "".join(SYSTEM_LETTERS.get(x, "?") for x in used_sys),
             "inter_system_m": {SYSTEM_LETTERS.get(x, "?"): float(flt.rx_isb[i])
                                for i, x in enumerate(others)},
             "clock_drift_rw": None if q is None else float(np.clip(q, *tcfg.drift_rw_bounds)),
             "excluded": int(a["nx"].sum()) if len(t_ep) else 0,
             "clock_jumps": sum(1 for d in decisions if d.clock_jump_m != 0.0),
             "variance_factor": float(nav.scale.value()), "grade": tcfg.grade,
             "motion_constraints": "car: non-holonomic, level road" if tcfg.platform == "car"
             else "none", "nhc_refused": nav.nhc_refused}
    return TightInsResult(a["t"], a["lat"], a["lon"], a["h"], a["v"].reshape(-1, 3),
                          a["C"].reshape(-1, 3, 3), a["sig"].reshape(-1, 3), a["clk"],
                          a["drift"], a["nu"], a["nx"], decisions, start, stats)


__all__ = ["TightInsConfig", "TightIns", "TightInsResult", "EpochDecision", "start_tight",
           "run_tight_ins"]
