"""Geodetic datums of seed 004: SK-42 (Pulkovo 1942), PZ-90, PZ-90.11 and WGS-84 (DESIGN §5, §7).

Seven-parameter Helmert transforms between geocentric (ECEF) coordinates, with the parameter sets
of GOST 32453-2017 and GOST R 51794-2001 as named constants.

Sign convention
---------------
Every constant here is in the **coordinate-frame** convention of the GOST standards (and of EPSG
method 9607 / PROJ ``+convention=coordinate_frame``)::

    X_B = (dX, dY, dZ) + (1 + m) R X_A,     R = [[  1,  wz, -wy],
                                                 [-wz,   1,  wx],
                                                 [ wy, -wx,   1]]

with the angles ``wx, wy, wz`` in arc-seconds and the scale ``m`` in ppm (GOST R 51794-2001 §5,
GOST 32453-2017 §5). PROJ's ``+towgs84`` and ``+convention=position_vector`` use the transposed
rotation: the three angles change sign there (:meth:`HelmertParams.to_towgs84` does it). Copying the
GOST signs into ``+towgs84`` unchanged moves points by ``2 |w × r|``, 11-29 m over Russia
(``tests/test_datum.py`` shows it).

Inverse
-------
``helmert(xyz, p, inverse=True)`` is the **exact** inverse of the linear map above,
``X_A = ((1 + m) R)^{-1} (X_B - dX)`` (a 3 x 3 solve): a forward/inverse round trip is exact to
rounding (nanometres). The standards print the reverse direction as the same numbers with all
seven signs flipped (:meth:`HelmertParams.reversed`); that is a first-order inverse whose round
trip misses by ``|w × dX| + |w|² |X|``, about 0.6 mm for SK-42 (a translation of 160 m turned by
0.8″), so it is offered for comparison with printed values only.

Paths
-----
:func:`transform_path` picks the direct parameter set when one exists (every pair except
PZ-90 <-> PZ-90.11) and otherwise goes through WGS-84: PZ-90 -> WGS-84 (GOST R 51794-2001) ->
PZ-90.11 (GOST 32453-2017). Going through SK-42 instead would add the metre-level distortion of
the SK-42 realisation that the SK-42 sets average out; the geocentric sets agree to decimetres.

Geodetic <-> ECEF on each datum's ellipsoid is :func:`selfnav.earth.geodetic_to_ecef` and the
iterative inverse :func:`selfnav.earth.ecef_to_geodetic` (seed 004 notes that the inverse needs
iteration). SK-42 lives on the Krasovsky 1940 ellipsoid, PZ-90 and PZ-90.11 on the PZ-90
ellipsoid (a = 6378136 m, 1/f = 298.25784), WGS-84 on its own.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from selfnav.earth import KRASOVSKY, PZ90, WGS84, Ellipsoid, ecef_to_geodetic, geodetic_to_ecef
from selfnav.errors import SelfnavError

ARCSEC = np.pi / (180.0 * 3600.0)
PPM = 1e-6

#: Datum keys accepted everywhere (CLI ``--gnss-datum``/``--out-datum`` included).
DATUMS = ("wgs84", "pz90.11", "pz90", "sk42")

_ALIASES = {
    "wgs84": "wgs84", "wgs": "wgs84", "epsg4326": "wgs84",
    "pz90.11": "pz90.11", "pz9011": "pz90.11", "pz90_11": "pz90.11",
    "pz90": "pz90", "pz90.2001": "pz90",
    "sk42": "sk42", "pulkovo42": "sk42", "pulkovo1942": "sk42", "ск42": "sk42",
}

ELLIPSOIDS: dict[str, Ellipsoid] = {
    "wgs84": WGS84, "pz90.11": PZ90, "pz90": PZ90, "sk42": KRASOVSKY,
}


@dataclass(frozen=True)
class HelmertParams:
    """One GOST seven-parameter set, coordinate-frame convention (module docstring).

    Attributes
    ----------
    source, target : str
        Datum keys (:data:`DATUMS`): the set maps ``source`` ECEF to ``target`` ECEF.
    dx, dy, dz : float
        Translation, m.
    wx, wy, wz : float
        Rotations, arc-seconds (coordinate-frame sign).
    m : float
        Scale difference, ppm.
    standard : str
        Where the numbers come from.
    year : int
        Year of that standard.
    """

    source: str
    target: str
    dx: float
    dy: float
    dz: float
    wx: float
    wy: float
    wz: float
    m: float
    standard: str
    year: int

    @property
    def translation(self) -> np.ndarray:
        return np.array([self.dx, self.dy, self.dz])

    def matrix(self) -> np.ndarray:
        """``(1 + m) R``: the linear part of the map, GOST R 51794-2001 (coordinate frame)."""
        wx, wy, wz = self.wx * ARCSEC, self.wy * ARCSEC, self.wz * ARCSEC
        R = np.array([[1.0, wz, -wy], [-wz, 1.0, wx], [wy, -wx, 1.0]])
        return (1.0 + self.m * PPM) * R

    def reversed(self) -> "HelmertParams":
        """The reverse set as the standards print it: all seven signs flipped (first-order)."""
        return replace(self, source=self.target, target=self.source, dx=-self.dx, dy=-self.dy,
                       dz=-self.dz, wx=-self.wx, wy=-self.wy, wz=-self.wz, m=-self.m)

    def to_proj_helmert(self, convention: str = "coordinate_frame") -> str:
        """A PROJ ``+proj=helmert`` step for this set, in either PROJ convention.

        ``position_vector`` flips the three rotation signs so that both strings describe the
        same transformation.
        """
        if convention not in ("coordinate_frame", "position_vector"):
            raise ValueError(f"unknown convention {convention!r}")
        s = 1.0 if convention == "coordinate_frame" else -1.0
        return (f"+proj=helmert +x={self.dx!r} +y={self.dy!r} +z={self.dz!r} +rx={s * self.wx!r} "
                f"+ry={s * self.wy!r} +rz={s * self.wz!r} +s={self.m!r} +convention={convention}")

    def to_towgs84(self) -> str:
        """The ``+towgs84=`` value (PROJ position-vector convention: rotation signs flipped)."""
        v = (self.dx, self.dy, self.dz, -self.wx, -self.wy, -self.wz, self.m)
        return ",".join(repr(float(x)) for x in v)


# ------------------------------------------------------------------------------------------------
# The parameter sets of DESIGN §7 (GOST coordinate-frame signs, angles in ″, scale in ppm)
# ------------------------------------------------------------------------------------------------
SK42_TO_PZ9011 = HelmertParams("sk42", "pz90.11", 23.557, -140.844, -79.778, -0.0023, -0.34646,
                               -0.79421, -0.228, "GOST 32453-2017", 2017)
WGS84_TO_PZ9011 = HelmertParams("wgs84", "pz90.11", -0.013, 0.106, 0.022, -0.0023, 0.00354,
                                -0.00421, -0.008, "GOST 32453-2017", 2017)
#: Identical to EPSG:5044 "Pulkovo 1942 to WGS 84 (20)".
SK42_TO_WGS84 = HelmertParams("sk42", "wgs84", 23.57, -140.95, -79.80, 0.0, -0.35, -0.79, -0.22,
                              "GOST 32453-2017 (= EPSG:5044)", 2017)
SK42_TO_PZ90 = HelmertParams("sk42", "pz90", 25.0, -141.0, -80.0, 0.0, -0.35, -0.66, 0.0,
                             "GOST R 51794-2001", 2001)
#: Identical to EPSG "PZ-90 to WGS 84 (2)".
PZ90_TO_WGS84 = HelmertParams("pz90", "wgs84", -1.08, -0.27, -0.90, 0.0, 0.0, -0.16, -0.12,
                              "GOST R 51794-2001", 2001)

#: Every set of the DESIGN §7 table.
PARAMETER_SETS: tuple[HelmertParams, ...] = (
    SK42_TO_PZ9011, WGS84_TO_PZ9011, SK42_TO_WGS84, SK42_TO_PZ90, PZ90_TO_WGS84)

#: Route used where no direct set exists (module docstring, "Paths").
_VIA = {frozenset(("pz90", "pz90.11")): "wgs84"}


def datum_key(name: str) -> str:
    """Normalise a datum name (``"PZ-90.11"``, ``"SK-42"``, ``"wgs84"``...) to a key of DATUMS."""
    k = str(name).strip().lower().replace("-", "").replace(" ", "").replace("_", "")
    if k in _ALIASES:
        return _ALIASES[k]
    raise SelfnavError(f"unknown datum '{name}' (use one of: {', '.join(DATUMS)})")


def ellipsoid_of(datum: str) -> Ellipsoid:
    """The ellipsoid a datum's geodetic coordinates refer to."""
    return ELLIPSOIDS[datum_key(datum)]


