"""Single-point positioning from raw measurements and broadcast ephemerides, with Doppler
velocity and multi-satellite fault detection and exclusion (issue 23).

Per epoch and satellite (one signal each, by :data:`SIGNAL_PREFERENCE`)::

    t_tx = t_rx − ρ/c − δt^s(t_tx)                       transmit time (2 iterations)
    ρ_c  = ρ + c (δt^s − T_GD) − I − T                  corrected pseudorange
    ρ_c  = |R_3(Ω τ) r^s(t_tx) − r| + c δt_sys + ε       solved by :func:`selfnav.gnss.spp.solve_spp`

``δt^s`` with the relativistic term and the signal's broadcast group delay
(:mod:`selfnav.gnss.ephemeris`), ``I`` Klobuchar (GPS parameters of the file, scaled to the
carrier; RTKLIB's default set with a warning when the file has none), ``T`` Saastamoinen
(:mod:`selfnav.gnss.atmosphere`), both at a first all-satellite fix. The range rate
``ρ̇ = −λ D`` gives the velocity and clock drift by weighted least squares on::

    ρ̇ = u·(v^s − v) + c (δṫ − δṫ^s) + (Ω/c)(v^s_x y − v^s_y x)       (selfnav.gnss.models (2))

with the same largest-consistent-subset exclusion (:mod:`selfnav.gnss.fde`). Weights: the
C/N0 model ``σ² = σ0² 10^{(C0 − C/N0)/10}`` (default) or C/N0 with ``1/sin²E``, scaled by the
causal variance factor of the past residuals, so the χ² tests and the σ follow the data.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from selfnav.earth import enu_rotation
from selfnav.errors import InputError, SelfnavWarning
from selfnav.gnss.atmosphere import (KLOBUCHAR_DEFAULT, azimuth_elevation, klobuchar,
                                     klobuchar_bds, saastamoinen)
from selfnav.gnss.ephemeris import group_delay, satellite_states, select_ephemeris
from selfnav.gnss.fde import VarianceScale, fde_epoch
from selfnav.gnss.spp import (C_LIGHT, OMEGA_EARTH, SppConfig, SppResult, observation_variance,
                              sagnac_rotate, solve_spp)
from selfnav.io.gnss_raw import (BDT_OFFSET_S, BEIDOU, GALILEO, GLONASS, GPS, QZSS,
                                 GnssObservations,
                                 RawGnss, frequency, sat_names)

#: signals used for positioning, most preferred first (one per satellite and epoch)
SIGNAL_PREFERENCE = {
    GPS: ("1C", "1W", "1X", "1P", "2W", "2L", "2S", "2X", "5Q", "5I", "5X"),
    QZSS: ("1C", "1X", "2L", "2X", "5Q", "5X"),
    GALILEO: ("1C", "1B", "1X", "7Q", "7I", "7X", "5Q", "5I", "5X"),
    BEIDOU: ("2I", "6I", "7I", "2X", "6X", "1P", "1D", "1X", "5P", "5X"),
    GLONASS: ("1C", "1P", "2C", "2P"),
}


@dataclass
class RawSppConfig:
    """Options of :func:`spp_raw`.

    Attributes
    ----------
    spp : SppConfig
        The solver's (default: C/N0 weights, σ0 5 m at 45 dBHz, largest-consistent-subset
        exclusion, adaptive σ, α = 10⁻³).
    systems : tuple of system codes used
    elevation_mask_deg : satellites below are not used
    ionosphere, troposphere : apply the Klobuchar / Saastamoinen corrections
    smoothing_s : time constant (s) of the Doppler-aided code smoothing (:func:`smooth_code`);
        0 switches it off
    doppler_sigma0 : m/s, range-rate σ at ``spp.cn0_ref``
    velocity : solve the Doppler velocity
    """

    spp: SppConfig = field(default_factory=lambda: SppConfig(
        weighting="cn0", fde="subset", adaptive_sigma=True, max_exclusions=12))
    systems: tuple = (GPS, GALILEO, BEIDOU, GLONASS, QZSS)
    elevation_mask_deg: float = 5.0
    ionosphere: bool = True
    troposphere: bool = True
    doppler_sigma0: float = 0.1
    velocity: bool = True
    smoothing_s: float = 30.0


@dataclass
class RawSppResult:
    """SPP of raw measurements: the position solution ``spp`` (epochs ``spp.t``), Doppler
    velocity (ENU m/s, NaN where none), its σ, the clock drift (m/s), and per-observation
    tables of the satellites used (``obs_*``: name, elevation, azimuth, the corrections, the
    residual). ``excluded`` / ``excluded_doppler`` list per epoch the satellites left out."""

    spp: SppResult
    velocity_enu: np.ndarray
    sigma_vel_enu: np.ndarray
    clock_drift: np.ndarray
    vel_passed: np.ndarray
    excluded: list
    excluded_doppler: list
    obs_name: np.ndarray
    obs_elevation: np.ndarray
    obs_azimuth: np.ndarray
    obs_iono: np.ndarray
    obs_tropo: np.ndarray
    obs_t: np.ndarray
    stats: dict


def select_signals(obs: GnssObservations, systems) -> np.ndarray:
    """Row indices of one signal per (epoch, satellite): the first of
    :data:`SIGNAL_PREFERENCE` with a pseudorange."""
    rank = np.full(len(obs), 99)
    for s, prefs in SIGNAL_PREFERENCE.items():
        if s not in systems:
            continue
        m = obs.system == s
        for k, code in enumerate(prefs):
            rank[m & (obs.signal == code)] = np.minimum(rank[m & (obs.signal == code)], k)
    ok = (rank < 99) & np.isfinite(obs.pseudorange)
    idx = np.flatnonzero(ok)
    order = np.lexsort((rank[idx], obs.prn[idx], obs.system[idx], obs.t[idx]))
    idx = idx[order]
    key = np.stack([obs.t[idx], obs.system[idx], obs.prn[idx]], axis=1)
    first = np.ones(len(idx), bool)
    first[1:] = np.any(key[1:] != key[:-1], axis=1)
    return idx[first]


def smooth_code(obs: GnssObservations, tau_s: float = 30.0, jump_sigma: float = 4.0,
                coast_s: float = 120.0, cusum_k: float = 0.5, cusum_h: float = 8.0):
    """Doppler-aided code smoothing (the Hatch (1982) filter with the integrated Doppler in
    place of the carrier phase), causal, per satellite and signal::

        p_k = ρ̂_{k−1} + ½ (ρ̇_k + ρ̇_{k−1}) Δt + δ_k                    prediction, ρ̇ = −λ D
        ρ̂_k = ρ_k / N_k + (1 − 1/N_k) p_k,      N_k = min(N_{k−1} + 1, τ / Δt)

    ``δ_k`` is the median over the satellites of the epoch of ``ρ_k − (p_k − δ_k)``: a
    receiver clock step (phones steer their clock, u-blox receivers jump it by milliseconds)
    moves every pseudorange and no Doppler; a few faulty satellites do not move the median.

    **Code faults.** When a pseudorange departs from its prediction by more than
    ``jump_sigma · s`` (``s`` the satellite's running σ of ``ρ − p``, started from the
    receiver's σ or 5 m, updated slowly with the differences clipped at 3 s so that a ramp
    does not widen its own test), when the mean of its last ``M = 10`` differences
    exceeds ``jump_sigma · s / √M``, or when a two-sided CUSUM of ``(ρ − p)/s`` (Page 1954;
    reference ``cusum_k``, threshold ``cusum_h``) signals a ramp — a few metres of drift
    against the Doppler, below both tests, that the smoother would otherwise absorb (a phone's
    6 m code noise let a 0.5 m/s ramp on two satellites run 27 s and put 7 m into the
    smoothed ranges before the mean test fired) —, the code is not used and the range coasts
    on the Doppler for up to ``coast_s``. A CUSUM alarm **rewinds**: the range coasts from the
    smoothed range of the epoch where the CUSUM last stood at zero (where the drift began)
    carried by the Doppler since, so what the smoother took in of the ramp is given back. A
    step, or a ramp, on one satellite's code is bridged by its own Doppler; the code is taken
    again when it agrees with the Doppler once more (restart of the CUSUM), or after
    ``coast_s`` of disagreement (restart, ``N = 1``). A gap (over 3 median intervals) or a
    missing Doppler restarts too. Returns the smoothed pseudoranges, ``N`` and a flag per
    observation (True: the code was not used, coasting).
    """
    pr = obs.pseudorange.copy()
    N = np.ones(len(obs))
    coasting = np.zeros(len(obs), bool)
    if tau_s <= 0 or len(obs) == 0:
        return pr, N, coasting
    rr = -obs.doppler * C_LIGHT / obs.frequency
    keys = list(zip(obs.system.tolist(), obs.prn.tolist(), [str(c) for c in obs.signal]))
    sig0 = np.where(np.isfinite(obs.pr_sigma) & (obs.pr_sigma > 0), obs.pr_sigma, 5.0)
    t_ep, ep = np.unique(obs.t, return_inverse=True)
    dt_med = float(np.median(np.diff(t_ep))) if len(t_ep) > 1 else 1.0
    nmax = max(1.0, tau_s / max(dt_med, 1e-3))
    order = np.argsort(ep, kind="stable")
    bounds = np.searchsorted(ep[order], np.arange(len(t_ep) + 1))
    state: dict = {}          # key -> [ρ̂, N, s², t, ρ̇, coasting since (t) or None]
    recent: dict = {}         # key -> the last M code − prediction differences
    cusum: dict = {}          # key -> per side (rising, falling): [g, ρ̂ where g was last 0,
                              #         the Doppler's range change since, N there]
    M = 10
    for e in range(len(t_ep)):
        rows = order[bounds[e]:bounds[e + 1]]
        cont, pred, inn = [], [], []
        for i in rows:
            st = state.get(keys[i])
            if (st is not None and obs.t[i] - st[3] <= 3 * dt_med and np.isfinite(rr[i])
                    and np.isfinite(st[4]) and np.isfinite(pr[i])):
                p = st[0] + 0.5 * (rr[i] + st[4]) * (obs.t[i] - st[3])
                cont.append(i)
                pred.append(p)
                inn.append(pr[i] - p)
        ok_delta = len(inn) >= 3
        delta = float(np.median(inn)) if ok_delta else 0.0
        done = set()
        for i, p, d in zip(cont, pred, inn):
            if not ok_delta:
                break
            st = state[keys[i]]
            dd = d - delta
            p = p + delta
            hist = recent.setdefault(keys[i], [])
            hist.append(dd)
            del hist[:-M]
            drifting = len(hist) == M and (sum(hist) / M) ** 2 > jump_sigma**2 * st[2] / M
            cu = cusum.get(keys[i])
            if cu is None:
                cu = cusum[keys[i]] = [[0.0, st[0], 0.0, st[1]], [0.0, st[0], 0.0, st[1]]]
            inc = p - st[0]                           # the Doppler's range change (+ clock)
            z = dd / math.sqrt(st[2])
            for c, sgn in zip(cu, (1.0, -1.0)):
                c[0], c[2] = max(0.0, c[0] + sgn * z - cusum_k), c[2] + inc
            c = cu[0] if cu[0][0] > cu[1][0] else cu[1]
            ramp = st[5] is None and c[0] > cusum_h
            if ramp and c[3] >= 0.5 * nmax:           # from where the drift began, if the
                # smoother had settled there (an early range carries the raw code's noise)
                p = c[1] + c[2]
            if dd * dd > jump_sigma**2 * st[2] or drifting or ramp:
                since = st[5] if st[5] is not None else obs.t[i]
                if obs.t[i] - since < coast_s:        # coast on the Doppler
                    pr[i], N[i], coasting[i] = p, st[1], True
                    state[keys[i]] = [p, st[1], st[2], obs.t[i], rr[i], since]
                    done.add(i)
                continue
            st[2] = 0.995 * st[2] + 0.005 * min(dd * dd, 9.0 * st[2])   # slow, clipped: a
            # ramp must not teach the test its own growth
            n = min(st[1] + 1.0, nmax)
            pr[i] = pr[i] / n + (1.0 - 1.0 / n) * p
            N[i] = n
            for c in cu:
                if st[5] is not None:                 # the code agrees again: a fresh CUSUM
                    c[0] = 0.0
                if c[0] == 0.0:                       # the last smoothed range at zero
                    c[1:] = [pr[i], 0.0, n]
            state[keys[i]] = [pr[i], n, st[2], obs.t[i], rr[i], None]
            done.add(i)
        for i in rows:
            if i not in done:
                recent.pop(keys[i], None)
                cusum.pop(keys[i], None)
                st = state.get(keys[i])
                s2 = st[2] if st is not None else 2.0 * sig0[i] ** 2
                state[keys[i]] = [pr[i], 1.0, s2, obs.t[i], rr[i], None]
    return pr, N, coasting


def _corrections(raw: RawGnss, obs: GnssObservations, cfg: RawSppConfig):
    """Satellite states and corrected pseudoranges of the selected observations."""
    eph = raw.eph
    if len(eph) == 0:
        raise InputError(raw.source, "no ephemerides: the file carries none; give a RINEX "
                                     "navigation file (--nav)")
    ie = select_ephemeris(eph, obs.system, obs.prn, obs.t - obs.pseudorange / C_LIGHT)
    keep = ie >= 0
    obs, ie = obs.select(keep), ie[keep]
    if len(obs) == 0:
        raise InputError(raw.source, "no measurement has a healthy ephemeris within its "
                                     "validity (wrong navigation file or day?)")
    glo = obs.system == GLONASS
    if np.any(glo):       # frequency channel from the ephemeris where the reader had none
        k = np.where(glo & (obs.glo_k == 0), eph.glo_k[ie], obs.glo_k)
        obs.glo_k = k
        obs.frequency = frequency(obs.system, obs.signal, k)
    t_tx = obs.t - obs.pseudorange / C_LIGHT
    for _ in range(2):
        _, _, clk, _ = satellite_states(eph, ie, t_tx)
        t_tx = obs.t - obs.pseudorange / C_LIGHT - clk
    pos, vel, clk, drift = satellite_states(eph, ie, t_tx)
    tgd = group_delay(eph, ie, obs.system, obs.signal)
    pr = obs.pseudorange + C_LIGHT * (clk - tgd)
    ok = np.all(np.isfinite(pos), axis=1) & np.isfinite(pr)
    kept = np.flatnonzero(keep)[ok]
    return obs.select(ok), pos[ok], vel[ok], drift[ok], pr[ok], t_tx[ok], kept


def ionosphere_delay(raw: RawGnss, t, lat, lon, az, el, freq):
    """Broadcast ionosphere delay (m) of each observation: GPS (or QZSS) Klobuchar where the
    file has its parameters, else BeiDou's Klobuchar, else GPS Klobuchar with RTKLIB's default
    parameters (with a warning). Returns (delay, model name)."""
    ion = raw.eph.ion
    for s in (GPS, QZSS):
        v = ion.get(s)
        if v is not None and len(v) == 8 and np.any(np.asarray(v) != 0):
            return klobuchar(t, lat, lon, az, el, v[:4], v[4:], freq), "klobuchar-gps"
    v = ion.get(BEIDOU)
    if v is not None and len(v) == 8 and np.any(np.asarray(v) != 0):
        return klobuchar_bds(t - BDT_OFFSET_S, lat, lon, az, el, v[:4], v[4:], freq), \
            "klobuchar-bds"
    warnings.warn(f"{raw.source}: no broadcast ionosphere parameters; Klobuchar with RTKLIB's "
                  "default set (2004), expect metres of ionospheric error", SelfnavWarning,
                  stacklevel=3)
    a, b = KLOBUCHAR_DEFAULT
    return klobuchar(t, lat, lon, az, el, a, b, freq), "klobuchar-default"


@dataclass
class CorrectedObservations:
    """The observations of a raw record ready for positioning (one row each, by epoch): the
    selected signals, the satellites' states at transmit time, the pseudorange corrected for
    the satellite clock, group delay, ionosphere and troposphere (``pr``), its a-priori
    variance by the C/N0 model (``var``; ``smooth_factor`` times it for a smoothed code) and
    the line of sight from a coarse all-satellite fix of the same epoch (``az``, ``el``).
    Causal: each row uses its epoch and the past."""

    obs: GnssObservations
    sat: np.ndarray
    sat_vel: np.ndarray
    sat_drift: np.ndarray
    pr: np.ndarray
    var: np.ndarray
    smooth_factor: np.ndarray
    az: np.ndarray
    el: np.ndarray
    iono: np.ndarray
    tropo: np.ndarray
    iono_model: str

    def range_rate(self, cfg: RawSppConfig) -> tuple[np.ndarray, np.ndarray]:
        """``(ρ̇, var)`` of each row, m/s (NaN where the row has no Doppler)."""
        return range_rate(self.obs, cfg)


def range_rate(obs: GnssObservations, cfg: RawSppConfig) -> tuple[np.ndarray, np.ndarray]:
    """``ρ̇ = −λ D`` (m/s; NaN without a Doppler) and its variance by the C/N0 model."""
    rr = -obs.doppler * C_LIGHT / obs.frequency
    var = cfg.doppler_sigma0**2 * 10.0 ** ((cfg.spp.cn0_ref - _cn0(obs)) / 10.0)
    return rr, var


def correct_observations(raw: RawGnss, cfg: RawSppConfig | None = None, *,
                         carry_geometry: bool = False) -> CorrectedObservations:
    """Signals selected, code smoothed (``cfg.smoothing_s``; 0: raw code), satellites and
    corrections of every observation of a raw record with ephemerides (module docstring).

    ``carry_geometry``: an epoch with too few satellites for its own fix takes the last fix
    before it for its lines of sight and atmosphere (kilometres are enough there; a tight
    filter uses such epochs); otherwise its observations are dropped (no elevation)."""
    cfg = cfg or RawSppConfig()
    obs = raw.obs
    if len(raw.eph) == 0:
        raise InputError(raw.source, "no ephemerides: the file carries none; give a RINEX "
                                     "navigation file (--nav)")
    obs = obs.select(select_signals(obs, cfg.systems))
    if len(obs) == 0:
        raise InputError(raw.source, "no pseudorange of a supported signal (GPS, Galileo, "
                                     "BeiDou, GLONASS, QZSS)")
    pr_s, n_smooth, coasting = smooth_code(obs, cfg.smoothing_s)
    nmax = np.maximum(cfg.smoothing_s / _median_interval(obs), 1.0) if cfg.smoothing_s > 0 else 1.0
    obs.pseudorange = pr_s
    obs, sat, sat_vel, sat_drift, pr, t_tx, keep = _corrections(raw, obs, cfg)
    # variance of a smoothed pseudorange: σ² (1/N + 1/N_max): the white part averages down,
    # a share as large as one full window's does not (multipath is correlated)
    smooth_factor = 1.0 / n_smooth[keep] + 1.0 / nmax
    # coarse all-satellite fix for the line-of-sight geometry
    coarse = solve_spp(obs.t, pr, None, sat, obs.system, None, _cn0(obs),
                       SppConfig(weighting="cn0", raim=False))
    ep = np.searchsorted(coarse.t, obs.t)
    if carry_geometry:
        last = np.maximum.accumulate(np.where(np.isfinite(coarse.lat), np.arange(len(coarse.t)),
                                              -1))
        ep = last[ep]
    ep_ok = ep >= 0
    ep = np.maximum(ep, 0)
    rx = coarse.ecef[ep]
    lat, lon, h = (np.where(ep_ok, x[ep], np.nan) for x in (coarse.lat, coarse.lon, coarse.h))
    az, el = azimuth_elevation(rx, sagnac_rotate(sat, rx), lat, lon)
    iono, iono_model = np.zeros(len(obs)), "none"
    if cfg.ionosphere:
        iono, iono_model = ionosphere_delay(raw, obs.t, lat, lon, az, el, obs.frequency)
    tropo = saastamoinen(lat, h, el) if cfg.troposphere else np.zeros(len(obs))
    m = np.isfinite(el) & (el >= np.radians(cfg.elevation_mask_deg))
    iono, tropo = np.nan_to_num(iono), np.nan_to_num(tropo)
    obs = obs.select(m)
    var = observation_variance(np.full(len(obs), cfg.spp.sigma0**2), el[m], _cn0(obs), cfg.spp)
    return CorrectedObservations(obs, sat[m], sat_vel[m], sat_drift[m], (pr - iono - tropo)[m],
                                 var, smooth_factor[m], az[m], el[m], iono[m], tropo[m],
                                 iono_model)


def spp_raw(raw: RawGnss, cfg: RawSppConfig | None = None) -> RawSppResult:
    """Positions, velocities and exclusions of every epoch of a raw record."""
    cfg = cfg or RawSppConfig()
    if raw.obs.corrected:
        return _spp_corrected(raw, cfg)
    c = correct_observations(raw, cfg)
    obs = c.obs
    res = solve_spp(obs.t, c.pr, c.var * c.smooth_factor, c.sat, obs.system, c.el, _cn0(obs),
                    replace(cfg.spp, weighting="variance", variance_scale=1.0))
    out = _finish(raw, cfg, obs, res, c.sat, c.sat_vel, c.sat_drift, c.az, c.el, c.iono, c.tropo)
    out.stats["ionosphere"] = c.iono_model
    return out


def _median_interval(obs):
    ep = np.unique(obs.t)
    return float(np.median(np.diff(ep))) if len(ep) > 1 else 1.0


def _cn0(obs):
    return np.where(np.isfinite(obs.cn0), obs.cn0, 35.0)


def _spp_corrected(raw, cfg):
    """smartLoc-like input: pseudoranges already corrected, satellite positions given."""
    obs = raw.obs
    el = obs.elevation if obs.elevation is not None else np.full(len(obs), np.pi / 2)
    m = el >= np.radians(cfg.elevation_mask_deg)
    m &= np.isin(obs.system, cfg.systems)
    obs, el = obs.select(m), el[m]
    res = solve_spp(obs.t, obs.pseudorange, obs.variance, obs.sat_ecef, obs.system, el,
                    _cn0(obs), cfg.spp)
    z = np.zeros(len(obs))
    return _finish(raw, replace(cfg, velocity=False), obs, res, obs.sat_ecef,
                   np.full((len(obs), 3), np.nan), z, np.full(len(obs), np.nan), el, z, z)


def _finish(raw, cfg, obs, res, sat, sat_vel, sat_drift, az, el, iono, tropo):
    names = sat_names(obs.system, obs.prn)
    E = len(res.t)
    excluded = [[] for _ in range(E)]
    for i in np.flatnonzero(~res.obs_used):
        excluded[res.obs_epoch[i]].append(str(names[i]))
    vel = np.full((E, 3), np.nan)
    svel = np.full((E, 3), np.nan)
    drift = np.full(E, np.nan)
    vpass = np.zeros(E, bool)
    excl_d = [[] for _ in range(E)]
    stats = dict(res.stats)
    if cfg.velocity and np.any(np.isfinite(obs.doppler)):
        vel, svel, drift, vpass, excl_d, vs = _velocity(res, obs, sat, sat_vel, sat_drift, names,
                                                        cfg)
        stats.update(vs)
    stats.update(systems=[int(s) for s in res.systems], satellites=len(np.unique(names)),
                 observations=len(obs))
    return RawSppResult(res, vel, svel, drift, vpass, excluded, excl_d, names, el, az, iono,
                        tropo, obs.t, stats)


def _velocity(res, obs, sat, sat_vel, sat_drift, names, cfg):
    """Doppler velocity and clock drift per epoch, with the subset exclusion."""
    E = len(res.t)
    vel = np.full((E, 3), np.nan)
    svel = np.full((E, 3), np.nan)
    drift = np.full(E, np.nan)
    vpass = np.zeros(E, bool)
    excl = [[] for _ in range(E)]
    rr, var = range_rate(obs, cfg)
    ok = np.isfinite(rr) & res.obs_used & np.all(np.isfinite(sat_vel), axis=1)
    ep = res.obs_epoch
    scale = VarianceScale()
    order = np.argsort(ep, kind="stable")
    bounds = np.searchsorted(ep[order], np.arange(E + 1))
    n_excl = 0
    for e in range(E):
        if not np.isfinite(res.lat[e]):
            continue
        rows = order[bounds[e]:bounds[e + 1]]
        rows = rows[ok[rows]]
        if len(rows) < 5:
            continue
        r0 = res.ecef[e]
        s = sagnac_rotate(sat[rows], r0)
        d = s - r0
        u = d / np.linalg.norm(d, axis=1)[:, None]
        vs = sat_vel[rows]
        pred = np.einsum("ij,ij->i", u, vs) - C_LIGHT * sat_drift[rows] + OMEGA_EARTH / C_LIGHT * (
            vs[:, 0] * r0[1] - vs[:, 1] * r0[0])
        H = np.column_stack([-u, np.ones(len(rows))])   # Sagnac terms in v: < 1e-5 of u
        y = rr[rows] - pred
        s2 = scale.value() if len(scale.buf) >= scale.min_count else scale.value(
            fde_epoch(H, y, var[rows], max_exclusions=0).z)
        f = fde_epoch(H, y, var[rows] * s2, alpha=cfg.spp.alpha, max_subsets=cfg.spp.max_subsets)
        scale.add(f.z * np.sqrt(s2))
        infl = f.T / f.dof if (not f.passed and f.dof > 0) else 1.0
        C = enu_rotation(res.lat[e], res.lon[e])
        vel[e] = C @ f.dx[:3]
        svel[e] = np.sqrt(np.maximum(np.diag(C @ f.P[:3, :3] @ C.T) * infl, 0))
        drift[e] = f.dx[3]
        vpass[e] = f.passed
        excl[e] = [str(x) for x in names[rows[~f.used]]]
        n_excl += int((~f.used).sum())
    return vel, svel, drift, vpass, excl, {"doppler_excluded": n_excl,
                                           "velocity_epochs": int(np.isfinite(vel[:, 0]).sum())}
