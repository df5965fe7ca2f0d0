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
    out[0] = C
    for k in range(n):
        rodrigues(rotvec[k, 0], rotvec[k, 1], rotvec[k, 2], R)
        C = C @ R
        if k % 1000 == 999:
            C = 1.5 * C - 0.5 * C @ C.T @ C
        out[k + 1] = C
    return out
