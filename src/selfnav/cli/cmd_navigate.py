"""``selfnav navigate``: INS/GNSS navigation (DESIGN §5, §6) — parses, calls
:func:`selfnav.api.navigate`, writes and reports."""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json
from selfnav.errors import SelfnavError

#: Shortest IMU record, s, and the coarsest sample intervals navigate accepts / calls fine.
MIN_IMU_S = 5.0
MAX_IMU_DT_S = 0.2
WARN_IMU_DT_S = 0.05


def _vec3(text: str, name: str) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise SelfnavError(f"{name} must be three numbers separated by commas, got '{text}'") from None
    if v.shape != (3,):
        raise SelfnavError(f"{name} must be three numbers separated by commas, got '{text}'")
    return v


def _magnetometer(imu, mag_path: Path | None):
    """Magnetometer columns from a separate CSV, interpolated onto the IMU times."""
    if mag_path is None:
        return imu
    from selfnav.io.csvio import check_time, read_table

    tab = read_table(mag_path, ("t", "mx", "my", "mz"))
    check_time(tab, min_rows=2)
    imu.mag_b = np.column_stack([np.interp(imu.t, tab["t"], tab[c]) for c in ("mx", "my", "mz")])
    return imu


def _odometer(imu_path: Path, odo_path: Path | None):
    """Wheel speed from ``--odometer`` or the ``speed_mps`` column of the IMU CSV (or None)."""
    from selfnav.io.odometer import has_odometer, read_odometer

    if odo_path is not None:
        return read_odometer(odo_path)
    return read_odometer(imu_path) if has_odometer(imu_path) else None


def _run_tight(label: str, call, out: Path, out_datum: str, comment: str, fix_log,
               as_json: bool):
    """A tightly coupled run (``call(progress)`` → Solution) under a progress bar, its solution
    and per-satellite log written; returns ``(solution, seconds, span s)``."""
    from selfnav import api
    from selfnav.cli.progress import bar

    t0 = time.perf_counter()
    with bar(label, enabled=not as_json) as update:
        sol = call(lambda done, total: update(done / max(total, 1)))
    elapsed = time.perf_counter() - t0
    sol.to_csv(out, datum=out_datum, comments=[comment])
    if fix_log is not None:
        api.write_tight_log(fix_log, sol)
    return sol, elapsed, float(sol.t[-1] - sol.t[0]) if len(sol) > 1 else 0.0


def _navigate_raw(path: Path, out: Path, *, smooth: bool, fix_log, out_datum: str,
                  as_json: bool, drift_guard: bool) -> None:
    """``navigate --gnss-raw``: :func:`selfnav.api.navigate_raw`, written and reported."""
    from selfnav import api

    sol, elapsed, span = _run_tight(
        "navigating (tight)",
        lambda progress: api.navigate_raw(path, smooth=smooth, drift_guard=drift_guard,
                                          progress=progress),
        out, out_datum, f"selfnav navigate --gnss-raw {path.name}{' --smooth' if smooth else ''}",
        fix_log, as_json)
    s = sol.stats
    summary = {"method": sol.method, "epochs": len(sol), "duration_s": span,
               "seconds": elapsed, "real_time_factor": span / max(elapsed, 1e-9), **s,
               "out": str(out)}
    if as_json:
        emit_json(summary)
        return
    print(f"{out}: {len(sol)} epochs over {span:.1f} s, {elapsed:.1f} s "
          f"({summary['real_time_factor']:.0f}× real time), tightly coupled"
          f"{' and smoothed' if smooth else ''}")
    print(f"  satellites given a delayed component: {100 * s['reflected_share']:.0f} %; "
          f"median σ_h {s['median_sigma_h_m']:.1f} m (errors correlated over epochs: "
          f"σ inflated {s['inflation_median']:.0f}× in variance)")
    for e in s.get("guard_episodes", []):
        end = "the end" if e["end_s"] is None else f"{e['end_s']:.1f} s"
        print(f"  drift guard: held the odometry's track from {e['start_s']:.1f} s to {end} "
              f"(every satellite drifting since {e['branch_s']:.1f} s)")


