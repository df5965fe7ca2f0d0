"""2-D navigation from a car's speed and yaw rate, aided by position fixes that contain
unflagged outliers (DESIGN §7 "Outliers"; the same defence as :mod:`selfnav.ins.ekf`).

State (local ENU tangent plane at ``origin``)::

    x = [E, N, H, s, b]      E, N (m), heading H (rad, clockwise from North),
                             speed scale factor s (speed = s·v), yaw-rate bias b (rad/s)

Dead reckoning between samples (midpoint heading ``H_m = H + ½Δt Ḣ``)::

    Ḣ = −(ω_z − b)            (ω_z counter-clockwise about Up, DESIGN §2: H is clockwise)     (1)
    E⁺ = E + s v Δt sin H_m,  N⁺ = N + s v Δt cos H_m,  H⁺ = H + Δt Ḣ                        (2)

Process noise from the odometry's white noise (σ_v, σ_ω through the Jacobian of (2)), random
walks on s and b, and a small position random walk for wheel slip and the planar model.

**Outliers.** A fix z (E, N) is tested by its normalized innovation squared
``NIS = rᵀ(P_EN + R)⁻¹r`` against χ²₂ (0.999). The gate alone fails once P has grown while
rejecting (every outlier then passes), so the robust filter adds a *window test* that P cannot
weaken: the displacement between consecutive fixes must agree with the dead-reckoned displacement
(accurate to decimetres over seconds even when the absolute position has drifted)::

    d = (z_b − z_a) − (D_b − D_a),    dᵀ d / (σ_a² + σ_b² + σ_rel²) ≤ χ²₂(0.999)            (3)

with D the displacement accumulated by propagation only and ``σ_rel`` the dead-reckoning error
over the gap (heading and scale errors times the distance, plus slip). After ``suspect_after``
consecutive rejections the filter is *suspect*: it dead-reckons and re-acquires only when a whole
window of fixes is consistent under (3); if that consistent window is still beyond the gate, P is
widened by the offset (the dead reckoning, not the fixes, has drifted). ``robust=False`` keeps the
χ² gate alone, to show the difference. An RTS smoother runs over the stored epochs on request.

Start-up: the first ``init_window`` seconds of dead reckoning (in a frame with H = 0 at the first
sample) are fitted to the fixes by a trimmed 2-D rigid transform (rotation + translation,
Procrustes); the rotation is the initial heading, so no heading sensor is needed — only motion
with some turning or straight travel longer than the fix noise.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from selfnav.earth import ecef_to_enu, enu_to_geodetic
from selfnav.errors import SelfnavError

CHI2_2_999 = 13.816
NX = 5
IE, IN, IH, IS, IB = range(5)


@dataclass
class OdoConfig:
    """Noise model and options of :func:`run_odometry_filter` (SI units)."""

    speed_sigma: float = 0.05               # white speed noise, m/s (smartLoc: variance 0.0025)
    yaw_rate_sigma: float = 0.002           # white yaw-rate noise, rad/s (smartLoc: 4e-6)
    scale_sigma0: float = 0.05
    scale_rw: float = 1e-4                  # 1/√s
    bias_sigma0: float = np.radians(1.0)    # rad/s
    bias_rw: float = 1e-5                   # rad/s/√s
    pos_rw: float = 0.1                     # m/√s, slip and the planar model
    fix_sigma_scale: float = 2.0            # R = (scale·σ_fix)², σ_fix from the SPP covariance
    fix_sigma_floor: float = 3.0            # m
    gate: float = CHI2_2_999
    soft_gate: float = 4.0                  # robust only: up to soft_gate × gate, R inflated by NIS/gate
    robust: bool = True                     # the window test and suspect mode
    window: int = 6
    suspect_after: int = 2
    rel_drift_speed: float = 0.1            # m/s of relative dead-reckoning drift in (3)
    reacquire_heading: bool = True          # re-acquisition also widens heading and yaw-rate bias
    init_window: float = 30.0               # s of fixes for the start-up fit
    init_trim: float = 2.5                  # start-up: drop fixes beyond this × robust σ


@dataclass
class OdoResult:
    """Filter output at every odometry sample.

    ``east, north`` in the tangent plane at ``origin`` (lat, lon, h; rad, m), ``lat, lon`` the
    same positions in WGS-84. ``fix_status``: 1 used, 0 rejected, −1 no fix / before start.
    ``mode``: 1 where the filter was suspect (dead reckoning).
    """

    t: np.ndarray
    east: np.ndarray
    north: np.ndarray
    heading: np.ndarray
    scale: np.ndarray
    yaw_bias: np.ndarray
    sigma_en: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    fix_status: np.ndarray
    nis: np.ndarray
    mode: np.ndarray
    smoothed: bool
    stats: dict = field(default_factory=dict)


def propagate(x, v, w, dt):
    """Dead-reckoning step (2) and its Jacobians: returns (x⁺, F, G) with G for (v, ω_z) noise."""
    E, N, H, s, b = x
    hd = -(w - b)
    Hm = H + 0.5 * dt * hd
    sH, cH = np.sin(Hm), np.cos(Hm)
    d = s * v * dt
    xn = np.array([E + d * sH, N + d * cH, H + dt * hd, s, b])
    F = np.eye(NX)
    F[IE, IH], F[IN, IH] = d * cH, -d * sH
    F[IE, IS], F[IN, IS] = v * dt * sH, v * dt * cH
    F[IE, IB], F[IN, IB] = 0.5 * dt * d * cH, -0.5 * dt * d * sH
    F[IH, IB] = dt
    G = np.zeros((NX, 2))
    G[IE, 0], G[IN, 0] = s * dt * sH, s * dt * cH
    G[IE, 1], G[IN, 1] = -0.5 * dt * d * cH, 0.5 * dt * d * sH
    G[IH, 1] = -dt
    return xn, F, G


def dead_reckon(t, speed, yaw_rate, x0=(0.0, 0.0, 0.0, 1.0, 0.0)):
    """Plain dead reckoning (2) over samples (speed and yaw rate of sample k act on [t_k, t_k+1])."""
    x = np.array(x0, float)
    out = np.empty((len(t), NX))
    out[0] = x
    for k in range(1, len(t)):
        x, _, _ = propagate(x, speed[k - 1], yaw_rate[k - 1], t[k] - t[k - 1])
        out[k] = x
    return out


def _rigid_fit(a, b):
    """Rotation R (2×2) and translation c minimizing Σ|R a_i + c − b_i|² (Procrustes)."""
    ma, mb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((a - ma).T @ (b - mb))
    D = np.diag([1.0, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    return R, mb - R @ ma


def initial_state(t, speed, yaw_rate, t_fix, z_fix, cfg: OdoConfig):
    """Start-up fit (module docstring): returns (x0, P0) at ``t[0]``.

    The dead-reckoned track with H = 0 is rotated and shifted onto the fixes of the first
    ``init_window`` seconds, trimming fixes beyond ``init_trim`` robust σ and refitting.
    """
    m = (t_fix <= t[0] + cfg.init_window) & np.all(np.isfinite(z_fix), axis=1)
    if m.sum() < 5:
        raise SelfnavError(f"fewer than 5 fixes in the first {cfg.init_window:g} s to start from")
    dr = dead_reckon(t, speed, yaw_rate)
    a = np.column_stack([np.interp(t_fix[m], t, dr[:, IE]), np.interp(t_fix[m], t, dr[:, IN])])
    b = z_fix[m]
    if np.ptp(a, axis=0).max() < 3 * cfg.fix_sigma_floor:
        raise SelfnavError("the vehicle did not move during the start-up window (heading needs motion)")
    keep = np.ones(len(a), bool)
    for _ in range(10):
        R, c = _rigid_fit(a[keep], b[keep])
        res = np.linalg.norm(a @ R.T + c - b, axis=1)
        sc = 1.4826 * np.median(res[keep]) + 1e-3
        new = res <= cfg.init_trim * sc
        if new.sum() < 5 or np.array_equal(new, keep):
            break
        keep = new
    # a vector (e, n) of the dead-reckoned frame at heading 0 points along heading 0 = North;
    # R rotates it; the heading of the rotated North axis is the initial heading
    H0 = np.arctan2(R[0, 1], R[1, 1])
    sp = float(np.sqrt(np.mean(res[keep] ** 2)))
    span = float(np.sqrt(np.mean(np.sum((a[keep] - a[keep].mean(0)) ** 2, axis=1)))) + 1.0
    x0 = np.array([c[0], c[1], H0, 1.0, 0.0])
    P0 = np.diag([(2 * sp) ** 2 + 1.0, (2 * sp) ** 2 + 1.0, (2 * sp / span) ** 2 + np.radians(2) ** 2,
                  cfg.scale_sigma0**2, cfg.bias_sigma0**2])
    return x0, P0


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _disp_ok(fa, fb, cfg, P):
    """Test (3) for two fixes ``(t, z, sigma, D, dist)``: D the propagated displacement, dist
    the distance travelled, both since the start."""
    (ta, za, sa, Da, la), (tb, zb, sb, Db, lb) = fa, fb
    dist = abs(lb - la)
    s_rel2 = (np.sqrt(P[IH, IH]) * dist) ** 2 + (np.sqrt(P[IS, IS]) * dist) ** 2 \
        + (cfg.rel_drift_speed * (tb - ta)) ** 2
    d = (zb - za) - (Db - Da)
    return float(d @ d) / (sa**2 + sb**2 + s_rel2) <= cfg.gate


def _widen(r, dist, dt, heading: bool):
    """Re-acquisition: the dead reckoning has drifted by ``r`` beyond what P allowed over
    ``dist`` metres and ``dt`` seconds since the last accepted fix. Returns the covariance to
    add: the offset on position and, with ``heading``, the angle it subtends (|r|/dist) on the
    heading and the bias that would produce it (error ≈ ½ b v Δt², so b ≈ 2|r|/(dist·Δt)) on
    the yaw-rate bias. It acts as process noise (the smoother sees it in P⁻)."""
    a = float(np.hypot(*r))
    dP = np.zeros((NX, NX))
    dP[:2, :2] = np.diag(r * r)
    if heading:
        dP[IH, IH] = min(a / max(dist, 1.0), 1.0) ** 2
        dP[IB, IB] = (2.0 * a / max(dist * dt, 1.0)) ** 2
    return dP


def run_odometry_filter(t, speed, yaw_rate, t_fix, z_fix, sigma_fix, cfg: OdoConfig | None = None,
                        *, smooth: bool = False, x0=None, P0=None) -> dict:
    """Run the speed/yaw-rate filter over a record with fixes (batch call).

    Parameters
    ----------
    t, speed, yaw_rate : (N,) odometry samples (s, m/s, rad/s counter-clockwise)
    t_fix : (F,) s, fix times (each snapped to the nearest odometry sample at or after it)
    z_fix : (F, 2) m, fix E, N in the tangent plane; NaN rows are skipped
    sigma_fix : (F,) m, horizontal σ per axis of each fix
    cfg : OdoConfig
    smooth : bool
        Rauch–Tung–Striebel smoother over the stored epochs.
    x0, P0 : optional initial state and covariance at ``t[0]`` (default: :func:`initial_state`)

    Returns
    -------
    dict with arrays ``x`` (N, 5), ``P`` (N, 5, 5), ``fix_status``, ``nis``, ``mode`` (per
    fix) and ``stats``.
    """
    cfg = cfg or OdoConfig()
    t = np.asarray(t, float)
    speed = np.asarray(speed, float)
    yaw_rate = np.asarray(yaw_rate, float)
    t_fix = np.asarray(t_fix, float)
    z_fix = np.asarray(z_fix, float)
    sig = np.maximum(cfg.fix_sigma_scale * np.asarray(sigma_fix, float), cfg.fix_sigma_floor)
    if x0 is None:
        x0, P0 = initial_state(t, speed, yaw_rate, t_fix, z_fix, cfg)
    x = np.array(x0, float)
    P = np.array(P0, float)
    n = len(t)
    k_fix = np.searchsorted(t, t_fix - 1e-6)
    fixes_at = {}
    for i, k in enumerate(k_fix):
        if k < n and np.all(np.isfinite(z_fix[i])) and np.isfinite(sig[i]):
            fixes_at.setdefault(int(k), []).append(i)
    Qc = np.diag([cfg.speed_sigma**2, cfg.yaw_rate_sigma**2])
    xs, Ps, xm, Pm, Fs = (np.empty((n, NX)), np.empty((n, NX, NX)), np.empty((n, NX)),
                          np.empty((n, NX, NX)), np.empty((n, NX, NX)))
    nf = len(t_fix)
    fix_status = -np.ones(nf, int)
    nis_all = np.full(nf, np.nan)
    mode_all = np.zeros(nf, int)
    D = np.zeros(2)
    dist = 0.0
    buf = []
    suspect = False
    rejections = streak = reacq = 0
    t_acc, dist_acc = t[0], 0.0
    H2 = np.zeros((2, NX))
    H2[0, IE] = H2[1, IN] = 1.0
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            xn, F, G = propagate(x, speed[k - 1], yaw_rate[k - 1], dt)
            D += xn[:2] - x[:2]
            dist += abs(speed[k - 1]) * dt
            Q = G @ Qc @ G.T + np.diag([cfg.pos_rw**2 * dt, cfg.pos_rw**2 * dt, 0.0,
                                        cfg.scale_rw**2 * dt, cfg.bias_rw**2 * dt])
            x, P = xn, F @ P @ F.T + Q
        else:
            F = np.eye(NX)
        xm[k], Pm[k], Fs[k] = x, P, F
        for i in fixes_at.get(k, ()):
            r = z_fix[i] - x[:2]
            R = np.eye(2) * sig[i] ** 2
            S = P[:2, :2] + R
            nis = float(r @ np.linalg.solve(S, r))
            nis_all[i] = nis
            ok = nis <= cfg.gate * (cfg.soft_gate if cfg.robust else 1.0)
            if cfg.robust:
                buf.append((t_fix[i], z_fix[i], sig[i], D.copy(), dist))
                buf = buf[-cfg.window:]
                if suspect:
                    win_ok = len(buf) >= cfg.window and all(
                        _disp_ok(buf[j], buf[j + 1], cfg, P) for j in range(len(buf) - 1))
                    streak = streak + 1 if win_ok else 0
                    if win_ok and not ok and streak >= cfg.window:
                        dP = _widen(r, dist - dist_acc, t[k] - t_acc, cfg.reacquire_heading)
                        P = P + dP
                        Pm[k] = Pm[k] + dP
                        nis = float(r @ np.linalg.solve(P[:2, :2] + R, r))
                        ok = True
                        reacq += 1
                    elif not win_ok:
                        ok = False
                elif len(buf) > 1:
                    ok = ok and _disp_ok(buf[-2], buf[-1], cfg, P)
            mode_all[i] = int(suspect)
            if ok:
                R = R * max(1.0, nis / cfg.gate)
                S = P[:2, :2] + R
                K = np.linalg.solve(S, H2 @ P).T
                x = x + K @ r
                IKH = np.eye(NX) - K @ H2
                P = IKH @ P @ IKH.T + K @ R @ K.T
                fix_status[i] = 1
                t_acc, dist_acc = t[k], dist
                rejections = streak = 0
                suspect = False
            else:
                fix_status[i] = 0
                rejections += 1
                if cfg.robust and rejections >= cfg.suspect_after:
                    suspect = True
        x[IH] = _wrap(x[IH])
        xs[k], Ps[k] = x, P
    smoothed = False
    if smooth and n > 2:
        xs, Ps = rts_smooth(xs, Ps, xm, Pm, Fs)
        smoothed = True
    stats = {"fixes": int(sum(len(v) for v in fixes_at.values())), "accepted": int((fix_status == 1).sum()),
             "rejected": int((fix_status == 0).sum()), "reacquisitions": reacq,
             "suspect_fixes": int(mode_all.sum())}
    return dict(x=xs, P=Ps, fix_status=fix_status, nis=nis_all, mode=mode_all, smoothed=smoothed,
                stats=stats)


def rts_smooth(x_plus, P_plus, x_minus, P_minus, F):
    """Rauch–Tung–Striebel smoother; ``F[k]`` maps epoch k−1 to k (heading differences wrapped).

    ``C_k = P⁺_k F_{k+1}ᵀ (P⁻_{k+1})⁻¹``, ``x̂_k = x⁺_k + C_k (x̂_{k+1} − x⁻_{k+1})``,
    ``P̂_k = P⁺_k + C_k (P̂_{k+1} − P⁻_{k+1}) C_kᵀ``.
    """
    n = len(x_plus)
    xs, Ps = x_plus.copy(), P_plus.copy()
    for k in range(n - 2, -1, -1):
        C = np.linalg.solve(P_minus[k + 1].T, (P_plus[k] @ F[k + 1].T).T).T
        d = xs[k + 1] - x_minus[k + 1]
        d[IH] = _wrap(d[IH])
        xs[k] = x_plus[k] + C @ d
        xs[k, IH] = _wrap(xs[k, IH])
        Ps[k] = P_plus[k] + C @ (Ps[k + 1] - P_minus[k + 1]) @ C.T
    return xs, Ps


def _to_result(t, out, origin):
    x, P = out["x"], out["P"]
    lat, lon, _ = enu_to_geodetic(np.column_stack([x[:, IE], x[:, IN], np.zeros(len(x))]), *origin)
    sig = np.sqrt(np.maximum(np.stack([P[:, IE, IE], P[:, IN, IN]], axis=1), 0.0))
    return OdoResult(t, x[:, IE], x[:, IN], x[:, IH], x[:, IS], x[:, IB], sig, lat, lon,
                     out["fix_status"], out["nis"], out["mode"], out["smoothed"], out["stats"])


def horizontal_metrics(err_en):
    """RMS, 95 % and max of horizontal errors (m) from (N, 2) E/N errors (NaN rows skipped)."""
    e = np.hypot(err_en[:, 0], err_en[:, 1])
    e = e[np.isfinite(e)]
    return {"rms_m": float(np.sqrt(np.mean(e * e))), "p95_m": float(np.percentile(e, 95)),
            "max_m": float(np.max(e)), "mean_m": float(np.mean(e)), "n": int(e.size)}


def run_smartloc(folder, *, spp_cfg=None, odo_cfg: OdoConfig | None = None,
                 return_results: bool = False) -> dict:
    """SPP, the robust filter, the gate-only filter and the smoother on a smartLoc folder,
    each scored against the ground truth (horizontal error in the tangent plane at the first fix).

    Returns a dict ``{"spp": metrics, "robust": …, "gate_only": …, "smoother": …, "spp_stats",
    "filter_stats", "gate_only_stats", "runtime_s"}`` (metrics from :func:`horizontal_metrics`);
    with ``return_results`` also ``"results"`` (the SppResult and the OdoResults).
    """
    from dataclasses import replace

    from selfnav.io.smartloc import find_smartloc_files, read_smartloc_input, read_smartloc_truth
    from selfnav.gnss.spp import SppConfig, spp_from_pseudoranges

    t_start = time.perf_counter()
    inp, gt = find_smartloc_files(folder)
    prs, odo = read_smartloc_input(inp)
    truth = read_smartloc_truth(gt)
    spp_cfg = spp_cfg or SppConfig(weighting="cn0")
    odo_cfg = odo_cfg or OdoConfig(speed_sigma=float(np.sqrt(np.median(odo.variances[:, 0]))),
                                   yaw_rate_sigma=float(np.sqrt(np.median(odo.variances[:, 5]))))
    t_spp0 = time.perf_counter()
    sp = spp_from_pseudoranges(prs, spp_cfg)
    t_spp = time.perf_counter() - t_spp0
    ok = sp.valid
    i0 = int(np.flatnonzero(ok)[0])
    origin = (sp.lat[i0], sp.lon[i0], sp.h[i0])
    z = ecef_to_enu(sp.ecef, *origin)[:, :2]
    gt_en = ecef_to_enu(truth.ecef, *origin)[:, :2]

    def truth_at(tq):
        return np.column_stack([np.interp(tq, truth.t, gt_en[:, j]) for j in range(2)])

    res = {"spp": horizontal_metrics(z[ok] - truth_at(sp.t[ok]))}
    results = {"spp": sp}
    runs = (("robust", odo_cfg, False), ("gate_only", replace(odo_cfg, robust=False), False),
            ("smoother", odo_cfg, True))
    for name, c, sm in runs:
        out = run_odometry_filter(odo.t, odo.speed, odo.yaw_rate, sp.t, z, sp.sigma_m, c, smooth=sm)
        r = _to_result(odo.t, out, origin)
        res[name] = horizontal_metrics(np.column_stack([r.east, r.north]) - truth_at(odo.t))
        res[f"{name}_stats"] = r.stats
        results[name] = r
    res["spp_stats"] = sp.stats
    res["spp_time_s"] = t_spp
    res["runtime_s"] = time.perf_counter() - t_start
    if return_results:
        res["results"] = results
    return res
