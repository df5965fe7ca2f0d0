"""The navigator on every simulated platform (issue 20): does it start, how soon after the
first fix, and how well does it follow — SIMULATED data (selfnav.simulate).

    python benchmarks/platforms_start.py [--seeds 30 31 32] [--duration 300] [--mode profile|auto]
    python benchmarks/platforms_start.py --clean [--seeds 40 41 42] [--mode profile|auto]
    python benchmarks/platforms_start.py --rtk-walk [--seeds 40 41 42]
    python benchmarks/platforms_start.py --ship [--seeds 1 2]
    python benchmarks/platforms_start.py --wobble [--seeds 1 2 3 4 5]

Per platform and start (at rest / moving): seconds from the first fix to the start, the start
kind and heading source, horizontal RMS (and the fixes' σ) and heading RMS over the whole
solution and from 60 s after the start (the heading hypotheses resolved), the largest error
at the end of the issue's outages (10 s every 30 s for the walker and the rover, 30 s every
120 s for the boat and the drone, from 60 s after the start; a second run), the CPU time of
the clean run. ``--mode profile`` passes ``platform=<the platform>``; ``auto`` the defaults.

``--clean``: each platform started moving on white fixes only (the scenario's drifting part
off: the issue's "clean"), RMS from a minute after the start against the fixes' σ.

``--rtk-walk``: the issue's handheld walk, simulated — 5 Hz fixes of 2 cm without drift, the
walker standing 30 s first — with ``--platform pedestrian`` and with ``--no-nhc``, outages of
10 s every 30 s from 30 s after the start. ``--ship``: the ``ship`` scenario (yaw ±5° about its
course at 6 m/s) with the defaults, ``--no-nhc`` and ``--platform boat``.

``--wobble``: could the raw gyros tell a hull from a car when the defaults start? The ship
scenario and the built-in car (consumer, industrial, tactical) with the defaults; over the
IMU before the start (at most 30 s), the gyro rates split into the part about gravity (the mean
specific force) and the part across it, integrated and detrended by a quadratic: the RMS of
the tilt and of the heading left (a hull rocks and yaws in the waves; a car turns); and the
real drive_0708 (when ``../shared/data`` has it), every window where it moves and does not
turn.
"""
from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import selfnav
from selfnav.earth import enu_offset

PLATFORMS = ("pedestrian", "rover", "boat", "drone")

#: outages of the issue's acceptance: (length, period) s — 10 s every 30 s for the slow ground
#: platforms, 30 s every 120 s for the boat and the drone
OUTAGES = {"pedestrian": (10.0, 30.0), "rover": (10.0, 30.0), "boat": (30.0, 120.0),
           "drone": (30.0, 120.0)}

RTK_WALK = {"scenario": {"kind": "pedestrian", "duration": 240, "start": "rest"},
            "gnss": {"rate_hz": 5, "sigma_m": 0.02, "correlated_sigma_m": 0.0,
                     "spike_rate": 0.0}}


