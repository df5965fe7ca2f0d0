"""Measurements of the error-state filter as small objects (DESIGN §9; pyins's ``Position``).

Each measurement holds its data and σ and builds, for a filter's current state, the residual
``r = h(x̃) − z``, the Jacobian ``H = ∂h/∂δx`` and the noise ``R`` (:meth:`Measurement.model`);
:meth:`selfnav.ins.ekf.InsGnssFilter.update` applies them, the policy
(:mod:`selfnav.ins.policy`) judges them first. A new aid is a class here, not a branch in the
navigator.

**GNSS position** at the antenna and at the fix's time. The INS state of stamp ``t`` is the
truth at ``t + ε`` (``ε`` the IMU time offset); the fix at true time ``t_k`` is compared with the
state of true time ``t_s ≥ t_k`` moved back by the lead ``τ = t_s − t_k`` (under one IMU
sample when the navigator queues fixes by true time; up to a receiver's latency when a fix
arrives after the IMU has passed it) over the recent accelerations
(:meth:`selfnav.ins.ekf.InsGnssFilter.back`: a single block's acceleration times τ carries
that block's noise and misses a brake or a turn)::

    h(x) = r_INS(t_s − τ) + C_b^n l̂,   ∂h/∂δr = I, ∂h/∂ψ = [C_b^n l̂ ×], ∂h/∂δl = C_b^n,
                                      ∂h/∂δε = −v^n                     (τ grows with ε)

**GNSS velocity** at the antenna, reported ``λ_v`` late (receivers that difference positions or
smooth the Doppler give the velocity of the last interval: 0.13 s on drive_0708)::

    h(x) = v^n(t_s − τ − λ_v) + C_b^n (ω_b × l̂),  ∂h/∂δε = ∂h/∂δλ_v = −a^n

**Non-holonomic constraint** in the *vehicle* frame at a point that does not slip sideways (the
rear-axle centre): ``v_v = C_vb (C_bn^T v^n + ω_b × l_nhc)`` with ``C_vb = exp([μ×])``,
μ = (pitch, 0, yaw) of the IMU relative to the vehicle; ``z = (v_v,R, v_v,U) = 0``.

The constraint's own error (slip, a hull's sway) is correlated over seconds to minutes; taken
as white every aiding step, the constraint is as many times too sure as the error has steps
per correlation time. :class:`NhcCheck` watches for it: a platform whose innovations stay a
large part of the constraint's σ slips sideways (a hull yawing in the waves), and an ``auto``
navigator without a road map widens the constraint (docs/platforms.md). Their correlation
alone does not tell: a GNSS drag's small innovations are correlated too.

**Wheel speed** (odometer): the forward speed at the NHC point scaled by ``1 + k``.

**Pseudoranges and range rates** (tight coupling, :mod:`selfnav.ins.tight`): the antenna's
position and velocity as the GNSS fixes above see them, into each satellite's range and range
rate (:mod:`selfnav.gnss.models` (1)–(2)) with the receiver clock bias ``b_r`` and drift
``ḃ_r``::

    h(x) = |r^s − r_a| + b_r,   ∂h/∂δx = −u^T C_n^e ∂r_a/∂δx + ∂/∂δb_r
    ḣ(x) = u·(v^s − v_a) + ḃ_r + …

(``u`` the line of sight from the antenna to the satellite, ``C_n^e`` ENU to ECEF).

**Roads** (:mod:`selfnav.roads.aid`): the distance across the road's centre line (and along it
at a corner), the road heading, a level road (``v_U = 0``).
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numba
import numpy as np

from selfnav import attitude as att
from selfnav.attitude import rotvec_to_dcm3, skew3
from selfnav.correlation import ar1_variance_factor, lag_one_correlation
from selfnav.earth import OMEGA_EARTH, enu_offset, enu_rotation, geodetic_to_ecef
from selfnav.gnss.models import doppler_model, pseudorange_model
from selfnav.ins.ekf import IBG, IP, IV

#: indices of the position / velocity error states (the first six)
_POS = (0, 1, 2)


@dataclass
class Model:
    """A measurement linearised at a filter's state: residual ``h(x̃) − z``, ``H``, ``R``."""

    kind: str
    r: np.ndarray
    H: np.ndarray
    R: np.ndarray

    def rows(self, idx) -> "Model":
        """The model restricted to some of its rows."""
        idx = list(idx)
        return Model(self.kind, self.r[idx], self.H[idx], self.R[np.ix_(idx, idx)])