def _navigate_raw_imu(path: Path, imu: Path, out: Path, *, grade: str, platform: str, fix_log,
                      out_datum: str, as_json: bool) -> None:
    """``navigate --gnss-raw FILE --imu FILE``: :func:`selfnav.api.navigate_raw_imu`."""
    from selfnav import api

    sol, elapsed, span = _run_tight(
        "navigating (tight, INS)",
        lambda progress: api.navigate_raw_imu(path, imu, grade=grade, platform=platform,
                                              progress=progress),
        out, out_datum,
        f"selfnav navigate --gnss-raw {path.name} --imu {imu.name} (tightly coupled, causal)",
        fix_log, as_json)
    s = sol.stats
    summary = {"method": sol.method, "epochs": len(sol), "duration_s": span,
               "seconds": elapsed, **s, "out": str(out)}
    if as_json:
        emit_json(summary)
        return
    st = s["start"]
    print(f"{out}: {len(sol)} epochs over {span:.1f} s, {elapsed:.1f} s, tightly coupled INS "
          f"(grade {s['grade']})")
    print(f"  start {st['method']}, heading {st['heading_deg']:.1f}° ± "
          f"{st['sigma_heading_deg']:.1f}°; satellites excluded {s['excluded']} times, clock "
          f"jumps {s['clock_jumps']}; median σ_h {s['median_sigma_h_m']:.2f} m; constellations "
          f"{s['systems']}; motion constraints: {s['motion_constraints']}"
          f"{'' if platform != 'auto' else ' (--platform car for a car)'}")


