"""Satellite positions, velocities and clocks from broadcast ephemerides (vectorized).

* GPS, QZSS, Galileo, BeiDou: the Keplerian user algorithm of IS-GPS-200 (Table 20-IV), with
  each system's μ and Ω_e (Galileo OS SIS ICD §5.1.1, BDS-SIS-ICD-B1I §5.2.4); BeiDou GEO
  satellites (PRN 1–5, 59–63) rotated by R_X(−5°) R_Z(Ω_e t_k) into BDCS (BDS ICD §5.2.4.12).
* GLONASS: 4th-order Runge–Kutta integration of the PZ-90 equations of motion with J2 and the
  broadcast lunisolar acceleration, steps ≤ 60 s (ICD GLONASS 2008, Appendix A.3.1.2).
* Clock: ``δt = a_f0 + a_f1 (t − t_oc) + a_f2 (t − t_oc)² + Δt_r``, relativistic
  ``Δt_r = F e √A sin E_k``, F = −4.442807633e−10 s/m^½ (IS-GPS-200 §20.3.3.3.3.1); GLONASS
  ``δt = −τ_n + γ_n (t − t_b)``. Group delays are applied per signal by the caller.

Positions are ECEF (WGS-84 / GTRF / BDCS / PZ-90, within decimetres of each other) at the
given transmit time, in the Earth frame of that time.
"""
from __future__ import annotations

import numpy as np

from selfnav.io.gnss_raw import (BDT_OFFSET_S, BEIDOU, GALILEO, GLONASS, GPS, GPS_WEEK_S, QZSS,
                                 Ephemerides)

MU_GPS = 3.986005e14
MU_GAL = 3.986004418e14
MU_BDS = 3.986004418e14
OMEGA_E_GPS = 7.2921151467e-5
OMEGA_E_BDS = 7.292115e-5
F_REL = -4.442807633e-10
# GLONASS PZ-90 (ICD 2008, Table 3.2)
MU_GLO = 3.9860044e14
A_GLO = 6378136.0
J2_GLO = 1.0826257e-3
OMEGA_E_GLO = 7.292115e-5
#: largest |t − t_oe| an ephemeris is used for, s (RTKLIB's MAXDTOE values)
MAX_AGE_S = {GPS: 7200.0, QZSS: 7200.0, GALILEO: 14400.0, BEIDOU: 21600.0, GLONASS: 1800.0}


