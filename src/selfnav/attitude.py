"""Attitude: the seeds' DCM convention, Euler angles, quaternions, skew/vee, rotation vectors.

DESIGN §2. The navigation frame is ENU, the body frame RFU. The seeds' matrix
(seed 000 §2, seed 002 (4)) is

    C_n^b = R_y(γ) R_x(θ) R_z(ψ),   ψ = -heading,  θ = pitch,  γ = roll,

with ``R_*`` *frame* rotations. Its second row, the forward axis in ENU, is
``(cos θ sin H, cos θ cos H, sin θ)``. Equivalently ``C_b^n = (C_n^b)^T`` is scipy's
``Rotation.from_euler('ZXY', [ψ, θ, γ])``.

Quaternions are scalar-first ``(w, x, y, z)`` and represent ``C_b^n``.
All functions accept a single item or a stack with leading dimensions.
"""
from __future__ import annotations

import math

import numpy as np


def skew(v):
    """Skew matrix ``[v]`` with ``[v] u = v × u`` (DESIGN §2; fixes seed 002's (2,1) typo)."""
    v = np.asarray(v, dtype=float)
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack(
        [np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2
    )


def skew3(v):
    """:func:`skew` of one 3-vector (the per-epoch fast path of the filter)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotvec_to_dcm3(rv):
    """:func:`rotvec_to_dcm` of one rotation vector (the per-epoch fast path)."""
    th2 = float(rv @ rv)
    K = skew3(rv)
    if th2 < 1e-12:
        return np.eye(3) + K + 0.5 * (K @ K)
    th = np.sqrt(th2)
    return np.eye(3) + np.sin(th) / th * K + (1.0 - np.cos(th)) / th2 * (K @ K)


def vee(m):
    """Inverse of :func:`skew` (antisymmetric part)."""
    m = np.asarray(m, dtype=float)
    return 0.5 * np.stack(
        [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1
    )


def frame_rotation(axis: int, a):
    """Frame rotation about axis 0 (x), 1 (y) or 2 (z) by ``a`` rad (the factors of
    :func:`dcm_nb_from_euler`)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    if axis == 0:
        rows = [[o, z, z], [z, c, s], [z, -s, c]]
    elif axis == 1:
        rows = [[c, z, -s], [z, o, z], [s, z, c]]
    else:
        rows = [[c, s, z], [-s, c, z], [z, z, o]]
    return np.stack([np.stack(r, -1) for r in rows], -2)


def dcm_nb_from_euler(roll, pitch, heading):
    """``C_n^b`` (nav ENU -> body RFU) from roll, pitch, heading in rad (seed 000 (2.1)).

    Heading is clockwise from true North; the seeds' yaw is ``ψ = -heading``.
    """
    psi = -np.asarray(heading, dtype=float)
    return frame_rotation(1, roll) @ frame_rotation(0, pitch) @ frame_rotation(2, psi)


def dcm_bn_from_euler(roll, pitch, heading):
    """``C_b^n`` (body -> nav), the transpose of :func:`dcm_nb_from_euler`."""
    return np.swapaxes(dcm_nb_from_euler(roll, pitch, heading), -1, -2)


def euler_from_dcm_nb(C_nb):
    """Roll, pitch, heading (rad; heading in [0, 2π)) from ``C_n^b`` (one matrix takes a
    scalar path: the navigator's every returned state)."""
    C = np.asarray(C_nb, dtype=float)
    if C.shape == (3, 3):
        return (math.atan2(-C[0, 2], C[2, 2]), math.asin(min(max(C[1, 2], -1.0), 1.0)),
                math.atan2(C[1, 0], C[1, 1]) % (2.0 * math.pi))
    pitch = np.arcsin(np.clip(C[..., 1, 2], -1.0, 1.0))
    heading = np.mod(np.arctan2(C[..., 1, 0], C[..., 1, 1]), 2 * np.pi)
    roll = np.arctan2(-C[..., 0, 2], C[..., 2, 2])
    return roll, pitch, heading


def euler_from_dcm_bn(C_bn):
    """Roll, pitch, heading from ``C_b^n``."""
    return euler_from_dcm_nb(np.swapaxes(np.asarray(C_bn, dtype=float), -1, -2))


def euler_rates_to_body(roll, pitch, roll_rate, pitch_rate, heading_rate):
    """``ω_nb^b`` (body RFU, rad/s, shape (..., 3)) from Euler angles and their rates.

    Seed 002 (6) with the seeds' yaw rate ``ψ̇ = −heading rate`` (the convention of
    :func:`dcm_nb_from_euler`).
    """
    g, th = np.asarray(roll, float), np.asarray(pitch, float)
    gd, thd = np.asarray(roll_rate, float), np.asarray(pitch_rate, float)
    psid = -np.asarray(heading_rate, float)
    return np.stack([
        thd * np.cos(g) - psid * np.cos(th) * np.sin(g),   # seed 002, (6) row 1
        psid * np.sin(th) + gd,                             # row 2
        thd * np.sin(g) + psid * np.cos(th) * np.cos(g),    # row 3
    ], axis=-1)


def rotvec_to_dcm(rv):
    """Rotation vector -> active rotation matrix ``exp([rv])`` (Rodrigues), series-safe near 0."""
    rv = np.asarray(rv, dtype=float)
    th2 = np.sum(rv * rv, axis=-1)
    th = np.sqrt(th2)
    small = th < 1e-4
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0 + th2**2 / 120.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th2 / 24.0 + th2**2 / 720.0, (1.0 - np.cos(ths)) / ths**2)
    K = skew(rv)
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + a[..., None, None] * K + b[..., None, None] * (K @ K)