class Measurement:
    """Base class: ``kind`` names it in logs; :meth:`model` linearises it at ``flt``."""

    kind = "measurement"

    def model(self, flt) -> Model:  # pragma: no cover - interface
        raise NotImplementedError


@dataclass
class PositionFix(Measurement):
    """A GNSS position (rad, rad, m) at true time ``t``; σ horizontal per axis and vertical, m."""

    t: float
    lat: float
    lon: float
    h: float
    sigma_h: float
    sigma_v: float
    kind = "position"

    def model(self, flt) -> Model:
        ins, lay = flt.ins, flt.layout
        C_bn = ins.C_nb.T
        l_n = C_bn @ flt.lever_b
        z = enu_offset(ins.lat, ins.lon, ins.h, self.lat, self.lon, self.h)
        v = ins.velocity_n
        lead = flt.t_true - self.t
        # the state moved back by the lead over the recent accelerations (a fix that arrives
        # late, up to a receiver's latency after the IMU has passed it)
        back = flt.back(lead)[0] if lead > 0.0 else v * lead
        r = l_n - back - z
        H = np.zeros((3, flt.nx))
        H[0, 0] = H[1, 1] = H[2, 2] = 1.0
        H[:, IP] = skew3(l_n)
        if lay.lever is not None:
            H[:, lay.lever] = C_bn
        if lay.toff is not None:
            H[:, lay.toff.start] = -v
        R = np.diag([self.sigma_h**2, self.sigma_h**2, self.sigma_v**2])
        return Model(self.kind, r, H, R)

    def offset_from(self, flt) -> np.ndarray:
        """ENU metres of the fix from the filter's predicted antenna position."""
        return -self.model(flt).r


@dataclass
class VelocityFix(Measurement):
    """A GNSS velocity (ENU, m/s; NaN vertical: horizontal only) at true time ``t``; σ per
    horizontal axis and vertical, m/s."""

    t: float
    velocity_n: np.ndarray
    sigma: float
    sigma_up: float
    kind = "velocity"

    def model(self, flt) -> Model:
        ins, lay = flt.ins, flt.layout
        C_bn = ins.C_nb.T
        v_lever = C_bn @ np.cross(flt.omega_b, flt.lever_b)
        a_n = flt.acceleration_n
        delay = (flt.t_true - self.t) + flt.velocity_lag
        vz = np.asarray(self.velocity_n, float)
        rows = [0, 1, 2] if np.isfinite(vz[2]) else [0, 1]
        back = flt.back(delay)[1] if delay > 0.0 else a_n * delay
        r = ins.velocity_n + v_lever - back - np.where(np.isfinite(vz), vz, 0.0)
        H = np.zeros((3, flt.nx))
        H[0, 3] = H[1, 4] = H[2, 5] = 1.0
        H[:, IP] = skew3(v_lever)
        if lay.lever is not None:
            H[:, lay.lever] = C_bn @ skew3(flt.omega_b)
        if lay.toff is not None:
            H[:, lay.toff.start] = -a_n
        if lay.vlag is not None:
            H[:, lay.vlag.start] = -a_n
        R = np.diag([self.sigma**2, self.sigma**2, self.sigma_up**2])
        return Model(self.kind, r, H, R).rows(rows)


