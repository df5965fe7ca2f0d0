"""PX4 ULog flight logs (``.ulg``, read with pyulog): IMU, magnetometer, GNSS, barometer and the
autopilot's own attitude.

Topics read (the first instance of each):

| topic | what | to selfnav |
| --- | --- | --- |
| ``sensor_combined`` | ``gyro_rad[3]`` rad/s, ``accelerometer_m_s2[3]`` m/s² (FRD body, the board rotation and calibration already applied by PX4); old logs also ``magnetometer_ga[3]``, ``baro_alt_meter`` | :class:`~selfnav.types.ImuData`, RFU |
| ``vehicle_magnetometer`` (newer logs) | ``magnetometer_ga[3]`` Gauss, FRD | ``mag_b`` in nT, interpolated onto the IMU times |
| ``vehicle_gps_position`` / ``sensor_gps`` | ``lat``/``lon`` (1e-7°) or ``latitude_deg``/``longitude_deg``, ``alt_ellipsoid`` (mm) or ``altitude_ellipsoid_m``, ``eph``/``epv`` m, ``vel_n/e/d_m_s``, ``s_variance_m_s`` (speed accuracy, m/s), ``fix_type`` | :class:`~selfnav.types.GnssData` (fix type ≥ 3), ENU velocity |
| ``vehicle_air_data`` | ``baro_alt_meter``, ``baro_pressure_pa``, ``baro_temp_celcius`` | :class:`~selfnav.types.BaroData` |
| ``vehicle_attitude`` | ``q[4]`` (w, x, y, z), FRD body → NED | :class:`~selfnav.types.AttitudeData` (ENU → RFU) |

PX4's body frame is FRD and its navigation frame NED; both become selfnav's RFU / ENU here, once,
through ``M = [[0,1,0],[1,0,0],[0,0,−1]]`` (``v_RFU = M v_FRD``, ``C_b^n(ENU,RFU) = M C_b^n(NED,
FRD) M``, as :mod:`selfnav.io.kfgins`). Time is the log's boot time in seconds (``timestamp``
µs / 1e6; ``timestamp_sample`` where a topic has it), one base for every topic of the log.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav.errors import InputError, warn
from selfnav.io.imu import check_imu_units
from selfnav.types import AttitudeData, BaroData, GnssData, ImuData

ULOG_SUFFIXES = (".ulg",)
#: FRD ↔ RFU and NED ↔ ENU (symmetric, its own inverse, det +1).
M_FRD_RFU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: nT per Gauss.
NT_PER_GAUSS = 1e5
#: PX4's "no new sample" mark in ``*_timestamp_relative`` fields.
RELATIVE_INVALID = 2147483647
#: Which estimator wrote ``vehicle_attitude``, by ``SYS_MC_EST_GROUP`` (PX4 up to v1.13).
EST_GROUPS = {0: "attitude_estimator_q (with INAV)", 1: "attitude_estimator_q (with LPE)",
              2: "ekf2", 3: "ekf2 (Q + LPE fallback)"}


def _ulog(path, topics):
    p = Path(path)
    try:
        from pyulog import ULog
    except ImportError:                                   # pragma: no cover - a declared dep
        raise InputError(p, "reading PX4 ULog files needs pyulog (pip install pyulog)") from None
    if not p.is_file():
        raise InputError(p, "no such file" if not p.exists() else "is not a file")
    try:
        with open(p, "rb") as fh:
            head = fh.read(7)
    except OSError as e:
        raise InputError(p, f"cannot be read ({e.strerror})") from None
    if head != b"ULog\x01\x12\x35":
        raise InputError(p, "is not a PX4 ULog file (no 'ULog' header): a .ulg from a PX4 "
                         "autopilot's SD card, or another format (see --imu-format)")
    try:
        return ULog(str(p), list(topics))
    except Exception as e:   # pyulog raises plain Exceptions on damaged files
        raise InputError(p, f"is a damaged ULog file ({type(e).__name__}: {str(e)[:80]})") from None


def _dataset(u, names, path, required=True):
    """The first instance of the first topic of ``names`` the log holds (or None)."""
    for name in names:
        ds = [d for d in u.data_list if d.name == name]
        if ds:
            return min(ds, key=lambda d: d.multi_id)
    if required:
        have = sorted({d.name for d in u.data_list})
        if not have and not getattr(u, "message_formats", None):
            raise InputError(path, "is a ULog file with no logged messages (empty, or cut "
                             "short before the first data)")
        raise InputError(path, f"has no {' or '.join(names)} messages (its topics: "
                         f"{', '.join(have[:12])}{' ...' if len(have) > 12 else ''})")
    return None


def _vec(data, base, n=3):
    return np.column_stack([np.asarray(data[f"{base}[{i}]"], dtype=float) for i in range(n)])


def _time(data, field="timestamp"):
    return np.asarray(data[field], dtype=np.float64) * 1e-6


def _increasing(t, path, what):
    """Indices that keep ``t`` strictly increasing (repeated stamps dropped with a warning)."""
    keep = np.concatenate([[True], np.diff(t) > 0])
    if not keep.all():
        back = int(np.sum(np.diff(t) < 0))
        if back:
            raise InputError(path, f"{what} time stamps go backwards {back} times (a log that "
                             "was cut and joined?)")
        warn(f"{path}: {int((~keep).sum())} repeated {what} time stamps dropped")
    return np.flatnonzero(keep)


def _frd(x):
    return None if x is None else x @ M_FRD_RFU.T


def params(path) -> dict:
    """The log's initial parameters (``{name: value}``)."""
    return dict(_ulog(path, ["sensor_combined"]).initial_parameters)