def register(app: typer.Typer) -> None:
    @app.command("navigate")
    def navigate_cmd(
        out: opt.out_file("Solution CSV (t, lat_deg, lon_deg, h_m, velocity, attitude, σ, "
                          "sigma_h_m, gnss status)."),
        imu: opt.OptionalImuFile = None,
        gnss: opt.OptionalGnssFile = None,
        gnss_raw: Annotated[Optional[Path], typer.Option(
            "--gnss-raw", help="Raw pseudoranges, tightly coupled, every satellite judged on "
                               "its own: with --imu (stamped in GPS time; RINEX with navigation "
                               "records, UBX, PSINS .mat) the INS; alone, the car's speed and "
                               "yaw rate in the same file (smartLoc format). Instead of "
                               "--gnss.")] = None,
        drift_guard: Annotated[bool, typer.Option(
            "--drift-guard/--no-drift-guard",
            help="--gnss-raw: hold the odometry's track when every satellite drifts together "
                 "(a spoofer's drag); off by default: it also holds on some clean city "
                 "drives (docs/gnss.md).")] = False,
        method: Annotated[str, opt.choice_option(
            "--method", choices=("ekf", "seed"),
            help="ekf: error-state Kalman filter; seed: seed 004's two loops (needs --map).")
        ] = "ekf",
        map_: opt.MapFile = None,
        smooth: Annotated[bool, typer.Option("--smooth", help="RTS smoother "
                                             "(post-processing).")] = False,
        imu_format: opt.ImuFormat = "auto",
        imu_axes: opt.ImuAxes = None,
        imu_mount: opt.ImuMount = None,
        gnss_format: opt.GnssFormat = "auto",
        gnss_datum: opt.GnssDatum = "wgs84",
        out_datum: opt.OutDatum = "wgs84",
        grade: opt.NavGrade = "auto",
        lever_arm: Annotated[Optional[str], typer.Option(
            metavar="X,Y,Z", help="IMU-to-antenna lever arm, body RFU, m: x,y,z (default: "
                                  "estimated, and the solution is the antenna's position).")] = None,
        imu_time_offset: Annotated[Optional[float], typer.Option(
            help="Added to the IMU time stamps after the reader's own (the rtklibexplorer "
                 "format applies upstream's -0.125 s), s (default: estimated from the "
                 "data).")] = None,
        init: Annotated[Optional[Path], typer.Option(
            "--init", help="Start from the state of this trajectory file (truth/solution CSV "
                           "with velocity and attitude, PSINS avp CSV) at the IMU start instead "
                           "of aligning from GNSS; then --gnss is optional.")] = None,
        fix_log: Annotated[Optional[Path], typer.Option(
            "--fix-log", parser=opt.file_path, metavar="FILE",
            help="Write one row per GNSS fix: t, status, reason, NIS (a FILE, written "
                 "atomically).")] = None,
        platform: Annotated[str, opt.choice_option(
            "--platform", choices=opt.PLATFORMS,
            help="What carries the IMU: its motion constraints and its start (auto: a car's, "
                 "and a platform that moves slower than a car's start needs is started as a "
                 "slow platform; pedestrian, rover, boat, aircraft, drone start at once, at "
                 "rest or moving at any speed; NHC with a mounting-yaw state for pedestrian, "
                 "rover and boat (its sway: σ 1 m/s), none for aircraft, drone).")] = "auto",
        nhc: Annotated[Optional[bool], typer.Option(
            "--nhc/--no-nhc", help="Non-holonomic constraint (default: as the platform "
                                   "says; on for a car).")] = None,
        scale_factors: Annotated[Optional[bool], typer.Option(
            "--scale-factors/--no-scale-factors",
            help="Estimate scale factors and axis misalignment (default: as the grade "
                 "says; on for auto, consumer and industrial).")] = None,
        mount_states: Annotated[Optional[bool], typer.Option(
            "--mount-states/--no-mount-states",
            help="Estimate the IMU's pitch and yaw to the vehicle (2 states, seen by the "
                 "NHC; default: as the platform says — off for a car, on for a walker, a "
                 "rover, a boat and a slow platform).")] = None,
        magnetometer_aid: Annotated[Optional[bool], typer.Option(
            "--magnetometer-aid/--no-magnetometer-aid",
            help="After the start, the magnetometer (the IMU file's mx,my,mz or --mag) as a "
                 "heading aid once its offset is fitted from the turns (default: as the "
                 "platform says — on for a walker, a rover, a boat and a slow platform, off "
                 "for a car and a drone).")] = None,
        out_rate: Annotated[float, typer.Option(
            "--out-rate", metavar="HZ", min=0.0,
            help="Output rows per second, on a regular grid of the GNSS time (0: a row at "
                 "every IMU sample).")] = 10.0,
        nhc_lever: Annotated[str, typer.Option(
            metavar="X,Y,Z", help="IMU to the rear-axle centre (where the NHC holds), body RFU, m: "
                 "x,y,z.")] = "0,0,0",
        matcher: Annotated[str, opt.choice_option(
            "--matcher", choices=("seed", "mht"),
            help="--method seed identification: seed (residual minimisation, seed 004 §3) or "
                 "mht (road particles).")] = "seed",
        ins_datum: Annotated[str, opt.choice_option(
            "--ins-datum", choices=opt.DATUMS, normalize=opt.datum_key_lazy,
            help="--method seed: datum of the fast loop.")] = "sk42",
        declination_deg: Annotated[Optional[float], typer.Option(
            min=-180.0, max=180.0,
            help="Magnetic declination, deg (default: IGRF at the start).")] = None,
        mag: Annotated[Optional[Path], typer.Option(
            "--mag", help="Magnetometer CSV t,mx,my,mz (default: mx,my,mz columns of the IMU "
                          "CSV).")] = None,
        odometer: Annotated[Optional[Path], typer.Option(
            "--odometer", help="Wheel speed CSV t,speed_mps on the IMU clock (default: the "
                               "speed_mps column of the IMU CSV, if any).")] = None,
        as_json: opt.Json = False,
    ):
        """Navigate with an IMU and GNSS; survives unflagged GNSS outliers (window test)."""
        from selfnav import api
        from selfnav.io.imu import check_imu_rate
        from selfnav.io.output import check_output_file
        from selfnav.summary import solution_span

        check_output_file(out)
        if fix_log is not None:
            check_output_file(fix_log)
        if gnss_raw is not None:
            if gnss is not None or map_ is not None:
                raise SelfnavError("--gnss-raw navigates from its own pseudoranges: give it "
                                   "without --gnss and --map")
            if imu is not None:
                _navigate_raw_imu(gnss_raw, imu, out, grade=grade, platform=platform,
                                  fix_log=fix_log, out_datum=out_datum, as_json=as_json)
                return
            _navigate_raw(gnss_raw, out, smooth=smooth, fix_log=fix_log, out_datum=out_datum,
                          as_json=as_json, drift_guard=drift_guard)
            return
        if imu is None:
            raise SelfnavError("navigate needs --imu FILE (or --gnss-raw FILE: pseudoranges "
                               "with the car's odometry)")
        if gnss is None and init is None:
            raise SelfnavError("navigate needs --gnss FILE (or an initial state: --init FILE)")
        lever = None if lever_arm is None else _vec3(lever_arm, "--lever-arm")
        nhc_arm = _vec3(nhc_lever, "--nhc-lever")
        data = _magnetometer(api.read_imu(imu, imu_format, axes=imu_axes, mount=imu_mount), mag)
        check_imu_rate(data, "navigate", min_duration_s=MIN_IMU_S, max_dt_s=MAX_IMU_DT_S,
                       warn_dt_s=WARN_IMU_DT_S)
        g = api.read_gnss(gnss, gnss_format, gnss_datum) if gnss is not None else None
        graph = None
        if map_ is not None:
            if g is None:
                graph = api.read_roads(map_)
            else:
                graph = api.check_map_covers(map_, g.lat, g.lon, what="GNSS fixes")
        odo = _odometer(imu, odometer)
        t0 = time.perf_counter()
        progress = bar = None
        if not as_json and sys.stderr.isatty():
            from rich.progress import Progress

            bar = Progress(transient=True, console=None)
            bar.start()
            task = bar.add_task("navigating", total=1.0)
            progress = lambda x: bar.update(task, completed=x)  # noqa: E731
        try:
            if method == "seed":
                sol = api.navigate(data, g, graph, method=method, matcher=matcher,
                                   ins_datum=ins_datum, declination_deg=declination_deg,
                                   progress=progress, odometer=odo)
            else:
                extra = {} if scale_factors is None else {
                    "scale_factors": scale_factors, "misalignment": scale_factors}
                if mount_states is not None:
                    extra["mount_states"] = mount_states
                if magnetometer_aid is not None:
                    extra["use_magnetometer"] = magnetometer_aid
                sol = api.navigate(data, g, graph, smooth=smooth, grade=grade,
                                   lever_arm_m=lever, nhc_lever_m=nhc_arm,
                                   imu_time_offset_s=imu_time_offset, nhc=nhc,
                                   platform=platform, init=init,
                                   out_rate_hz=out_rate, progress=progress, odometer=odo,
                                   **extra)
        except np.linalg.LinAlgError as e:   # a safety net: one line, not a traceback
            from selfnav.io.imu import MAX_BRIDGE_SAMPLES, imu_gaps

            gaps = imu_gaps(data, MAX_BRIDGE_SAMPLES + 1)
            cause = (f"; the likely cause is {max(gaps, key=lambda g: g.duration).describe()}"
                     if gaps else "")
            raise SelfnavError(f"{imu}: the filter failed numerically ({e}){cause}") from None
        finally:
            if bar is not None:
                bar.stop()
        elapsed = time.perf_counter() - t0
        sol.to_csv(out, datum=out_datum, comments=[
            f"selfnav navigate --method {method}{' --smooth' if smooth else ''}"
            f"{' --map ' + map_.name if map_ is not None else ''}; imu {imu.name}; "
            f"gnss {gnss.name if gnss is not None else 'none'}"])
        if fix_log is not None:
            api.write_fix_log(fix_log, sol)
        span = float(data.t[-1] - data.t[0])
        cover = solution_span(sol.t, data.t)
        summary = {"method": method, "map": None if map_ is None else str(map_),
                   "epochs": len(sol), "imu_samples": len(data), "duration_s": span, **cover,
                   "seconds": elapsed, "real_time_factor": span / max(elapsed, 1e-9),
                   **sol.stats, "out": str(out)}
        if as_json:
            emit_json(summary)
            return
        print(f"{out}: {summary['epochs']} epochs {cover['span']} "
              f"({100 * cover['coverage']:.0f} % covered), {elapsed:.1f} s "
              f"({summary['real_time_factor']:.0f}× real time)")
        s = sol.stats
        if method == "seed":
            print(f"  seed 004 slow loop ({matcher}): k_M {s['k_m']}, "
                  f"{s['healthy_fixes']} fixes judged healthy")
            return
        c = s["fix_status"]
        print(f"  GNSS fixes: {c['used']} used, {c['degraded']} used in part, "
              f"{c['rejected']} rejected, {c['suspect']} held while suspect, "
              f"{c['aligning']} before the start; {s['fixes_excluded_later']} excluded later")
        drift = (f", clock drift {s['imu_clock_drift_ppm']:+.0f} ppm"
                 if "imu_clock_drift_ppm" in s else "")
        print(f"  IMU time offset {s['imu_time_offset_s']:+.3f} s at the end (estimate "
              f"included{drift}); lever "
              f"arm {', '.join(f'{x:.2f}' for x in s['lever_arm_m'])} m (RFU)")
        eps = [e for e in s.get("episodes", []) if e["kind"] != "outage"]
        if eps:
            kinds = ", ".join(f"{e['kind']} {e['start_s']:.1f}-{(e['end_s'] or 0):.1f} s" for e in eps[:3])
            print(f"  fault episodes: {len(eps)} ({kinds}{', ...' if len(eps) > 3 else ''})")
        md = s.get("map_doubt")
        if md and md["seconds"] > 0:
            print(f"  the map's doubt: off the roads running its way from {md['first_s']:.1f} "
                  f"s, up to {md['largest_m']:.0f} m; σ at least that for {md['seconds']:.0f} s")
        if "mounting_deg" in s:
            print(f"  IMU mounting to the vehicle: pitch {s['mounting_deg'][0]:.2f}°, "
                  f"yaw {s['mounting_deg'][1]:.2f}°")