@numba.njit(cache=True)
def _nhc_rows(s, w_b, lever, mu, mu_col, nx):  # pragma: no cover - compiled
    """Residual and Jacobian of the non-holonomic constraint (:class:`NonHolonomic`) at
    strapdown state ``s``; ``mu_col`` the first column of the mounting block or -1."""
    C_nb = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C_nb[i, j] = s[6 + 3 * j + i]          # transpose of C_bn
    v = s[3:6]
    vv = C_nb @ v
    vv[0] += w_b[1] * lever[2] - w_b[2] * lever[1]
    vv[1] += w_b[2] * lever[0] - w_b[0] * lever[2]
    vv[2] += w_b[0] * lever[1] - w_b[1] * lever[0]
    C_vn = C_nb
    if mu_col >= 0 or mu[0] != 0.0 or mu[1] != 0.0:
        x, z = mu[0], mu[1]
        th2 = x * x + z * z
        if th2 < 1e-12:
            a1, b1 = 1.0, 0.5
        else:
            th = np.sqrt(th2)
            a1, b1 = np.sin(th) / th, (1.0 - np.cos(th)) / th2
        K = np.array([[0.0, -z, 0.0], [z, 0.0, -x], [0.0, x, 0.0]])
        C_vb = np.eye(3) + a1 * K + b1 * (K @ K)
        C_vn = C_vb @ C_nb
        vv = C_vb @ vv
    H = np.zeros((2, nx))
    r = np.empty(2)
    Sv = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    for a, row in enumerate((0, 2)):
        r[a] = vv[row]
        for j in range(3):
            H[a, 3 + j] = C_vn[row, j]
        hp = -(C_vn[row] @ Sv)
        for j in range(3):
            H[a, 6 + j] = hp[j]
    if mu_col >= 0:
        # -[v_v×] restricted to rows (x, z) and columns (x, z)
        H[0, mu_col] = 0.0
        H[0, mu_col + 1] = -vv[1]
        H[1, mu_col] = vv[1]
        H[1, mu_col + 1] = 0.0
    return r, H


def vehicle_velocity(flt):
    """Velocity at the NHC point (rear axle) in the vehicle frame and ``C_vn``:
    ``(v_v, C_vn)`` (module docstring)."""
    C_nb = flt.ins.C_nb
    vv = C_nb @ flt.ins.velocity_n
    C_vn = C_nb
    lever = flt.nhc_lever_b
    if lever[0] or lever[1] or lever[2]:
        vv = vv + np.cross(flt.omega_b, lever)
    if flt.layout.mu is not None or flt.mu[0] or flt.mu[1]:
        C_vb = rotvec_to_dcm3(np.array([flt.mu[0], 0.0, flt.mu[1]]))
        C_vn = C_vb @ C_nb
        vv = C_vb @ vv
    return vv, C_vn


@dataclass
class NonHolonomic(Measurement):
    """A wheeled vehicle does not slide sideways nor leave the ground: the lateral and
    vertical velocity at the NHC point are zero with σ ``sigma`` and ``sigma_up`` m/s."""

    sigma: float
    sigma_up: float
    kind = "nhc"

    def model(self, flt) -> Model:
        mu_col = -1 if flt.layout.mu is None else flt.layout.mu.start
        r, H = _nhc_rows(flt.ins.state_array(), flt.omega_b, flt.nhc_lever_b, flt.mu, mu_col,
                         flt.nx)
        R = np.zeros((2, 2))
        R[0, 0], R[1, 1] = self.sigma**2, self.sigma_up**2
        return Model(self.kind, r, H, R)