def read_ulog_imu(path) -> ImuData:
    """IMU (and magnetometer) of a PX4 log in RFU: ``sensor_combined`` gyro and accelerometer;
    the magnetometer of ``vehicle_magnetometer`` or, in older logs, of ``sensor_combined``,
    in nT, linearly interpolated onto the IMU times (held at the ends).

    ``meta``: ``format = "ulog"``, ``hardware``, ``software``, ``mag_unit = "nT"``,
    ``attitude_estimator`` (which PX4 module wrote ``vehicle_attitude``), ``declination_deg``
    (the declination parameter that estimator used: ``ATT_MAG_DECL`` or ``EKF2_MAG_DECL``).
    """
    p = Path(path)
    u = _ulog(p, ["sensor_combined", "vehicle_magnetometer"])
    sc = _dataset(u, ["sensor_combined"], p).data
    t = _time(sc)
    keep = _increasing(t, p, "sensor_combined")
    t = t[keep]
    w = _vec(sc, "gyro_rad")[keep]
    f = _vec(sc, "accelerometer_m_s2")[keep]
    rel = np.asarray(sc.get("accelerometer_timestamp_relative", np.zeros(len(keep))),
                     dtype=float)[keep]
    ok = rel != RELATIVE_INVALID
    if ok.all() and np.any(rel != 0):         # accelerometer sampled at other instants
        ta = t + rel * 1e-6
        o = np.argsort(ta, kind="stable")
        f = np.column_stack([np.interp(t, ta[o], f[o, k]) for k in range(3)])
    mag_t, mag = None, None
    vm = _dataset(u, ["vehicle_magnetometer"], p, required=False)
    if vm is not None and len(vm.data["timestamp"]) > 1:
        mag_t = _time(vm.data, "timestamp_sample" if "timestamp_sample" in vm.data else
                      "timestamp")
        mag = _vec(vm.data, "magnetometer_ga")
    elif "magnetometer_ga[0]" in sc:
        rel_m = np.asarray(sc["magnetometer_timestamp_relative"], dtype=float)[keep]
        m_all = _vec(sc, "magnetometer_ga")[keep]
        good = rel_m != RELATIVE_INVALID
        tm = t + rel_m * 1e-6            # each sample repeats until the next one comes
        _, first = np.unique(tm[good], return_index=True)
        new = np.flatnonzero(good)[first]
        if len(new) > 1 and np.any(m_all[new] != 0):
            mag_t, mag = tm[new], m_all[new]
    mag_b = None
    if mag is not None:
        o = _increasing(mag_t, p, "magnetometer")
        mag_t, mag = mag_t[o], mag[o]
        mag_b = np.column_stack([np.interp(t, mag_t, mag[:, k]) for k in range(3)]) * NT_PER_GAUSS
    prm = u.initial_parameters
    info = u.msg_info_dict
    group = prm.get("SYS_MC_EST_GROUP")
    est = EST_GROUPS.get(int(group), "unknown") if group is not None else (
        "ekf2" if "EKF2_MAG_DECL" in prm else "unknown")
    decl = prm.get("ATT_MAG_DECL") if est.startswith("attitude_estimator_q") else prm.get(
        "EKF2_MAG_DECL")
    imu = ImuData(t, _frd(w), _frd(f), _frd(mag_b), source=str(p), meta={
        "format": "ulog", "hardware": info.get("ver_hw", ""), "software": info.get("ver_sw", ""),
        "mag_unit": "nT" if mag_b is not None else None, "attitude_estimator": est,
        "declination_deg": None if decl is None else float(decl)})
    check_imu_units(imu, p)
    return imu


