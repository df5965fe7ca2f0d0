"""The data every stage passes on (DESIGN §6, §9): IMU samples, GNSS fixes, attitude, trajectories.

Plain containers at the bottom of the package: SI units and radians, frames in the names
(ENU navigation frame, RFU body frame, ``C_nb`` = nav ENU → body RFU). Readers in
:mod:`selfnav.io` build them from files; simulators build them from scenarios; every
algorithm takes them. Nothing here imports another selfnav module.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np


def _take(x, mask):
    return None if x is None else x[mask]


@dataclass
class ImuData:
    """IMU samples in the body RFU frame, SI units.

    Attributes
    ----------
    t : (N,) float64
        Time, s, strictly increasing: the *end* of each sample interval.
    omega_ib_b : (N, 3)
        Angular rate, rad/s: the mean over the interval ending at ``t`` (an increment divided
        by the interval) — the package's one convention for IMU rows.
    f_ib_b : (N, 3)
        Specific force, m/s², mean over the same interval.
    mag_b : (N, 3) or None
        Magnetometer, any unit.
    position : (N,) int or None
        Position index for multi-position records.
    source : str
        Where the data came from (file name, ``"simulated ..."``).
    meta : dict
        Format-specific header values (e.g. PSINS site and nominal g, a time offset applied).
    """

    t: np.ndarray
    omega_ib_b: np.ndarray
    f_ib_b: np.ndarray
    mag_b: np.ndarray | None = None
    position: np.ndarray | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    @cached_property
    def dt(self) -> float:
        """Median sample interval, s (computed once)."""
        return float(np.median(np.diff(self.t))) if len(self.t) > 1 else float("nan")

    @property
    def duration(self) -> float:
        """Covered time span, s (N samples of interval dt)."""
        return float(self.t[-1] - self.t[0] + self.dt) if len(self.t) > 1 else 0.0

    def select(self, mask) -> "ImuData":
        """A subset of the samples (index array, slice or boolean mask)."""
        return ImuData(self.t[mask], self.omega_ib_b[mask], self.f_ib_b[mask],
                       _take(self.mag_b, mask), _take(self.position, mask), self.source,
                       dict(self.meta))

    def shifted(self, dt_s: float) -> "ImuData":
        """The same samples with ``dt_s`` added to every time stamp."""
        return replace(self, t=self.t + dt_s, meta=dict(self.meta))


@dataclass
class GnssData:
    """GNSS fixes in WGS-84.

    Attributes
    ----------
    t : (N,) s
    lat, lon : (N,) rad
    h : (N,) m, ellipsoidal
    sigma_m : (N,) horizontal σ per axis, m (NaN: not given), or None
    velocity_n : (N, 3) ENU m/s, or None
    quality : (N,) int or None (RTKLIB Q: 1 fix, 2 float, 5 single, ...)
    source : str
    sigma_v_m : (N,) vertical σ, m, or None (then 1.5 × the horizontal one)
    sigma_vel_mps : (N,) velocity σ per horizontal axis, m/s, or None (not given)
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    sigma_m: np.ndarray | None = None
    velocity_n: np.ndarray | None = None
    quality: np.ndarray | None = None
    source: str = ""
    sigma_v_m: np.ndarray | None = None
    sigma_vel_mps: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def from_arrays(cls, t, lat, lon, h, sigma_m=None, velocity_n=None, *, source="",
                    quality=None, sigma_v_m=None, sigma_vel_mps=None) -> "GnssData":
        """Fixes from array-likes (radians); a scalar ``sigma_m`` applies to every fix."""
        t = np.asarray(t, dtype=float)
        sig = None if sigma_m is None else np.broadcast_to(
            np.asarray(sigma_m, dtype=float), t.shape).copy()
        return cls(t, np.asarray(lat, dtype=float), np.asarray(lon, dtype=float),
                   np.asarray(h, dtype=float), sig,
                   None if velocity_n is None else np.asarray(velocity_n, dtype=float),
                   None if quality is None else np.asarray(quality), source,
                   None if sigma_v_m is None else np.asarray(sigma_v_m, dtype=float),
                   None if sigma_vel_mps is None else np.asarray(sigma_vel_mps, dtype=float))

    def select(self, mask) -> "GnssData":
        """A subset of the fixes (index array, slice or boolean mask)."""
        return GnssData(self.t[mask], self.lat[mask], self.lon[mask], self.h[mask],
                        _take(self.sigma_m, mask), _take(self.velocity_n, mask),
                        _take(self.quality, mask), self.source, _take(self.sigma_v_m, mask),
                        _take(self.sigma_vel_mps, mask))

    def copy(self) -> "GnssData":
        return self.select(np.ones(len(self.t), bool))


@dataclass
class Trajectory:
    """Position, velocity and attitude against time (the truth and solution files, DESIGN §6).

    Attributes
    ----------
    t : (N,) s
    lat, lon : (N,) rad (WGS-84 geodetic)
    h : (N,) m
    velocity_n : (N, 3) m/s, ENU (NaN where unknown)
    C_nb : (N, 3, 3) nav ENU -> body RFU (NaN where unknown)
    source : str
        ``"simulated ..."`` for simulated data.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    velocity_n: np.ndarray
    C_nb: np.ndarray
    source: str = "simulated"

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask) -> "Trajectory":
        """A subset of the epochs."""
        return Trajectory(self.t[mask], self.lat[mask], self.lon[mask], self.h[mask],
                          self.velocity_n[mask], self.C_nb[mask], self.source)


@dataclass
class AttitudeData:
    """Attitude samples: ``t`` (N,) s and ``C_nb`` (N, 3, 3) nav ENU → body RFU."""

    t: np.ndarray
    C_nb: np.ndarray
    source: str = ""
    lines: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class OdometerData:
    """Wheel speed (odometer): ``t`` (N,) s on the IMU's clock and ``speed_mps`` (N,) the
    vehicle's forward speed at that instant (rear axle), m/s, as the sensor reports it (its
    scale-factor error included); ``meta`` what the source says about it (a simulator: the
    true ``scale_factor``)."""

    t: np.ndarray
    speed_mps: np.ndarray
    source: str = ""
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask) -> "OdometerData":
        """A subset of the samples (index array, slice or boolean mask)."""
        return OdometerData(self.t[mask], self.speed_mps[mask], self.source, dict(self.meta))

    def shifted(self, dt_s: float) -> "OdometerData":
        """The same samples with ``dt_s`` added to every time stamp."""
        return replace(self, t=self.t + dt_s, meta=dict(self.meta))


@dataclass
class BaroData:
    """Barometer samples: ``t`` (N,) s, ``altitude_m`` (N,) barometric altitude (the sensor's
    own conversion, above its reference pressure, not ellipsoidal), ``pressure_pa`` and
    ``temperature_c`` where known."""

    t: np.ndarray
    altitude_m: np.ndarray
    pressure_pa: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    source: str = ""

    def __len__(self) -> int:
        return len(self.t)
