"""Broadcast navigation messages decoded from raw subframes (as u-blox RXM-SFRBX delivers them)
into ephemeris rows for :class:`~selfnav.io.gnss_raw.Ephemerides`.

* GPS / QZSS LNAV (IS-GPS-200 §20.3.3): subframes 1–3 (clock, orbit), subframe 4 page 18
  (Klobuchar α, β). u-blox gives each 30-bit word right-aligned with the D30* inversion already
  undone; bits 29..6 are the 24 data bits.
* Galileo I/NAV (Galileo OS SIS ICD §4.3.5): nominal pages (even + odd part, CRC-24Q checked),
  word types 1–5 (orbit, clock, BGD, health, NeQuick ai0–ai2).
* BeiDou D1 (BDS-SIS-ICD-B1I §5.2): subframes 1–3 of the MEO/IGSO satellites (clock, TGD,
  Klobuchar, orbit); u-blox gives the 30-bit words de-interleaved, parity in place.

Bit positions follow the ICDs (cross-checked with RTKLIB's ``rcvraw.c``). Each decoder keeps
the latest parts per satellite and emits a row when a consistent set is complete (equal
IODE / IODnav / AODE), once per issue.
"""
from __future__ import annotations

import numpy as np

from selfnav.io.gnss_raw import BDT_OFFSET_S, BDT_WEEK0, BEIDOU, GALILEO, GPS, GPS_WEEK_S

PI_SC = 3.1415926535898          # the ICDs' π for semicircles
URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0,
         3072.0, 6144.0)


def getbitu(buff: bytes, pos: int, length: int) -> int:
    """Unsigned big-endian bit field of ``length`` bits starting at bit ``pos``."""
    v = 0
    for i in range(pos, pos + length):
        v = (v << 1) | ((buff[i >> 3] >> (7 - (i & 7))) & 1)
    return v


def getbits(buff: bytes, pos: int, length: int) -> int:
    """Two's-complement signed bit field."""
    v = getbitu(buff, pos, length)
    return v - (1 << length) if v & (1 << (length - 1)) else v


