"""A simulated aircraft: level flight, climb, coordinated turns, descent (issue 3).

The flight is defined by three smooth schedules: speed ``V(t)``, flight-path angle ``γ(t)`` and
turn rate ``ψ̇(t)`` (heading rate), each a sum of manoeuvres with quintic (C²) ramps, so that
accelerations and body rates are continuous. Then, in ENU::

    V^n = V (cos γ sin H, cos γ cos H, sin γ),   H = H0 + ∫ψ̇ dt
    φ̇ = V_N / R_φ,   λ̇ = V_E / (R_λ cos φ),   ḣ = V_U                 (seed 004 (10))

integrated with the trapezoidal rule on the output grid. Attitude: pitch ``γ + α`` (constant
angle of attack), roll the bank of a coordinated turn ``atan(V ψ̇ / g)``, heading ``H`` (no
sideslip). The sensors come from :func:`selfnav.sim.inverse.imu_from_trajectory`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_trapezoid

from selfnav import attitude as att
from selfnav.earth import normal_gravity, radii
from selfnav.types import Trajectory


def smoothstep(x):
    """Quintic ramp 0 -> 1 on [0, 1] with zero first and second derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x * x)


@dataclass
class Manoeuvre:
    """A change of one schedule: ``value`` held over ``[start, end]`` with ``ramp``-second ramps.

    kind : "turn" (turn rate, rad/s), "climb" (flight-path angle, rad) or "speed" (m/s added)
    """

    kind: str
    start: float
    end: float
    value: float
    ramp: float = 10.0

    def profile(self, t):
        up = smoothstep((t - self.start) / self.ramp)
        down = smoothstep((t - self.end + self.ramp) / self.ramp)
        return self.value * (up - down)


def default_flight(duration: float, *, turn_rate_deg=3.0, climb_deg=4.0):
    """Climb, a right turn of about 180°, a level leg, a descending left turn of about 90°.

    Times are fractions of ``duration`` (at least 200 s).
    """
    T = float(duration)
    r = np.radians(turn_rate_deg)
    t180 = np.pi / r + 10.0
    t90 = 0.5 * np.pi / r + 10.0
    return [
        Manoeuvre("speed", 0.05 * T, T, 10.0, ramp=min(30.0, 0.05 * T)),
        Manoeuvre("climb", 0.08 * T, 0.35 * T, np.radians(climb_deg), ramp=min(15.0, 0.05 * T)),
        Manoeuvre("turn", 0.40 * T, 0.40 * T + min(t180, 0.2 * T), r, ramp=min(10.0, 0.03 * T)),
        Manoeuvre("turn", 0.70 * T, 0.70 * T + min(t90, 0.15 * T), -r, ramp=min(10.0, 0.03 * T)),
        Manoeuvre("climb", 0.70 * T, 0.90 * T, -np.radians(0.5 * climb_deg),
                  ramp=min(15.0, 0.05 * T)),
    ]


def aircraft_trajectory(duration=900.0, dt=0.01, lat0=np.radians(50.45), lon0=np.radians(30.52),
                        h0=500.0, *, speed=60.0, heading0_deg=45.0, alpha_deg=2.0,
                        manoeuvres=None, seed=None) -> Trajectory:
    """Simulated aircraft flight.

    Parameters
    ----------
    duration, dt : s
    lat0, lon0 : rad; h0 : m (WGS-84)
    speed : initial true airspeed = ground speed (no wind), m/s
    heading0_deg : initial heading, clockwise from North
    alpha_deg : angle of attack (pitch minus flight-path angle)
    manoeuvres : list of :class:`Manoeuvre`, default :func:`default_flight`
    seed : int, optional
        Perturbs the initial heading and the turn rates by a few percent (same seed, same flight).
    """
    rng = np.random.default_rng(seed)
    n = int(np.floor(duration / dt + 1e-9)) + 1
    t = np.arange(n) * dt
    mans = default_flight(duration) if manoeuvres is None else list(manoeuvres)
    if seed is not None:
        mans = [Manoeuvre(m.kind, m.start, m.end, m.value * (1 + 0.05 * rng.normal()), m.ramp)
                for m in mans]
        heading0_deg = heading0_deg + 10.0 * rng.normal()
    V = np.full(n, float(speed))
    gam = np.zeros(n)
    rate = np.zeros(n)
    for m in mans:
        p = m.profile(t)
        if m.kind == "speed":
            V += p
        elif m.kind == "climb":
            gam += p
        elif m.kind == "turn":
            rate += p
        else:
            raise ValueError(f"unknown manoeuvre kind '{m.kind}' (turn, climb, speed)")
    H = np.radians(heading0_deg) + cumulative_trapezoid(rate, t, initial=0.0)
    v_n = V[:, None] * np.column_stack([np.cos(gam) * np.sin(H), np.cos(gam) * np.cos(H),
                                         np.sin(gam)])
    # position: trapezoid on the ENU velocity, radii from a first pass
    h = h0 + cumulative_trapezoid(v_n[:, 2], t, initial=0.0)
    lat = np.full(n, float(lat0))
    for _ in range(3):
        R_phi, R_lam = radii(lat, h)
        lat = lat0 + cumulative_trapezoid(v_n[:, 1] / R_phi, t, initial=0.0)
    R_phi, R_lam = radii(lat, h)
    lon = lon0 + cumulative_trapezoid(v_n[:, 0] / (R_lam * np.cos(lat)), t, initial=0.0)
    bank = np.arctan(V * rate / normal_gravity(lat, h))
    C_nb = att.dcm_nb_from_euler(bank, gam + np.radians(alpha_deg), H)
    return Trajectory(t, lat, np.angle(np.exp(1j * lon)), h, v_n, C_nb,
                      source="simulated aircraft (climb, coordinated turns)")