class NhcCheck:
    """Does the platform move along its nose, and how sure may its sideways constraint be?
    The non-holonomic constraint's lateral innovations of ``M`` while the fixes hold the
    velocity (status GNSS), over the last ``window`` updates (30 s), looked at every ``step``
    updates (5 s) once ``min_updates`` are in:

    * their RMS against the constraint's prior σ: a car that keeps the constraint leaves a
      small part of it — even while a GNSS drag pulls its velocity (the heading takes the
      pull) — and a hull that yaws about its course most of it, correlated over the wave.
      Measured over 30 s windows: simulated cars at most 0.18 σ, two drags from power-on and
      after a start 0.24 σ, the simulated ship (±5° about its course at 6 m/s) 0.60–0.86 σ —
      but campaign cars following a drift or drag window 0.40–0.90 σ: the size alone does not
      tell a sway from a followed fault (the navigator widens only without a road map). The
      constraint's own error is what the innovations hold beyond the state's uncertainty,
      ``e² = mean(r²) − mean(H P Hᵀ)`` (innovation-based adaptive estimation of R, Mehra
      1970): a start whose heading still converges has large innovations its σ explains (a
      simulated industrial car 0.22 m/s at √HPHᵀ 0.20). The σ the constraint may use is
      ``σ · clip(e / (slip_ratio σ), 1, widen)`` (:attr:`scale`): unchanged below
      ``slip_ratio`` (0.4) of it, up to ``widen`` × (the boat profile's 1 m/s for the car's
      0.5: twice a ship's sway), the factor ``1/slip_ratio`` standing for the error's
      correlation over the updates. The first widening makes :meth:`add` return True (the
      navigator says so, :attr:`seen`);
    * their AR(1) variance-of-the-mean equivalent ``σ_eff² = mean(r²)(1 + ρ)/(1 − ρ)`` (ρ the
      lag-one correlation about zero, at most ``rho_max``): the σ a correlated error would
      need, reported (:attr:`largest`; drive_0708 0.31 m/s, the ship 4–7 m/s). It is not the
      test: a drag's small innovations are correlated too (σ_eff up to 11 m/s on a drag from
      power-on; loosening on it lost that drive to its drag, docs/platforms.md) — their size
      is what tells them from a sway."""

    def __init__(self, window: int = 150, step: int = 25, min_updates: int = 25,
                 slip_ratio: float = 0.4, widen: float = 2.0, rho_max: float = 0.99):
        self.window, self.step, self.min_updates = int(window), int(step), int(min_updates)
        self.slip_ratio, self.widen, self.rho_max = float(slip_ratio), float(widen), float(rho_max)
        self._r = collections.deque(maxlen=self.window)
        self._n = 0                     # updates since the last look
        self.scale = np.ones(2)         # the constraint's σ over its prior (lateral, vertical)
        self.seen = None                # (t, RMS, σ_eff, vertical RMS) when first widened
        self.largest = 0.0              # largest σ_eff, m/s
        self.largest_rms = 0.0          # largest RMS of a window, m/s
        self.largest_scale = np.ones(2)

    def add(self, t: float, r: np.ndarray, sigma: np.ndarray, hph=(0.0, 0.0)) -> bool:
        """One innovation ``r`` (lateral, vertical; m/s) of the constraint whose prior σ are
        ``sigma`` (lateral, vertical), ``hph`` the part of its variance the state's own
        uncertainty explains (``diag(H P Hᵀ)``); True when it is first widened."""
        self._r.append(np.concatenate([np.asarray(r, float)[:2], np.asarray(hph, float)[:2]]))
        self._n += 1
        if len(self._r) < self.min_updates or self._n < self.step:
            return False
        self._n = 0
        a = np.asarray(self._r)
        x = a[:, :2]
        rms = np.sqrt(np.mean(x * x, axis=0))
        eff = rms[0] * math.sqrt(ar1_variance_factor(lag_one_correlation(x[:, 0],
                                                                          self.rho_max)))
        self.largest, self.largest_rms = max(self.largest, eff), max(self.largest_rms, rms[0])
        # the constraint's own error: what the innovations hold beyond the state's uncertainty
        # (a start's heading still converging shows as large innovations, and is explained)
        own = np.sqrt(np.maximum(rms**2 - np.mean(a[:, 2:], axis=0), 0.0))
        self.scale = np.clip(own / (self.slip_ratio * np.asarray(sigma, float)), 1.0,
                             self.widen)
        self.largest_scale = np.maximum(self.largest_scale, self.scale)
        if self.scale.max() > 1.0 and self.seen is None:
            self.seen = (float(t), float(rms[0]), eff, float(rms[1]))
            return True
        return False


@dataclass
class ZeroVelocity(Measurement):
    """The IMU is still: zero velocity with σ ``sigma`` m/s per axis."""

    sigma: float
    kind = "zupt"

    def model(self, flt) -> Model:
        H = np.zeros((3, flt.nx))
        H[0, 3] = H[1, 4] = H[2, 5] = 1.0
        return Model(self.kind, flt.ins.velocity_n, H, np.eye(3) * self.sigma**2)


