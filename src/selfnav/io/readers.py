"""One entry per kind of input: the format dispatch of every reader (DESIGN §6).

:func:`read_imu` and :func:`read_gnss` pick the reader by ``fmt`` or, with ``"auto"``, by the
file name; each format module stays independent of the others (no module here is imported by a
format reader).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from selfnav import axes as _axes
from selfnav.errors import InputError
from selfnav.io.gnss import read_gnss_csv, read_nmea, read_rtklib_pos, to_wgs84
from selfnav.io.imu import read_imu_csv
from selfnav.io.kfgins import read_kfgins_imu
from selfnav.io.nmea_rmc import read_nmea_rmc
from selfnav.io.psins import read_psins_imu
from selfnav.io.psins_gnss import read_psins_tc_imu
from selfnav.io.psins_mat import (AVP_COLUMNS, INCREMENT_COLUMNS, header_of, read_avp_csv,
                                  read_increments_csv)
from selfnav.io import rtklibexplorer
from selfnav.io.rtklibexplorer import IMU_T_OFF, read_rtklibexplorer_imu
from selfnav.io.ulog import ULOG_SUFFIXES, read_ulog_baro, read_ulog_gnss, read_ulog_imu
from selfnav.types import BaroData, GnssData, ImuData

IMU_FORMATS = ("auto", "csv", "psins", "psins-csv", "psins-mat", "rtklibexplorer", "kfgins",
               "ulog")
GNSS_FORMATS = ("auto", "csv", "pos", "nmea", "psins-avp", "ulog")

#: The axes each IMU format's columns are in, by the format's own documentation (the reader
#: converts them to RFU). ``rtklibexplorer`` documents none: its default is the preset of
#: :data:`selfnav.io.rtklibexplorer.DEFAULT_AXES` (the reader returns the sensor's axes).
FORMAT_AXES = {"csv": "RFU", "psins": "RFU", "psins-csv": "RFU", "psins-mat": "RFU",
               "kfgins": "FRD", "ulog": "FRD"}


def imu_format_of(path) -> str:
    """The IMU format ``auto`` picks: PSINS for ``.imu``/``.imu.gz`` (and its tightly coupled
    demo's ``.mat``), PX4 ULog for ``.ulg``,
    rtklibexplorer when a
    ``.tag`` file stands beside the CSV, PSINS increments for a CSV headed ``dtheta_x_rad,...``,
    the native CSV otherwise."""
    p = Path(path)
    name = p.name.lower()
    if name.endswith((".imu", ".imu.gz")):
        return "psins"
    if name.endswith(ULOG_SUFFIXES):
        return "ulog"
    if name.endswith(".mat"):
        return "psins-mat"
    if p.with_name(p.name + ".tag").exists():
        return "rtklibexplorer"
    if header_of(p)[:1] == (INCREMENT_COLUMNS[0],):
        return "psins-csv"
    return "csv"


def read_imu(path, fmt: str = "auto", *, time_offset_s: float = 0.0, axes=None,
             mount=None) -> ImuData:
    """Read an IMU file into the vehicle's RFU frame.

    Parameters
    ----------
    path : str or Path
    fmt : {"auto", "csv", "psins", "psins-csv", "psins-mat", "rtklibexplorer", "kfgins", "ulog"}
        ``auto``: :func:`imu_format_of`.
    time_offset_s : float
        Added to the time stamps, s. The rtklibexplorer format applies upstream's own
        ``imu_t_off`` (−0.125 s) first; ``imu.meta["time_offset_s"]`` is the total applied.
    axes : None, str or selfnav.axes.ImuFrame
        The axes of the file's columns (``--imu-axes``): an axes spec (``FRD``,
        ``x=-F,y=R,z=U``, :func:`selfnav.axes.parse_axes`), a preset name
        (:data:`selfnav.axes.PRESETS`) or ``"detect"`` (the columns are left in the file's
        own axes, ``meta["axes_source"] = "detect"``, for the navigator to detect). ``None``:
        the format's documented axes (:data:`FORMAT_AXES`; rtklibexplorer: its preset).
    mount : None, str or (3,)
        ``roll,pitch,yaw`` degrees of the IMU on the vehicle (``--imu-mount``), applied after
        the axes; overrides a preset's.

    Returns
    -------
    ImuData
        ``meta`` holds ``axes``, ``mount_deg``, ``axes_preset`` and ``axes_source``
        (``format``, ``preset``, ``given``, ``detect``).
    """
    p = Path(path)
    fmt = imu_format_of(p) if fmt == "auto" else fmt
    frame = _frame_of(fmt, axes, mount) if fmt in IMU_FORMATS else None
    if fmt == "csv":
        imu = read_imu_csv(p)
    elif fmt == "psins":
        imu = read_psins_imu(p)
    elif fmt == "kfgins":
        imu = read_kfgins_imu(p)
    elif fmt == "psins-csv":
        imu = read_increments_csv(p)
    elif fmt == "psins-mat":
        imu = read_psins_tc_imu(p)
    elif fmt == "ulog":
        imu = read_ulog_imu(p)
    elif fmt == "rtklibexplorer":
        imu = read_rtklibexplorer_imu(p, t_offset=IMU_T_OFF + time_offset_s)
        imu.meta["time_offset_s"] = IMU_T_OFF + time_offset_s
        imu.meta["format_time_offset_s"] = IMU_T_OFF
        return _in_frame(imu, fmt, frame)
    else:
        raise InputError(p, f"unknown IMU format '{fmt}' (use {', '.join(IMU_FORMATS)})")
    if time_offset_s:
        imu = imu.shifted(time_offset_s)
    imu.meta["time_offset_s"] = float(time_offset_s)
    imu.meta["format_time_offset_s"] = 0.0
    return _in_frame(imu, fmt, frame)


def _frame_of(fmt: str, axes, mount):
    """The :class:`~selfnav.axes.ImuFrame` (or ``"detect"``) a format's file is read into."""
    if fmt in FORMAT_AXES:
        default = _axes.ImuFrame(_axes.parse_axes(FORMAT_AXES[fmt]), source="format")
    else:
        default = _axes.imu_frame(rtklibexplorer.DEFAULT_AXES)
        if default != _axes.DETECT:
            default = replace(default, source="format")
    if axes is not None:
        return _axes.imu_frame(axes, mount)
    if mount is None:
        return default
    if default == _axes.DETECT:
        raise _axes.AxesError("--imu-mount needs --imu-axes for this format (its axes are "
                              "detected by default)")
    return replace(default, mount_deg=_axes.parse_mount(mount), source="given")


