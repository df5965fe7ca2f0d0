"""Strapdown mechanization in the ENU frame: the fast loop of seed 004 (DESIGN §2, §5).

One step turns the body increments ``Δθ_k = ∫ω_ib^b dt`` and ``Δv_k = ∫f^b dt`` over
``[t_{k-1}, t_k]`` into the new latitude, longitude, height, ENU velocity and attitude:

* **attitude** (seed 004 (3), Poisson ``Ṁ = M[ω_b] − [ω_γ]M`` solved exactly over the step):
  ``C_b^n(k) = exp(−[ζ_k]) C_b^n(k−1) exp([φ_k])`` with the body rotation vector
  ``φ_k = Δθ_k + Δθ_{k−1} × Δθ_k / 12`` (two-sample coning correction) and the rotation of the
  navigation frame ``ζ_k = ω_in^n Δt``, ``ω_in^n = ω_ie^n + ω_en^n`` evaluated mid-step, where
  ``ω_en^n = (−V_N/R_φ, V_E/R_λ, V_E tanφ/R_λ)`` and ``ω_ie^n = (0, Ω cosφ, Ω sinφ)``
  (seed 004 (2));
* **velocity** (seed 004 (6)–(9)): ``Δv^b`` plus the rotation term ``½Δθ×Δv + ⅙Δθ×(Δθ×Δv)``
  (exact for a constant rate; the second-order part removes a vertical bias ``ω²Δt²g/6`` that
  the vertical channel would amplify) and the two-sample sculling term
  ``(Δθ_{k−1}×Δv_k + Δv_{k−1}×Δθ_k)/12``, projected with ``(I − ½[ζ]) C_b^n(k−1)``, plus
  ``(g^n − (2ω_ie^n + ω_en^n) × V) Δt`` (seed 004 (6), exact) at the mid-step state extrapolated
  from the previous step;
* **gravity** (seed 004 (4)–(5)): Somigliana normal gravity with the height term
  (:func:`selfnav.earth.normal_gravity`; the seed's rounded γe, γp only with ``seed_gravity=True``),
  the deflection of the vertical ``(ξ, η)`` and the anomaly ``Δg``:
  ``g^n = (−γη, −γξ, −(γ + Δg))`` with ``ξ = Φ − φ``, ``η = (Λ − λ) cos φ`` (astronomic minus
  geodetic). **Sign note** (seed 004 (5)): used in (8) as ``V̇ = n − a``, the printed
  ``g_E = −γη_g, g_N = −γξ_g`` give the horizontal gravity ``+γη, +γξ``, the opposite of the
  usual geodetic sign of ξ, η; selfnav keeps the usual sign, so a plumb line deflected to the
  North (ξ < 0) gives a northward gravity component (tested);
* **position** (seed 004 (10)): trapezoidal velocity, radii at the mid-step latitude and height.

Step k uses the state at ``t_{k−1}`` and the increments of steps k−1 and k; the first step,
without a previous increment, takes it equal to the current one (no coning/sculling term).

The per-sample loop is one numba kernel shared by the batch call :func:`integrate` and the
streaming :class:`Strapdown`, so both give bit-identical results.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from selfnav.earth import SEED004_GAMMA_E, SEED004_GAMMA_P, WGS84, Ellipsoid
from selfnav.errors import SelfnavError
from selfnav.kernels import rodrigues
from selfnav.types import Trajectory

_VERTICAL = {"free": 0, "fixed": 1}
_NS = 15  # state: lat, lon, h, vE, vN, vU, C_bn (row-major 9)
# history: dθ_prev(3), dv_prev(3), ΔV^n_prev(3), Δlat_prev, Δh_prev, dt_prev, has_prev, step
_NH = 14


# --------------------------------------------------------------------------------------------
# numba kernel
# --------------------------------------------------------------------------------------------
@njit(cache=True)
def _gravity_sw(s2, w, h, a, f, m, ge, k):
    """Normal gravity from ``s2 = sin²φ`` and ``w = √(1 − e² s2)`` (seed 004 (4); TR8350.2 4-3)."""
    g0 = ge * (1.0 + k * s2) / w
    return g0 * (1.0 - 2.0 / a * (1.0 + f + m - 2.0 * f * s2) * h + 3.0 / (a * a) * h * h)


@njit(cache=True)
def _gravity(lat, h, a, e2, f, m, ge, k):
    """Normal gravity, identical to :func:`selfnav.earth.normal_gravity` (seed 004 (4))."""
    s2 = np.sin(lat) ** 2
    return _gravity_sw(s2, np.sqrt(1.0 - e2 * s2), h, a, f, m, ge, k)


@njit(cache=True)
def _mechanize(dth, dvb, dts, defl, anom, href, s, p, prm, out_pos, out_vel, out_C):
    """Advance the state ``s`` (and history ``p``) over all samples; write each new state.

    ``prm = (a, e2, f, m, γe, k, Ω, vertical_mode, coning, sculling)``.
    """
    a, e2, f, m, ge, kk, Om = prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6]
    vmode = int(prm[7])
    coning = prm[8] != 0.0
    sculling = prm[9] != 0.0
    C = np.empty((3, 3))
    Z = np.empty((3, 3))
    B = np.empty((3, 3))
    T = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = s[6 + 3 * i + j]
    nd, na, nh = defl.shape[0], anom.shape[0], href.shape[0]
    for k in range(dth.shape[0]):
        dt = dts[k]
        tx, ty, tz = dth[k, 0], dth[k, 1], dth[k, 2]
        ux, uy, uz = dvb[k, 0], dvb[k, 1], dvb[k, 2]
        lat, lon, h = s[0], s[1], s[2]
        vE, vN, vU = s[3], s[4], s[5]
        if p[12] != 0.0:
            px, py, pz = p[0], p[1], p[2]
            qx, qy, qz = p[3], p[4], p[5]
            r = 0.5 * dt / p[11]
            eE, eN, eU, elat, eh = r * p[6], r * p[7], r * p[8], r * p[9], r * p[10]
        else:
            px, py, pz = tx, ty, tz
            qx, qy, qz = ux, uy, uz
            eE = eN = eU = elat = eh = 0.0
        # ---- mid-step extrapolated state: rates, gravity, Coriolis (seed 004 (2), (4)-(6))
        latm = lat + elat
        hm = h + eh
        vEm, vNm, vUm = vE + eE, vN + eN, vU + eU
        sl, cl = np.sin(latm), np.cos(latm)
        tl = sl / cl
        s2 = sl * sl
        w = np.sqrt(1.0 - e2 * s2)
        RN = a / w
        RM = RN * (1.0 - e2) / (w * w)
        RNh = RN + hm
        RMh = RM + hm
        wieN, wieU = Om * cl, Om * sl
        wenE, wenN, wenU = -vNm / RMh, vEm / RNh, vEm * tl / RNh
        gam = _gravity_sw(s2, w, hm, a, f, m, ge, kk)
        kd = k if nd > 1 else 0
        ka = k if na > 1 else 0
        gE = -gam * defl[kd, 1]
        gN = -gam * defl[kd, 0]
        gU = -(gam + anom[ka])
        # ---- velocity (seed 004 (7)-(9)) with rotation and sculling corrections
        bx, by, bz = ux, uy, uz
        if sculling:
            # rotation term J_l(Δθ)Δv ≈ Δv + Δθ×Δv/2 + Δθ×(Δθ×Δv)/6 (exact for a constant rate)
            rx, ry, rz = ty * uz - tz * uy, tz * ux - tx * uz, tx * uy - ty * ux
            bx += 0.5 * rx + (ty * rz - tz * ry) / 6.0
            by += 0.5 * ry + (tz * rx - tx * rz) / 6.0
            bz += 0.5 * rz + (tx * ry - ty * rx) / 6.0
            # two-sample sculling
            bx += ((py * uz - pz * uy) + (qy * tz - qz * ty)) / 12.0
            by += ((pz * ux - px * uz) + (qz * tx - qx * tz)) / 12.0
            bz += ((px * uy - py * ux) + (qx * ty - qy * tx)) / 12.0
        nx = C[0, 0] * bx + C[0, 1] * by + C[0, 2] * bz
        ny = C[1, 0] * bx + C[1, 1] * by + C[1, 2] * bz
        nz = C[2, 0] * bx + C[2, 1] * by + C[2, 2] * bz
        zx, zy, zz = wenE * dt, (wieN + wenN) * dt, (wieU + wenU) * dt
        fE = nx - 0.5 * (zy * nz - zz * ny)
        fN = ny - 0.5 * (zz * nx - zx * nz)
        fU = nz - 0.5 * (zx * ny - zy * nx)
        cx, cy, cz = wenE, 2.0 * wieN + wenN, 2.0 * wieU + wenU
        corE = cy * vUm - cz * vNm
        corN = cz * vEm - cx * vUm
        corU = cx * vNm - cy * vEm
        vE1 = vE + fE + (gE - corE) * dt
        vN1 = vN + fN + (gN - corN) * dt
        vU1 = vU + fU + (gU - corU) * dt
        # ---- position (seed 004 (10)); the radii and trigonometry of the extrapolated
        # mid-step latitude serve the whole step (their error is ~1e-12 relative)
        if vmode == 1:
            h1 = href[k if nh > 1 else 0]
            vU1 = (h1 - h) / dt
        else:
            h1 = h + 0.5 * (vU + vU1) * dt
        hm = 0.5 * (h + h1)
        RNh = RN + hm
        RMh = RM + hm
        vEm, vNm = 0.5 * (vE + vE1), 0.5 * (vN + vN1)
        lat1 = lat + vNm * dt / RMh
        lon1 = lon + vEm * dt / (RNh * cl)
        # ---- attitude (seed 004 (3)): exact rotation of body and navigation frames
        zx = -vNm / RMh * dt
        zy = (wieN + vEm / RNh) * dt
        zz = (wieU + vEm * tl / RNh) * dt
        fx, fy, fz = tx, ty, tz
        if coning:
            fx += (py * tz - pz * ty) / 12.0
            fy += (pz * tx - px * tz) / 12.0
            fz += (px * ty - py * tx) / 12.0
        rodrigues(-zx, -zy, -zz, Z)
        rodrigues(fx, fy, fz, B)
        for i in range(3):
            for j in range(3):
                T[i, j] = C[i, 0] * B[0, j] + C[i, 1] * B[1, j] + C[i, 2] * B[2, j]
        for i in range(3):
            for j in range(3):
                C[i, j] = Z[i, 0] * T[0, j] + Z[i, 1] * T[1, j] + Z[i, 2] * T[2, j]
        p[13] += 1.0
        if p[13] >= 128.0:  # re-orthonormalize: C <- 1.5 C - 0.5 C C^T C
            p[13] = 0.0
            for i in range(3):
                for j in range(3):
                    T[i, j] = C[i, 0] * C[j, 0] + C[i, 1] * C[j, 1] + C[i, 2] * C[j, 2]
            for i in range(3):
                for j in range(3):
                    Z[i, j] = 1.5 * C[i, j] - 0.5 * (T[i, 0] * C[0, j] + T[i, 1] * C[1, j]
                                                     + T[i, 2] * C[2, j])
            for i in range(3):
                for j in range(3):
                    C[i, j] = Z[i, j]
        # ---- history for the next step
        p[0], p[1], p[2] = tx, ty, tz
        p[3], p[4], p[5] = ux, uy, uz
        p[6], p[7], p[8] = vE1 - vE, vN1 - vN, vU1 - vU
        p[9], p[10], p[11], p[12] = lat1 - lat, h1 - h, dt, 1.0
        s[0], s[1], s[2], s[3], s[4], s[5] = lat1, lon1, h1, vE1, vN1, vU1
        for i in range(3):
            for j in range(3):
                s[6 + 3 * i + j] = C[i, j]
                out_C[k, j, i] = C[i, j]  # C_nb = C_bn^T
        out_pos[k, 0], out_pos[k, 1], out_pos[k, 2] = lat1, lon1, h1
        out_vel[k, 0], out_vel[k, 1], out_vel[k, 2] = vE1, vN1, vU1


# --------------------------------------------------------------------------------------------
# Python API
# --------------------------------------------------------------------------------------------
@dataclass
class InsState:
    """Navigation state at one instant (rad, m, m/s; ``C_nb`` nav ENU -> body RFU)."""

    t: float
    lat: float
    lon: float
    h: float
    velocity_n: np.ndarray
    C_nb: np.ndarray


def _params(ellipsoid: Ellipsoid, seed_gravity: bool, vertical: str, coning: bool, sculling: bool):
    if vertical not in _VERTICAL:
        raise SelfnavError(f"unknown vertical channel mode '{vertical}' (use free or fixed)")
    ge, gp = (SEED004_GAMMA_E, SEED004_GAMMA_P) if seed_gravity else (ellipsoid.gamma_e,
                                                                      ellipsoid.gamma_p)
    k = (ellipsoid.b * gp) / (ellipsoid.a * ge) - 1.0  # as selfnav.earth.normal_gravity
    return np.array([ellipsoid.a, ellipsoid.e2, ellipsoid.f, ellipsoid.m, ge, k, ellipsoid.omega,
                     _VERTICAL[vertical], float(coning), float(sculling)])


def _per_sample(x, n, width, name):
    """Scalar/constant input -> (1, width); series -> (n, width); contiguous float64."""
    a = np.asarray(x, dtype=float)
    if width == 0:
        a = a.reshape(-1)
        if a.size not in (1, n):
            raise SelfnavError(f"{name}: expected a scalar or {n} values, got {a.size}")
        return np.ascontiguousarray(a)
    a = a.reshape(-1, width)
    if a.shape[0] not in (1, n):
        raise SelfnavError(f"{name}: expected one or {n} rows of {width}, got {a.shape[0]}")
    return np.ascontiguousarray(a)


class Strapdown:
    """Streaming strapdown INS (seed 004 fast loop (1)-(10)) in the ENU frame.

    Parameters
    ----------
    lat, lon, h : float
        Initial geodetic position, rad, rad, m.
    velocity_n : (3,)
        Initial ENU velocity, m/s.
    C_nb : (3, 3)
        Initial attitude, nav ENU -> body RFU (:func:`selfnav.attitude.dcm_nb_from_euler`).
    t : float
        Time of the initial state, s.
    ellipsoid : Ellipsoid
        Radii and normal gravity (WGS-84; seed 004 uses Krasovsky for the radii).
    seed_gravity : bool
        Seed 004 (4) rounded γe = 9.780, γp = 9.832 (18-33 mGal low, DESIGN §7).
    vertical : {"free", "fixed"}
        ``fixed`` holds the height at ``h_ref`` (height aiding: the unstable vertical channel is
        replaced by a reference height; ``V_U`` follows its differences).
    h_ref : float
        Reference height for ``vertical="fixed"`` (default: the initial height).
    deflection : (2,)
        Deflection of the vertical ``(ξ, η)``, rad (seed 004 (5); sign in the module docstring).
    anomaly : float
        Gravity anomaly ``Δg``, m/s².

    ``h_ref``, ``deflection`` and ``anomaly`` given here are constants; per-sample series go to
    :meth:`run` (or :func:`integrate`), per-step values to :meth:`update`.
    coning, sculling : bool
        Two-sample coning correction; velocity rotation and sculling terms (switch them off
        only to see what they are worth).

    Examples
    --------
    >>> ins = Strapdown(lat, lon, h, v0, C0)          # doctest: +SKIP
    >>> for dth, dv in stream: ins.update(dth, dv, 0.005)
    >>> ins.lat, ins.velocity_n, ins.C_nb
    """

    def __init__(self, lat, lon, h, velocity_n, C_nb, *, t=0.0, ellipsoid: Ellipsoid = WGS84,
                 seed_gravity: bool = False, vertical: str = "free", h_ref=None,
                 deflection=(0.0, 0.0), anomaly=0.0, coning: bool = True, sculling: bool = True):
        self.ellipsoid = ellipsoid
        self._prm = _params(ellipsoid, seed_gravity, vertical, coning, sculling)
        self.t = float(t)
        self._s = np.zeros(_NS)
        self._p = np.zeros(_NH)
        self.set_state(lat=lat, lon=lon, h=h, velocity_n=velocity_n, C_nb=C_nb)
        self.deflection = np.asarray(deflection, dtype=float)
        self.anomaly = np.asarray(anomaly, dtype=float)
        self.h_ref = np.asarray(h if h_ref is None else h_ref, dtype=float)
        self._fixed = None     # constant gravity inputs of advance(), built on first use

    # ---- state access
    def set_state(self, *, lat=None, lon=None, h=None, velocity_n=None, C_nb=None, check=True):
        """Overwrite parts of the state (a correction from an aiding filter).

        The extrapolation history keeps the last *increments*, so a reset does not disturb it.
        ``check=False`` skips the rotation-matrix test (for callers that build ``C_nb`` from
        rotations, e.g. a filter correcting at every step).
        """
        s = self._s
        if lat is not None:
            s[0] = float(lat)
        if lon is not None:
            s[1] = float(lon)
        if h is not None:
            s[2] = float(h)
        if velocity_n is not None:
            s[3:6] = np.asarray(velocity_n, dtype=float).reshape(3)
        if C_nb is not None:
            C = np.asarray(C_nb, dtype=float).reshape(3, 3)
            if check and not np.allclose(C @ C.T, np.eye(3), atol=1e-6):
                raise SelfnavError("C_nb is not a rotation matrix")
            s[6:15] = C.T.reshape(9)

    def state_array(self) -> np.ndarray:
        """The live state vector (lat, lon, h, v^n (3), C_b^n row-major (9)) for filters that
        correct it in place (compiled kernels); keep ``C_b^n`` a rotation."""
        return self._s

    @property
    def lat(self) -> float:
        return float(self._s[0])

    @property
    def lon(self) -> float:
        return float(self._s[1])

    @property
    def h(self) -> float:
        return float(self._s[2])

    @property
    def velocity_n(self) -> np.ndarray:
        return self._s[3:6].copy()

    @property
    def C_nb(self) -> np.ndarray:
        return self._s[6:15].reshape(3, 3).T.copy()

    @property
    def state(self) -> InsState:
        return InsState(self.t, self.lat, self.lon, self.h, self.velocity_n, self.C_nb)

    # ---- integration
    def _run(self, dtheta, dv, dt, h_ref, deflection, anomaly):
        n = dtheta.shape[0]
        pos = np.empty((n, 3))
        vel = np.empty((n, 3))
        C = np.empty((n, 3, 3))
        _mechanize(dtheta, dv, dt,
                   _per_sample(self.deflection if deflection is None else deflection, n, 2,
                               "deflection"),
                   _per_sample(self.anomaly if anomaly is None else anomaly, n, 0, "anomaly"),
                   _per_sample(self.h_ref if h_ref is None else h_ref, n, 0, "h_ref"),
                   self._s, self._p, self._prm, pos, vel, C)
        return pos, vel, C

    def update(self, dtheta, dv, dt, *, h_ref=None, deflection=None, anomaly=None) -> InsState:
        """Advance by one interval of body increments ``Δθ`` (rad) and ``Δv`` (m/s) over ``dt`` s.

        Returns the new :class:`InsState`; ``h_ref``, ``deflection``, ``anomaly`` override the
        constructor's values for this step.
        """
        dth = np.asarray(dtheta, dtype=float).reshape(1, 3)
        dvb = np.asarray(dv, dtype=float).reshape(1, 3)
        dt = float(dt)
        if not dt > 0.0:
            raise SelfnavError(f"time step must be positive, got {dt}")
        self._run(dth, dvb, np.array([dt]), None if h_ref is None else [h_ref],
                  None if deflection is None else np.reshape(deflection, (1, 2)),
                  None if anomaly is None else [anomaly])
        self.t += dt
        return self.state

    def advance(self, t, dt, dtheta, dv, *, states: bool = False):
        """The filter's fast path of :meth:`run`: advance over intervals of lengths ``dt``
        ending at times ``t`` (C-contiguous float64 arrays, checked by the caller) with the
        constructor's gravity options; returns the last attitude ``C_nb``, or with
        ``states`` every new state ``(pos (N, 3), vel (N, 3), C_nb (N, 3, 3))``."""
        n = dtheta.shape[0]
        pos = np.empty((n, 3))
        vel = np.empty((n, 3))
        C = np.empty((n, 3, 3))
        if self._fixed is None:
            self._fixed = (_per_sample(self.deflection, n, 2, "deflection"),
                           _per_sample(self.anomaly, n, 0, "anomaly"),
                           _per_sample(self.h_ref, n, 0, "h_ref"))
        defl, anom, href = self._fixed
        _mechanize(dtheta, dv, dt, defl, anom, href, self._s, self._p, self._prm, pos, vel, C)
        self.t = float(t[-1])
        return (pos, vel, C) if states else C[-1]

    def run(self, t, dtheta, dv, *, h_ref=None, deflection=None, anomaly=None) -> Trajectory:
        """Advance over a batch of intervals ending at times ``t`` (N,); returns the N new states.

        ``h_ref``, ``deflection`` and ``anomaly`` may be per-sample series here.
        """
        t = np.asarray(t, dtype=float).reshape(-1)
        dth = np.ascontiguousarray(np.asarray(dtheta, dtype=float).reshape(-1, 3))
        dvb = np.ascontiguousarray(np.asarray(dv, dtype=float).reshape(-1, 3))
        n = len(t)
        if dth.shape[0] != n or dvb.shape[0] != n:
            raise SelfnavError(f"dtheta, dv and t must have the same length ({dth.shape[0]}, "
                               f"{dvb.shape[0]}, {n})")
        dt = np.diff(np.concatenate([[self.t], t]))
        if n and not np.all(dt > 0.0):
            k = int(np.argmax(~(dt > 0.0)))
            raise SelfnavError(f"sample times must increase after the state time {self.t}: "
                               f"sample {k} at t = {t[k]}")
        pos, vel, C = self._run(dth, dvb, dt, h_ref, deflection, anomaly)
        if n:
            self.t = float(t[-1])
        return Trajectory(t, pos[:, 0], pos[:, 1], pos[:, 2], vel, C,
                          source="strapdown free-inertial")


def increments_from_rates(t, omega_ib_b, f_ib_b, t0=None):
    """Body increments from rates taken as the mean over the interval ending at each ``t``.

    Returns ``(dtheta, dv, t0)``; ``t0`` defaults to one median interval before ``t[0]``.
    """
    t = np.asarray(t, dtype=float)
    if t0 is None:
        t0 = t[0] - (float(np.median(np.diff(t))) if len(t) > 1 else 0.0)
    dt = np.diff(np.concatenate([[t0], t]))
    return np.asarray(omega_ib_b) * dt[:, None], np.asarray(f_ib_b) * dt[:, None], float(t0)


def integrate(t, dtheta, dv, lat0, lon0, h0, velocity0_n, C_nb0, *, t0=None, rates=False,
              **options) -> Trajectory:
    """Free-inertial integration of a whole record (batch form of :class:`Strapdown`).

    Parameters
    ----------
    t : (N,)
        End time of each interval, s.
    dtheta, dv : (N, 3)
        Body increments ``∫ω_ib^b dt`` (rad) and ``∫f^b dt`` (m/s); with ``rates=True`` the rates
        ``ω_ib^b`` (rad/s) and specific force ``f^b`` (m/s²), each the mean over its interval.
    lat0, lon0, h0, velocity0_n, C_nb0
        State at ``t0`` (rad, rad, m, m/s ENU, nav -> body DCM).
    t0 : float, optional
        Time of the initial state (default: one median interval before ``t[0]``).
    **options
        Keyword arguments of :class:`Strapdown` (``vertical``, ``h_ref``, ``deflection``,
        ``anomaly``, ``seed_gravity``, ``ellipsoid``, ``coning``, ``sculling``); ``h_ref``,
        ``deflection`` and ``anomaly`` may be per-sample series.

    Returns
    -------
    Trajectory
        N + 1 samples: the initial state at ``t0`` followed by the state at each ``t``.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    if len(t) == 0:
        raise SelfnavError("no IMU samples to integrate")
    if rates:
        dtheta, dv, t0 = increments_from_rates(t, dtheta, dv, t0)
    elif t0 is None:
        t0 = t[0] - (float(np.median(np.diff(t))) if len(t) > 1 else 0.0)
    series = {k: options.pop(k) for k in ("h_ref", "deflection", "anomaly") if k in options}
    ins = Strapdown(lat0, lon0, h0, velocity0_n, C_nb0, t=t0, **options)
    first = ins.state
    tr = ins.run(t, dtheta, dv, **series)
    return Trajectory(
        np.concatenate([[first.t], tr.t]), np.concatenate([[first.lat], tr.lat]),
        np.concatenate([[first.lon], tr.lon]), np.concatenate([[first.h], tr.h]),
        np.concatenate([first.velocity_n[None], tr.velocity_n]),
        np.concatenate([first.C_nb[None], tr.C_nb]), source="strapdown free-inertial")