@dataclass
class ZeroRate(Measurement):
    """The IMU is still: it turns with the Earth only. A zero angular-rate update (ZARU) on
    the gyro biases from one block of bias-corrected rates ``w_blk`` (N, 3), rad/s::

        h(x) = C_nb ω_ie^n + δb_g,   z = mean(w_blk),   ∂h/∂δb_g = I

    σ per axis: the block's own sample scatter (engine vibration, quantisation: the samples
    taken as fully correlated, a bound) and at least ``sigma`` rad/s — and, given the block's
    length ``span_s``, at least the gyro white noise's over it, ``arw / √span_s``: a block of
    one or two samples has no scatter to speak of (a fault-bank reference brought to a fix's
    time between two of its steps took one sample's rate at σ 0.01 °/s, and the correlation
    of its heading with the yaw bias turned it by 3.7° at a stop: simulated campaign drive
    8456975962355837506, 100 m off at σ 20 m for five minutes)."""

    w_blk: np.ndarray
    sigma: float
    span_s: float | None = None
    kind = "zaru"

    def model(self, flt) -> Model:
        lat = flt.ins.lat
        omega_ie_n = OMEGA_EARTH * np.array([0.0, np.cos(lat), np.sin(lat)])
        w = np.asarray(self.w_blk, float)
        r = flt.ins.C_nb @ omega_ie_n - w.mean(0)
        H = np.zeros((3, flt.nx))
        H[:, IBG] = np.eye(3)
        s = np.maximum(w.std(0), self.sigma)
        if self.span_s:
            s = np.maximum(s, flt.cfg.imu.arw / np.sqrt(self.span_s))
        return Model(self.kind, r, H, np.diag(s**2))


def _forward_speed_rows(flt, gain: float):
    """``(v_v, C_vn, H)``: the vehicle-frame velocity at the NHC point and the Jacobian row of
    ``gain · v_v,F`` in velocity, attitude and (where estimated) mounting — the part
    :class:`WheelSpeed` and :class:`ForwardSpeed` share."""
    vv, C_vn = vehicle_velocity(flt)
    H = np.zeros((1, flt.nx))
    H[0, IV] = gain * C_vn[1]
    H[0, IP] = -gain * C_vn[1] @ skew3(flt.ins.velocity_n)
    if flt.layout.mu is not None:
        H[0, flt.layout.mu] = -gain * skew3(vv)[1, [0, 2]]
    return vv, C_vn, H


@dataclass
class WheelSpeed(Measurement):
    """Wheel speed, m/s, at the NHC point in the vehicle frame, scaled by ``1 + k``, sampled at
    ``stamp`` on the IMU's clock (the INS's own time base, ``ins.t``; None: now)::

        h = (1 + k̂) (v_v,F + (C_vn a^n)[F] (stamp − t_ins)),
        ∂h/∂δv = (1 + k̂) C_vn[F],   ∂h/∂ψ = −(1 + k̂) C_vn[F] [v^n×],
        ∂h/∂δk = v_v,F,      ∂h/∂δμ = −(1 + k̂) [v_v×][F] (pitch, yaw),   ∂h/∂δε = 0

    The IMU and the wheel speed share one clock, so the IMU time offset ε (against the fixes'
    true time) shifts both alike and does not enter: a term ``−(C_vn a)[F] δε``, as for a fix,
    had the odometer witness an offset it cannot see — on a simulated drive with both clocks
    0.25 s off the fixes' the offset was learnt as 0.07 s at a σ of 2 ms (issue 19, stop 64).
    """

    speed: float
    sigma: float
    stamp: float | None = None
    kind = "odometer"

    def model(self, flt) -> Model:
        g = 1.0 + flt.odo_scale
        vv, C_vn, H = _forward_speed_rows(flt, g)
        lay = flt.layout
        if lay.odo is not None:
            H[0, lay.odo.start] = vv[1]
        v_f = vv[1]
        if self.stamp is not None:      # the INS is within an IMU sample of the stamp
            v_f += float(C_vn[1] @ flt.acceleration_n) * (self.stamp - flt.ins.t)
        return Model(self.kind, np.array([g * v_f - float(self.speed)]), H,
                     np.array([[self.sigma**2]]))


