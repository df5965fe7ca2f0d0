"""The MEMS EKF against a fibre-optic INS: PSINS ``psins_fog_mems_vehicle`` (issue 4).

The record (PSINS ``transfer_align_fog_mems.mat``, 100 s of a car driving north) holds a
low-cost MEMS IMU at 100 Hz and a fibre-optic INS (FOG-INS) navigating at 10 Hz beside it.
There is no GNSS. This module runs :class:`selfnav.ins.Navigator` on the MEMS increments with
the **FOG-INS position, decimated to 1 Hz and given σ ≈ 1 m, as the "GNSS" aiding** (the
only position source in the record), and measures the MEMS solution's attitude and velocity
against the FOG-INS.

**What upstream does** (PSINS ``demos/test_align_transfer_fog_mems.m``): a *transfer
alignment*: an 18-state filter matches the MEMS attitude *and* velocity to the FOG-INS at
10 Hz and estimates the gyro/accel biases and the MEMS-to-FOG mounting angles ``mu0``. Here
the aiding is weaker on purpose (position only, 1 Hz, no attitude), as a user with a GNSS
receiver would have it; attitude is observable only through the accelerations of the drive.

**Mounting.** The two units are not perfectly aligned: the MEMS attitude is the FOG attitude
turned by ``mu0`` in the body frame (PSINS compares ``q_nb^s ⊗ q(−mu0)`` with ``q_nb^m``),
``C_b^n(MEMS) = C_b^n(FOG) · exp([μ])``, μ a body (RFU) rotation vector. After convergence the
attitude difference MEMS − FOG is therefore a constant μ plus the filter's own error; the
mean of ``log(C_n^b(FOG) C_b^n(MEMS))`` over the converged part estimates μ, reported against
``mu0``.

**Non-holonomic constraint.** The FOG heading differs from the course over ground by
4.55° ± 0.11° over the whole run (the units are mounted at a yaw offset to the car's axis;
the data set's README notes it), so the constraint "no lateral body velocity" does not hold for these IMU axes; it is
off by default here (``nhc=True`` shows its effect: the filter turns the heading to the track).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav import attitude as att
from selfnav.ins import FilterConfig, Navigator, feed
from selfnav.types import GnssData
from selfnav.io.psins_mat import read_fog_mems

DEG = np.pi / 180.0
DPH = DEG / 3600.0  # deg/h in rad/s


def fog_gnss(data: dict, *, rate_hz: float = 1.0, sigma_m: float = 1.0, seed: int | None = None,
             noise: bool = False, velocity: bool = False) -> GnssData:
    """FOG-INS positions decimated to ``rate_hz`` as GNSS-like fixes with σ = ``sigma_m``.

    With ``noise=True`` white noise of that σ is added (seeded), to mimic a receiver; by
    default the FOG positions are used as they are (they are smooth, σ then only weights them).
    ``velocity=True`` also attaches the FOG ENU velocity (the upstream demo's velocity matching;
    used by the filter with ``use_velocity=True``).
    """
    t = data["t_ref"]
    step = max(1, int(round(1.0 / (rate_hz * np.median(np.diff(t))))))
    idx = np.arange(step - 1, len(t), step)
    lat, lon = data["lat_ref"][idx].copy(), data["lon_ref"][idx].copy()
    h = _fog_h(data)[idx].copy()
    if noise:
        from selfnav.earth import radii
        rng = np.random.default_rng(seed)
        rm, rn = radii(lat, h)
        e = rng.normal(0.0, sigma_m, (len(idx), 3))
        lat += e[:, 1] / rm
        lon += e[:, 0] / (rn * np.cos(lat))
        h += 1.5 * e[:, 2]
    vel = data["v_ref"][idx].copy() if velocity else None
    return GnssData(t[idx], lat, lon, h, np.full(len(idx), sigma_m), vel, None,
                    "FOG-INS position decimated (psins_fog_mems_vehicle)")


def _fog_h(data):
    if "h_ref" in data:
        return data["h_ref"]
    # psins_mat returns no height: read it from the CSV (column 9)
    return data["_h"]


def _load(folder):
    folder = Path(folder)
    d = read_fog_mems(folder)
    if "h_ref" not in d:
        a = np.loadtxt(folder / "fogavp.csv", delimiter=",", skiprows=1, ndmin=2)
        d["_h"] = a[:, 8]
    return d


def _db0(folder):
    """Upstream reference MEMS accelerometer bias ``db0`` (m/s²) from the .mat, if readable."""
    mat = Path(folder) / "transfer_align_fog_mems.mat"
    if not mat.exists():
        return None
    from scipy.io import loadmat

    return np.asarray(loadmat(mat, variable_names=["db0"])["db0"], float).ravel()


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _rms(x, axis=0):
    return np.sqrt(np.mean(np.square(x), axis=axis))


def initial_state(data: dict, att_error_deg=(0.5, -0.5, 3.0), vel_error=(0.1, 0.1, 0.0)) -> dict:
    """Initial state from the FOG-INS at its first epoch plus an alignment error.

    ``att_error_deg`` (roll, pitch, heading) and ``vel_error`` (ENU m/s) are *added* to the FOG
    values: a MEMS in-motion coarse alignment is good to tenths of a degree in tilt and a few
    degrees in heading.
    """
    C0 = data["attitude"].C_nb[0]
    r, p, hd = att.euler_from_dcm_nb(C0)
    e = np.radians(att_error_deg)
    C = att.dcm_nb_from_euler(r + e[0], p + e[1], hd + e[2])
    return dict(t=float(data["t_ref"][0]), lat=float(data["lat_ref"][0]),
                lon=float(data["lon_ref"][0]), h=float(_fog_h(data)[0]),
                velocity_n=data["v_ref"][0] + np.asarray(vel_error, float), C_nb=C,
                sigmas=([2.0, 2.0, 3.0], [0.3, 0.3, 0.3],
                        [np.radians(1.0), np.radians(1.0), np.radians(5.0)]))


def default_config(**kw) -> FilterConfig:
    """Filter settings for this MEMS.

    Gyro bias prior 500 °/h as in the PSINS demo's error model; the accelerometer bias prior is
    10 mg, not the demo's 1000 µg: the demo's own reference ``db0`` reaches 7 mg, and a prior
    that tight leaves the horizontal bias in the tilt (pitch off by ≈ 0.3°).
    """
    d = dict(arw=np.radians(0.1) / 60.0, vrw=0.01 / 60.0 * 10, gyro_bias_sigma=500 * DPH,
             accel_bias_sigma=10e-3 * 9.80665, gyro_bias_instability=10 * DPH,
             accel_bias_instability=1e-4, instability_tau=100.0, nhc=False, zupt=False,
             bank=False, sigma_floor=0.1, aid_step=0.1)
    d.update(kw)
    return FilterConfig().updated(**d)


def _match(t_ref, t_sol):
    """Index of the last solution record at each reference time (None where absent)."""
    key_s = np.round(t_sol * 1e4).astype(np.int64)
    key_r = np.round(t_ref * 1e4).astype(np.int64)
    j = np.searchsorted(key_s, key_r, side="right") - 1
    ok = (j >= 0) & (key_s[np.clip(j, 0, None)] == key_r)
    return j, ok


def evaluate_fog_mems(folder, *, settle_s: float = 30.0, gnss_rate_hz: float = 1.0,
                      gnss_sigma_m: float = 1.0, gnss_noise: bool = False, seed: int = 1,
                      aid_velocity: bool = False,
                      att_error_deg=(0.5, -0.5, 3.0), vel_error=(0.1, 0.1, 0.0),
                      smooth: bool = False, **cfg) -> dict:
    """Run the MEMS EKF on ``psins_fog_mems_vehicle`` and compare it with the FOG-INS.

    Parameters
    ----------
    folder : path of the data set (``mimu.csv``, ``fogavp.csv``, ``.mat``)
    settle_s : errors are summarized after this many seconds from the start (convergence)
    gnss_rate_hz, gnss_sigma_m, gnss_noise, seed : the FOG-position aiding (:func:`fog_gnss`)
    aid_velocity : also aid with the FOG velocity (σ ``velocity_sigma``, default 0.1 m/s)
    att_error_deg, vel_error : initial error added to the FOG state (:func:`initial_state`)
    smooth : run the RTS smoother
    **cfg : overrides of :func:`default_config` (:class:`~selfnav.ins.FilterConfig` fields)

    Returns
    -------
    dict
        ``att_rms_deg`` / ``att_max_deg`` (roll, pitch, heading; MEMS − FOG after ``settle_s``,
        raw), ``att_resid_rms_deg`` (after removing the estimated mounting μ), ``mount_deg``
        (μ, RFU rotation vector, deg) and ``mu0_deg``, ``vel_rms`` / ``vel_max`` (E, N, U m/s),
        ``pos_rms_m`` (horizontal vs FOG), ``gyro_bias_dph`` (final estimate, deg/h) and
        ``eb0_dph``, ``gyro_bias_diff_dph``, ``heading_err_final_deg`` and the time series
        ``t``, ``att_err_deg`` (N, 3), ``vel_err`` (N, 3), ``gyro_bias_t_dph`` (N, 3).
    """
    data = _load(folder)
    gnss = fog_gnss(data, rate_hz=gnss_rate_hz, sigma_m=gnss_sigma_m, noise=gnss_noise, seed=seed,
                    velocity=aid_velocity)
    if aid_velocity:
        cfg.setdefault("use_velocity", True)
    fc = default_config(**cfg)
    init = initial_state(data, att_error_deg, vel_error)
    nav = Navigator(fc, init=init, smoother=smooth, out_rate_hz=0.0,
                    imu_time_offset_s=0.0)
    res = feed(nav, data["imu"], gnss).result(smooth)
    tr = res.trajectory
    j, ok = _match(data["t_ref"], tr.t)
    ok &= data["t_ref"] > init["t"] + 1e-6
    tref = data["t_ref"][ok]
    js = j[ok]
    C_fog = data["attitude"].C_nb[ok]
    C_sol = tr.C_nb[js]
    rf, pf, hf = att.euler_from_dcm_nb(C_fog)
    rs, ps, hs = att.euler_from_dcm_nb(C_sol)
    e_att = np.column_stack([_wrap(rs - rf), _wrap(ps - pf), _wrap(hs - hf)])
    e_vel = tr.velocity_n[js] - data["v_ref"][ok]
    from selfnav.earth import radii
    rm, rn = radii(data["lat_ref"][ok], 0.0)
    e_pos = np.column_stack([(tr.lon[js] - data["lon_ref"][ok]) * rn * np.cos(data["lat_ref"][ok]),
                             (tr.lat[js] - data["lat_ref"][ok]) * rm])
    # mounting: C_b^n(MEMS) = C_b^n(FOG) exp([μ]) → μ = log(C_n^b(FOG) C_b^n(MEMS)) (body RFU)
    mu_t = att.dcm_to_rotvec(C_fog @ np.swapaxes(C_sol, -1, -2))
    conv = tref >= init["t"] + settle_s
    mu = mu_t[conv].mean(0)
    C_res = att.rotvec_to_dcm(mu)[None] @ C_sol  # C_n^b(MEMS) turned back by μ: exp([μ]) C_n^b
    rr, pr, hr = att.euler_from_dcm_nb(C_res)
    e_res = np.column_stack([_wrap(rr - rf), _wrap(pr - pf), _wrap(hr - hf)])
    bg = res.gyro_bias[js]
    out = {
        "settle_s": settle_s, "t0": init["t"], "epochs": int(conv.sum()),
        "att_rms_deg": np.degrees(_rms(e_att[conv])).tolist(),
        "att_max_deg": np.degrees(np.max(np.abs(e_att[conv]), 0)).tolist(),
        "att_mean_deg": np.degrees(e_att[conv].mean(0)).tolist(),
        "att_resid_rms_deg": np.degrees(_rms(e_res[conv])).tolist(),
        "mount_deg": np.degrees(mu).tolist(),
        "vel_rms": _rms(e_vel[conv]).tolist(),
        "vel_max": np.max(np.abs(e_vel[conv]), 0).tolist(),
        "pos_rms_m": float(_rms(np.hypot(e_pos[conv, 0], e_pos[conv, 1]))),
        "gyro_bias_dph": (bg[-1] / DPH).tolist(),
        "heading_err_final_deg": float(np.degrees(e_att[-1, 2])),
        "accel_bias": res.accel_bias[js][-1].tolist(),
        "fixes_accepted": res.stats["fix_status"]["used"], "fixes": res.stats["fixes"],
        "t": tref, "att_err_deg": np.degrees(e_att), "vel_err": e_vel,
        "gyro_bias_t_dph": bg / DPH, "sigma_att_deg": np.degrees(res.sigma_att[js]),
    }
    if "eb0" in data:
        out["eb0_dph"] = (data["eb0"] / DPH).tolist()
        out["gyro_bias_diff_dph"] = ((bg[-1] - data["eb0"]) / DPH).tolist()
    db0 = _db0(folder)
    if db0 is not None:
        out["db0_ug"] = (db0 / 9.80665e-6).tolist()
    out["accel_bias_ug"] = (np.asarray(out["accel_bias"]) / 9.80665e-6).tolist()
    if "mu0" in data:
        out["mu0_deg"] = np.degrees(data["mu0"]).tolist()
        out["mount_diff_deg"] = np.degrees(mu - data["mu0"]).tolist()
    return out


def summary(r: dict) -> str:
    """Short text table of :func:`evaluate_fog_mems` results."""
    f3 = lambda v, p=3: ", ".join(f"{x:.{p}f}" for x in v)  # noqa: E731
    lines = [
        f"after {r['settle_s']:.0f} s ({r['epochs']} FOG epochs at 10 Hz):",
        f"  attitude RMS (roll, pitch, heading) deg : {f3(r['att_rms_deg'])}",
        f"  attitude max                        deg : {f3(r['att_max_deg'])}",
        f"  attitude RMS after mounting removal deg : {f3(r['att_resid_rms_deg'])}",
        f"  mounting mu (RFU rot. vector)       deg : {f3(r['mount_deg'])}",
        f"  upstream mu0                        deg : {f3(r.get('mu0_deg', [np.nan] * 3))}",
        f"  velocity RMS (E, N, U)              m/s : {f3(r['vel_rms'])}",
        f"  horizontal position RMS               m : {r['pos_rms_m']:.3f}",
        f"  gyro bias final                    deg/h: {f3(r['gyro_bias_dph'], 1)}",
        f"  upstream eb0                       deg/h: {f3(r.get('eb0_dph', [np.nan] * 3), 1)}",
        f"  accel bias final                    µg  : {f3(r['accel_bias_ug'], 0)}",
        f"  upstream db0                        µg  : {f3(r.get('db0_ug', [np.nan] * 3), 0)}",
    ]
    return "\n".join(lines)


if __name__ == "__main__":  # pragma: no cover
    import argparse

    ap = argparse.ArgumentParser(description="MEMS EKF against the FOG-INS (psins_fog_mems_vehicle)")
    ap.add_argument("folder", nargs="?", default="/work/shared/data/psins_fog_mems_vehicle")
    ap.add_argument("--smooth", action="store_true", help="RTS smoother")
    ap.add_argument("--velocity", action="store_true", help="also aid with the FOG velocity")
    ap.add_argument("--rate-hz", type=float, default=1.0, help="aiding rate (FOG epochs at 10 Hz)")
    ap.add_argument("--nhc", action="store_true", help="non-holonomic constraint on")
    a = ap.parse_args()
    print(summary(evaluate_fog_mems(a.folder, smooth=a.smooth, aid_velocity=a.velocity,
                                    gnss_rate_hz=a.rate_hz, nhc=a.nhc)))
