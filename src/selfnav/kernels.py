"""Shared numba kernels of the per-sample loops (rotations), one copy for every module.

Only small ``@njit`` functions live here, callable from other compiled loops (strapdown
mechanization, the moving-base observer) and from Python. Vectorized NumPy forms of the same
geometry are in :mod:`selfnav.attitude`.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def rodrigues(x, y, z, out):  # pragma: no cover - compiled
    """``exp([v])`` for the rotation vector ``v = (x, y, z)``, written into ``out`` (3, 3).

    Series below ``|v| = 0.01`` rad (truncation < 1e-21); the same matrix as
    :func:`selfnav.attitude.rotvec_to_dcm`.
    """
    th2 = x * x + y * y + z * z
    if th2 < 1e-4:
        A = 1.0 - th2 / 6.0 * (1.0 - th2 / 20.0 * (1.0 - th2 / 42.0))
        B = 0.5 - th2 / 24.0 * (1.0 - th2 / 30.0 * (1.0 - th2 / 56.0))
    else:
        th = np.sqrt(th2)
        A = np.sin(th) / th
        B = (1.0 - np.cos(th)) / th2
    out[0, 0] = 1.0 + B * (x * x - th2)
    out[0, 1] = -A * z + B * x * y
    out[0, 2] = A * y + B * x * z
    out[1, 0] = A * z + B * x * y
    out[1, 1] = 1.0 + B * (y * y - th2)
    out[1, 2] = -A * x + B * y * z
    out[2, 0] = -A * y + B * x * z
    out[2, 1] = A * x + B * y * z
    out[2, 2] = 1.0 + B * (z * z - th2)


@njit(cache=True)
def cumulative_rotation(rotvec):  # pragma: no cover - compiled
    """Products ``Q_k = exp([r_0]) ⋯ exp([r_{k−1}])`` (N+1, 3, 3) of N rotation vectors, ``Q_0 = I``.

    Re-orthonormalised (first order, ``Q ← 1.5 Q − 0.5 Q Qᵀ Q``) every 1000 steps against
    round-off.
    """
    n = rotvec.shape[0]
    out = np.empty((n + 1, 3, 3))
    C = np.eye(3)
    R = np.empty((3, 3))
    T = np.empty((3, 3))
    out[0] = C
    for k in range(n):
        rodrigues(rotvec[k, 0], rotvec[k, 1], rotvec[k, 2], R)
        mat3_mul(C, R, T)
        C[:, :] = T
        if k % 1000 == 999:
            C = 1.5 * C - 0.5 * C @ C.T @ C
        out[k + 1] = C
    return out


@njit(cache=True)
def rotation_log(R):  # pragma: no cover - compiled
    """Rotation vector of a rotation matrix ``R`` (angle in [0, π)), accurate for small angles.

    From the antisymmetric part ``v = vee(R − Rᵀ)/2 = sin θ · axis`` and ``cos θ = (tr R − 1)/2``:
    ``θ = atan2(|v|, cos θ)``, rotvec ``= v θ / sin θ`` (series below 1e-6 rad).
    """
    vx = 0.5 * (R[2, 1] - R[1, 2])
    vy = 0.5 * (R[0, 2] - R[2, 0])
    vz = 0.5 * (R[1, 0] - R[0, 1])
    s = np.sqrt(vx * vx + vy * vy + vz * vz)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    th = np.arctan2(s, c)
    f = 1.0 + th * th / 6.0 if s < 1e-6 else th / s
    out = np.empty(3)
    out[0], out[1], out[2] = f * vx, f * vy, f * vz
    return out


@njit(cache=True)
def mat3_mul(A, B, out):  # pragma: no cover - compiled
    """``out = A @ B`` for 3×3 matrices (no allocation, no BLAS call)."""
    for i in range(3):
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        for j in range(3):
            out[i, j] = a0 * B[0, j] + a1 * B[1, j] + a2 * B[2, j]


@njit(cache=True)
def mat3_tmul(A, B, out):  # pragma: no cover - compiled
    """``out = Aᵀ @ B`` for 3×3 matrices."""
    for i in range(3):
        a0, a1, a2 = A[0, i], A[1, i], A[2, i]
        for j in range(3):
            out[i, j] = a0 * B[0, j] + a1 * B[1, j] + a2 * B[2, j]


@njit(cache=True)
def nav_increments(C_nb, rotvec):  # pragma: no cover - compiled
    """Navigation-frame rotation vectors ``ζ_k = log(C_b^n(k) exp([r_k]) C_n^b(k+1))`` (N-1, 3)
    from attitudes ``C_nb`` (N, 3, 3) and body rotation vectors ``r`` (N-1, 3) (seed 002,
    form (b))."""
    n = rotvec.shape[0]
    out = np.empty((n, 3))
    B = np.empty((3, 3))
    T = np.empty((3, 3))
    E = np.empty((3, 3))
    for k in range(n):
        rodrigues(rotvec[k, 0], rotvec[k, 1], rotvec[k, 2], B)
        mat3_tmul(C_nb[k], B, T)
        mat3_mul(T, C_nb[k + 1], E)
        out[k] = rotation_log(E)
    return out


@njit(cache=True)
def relative_rotations(Q, k, part):  # pragma: no cover - compiled
    """Rotation vectors between consecutive orientations ``R_j = Q[k_j] exp([p_j])`` (M-1, 3):
    ``log(R_jᵀ R_{j+1})``."""
    m = k.shape[0]
    out = np.empty((max(m - 1, 0), 3))
    B = np.empty((3, 3))
    prev = np.empty((3, 3))
    cur = np.empty((3, 3))
    E = np.empty((3, 3))
    rodrigues(part[0, 0], part[0, 1], part[0, 2], B)
    mat3_mul(Q[k[0]], B, prev)
    for j in range(1, m):
        rodrigues(part[j, 0], part[j, 1], part[j, 2], B)
        mat3_mul(Q[k[j]], B, cur)
        mat3_tmul(prev, cur, E)
        out[j - 1] = rotation_log(E)
        prev[:, :] = cur
    return out


@njit(cache=True)
def inv3(A):  # pragma: no cover - compiled
    """Inverse of a 3×3 matrix by its adjugate (the sensor matrices ``I + S + M``: a call
    costs a fraction of ``numpy.linalg.inv``'s overhead)."""
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    d, e, f = A[1, 0], A[1, 1], A[1, 2]
    g, h, i = A[2, 0], A[2, 1], A[2, 2]
    co0, co1, co2 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * co0 + b * co1 + c * co2
    out = np.empty((3, 3))
    out[0, 0] = co0 / det
    out[1, 0] = co1 / det
    out[2, 0] = co2 / det
    out[0, 1] = (c * h - b * i) / det
    out[1, 1] = (a * i - c * g) / det
    out[2, 1] = (b * g - a * h) / det
    out[0, 2] = (b * f - c * e) / det
    out[1, 2] = (c * d - a * f) / det
    out[2, 2] = (a * e - b * d) / det
    return out


@njit(cache=True)
def median_abs_second_difference(x):  # pragma: no cover - compiled
    """Per column of ``x`` (N, 3) the median of ``|x_{k+1} − 2 x_k + x_{k−1}|``."""
    n = x.shape[0] - 2
    out = np.empty(x.shape[1])
    d = np.empty(n)
    for j in range(x.shape[1]):
        for k in range(n):
            d[k] = abs(x[k + 2, j] - 2.0 * x[k + 1, j] + x[k, j])
        out[j] = np.median(d)
    return out
