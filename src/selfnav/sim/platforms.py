"""Slow and unusual platforms (issue 20): a walker with a handheld unit, a skid-steer rover, a small
boat in waves, a hovering and manoeuvring multirotor drone (all simulated).

Each generator returns a :class:`~selfnav.types.Trajectory` sampled at ``dt`` that the exact
inverse strapdown (:func:`selfnav.sim.inverse.imu_from_trajectory`) turns into sensor data, and
each takes ``start="rest"`` (the platform stands still for ``rest_s`` seconds, then sets off
smoothly) or ``start="moving"`` (under way from the first sample). Motion is built from smooth
pieces only — quintic ramps (C², :func:`selfnav.sim.aircraft.smoothstep`), sinusoids and cubic
splines through random knots — so that rates and specific force are continuous.

* **pedestrian**: 1.4 m/s with the speed, height and sideways sway of each step (1.7–2.0 Hz),
  legs of 10–40 m and tight turns (45–180° at up to 90 °/s, slowing down in them); the unit is
  held in the hand: its heading is off the walking direction by a few degrees and sways with
  the steps, pitch and roll wander by a few degrees; standing still it trembles slightly.
* **rover**: 0.3 m/s skid-steer: legs of 4–15 m, turns on the spot or nearly (20 °/s), the
  velocity slipping sideways in turns (``slip_s`` × yaw rate) and a little on the straights;
  terrain pitch and roll of a few degrees and a vibration.
* **boat**: 1 m/s with gentle course changes, surge, heave, roll, pitch and yaw of an irregular
  sea (two sinusoids per axis, random phases); at rest it drifts in the waves, still rocking.
* **drone**: a multirotor: at rest on the ground, take-off, hover (wandering by decimetres),
  legs at 5 m/s with accelerations and yaw turns, hover again. Its body z axis follows the
  thrust ``a + g`` (it tilts into every acceleration), its heading follows a yaw schedule, the
  propellers add a small attitude jitter in flight; ``start="moving"`` begins in flight.
"""
from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from selfnav import attitude as att
from selfnav.earth import normal_gravity, radii
from selfnav.errors import SelfnavError
from selfnav.sim.aircraft import smoothstep
from selfnav.types import Trajectory

STARTS = ("rest", "moving")
PLATFORMS = ("pedestrian", "rover", "boat", "drone")


def _check_start(start):
    if start not in STARTS:
        raise SelfnavError(f"start '{start}' unknown: use rest or moving")


def _grid(duration, dt):
    n = int(np.floor(duration / dt + 1e-9)) + 1
    return np.arange(n) * dt


def smooth_noise(t, sigma, knot_s, rng, dims=1):
    """A smooth random signal: a cubic spline through N(0, σ²) knots every ``knot_s`` seconds."""
    t = np.asarray(t, dtype=float)
    tk = np.arange(t[0] - knot_s, t[-1] + 2 * knot_s, knot_s)
    y = rng.normal(size=(len(tk), dims)) * sigma
    out = CubicSpline(tk, y)(t)
    return out[:, 0] if dims == 1 else out


def _ramp_up(t, t0, ramp):
    return smoothstep((t - t0) / ramp) if ramp > 0 else (t >= t0).astype(float)


def _turn_schedule(t, start_t, rng, *, leg_s, turn_deg, max_rate_deg, ramp_frac=0.3):
    """Heading-rate pulses: a leg of ``leg_s`` (low, high) seconds, then a turn of ``turn_deg``
    (low, high) degrees either way at up to ``max_rate_deg`` °/s. Returns the heading rate and
    a 0..1 'turning' weight."""
    rate = np.zeros_like(t)
    turning = np.zeros_like(t)
    s = start_t + rng.uniform(*leg_s)
    while s < t[-1]:
        ang = np.radians(rng.uniform(*turn_deg)) * rng.choice([-1.0, 1.0])
        r = np.radians(max_rate_deg) * rng.uniform(0.6, 1.0)
        T = abs(ang) / r / (1.0 - ramp_frac)          # ramps cost ramp_frac of the area
        ramp = ramp_frac * T
        up = smoothstep((t - s) / ramp)
        down = smoothstep((t - s - T + ramp) / ramp)
        prof = up - down
        rate += np.sign(ang) * r * prof
        turning = np.maximum(turning, prof)
        s += T + rng.uniform(*leg_s)
    return rate, turning


def _integrate_plane(t, v_e, v_n, v_u, lat0, lon0, h0):
    """Geodetic position from an ENU velocity by the trapezoid rule (radii from a first pass)."""
    from scipy.integrate import cumulative_trapezoid as ct

    h = h0 + ct(v_u, t, initial=0.0)
    lat = np.full(len(t), float(lat0))
    for _ in range(3):
        r_phi, r_lam = radii(lat, h)
        lat = lat0 + ct(v_n / r_phi, t, initial=0.0)
    r_phi, r_lam = radii(lat, h)
    lon = lon0 + ct(v_e / (r_lam * np.cos(lat)), t, initial=0.0)
    return lat, np.angle(np.exp(1j * lon)), h


