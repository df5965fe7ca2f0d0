"""Seed 004 road-vehicle navigator: fast strapdown loop + slow map/GNSS loop, no optimal filter.

Shcherban, Tolmachev, Konev (seed ``004_…``, §3; DESIGN §5). The *fast loop* is the strapdown
mechanization (1)–(10) (:class:`selfnav.ins.strapdown.Strapdown`, on the Krasovsky ellipsoid in
SK-42 as the seed has it) run for ``k_M`` steps of ``T0``; the *slow loop*, at each GNSS fix
(``T_M = k_M T0``), does:

1. INS position SK-42 → WGS-84 (geodetic → ECEF → Helmert, GOST), GNSS (PZ-90 in the seed's case)
   → WGS-84 (:mod:`selfnav.datum`);
2. mean magnetic course over the period (12), corrected to the direction of the road from the
   map → ``K^ист``;
3. the mean speed ΔV (11) and predicted travel ``ΔS = T_M ΔV`` (13). **Erratum** (DESIGN §5):
   (11) prints ``T0·|n|``, the magnitude of specific force (gravity included); selfnav reads it
   as the mean fast-loop speed ``|V|`` over the period
   (:func:`selfnav.ins.strapdown.slow_period_speed`);
4. the ``m`` road points in the neighbourhood of the prediction (road centre lines sampled every
   ``point_step`` m within ``radius`` of it);
5. identification by minimising residuals over the INS prediction, the recent GNSS fixes
   (each carried to now by the travel since it) and the course: a bounded (Tukey) loss on the
   GNSS residuals and a GNSS health test (fix-to-fix steps against the travel) so that an
   unflagged 200 m outlier can pull the solution neither off the road (only road points are
   candidates) nor along it;
6. back-conversion WGS-84 → SK-42 (iterative ECEF → geodetic), and the reset of the fast loop:
   φ, λ, h; velocities from position differences (14); heading from the road, pitch from V_h
   (15).

Gaps the seed leaves, filled and said so here:

* the initial state: the in-motion alignment of the EKF (:func:`selfnav.ins.init_from_gnss`)
  over a 15-fix window, started after the first run of 20 healthy fixes (:func:`robust_init`;
  an outlier window at start-up must not seed the navigator hundreds of metres off), heading
  from the nearest road direction — the navigator starts there;
* the height: the road map has none; ``h`` is the mean of the last ``n_height`` healthy GNSS
  heights (held through outlier windows), so (14)'s ``V_h`` and (15)'s pitch are smooth (a
  median of 10 fixes at σ_v 15 m moved metres per second: pitch errors of 20°, which leak
  gravity into the speed and wreck the tilt compensation of the magnetometer);
* the first reset uses the alignment's velocity (a position difference over the first, partial
  period divides the alignment error by a fraction of a second);
* the velocity of (14) is a position difference over the period, i.e. the velocity at
  mid-period; taken literally as the initial velocity of the next period it lags by ``T_M/2``
  and follows only half of every acceleration (braking before a corner is missed by metres per
  second). ``velocity_reset="end"`` (default) adds the fast loop's own velocity change over the
  second half of the period, limits what one identification correction may change it by, and
  (inside GNSS outlier windows) adds the mean speed correction of the last healthy periods —
  the drift of the fast loop's speed, which the seed's (11) says carries the accelerometer
  errors; ``"literal"`` is the print;
* the roll: (15) resets K and pitch only. With consumer gyros (1 °/s turn-on bias) a roll left
  to the gyros is tens of degrees off within a minute and its gravity leak wrecks the speed;
  ``roll="level"`` (default) resets it from the mean specific force of the period corrected
  for the centripetal term, ``roll="keep"`` is the literal seed.

``matcher="mht"`` replaces step 5 by the road-constrained particle matcher of
:mod:`selfnav.roads.particles` (driven by the same ΔS and course); everything else stays.

**Odometer** (beyond the seed, optional): with wheel speed the mean speed of (11) is the
odometer's over the period, divided by ``1 + k̂``, and the speed of the reset (14) is the
odometer's at the end of the period (the direction stays (14)'s). ``k̂``, the odometer's
scale-factor error, is fitted by least squares to the healthy fixes: their displacement from
the first healthy fix against the odometer's travel integrated along the road course since,
``Δz ≈ Δo / (1 + k)`` (once ``odo_learn_m`` metres are behind; the loop has no filter state for
it, and the identified positions, which follow the odometer's own prediction, cannot tell).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfnav import attitude as att
from selfnav import datum as dm
from selfnav.earth import KRASOVSKY, radii
from selfnav.errors import SelfnavError
from selfnav.roads.particles import MatcherConfig, RoadParticles, move_particles, successor_table, wrap
from selfnav.roads.graph import RoadGraph
from selfnav.types import Trajectory
from selfnav.ins.align import healthy_start, robust_init
from selfnav.ins.strapdown import Strapdown


@dataclass
class SeedConfig:
    """Options of :func:`run_seed` (SI, radians)."""

    matcher: str = "seed"             # "seed" (residual minimisation) or "mht" (particles)
    ins_datum: str = "sk42"           # datum of the fast loop (seed: SK-42 on Krasovsky)
    sigma_gnss: float = 10.0          # nominal GNSS σ per axis, m (seed: 10 m)
    n_fixes: int = 5                  # recent fixes in the identification
    tukey_c: float = 5.0              # Tukey cut-off in σ
    sigma_pred: float = 0.5           # σ of the INS prediction, m (+ pred_rel · ΔS)
    pred_rel: float = 0.02
    n_height: int = 60                # healthy GNSS heights averaged for h, fixes
    sigma_course: float = np.radians(15.0)
    radius: float = 25.0              # neighbourhood of the prediction, m
    point_step: float = 0.5           # spacing of the m road points, m
    roll: str = "level"               # "level" or "keep" (literal (15))
    velocity_reset: str = "end"       # "end" (mid-period velocity carried to the end) or "literal"
    velocity_kick: float = 3.0        # m/s: most an identification correction changes V ("end")
    drift_window: int = 0             # healthy periods averaged for the speed drift (0: off)
    odo_learn_m: float = 300.0        # identified metres before the odometer scale is learnt
    declination: float | None = None  # rad; None: from the field model at the start
    mht: MatcherConfig = field(default_factory=MatcherConfig)


@dataclass
class SeedResult:
    """Output of :func:`run_seed`: the slow-loop solution (WGS-84) and per-epoch diagnostics."""

    trajectory: Trajectory
    diagnostics: dict
    stats: dict


def _tukey(r, c):
    """Tukey's biweight loss ρ(r) (bounded: c²/6 beyond c)."""
    x = np.minimum((r / c) ** 2, 1.0)
    return (c * c / 6.0) * (1.0 - (1.0 - x) ** 3)