def helmert(xyz, params: HelmertParams, inverse: bool = False):
    """Apply a Helmert set to ECEF coordinates (GOST R 51794-2001 §5, coordinate frame).

    Parameters
    ----------
    xyz : array_like, (..., 3)
        ECEF coordinates in ``params.source`` (or ``params.target`` when ``inverse``), m.
    params : HelmertParams
    inverse : bool
        Map target -> source with the exact inverse ``((1 + m) R)^{-1} (X - dX)`` (not the
        sign-flipped set; see the module docstring).

    Returns
    -------
    ndarray, (..., 3), m
    """
    xyz = np.asarray(xyz, dtype=float)
    M = params.matrix()
    if not inverse:
        return xyz @ M.T + params.translation
    return np.linalg.solve(M, (xyz - params.translation).reshape(-1, 3).T).T.reshape(xyz.shape)


def _edges() -> dict[tuple[str, str], tuple[HelmertParams, bool]]:
    e = {}
    for p in PARAMETER_SETS:
        e[(p.source, p.target)] = (p, False)
        e[(p.target, p.source)] = (p, True)
    return e


_EDGES = _edges()


def transform_path(src: str, dst: str) -> list[tuple[HelmertParams, bool]]:
    """The steps ``[(params, inverse), ...]`` that :func:`convert_ecef` applies from src to dst.

    A direct set when one exists; PZ-90 <-> PZ-90.11 goes through WGS-84 (module docstring).
    """
    src, dst = datum_key(src), datum_key(dst)
    if src == dst:
        return []
    if (src, dst) in _EDGES:
        return [_EDGES[(src, dst)]]
    via = _VIA.get(frozenset((src, dst)))
    if via is not None:
        return [_EDGES[(src, via)], _EDGES[(via, dst)]]
    # general fallback (not reached with the four datums): breadth-first search
    prev = {src: None}
    queue = deque([src])
    while queue:
        a = queue.popleft()
        for (u, v) in _EDGES:
            if u == a and v not in prev:
                prev[v] = u
                queue.append(v)
    if dst not in prev:
        raise SelfnavError(f"no datum transformation from {src} to {dst}")
    chain = [dst]
    while prev[chain[-1]] is not None:
        chain.append(prev[chain[-1]])
    chain.reverse()
    return [_EDGES[(u, v)] for u, v in zip(chain[:-1], chain[1:])]