def select_ephemeris(eph: Ephemerides, system, prn, t, *, healthy_only: bool = True):
    """Index into ``eph`` of the ephemeris with the nearest ``toe`` for each (system, prn, t),
    −1 where none is within :data:`MAX_AGE_S` (or all are unhealthy)."""
    system = np.asarray(system, int)
    prn = np.asarray(prn, int)
    t = np.asarray(t, float)
    out = np.full(t.shape, -1, int)
    if len(eph) == 0:
        return out
    ok_eph = (eph.health == 0) | ~np.isfinite(eph.health) if healthy_only else np.ones(len(eph), bool)
    key_e = eph.system.astype(np.int64) * 1000 + eph.prn
    key_o = system.astype(np.int64) * 1000 + prn
    for k in np.unique(key_o):
        rows = np.flatnonzero((key_e == k) & ok_eph)
        if rows.size == 0:
            continue
        sel = np.flatnonzero(key_o == k)
        d = np.abs(t[sel, None] - eph.toe[rows][None, :])
        best = np.argmin(d, axis=1)
        age = d[np.arange(len(sel)), best]
        lim = MAX_AGE_S.get(int(k // 1000), 7200.0)
        out[sel] = np.where(age <= lim, rows[best], -1)
    return out


def _kepler_E(M, e, iters=10):
    E = M.copy()
    for _ in range(iters):
        E = E - (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
    return E


def kepler_position(eph: Ephemerides, idx, t):
    """ECEF position (N, 3) and the eccentric anomaly of Keplerian ephemerides ``idx`` at GPS
    times ``t`` (IS-GPS-200 Table 20-IV)."""
    idx = np.asarray(idx, int)
    t = np.asarray(t, float)
    p = {k: v[idx] for k, v in eph.params.items()}
    sysc = eph.system[idx]
    prn = eph.prn[idx]
    mu = np.where(sysc == GPS, MU_GPS, np.where(sysc == QZSS, MU_GPS, MU_GAL))
    we = np.where(sysc == BEIDOU, OMEGA_E_BDS, OMEGA_E_GPS)
    toe = eph.toe[idx]
    # seconds of week of toe in the system's own time (BDT = GPST − 14 s)
    toe_sow = np.mod(toe - np.where(sysc == BEIDOU, BDT_OFFSET_S, 0.0), GPS_WEEK_S)
    A = p["sqrt_a"] ** 2
    tk = t - toe
    n = np.sqrt(mu / A**3) + p["delta_n"]
    M = p["m0"] + n * tk
    e = p["e"]
    E = _kepler_E(M, e)
    nu = np.arctan2(np.sqrt(1 - e * e) * np.sin(E), np.cos(E) - e)
    phi = nu + p["omega"]
    s2, c2 = np.sin(2 * phi), np.cos(2 * phi)
    u = phi + p["cus"] * s2 + p["cuc"] * c2
    r = A * (1 - e * np.cos(E)) + p["crs"] * s2 + p["crc"] * c2
    i = p["i0"] + p["idot"] * tk + p["cis"] * s2 + p["cic"] * c2
    xp, yp = r * np.cos(u), r * np.sin(u)
    geo = (sysc == BEIDOU) & ((prn <= 5) | (prn >= 59))
    Om = p["omega0"] + (p["omega_dot"] - we) * tk - we * toe_sow
    Om_geo = p["omega0"] + p["omega_dot"] * tk - we * toe_sow
    Om = np.where(geo, Om_geo, Om)
    cO, sO, ci, si = np.cos(Om), np.sin(Om), np.cos(i), np.sin(i)
    x = xp * cO - yp * ci * sO
    y = xp * sO + yp * ci * cO
    z = yp * si
    pos = np.column_stack([x, y, z])
    if np.any(geo):
        g = np.flatnonzero(geo)
        a5 = np.radians(-5.0)
        th = we[g] * tk[g]
        xg, yg, zg = x[g], y[g], z[g]
        # R_X(−5°): y' = y cos + z sin, z' = −y sin + z cos (frame rotation)
        y1 = yg * np.cos(a5) + zg * np.sin(a5)
        z1 = -yg * np.sin(a5) + zg * np.cos(a5)
        # R_Z(Ω_e t_k)
        pos[g, 0] = xg * np.cos(th) + y1 * np.sin(th)
        pos[g, 1] = -xg * np.sin(th) + y1 * np.cos(th)
        pos[g, 2] = z1
    return pos, E


def _glonass_accel(state, acc_ls):
    r = state[:, :3]
    v = state[:, 3:]
    r2 = np.sum(r * r, axis=1)
    rn = np.sqrt(r2)
    a = -MU_GLO / (r2 * rn)
    b = 1.5 * J2_GLO * MU_GLO * A_GLO**2 / (r2 * r2 * rn)
    c = 5.0 * r[:, 2] ** 2 / r2
    w2 = OMEGA_E_GLO**2
    out = np.empty_like(state)
    out[:, :3] = v
    out[:, 3] = (a + b * (c - 1) + w2) * r[:, 0] + 2 * OMEGA_E_GLO * v[:, 1] + acc_ls[:, 0]
    out[:, 4] = (a + b * (c - 1) + w2) * r[:, 1] - 2 * OMEGA_E_GLO * v[:, 0] + acc_ls[:, 1]
    out[:, 5] = (a + b * (c - 3)) * r[:, 2] + acc_ls[:, 2]
    return out


def glonass_state(eph: Ephemerides, idx, t, step: float = 60.0):
    """PZ-90 position and velocity (N, 3) of GLONASS ephemerides ``idx`` at GPS times ``t``:
    RK4 from ``t_b`` with equal steps of at most ``step`` s (ICD GLONASS 2008, A.3.1.2)."""
    idx = np.asarray(idx, int)
    p = eph.params
    state = np.column_stack([p[k][idx] for k in ("x", "y", "z", "vx", "vy", "vz")])
    acc = np.column_stack([p[k][idx] for k in ("ax", "ay", "az")])
    acc = np.where(np.isfinite(acc), acc, 0.0)
    tk = np.asarray(t, float) - eph.toe[idx]
    nsteps = int(np.ceil(np.max(np.abs(tk)) / step)) if tk.size else 0
    if nsteps == 0:
        return state[:, :3], state[:, 3:]
    h = (tk / nsteps)[:, None]
    for _ in range(nsteps):
        k1 = _glonass_accel(state, acc)
        k2 = _glonass_accel(state + 0.5 * h * k1, acc)
        k3 = _glonass_accel(state + 0.5 * h * k2, acc)
        k4 = _glonass_accel(state + h * k3, acc)
        state = state + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return state[:, :3], state[:, 3:]


def satellite_states(eph: Ephemerides, idx, t, *, dt_vel: float = 0.01):
    """Satellite ECEF position (N, 3), velocity (N, 3), clock offset (N,) s and clock drift
    (N,) s/s at GPS transmit times ``t`` for ephemeris rows ``idx`` (−1: NaN).

    The clock includes the relativistic term; no group delay. Keplerian velocities are central
    differences over ±``dt_vel`` (error below 1 µm/s).
    """
    idx = np.asarray(idx, int)
    t = np.asarray(t, float)
    N = len(idx)
    pos = np.full((N, 3), np.nan)
    vel = np.full((N, 3), np.nan)
    clk = np.full(N, np.nan)
    drift = np.full(N, np.nan)
    ok = idx >= 0
    if not ok.any():
        return pos, vel, clk, drift
    sysc = np.where(ok, eph.system[np.maximum(idx, 0)], 0)
    glo = ok & (sysc == GLONASS)
    kep = ok & ~glo & np.isin(sysc, (GPS, QZSS, GALILEO, BEIDOU))
    if kep.any():
        k = np.flatnonzero(kep)
        i, tt = idx[k], t[k]
        p0, E = kepler_position(eph, i, tt)
        pp, _ = kepler_position(eph, i, tt + dt_vel)
        pm, _ = kepler_position(eph, i, tt - dt_vel)
        pos[k] = p0
        vel[k] = (pp - pm) / (2 * dt_vel)
        P = eph.params
        dtc = tt - eph.toc[i]
        e, sa = P["e"][i], P["sqrt_a"][i]
        rel = F_REL * e * sa * np.sin(E)
        af2 = np.where(np.isfinite(P["af2"][i]), P["af2"][i], 0.0)
        clk[k] = P["af0"][i] + P["af1"][i] * dtc + af2 * dtc**2 + rel
        # relativistic drift F e √A cos E · Ė,  Ė = n / (1 − e cos E)
        mu = np.where(eph.system[i] == BEIDOU, MU_BDS,
                      np.where(eph.system[i] == GALILEO, MU_GAL, MU_GPS))
        n = np.sqrt(mu / sa**6) + P["delta_n"][i]
        drift[k] = P["af1"][i] + 2 * af2 * dtc + F_REL * e * sa * np.cos(E) * n / (1 - e * np.cos(E))
    if glo.any():
        g = np.flatnonzero(glo)
        i = idx[g]
        pos[g], vel[g] = glonass_state(eph, i, t[g])
        P = eph.params
        gam = np.where(np.isfinite(P["gamma_n"][i]), P["gamma_n"][i], 0.0)
        clk[g] = -P["tau_n"][i] + gam * (t[g] - eph.toe[i])
        drift[g] = gam
    return pos, vel, clk, drift


def group_delay(eph: Ephemerides, idx, system, signal):
    """Broadcast group delay (s) to subtract from the satellite clock for a single-frequency
    user of ``signal`` (IS-GPS-200 §20.3.3.3.3.2; Galileo OS ICD §5.1.5; BDS ICD §5.2.4.10).

    GPS/QZSS: L1 ``T_GD``, L2 ``γ T_GD`` (γ = (77/60)²); L5 and L2C without the CNAV ISC.
    Galileo (I/NAV clock, E1–E5b): E1 ``BGD(E1,E5b)``, E5b ``(f1/f7)² BGD``, E5a ``(f1/f5)²
    BGD(E1,E5a)``. BeiDou (D1/D2 clock referenced to B3I): B1I ``T_GD1``, B2I ``T_GD2``, B3I 0;
    B1C / B2a (no CNAV group delays in D1/D2) 0.
    """
    idx = np.asarray(idx, int)
    system = np.asarray(system, int)
    band = np.array([str(s)[:1] for s in np.atleast_1d(signal)])
    out = np.zeros(len(idx))
    ok = idx >= 0
    i = np.maximum(idx, 0)
    tgd = np.where(ok, eph.params["tgd"][i], 0.0) if len(eph) else np.zeros(len(idx))
    tgd2 = np.where(ok, eph.params["tgd2"][i], 0.0) if len(eph) else np.zeros(len(idx))
    tgd = np.where(np.isfinite(tgd), tgd, 0.0)
    tgd2 = np.where(np.isfinite(tgd2), tgd2, 0.0)
    gps = np.isin(system, (GPS, QZSS))
    out = np.where(gps & (band == "1"), tgd, out)
    out = np.where(gps & (band == "2"), (77.0 / 60.0) ** 2 * tgd, out)
    gal = system == GALILEO
    out = np.where(gal & (band == "1"), tgd, out)
    out = np.where(gal & (band == "7"), (154.0 / 118.0) ** 2 * tgd, out)
    out = np.where(gal & (band == "5"), (154.0 / 115.0) ** 2 * tgd2, out)
    bds = system == BEIDOU
    out = np.where(bds & (band == "2"), tgd, out)
    out = np.where(bds & (band == "7"), tgd2, out)
    return out
