"""Per-satellite faults injected into raw measurements (simulated or real): steps and ramps on
the pseudorange, optionally with the matching Doppler (a fault consistent in range and range
rate, as a spoofer or a slowly moving reflection would make it). Used to test the exclusion of
:mod:`selfnav.gnss.fde` with known truth; what is injected is returned for the record.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from selfnav.io.gnss_raw import GnssObservations

C_LIGHT = 299_792_458.0


@dataclass
class SatelliteFault:
    """One fault on one satellite (every signal of it).

    Attributes
    ----------
    system, prn : the satellite
    t_start : s, GPS time the fault begins (see :func:`fault_at`)
    duration : s, how long it lasts (``inf``: to the end); after it the range is clean again
    kind : ``"step"`` (``size`` m from ``t_start``) or ``"ramp"`` (``size`` m/s growing from 0)
    size : m or m/s
    doppler : bool, also shift the Doppler by the ramp's rate (a range-rate-consistent fault)
    hold : bool, a ramp that stops growing at the end of ``duration`` and stays (instead of
        vanishing)
    """

    system: int
    prn: int
    t_start: float
    duration: float
    kind: str
    size: float
    doppler: bool = False
    hold: bool = False

    def bias(self, t):
        """Range bias (m) and range-rate bias (m/s) at times ``t``."""
        t = np.asarray(t, float)
        dt = t - self.t_start
        on = (dt >= 0) & (dt <= self.duration)
        if self.kind == "step":
            b = np.where(on, self.size, 0.0)
            return b, np.zeros_like(b)
        if self.kind != "ramp":
            raise ValueError(f"fault kind '{self.kind}' (step, ramp)")
        b = np.where(on, self.size * dt, 0.0)
        rate = np.where(on, self.size, 0.0)
        if self.hold:
            after = dt > self.duration
            b = np.where(after, self.size * self.duration, b)
        return b, rate


def fault_at(obs: GnssObservations, t_rel: float) -> float:
    """GPS time ``t_rel`` seconds after the first epoch of ``obs``."""
    return float(obs.t[0]) + t_rel


def inject_faults(obs: GnssObservations, faults) -> GnssObservations:
    """A copy of ``obs`` with the faults added to the pseudoranges (and Dopplers where asked:
    ``D −= ḃ / λ``)."""
    out = replace(obs, pseudorange=obs.pseudorange.copy(), doppler=obs.doppler.copy())
    for f in faults:
        m = (obs.system == f.system) & (obs.prn == f.prn)
        b, rate = f.bias(obs.t[m])
        out.pseudorange[m] += b
        if f.doppler:
            out.doppler[m] -= rate * obs.frequency[m] / C_LIGHT
    return out


def only_satellites(obs: GnssObservations, t_from: float, t_to: float, n: int):
    """A partial sky: within ``[t_from, t_to)`` (GPS s) only the ``n`` satellites of the most
    observed system that are seen most often there are kept (a street that hides the rest);
    ``n = 0`` keeps none."""
    from selfnav.io.gnss_raw import sat_names

    win = (obs.t >= t_from) & (obs.t < t_to)
    systems, counts = np.unique(obs.system, return_counts=True)
    main = systems[np.argmax(counts)]
    names = sat_names(obs.system, obs.prn)
    cand, cnt = np.unique(names[win & (obs.system == main)], return_counts=True)
    keep = cand[np.argsort(-cnt, kind="stable")[:n]]
    return obs.select(~win | np.isin(names, keep))


def receiver_drift(raw, t_start: float, duration: float, rate: float, direction_enu, ref_llh,
                   *, doppler: bool = False, hold: bool = True):
    """A copy of a raw record (:class:`selfnav.io.gnss_raw.RawGnss`, with ephemerides) whose
    pseudoranges move as by a receiver displaced ``rate`` m/s along ``direction_enu`` from
    ``t_start`` (GPS s) for ``duration`` s, then held there (``hold``) or released: every
    satellite by ``−u·d`` (``u`` its line of sight from ``ref_llh`` = (lat, lon rad, h m)) — a
    spoofer's drag or issue 23's geometry-consistent drift, invisible to per-satellite tests.
    ``doppler``: the Dopplers move with it (``−u·ḋ``)."""
    from selfnav.earth import enu_rotation, geodetic_to_ecef
    from selfnav.gnss.ephemeris import satellite_states, select_ephemeris

    obs = raw.obs
    dt = np.clip(obs.t - t_start, 0.0, None)
    d = np.minimum(dt, duration) * rate if hold else np.where(dt <= duration, dt * rate, 0.0)
    moving = (obs.t >= t_start) & (obs.t <= t_start + duration)
    ie = select_ephemeris(raw.eph, obs.system, obs.prn, obs.t)
    sat = satellite_states(raw.eph, ie, obs.t - 0.07)[0]
    r0 = geodetic_to_ecef(*ref_llh)
    u = sat - r0
    u = u / np.linalg.norm(u, axis=1)[:, None]
    e = enu_rotation(ref_llh[0], ref_llh[1]).T @ (np.asarray(direction_enu, float)
                                                  / np.linalg.norm(direction_enu))
    ue = np.nan_to_num(u @ e)
    out = replace(obs, pseudorange=obs.pseudorange - ue * d, doppler=obs.doppler.copy())
    if doppler:
        out.doppler = obs.doppler + np.where(moving, ue * rate, 0.0) * obs.frequency / C_LIGHT
    return replace(raw, obs=out)

