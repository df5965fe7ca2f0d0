"""IMU axes and mounting as data (issue 20): one notation for every reader, and their detection.

**Axes.** What each sensor axis points to on the vehicle, in the letters ``R L F B U D``
(right, left, forward, backward, up, down; ``E W N S`` are read as ``R L F B`` so that the
common "NED body" means ``FRD``). Two spellings:

* three letters, the directions of the sensor's x, y and z: ``RFU`` (selfnav's own body frame,
  DESIGN §2), ``FRD`` (PX4, KF-GINS, aerospace), ``FLU`` (ROS), ``BRU`` (the rtklibexplorer
  logger);
* assignments ``x=-F,y=R,z=U`` (a sign in front of a letter reverses it: ``-F`` is ``B``).

:func:`parse_axes` returns the signed permutation ``P`` with ``v_RFU = P v_sensor``; a spec
naming an axis twice, two opposite directions, an unknown letter or a left-handed triad is one
:class:`AxesError` line.

**Mounting.** ``roll, pitch, yaw`` (deg at the edges, rad inside) of the IMU relative to the
vehicle, in the conventions of DESIGN §2 with the vehicle's RFU frame in the place of ENU:
``C_v^imu = R_y(roll) R_x(pitch) R_z(−yaw)`` (frame rotations), so yaw is clockwise seen from
above, pitch nose-up, roll right side down, and ``v_vehicle = C_imu^v v_imu`` with
``C_imu^v = exp([ψ e_z]) exp([θ e_x]) exp([γ e_y])``, ψ = −yaw (scipy:
``Rotation.from_euler('ZXY', [ψ, θ, γ])``, checked in the tests).

A reading therefore goes ``v_vehicle = C_imu^v P v_sensor`` (:func:`to_vehicle`), and the
writer side is its inverse (:func:`from_vehicle`). Named presets (:data:`PRESETS`) carry axes
and a mounting together: a reader never carries one data set's installation in its code.

**Detection** (pure functions of whatever window of samples they are given, so that a causal
navigator can call them on its first seconds): :func:`detect_up_axis` from gravity, and
:func:`detect_forward_axis` from the horizontal specific force against the acceleration of the
GNSS velocity on a vehicle, with a fine yaw mounting angle and its σ. Both return what they
found with a confidence; :func:`frame_from_detection` makes an :class:`ImuFrame` of it, and
:func:`compare_frames` says in one line where a given frame disagrees with a detected one.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from selfnav import attitude as att
from selfnav.earth import radii
from selfnav.errors import SelfnavError
from selfnav.types import GnssData, ImuData

#: Direction of each letter in the vehicle's RFU frame: (axis index, sign).
_LETTER = {"R": (0, 1), "L": (0, -1), "F": (1, 1), "B": (1, -1), "U": (2, 1), "D": (2, -1)}
#: Geographic letters read as body letters ("NED body" = FRD, "ENU body" = RFU).
_ALIAS = {"E": "R", "W": "L", "N": "F", "S": "B"}
_OPPOSITE = {"R": "L", "L": "R", "F": "B", "B": "F", "U": "D", "D": "U"}
#: Canonical letter of each (index, sign).
_NAME = {v: k for k, v in _LETTER.items()}

#: What the spellings ``detect`` and ``auto`` mean to a reader: no conversion, the navigator
#: detects the axes (:func:`detect_up_axis`, :func:`detect_forward_axis`).
DETECT = "detect"


class AxesError(SelfnavError):
    """An IMU axes or mounting spec that no IMU can have (one line, exit 2)."""


# --------------------------------------------------------------------------- axes
@dataclass(frozen=True)
class Axes:
    """A sensor axes convention: ``letters`` (the canonical three-letter name) and
    ``matrix`` (3×3 signed permutation, ``v_RFU = matrix @ v_sensor``)."""

    letters: str

    @property
    def matrix(self) -> np.ndarray:
        P = np.zeros((3, 3))
        for j, ch in enumerate(self.letters):
            i, s = _LETTER[ch]
            P[i, j] = float(s)
        return P

    @property
    def is_rfu(self) -> bool:
        return self.letters == "RFU"

    def assignments(self) -> str:
        """The same axes as ``x=R,y=F,z=U``."""
        return ",".join(f"{a}={c}" for a, c in zip("xyz", self.letters))

    def __str__(self) -> str:
        return self.letters


RFU = Axes("RFU")


def _letter(token: str, spec: str) -> str:
    """One signed letter (``F``, ``-F``, ``+n``) as a canonical body letter."""
    t = token.strip().upper()
    sign = 1
    while t[:1] in "+-" and t:
        sign = -sign if t[0] == "-" else sign
        t = t[1:].strip()
    if len(t) != 1 or (t not in _LETTER and t not in _ALIAS):
        raise AxesError(f"IMU axes '{spec}': '{token.strip()}' is not a direction (use R L F B "
                        "U D for right, left, forward, back, up, down; E W N S also work)")
    ch = _ALIAS.get(t, t)
    return ch if sign > 0 else _OPPOSITE[ch]


def parse_axes(spec) -> Axes:
    """Parse an axes spec (three letters or ``x=…,y=…,z=…``) into :class:`Axes`.

    Parameters
    ----------
    spec : str or Axes
        ``"FRD"``, ``"rfu"``, ``"NED"`` (read as FRD), ``"x=-F,y=R,z=U"``, ``"x=B, y=R, z=U"``.

    Raises
    ------
    AxesError
        One line: an unknown letter, a missing or repeated axis, two directions along the same
        line (``F`` and ``B``), a left-handed triad (with the right-handed spec it resembles).
    """
    if isinstance(spec, Axes):
        return spec
    text = str(spec).strip()
    if not text:
        raise AxesError("IMU axes: empty spec (give three letters such as FRD, or x=F,y=R,z=D)")
    if "=" in text:
        got = {}
        for part in re.split(r"[,;\s]+", text):
            if not part:
                continue
            name, eq, val = part.partition("=")
            name = name.strip().lower()
            if not eq or name not in ("x", "y", "z") or not val.strip():
                raise AxesError(f"IMU axes '{text}': '{part}' is not an assignment like x=F")
            if name in got:
                raise AxesError(f"IMU axes '{text}': {name} is given twice")
            got[name] = _letter(val, text)
        missing = [a for a in "xyz" if a not in got]
        if missing:
            hint = ""
            if len(missing) == 1:
                known = {a: got[a] for a in got}
                third = _complete(known, missing[0])
                if third is not None:
                    full = ",".join(f"{a}={(known | {missing[0]: third})[a]}" for a in "xyz")
                    hint = f" (the right-hand rule makes it {missing[0]}={third}: write {full})"
            raise AxesError(f"IMU axes '{text}': {', '.join(missing)} not given{hint}")
        letters = "".join(got[a] for a in "xyz")
    else:
        compact = re.sub(r"[\s,]+", "", text)
        tokens = re.findall(r"[+-]*[A-Za-z]", compact)
        if "".join(tokens) != compact or len(tokens) != 3:
            raise AxesError(f"IMU axes '{text}': give three directions, one per sensor axis x, y, "
                            "z (such as FRD, RFU, FLU) or assignments such as x=-F,y=R,z=U")
        letters = "".join(_letter(tk, text) for tk in tokens)
    for a, b in ((0, 1), (0, 2), (1, 2)):
        if letters[a] == letters[b]:
            raise AxesError(f"IMU axes '{text}': {'xyz'[a]} and {'xyz'[b]} both point {letters[a]}")
        if _LETTER[letters[a]][0] == _LETTER[letters[b]][0]:
            raise AxesError(f"IMU axes '{text}': {'xyz'[a]}={letters[a]} and "
                            f"{'xyz'[b]}={letters[b]} lie along the same line (one of them must "
                            "be another direction)")
    ax = Axes(letters)
    if np.linalg.det(ax.matrix) < 0:
        fixed = letters[:2] + _OPPOSITE[letters[2]]
        raise AxesError(f"IMU axes '{text}' is left-handed (x × y = −z), which no IMU is: did you "
                        f"mean {fixed}?")
    return ax


def _complete(known: dict, missing: str):
    """The letter that makes a right-handed triad of two given axes (None if they clash)."""
    vec = {}
    for a, ch in known.items():
        i, s = _LETTER[ch]
        v = np.zeros(3)
        v[i] = s
        vec[a] = v
    if len(vec) != 2:
        return None
    order = {"x": ("y", "z"), "y": ("z", "x"), "z": ("x", "y")}[missing]
    c = np.cross(vec[order[0]], vec[order[1]])
    if np.count_nonzero(c) != 1:
        return None
    i = int(np.flatnonzero(c)[0])
    return _NAME[(i, int(np.sign(c[i])))]


def axes_from_matrix(P) -> Axes:
    """The :class:`Axes` of a signed permutation ``P`` (``v_RFU = P v_sensor``)."""
    P = np.asarray(P, dtype=float)
    if P.shape != (3, 3) or not np.allclose(np.abs(P).sum(0), 1) or not np.allclose(
            np.abs(P).sum(1), 1) or not np.all(np.isin(P, (-1.0, 0.0, 1.0))):
        raise AxesError("not a signed permutation matrix")
    letters = "".join(_NAME[(int(np.flatnonzero(P[:, j])[0]),
                             int(P[np.flatnonzero(P[:, j])[0], j]))] for j in range(3))
    return parse_axes(letters)


# --------------------------------------------------------------------------- mounting
def mount_matrix(roll, pitch, yaw) -> np.ndarray:
    """``C_imu^v`` (IMU RFU → vehicle RFU) from the mounting angles, rad (module docstring).

    Built as ``exp([ψ e_z]) exp([θ e_x]) exp([γ e_y])`` with ψ = −yaw (each factor by
    :func:`selfnav.attitude.rotvec_to_dcm`), equal to ``C_b^n`` of
    :func:`selfnav.attitude.dcm_bn_from_euler` with the vehicle in the place of ENU.
    """
    z = att.rotvec_to_dcm(np.array([0.0, 0.0, -float(yaw)]))
    x = att.rotvec_to_dcm(np.array([float(pitch), 0.0, 0.0]))
    y = att.rotvec_to_dcm(np.array([0.0, float(roll), 0.0]))
    return z @ x @ y


def mount_angles(C_imu_v) -> tuple[float, float, float]:
    """``(roll, pitch, yaw)`` rad of a mounting matrix (inverse of :func:`mount_matrix`)."""
    r, p, h = att.euler_from_dcm_bn(np.asarray(C_imu_v, dtype=float))
    return float(r), float(p), float((h + np.pi) % (2 * np.pi) - np.pi)


def parse_mount(text) -> tuple[float, float, float]:
    """``"R,P,Y"`` (degrees) → ``(roll_deg, pitch_deg, yaw_deg)``; one line if it is not three
    finite numbers, or pitch is outside ±90°."""
    if isinstance(text, (tuple, list, np.ndarray)):
        vals = [float(v) for v in text]
    else:
        try:
            vals = [float(v) for v in str(text).replace(";", ",").split(",")]
        except ValueError:
            raise AxesError(f"IMU mount '{text}': give roll,pitch,yaw in degrees, three numbers "
                            "separated by commas (such as 0,-6.79,5.35)") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise AxesError(f"IMU mount '{text}': give roll,pitch,yaw in degrees, three numbers "
                        "separated by commas (such as 0,-6.79,5.35)")
    if abs(vals[1]) > 90.0:
        raise AxesError(f"IMU mount '{text}': pitch {vals[1]:g}° is outside ±90° (a sensor "
                        "mounted upside down or sideways is an axes spec, --imu-axes)")
    return tuple(vals)


# --------------------------------------------------------------------------- frames and presets
@dataclass(frozen=True)
class ImuFrame:
    """Axes plus mounting: how a sensor's columns become the vehicle's RFU frame.

    Attributes
    ----------
    axes : Axes
    mount_deg : (roll, pitch, yaw) degrees of the IMU on the vehicle
    name : preset name, or ``""``
    source : who said so: ``"given"``, ``"preset"``, ``"format"`` (a reader's documented
        default), ``"detected"``
    """

    axes: Axes = RFU
    mount_deg: tuple = (0.0, 0.0, 0.0)
    name: str = ""
    source: str = "format"

    @property
    def has_mount(self) -> bool:
        return any(v != 0.0 for v in self.mount_deg)

    @property
    def is_identity(self) -> bool:
        return self.axes.is_rfu and not self.has_mount

    @property
    def mount(self) -> np.ndarray:
        """``C_imu^v`` (identity when there is no mounting)."""
        r, p, y = np.radians(self.mount_deg)
        return mount_matrix(r, p, y) if self.has_mount else np.eye(3)

    @property
    def matrix(self) -> np.ndarray:
        """``v_vehicle = matrix @ v_sensor`` (mount @ axes)."""
        return self.mount @ self.axes.matrix

    def describe(self) -> str:
        """``"axes FRD, mount 0,-6.79,5.35 deg (preset rtklibexplorer-drive0708)"``."""
        s = f"axes {self.axes.letters}"
        if self.has_mount:
            s += ", mount " + ",".join(f"{v:g}" for v in self.mount_deg) + " deg"
        if self.name:
            s += f" (preset {self.name})"
        return s

    def to_meta(self) -> dict:
        return {"axes": self.axes.letters, "mount_deg": tuple(float(v) for v in self.mount_deg),
                "axes_preset": self.name, "axes_source": self.source}


@dataclass(frozen=True)
class Preset:
    """A named installation: axes, mounting and where the numbers come from."""

    axes: str
    mount_deg: tuple
    description: str


#: Named installations (``--imu-axes NAME``). Each says where its numbers come from.
PRESETS = {
    "rtklibexplorer-drive0708": Preset(
        "BRU", (0.0, -6.79, 5.35),
        "the rtklibexplorer GNSS_IMU car-roof logger of drive_0708: sensor x back, y right, z up; "
        "mounting pitch -6.79 deg, yaw +5.35 deg (upstream drive_config.py imu_misalign "
        "[180,0,180] + [0,-6.79,5.35] roll, pitch, yaw)"),
    "px4": Preset("FRD", (0.0, 0.0, 0.0),
                  "PX4 autopilots (ULog sensor_combined): body front, right, down, board "
                  "rotation already applied by PX4"),
    "kfgins": Preset("FRD", (0.0, 0.0, 0.0), "KF-GINS / i2Nav text IMU files: front, right, down"),
    "ros": Preset("FLU", (0.0, 0.0, 0.0), "ROS REP 103 base_link: x forward, y left, z up"),
}


def imu_frame(axes=None, mount=None, *, default: "ImuFrame | None" = None) -> ImuFrame | str:
    """Resolve what a user gave (``--imu-axes``, ``--imu-mount``) into an :class:`ImuFrame`.

    Parameters
    ----------
    axes : None, str, Axes or ImuFrame
        ``None``: ``default`` (a reader's documented axes; RFU when none); a preset name of
        :data:`PRESETS`; an axes spec (:func:`parse_axes`); ``"detect"`` (returned as the
        string :data:`DETECT`: the reader leaves the sensor's axes, the navigator detects).
    mount : None, str or (3,) degrees
        Overrides the preset's (or default's) mounting.
    """
    base = default or ImuFrame()
    if isinstance(axes, ImuFrame):
        frame = axes
    elif axes is None:
        frame = base
    else:
        key = str(axes).strip()
        low = key.lower()
        if low in (DETECT, "auto"):
            if mount is not None:
                raise AxesError("--imu-mount needs --imu-axes (the axes are detected with "
                                "--imu-axes detect, the mounting with them)")
            return DETECT
        if low in PRESETS:
            p = PRESETS[low]
            frame = ImuFrame(parse_axes(p.axes), tuple(float(v) for v in p.mount_deg), low,
                             "preset")
        else:
            frame = ImuFrame(parse_axes(key), (0.0, 0.0, 0.0), "", "given")
    if mount is not None:
        frame = replace(frame, mount_deg=parse_mount(mount),
                        source="given" if frame.source != "preset" else "preset+mount")
    return frame


def preset_names() -> tuple:
    return tuple(PRESETS)


# --------------------------------------------------------------------------- applying
def _rotate(x, M):
    return None if x is None else np.asarray(x, dtype=float) @ M.T


def to_vehicle(imu: ImuData, frame) -> ImuData:
    """Rates, specific force and magnetometer from the sensor's axes to the vehicle's RFU.

    ``v_vehicle = C_imu^v (P v_sensor)``: the signed permutation first (exact), then the
    mounting rotation when there is one. ``meta`` records the frame (``axes``, ``mount_deg``,
    ``axes_preset``, ``axes_source``). ``frame`` is an :class:`ImuFrame` or what
    :func:`imu_frame` accepts.
    """
    frame = frame if isinstance(frame, ImuFrame) else imu_frame(frame)
    if frame == DETECT:
        raise AxesError("to_vehicle needs axes, not 'detect' (detect them first)")
    P = frame.axes.matrix
    w, f, m = _rotate(imu.omega_ib_b, P), _rotate(imu.f_ib_b, P), _rotate(imu.mag_b, P)
    if frame.has_mount:
        R = frame.mount
        w, f, m = _rotate(w, R), _rotate(f, R), _rotate(m, R)
    meta = dict(imu.meta)
    meta.update(frame.to_meta())
    return replace(imu, omega_ib_b=w, f_ib_b=f, mag_b=m, meta=meta)


def from_vehicle(imu: ImuData, frame) -> ImuData:
    """The inverse of :func:`to_vehicle`: vehicle-RFU samples as a sensor in ``frame`` would
    give them (the writer side: a simulated drive in any axes convention and mounting)."""
    frame = frame if isinstance(frame, ImuFrame) else imu_frame(frame)
    meta = dict(imu.meta)
    meta.update({"written_axes": frame.axes.letters, "written_mount_deg": frame.mount_deg})
    if frame.has_mount:
        w, f, m = (_rotate(x, frame.mount.T) for x in (imu.omega_ib_b, imu.f_ib_b, imu.mag_b))
    else:
        w, f, m = imu.omega_ib_b, imu.f_ib_b, imu.mag_b
    P = frame.axes.matrix
    w, f, m = _rotate(w, P.T), _rotate(f, P.T), _rotate(m, P.T)
    return replace(imu, omega_ib_b=w, f_ib_b=f, mag_b=m, meta=meta)


# --------------------------------------------------------------------------- detection: up
def _phi(x):
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def _block_means(x, n_blocks):
    n = len(x) // n_blocks * n_blocks
    if n_blocks < 2 or n == 0:
        return None
    return x[:n].reshape(n_blocks, -1, x.shape[1]).mean(axis=1)


def _axis_label(index: int, sign: int) -> str:
    return ("+" if sign > 0 else "-") + "xyz"[index]


@dataclass
class UpAxis:
    """The sensor axis that points up, found from gravity (:func:`detect_up_axis`).

    Attributes
    ----------
    axis : str
        ``"+z"``, ``"-x"``, …: the signed sensor axis nearest to the mean specific force.
    index, sign : int
        The same as an index 0..2 and ±1.
    up_s : (3,) unit vector
        Mean specific force direction in sensor axes (the measured up).
    tilt_rad : float
        Angle between ``up_s`` and the chosen axis.
    sigma_rad : float
        1σ of the direction ``up_s`` (scatter of the window, accelerometer bias prior).
    confidence : float
        Probability (Gaussian, from ``sigma_rad``) that the chosen axis is the nearest one to
        the true up; 0 when the mean |f| is not gravity.
    gravity_ratio : float
        ``|mean f| / 9.80665``.
    samples : int
    """

    axis: str
    index: int
    sign: int
    up_s: np.ndarray
    tilt_rad: float
    sigma_rad: float
    confidence: float
    gravity_ratio: float
    samples: int

    def to_dict(self) -> dict:
        return {"axis": self.axis, "tilt_deg": math.degrees(self.tilt_rad),
                "sigma_deg": math.degrees(self.sigma_rad), "confidence": self.confidence,
                "gravity_ratio": self.gravity_ratio, "samples": self.samples}


#: Standard gravity, m/s² (the unit of ``gravity_ratio``).
G0 = 9.80665


def detect_up_axis(f_s, *, accel_bias_sigma: float = 0.2, blocks: int = 10) -> UpAxis:
    """The up axis of a sensor from the specific force of a window of samples.

    The mean specific force of a window points up (``f = −g`` at rest; a vehicle's own
    accelerations average out over seconds). Its direction's σ combines the scatter of
    ``blocks`` consecutive block means (which sees the vehicle's accelerations, correlated
    over seconds) with an accelerometer bias prior ``accel_bias_sigma`` m/s² (the consumer
    grade's 2 mg is 0.02; 0.2 leaves room for cheaper parts). The confidence is the Gaussian
    probability that the true direction lies nearer to the chosen axis than to the next one:
    ``Φ((θ₂ − θ₁) / (2σ))``.

    Parameters
    ----------
    f_s : (N, 3) specific force, m/s², in the sensor's own axes
    accel_bias_sigma : m/s²
    blocks : number of block means for the scatter

    Returns
    -------
    UpAxis
    """
    f = np.asarray(f_s, dtype=float)
    if f.ndim != 2 or f.shape[1] != 3 or len(f) < 2:
        raise SelfnavError("detect_up_axis needs an (N, 3) specific force with N >= 2")
    m = f.mean(axis=0)
    norm = float(np.linalg.norm(m))
    u = m / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    bm = _block_means(f, min(blocks, len(f)))
    if bm is not None:
        scatter = float(np.linalg.norm(bm.std(axis=0, ddof=1))) / math.sqrt(len(bm))
    else:
        scatter = float(np.linalg.norm(f.std(axis=0))) / math.sqrt(len(f))
    sigma = math.hypot(scatter, accel_bias_sigma) / max(norm, 1e-9)
    ang = np.arccos(np.clip(np.abs(u), 0.0, 1.0))    # angle to ±each axis (nearest sign)
    order = np.argsort(ang)
    i = int(order[0])
    s = 1 if u[i] >= 0 else -1
    margin = 0.5 * float(ang[order[1]] - ang[i])
    ratio = norm / G0
    conf = _phi(margin / max(sigma, 1e-12)) if 0.5 < ratio < 1.5 else 0.0
    return UpAxis(_axis_label(i, s), i, s, u, float(ang[i]), float(sigma), float(conf),
                  float(ratio), int(len(f)))


# --------------------------------------------------------------------------- detection: forward
@dataclass
class ForwardAxis:
    """The sensor axis that points forward on a vehicle (:func:`detect_forward_axis`).

    Attributes
    ----------
    axis : str
        Signed sensor axis (``"+x"``, ``"-y"``, …) nearest to the forward direction, among the
        two axes perpendicular to the up axis.
    index, sign : int
    forward_s : (3,) unit vector, the forward direction found, in sensor axes
    yaw_mount_rad : float
        Fine yaw of the IMU on the vehicle, rad (the ``yaw`` of ``--imu-mount``): the angle,
        clockwise seen from above, from the vehicle's forward direction to the chosen axis.
    sigma_yaw_rad : float
        1σ of ``yaw_mount_rad`` from the least-squares fit.
    confidence : float
        Gaussian probability that the chosen axis is the nearest to forward
        (``Φ((45° − |yaw|)/σ)``); 0 without enough acceleration or turning to see.
    along_gain, lateral_gain : float
        Length of the fitted forward and right vectors (≈ 1 when the specific force and the
        GNSS accelerations agree in scale).
    handed : int
        +1 when the lateral fit says right × forward = up (a right-handed, correctly signed
        triad), −1 when it says the opposite, 0 when there was no turning to tell.
    turn_correlation : float
        Correlation of the GNSS course rate with the gyro rate about −up (≈ +1 when the up
        axis and the gyro signs are right; NaN without turns).
    epochs : int
        GNSS epochs used.
    """

    axis: str
    index: int
    sign: int
    forward_s: np.ndarray
    yaw_mount_rad: float
    sigma_yaw_rad: float
    confidence: float
    along_gain: float
    lateral_gain: float
    handed: int
    turn_correlation: float
    epochs: int

    def to_dict(self) -> dict:
        return {"axis": self.axis, "yaw_mount_deg": math.degrees(self.yaw_mount_rad),
                "sigma_yaw_deg": math.degrees(self.sigma_yaw_rad), "confidence": self.confidence,
                "along_gain": self.along_gain, "lateral_gain": self.lateral_gain,
                "handed": self.handed, "turn_correlation": self.turn_correlation,
                "epochs": self.epochs}


def gnss_velocity_n(gnss: GnssData) -> tuple[np.ndarray, np.ndarray]:
    """ENU velocity of a GNSS record: its own where given, else central differences of the
    positions over ±1 s (at the fix times; the ends one-sided). Returns ``(t, velocity_n)``."""
    t = np.asarray(gnss.t, dtype=float)
    if gnss.velocity_n is not None and np.all(np.isfinite(gnss.velocity_n[:, :2])):
        v = np.array(gnss.velocity_n, dtype=float)
        v[:, 2] = np.where(np.isfinite(v[:, 2]), v[:, 2], 0.0)
        return t, v
    r_phi, r_lam = radii(gnss.lat, gnss.h)
    lon = np.unwrap(gnss.lon)
    p = np.column_stack([(lon - lon[0]) * r_lam * np.cos(gnss.lat), (gnss.lat - gnss.lat[0]) * r_phi,
                         gnss.h - gnss.h[0]])
    # central differences over ±1 s (at least one fix each side): the noise of a difference
    # of positions falls with its span
    m = max(1, int(round(1.0 / max(float(np.median(np.diff(t))), 1e-6)))) if len(t) > 2 else 1
    i = np.arange(len(t))
    a, b = np.clip(i - m, 0, len(t) - 1), np.clip(i + m, 0, len(t) - 1)
    span = np.where(t[b] > t[a], t[b] - t[a], np.nan)
    v = (p[b] - p[a]) / span[:, None]
    return t, v


def _interval_means(t_imu, x, t0, t1):
    """Mean of IMU rows (interval means ending at ``t_imu``) over ``[t0, t1]`` (cumulative sums,
    row granularity)."""
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    i0 = np.searchsorted(t_imu, t0, side="right")
    i1 = np.searchsorted(t_imu, t1, side="right")
    n = np.maximum(i1 - i0, 1)
    return (c[i1] - c[i0]) / n[:, None], i1 - i0


def detect_forward_axis(imu: ImuData, gnss: GnssData, *, up: UpAxis | None = None,
                        min_speed: float = 1.0, span_s: float | None = None) -> ForwardAxis:
    """The forward axis of a sensor on a vehicle, from its horizontal specific force against the
    acceleration of the GNSS velocity.

    On a vehicle that does not slip sideways the horizontal specific force is, in the plane
    perpendicular to up, ``f_h = (a_along + g sin γ) F + a_lat R + c``: the along-track
    acceleration (the derivative of the GNSS speed, plus gravity along a climb of angle γ)
    along the forward direction ``F``, the lateral acceleration ``v · dχ/dt`` (χ the course)
    along the right direction ``R``, and a constant ``c`` (accelerometer bias and a tilt of the
    mounting). Both are averaged over ``span_s`` around each GNSS epoch on both sides (the IMU
    rows by their interval means), and ``F``, ``R``, ``c`` are fitted by least squares over the
    epochs faster than ``min_speed`` — as a *reverse* regression, ``a_along = F·(f_h − c)``
    and ``a_lat = R·(f_h − c)``, so that the noise of the differenced GNSS velocity sits in the
    responses and does not shrink the fit. The forward axis is the sensor axis nearest to ``F``; the
    fine yaw mounting angle is the angle between them, its σ from the fit's covariance with
    the residual variance.

    Parameters
    ----------
    imu : ImuData
        In the sensor's own axes (a reader given ``axes="detect"``).
    gnss : GnssData
        On the IMU's time base; velocity used where given, else from the positions.
    up : UpAxis, optional
        Default: :func:`detect_up_axis` of the IMU rows that overlap the GNSS span.
    min_speed : m/s
    span_s : s, averaging window (≥ 2 GNSS intervals); default 1 s with the receiver's
        velocity, 4 s with a velocity differenced from positions (twice differenced noise)

    Returns
    -------
    ForwardAxis
    """
    t_imu = np.asarray(imu.t, dtype=float)
    tg, vg = gnss_velocity_n(gnss)
    if span_s is None:
        span_s = 1.0 if gnss.velocity_n is not None else 4.0
    keep = (tg >= t_imu[0]) & (tg <= t_imu[-1])
    tg, vg = tg[keep], vg[keep]
    if up is None:
        m = (t_imu >= (tg[0] if len(tg) else t_imu[0])) & (t_imu <= (tg[-1] if len(tg) else t_imu[-1]))
        up = detect_up_axis(imu.f_ib_b[m] if m.sum() > 10 else imu.f_ib_b)
    u = np.asarray(up.up_s, dtype=float)
    empty = ForwardAxis("?", -1, 0, np.full(3, np.nan), float("nan"), float("nan"), 0.0,
                        float("nan"), float("nan"), 0, float("nan"), 0)
    if len(tg) < 5:
        return empty
    dtg = float(np.median(np.diff(tg)))
    half = max(0.5 * span_s, dtg)
    k = max(1, int(round(half / dtg)))
    # GNSS: speed, course, their rates over ±k epochs
    sp = np.hypot(vg[:, 0], vg[:, 1])
    chi = np.unwrap(np.arctan2(vg[:, 0], vg[:, 1]))
    i = np.arange(k, len(tg) - k)
    t0, t1 = tg[i - k], tg[i + k]
    a_al = (sp[i + k] - sp[i - k]) / (t1 - t0)
    chi_rate = (chi[i + k] - chi[i - k]) / (t1 - t0)
    s_mid = sp[i]
    slope = np.where(s_mid > 0.1, vg[i, 2] / np.maximum(np.hypot(s_mid, vg[i, 2]), 1e-9), 0.0)
    a_al = a_al + G0 * slope
    a_lat = s_mid * chi_rate
    # IMU: mean specific force and rate over the same spans
    f_mean, n_rows = _interval_means(t_imu, np.asarray(imu.f_ib_b, float), t0, t1)
    w_mean, _ = _interval_means(t_imu, np.asarray(imu.omega_ib_b, float), t0, t1)
    ok = (n_rows > 0) & (sp[i - k] > min_speed) & (sp[i + k] > min_speed) & (s_mid > min_speed)
    ok &= np.isfinite(a_al) & np.isfinite(a_lat)
    # course rate against the gyro about −up (heading clockwise)
    turn = -(w_mean @ u)
    corr = float("nan")
    if ok.sum() > 5 and np.std(chi_rate[ok]) > 1e-3 and np.std(turn[ok]) > 0:
        corr = float(np.corrcoef(chi_rate[ok], turn[ok])[0, 1])
    if ok.sum() < 8:
        return replace(empty, turn_correlation=corr, epochs=int(ok.sum()))
    # basis of the plane perpendicular to up
    e1 = np.cross(u, np.eye(3)[int(np.argmin(np.abs(u)))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    B = np.column_stack([e1, e2])
    # reverse regression (the GNSS accelerations, the noisy side, as the responses):
    # a_along = F·(f_p − c), a_lat = R·(f_p − c), unbiased however noisy the GNSS
    fp = f_mean[ok] @ B                                 # (M, 2) in the plane
    X = np.column_stack([fp, np.ones(len(fp))])
    Y = np.column_stack([a_al[ok], a_lat[ok]])
    XtX = X.T @ X
    try:
        XtX_inv = np.linalg.inv(XtX)
    except np.linalg.LinAlgError:
        return replace(empty, turn_correlation=corr, epochs=int(ok.sum()))
    coef = XtX_inv @ X.T @ Y                            # columns: along, lateral
    res = Y - X @ coef
    dof = max(len(Y) - 3, 1)
    s2 = np.sum(res ** 2, axis=0) / dof                 # per response
    # each epoch's span overlaps its 2k neighbours': the residuals are correlated over 2k
    # epochs, so the least-squares covariance is inflated by 2k (fewer independent epochs)
    infl2 = 2.0 * k
    Fp, Rp = coef[:2, 0], coef[:2, 1]
    gain_f = float(np.linalg.norm(Fp))
    gain_r = float(np.linalg.norm(Rp))
    if not gain_f > 0:
        return replace(empty, turn_correlation=corr, epochs=int(ok.sum()))
    cov_f = infl2 * s2[0] * XtX_inv[:2, :2]
    cov_r = infl2 * s2[1] * XtX_inv[:2, :2]
    nf = Fp / gain_f
    perp = np.array([-nf[1], nf[0]])
    sig_perp = math.sqrt(float(perp @ cov_f @ perp)) / gain_f
    sig_gain = math.sqrt(float(nf @ cov_f @ nf))
    F = B @ nf
    handed = 0
    if gain_r > 0:
        nr = Rp / gain_r
        if gain_r > 3.0 * math.sqrt(float(nr @ cov_r @ nr)):
            R3 = B @ nr
            handed = 1 if float(np.cross(R3, F) @ u) > 0 else -1
    # nearest sensor axis to F among those perpendicular to up
    cand = [j for j in range(3) if j != up.index]
    best = max(cand, key=lambda j: abs(F[j]))
    sgn = 1 if F[best] >= 0 else -1
    a_vec = np.zeros(3)
    a_vec[best] = sgn
    a_vec -= (a_vec @ u) * u
    a_vec /= np.linalg.norm(a_vec)
    # yaw: from the vehicle's forward F to the IMU axis, clockwise seen from above (about −u)
    yaw = float(math.atan2(-(np.cross(F, a_vec) @ u), float(F @ a_vec)))
    conf = _phi((math.pi / 4 - abs(yaw)) / max(sig_perp, 1e-12))
    if gain_f < 3.0 * sig_gain:
        conf = 0.0                                      # no along-track acceleration to see
    return ForwardAxis(_axis_label(best, sgn), best, sgn, F, yaw, float(sig_perp), float(conf),
                       gain_f, gain_r, handed, corr, int(ok.sum()))


# --------------------------------------------------------------------------- detected frames
def frame_from_detection(up: UpAxis, forward: ForwardAxis | None = None, *,
                         yaw: bool = True) -> ImuFrame:
    """The :class:`ImuFrame` of what was detected: the up axis ``U``, the forward axis ``F``
    and the third axis by the right-hand rule; with ``yaw`` the fine yaw mounting angle.

    Without a forward axis (``None`` or no confidence) the sensor axis after the up axis in the
    cyclic order x → y → z is taken as forward (the heading is then the navigator's business:
    a mounting yaw of 90° only turns the heading).
    """
    if up.index < 0:
        raise AxesError("no up axis detected")
    U = np.zeros(3)
    U[up.index] = up.sign
    if forward is not None and forward.index >= 0 and forward.index != up.index:
        Fv = np.zeros(3)
        Fv[forward.index] = forward.sign
        yaw_deg = math.degrees(forward.yaw_mount_rad) if yaw else 0.0
    else:
        Fv = np.zeros(3)
        Fv[(up.index + 1) % 3] = 1.0
        yaw_deg = 0.0
    Rv = np.cross(Fv, U)                 # R × F = U  ⇔  R = F × U
    # P maps sensor → RFU: rows are the sensor-axis coordinates of R, F, U
    P = np.vstack([Rv, Fv, U])
    return ImuFrame(axes_from_matrix(P), (0.0, 0.0, yaw_deg), "", "detected")


def compare_frames(given: ImuFrame, detected: ImuFrame, *, yaw_tolerance_deg: float = 10.0,
                   up: UpAxis | None = None, forward: ForwardAxis | None = None) -> str | None:
    """One line when a given frame disagrees with a detected one (None when they agree).

    The up axes are compared when ``up`` is confident (≥ 0.99); forward when ``forward`` is;
    the yaw mounting when its difference exceeds both ``yaw_tolerance_deg`` and 3σ.
    """
    Pg, Pd = given.axes.matrix, detected.axes.matrix
    msgs = []
    if up is None or up.confidence >= 0.99:
        if not np.array_equal(Pg[2], Pd[2]):
            msgs.append(f"up is sensor axis {_axis_of(Pd[2])} by gravity, not "
                        f"{_axis_of(Pg[2])}")
    if forward is not None and forward.confidence >= 0.99:
        if not np.array_equal(Pg[1], Pd[1]):
            msgs.append(f"forward is sensor axis {_axis_of(Pd[1])} by the GNSS accelerations, "
                        f"not {_axis_of(Pg[1])}")
        elif abs(given.mount_deg[2] - detected.mount_deg[2]) > max(
                yaw_tolerance_deg, 3 * math.degrees(forward.sigma_yaw_rad)):
            msgs.append(f"yaw mounting {detected.mount_deg[2]:.1f}° ± "
                        f"{math.degrees(forward.sigma_yaw_rad):.1f}° by the GNSS accelerations, "
                        f"not {given.mount_deg[2]:g}°")
    if not msgs:
        return None
    return (f"IMU {given.describe()} disagrees with the data: " + "; ".join(msgs)
            + f" (detected axes {detected.axes.letters})")


def _axis_of(row) -> str:
    j = int(np.flatnonzero(row)[0])
    return _axis_label(j, int(row[j]))


__all__ = ["Axes", "AxesError", "DETECT", "ForwardAxis", "ImuFrame", "PRESETS", "Preset", "RFU",
           "UpAxis", "axes_from_matrix", "compare_frames", "detect_forward_axis",
           "detect_up_axis", "frame_from_detection", "from_vehicle", "gnss_velocity_n",
           "imu_frame", "mount_angles", "mount_matrix", "parse_axes", "parse_mount",
           "preset_names", "to_vehicle"]