def read_ulog_gnss(path, *, min_fix_type: int = 3) -> GnssData:
    """GNSS fixes of a PX4 log (``vehicle_gps_position`` or ``sensor_gps``) in WGS-84.

    σ per horizontal axis: ``eph`` (the receiver's horizontal accuracy, taken as the σ per
    axis: conservative by up to √2), vertical ``epv``, velocity ``s_variance_m_s`` (the
    receiver's speed accuracy, m/s, despite the name). ``quality`` in RTKLIB's scale: 1 RTK
    fixed (PX4 fix type 6), 2 float (5), 4 DGPS (4), 5 single (3). Fixes with a fix type
    below ``min_fix_type`` are dropped (one warning with the count). The height is
    ellipsoidal (``alt_ellipsoid``); a log without it gives the MSL height and a warning.
    """
    p = Path(path)
    u = _ulog(p, ["vehicle_gps_position", "sensor_gps"])
    d = _dataset(u, ["vehicle_gps_position", "sensor_gps"], p).data
    field = "timestamp_sample" if "timestamp_sample" in d and np.all(
        np.asarray(d["timestamp_sample"]) > 0) else "timestamp"
    t = _time(d, field)
    fix = np.asarray(d["fix_type"], dtype=int)
    good = fix >= min_fix_type
    if not good.any():
        raise InputError(p, f"has {len(t)} GNSS messages but no 3-D fix (fix_type < "
                         f"{min_fix_type} throughout): the receiver never locked")
    if (~good).any():
        warn(f"{p}: {int((~good).sum())} of {len(t)} GNSS messages without a 3-D fix dropped")
    if "latitude_deg" in d:
        lat = np.asarray(d["latitude_deg"], float)
        lon = np.asarray(d["longitude_deg"], float)
    else:
        lat = np.asarray(d["lat"], float) * 1e-7
        lon = np.asarray(d["lon"], float) * 1e-7
    if "altitude_ellipsoid_m" in d:
        h = np.asarray(d["altitude_ellipsoid_m"], float)
    elif "alt_ellipsoid" in d and np.any(np.asarray(d["alt_ellipsoid"]) != 0):
        h = np.asarray(d["alt_ellipsoid"], float) * 1e-3
    else:
        h = np.asarray(d["altitude_msl_m"] if "altitude_msl_m" in d else
                       np.asarray(d["alt"], float) * 1e-3, float)
        warn(f"{p}: the GNSS messages hold no ellipsoidal height: the height above mean sea "
             "level is used (tens of metres off the WGS-84 ellipsoid)")
    sig = np.asarray(d["eph"], float)
    sig_v = np.asarray(d["epv"], float)
    vel = None
    if all(k in d for k in ("vel_n_m_s", "vel_e_m_s", "vel_d_m_s")):
        valid = np.asarray(d.get("vel_ned_valid", np.ones(len(t))), bool)
        vel = np.column_stack([d["vel_e_m_s"], d["vel_n_m_s"], -np.asarray(d["vel_d_m_s"], float)])
        vel = np.where(valid[:, None], vel, np.nan).astype(float)
    sig_vel = np.asarray(d["s_variance_m_s"], float) if "s_variance_m_s" in d else None
    q = np.select([fix == 6, fix == 5, fix == 4], [1, 2, 4], 5)
    m = np.flatnonzero(good)
    keep = m[_increasing(t[m], p, "GNSS")]
    ok_sig = np.where(sig[keep] > 0, sig[keep], np.nan)
    return GnssData(t[keep], np.radians(lat[keep]), np.radians(lon[keep]), h[keep], ok_sig,
                    None if vel is None or not np.all(np.isfinite(vel[keep])) else vel[keep],
                    q[keep], str(p), np.where(sig_v[keep] > 0, sig_v[keep], np.nan),
                    None if sig_vel is None else np.where(sig_vel[keep] > 0, sig_vel[keep],
                                                          np.nan))