def _traj(t, lat, lon, h, v, C_nb, source):
    return Trajectory(t, lat, lon, h, v, C_nb, source=source)


# ----------------------------------------------------------------------------- pedestrian
def pedestrian_trajectory(duration=300.0, dt=0.01, lat0=np.radians(48.0), lon0=np.radians(11.0),
                          h0=500.0, *, start="rest", rest_s=30.0, speed=1.4, step_hz=None,
                          heading0_deg=None, leg_s=(8.0, 30.0), turn_deg=(45.0, 180.0),
                          turn_rate_deg=90.0, bounce_m=0.025, sway_m=0.02, speed_swing=0.12,
                          hand_pitch_deg=None, hand_roll_deg=None, hand_yaw_deg=None,
                          hand_sway_deg=3.0, hand_wander_deg=2.0, tremor_deg=0.05,
                          seed=None) -> Trajectory:
    """A person walking with a handheld unit (module docstring); angles in degrees, SI else."""
    _check_start(start)
    rng = np.random.default_rng(seed)
    t = _grid(duration, dt)
    t_go = rest_s if start == "rest" else -10.0
    go = _ramp_up(t, t_go, 2.0)                        # 2 s to walking pace
    f_step = float(step_hz or rng.uniform(1.7, 2.0))
    ph = rng.uniform(0, 2 * np.pi, 4)
    H0 = np.radians(rng.uniform(0, 360) if heading0_deg is None else heading0_deg)
    rate, turning = _turn_schedule(t, max(t_go, 0.0) + 2.0, rng, leg_s=leg_s,
                                   turn_deg=turn_deg, max_rate_deg=turn_rate_deg)
    rate *= go
    from scipy.integrate import cumulative_trapezoid as ct

    H = H0 + ct(rate, t, initial=0.0)
    w = 2 * np.pi * f_step
    v_fwd = speed * go * (1.0 - 0.3 * turning) * (1.0 + speed_swing * np.sin(w * t + ph[0]))
    # sideways sway at half the step rate, vertical bounce at the step rate
    sway_v = sway_m * (w / 2) * np.cos(w / 2 * t + ph[1]) * go
    bounce_v = bounce_m * w * np.cos(w * t + ph[2]) * go
    sH, cH = np.sin(H), np.cos(H)
    v = np.column_stack([v_fwd * sH + sway_v * cH, v_fwd * cH - sway_v * sH, bounce_v])
    lat, lon, h = _integrate_plane(t, v[:, 0], v[:, 1], v[:, 2], lat0, lon0, h0)
    # the unit in the hand
    p0 = rng.uniform(-15.0, 5.0) if hand_pitch_deg is None else hand_pitch_deg
    r0 = rng.uniform(-5.0, 5.0) if hand_roll_deg is None else hand_roll_deg
    y0 = rng.uniform(-10.0, 10.0) if hand_yaw_deg is None else hand_yaw_deg
    wander = smooth_noise(t, np.radians(hand_wander_deg), 3.0, rng, dims=3) * go[:, None]
    tremor = smooth_noise(t, np.radians(tremor_deg), 0.2, rng, dims=3)
    sway = np.radians(hand_sway_deg) * go
    roll = np.radians(r0) + sway * np.sin(w / 2 * t + ph[1]) + wander[:, 0] + tremor[:, 0]
    pitch = np.radians(p0) + 0.5 * sway * np.sin(w * t + ph[3]) + wander[:, 1] + tremor[:, 1]
    yaw = H + np.radians(y0) + 0.7 * sway * np.sin(w / 2 * t + ph[1] + 0.5) + wander[:, 2] \
        + tremor[:, 2]
    C = att.dcm_nb_from_euler(roll, pitch, yaw)
    return _traj(t, lat, lon, h, v, C, f"simulated pedestrian ({speed:g} m/s, handheld, "
                 f"steps {f_step:.2f} Hz, start {start})")