def convert_ecef(xyz, src: str, dst: str):
    """ECEF coordinates in datum ``src`` to ECEF in datum ``dst``, m, shape ``(..., 3)``."""
    out = np.asarray(xyz, dtype=float)
    for params, inv in transform_path(src, dst):
        out = helmert(out, params, inverse=inv)
    return out


def convert(lat, lon, h, src: str, dst: str):
    """Geodetic coordinates from one datum to another.

    Parameters
    ----------
    lat, lon : array_like
        Geodetic latitude and longitude on ``src``'s ellipsoid, rad.
    h : array_like
        Ellipsoidal height, m.
    src, dst : str
        Datum names (:func:`datum_key`).

    Returns
    -------
    lat, lon, h : rad, rad, m on ``dst``'s ellipsoid.
    """
    xyz = geodetic_to_ecef(lat, lon, h, ellipsoid_of(src))
    return ecef_to_geodetic(convert_ecef(xyz, src, dst), ellipsoid_of(dst))


def ecef_to_geodetic_in(xyz, src: str, dst: str):
    """ECEF in ``src`` to geodetic ``(lat, lon, h)`` in ``dst`` (the seed 004 case: PZ-90 ECEF
    GNSS fixes in, SK-42 latitude and longitude out). Radians and metres."""
    return ecef_to_geodetic(convert_ecef(xyz, src, dst), ellipsoid_of(dst))


def geodetic_to_ecef_in(lat, lon, h, src: str, dst: str):
    """Geodetic ``(lat, lon, h)`` in ``src`` (rad, m) to ECEF in ``dst``, m."""
    return convert_ecef(geodetic_to_ecef(lat, lon, h, ellipsoid_of(src)), src, dst)