def read_ulog_baro(path) -> BaroData:
    """Barometric altitude of a PX4 log (``vehicle_air_data``; in older logs
    ``sensor_combined.baro_alt_meter`` when it is not all zero)."""
    p = Path(path)
    u = _ulog(p, ["vehicle_air_data", "sensor_combined"])
    d = _dataset(u, ["vehicle_air_data"], p, required=False)
    if d is not None:
        d = d.data
        t = _time(d, "timestamp_sample" if "timestamp_sample" in d else "timestamp")
        alt = np.asarray(d["baro_alt_meter"], float)
        pa = np.asarray(d["baro_pressure_pa"], float) if "baro_pressure_pa" in d else None
        tc = np.asarray(d["baro_temp_celcius"], float) if "baro_temp_celcius" in d else None
    else:
        sc = _dataset(u, ["sensor_combined"], p).data
        if "baro_alt_meter" not in sc or not np.any(np.asarray(sc["baro_alt_meter"]) != 0):
            raise InputError(p, "has no barometer data (no vehicle_air_data; "
                             "sensor_combined.baro_alt_meter is all zero)")
        t = _time(sc)
        rel = np.asarray(sc.get("baro_timestamp_relative", np.zeros(len(t))), float)
        t = t + np.where(rel != RELATIVE_INVALID, rel, 0.0) * 1e-6
        alt = np.asarray(sc["baro_alt_meter"], float)
        pa = None
        tc = np.asarray(sc["baro_temp_celcius"], float) if "baro_temp_celcius" in sc else None
    keep = _increasing(t, p, "barometer")
    return BaroData(t[keep], alt[keep], None if pa is None else pa[keep],
                    None if tc is None else tc[keep], source=str(p))


def read_ulog_attitude(path) -> AttitudeData:
    """The autopilot's own attitude (``vehicle_attitude``) as ``C_nb`` ENU → RFU."""
    p = Path(path)
    u = _ulog(p, ["vehicle_attitude"])
    d = _dataset(u, ["vehicle_attitude"], p).data
    t = _time(d)
    keep = _increasing(t, p, "vehicle_attitude")
    q = _vec(d, "q", 4)[keep]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    C = np.empty((len(q), 3, 3))           # C_b^n (FRD → NED), Hamilton, scalar first
    C[:, 0] = np.column_stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)])
    C[:, 1] = np.column_stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)])
    C[:, 2] = np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
    C_bn = M_FRD_RFU @ C @ M_FRD_RFU
    return AttitudeData(t[keep], np.swapaxes(C_bn, -1, -2), source=f"{p} (vehicle_attitude)")
