"""One entry point for every raw GNSS format: :func:`read_gnss_raw` (and
:func:`detect_format`) over the readers of :mod:`selfnav.io.rinex`, :mod:`selfnav.io.ubx`,
:mod:`selfnav.io.android`, :mod:`selfnav.io.smartloc` and :mod:`selfnav.io.psins_gnss`."""
from __future__ import annotations

from pathlib import Path

from selfnav.errors import InputError
from selfnav.io.android import read_gnsslogger
from selfnav.io.gnss_raw import RawGnss
from selfnav.io.psins_gnss import read_psins_gnss
from selfnav.io.rinex import read_rinex, read_rinex_nav
from selfnav.io.smartloc import read_smartloc_raw
from selfnav.io.ubx import read_ubx

RAW_FORMATS = ("auto", "rinex", "ubx", "android", "smartloc", "psins")


def detect_format(path) -> str:
    """The raw format of a file from its name and first bytes."""
    path = Path(path)
    name = path.name.lower()
    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except OSError as e:
        raise InputError(path, f"cannot read ({e.strerror})") from None
    if name.endswith(".ubx") or head[:2] == b"\xb5\x62":
        return "ubx"
    if name.endswith(".mat") or head[:6] == b"MATLAB":
        return "psins"
    text = head.decode("latin-1")
    if "RINEX VERSION / TYPE" in text:
        return "rinex"
    if "# Raw," in text or "\nRaw," in text or text.startswith("Raw,") or "GnssLogger" in text:
        return "android"
    if "pseudorange3" in text or "odom3" in text:
        return "smartloc"
    if b"\xb5\x62" in head:
        return "ubx"
    raise InputError(path, "not a raw GNSS file selfnav reads (RINEX observation, u-blox UBX, "
                           "Android GnssLogger, smartLoc, PSINS .mat)")


def read_gnss_raw(path, nav=None, *, fmt: str = "auto") -> RawGnss:
    """Read raw measurements (and the ephemerides the file has) from any supported format.

    Parameters
    ----------
    path : str or Path
        RINEX 2/3 observation file, u-blox ``.ubx``, Android GnssLogger ``.txt``, smartLoc
        ``*_Input.txt`` or PSINS ``insgpseo_tc.mat``.
    nav : str, Path or list, optional
        RINEX 2/3 navigation file(s) adding ephemerides (and Klobuchar parameters).
    fmt : one of :data:`RAW_FORMATS`
    """
    path = Path(path)
    fmt = detect_format(path) if fmt == "auto" else fmt
    if fmt == "rinex":
        raw = read_rinex(path)
    elif fmt == "ubx":
        raw = read_ubx(path)
    elif fmt == "android":
        raw = read_gnsslogger(path)
    elif fmt == "smartloc":
        raw = read_smartloc_raw(path)
    elif fmt == "psins":
        raw = read_psins_gnss(path)
    else:
        raise InputError(path, f"unknown raw GNSS format '{fmt}' ({', '.join(RAW_FORMATS)})")
    if nav is not None:
        for p in ([nav] if isinstance(nav, (str, Path)) else nav):
            raw.eph = raw.eph.merged(read_rinex_nav(p))
    if len(raw.obs) == 0:
        raise InputError(path, "holds no GNSS measurements")
    return raw