def _navigate(imu, gnss, kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return selfnav.navigate(imu, gnss, **kw)


def outage_ends(sim, kw, t_from, length, period):
    """Largest horizontal error at the end of each outage (the last row before the fixes
    come back) of a run without the fixes of ``length`` s every ``period`` s from ``t_from``."""
    gnss = sim.gnss.as_gnss()
    phase = (gnss.t - t_from) % period
    cut = (gnss.t >= t_from) & (phase >= period - length)
    tr = _navigate(sim.imu, gnss.select(~cut), kw).trajectory
    ends = []
    for t_end in np.arange(t_from + period, gnss.t[-1], period):
        k = np.searchsorted(tr.t, t_end) - 1
        if k < 0 or tr.t[k] < t_end - length:
            continue
        j = np.searchsorted(sim.truth.t, tr.t[k])
        d = enu_offset(sim.truth.lat[j], sim.truth.lon[j], 0.0, tr.lat[k], tr.lon[k], 0.0)
        ends.append(float(np.hypot(d[0], d[1])))
    return max(ends) if ends else float("nan")


def one(kind, start, seed, duration, mode):
    sim = selfnav.simulate(kind, seed=seed, duration=duration, start=start)
    gnss = sim.gnss.as_gnss()
    kw = {} if mode == "auto" else {"platform": kind}
    t0 = time.process_time()
    try:
        sol = _navigate(sim.imu, gnss, kw)
    except selfnav.errors.SelfnavError as e:
        return dict(kind=kind, start=start, seed=seed, error=str(e)[:60])
    cpu = time.process_time() - t0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ev = selfnav.evaluate(sim.truth, sol)
        tr = sol.trajectory
        late = selfnav.evaluate(sim.truth, tr.select(tr.t >= sol.stats["start_s"] + 60.0))
    st = sol.stats
    out_max = outage_ends(sim, kw, st["start_s"] + 60.0, *OUTAGES[kind])
    return dict(kind=kind, start=start, seed=seed, delay=st["start_s"] - gnss.t[0], out=out_max,
                start_kind=st.get("start_kind"), heading=st.get("start_heading"),
                rms=ev["horizontal_rms_m"], sigma=float(np.median(gnss.sigma_m)),
                hdg=ev["heading_rms_deg"], hdg60=late["heading_rms_deg"],
                rms60=late["horizontal_rms_m"], cpu=cpu)


def rtk_walk(seeds):
    print("| seed | options | start after 1st fix s | horizontal RMS m | heading RMS ° | "
          "10 s outage ends, max m |")
    print("| ---: | --- | ---: | ---: | ---: | ---: |")
    for seed in seeds:
        sim = selfnav.simulate(RTK_WALK, seed=seed)
        gnss = sim.gnss.as_gnss()
        for kw in ({"platform": "pedestrian"}, {"nhc": False}):
            sol = _navigate(sim.imu, gnss, kw)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ev = selfnav.evaluate(sim.truth, sol)
            t_from = sol.stats["start_s"] + 30.0
            print(f"| {seed} | {kw} | {sol.stats['start_s'] - gnss.t[0]:.0f} | "
                  f"{ev['horizontal_rms_m']:.3f} | {ev['heading_rms_deg']:.1f} | "
                  f"{outage_ends(sim, kw, t_from, 10.0, 30.0):.2f} |", flush=True)


def clean(seeds, duration, mode):
    print("| platform | seed | fix σ m | raw fixes RMS m | RMS from a minute after the start m "
          "| / fix σ |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for kind in PLATFORMS:
        for seed in seeds:
            spec = {"scenario": {"kind": kind, "duration": duration, "start": "moving"},
                    "gnss": {"correlated_sigma_m": 0.0}}
            sim = selfnav.simulate(spec, seed=seed)
            gnss = sim.gnss.as_gnss()
            sol = _navigate(sim.imu, gnss, {} if mode == "auto" else {"platform": kind})
            tr, T = sol.trajectory, sim.truth
            late = tr.select(tr.t >= sol.stats["start_s"] + 60.0)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rms = selfnav.evaluate(T, late)["horizontal_rms_m"]
            j = np.clip(np.searchsorted(T.t, gnss.t), 0, len(T.t) - 1)
            d = enu_offset(T.lat[j], T.lon[j], 0.0, gnss.lat, gnss.lon, 0.0)
            raw = float(np.sqrt(np.mean(d[:, 0] ** 2 + d[:, 1] ** 2)))
            s = float(np.median(gnss.sigma_m))
            print(f"| {kind} | {seed} | {s:.2f} | {raw:.2f} | {rms:.2f} | {rms / s:.2f} |",
                  flush=True)


def ship(seeds):
    print("| seed | options | horizontal RMS m | heading RMS ° |")
    print("| ---: | --- | ---: | ---: |")
    for seed in seeds:
        sim = selfnav.simulate("ship", seed=seed, duration=300)
        gnss = sim.gnss.as_gnss()
        for kw in ({}, {"nhc": False}, {"platform": "boat"}):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                ev = selfnav.evaluate(sim.truth, _navigate(sim.imu, gnss, kw))
            print(f"| {seed} | {kw or 'defaults'} | {ev['horizontal_rms_m']:.1f} | "
                  f"{ev['heading_rms_deg']:.1f} |", flush=True)


def wobble_deg(imu, t_end, window=30.0):
    """Tilt and heading wobble (RMS °) of the IMU over ``window`` s before ``t_end`` and the
    span used (s): the rates about gravity and across it, integrated, less a quadratic."""
    m = (imu.t > t_end - window) & (imu.t <= t_end)
    t, w = imu.t[m], imu.omega_ib_b[m]
    up = imu.f_ib_b[m].mean(axis=0)
    up /= np.linalg.norm(up)
    w_up = w @ up
    angle = np.cumsum(np.column_stack([w - np.outer(w_up, up), w_up])
                      * np.diff(t, prepend=t[0])[:, None], axis=0)
    A = np.vander((t - t.mean()) / window, 3)
    left = angle - A @ np.linalg.lstsq(A, angle, rcond=None)[0]
    return (np.degrees(np.sqrt(np.mean(np.sum(left[:, :3] ** 2, axis=1)))),
            np.degrees(np.sqrt(np.mean(left[:, 3] ** 2))), t[-1] - t[0])


def wobble(seeds):
    print("| platform | seed | start s | IMU before it s | tilt wobble ° | heading wobble ° |")
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    runs = [("ship", "ship", s) for s in seeds] + [
        (f"car, {g}", {"scenario": {"kind": "car", "duration": 200}, "imu": {"grade": g}}, s)
        for g in ("consumer", "industrial", "tactical") for s in seeds]
    for label, spec, seed in runs:
        sim = selfnav.simulate(spec, seed=seed, duration=120 if spec == "ship" else None)
        sol = _navigate(sim.imu, sim.gnss.as_gnss(), {})
        t0 = sol.stats["start_s"]
        tilt, yaw, span = wobble_deg(sim.imu, t0)
        print(f"| {label} | {seed} | {t0:.0f} | {span:.0f} | {tilt:.2f} | {yaw:.2f} |",
              flush=True)
    real = Path(__file__).resolve().parents[2] / "shared" / "data" / "rtklibexplorer_drive_0708"
    if not real.exists():
        return
    # a real car: every window of the drive (every 2 s) where it moves and does not turn
    imu, gnss = selfnav.read_imu(real / "imu_1934.csv"), selfnav.read_gnss(real / "gnss_1934_sf.pos")
    speed = np.hypot(*gnss.velocity_n[:, :2].T)
    print("\n| real drive_0708, window s | windows moving (> 3 m/s), heading wobble < 1° | "
          "their largest tilt wobble ° |")
    print("| ---: | ---: | ---: |")
    for window in (8.0, 15.0, 30.0):
        calm = []
        for t_end in np.arange(imu.t[0] + window, imu.t[-1], 2.0):
            tilt, yaw, _ = wobble_deg(imu, t_end, window)
            if yaw < 1.0 and np.interp(t_end, gnss.t, speed) > 3.0:
                calm.append(tilt)
        print(f"| {window:.0f} | {len(calm)} | {max(calm):.2f} |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=None)
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--mode", choices=("profile", "auto"), default="profile")
    ap.add_argument("--rtk-walk", action="store_true")
    ap.add_argument("--ship", action="store_true")
    ap.add_argument("--clean", action="store_true")
    ap.add_argument("--wobble", action="store_true")
    a = ap.parse_args()
    if a.clean:
        return clean(a.seeds or [40, 41, 42], a.duration if a.duration != 300.0 else 240.0,
                     a.mode)
    if a.rtk_walk:
        return rtk_walk(a.seeds or [40, 41, 42])
    if a.ship:
        return ship(a.seeds or [1, 2])
    if a.wobble:
        return wobble(a.seeds or [1, 2, 3, 4, 5])
    print("| platform | start | seed | start after 1st fix s | kind / heading | horizontal RMS m "
          "(fix σ) | from 60 s after the start | heading RMS ° | from 60 s after | outage ends "
          "max m | CPU s |")
    print("| --- | --- | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for kind in PLATFORMS:
        for start in ("rest", "moving"):
            for seed in a.seeds or [30, 31, 32]:
                r = one(kind, start, seed, a.duration, a.mode)
                if "error" in r:
                    print(f"| {kind} | {start} | {seed} | no start: {r['error']} | | | | | | | |")
                    continue
                print(f"| {kind} | {start} | {seed} | {r['delay']:.1f} | {r['start_kind']} / "
                      f"{r['heading']} | {r['rms']:.2f} ({r['sigma']:.2f}) | {r['rms60']:.2f} | "
                      f"{r['hdg']:.1f} | {r['hdg60']:.1f} | {r['out']:.1f} | {r['cpu']:.1f} |",
                      flush=True)


if __name__ == "__main__":
    main()
