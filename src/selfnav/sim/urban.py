"""A car in city streets: pseudoranges with reflections and the car's odometry, in the smartLoc
form (SIMULATED data; for :mod:`selfnav.gnss.tight`, ``selfnav navigate --gnss-raw``).

The car drives straight streets joined by 90° turns (left or right, 20–60 s apart, with a stop
now and then) at 5–12 m/s. Satellites are the Walker-like constellations of
:mod:`selfnav.sim.satellites` (GPS + Galileo). Each street has buildings of its own height
(10–40 m) and width (16–40 m) on both sides along the car's heading: a satellite below the
buildings' edge (:class:`selfnav.sim.satellites.StreetCanyon`) is received by reflection with
probability ``p_nlos`` (drawn per satellite and street), late by an exponential delay (mean
``nlos_mean_m``) that varies slowly, at 8 dB less C/N0; else not at all. Every received signal
also carries multipath correlated over seconds (Gauss–Markov, τ ``multipath_tau``, σ = half the
code noise's) and white code noise ``σ0 10^((45 − C/N0)/20)``. As in the smartLoc files, the
pseudoranges are corrected already (satellite clock, atmosphere) and carry the satellite's
position at transmit time, Earth-fixed then::

    ρ = |r_s − r| + ω_e/c (x_s y − y_s x) + c δt_r + b_sys + delay + multipath + ε

The odometry has a scale error (±2 %), a yaw-rate bias (±0.1 °/s) and white noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from selfnav.earth import ecef_to_enu, enu_rotation, geodetic_to_ecef
from selfnav.gnss.atmosphere import azimuth_elevation
from selfnav.gnss.ephemeris import satellite_states
from selfnav.gnss.models import pseudorange_model
from selfnav.io.gnss_raw import GALILEO, GPS, GPS_WEEK_S
from selfnav.io.smartloc import Odometry, Pseudoranges, SmartlocTruth
from selfnav.sim.satellites import StreetCanyon, walker_ephemerides

#: libRSF system codes (the smartLoc format)
SMARTLOC_SYSTEM = {GPS: 1, GALILEO: 8}


@dataclass
class UrbanConfig:
    duration: float = 300.0          # s
    rate_hz: float = 5.0
    lat_deg: float = 52.5
    lon_deg: float = 13.37
    h_m: float = 40.0
    sigma0: float = 1.0              # m, code noise at 45 dBHz
    p_nlos: float = 0.5
    nlos_mean_m: float = 25.0
    multipath_tau: float = 5.0       # s
    speed_sigma: float = 0.05        # m/s
    yaw_rate_sigma: float = 0.002    # rad/s
    t0: float = 2304 * GPS_WEEK_S + 3 * 86400 + 36000.0


def _drive(cfg: UrbanConfig, rng):
    """Speed, yaw rate and the street index per sample: straights, 90° turns, stops."""
    dt = 1.0 / cfg.rate_hz
    t = np.arange(0.0, cfg.duration, dt)
    v = np.empty_like(t)
    w = np.zeros_like(t)
    street = np.zeros(len(t), int)
    k, s = 0, 0
    while k < len(t):
        length = rng.uniform(20.0, 60.0)
        cruise = rng.uniform(5.0, 12.0)
        n = int(length / dt)
        seg = np.full(n, cruise)
        ramp = min(int(4.0 / dt), n // 3)
        if rng.uniform() < 0.25:                      # a stop at the street's end
            seg[-ramp:] = np.linspace(cruise, 0.0, ramp)
            seg = np.r_[seg, np.zeros(int(rng.uniform(5, 15) / dt))]
            seg = np.r_[seg, np.linspace(0.0, cruise, ramp)]
        turn = int(6.0 / dt)
        w_seg = np.zeros(len(seg) + turn)
        w_seg[len(seg):] = rng.choice([-1.0, 1.0]) * (math.pi / 2) / 6.0
        seg = np.r_[seg, np.full(turn, min(cruise, 6.0))]
        m = min(len(seg), len(t) - k)
        v[k:k + m], w[k:k + m] = seg[:m], w_seg[:m]
        street[k:k + m] = s
        k += m
        s += 1
    return t, v, w, street


def simulate_urban_drive(seed: int = 0, cfg: UrbanConfig | None = None):
    """One SIMULATED city drive (module docstring).

    Returns
    -------
    (Pseudoranges, Odometry, SmartlocTruth)
        times from 0 s; system codes as in the smartLoc format (1 GPS, 8 Galileo).
    """
    cfg = cfg or UrbanConfig()
    rng = np.random.default_rng(seed)
    t, v, w, street = _drive(cfg, rng)
    heading0 = rng.uniform(0, 2 * math.pi)
    # truth track (exact integration at the samples' midpoints)
    H = heading0 - np.r_[0.0, np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))]
    Hm = 0.5 * (H[1:] + H[:-1])
    ds = 0.5 * (v[1:] + v[:-1]) * np.diff(t)
    E = np.r_[0.0, np.cumsum(ds * np.sin(Hm))]
    N = np.r_[0.0, np.cumsum(ds * np.cos(Hm))]
    lat0, lon0 = math.radians(cfg.lat_deg), math.radians(cfg.lon_deg)
    r0 = geodetic_to_ecef(lat0, lon0, cfg.h_m)
    C_en = enu_rotation(lat0, lon0)
    r = r0 + np.column_stack([E, N, np.zeros(len(t))]) @ C_en
    # satellites, clocks
    eph = walker_ephemerides(cfg.t0 + cfg.duration / 2, (GPS, GALILEO), seed)
    ns = len(eph)
    clock = 2.0e4 - 40.0 * t + np.cumsum(rng.normal(0, 0.05, len(t)))
    isb = {GPS: 0.0, GALILEO: rng.normal(0, 10.0)}
    b = np.array([isb[s] for s in eph.system])                  # per satellite
    code = np.array([SMARTLOC_SYSTEM[s] for s in eph.system], int)
    n_streets = int(street.max()) + 1
    width = rng.uniform(16.0, 40.0, n_streets)
    height = rng.uniform(10.0, 40.0, n_streets)
    p_draw = rng.uniform(size=(n_streets, ns))
    delay = rng.exponential(cfg.nlos_mean_m, (n_streets, ns)) + 2.0
    phase = rng.uniform(0, 2 * math.pi, ns)
    mp = np.zeros(ns)
    rows = {k: [] for k in ("t", "pr", "sat", "sys", "prn", "el", "cn0")}
    for k in range(len(t)):
        tt = cfg.t0 + t[k]
        pos, _, _, _ = satellite_states(eph, np.arange(ns), np.full(ns, tt - 0.075))
        az, el = azimuth_elevation(r[k], pos, lat0, lon0)
        canyon = StreetCanyon(math.degrees(H[k]), width[street[k]], height[street[k]])
        hidden = el < canyon.mask_elevation(az)
        refl = hidden & (p_draw[street[k]] < cfg.p_nlos)
        vis = (el > math.radians(10.0)) & (~hidden | refl)
        cn0 = 30.0 + 18.0 * np.sin(np.maximum(el, 0)) - 8.0 * refl
        sig = cfg.sigma0 * 10.0 ** ((45.0 - cn0) / 20.0)
        phi = math.exp(-(t[k] - t[k - 1]) / cfg.multipath_tau) if k else 0.0
        mp = phi * mp + rng.normal(0, 1, ns) * 0.5 * sig * math.sqrt(1 - phi * phi)
        late = np.where(refl, delay[street[k]] * (1 + 0.3 * np.sin(2 * math.pi * t[k] / 40.0
                                                                   + phase)), 0.0)
        rho, _ = pseudorange_model(r[k], clock[k], pos)
        pr = rho + b + late + mp + rng.normal(0, 1, ns) * sig
        i = np.flatnonzero(vis)
        rows["t"].append(np.full(len(i), t[k]))
        rows["pr"].append(pr[i])
        rows["sat"].append(pos[i])
        rows["sys"].append(code[i])
        rows["prn"].append(eph.prn[i].astype(int))
        rows["el"].append(el[i])
        rows["cn0"].append(cn0[i])
    a = {key: np.concatenate(val) for key, val in rows.items()}
    n = len(a["t"])
    prs = Pseudoranges(a["t"], a["pr"], np.full(n, 25.0), a["sat"], a["prn"], a["sys"], a["el"],
                       a["cn0"], source="SIMULATED urban drive (selfnav.sim.urban)")
    scale = 1.0 + rng.uniform(-0.02, 0.02)
    bias = math.radians(rng.uniform(-0.1, 0.1))
    speed = v / scale + rng.normal(0, cfg.speed_sigma, len(t))
    speed[v == 0] = 0.0
    yaw = w + bias + rng.normal(0, cfg.yaw_rate_sigma, len(t))
    odo = Odometry(t, np.column_stack([speed, np.zeros((len(t), 2))]),
                   np.column_stack([np.zeros((len(t), 2)), yaw]),
                   np.tile([cfg.speed_sigma ** 2, 0, 0, 0, 0, cfg.yaw_rate_sigma ** 2],
                           (len(t), 1)), source="SIMULATED urban drive (selfnav.sim.urban)")
    truth = SmartlocTruth(t, r, source="SIMULATED urban drive (selfnav.sim.urban)")
    return prs, odo, truth


def horizontal_errors(t, east, north, origin, truth: SmartlocTruth):
    """Horizontal errors (m) of a track in the tangent plane at ``origin`` against the truth."""
    g = ecef_to_enu(truth.ecef, *origin)
    return np.hypot(east - np.interp(t, truth.t, g[:, 0]), north - np.interp(t, truth.t, g[:, 1]))


__all__ = ["UrbanConfig", "simulate_urban_drive", "horizontal_errors"]