def _in_frame(imu: ImuData, fmt: str, frame) -> ImuData:
    """Rows of a reader (in its format's documented axes, or the sensor's for rtklibexplorer)
    into ``frame``: the format's own conversion is undone first (exact: a signed permutation)
    when the user describes the file's columns."""
    own = FORMAT_AXES.get(fmt)
    if own is not None and own != "RFU":
        raw = _axes.from_vehicle(imu, _axes.imu_frame(own))
        for k in ("written_axes", "written_mount_deg"):
            raw.meta.pop(k, None)
    else:
        raw = imu
    if frame == _axes.DETECT:
        raw.meta.update({"axes": "sensor", "mount_deg": (0.0, 0.0, 0.0), "axes_preset": "",
                         "axes_source": "detect"})
        return raw
    if own is not None and frame.source == "format":
        imu.meta.update(frame.to_meta())
        return imu                         # the reader's own conversion is the answer
    return _axes.to_vehicle(raw, frame)


def read_imu_positions(paths, fmt: str = "auto", *, axes=None, mount=None) -> ImuData:
    """Read a multi-position record: several files (one per position) or one with ``position``
    (``axes``, ``mount`` as :func:`read_imu`)."""
    paths = list(paths)
    if len(paths) == 1:
        return read_imu(paths[0], fmt, axes=axes, mount=mount)
    parts = [read_imu(p, fmt, axes=axes, mount=mount) for p in paths]
    t = np.concatenate([p.t for p in parts])
    pos = np.concatenate([np.full(len(p), k) for k, p in enumerate(parts)])
    return ImuData(
        t, np.concatenate([p.omega_ib_b for p in parts]), np.concatenate([p.f_ib_b for p in parts]),
        None, pos, source=" + ".join(str(p) for p in paths),
    )