def integrate_imu(imu, lat0, lon0, h0, velocity0_n, C_nb0, **options) -> Trajectory:
    """:func:`integrate` for an :class:`selfnav.io.ImuData` record (rates, mean over interval)."""
    return integrate(imu.t, imu.omega_ib_b, imu.f_ib_b, lat0, lon0, h0, velocity0_n, C_nb0,
                     rates=True, **options)


def slow_period_speed(velocity_n, k_m: int, *, dv=None, C_nb=None, dt=None, g=None):
    """Seed 004 (11): the mean speed over each slow period of ``k_m`` fast steps, m/s.

    **Erratum** (DESIGN §5): the seed prints ``ΔV = T0·|n|`` averaged over the period, the
    magnitude of the specific force, which contains gravity (≈ 9.8 m/s² at rest). Its use in
    (13), ``ΔS = T_M ΔV``, needs a speed, so selfnav reads (11) as the mean fast-loop speed
    ``|V|`` over the period (default). With ``dv``, ``C_nb``, ``dt`` and ``g`` given, it instead
    integrates the gravity-compensated along-path acceleration ``(C_b^n Δv^b − g^n Δt)·V̂``
    from the first speed of each period — the accelerometer-based reading the seed intends.

    Parameters
    ----------
    velocity_n : (N + 1, 3)
        Fast-loop ENU velocities (the state before and after each of the N steps).
    k_m : int
        Fast steps per slow period; the last incomplete period is dropped.
    dv, C_nb, dt, g : optional
        Body velocity increments (N, 3), attitudes (N + 1, 3, 3), step lengths (N,) and gravity
        magnitude (scalar or (N,)) for the accelerometer-based reading.

    Returns
    -------
    (M,) mean speed of each complete slow period, m/s.
    """
    v = np.asarray(velocity_n, dtype=float)
    n = len(v) - 1
    k_m = int(k_m)
    if k_m < 1 or n < k_m:
        raise SelfnavError(f"need at least k_m = {k_m} fast steps, got {n}")
    M = n // k_m
    if dv is None:
        speed = np.linalg.norm(v[1:M * k_m + 1], axis=1)
        return speed.reshape(M, k_m).mean(axis=1)
    C_bn = np.swapaxes(np.asarray(C_nb, dtype=float), -1, -2)
    dvn = np.einsum("nij,nj->ni", C_bn[:-1], np.asarray(dv, dtype=float))
    dvn[:, 2] -= np.broadcast_to(np.asarray(g, dtype=float), (n,)) * np.asarray(dt)
    u = v[:-1] / np.maximum(np.linalg.norm(v[:-1], axis=1, keepdims=True), 1e-9)
    along = np.sum(dvn * u, axis=1)[:M * k_m].reshape(M, k_m)
    start = np.linalg.norm(v[0:M * k_m:k_m], axis=1)
    return (start[:, None] + np.cumsum(along, axis=1)).mean(axis=1)