def road_points(graph: RoadGraph, xy, radius, step, course=None, tol=np.radians(60.0)):
    """The ``m`` road points near ``xy``: centre lines sampled every ``step`` m inside the disc.

    Returns ``(points (m, 2), segment (m,), road heading (m,))``. With ``course`` only directed
    segments within ``tol`` of it are used (the direction of travel on two-way roads), unless
    none is.
    """
    import shapely

    si = np.asarray(graph.tree.query(shapely.points(np.asarray(xy, float)), predicate="dwithin",
                                     distance=radius), np.int64)
    if len(si) == 0:
        c = graph.candidates(np.atleast_2d(xy), radius, k=2, per_way=False)
        si = c.seg
    if course is not None:
        ok = np.abs(wrap(graph.seg_heading[si] - course)) <= tol
        if ok.any():
            si = si[ok]
    pts, segs = [], []
    for s in si:
        L = graph.seg_len[s]
        a = np.arange(0.0, L + 1e-9, step) if L > 0 else np.zeros(1)
        p = graph.segment_points(np.full(len(a), s), a)
        pts.append(p)
        segs.append(np.full(len(a), s))
    p = np.concatenate(pts)
    s = np.concatenate(segs)
    d = np.hypot(*(p - xy).T)
    keep = d <= max(radius, float(d.min()) + step)
    return p[keep], s[keep], graph.seg_heading[s[keep]]