# ----------------------------------------------------------------------------- rover
def rover_trajectory(duration=600.0, dt=0.005, lat0=np.radians(40.1), lon0=np.radians(-105.15),
                     h0=1600.0, *, start="rest", rest_s=30.0, speed=0.3, heading0_deg=None,
                     leg_s=(12.0, 50.0), turn_deg=(30.0, 180.0), turn_rate_deg=20.0,
                     slip_s=0.5, slip_noise_deg=2.0, terrain_deg=3.0, terrain_knot_m=4.0,
                     vibration_deg=0.3, seed=None) -> Trajectory:
    """A slow skid-steer rover (module docstring): it nearly stops to turn; the velocity
    slips ``slip_s`` × yaw rate to the outside of a turn (and ``slip_noise_deg`` at random)."""
    _check_start(start)
    rng = np.random.default_rng(seed)
    t = _grid(duration, dt)
    t_go = rest_s if start == "rest" else -10.0
    go = _ramp_up(t, t_go, 3.0)
    H0 = np.radians(rng.uniform(0, 360) if heading0_deg is None else heading0_deg)
    rate, turning = _turn_schedule(t, max(t_go, 0.0) + 3.0, rng, leg_s=leg_s,
                                   turn_deg=turn_deg, max_rate_deg=turn_rate_deg)
    rate *= go
    from scipy.integrate import cumulative_trapezoid as ct

    H = H0 + ct(rate, t, initial=0.0)
    v_fwd = speed * go * (1.0 - 0.85 * turning)
    slip = slip_s * rate + np.radians(slip_noise_deg) * smooth_noise(t, 1.0, 5.0, rng) * go
    course = H + slip
    v = np.column_stack([v_fwd * np.sin(course), v_fwd * np.cos(course), np.zeros_like(t)])
    # terrain: pitch and roll varying with distance travelled, a little climb with the pitch
    s = ct(v_fwd, t, initial=0.0)
    knots = max(terrain_knot_m, 0.5)
    terr = smooth_noise(s / max(speed, 1e-3), np.radians(terrain_deg), knots / max(speed, 1e-3),
                        rng, dims=2)
    pitch = terr[:, 0]
    roll = terr[:, 1]
    v[:, 2] = v_fwd * np.sin(pitch)
    vib = smooth_noise(t, np.radians(vibration_deg), 0.25, rng, dims=3) * go[:, None]
    lat, lon, h = _integrate_plane(t, v[:, 0], v[:, 1], v[:, 2], lat0, lon0, h0)
    C = att.dcm_nb_from_euler(roll + vib[:, 0], pitch + vib[:, 1], H + vib[:, 2])
    return _traj(t, lat, lon, h, v, C, f"simulated rover ({speed:g} m/s skid-steer, slip "
                 f"{slip_s:g} s x yaw rate, start {start})")


# ----------------------------------------------------------------------------- boat
def boat_trajectory(duration=900.0, dt=0.01, lat0=np.radians(59.4), lon0=np.radians(24.7),
                    h0=0.0, *, start="moving", rest_s=60.0, speed=1.0, heading0_deg=None,
                    leg_s=(60.0, 180.0), turn_deg=(20.0, 90.0), turn_rate_deg=3.0,
                    roll_deg=4.0, pitch_deg=2.0, yaw_deg=2.0, heave_m=0.3, surge_mps=0.1,
                    wave_period_s=6.0, drift_mps=0.05, seed=None) -> Trajectory:
    """A small boat at ``speed`` in an irregular sea (module docstring); ``start="rest"``
    drifts (``drift_mps``) in the waves for ``rest_s`` seconds before getting under way."""
    _check_start(start)
    rng = np.random.default_rng(seed)
    t = _grid(duration, dt)
    t_go = rest_s if start == "rest" else -30.0
    go = _ramp_up(t, t_go, 20.0)
    H0 = np.radians(rng.uniform(0, 360) if heading0_deg is None else heading0_deg)
    rate, _ = _turn_schedule(t, max(t_go, 0.0) + 20.0, rng, leg_s=leg_s, turn_deg=turn_deg,
                             max_rate_deg=turn_rate_deg)
    rate *= go
    from scipy.integrate import cumulative_trapezoid as ct

    course = H0 + ct(rate, t, initial=0.0)

    def sea(amp, period):
        a = rng.uniform(0.6, 1.0, 2)
        p = period * np.array([1.0, rng.uniform(0.6, 0.8)])
        ph = rng.uniform(0, 2 * np.pi, 2)
        x = sum(a[i] * np.sin(2 * np.pi * t / p[i] + ph[i]) for i in range(2)) / a.sum()
        dx = sum(a[i] * 2 * np.pi / p[i] * np.cos(2 * np.pi * t / p[i] + ph[i])
                 for i in range(2)) / a.sum()
        return amp * x, amp * dx

    roll, _ = sea(np.radians(roll_deg), wave_period_s * 1.3)
    pitch, _ = sea(np.radians(pitch_deg), wave_period_s * 0.8)
    yaw, _ = sea(np.radians(yaw_deg), wave_period_s * 1.7)
    _, heave_v = sea(heave_m, wave_period_s)
    surge, _ = sea(surge_mps, wave_period_s)
    drift_dir = rng.uniform(0, 2 * np.pi)
    v_fwd = speed * go + surge
    v = np.column_stack([v_fwd * np.sin(course) + drift_mps * np.sin(drift_dir) * (1 - go),
                         v_fwd * np.cos(course) + drift_mps * np.cos(drift_dir) * (1 - go),
                         heave_v])
    lat, lon, h = _integrate_plane(t, v[:, 0], v[:, 1], v[:, 2], lat0, lon0, h0)
    C = att.dcm_nb_from_euler(roll, pitch, course + yaw)
    return _traj(t, lat, lon, h, v, C, f"simulated boat ({speed:g} m/s in waves, start {start})")