def gnss_format_of(path) -> str:
    """The GNSS format ``auto`` picks from the extension: ``.pos`` RTKLIB, ``.nmea``/``.nma``/
    ``.gga`` NMEA, ``.ulg`` PX4 ULog, a CSV headed ``pitch_rad,...`` a PSINS navigation output,
    anything else the native CSV."""
    ext = Path(path).suffix.lower()
    fmt = {".pos": "pos", ".nmea": "nmea", ".nma": "nmea", ".gga": "nmea",
           ".ulg": "ulog"}.get(ext, "csv")
    if fmt == "csv" and header_of(path)[:1] == (AVP_COLUMNS[0],):
        return "psins-avp"
    return fmt


def _with_rmc_velocity(g: GnssData, path) -> GnssData:
    """Add the horizontal velocity of RMC sentences (same time stamps) to GGA fixes."""
    try:
        rmc = read_nmea_rmc(path)
    except InputError:
        return g
    if len(rmc.t) == 0:
        return g
    idx = np.clip(np.searchsorted(rmc.t, g.t), 0, len(rmc.t) - 1)
    if not np.all(np.abs(rmc.t[idx] - g.t) < 1e-3):
        return g
    v = rmc.velocity_n[idx].copy()
    v[:, 2] = np.where(np.isfinite(v[:, 2]), v[:, 2], 0.0)
    g.velocity_n = v
    return g


def read_gnss(path, fmt: str = "auto", datum: str = "wgs84") -> GnssData:
    """Read GNSS fixes: ``csv`` (native), ``pos`` (RTKLIB), ``nmea``, ``ulog`` (PX4
    ``vehicle_gps_position`` / ``sensor_gps``); ``auto`` by extension.

    Positions come back in WGS-84 whatever ``datum`` the file is in (``wgs84``, ``pz90.11``,
    ``pz90``, ``sk42``).
    """
    p = Path(path)
    fmt = gnss_format_of(p) if fmt == "auto" else fmt
    if fmt == "csv":
        return read_gnss_csv(p, datum)
    if fmt == "pos":
        g = read_rtklib_pos(p)
    elif fmt == "nmea":
        g = _with_rmc_velocity(read_nmea(p), p)
    elif fmt == "ulog":
        g = read_ulog_gnss(p)
    elif fmt == "psins-avp":
        # another navigator's output (PSINS avp) as position and velocity fixes, σ not given
        tr = read_avp_csv(p)
        g = GnssData(tr.t, tr.lat, tr.lon, tr.h, None, tr.velocity_n, None, str(p))
    else:
        raise InputError(p, f"unknown GNSS format '{fmt}' (use {', '.join(GNSS_FORMATS)})")
    if datum.lower() != "wgs84":
        g.lat, g.lon, g.h = to_wgs84(g.lat, g.lon, g.h, datum, p)
    return g


def read_baro(path, fmt: str = "auto") -> BaroData:
    """Barometric altitude: PX4 ULog ``vehicle_air_data`` (the only format with one so far)."""
    p = Path(path)
    if fmt == "auto":
        fmt = "ulog" if p.name.lower().endswith(ULOG_SUFFIXES) else "?"
    if fmt != "ulog":
        raise InputError(p, "barometer data is read from PX4 ULog files (.ulg) only")
    return read_ulog_baro(p)
