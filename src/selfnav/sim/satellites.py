"""Simulated satellites, pseudoranges and Dopplers with known truth (SIMULATED data).

Constellations are Walker-like sets of broadcast ephemerides (GPS: 6 planes × 4–5 satellites,
55°, a = 26 560 km; Galileo: 3 planes × 8, 56°, a = 29 600 km; small eccentricities), so the
orbits come from the same Keplerian model a receiver evaluates
(:func:`selfnav.gnss.ephemeris.satellite_states`). Per epoch and visible satellite::

    ρ = |R_3(Ω τ) r^s(t − τ) − r(t)| + c (δt_r(t) − δt^s) + I + T + b_NLOS + ε
    ρ̇ = u·(v^s − v) + c (δṫ_r − δṫ^s) + ε_ρ̇,          D = −ρ̇ / λ

with the receiver clock ``δt_r = b0 + d t + random walk``, Klobuchar ``I`` (the broadcast
parameters are given to the receiver too: no ionospheric error unless ``iono_error`` scales
the true delay), Saastamoinen ``T``, noise ``ε`` of σ ``σ0 10^{(45 − C/N0)/20}`` with
``C/N0 = 30 + 18 sin E`` dBHz (8 dB less when reflected).

**Partial sky** (:class:`StreetCanyon`): buildings of height H on both sides of a street of
width W along azimuth ψ hide a satellite below ``atan(H / (W/2 / |sin(A − ψ)|))``; a hidden
satellite is received by reflection (NLOS, a positive bias of exponential size, slowly
varying) with probability ``p_nlos`` (fixed per satellite for the run), else not at all.
Faults (steps, ramps) are added with :func:`selfnav.sim.faults.inject_faults`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfnav.earth import OMEGA_EARTH, ecef_to_geodetic
from selfnav.gnss.atmosphere import azimuth_elevation, klobuchar, saastamoinen
from selfnav.gnss.ephemeris import satellite_states
from selfnav.io.gnss_raw import (F_L1, GALILEO, GPS, GPS_WEEK_S, Ephemerides, GnssObservations,
                                 RawGnss)
from selfnav.sim.faults import inject_faults

C_LIGHT = 299_792_458.0
#: Klobuchar parameters of the simulation (a moderate day)
ION_ALPHA = np.array([1.1176e-08, 7.4506e-09, -5.9605e-08, -5.9605e-08])
ION_BETA = np.array([9.0112e04, 4.9152e04, -1.3107e05, -3.2768e05])


@dataclass
class StreetCanyon:
    """Buildings along a street (see the module docstring); ``None`` fields: open sky."""

    azimuth_deg: float = 0.0
    width_m: float = 30.0
    height_m: float = 15.0
    p_nlos: float = 0.5
    nlos_bias_m: float = 20.0

    def mask_elevation(self, az):
        """Elevation (rad) below which a satellite at azimuth ``az`` (rad) is hidden."""
        s = np.abs(np.sin(az - np.radians(self.azimuth_deg)))
        d = 0.5 * self.width_m / np.maximum(s, 1e-6)
        return np.arctan2(self.height_m, d)


@dataclass
class SatSimConfig:
    """Options of :func:`simulate_gnss`.

    Attributes
    ----------
    t0 : GPS time of the first epoch, s since the GPS epoch (default 2024-03-06 10:00 GPST)
    rate_hz : epochs per second
    systems : constellations (GPS, GALILEO)
    sigma0 : m, pseudorange σ at 45 dBHz
    doppler_sigma0 : m/s, range-rate σ at 45 dBHz
    clock_bias_m, clock_drift_mps, clock_rw_mps : receiver clock b0 (m), drift (m/s), random
        walk of the drift (m/s/√s)
    elevation_mask_deg : below this nothing is received
    canyon : StreetCanyon or None (open sky)
    iono_error : the true ionosphere is ``(1 + iono_error)`` × the broadcast model's
    seed : random seed
    system_offset_m : {system code: m}, the receiver's clock offset of a constellation against
        GPS (hardware delays: metres to tens of metres between GPS and Galileo or BeiDou)
    """

    t0: float = 2304 * GPS_WEEK_S + 3 * 86400 + 36000.0
    rate_hz: float = 1.0
    systems: tuple = (GPS, GALILEO)
    sigma0: float = 1.5
    doppler_sigma0: float = 0.05
    clock_bias_m: float = 3.0e4
    clock_drift_mps: float = 30.0
    clock_rw_mps: float = 0.01
    elevation_mask_deg: float = 5.0
    canyon: StreetCanyon | None = None
    iono_error: float = 0.0
    seed: int = 0
    faults: list = field(default_factory=list)
    system_offset_m: dict = field(default_factory=dict)


def walker_ephemerides(t_ref: float, systems=(GPS, GALILEO), seed: int = 0) -> Ephemerides:
    """Broadcast-like Keplerian ephemerides of GPS- and Galileo-like constellations, one issue
    per satellite with ``toe = toc = t_ref`` (healthy, no group delay)."""
    rng = np.random.default_rng(seed)
    rows = []
    toe_sow = float(np.mod(t_ref, GPS_WEEK_S))
    for system in systems:
        if system == GPS:
            planes, per, a, inc, prn = 6, 5, 26_559_700.0, 55.0, 1
        elif system == GALILEO:
            planes, per, a, inc, prn = 3, 8, 29_600_318.0, 56.0, 1
        else:
            continue
        for p in range(planes):
            for k in range(per):
                omega0 = 2 * np.pi * p / planes + OMEGA_EARTH * toe_sow   # inertial node
                m0 = 2 * np.pi * k / per + np.pi * p / (planes * per) + rng.normal(0, 0.05)
                rows.append(dict(
                    system=system, prn=prn, toe=t_ref, toc=t_ref, iode=1.0, health=0.0, ura=2.0,
                    sqrt_a=np.sqrt(a), e=rng.uniform(0.001, 0.01), i0=np.radians(inc),
                    omega0=omega0, omega=rng.uniform(0, 2 * np.pi), m0=m0, delta_n=4.5e-9,
                    idot=0.0, omega_dot=-8.0e-9, cuc=0.0, cus=0.0, crc=0.0, crs=0.0, cic=0.0,
                    cis=0.0, af0=rng.normal(0, 2e-4), af1=rng.normal(0, 1e-12), af2=0.0,
                    tgd=0.0, tgd2=0.0))
                prn += 1
    return Ephemerides.from_rows(rows, ion={GPS: np.r_[ION_ALPHA, ION_BETA]},
                                 source="simulated constellation")


def _geometry(eph, idx, t_rx, r_rx):
    """Geometric range with the exact Earth rotation over the flight time (3 iterations of
    the transmit time), the rotated satellite positions, satellite clock and drift."""
    tau = np.full(len(idx), 0.075)
    for _ in range(3):
        pos, _, clk, dclk = satellite_states(eph, idx, t_rx - tau)
        th = OMEGA_EARTH * tau
        c, s = np.cos(th), np.sin(th)
        rot = np.column_stack([c * pos[:, 0] + s * pos[:, 1], -s * pos[:, 0] + c * pos[:, 1],
                               pos[:, 2]])
        rho = np.linalg.norm(rot - r_rx, axis=1)
        tau = rho / C_LIGHT
    return rho, rot, clk, dclk


def simulate_gnss(t, rx_ecef, rx_vel_ecef=None, cfg: SatSimConfig | None = None):
    """Raw measurements along a receiver trajectory (SIMULATED).

    Parameters
    ----------
    t : (E,) s, epochs relative to ``cfg.t0``
    rx_ecef : (E, 3) or (3,) m, true receiver positions
    rx_vel_ecef : (E, 3) m/s or None (static)
    cfg : SatSimConfig

    Returns
    -------
    raw : RawGnss (``source`` says simulated)
    truth : dict with ``t`` (GPS s), ``ecef``, ``clock_m``, ``drift_mps``, ``nlos`` (set of
        satellite names received by reflection), ``faults``
    """
    cfg = cfg or SatSimConfig()
    rng = np.random.default_rng(cfg.seed)
    t = np.asarray(t, float)
    E = len(t)
    rx = np.broadcast_to(np.asarray(rx_ecef, float), (E, 3)).copy()
    rv = np.zeros((E, 3)) if rx_vel_ecef is None else np.broadcast_to(
        np.asarray(rx_vel_ecef, float), (E, 3)).copy()
    tg = cfg.t0 + t
    eph = walker_ephemerides(cfg.t0 + t[-1] / 2 if E else cfg.t0, cfg.systems, cfg.seed)
    # receiver clock: bias + drift + random walk of the drift
    dtt = np.diff(t, prepend=t[0] if E else 0.0)
    drift = cfg.clock_drift_mps + np.cumsum(rng.normal(0, 1, E) * cfg.clock_rw_mps
                                            * np.sqrt(np.maximum(dtt, 0)))
    clock = cfg.clock_bias_m + np.cumsum(drift * dtt)
    ns = len(eph)
    nlos_draw = rng.uniform(size=ns)
    nlos_bias = rng.exponential(cfg.canyon.nlos_bias_m if cfg.canyon else 0.0, ns) + \
        (2.0 if cfg.canyon else 0.0)
    nlos_phase = rng.uniform(0, 2 * np.pi, ns)
    lat, lon, h = ecef_to_geodetic(rx)
    cols = {k: [] for k in ("t", "sys", "prn", "pr", "dop", "cn0")}
    nlos_names = set()
    idx = np.arange(ns)
    offset = np.array([cfg.system_offset_m.get(int(x), 0.0) for x in eph.system])
    for e in range(E):
        rho, rot, clk, dclk = _geometry(eph, idx, tg[e], rx[e])
        # the range rate is the derivative of this very range (as a real Doppler is)
        hd = 0.05
        rho_p = _geometry(eph, idx, tg[e] + hd, rx[e] + rv[e] * hd)[0]
        rho_m = _geometry(eph, idx, tg[e] - hd, rx[e] - rv[e] * hd)[0]
        rate_geo = (rho_p - rho_m) / (2 * hd)
        az, el = azimuth_elevation(rx[e], rot, lat[e], lon[e])
        vis = el > np.radians(cfg.elevation_mask_deg)
        bias = np.zeros(ns)
        refl = np.zeros(ns, bool)
        if cfg.canyon is not None:
            hidden = el < cfg.canyon.mask_elevation(az)
            refl = hidden & (nlos_draw < cfg.canyon.p_nlos)
            vis &= ~hidden | refl
            bias = np.where(refl, nlos_bias * (1 + 0.3 * np.sin(2 * np.pi * tg[e] / 60.0
                                                                + nlos_phase)), 0.0)
        cn0 = 30.0 + 18.0 * np.sin(np.maximum(el, 0)) - 8.0 * refl
        sig = cfg.sigma0 * 10.0 ** ((45.0 - cn0) / 20.0)
        sig_d = cfg.doppler_sigma0 * 10.0 ** ((45.0 - cn0) / 20.0)
        iono = (1 + cfg.iono_error) * klobuchar(tg[e], lat[e], lon[e], az, el, ION_ALPHA,
                                                ION_BETA, F_L1)
        tropo = saastamoinen(lat[e], h[e], el)
        pr = (rho + clock[e] + offset - C_LIGHT * clk + iono + tropo + bias
              + rng.normal(0, 1, ns) * sig)
        rr = rate_geo + drift[e] - C_LIGHT * dclk + rng.normal(0, 1, ns) * sig_d
        v = np.flatnonzero(vis)
        # the receiver's time tag runs with its clock
        cols["t"].append(np.full(len(v), tg[e] + clock[e] / C_LIGHT))
        cols["sys"].append(eph.system[v])
        cols["prn"].append(eph.prn[v])
        cols["pr"].append(pr[v])
        cols["dop"].append(-rr[v] * F_L1 / C_LIGHT)
        cols["cn0"].append(cn0[v])
        for j in np.flatnonzero(refl & vis):
            nlos_names.add(f"{'G' if eph.system[j] == GPS else 'E'}{eph.prn[j]:02d}")
    a = {k: np.concatenate(v) if v else np.zeros(0) for k, v in cols.items()}
    obs = GnssObservations.build(a["t"], a["sys"].astype(int), a["prn"].astype(int),
                                 np.full(len(a["t"]), "1C", dtype=object), pseudorange=a["pr"],
                                 doppler=a["dop"], cn0=a["cn0"], source="SIMULATED")
    if cfg.faults:
        obs = inject_faults(obs, cfg.faults)
    truth = {"t": tg, "t_tag": tg + clock / C_LIGHT, "ecef": rx, "vel_ecef": rv,
             "clock_m": clock, "drift_mps": drift, "nlos": nlos_names, "faults": list(cfg.faults)}
    return RawGnss(obs, eph, None, "SIMULATED satellites (selfnav.sim.satellites)"), truth


def simulate_raw_drive(kind: str = "car", *, seed: int = 0, grade: str = "industrial",
                       duration: float = 300.0, cfg: SatSimConfig | None = None):
    """A built-in scenario (:func:`selfnav.sim.scenarios.simulate`) with raw GNSS along its
    truth, for tight coupling (SIMULATED): ``(truth, raw, imu)``, the IMU (with the grade's
    errors) stamped in GPS time as the observations are (``cfg.t0`` + the scenario's time),
    epochs at ``cfg.rate_hz`` on whole seconds of the scenario."""
    from selfnav.earth import enu_rotation, geodetic_to_ecef
    from selfnav.sim.scenarios import simulate
    from selfnav.types import ImuData

    cfg = cfg or SatSimConfig(seed=seed)
    sim = simulate(kind, seed=seed, grade=grade, duration=duration)
    tr = sim.truth
    te = np.arange(np.ceil(tr.t[0]), tr.t[-1], 1.0 / cfg.rate_hz)
    lat, lon, h = (np.interp(te, tr.t, x) for x in (tr.lat, tr.lon, tr.h))
    v = np.column_stack([np.interp(te, tr.t, tr.velocity_n[:, i]) for i in range(3)])
    rx = np.array([geodetic_to_ecef(a, b, c) for a, b, c in zip(lat, lon, h)])
    rv = np.einsum("kji,kj->ki", enu_rotation(lat, lon), v)        # ENU → ECEF
    raw, _ = simulate_gnss(te, rx, rv, cfg)
    imu = ImuData(sim.imu.t + cfg.t0, sim.imu.omega_ib_b, sim.imu.f_ib_b,
                  source=f"simulated {kind} (seed {seed}, {grade})",
                  meta={**sim.imu.meta, "time": "gps"})
    return tr, raw, imu