@dataclass
class ForwardSpeed(Measurement):
    """A prior on the speed along the vehicle's nose at the NHC point, m/s (a walker's or a
    rover's pace held through a GNSS outage): :class:`WheelSpeed`'s model without its scale
    factor or time stamp — a statement about now, not a sensor's sample::

        h = v_v,F,   ∂h/∂δv = C_vn[F],   ∂h/∂ψ = −C_vn[F] [v^n×],   ∂h/∂δμ = −[v_v×][F]
    """

    speed: float
    sigma: float
    kind = "speed prior"

    def model(self, flt) -> Model:
        vv, _, H = _forward_speed_rows(flt, 1.0)
        return Model(self.kind, np.array([vv[1] - float(self.speed)]), H,
                     np.array([[self.sigma**2]]))


def _heading_error(flt, heading):
    _, _, hdg = att.euler_from_dcm_nb(flt.ins.C_nb)
    return float(np.angle(np.exp(1j * (hdg - heading))))


@dataclass
class Heading(Measurement):
    """True heading (rad, clockwise from North), e.g. magnetic heading plus declination (seed
    004 (12)), σ rad. ``ψ_U`` raises the computed heading (``C̃ = (I − [ψ]) C``)."""

    heading: float
    sigma: float
    kind = "heading"

    def model(self, flt) -> Model:
        H = np.zeros((1, flt.nx))
        H[0, 8] = 1.0
        return Model(self.kind, np.array([_heading_error(flt, self.heading)]), H,
                     np.array([[self.sigma**2]]))


@dataclass
class RoadLine(Measurement):
    """The vehicle is on a road's centre line (and heads along it).

    ``normal_n``: unit horizontal normal of the road at the foot point (ENU); ``offset``: signed
    distance of the INS position from the line along it, m, σ ``sigma``; optionally the road
    direction ``heading`` (rad) with σ ``sigma_heading``, and a position along the road
    (a corner the map places: unit direction ``along_n``, offset ``along_offset``, σ
    ``sigma_along``).
    """

    normal_n: np.ndarray
    offset: float
    sigma: float
    heading: float | None = None
    sigma_heading: float | None = None
    along_n: np.ndarray | None = None
    along_offset: float | None = None
    sigma_along: float | None = None
    kind = "road"

    def model(self, flt) -> Model:
        rows, res, var = [], [], []
        h = np.zeros(flt.nx)
        h[0:2] = self.normal_n
        rows.append(h)
        res.append(self.offset)
        var.append(self.sigma**2)
        if self.along_n is not None:
            h1 = np.zeros(flt.nx)
            h1[0:2] = self.along_n
            rows.append(h1)
            res.append(self.along_offset)
            var.append(self.sigma_along**2)
        if self.heading is not None:
            h2 = np.zeros(flt.nx)
            h2[8] = 1.0
            rows.append(h2)
            res.append(_heading_error(flt, self.heading))
            var.append(self.sigma_heading**2)
        return Model(self.kind, np.array(res, float), np.array(rows), np.diag(var))


@dataclass
class RunVelocity(Measurement):
    """The horizontal velocity a run of fixes shows (ENU m/s, covariance 2×2): the rate of
    their offsets from a dead reckoning (:mod:`selfnav.ins.hypotheses`)."""

    velocity_n: np.ndarray
    cov: np.ndarray
    kind = "run velocity"

    def model(self, flt) -> Model:
        H = np.zeros((2, flt.nx))
        H[0, 3] = H[1, 4] = 1.0
        r = flt.ins.velocity_n[:2] - np.asarray(self.velocity_n, float)
        return Model(self.kind, r, H, np.asarray(self.cov, float))


@dataclass
class LevelRoad(Measurement):
    """A level-road prior: the vertical velocity is zero within ``sigma`` m/s."""

    sigma: float
    kind = "level"

    @classmethod
    def at_speed(cls, grade_sigma: float, speed: float, corr_s: float = 1.0) -> "LevelRoad":
        """The prior of a road whose grade has σ ``grade_sigma`` at horizontal ``speed`` m/s:
        ``grade_sigma·speed + 0.1`` m/s, times ``√corr_s`` when the grade holds over
        ``corr_s`` prior intervals (each then carries ``1/corr_s`` of its information)."""
        return cls((grade_sigma * float(speed) + 0.1) * math.sqrt(corr_s))

    def model(self, flt) -> Model:
        H = np.zeros((1, flt.nx))
        H[0, 5] = 1.0
        return Model(self.kind, np.array([flt.ins.velocity_n[2]]), H,
                     np.array([[self.sigma**2]]))