# ----------------------------------------------------------------------------- drone
def _thrust_attitude(acc_n, heading, g):
    """``C_nb`` of a multirotor: body z along ``a + g e_U``, forward toward ``heading``."""
    u = acc_n + np.column_stack([np.zeros(len(g)), np.zeros(len(g)), g])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    hv = np.column_stack([np.sin(heading), np.cos(heading), np.zeros_like(heading)])
    y = hv - np.sum(hv * u, axis=1, keepdims=True) * u
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, u)
    C_bn = np.stack([x, y, u], axis=-1)                # columns: body axes in ENU
    return np.swapaxes(C_bn, -1, -2)


def drone_trajectory(duration=300.0, dt=0.005, lat0=np.radians(47.4), lon0=np.radians(8.55),
                     h0=450.0, *, start="rest", rest_s=20.0, altitude_m=10.0, climb_mps=1.5,
                     speed=5.0, accel=2.0, hover_s=(10.0, 30.0), leg_m=(30.0, 80.0),
                     yaw_rate_deg=45.0, wander_m=0.2, jitter_deg=0.3, seed=None) -> Trajectory:
    """A multirotor (module docstring): rest on the ground (``start="rest"``, ``rest_s``),
    take-off to ``altitude_m``, then hovers of ``hover_s`` s and legs of ``leg_m`` metres at
    ``speed`` with ``accel``; ``start="moving"`` starts on a leg at altitude."""
    _check_start(start)
    rng = np.random.default_rng(seed)
    t = _grid(duration, dt)
    n = len(t)
    vel = np.zeros((n, 3))
    yaw = np.zeros(n)
    flying = np.zeros(n)
    H = np.radians(rng.uniform(0, 360))
    if start == "rest":
        t_up = rest_s
        T_climb = altitude_m / climb_mps + 2.0
        vel[:, 2] += climb_mps * (smoothstep((t - t_up) / 2.0) - smoothstep(
            (t - t_up - T_climb + 2.0) / 2.0))
        flying = smoothstep((t - t_up) / 1.0)
        s = t_up + T_climb + rng.uniform(*hover_s)
        h_start = h0
    else:
        flying[:] = 1.0
        s = 0.0
        h_start = h0 + altitude_m
    heading = np.full(n, H)
    first = start == "moving"
    while s < t[-1]:
        L = rng.uniform(*leg_m)
        ramp = speed / accel * 1.875                   # smoothstep's peak slope is 1.875
        T = L / speed + ramp
        d = rng.uniform(0, 2 * np.pi)
        if first:                                      # already at speed, facing the leg
            prof = 1.0 - smoothstep((t - s - T + ramp) / ramp)
            heading[:] = d
        else:
            prof = smoothstep((t - s) / ramp) - smoothstep((t - s - T + ramp) / ramp)
            # turn to face the leg during the hover before it (yaw rate limited, smooth)
            dH = (d - H + np.pi) % (2 * np.pi) - np.pi
            Ty = max(abs(dH) / np.radians(yaw_rate_deg) * 1.875, 1.0)
            heading += dH * smoothstep((t - (s - Ty - 0.5)) / Ty)
        vel[:, 0] += speed * np.sin(d) * prof
        vel[:, 1] += speed * np.cos(d) * prof
        H = d
        first = False
        s += T + rng.uniform(*hover_s)
    # hover wander (only in the air)
    wander = smooth_noise(t, wander_m * 0.5, 2.0, rng, dims=3) * flying[:, None]
    vel += np.gradient(wander, t, axis=0)
    lat, lon, h = _integrate_plane(t, vel[:, 0], vel[:, 1], vel[:, 2], lat0, lon0, h_start)
    acc = np.gradient(vel, t, axis=0)
    g = normal_gravity(lat, h)
    C = _thrust_attitude(acc * flying[:, None], heading, g)
    jit = smooth_noise(t, np.radians(jitter_deg), 0.08, rng, dims=3) * flying[:, None]
    C = np.einsum("nij,njk->nik", att.rotvec_to_dcm(jit), C)
    return _traj(t, lat, lon, h, vel, C, f"simulated multirotor drone (hover, legs at "
                 f"{speed:g} m/s, start {start})")


GENERATORS = {"pedestrian": pedestrian_trajectory, "rover": rover_trajectory,
              "boat": boat_trajectory, "drone": drone_trajectory}
