"""Readers for the smartLoc data sets (TU Chemnitz, libRSF format; DESIGN §8).

Input file: one measurement per line, whitespace separated, first token the type:

- ``pseudorange3``: t [s], pseudorange [m], variance [m²], satellite ECEF X, Y, Z [m], satellite
  id, system (1 GPS, 4 GLONASS, 8 Galileo, …), elevation [deg], C/N0 [dBHz]. Atmospheric delays
  and the satellite clock are already removed: what is left is the geometric range (at the
  satellite's transmit position, Earth-fixed at transmit time) plus one receiver clock per system.
- ``odom3``: t, vx, vy, vz [m/s], wx, wy, wz [rad/s], then 6 variances (vehicle frame: x forward,
  y left, z up, as in ROS).

Ground-truth file: ``point3`` t, ECEF X, Y, Z [m], then zeros.

Other measurement types are counted and ignored. Malformed rows raise a one-line
:class:`selfnav.errors.InputError` naming the file, the line and the likely cause.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from selfnav.errors import InputError

#: System codes of the libRSF format.
SYSTEM_NAMES = {1: "GPS", 2: "SBAS", 4: "GLONASS", 8: "Galileo", 16: "QZSS", 32: "BeiDou"}

_PR_FIELDS = ("t", "pseudorange", "variance", "sat_x", "sat_y", "sat_z", "sat_id", "system",
              "elevation_deg", "cn0_dbhz")
_ODOM_FIELDS = ("t", "vx", "vy", "vz", "wx", "wy", "wz")


@dataclass
class Pseudoranges:
    """Pseudorange observations, one row each, sorted by time (stable).

    Attributes
    ----------
    t : (M,) s
    pr : (M,) m
    var : (M,) m², the data set's variance
    sat_ecef : (M, 3) m
    sat_id, system : (M,) int
    elevation : (M,) rad
    cn0 : (M,) dBHz
    source : str
    """

    t: np.ndarray
    pr: np.ndarray
    var: np.ndarray
    sat_ecef: np.ndarray
    sat_id: np.ndarray
    system: np.ndarray
    elevation: np.ndarray
    cn0: np.ndarray
    source: str = ""

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class Odometry:
    """Vehicle odometry: body velocity (x forward, y left, z up) and angular rate.

    Attributes
    ----------
    t : (N,) s
    velocity_b : (N, 3) m/s
    omega_b : (N, 3) rad/s (``omega_b[:, 2]`` is the yaw rate, counter-clockwise positive)
    variances : (N, 6) the file's variances (vx, vy, vz, wx, wy, wz)
    """

    t: np.ndarray
    velocity_b: np.ndarray
    omega_b: np.ndarray
    variances: np.ndarray
    source: str = ""

    @property
    def speed(self) -> np.ndarray:
        return self.velocity_b[:, 0]

    @property
    def yaw_rate(self) -> np.ndarray:
        return self.omega_b[:, 2]


@dataclass
class SmartlocTruth:
    """Ground truth positions (ECEF, m)."""

    t: np.ndarray
    ecef: np.ndarray
    source: str = ""


def _read_lines(path: Path):
    try:
        text = path.read_text(encoding="ascii", errors="strict")
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except UnicodeDecodeError as e:
        raise InputError(path, f"not a text file (non-ASCII byte at offset {e.start})") from None
    except OSError as e:
        raise InputError(path, f"cannot read ({e.strerror})") from None
    return text.splitlines()


def _parse(path, row, tok, n_min, names):
    if len(tok) - 1 < n_min:
        raise InputError(path, f"'{tok[0]}' needs {n_min} numbers, found {len(tok) - 1} "
                               "(truncated line?)", row=row)
    try:
        vals = [float(x) for x in tok[1:n_min + 1]]
    except ValueError:
        for i, x in enumerate(tok[1:n_min + 1]):
            try:
                float(x)
            except ValueError:
                raise InputError(path, f"'{x}' is not a number", row=row,
                                 column=names[i] if i < len(names) else f"field {i + 1}") from None
        raise
    if not np.all(np.isfinite(vals)):
        i = int(np.argmin(np.isfinite(vals)))
        raise InputError(path, "value is not finite", row=row,
                         column=names[i] if i < len(names) else f"field {i + 1}")
    return vals


def read_smartloc_input(path):
    """Read a smartLoc ``*_Input.txt`` file.

    Returns
    -------
    (Pseudoranges, Odometry)

    Raises
    ------
    InputError
        Malformed rows, negative variances, time going backwards in the odometry, no data.
    """
    path = Path(path)
    pr_rows, pr_line, od_rows, od_line = [], [], [], []
    for i, line in enumerate(_read_lines(path), start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        if tok[0] == "pseudorange3":
            pr_rows.append(_parse(path, i, tok, 10, _PR_FIELDS))
            pr_line.append(i)
        elif tok[0] == "odom3":
            od_rows.append(_parse(path, i, tok, 13, _ODOM_FIELDS + ("var",) * 6))
            od_line.append(i)
    if not pr_rows:
        raise InputError(path, "no 'pseudorange3' lines (not a smartLoc input file?)")
    if not od_rows:
        raise InputError(path, "no 'odom3' lines (not a smartLoc input file?)")
    p = np.asarray(pr_rows)
    o = np.asarray(od_rows)
    bad = np.flatnonzero(p[:, 2] <= 0)
    if bad.size:
        raise InputError(path, "pseudorange variance must be positive", row=pr_line[bad[0]],
                         column="variance")
    bad = np.flatnonzero(np.linalg.norm(p[:, 3:6], axis=1) < 1e7)
    if bad.size:
        raise InputError(path, "satellite position is not in orbit (ECEF metres expected)",
                         row=pr_line[bad[0]], column="sat_x")
    bad = np.flatnonzero(np.diff(o[:, 0]) <= 0)
    if bad.size:
        raise InputError(path, "odometry time not strictly increasing", row=od_line[bad[0] + 1],
                         column="t")
    order = np.argsort(p[:, 0], kind="stable")
    p = p[order]
    prs = Pseudoranges(p[:, 0], p[:, 1], p[:, 2], p[:, 3:6].copy(), p[:, 6].astype(int),
                       p[:, 7].astype(int), np.radians(p[:, 8]), p[:, 9], source=str(path))
    odo = Odometry(o[:, 0], o[:, 1:4].copy(), o[:, 4:7].copy(), o[:, 7:13].copy(), source=str(path))
    return prs, odo


def read_smartloc_truth(path) -> SmartlocTruth:
    """Read a smartLoc ``*_GT.txt`` file (``point3`` t, ECEF X, Y, Z)."""
    path = Path(path)
    rows, lines = [], []
    for i, line in enumerate(_read_lines(path), start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        if tok[0] != "point3":
            raise InputError(path, f"unexpected measurement type '{tok[0]}' (ground truth has "
                                   "'point3' lines)", row=i)
        rows.append(_parse(path, i, tok, 4, ("t", "x", "y", "z")))
        lines.append(i)
    if not rows:
        raise InputError(path, "no 'point3' lines (not a smartLoc ground-truth file?)")
    g = np.asarray(rows)
    bad = np.flatnonzero(np.diff(g[:, 0]) <= 0)
    if bad.size:
        raise InputError(path, "time not strictly increasing", row=lines[bad[0] + 1], column="t")
    bad = np.flatnonzero(np.abs(np.linalg.norm(g[:, 1:4], axis=1) - 6.37e6) > 1e5)
    if bad.size:
        raise InputError(path, "position is not near the Earth's surface (ECEF metres expected)",
                         row=lines[bad[0]], column="x")
    return SmartlocTruth(g[:, 0], g[:, 1:4].copy(), source=str(path))


def write_smartloc(input_path, gt_path, prs: Pseudoranges, odo: Odometry,
                   truth: SmartlocTruth) -> None:
    """Write pseudoranges and odometry as a smartLoc ``*_Input.txt`` (lines in time order,
    each epoch's odometry before its pseudoranges) and the truth as ``*_GT.txt`` — the paths
    given (temporary files: the caller moves them into place)."""
    lines = []
    for k in range(len(odo.t)):
        v, w, q = odo.velocity_b[k], odo.omega_b[k], odo.variances[k]
        lines.append((odo.t[k], 0, "odom3 " + " ".join(f"{x:.9g}" for x in (
            odo.t[k], *v, *w, *q))))
    el = np.degrees(prs.elevation)
    for i in range(len(prs.t)):
        x, y, z = prs.sat_ecef[i]
        lines.append((prs.t[i], 1, f"pseudorange3 {prs.t[i]:.9g} {prs.pr[i]:.4f} "
                      f"{prs.var[i]:.6g} {x:.4f} {y:.4f} {z:.4f} {int(prs.sat_id[i])} "
                      f"{int(prs.system[i])} {el[i]:.4f} {prs.cn0[i]:.2f}"))
    lines.sort(key=lambda r: (r[0], r[1]))
    Path(input_path).write_text("\n".join(r[2] for r in lines) + "\n", encoding="ascii")
    Path(gt_path).write_text("".join(
        f"point3 {t:.9g} {x:.4f} {y:.4f} {z:.4f}" + " 0" * 9 + "\n"
        for t, (x, y, z) in zip(truth.t, truth.ecef)), encoding="ascii")


def find_smartloc_files(folder):
    """The ``*_Input.txt`` and ``*_GT.txt`` files of a smartLoc folder."""
    folder = Path(folder)
    inp = sorted(folder.glob("*_Input.txt"))
    gt = sorted(folder.glob("*_GT.txt"))
    if len(inp) != 1 or len(gt) != 1:
        raise InputError(folder, f"expected one '*_Input.txt' and one '*_GT.txt', found "
                                 f"{len(inp)} and {len(gt)}")
    return inp[0], gt[0]


def read_smartloc_raw(path):
    """A smartLoc input file as :class:`selfnav.io.gnss_raw.RawGnss`: the pseudoranges are
    already corrected (satellite clock, atmosphere) and carry satellite positions, elevation,
    variance and C/N0, so no ephemeris is needed (``obs.corrected``); the time is the file's."""
    from selfnav.io.gnss_raw import Ephemerides, GnssObservations, RawGnss

    prs, _ = read_smartloc_input(path)
    sig = np.where(prs.system == 4, "1C", "1C").astype(object)
    obs = GnssObservations.build(prs.t, prs.system, prs.sat_id, sig, pseudorange=prs.pr,
                                 cn0=prs.cn0, source=str(path), sat_ecef=prs.sat_ecef,
                                 corrected=True, elevation=prs.elevation, variance=prs.var)
    return RawGnss(obs, Ephemerides.empty(), None, str(path))