def _antenna_ecef(flt, t):
    """The antenna at (true) time ``t`` in ECEF, ENU → ECEF rotation and the antenna's ENU
    position model (:class:`PositionFix` at the INS's own point: ``r`` is the antenna's offset
    from it, ``H`` its Jacobian)."""
    ins = flt.ins
    at = PositionFix(t, ins.lat, ins.lon, ins.h, 1.0, 1.0).model(flt)
    C_ne = enu_rotation(ins.lat, ins.lon).T
    return geodetic_to_ecef(ins.lat, ins.lon, ins.h) + C_ne @ at.r, C_ne, at


@dataclass
class Pseudoranges(Measurement):
    """Pseudoranges of one epoch at true time ``t``, m, corrected for the satellite clock and
    group delay and the atmosphere; ``sat_ecef`` (M, 3) the satellites at transmit time,
    ``var`` (M,) m²; ``slot`` (M,) which inter-system clock offset each carries (-1: the
    reference constellation's clock alone)."""

    t: float
    pr: np.ndarray
    sat_ecef: np.ndarray
    var: np.ndarray
    slot: np.ndarray | None = None
    kind = "pseudorange"

    def model(self, flt) -> Model:
        r_a, C_ne, at = _antenna_ecef(flt, self.t)
        clock = np.full(len(self.pr), flt.rx_clock)
        slot = None if self.slot is None else np.asarray(self.slot)
        if slot is not None and np.any(slot >= 0):
            on = slot >= 0
            clock[on] += flt.rx_isb[slot[on]]
        rho, H4 = pseudorange_model(r_a, clock, np.asarray(self.sat_ecef, float))
        H = (H4[:, :3] @ C_ne) @ at.H
        H[:, flt.layout.clk.start] = 1.0
        if slot is not None and np.any(slot >= 0):
            rows = np.flatnonzero(slot >= 0)
            H[rows, flt.layout.isb.start + slot[rows]] = 1.0
        return Model(self.kind, rho - np.asarray(self.pr, float), H,
                     np.diag(np.asarray(self.var, float)))


@dataclass
class RangeRates(Measurement):
    """Range rates ``−λ D`` of one epoch at true time ``t``, m/s; the satellites' positions,
    velocities and clock drifts (m/s) at transmit time; ``var`` (M,) (m/s)²."""

    t: float
    rate: np.ndarray
    sat_ecef: np.ndarray
    sat_vel: np.ndarray
    sat_drift: np.ndarray
    var: np.ndarray
    kind = "range rate"

    def model(self, flt) -> Model:
        r_a, C_ne, _ = _antenna_ecef(flt, self.t)
        vel = VelocityFix(self.t, np.zeros(3), 1.0, 1.0).model(flt)
        rate, H7 = doppler_model(r_a, C_ne @ vel.r, flt.rx_drift, np.asarray(self.sat_ecef, float),
                                 np.asarray(self.sat_vel, float),
                                 np.asarray(self.sat_drift, float))
        H = (H7[:, 3:6] @ C_ne) @ vel.H
        H[:, flt.layout.clk.start + 1] = 1.0
        return Model(self.kind, rate - np.asarray(self.rate, float), H,
                     np.diag(np.asarray(self.var, float)))


@dataclass
class AlongTrackWiden:
    """Not a measurement: process noise along the track, (m/s)²/s × ``dt`` (the road aid's
    along-track speed variance while the map judges GNSS unhealthy)."""

    q_along: float
    dt: float

    def apply(self, flt, heading):
        u = np.array([np.sin(heading), np.cos(heading)])
        flt.P[3:5, 3:5] += np.outer(u, u) * (self.q_along * self.dt)


__all__ = ["Model", "Measurement", "PositionFix", "VelocityFix", "NonHolonomic",
           "ZeroVelocity", "ZeroRate", "WheelSpeed", "ForwardSpeed", "Heading", "RoadLine", "LevelRoad", "RunVelocity",
           "Pseudoranges", "RangeRates", "vehicle_velocity", "_POS"]