def _pack(words, bits_each: int, shift: int = 0) -> bytes:
    """Concatenate the ``bits_each`` bits of each word (after ``>> shift``) into bytes."""
    total = 0
    n = 0
    for w in words:
        total = (total << bits_each) | ((int(w) >> shift) & ((1 << bits_each) - 1))
        n += bits_each
    pad = (-n) % 8
    total <<= pad
    return total.to_bytes((n + pad) // 8, "big")


def _near_week(week_mod: int, modulus: int, ref_week: int) -> int:
    """Full week number nearest ``ref_week`` of a truncated week count."""
    return week_mod + modulus * round((ref_week - week_mod) / modulus)


def _toe_abs(week: int, sow: float, t_ref: float) -> float:
    t = week * GPS_WEEK_S + sow
    return t + GPS_WEEK_S * round((t_ref - t) / GPS_WEEK_S)


class LnavDecoder:
    """GPS / QZSS LNAV subframes → ephemeris rows (``system`` GPS or QZSS)."""

    def __init__(self, system: int = GPS):
        self.system = system
        self.parts: dict = {}
        self.emitted: set = set()
        self.ion = None

    def add(self, prn: int, words, t_gps: float):
        """One subframe (10 words as u-blox gives them) received at GPS time ``t_gps``;
        returns an ephemeris row (dict) when subframes 1–3 of one issue are in, else None."""
        b = _pack(words, 24, 6)
        if getbitu(b, 0, 8) != 0x8B:
            return None
        sf = getbitu(b, 43, 3)
        if sf == 4:
            if getbitu(b, 50, 6) == 56:           # page 18: ionosphere and UTC
                a = [getbits(b, 56, 8) * 2.0**-30, getbits(b, 64, 8) * 2.0**-27,
                     getbits(b, 72, 8) * 2.0**-24, getbits(b, 80, 8) * 2.0**-24]
                be = [getbits(b, 88, 8) * 2.0**11, getbits(b, 96, 8) * 2.0**14,
                      getbits(b, 104, 8) * 2.0**16, getbits(b, 112, 8) * 2.0**16]
                self.ion = np.array(a + be)
            return None
        if sf not in (1, 2, 3):
            return None
        self.parts.setdefault(prn, {})[sf] = b
        p = self.parts[prn]
        if not all(k in p for k in (1, 2, 3)):
            return None
        s1, s2, s3 = p[1], p[2], p[3]
        iodc = (getbitu(s1, 70, 2) << 8) | getbitu(s1, 168, 8)
        iode2, iode3 = getbitu(s2, 48, 8), getbitu(s3, 216, 8)
        if not (iode2 == iode3 == (iodc & 0xFF)):
            return None
        week = _near_week(getbitu(s1, 48, 10), 1024, int(t_gps // GPS_WEEK_S))
        ura_i = getbitu(s1, 60, 4)
        sc = PI_SC
        toc = getbitu(s1, 176, 16) * 16.0
        toe = getbitu(s2, 216, 16) * 16.0
        row = dict(
            system=self.system, prn=prn, iode=float(iode2),
            health=float(getbitu(s1, 64, 6)), ura=URA_M[ura_i] if ura_i < 15 else np.nan,
            tgd=getbits(s1, 160, 8) * 2.0**-31,
            toc=_toe_abs(week, toc, t_gps), toe=_toe_abs(week, toe, t_gps),
            af2=getbits(s1, 192, 8) * 2.0**-55, af1=getbits(s1, 200, 16) * 2.0**-43,
            af0=getbits(s1, 216, 22) * 2.0**-31,
            crs=getbits(s2, 56, 16) * 2.0**-5, delta_n=getbits(s2, 72, 16) * 2.0**-43 * sc,
            m0=getbits(s2, 88, 32) * 2.0**-31 * sc, cuc=getbits(s2, 120, 16) * 2.0**-29,
            e=getbitu(s2, 136, 32) * 2.0**-33, cus=getbits(s2, 168, 16) * 2.0**-29,
            sqrt_a=getbitu(s2, 184, 32) * 2.0**-19,
            cic=getbits(s3, 48, 16) * 2.0**-29, omega0=getbits(s3, 64, 32) * 2.0**-31 * sc,
            cis=getbits(s3, 96, 16) * 2.0**-29, i0=getbits(s3, 112, 32) * 2.0**-31 * sc,
            crc=getbits(s3, 144, 16) * 2.0**-5, omega=getbits(s3, 160, 32) * 2.0**-31 * sc,
            omega_dot=getbits(s3, 192, 24) * 2.0**-43 * sc,
            idot=getbits(s3, 224, 14) * 2.0**-43 * sc)
        key = (prn, iodc, row["toe"])
        if key in self.emitted:
            return None
        self.emitted.add(key)
        return row


def crc24q(data: bytes) -> int:
    """CRC-24Q (Galileo, SBAS, RTCM 3), polynomial 0x1864CFB."""
    crc = 0
    for byte in data:
        crc ^= byte << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= 0x1864CFB
    return crc & 0xFFFFFF


class InavDecoder:
    """Galileo I/NAV nominal pages (E1-B or E5b-I, 8 words as u-blox gives them) → rows."""

    def __init__(self):
        self.words: dict = {}
        self.emitted: set = set()
        self.ion = None
        self.crc_errors = 0

    def add(self, prn: int, words, t_gps: float):
        b = _pack(words, 32)
        even, odd = b[:16], b[16:]
        if getbitu(even, 1, 1) or getbitu(odd, 1, 1):      # alert page
            return None
        if getbitu(even, 0, 1) != 0 or getbitu(odd, 0, 1) != 1:
            return None
        # CRC over 4 pad bits + 114 bits of the even part + 82 bits of the odd part
        bits = (getbitu(even, 0, 114) << 82) | getbitu(odd, 0, 82)
        if crc24q(bits.to_bytes(25, "big")) != getbitu(odd, 82, 24):
            self.crc_errors += 1
            return None
        data = ((getbitu(even, 2, 112) << 16) | getbitu(odd, 2, 16)).to_bytes(16, "big")
        wt = getbitu(data, 0, 6)
        if not 1 <= wt <= 5:
            return None
        self.words.setdefault(prn, {})[wt] = data
        w = self.words[prn]
        if wt == 5:
            self.ion = np.array([getbitu(data, 6, 11) * 0.25, getbits(data, 17, 11) * 2.0**-8,
                                 getbits(data, 28, 14) * 2.0**-15])
        if not all(k in w for k in range(1, 6)):
            return None
        iods = [getbitu(w[k], 6, 10) for k in range(1, 5)]
        if len(set(iods)) != 1:
            return None
        sc = PI_SC
        w1, w2, w3, w4, w5 = (w[k] for k in range(1, 6))
        week = int(t_gps // GPS_WEEK_S)
        i = 16
        toe = getbitu(w1, i, 14) * 60.0
        toc = getbitu(w4, 54, 14) * 60.0
        e5b_hs, e1b_hs = getbitu(w5, 67, 2), getbitu(w5, 69, 2)
        e5b_dvs, e1b_dvs = getbitu(w5, 71, 1), getbitu(w5, 72, 1)
        row = dict(
            system=GALILEO, prn=prn, iode=float(iods[0]),
            health=float((e1b_hs << 4) | (e1b_dvs << 3) | (e5b_hs << 1) | e5b_dvs),
            ura=np.nan, toe=_toe_abs(week, toe, t_gps), toc=_toe_abs(week, toc, t_gps),
            m0=getbits(w1, 30, 32) * 2.0**-31 * sc, e=getbitu(w1, 62, 32) * 2.0**-33,
            sqrt_a=getbitu(w1, 94, 32) * 2.0**-19,
            omega0=getbits(w2, 16, 32) * 2.0**-31 * sc, i0=getbits(w2, 48, 32) * 2.0**-31 * sc,
            omega=getbits(w2, 80, 32) * 2.0**-31 * sc, idot=getbits(w2, 112, 14) * 2.0**-43 * sc,
            omega_dot=getbits(w3, 16, 24) * 2.0**-43 * sc,
            delta_n=getbits(w3, 40, 16) * 2.0**-43 * sc, cuc=getbits(w3, 56, 16) * 2.0**-29,
            cus=getbits(w3, 72, 16) * 2.0**-29, crc=getbits(w3, 88, 16) * 2.0**-5,
            crs=getbits(w3, 104, 16) * 2.0**-5,
            cic=getbits(w4, 22, 16) * 2.0**-29, cis=getbits(w4, 38, 16) * 2.0**-29,
            af0=getbits(w4, 68, 31) * 2.0**-34, af1=getbits(w4, 99, 21) * 2.0**-46,
            af2=getbits(w4, 120, 6) * 2.0**-59,
            tgd2=getbits(w5, 47, 10) * 2.0**-32, tgd=getbits(w5, 57, 10) * 2.0**-32)
        key = (prn, iods[0], row["toe"])
        if key in self.emitted:
            return None
        self.emitted.add(key)
        return row


class BdsD1Decoder:
    """BeiDou D1 subframes 1–3 (MEO / IGSO satellites, PRN 6–58) → ephemeris rows."""

    def __init__(self):
        self.parts: dict = {}
        self.emitted: set = set()
        self.ion = None

    def add(self, prn: int, words, t_gps: float):
        if prn <= 5 or prn >= 59:          # GEO satellites broadcast D2
            return None
        b = _pack(words, 30)
        if getbitu(b, 0, 11) != 0x712:
            return None
        sf = getbitu(b, 15, 3)
        if sf not in (1, 2, 3):
            return None
        self.parts.setdefault(prn, {})[sf] = b
        p = self.parts[prn]
        if not all(k in p for k in (1, 2, 3)):
            return None
        s1, s2, s3 = p[1], p[2], p[3]
        sow = [(getbitu(s, 18, 8) << 12) | getbitu(s, 30, 12) for s in (s1, s2, s3)]
        if not (sow[1] - sow[0] == 6 and sow[2] - sow[1] == 6):
            return None

        def s2f(buff, p1, l1, p2, l2, signed=True):
            v = (getbitu(buff, p1, l1) << l2) | getbitu(buff, p2, l2)
            if signed and v & (1 << (l1 + l2 - 1)):
                v -= 1 << (l1 + l2)
            return v

        sc = PI_SC
        week = getbitu(s1, 60, 13) + BDT_WEEK0
        toc = s2f(s1, 73, 9, 90, 8, False) * 8.0
        toe = ((getbitu(s2, 290, 2) << 15) | s2f(s3, 42, 10, 60, 5, False)) * 8.0
        ura_i = getbitu(s1, 48, 4)
        self.ion = np.array([getbits(s1, 126, 8) * 2.0**-30, getbits(s1, 134, 8) * 2.0**-27,
                             getbits(s1, 150, 8) * 2.0**-24, getbits(s1, 158, 8) * 2.0**-24,
                             s2f(s1, 166, 6, 180, 2) * 2.0**11, getbits(s1, 182, 8) * 2.0**14,
                             getbits(s1, 190, 8) * 2.0**16, s2f(s1, 198, 4, 210, 4) * 2.0**16])
        t_bdt = t_gps - BDT_OFFSET_S
        row = dict(
            system=BEIDOU, prn=prn, iode=float(getbitu(s1, 287, 5)),
            health=float(getbitu(s1, 42, 1)), ura=URA_M[ura_i] if ura_i < 15 else np.nan,
            toc=_toe_abs(week, toc, t_bdt) + BDT_OFFSET_S,
            toe=_toe_abs(week, toe, t_bdt) + BDT_OFFSET_S,
            tgd=getbits(s1, 98, 10) * 1e-10, tgd2=s2f(s1, 108, 4, 120, 6) * 1e-10,
            af2=getbits(s1, 214, 11) * 2.0**-66, af0=s2f(s1, 225, 7, 240, 17) * 2.0**-33,
            af1=s2f(s1, 257, 5, 270, 17) * 2.0**-50,
            delta_n=s2f(s2, 42, 10, 60, 6) * 2.0**-43 * sc, cuc=s2f(s2, 66, 16, 90, 2) * 2.0**-31,
            m0=s2f(s2, 92, 20, 120, 12) * 2.0**-31 * sc,
            e=s2f(s2, 132, 10, 150, 22, False) * 2.0**-33, cus=getbits(s2, 180, 18) * 2.0**-31,
            crc=s2f(s2, 198, 4, 210, 14) * 2.0**-6, crs=s2f(s2, 224, 8, 240, 10) * 2.0**-6,
            sqrt_a=s2f(s2, 250, 12, 270, 20, False) * 2.0**-19,
            i0=s2f(s3, 65, 17, 90, 15) * 2.0**-31 * sc, cic=s2f(s3, 105, 7, 120, 11) * 2.0**-31,
            omega_dot=s2f(s3, 131, 11, 150, 13) * 2.0**-43 * sc,
            cis=s2f(s3, 163, 9, 180, 9) * 2.0**-31, idot=s2f(s3, 189, 13, 210, 1) * 2.0**-43 * sc,
            omega0=s2f(s3, 211, 21, 240, 11) * 2.0**-31 * sc,
            omega=s2f(s3, 251, 11, 270, 21) * 2.0**-31 * sc)
        key = (prn, row["iode"], row["toe"])
        if key in self.emitted:
            return None
        self.emitted.add(key)
        return row