def identify(points, heading, pred, fixes, course, cfg: SeedConfig, sigma_pred):
    """Seed step 5: the road point minimising the residuals (module docstring).

    ``fixes`` are the recent healthy GNSS fixes carried to the current time, (k, 2).
    Returns the index of the best point and its cost.
    """
    cost = np.sum((points - pred) ** 2, axis=1) / sigma_pred**2
    if len(fixes):
        r = np.hypot(points[:, None, 0] - fixes[None, :, 0], points[:, None, 1] - fixes[None, :, 1])
        cost = cost + _tukey(r / cfg.sigma_gnss, cfg.tukey_c).sum(axis=1) * 2.0
    if course is not None:
        cost = cost + (wrap(heading - course) / cfg.sigma_course) ** 2
    j = int(np.argmin(cost))
    return j, float(cost[j])


def _course_mean(mag_b, roll, pitch, declination):
    """(12): circular mean of the magnetic course over the period (+ declination: true)."""
    from selfnav.sensors import magnetic_heading

    k = magnetic_heading(mag_b, roll, pitch, declination)
    return float(np.arctan2(np.mean(np.sin(k)), np.mean(np.cos(k))) % (2 * np.pi))


def run_seed(imu, gnss, graph: RoadGraph, cfg: SeedConfig | None = None, *, gnss_datum="wgs84",
             init=None, progress=None, odometer=None) -> SeedResult:
    """Run the seed 004 navigator over a record.

    Parameters
    ----------
    imu : ImuData
        Rates in body RFU; ``mag_b`` (N, 3) magnetometer (any unit) if present — else the
        course of (12) is the INS heading.
    gnss : GnssData
        Fixes in ``gnss_datum`` (the seed: PZ-90), converted to WGS-84 here (step 1).
    graph : RoadGraph
    cfg : SeedConfig
    init : dict, optional
        Initial state (``t, lat, lon, h, velocity_n, C_nb``, WGS-84); default
        :func:`selfnav.ins.init_from_gnss`.
    odometer : OdometerData, optional
        Wheel speed on the IMU's clock (module docstring).
    """
    cfg = cfg or SeedConfig()
    if cfg.matcher not in ("seed", "mht"):
        raise SelfnavError(f"unknown matcher '{cfg.matcher}' (seed or mht)")
    ell = KRASOVSKY if dm.datum_key(cfg.ins_datum) == "sk42" else dm.ellipsoid_of(cfg.ins_datum)
    ins_d = dm.datum_key(cfg.ins_datum)
    # step 1 (GNSS part): fixes to WGS-84, then to the map plane
    glat, glon, gh = (np.asarray(x, float) for x in (gnss.lat, gnss.lon, gnss.h))
    if dm.datum_key(gnss_datum) != "wgs84":
        glat, glon, gh = dm.convert(glat, glon, gh, gnss_datum, "wgs84")
    gx, gy = graph.to_local(glat, glon)
    gxy = np.column_stack([gx, gy])
    sig = (np.asarray(gnss.sigma_m, float) if gnss.sigma_m is not None
           else np.full(len(gnss.t), np.nan))
    sig = np.where(np.isfinite(sig), sig, cfg.sigma_gnss)
    if init is None:
        from selfnav.types import GnssData

        g84 = GnssData(gnss.t, glat, glon, gh, sig, gnss.velocity_n, None, "wgs84")
        init = robust_init(imu, g84, graph, sigma=cfg.sigma_gnss)
    t0 = float(init["t"])
    lat0, lon0, h0 = dm.convert(init["lat"], init["lon"], init["h"], "wgs84", ins_d) \
        if ins_d != "wgs84" else (init["lat"], init["lon"], init["h"])
    ins = Strapdown(float(lat0), float(lon0), float(h0), init["velocity_n"], init["C_nb"], t=t0,
                    ellipsoid=ell)
    mag = getattr(imu, "mag_b", None)
    decl = cfg.declination
    if decl is None and mag is not None:
        from selfnav.sensors import declination_inclination, earth_field_n

        decl = float(declination_inclination(earth_field_n(init["lat"], init["lon"], init["h"]))[0])
    decl = 0.0 if decl is None else decl
    dt_imu = np.diff(np.concatenate([[imu.t[0] - imu.dt], imu.t]))
    dth_all = imu.omega_ib_b * dt_imu[:, None]
    dv_all = imu.f_ib_b * dt_imu[:, None]

    x0, y0 = graph.to_local(init["lat"], init["lon"])
    p_prev = np.array([float(x0), float(y0)])
    pf = None
    _, _, hd_init = att.euler_from_dcm_nb(init["C_nb"])
    c0 = graph.candidates(p_prev[None], 50.0, k=1, per_way=False, heading=np.array([hd_init]),
                          heading_tol=np.pi / 2)
    seg_prev, along_prev = int(c0.seg[0]), float(c0.along[0])
    succ_off, succ = successor_table(graph)
    if cfg.matcher == "mht":
        pf = RoadParticles(graph, cfg.mht, seed=0)
        _, _, hd0 = att.euler_from_dcm_nb(init["C_nb"])
        pf.seed(p_prev, max(cfg.mht.seed_radius, 30.0), heading=float(hd0))
    health = RoadParticles(graph, MatcherConfig(sigma_gnss=cfg.sigma_gnss))  # its step test only
    recent = []          # (fix xy carried to now) of healthy fixes
    h_recent = []
    h_hold = float(init["h"])
    out = {k: [] for k in ("t", "lat", "lon", "h", "vel", "C", "course", "course_road", "ds",
                           "healthy", "m", "cost", "k_m", "ins_offset")}
    i_imu = int(np.searchsorted(imu.t, t0, side="right"))
    fix_idx = np.flatnonzero(gnss.t > t0)
    h_prev_ins = float(h0)
    _prev_geo = (float(lat0), float(lon0))
    reacq = 0
    drift = []           # speed corrections of the healthy periods, m/s
    last_fix = []        # the last 22 fixes (map plane), for the INS-free health test
    odo_k = 0.0          # odometer scale-factor error estimate
    odo_vec = np.zeros(2)  # odometer travel integrated along the road course, m
    odo_ref = None       # (odometer vector, fix) of the first healthy fix
    odo_sum = np.zeros(2)  # Σ Δz·Δo and Σ Δo·Δo over the healthy fixes
    for n_fix, k in enumerate(fix_idx):
        j = int(np.searchsorted(imu.t, gnss.t[k], side="right"))
        if j - i_imu < 1:
            continue
        # ---------------- fast loop: k_M steps of (1)-(10)
        tr = ins.run(imu.t[i_imu:j], dth_all[i_imu:j], dv_all[i_imu:j])
        T_M = float(imu.t[j - 1] - imu.t[i_imu] + dt_imu[i_imu])
        k_m = j - i_imu
        # (11) erratum reading: the mean fast-loop speed over the period (horizontal)
        dV = float(np.mean(np.hypot(tr.velocity_n[:, 0], tr.velocity_n[:, 1])))
        if odometer is not None:     # the wheel speed over the period, scale corrected
            v_odo = np.interp(tr.t, odometer.t, odometer.speed_mps)
            dV_raw = float(np.mean(v_odo))
            dV = dV_raw / (1.0 + odo_k)
        roll_b, pitch_b, hdg_b = att.euler_from_dcm_nb(tr.C_nb)
        # (12): mean magnetic course over the period (true: + declination)
        K_ins = float(np.arctan2(np.mean(np.sin(hdg_b)), np.mean(np.cos(hdg_b))) % (2 * np.pi))
        K_mean = K_ins
        # levelling of the period from the mean specific force (centripetal and along-track
        # acceleration removed, clipped at ±6°: a car does not tilt more); used for the
        # magnetometer's tilt compensation and the roll of the reset
        f_x = float(np.mean(imu.f_ib_b[i_imu:j, 0]))
        f_y = float(np.mean(imu.f_ib_b[i_imu:j, 1]))
        w_z = float(np.mean(imu.omega_ib_b[i_imu:j, 2]))
        spd = np.hypot(tr.velocity_n[:, 0], tr.velocity_n[:, 1])
        a_long = float(spd[-1] - spd[0]) / max(float(tr.t[-1] - tr.t[0]), 1e-3)
        g0 = 9.81
        roll_lev = float(np.arcsin(np.clip(-(f_x + dV * w_z) / g0, -0.1, 0.1)))
        pitch_lev = float(np.arcsin(np.clip((f_y - a_long) / g0, -0.1, 0.1)))
        if mag is not None:
            K_mag = _course_mean(mag[i_imu:j], roll_lev, pitch_lev, decl)
            # a magnetic course more than 120° from the gyro-carried course of the period
            # (which starts from the road direction) is a blunder (tilt, disturbance): not used
            if abs(float(wrap(K_mag - K_ins))) < np.radians(120.0):
                K_mean = K_mag
        i_imu = j
        # step 1 (INS part): SK-42 -> WGS-84 -> map plane
        if ins_d != "wgs84":
            la, lo, _ = dm.convert(ins.lat, ins.lon, ins.h, ins_d, "wgs84")
        else:
            la, lo = ins.lat, ins.lon
        p_ins = np.array([float(v) for v in graph.to_local(la, lo)])
        # (13): predicted travel along the map-corrected course
        dS = T_M * dV
        z = gxy[k]
        # GNSS health: the fix-to-fix step against the predicted travel along the mean course
        health._disp = dS * np.array([np.sin(K_mean), np.cos(K_mean)])
        ok = health.gnss_health(z, sig[k])
        # ... or the fixes are consistent among themselves (second differences over the last
        # 20, as at the start): a runaway fast loop must not get every fix judged unhealthy
        # and so never be corrected again
        last_fix.append(z.copy())
        del last_fix[:-22]
        if not ok and len(last_fix) == 22:
            ok = healthy_start(None, np.asarray(last_fix), np.full(22, sig[k]), 20) == 0
        if pf is None:
            # step 2: the course corrected to the road: the road direction nearest to K^ср
            # where the vehicle is; step 3: the prediction walks ΔS (13) along the road graph
            # from the last identified point, taking at a junction the branch nearest to K^ср
            sg, al = np.array([seg_prev]), np.array([along_prev])
            move_particles(sg, al, np.array([dS]), graph.seg_len, graph.seg_heading, graph.seg_twin,
                  succ_off, succ, K_mean, np.radians(20.0), 0.0, np.ones(1), np.full((1, 4), 0.5))
            pred = graph.segment_points(sg, al)[0]
            pred_pt = pred
            step = pred - p_prev
            recent = [r + step for r in recent]
            if ok:
                recent.append(z.copy())
            recent = recent[-cfg.n_fixes:]
            # step 4: the m road points around the prediction
            pts, segs, hds = road_points(graph, pred, cfg.radius, cfg.point_step, K_mean)
            # step 5: identification by minimising residuals
            jbest, cost = identify(pts, hds, pred, np.asarray(recent).reshape(-1, 2), K_mean,
                                   cfg, cfg.sigma_pred + cfg.pred_rel * dS)
            p_new = pts[jbest]
            K_road = float(hds[jbest])
            m_pts = len(pts)
            # lost track (a missed branch: the bounded loss then ignores every fix): when the
            # last n healthy fixes, carried to now, agree with each other and sit more than
            # max(15 m, 1.5 σ) from the solution, re-acquire on the road nearest their mean
            if ok and len(recent) >= cfg.n_fixes:
                rr = np.asarray(recent) - p_new
                if (np.hypot(*rr.mean(axis=0)) > max(15.0, 1.5 * cfg.sigma_gnss)
                        and np.median(np.hypot(*(rr - rr.mean(axis=0)).T)) < 2.0 * cfg.sigma_gnss):
                    centre = np.asarray(recent).mean(axis=0)
                    pts2, segs2, hds2 = road_points(graph, centre, 3.0 * cfg.sigma_gnss,
                                                    cfg.point_step, K_mean)
                    j2 = int(np.argmin(np.hypot(*(pts2 - centre).T)))
                    pts, segs, hds, jbest = pts2, segs2, hds2, j2
                    p_new, K_road = pts2[j2], float(hds2[j2])
                    reacq += 1
            seg_prev = int(segs[jbest])
            along_prev = float(np.hypot(*(p_new - graph.xy[graph.seg_u[seg_prev]])))
        else:
            pf.predict(dS, K_mean, T_M)
            pred_pt = p_prev + dS * np.array([np.sin(K_mean), np.cos(K_mean)])
            if ok:                      # the health test is done above, for both matchers
                pf.weigh_gnss(z, sig[k])
            est = pf.estimate()
            p_new, K_road, cost, m_pts = est["xy"], est["heading"], est["spread"], len(pf.seg)
        # height: median of the recent healthy GNSS heights (held through outliers)
        if ok:
            h_recent = (h_recent + [float(gh[k])])[-cfg.n_height:]
            h_hold = float(np.mean(h_recent))
        # step 6: back-conversion WGS-84 -> SK-42 (iterative inverse) and the reset (14)-(15)
        lat84, lon84 = graph.to_geodetic(p_new[0], p_new[1])
        if ins_d != "wgs84":
            lat_n, lon_n, h_n = dm.convert(float(lat84), float(lon84), h_hold, "wgs84", ins_d)
        else:
            lat_n, lon_n, h_n = float(lat84), float(lon84), h_hold
        lat_p, lon_p = _prev_geo
        R_phi, R_lam = radii(float(lat_n), float(h_n), ell)
        vE = (float(lon_n) - lon_p) / T_M * R_lam * np.cos(float(lat_n))      # (14)
        vN = (float(lat_n) - lat_p) / T_M * R_phi
        vU = (float(h_n) - h_prev_ins) / T_M
        if cfg.velocity_reset == "end":
            # the identification's correction (identified minus predicted position) enters the
            # velocity at most by ``velocity_kick`` m/s: a jump of the identification (another
            # branch, a re-seeded cloud) divided by T_M would throw the fast loop at 100 m/s
            corr = np.asarray(p_new, float) - pred_pt
            lim = cfg.velocity_kick * T_M
            n_c = float(np.hypot(*corr))
            if n_c > lim:
                en = pred_pt - p_prev + corr * (lim / n_c)
                # rotate the plane step into ENU through the geodetic differences' scale
                vE, vN = float(en[0]) / T_M, float(en[1]) / T_M
            # (14) differences positions over the period: that is the velocity at mid-period.
            # Carried to its end by the fast loop's own change over the second half (else the
            # reset velocity lags by T_M/2 and follows only half of every acceleration)
            dv_half = tr.velocity_n[-1] - np.mean(tr.velocity_n, axis=0)
            vE, vN = vE + float(dv_half[0]), vN + float(dv_half[1])
            # speed drift: while GNSS is healthy the resets tell how fast the fast loop's speed
            # drifts per period (accelerometer bias, gravity leaking through the gyro-driven
            # tilt of the period); inside outlier windows that mean correction is applied
            s_ins = float(np.hypot(*tr.velocity_n[-1, :2]))
            s_new = float(np.hypot(vE, vN))
            if ok and n_fix > 0 and s_ins > 1.0:
                drift.append(s_new - s_ins)
                del drift[:-cfg.drift_window]
            elif not ok and len(drift) >= 10 and s_new > 1.0:
                s_fix = max(s_ins + float(np.mean(drift)), 0.0)
                vE, vN = vE * s_fix / s_new, vN * s_fix / s_new
        if odometer is not None:
            odo_vec += T_M * dV_raw * np.array([np.sin(K_road), np.cos(K_road)])
            if ok and n_fix > 0:     # learn the scale from the healthy fixes
                if odo_ref is None:
                    odo_ref = (odo_vec.copy(), np.asarray(z, float).copy())
                else:
                    d_o, d_z = odo_vec - odo_ref[0], np.asarray(z, float) - odo_ref[1]
                    odo_sum += (float(d_z @ d_o), float(d_o @ d_o))
                    if np.hypot(*d_o) > cfg.odo_learn_m and odo_sum[0] > 0:
                        odo_k = float(np.clip(odo_sum[1] / odo_sum[0] - 1.0, -0.1, 0.1))
            s_end = float(v_odo[-1]) / (1.0 + odo_k)
            s_new = float(np.hypot(vE, vN))
            if s_new > 0.5:
                vE, vN = vE * s_end / s_new, vN * s_end / s_new
            elif s_end > 0.5:
                vE, vN = s_end * np.sin(K_road), s_end * np.cos(K_road)
        if n_fix == 0:   # the first step starts from the alignment, not from an identified fix
            vE, vN, vU = (float(x) for x in tr.velocity_n[-1])
        sp = float(np.sqrt(vE * vE + vN * vN + vU * vU))
        pitch = float(np.arcsin(vU / sp)) if sp > 0.1 else 0.0            # (15)
        roll = roll_lev if cfg.roll == "level" else float(roll_b[-1])
        C_nb = att.dcm_nb_from_euler(roll, pitch, K_road)                   # K = K^ист (15)
        ins.set_state(lat=lat_n, lon=lon_n, h=h_n, velocity_n=[vE, vN, vU], C_nb=C_nb)
        _prev_geo = (float(lat_n), float(lon_n))
        h_prev_ins = float(h_n)
        p_prev = np.asarray(p_new, float)
        for key, val in (("t", float(gnss.t[k])), ("lat", float(lat84)), ("lon", float(lon84)),
                         ("h", h_hold), ("vel", [vE, vN, vU]), ("C", C_nb), ("course", K_mean),
                         ("course_road", K_road), ("ds", dS), ("healthy", ok), ("m", m_pts),
                         ("cost", cost), ("k_m", k_m),
                         ("ins_offset", float(np.hypot(*(p_ins - p_new))))):
            out[key].append(val)
        if progress is not None and n_fix % 200 == 0:
            progress(n_fix / len(fix_idx))
    if not out["t"]:
        raise SelfnavError("no GNSS fix after the initial state: nothing to navigate")
    traj = Trajectory(np.asarray(out["t"]), np.asarray(out["lat"]), np.asarray(out["lon"]),
                      np.asarray(out["h"]), np.asarray(out["vel"]), np.asarray(out["C"]),
                      source=f"selfnav seed 004 navigator ({cfg.matcher})")
    diag = {k: np.asarray(out[k]) for k in ("course", "course_road", "ds", "healthy", "m",
                                            "cost", "k_m", "ins_offset")}
    stats = {"epochs": len(out["t"]), "t_start": t0, "healthy_fixes": int(diag["healthy"].sum()),
             "k_m": int(np.median(diag["k_m"])), "matcher": cfg.matcher,
             "declination_deg": float(np.degrees(decl)),
             "reseeds": int(pf.reseeds) if pf is not None else reacq}
    if odometer is not None:
        stats["odometer_scale_factor"] = odo_k
    return SeedResult(traj, diag, stats)


__all__ = ["SeedConfig", "SeedResult", "run_seed", "identify",
           "road_points"]
