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

**Detection** of the axes from the data is :mod:`selfnav.axes_detect`.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from selfnav import attitude as att
from selfnav.errors import SelfnavError
from selfnav.types import ImuData

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


def axis_label(index: int, sign: int) -> str:
    """``"+x"``, ``"-z"``, …: a signed sensor axis."""
    return ("+" if sign > 0 else "-") + "xyz"[index]


__all__ = ["Axes", "AxesError", "DETECT", "ImuFrame", "PRESETS", "Preset", "RFU",
           "axes_from_matrix", "axis_label", "from_vehicle", "imu_frame", "mount_angles",
           "mount_matrix", "parse_axes", "parse_mount", "preset_names", "to_vehicle"]
