"""Android GnssLogger text logs (``Raw`` lines, and ``Fix`` lines as the phone's own solution).

Pseudoranges follow Google's gps-measurement-tools (``ProcessGnssMeas.m``) and the Android
``GnssMeasurement`` documentation, for every constellation:

    t_Rx = TimeNanos + TimeOffsetNanos − (FullBiasNanos + BiasNanos)        GPS time, ns
    ρ = c · (t_Rx,sys − ReceivedSvTimeNanos)

with ``t_Rx,sys`` the reception time in the satellite's time scale and period: GPS, QZSS and
Galileo (TOW known) the time of week; Galileo with only the E1C secondary code the 100 ms
period; BeiDou the BDT week (GPST − 14 s); GLONASS the time of day in UTC(SU) (UTC + 3 h,
with the log's ``LeapSecond`` or the date's). Integer nanoseconds are kept in int64 until the
difference is taken (float64 of 10¹⁸ ns would lose 100 m).

A measurement is used when ``FullBiasNanos`` is set and the ``State`` bits say the code is
locked and the satellite time is resolved for that constellation (TOW decoded / known, E1C
second code, GLONASS time of day), and ``ReceivedSvTimeUncertaintyNanos`` < 500 ns; the others
are kept with a NaN pseudorange (and their Doppler). The pseudorange rate (m/s) becomes a
Doppler (Hz) ``−ρ̇ f / c``; ``AccumulatedDeltaRangeMeters`` a carrier phase where its state is
valid. ``ConstellationType``: 1 GPS, 2 SBAS, 3 GLONASS, 4 QZSS, 5 BeiDou, 6 Galileo.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from selfnav.errors import InputError
from selfnav.io.gnss_raw import (BEIDOU, GALILEO, GLONASS, GPS, QZSS, SBAS, Ephemerides,
                                 GnssObservations, RawGnss, leap_seconds_at)
from selfnav.types import GnssData

C_LIGHT = 299_792_458.0
_CONST = {1: GPS, 2: SBAS, 3: GLONASS, 4: QZSS, 5: BEIDOU, 6: GALILEO}
WEEK_NS = 604800 * 10**9
DAY_NS = 86400 * 10**9
_INT_COLS = ("TimeNanos", "FullBiasNanos", "ReceivedSvTimeNanos")
_REQUIRED = ("TimeNanos", "FullBiasNanos", "Svid", "State", "ReceivedSvTimeNanos",
             "ConstellationType")
# State bits (android.location.GnssMeasurement)
CODE_LOCK, TOW_DECODED, GLO_TOD_DECODED, E1C_2ND = 1, 8, 128, 2048
TOW_KNOWN, GLO_TOD_KNOWN = 16384, 32768
ADR_VALID = 1


def _band_signal(system, f):
    """RINEX signal code from the carrier frequency (Hz)."""
    if not np.isfinite(f):
        return "1C"
    if system == GLONASS:
        return "1C" if f > 1.5e9 else "2C"
    if system == BEIDOU:
        return "2I" if abs(f - 1561.098e6) < 1e6 else ("5P" if f < 1.19e9 else "1P")
    if abs(f - 1176.45e6) < 1e6:
        return "5Q" if system in (GPS, QZSS, GALILEO) else "5I"
    return "1C"


def read_gnsslogger(path) -> RawGnss:
    """Read a GnssLogger log (``# Raw,...`` header line, then ``Raw,...`` rows).

    Returns
    -------
    RawGnss
        No ephemerides (give a navigation file); the phone's ``Fix`` lines as ``receiver``.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except OSError as e:
        raise InputError(path, f"cannot read ({e.strerror})") from None
    header, rows, rows_line, fixes = None, [], [], []
    for i, line in enumerate(lines, start=1):
        s = line.strip()
        if s.startswith("# Raw,") or s.startswith("#Raw,"):
            header = [h.strip() for h in s.lstrip("#").strip().split(",")]
        elif s.startswith("Raw,"):
            rows.append(s.split(","))
            rows_line.append(i)
        elif s.startswith("Fix,"):
            fixes.append((i, s.split(",")))
    if header is None:
        raise InputError(path, "no '# Raw,...' header line: not an Android GnssLogger log")
    col = {h: j for j, h in enumerate(header)}
    missing = [c for c in _REQUIRED if c not in col]
    if missing:
        raise InputError(path, f"the Raw header lacks {', '.join(missing)}")
    if not rows:
        raise InputError(path, "holds no Raw measurement lines")

    def ints(name):
        j = col[name]
        out = np.zeros(len(rows), np.int64)
        for k, r in enumerate(rows):
            v = r[j].strip() if j < len(r) else ""
            if not v:
                continue
            try:
                out[k] = int(v)
            except ValueError:
                try:
                    if name in _INT_COLS:
                        raise ValueError(v)
                    out[k] = int(float(v))
                except ValueError:
                    raise InputError(path, f"'{v}' is not an integer", row=rows_line[k],
                                     column=name) from None
        return out

    def floats(name, fill=np.nan):
        if name not in col:
            return np.full(len(rows), fill)
        j = col[name]
        out = np.full(len(rows), fill)
        for k, r in enumerate(rows):
            v = r[j].strip() if j < len(r) else ""
            if v:
                try:
                    out[k] = float(v)
                except ValueError:
                    raise InputError(path, f"'{v}' is not a number", row=rows_line[k],
                                     column=name) from None
        return out

    time_ns = ints("TimeNanos")
    full_bias = ints("FullBiasNanos")
    rx_sv_ns = ints("ReceivedSvTimeNanos")
    svid = ints("Svid")
    state = ints("State")
    ctype = ints("ConstellationType")
    bias = np.nan_to_num(floats("BiasNanos"), nan=0.0)
    offset = np.nan_to_num(floats("TimeOffsetNanos"), nan=0.0)
    sv_unc = floats("ReceivedSvTimeUncertaintyNanos")
    cn0 = floats("Cn0DbHz")
    prr = floats("PseudorangeRateMetersPerSecond")
    prr_unc = floats("PseudorangeRateUncertaintyMetersPerSecond")
    adr = floats("AccumulatedDeltaRangeMeters")
    adr_state = np.nan_to_num(floats("AccumulatedDeltaRangeState", 0.0)).astype(np.int64)
    freq = floats("CarrierFrequencyHz")
    leap_col = floats("LeapSecond")
    system = np.array([_CONST.get(int(c), 0) for c in ctype])
    freq = np.where(np.isfinite(freq), freq,
                    np.where(system == GLONASS, 1602e6, np.where(system == BEIDOU, 1561.098e6,
                                                                 1575.42e6)))
    keep = system > 0
    if not np.any(full_bias != 0):
        raise InputError(path, "FullBiasNanos is 0 on every row: the phone had no GPS time "
                               "(no pseudoranges can be formed)")
    # reception time, GPS ns since the GPS epoch, integer part and fraction kept apart. As in
    # ProcessGnssMeas.m, the bias of the first row of each stretch of continuous hardware
    # clock is used for the whole stretch: the phone re-estimates FullBiasNanos + BiasNanos at
    # every epoch, and following those steps would put clock jumps into the pseudoranges that
    # the Doppler does not have; the receiver clock (and its drift) is estimated instead
    disc = ints("HardwareClockDiscontinuityCount") if "HardwareClockDiscontinuityCount" in col \
        else np.zeros(len(rows), np.int64)
    seg_start = np.r_[True, disc[1:] != disc[:-1]]
    valid_bias = full_bias != 0
    first = np.zeros(len(rows), int)
    cur = -1
    for k in range(len(rows)):
        if seg_start[k] or cur < 0 or not valid_bias[cur]:
            cur = k
        first[k] = cur
    t_int = time_ns - full_bias[first]
    t_frac = offset - bias[first]
    leap_date = leap_seconds_at(float(np.median(time_ns - full_bias)) * 1e-9)
    leap = np.where(np.isfinite(leap_col), leap_col, leap_date).astype(np.int64)
    rx_sys = np.mod(t_int, WEEK_NS)
    bds = system == BEIDOU
    rx_sys = np.where(bds, np.mod(t_int - 14 * 10**9, WEEK_NS), rx_sys)
    glo = system == GLONASS
    rx_sys = np.where(glo, np.mod(t_int + (3 * 3600 - leap) * 10**9, DAY_NS), rx_sys)
    gal_tow = (system == GALILEO) & ((state & (TOW_DECODED | TOW_KNOWN)) != 0)
    gal_100 = (system == GALILEO) & ~gal_tow & ((state & E1C_2ND) != 0)
    rx_sys = np.where(gal_100, np.mod(t_int, 10**8), rx_sys)
    period = np.where(glo, DAY_NS, np.where(gal_100, 10**8, WEEK_NS))
    d_ns = rx_sys - np.where(gal_100, np.mod(rx_sv_ns, 10**8), rx_sv_ns)
    d_ns = np.where(d_ns > period // 2, d_ns - period, d_ns)
    d_ns = np.where(d_ns < -period // 2, d_ns + period, d_ns)
    pr = (d_ns.astype(float) + t_frac) * 1e-9 * C_LIGHT
    resolved = np.where(glo, (state & (GLO_TOD_DECODED | GLO_TOD_KNOWN)) != 0,
                        np.where(system == GALILEO, gal_tow | gal_100,
                                 (state & (TOW_DECODED | TOW_KNOWN)) != 0))
    valid = (keep & (full_bias != 0) & ((state & CODE_LOCK) != 0) & resolved
             & ~(sv_unc >= 500) & (pr > 1e7) & (pr < 5e7))
    pr = np.where(valid, pr, np.nan)
    t = (t_int.astype(float) + t_frac) * 1e-9      # the reception time the ranges refer to
    # epochs: one time tag per TimeNanos (the rows of an epoch share it)
    _, ep = np.unique(time_ns, return_inverse=True)
    t_ep = np.array([t[ep == k].min() for k in range(ep.max() + 1)])[ep]
    sig = np.array([_band_signal(s, f) for s, f in zip(system, freq)], dtype=object)
    glo_k = np.where(glo, np.round((freq - 1602e6) / 0.5625e6), 0).astype(int)
    svid_sys = np.where(system == QZSS, np.where(svid >= 193, svid - 192, svid), svid)
    doppler = -prr * freq / C_LIGHT
    cp = np.where((adr_state & ADR_VALID) != 0, adr * freq / C_LIGHT, np.nan)
    m = keep
    obs = GnssObservations.build(
        t_ep[m], system[m], svid_sys[m], sig[m], pseudorange=pr[m], doppler=doppler[m],
        carrier_phase=cp[m], cn0=cn0[m], pr_sigma=(sv_unc * 1e-9 * C_LIGHT)[m],
        doppler_sigma=(prr_unc * freq / C_LIGHT)[m], glo_k=glo_k[m], source=str(path))
    receiver = _fixes(path, fixes, int(np.median(leap)))
    return RawGnss(obs, Ephemerides.empty(), receiver, str(path),
                   {"rows": len(rows), "valid_pseudoranges": int(valid.sum())})


def _fixes(path, fixes, leap):
    """``Fix,Provider,Latitude,Longitude,Altitude,Speed,Accuracy,(UTC)TimeInMs``."""
    vals = []
    for line, f in fixes:
        try:
            lat, lon, alt, acc, ms = float(f[2]), float(f[3]), float(f[4]), float(f[6]), float(f[7])
        except (ValueError, IndexError):
            continue
        vals.append((ms / 1e3 - 315964800.0 + leap, lat, lon, alt, acc))
    if not vals:
        return None
    a = np.array(vals)
    a = a[np.argsort(a[:, 0], kind="stable")]
    return GnssData(a[:, 0], np.radians(a[:, 1]), np.radians(a[:, 2]), a[:, 3], a[:, 4] / np.sqrt(2),
                    None, np.full(len(a), 5), f"{path} (phone Fix)")