def dcm_to_rotvec(C):
    """Active rotation matrix -> rotation vector (angle in [0, π])."""
    C = np.asarray(C, dtype=float)
    q = dcm_to_quat(C)
    return quat_to_rotvec(q)


def quat_to_rotvec(q):
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., :1] < 0, -q, q)
    w = q[..., 0]
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    ang = 2.0 * np.arctan2(s, w)
    small = s < 1e-9
    k = np.where(small, 2.0 / np.where(small, np.maximum(w, 1e-300), 1.0), ang / np.where(small, 1.0, s))
    return v * k[..., None]


def rotvec_to_quat(rv):
    rv = np.asarray(rv, dtype=float)
    th = np.linalg.norm(rv, axis=-1)
    small = th < 1e-8
    k = np.where(small, 0.5 - th**2 / 48.0, np.sin(th / 2) / np.where(small, 1.0, th))
    return np.concatenate([np.cos(th / 2)[..., None], rv * k[..., None]], axis=-1)


def quat_to_dcm(q):
    """Unit quaternion (w, x, y, z) -> active rotation matrix."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def dcm_to_quat(C):
    """Active rotation matrix -> unit quaternion (w, x, y, z), w >= 0 (Shepperd's method)."""
    C = np.asarray(C, dtype=float)
    shape = C.shape[:-2]
    C = C.reshape(-1, 3, 3)
    tr = np.trace(C, axis1=1, axis2=2)
    cand = np.stack([tr, C[:, 0, 0], C[:, 1, 1], C[:, 2, 2]], axis=1)
    i = np.argmax(cand, axis=1)
    q = np.empty((C.shape[0], 4))
    for k in range(4):
        m = i == k
        if not np.any(m):
            continue
        c = C[m]
        if k == 0:
            s = 2.0 * np.sqrt(1.0 + tr[m])
            q[m] = np.stack([0.25 * s, (c[:, 2, 1] - c[:, 1, 2]) / s, (c[:, 0, 2] - c[:, 2, 0]) / s,
                             (c[:, 1, 0] - c[:, 0, 1]) / s], 1)
        elif k == 1:
            s = 2.0 * np.sqrt(1.0 + c[:, 0, 0] - c[:, 1, 1] - c[:, 2, 2])
            q[m] = np.stack([(c[:, 2, 1] - c[:, 1, 2]) / s, 0.25 * s, (c[:, 0, 1] + c[:, 1, 0]) / s,
                             (c[:, 0, 2] + c[:, 2, 0]) / s], 1)
        elif k == 2:
            s = 2.0 * np.sqrt(1.0 + c[:, 1, 1] - c[:, 0, 0] - c[:, 2, 2])
            q[m] = np.stack([(c[:, 0, 2] - c[:, 2, 0]) / s, (c[:, 0, 1] + c[:, 1, 0]) / s, 0.25 * s,
                             (c[:, 1, 2] + c[:, 2, 1]) / s], 1)
        else:
            s = 2.0 * np.sqrt(1.0 + c[:, 2, 2] - c[:, 0, 0] - c[:, 1, 1])
            q[m] = np.stack([(c[:, 1, 0] - c[:, 0, 1]) / s, (c[:, 0, 2] + c[:, 2, 0]) / s,
                             (c[:, 1, 2] + c[:, 2, 1]) / s, 0.25 * s], 1)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(shape + (4,))


def quat_multiply(p, q):
    """Hamilton product ``p ⊗ q`` (so that ``dcm(p ⊗ q) = dcm(p) @ dcm(q)``)."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        -1,
    )


def orthonormalize(C):
    """Nearest rotation matrix (polar decomposition via SVD)."""
    C = np.asarray(C, dtype=float)
    u, _, vt = np.linalg.svd(C)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, -1] *= d[..., None]
    return u @ vt


def slerp_dcm(t_src, C_src, t_dst):
    """Interpolate a DCM series ``(N, 3, 3)`` at times ``t_dst`` by spherical linear interpolation."""
    t_src = np.asarray(t_src, dtype=float)
    t_dst = np.asarray(t_dst, dtype=float)
    i = np.clip(np.searchsorted(t_src, t_dst, side="right") - 1, 0, len(t_src) - 2)
    span = t_src[i + 1] - t_src[i]
    u = np.clip((t_dst - t_src[i]) / span, 0.0, 1.0)
    C0 = C_src[i]
    dC = np.swapaxes(C0, -1, -2) @ C_src[i + 1]
    rv = dcm_to_rotvec(dC)
    return C0 @ rotvec_to_dcm(rv * u[:, None])


def triad_nb(f_b, omega_b):
    """Attitude ``C_n^b`` from the mean specific force and Earth rate in body axes (gyrocompass).

    Up is along ``f_b``, East along ``omega_b × f_b``, North completes ENU; the columns of
    ``C_n^b`` are these nav axes expressed in the body frame.
    """
    f_b = np.asarray(f_b, dtype=float)
    omega_b = np.asarray(omega_b, dtype=float)
    up = f_b / np.linalg.norm(f_b, axis=-1, keepdims=True)
    east = np.cross(omega_b, up)
    east = east / np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    return np.stack([east, north, up], axis=-1)
