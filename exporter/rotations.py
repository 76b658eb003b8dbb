"""Vectorised rotation helpers: rotation vectors, matrices, quaternions
(x, y, z, w order, as glTF)."""

from __future__ import annotations

import numpy as np


def matrices_from_rotvec(rho: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) from rotation vectors (N, 3) (Rodrigues)."""
    theta = np.linalg.norm(rho, axis=1)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6, np.sin(theta) / safe)
    b = np.where(small, 0.5 - theta**2 / 24, (1 - np.cos(theta)) / (safe * safe))
    x, y, z = rho[:, 0], rho[:, 1], rho[:, 2]
    r = np.empty((len(rho), 3, 3))
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    r[:, 0, 0] = 1 - b * (yy + zz)
    r[:, 0, 1] = -a * z + b * xy
    r[:, 0, 2] = a * y + b * xz
    r[:, 1, 0] = a * z + b * xy
    r[:, 1, 1] = 1 - b * (xx + zz)
    r[:, 1, 2] = -a * x + b * yz
    r[:, 2, 0] = -a * y + b * xz
    r[:, 2, 1] = a * x + b * yz
    r[:, 2, 2] = 1 - b * (xx + yy)
    return r


def rotvec_rate(rho: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Angular velocities (N, 3, rad/s) of exp(rho) (N, 3) while rho changes
    at `rate` (N, 3, rad/s): the exponential map's left Jacobian times the
    rate. It is the rate itself only while rho keeps its direction."""
    theta = np.linalg.norm(rho, axis=1)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24, (1 - np.cos(theta)) / (safe * safe))
    b = np.where(small, 1 / 6 - theta**2 / 120, (safe - np.sin(theta)) / safe**3)
    turned = cross(rho, rate)
    return rate + a[:, None] * turned + b[:, None] * cross(rho, turned)


def rotation_rows(rho: np.ndarray) -> np.ndarray:
    """Rotation matrices (3, 3, N) from rotation vectors (3, N): the
    structure-of-arrays form of matrices_from_rotvec (each entry a
    contiguous row, several times faster on small vectors)."""
    x, y, z = rho
    t2 = x * x + y * y + z * z
    theta = np.sqrt(t2)
    small = theta < 1e-8
    if small.any():
        safe = np.where(small, 1.0, theta)
        a = np.where(small, 1.0 - t2 / 6, np.sin(safe) / safe)
        b = np.where(small, 0.5 - t2 / 24, (1 - np.cos(safe)) / (safe * safe))
    else:  # the same values, without the series' work
        a = np.sin(theta) / theta
        b = (1 - np.cos(theta)) / (theta * theta)
    ax, ay, az = a * x, a * y, a * z
    bx = b * x
    by = b * y
    r = np.empty((3, 3) + x.shape)
    r[0, 0] = 1 - b * (t2 - x * x)
    r[0, 1] = bx * y - az
    r[0, 2] = bx * z + ay
    r[1, 0] = bx * y + az
    r[1, 1] = 1 - b * (t2 - y * y)
    r[1, 2] = by * z - ax
    r[2, 0] = bx * z - ay
    r[2, 1] = by * z + ax
    r[2, 2] = 1 - b * (x * x + y * y)
    return r


def turn_rows(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """r v for matrices (3, 3, N) and vectors (3, N): (3, N)."""
    return r[:, 0] * v[0] + r[:, 1] * v[1] + r[:, 2] * v[2]


def qmul_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a b for quaternions as rows (4, ...), x y z w."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def qrotate_rows(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Vectors v (3, ...) turned by unit quaternions q (4, ...), as rows."""
    u, w = q[0:3], q[3]
    t = 2.0 * cross_rows(u, v)
    return v + w * t + cross_rows(u, t)


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for vectors as rows (3, N)."""
    first = a[1] * b[2] - a[2] * b[1]
    out = np.empty((3,) + first.shape, first.dtype)  # np.stack costs as much again
    out[0] = first
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of (..., 3) arrays (several times faster than np.cross,
    which dominates small per-update workloads)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    first = a1 * b2 - a2 * b1
    out = np.empty(first.shape + (3,))  # the broadcast shape, without broadcast_shapes' cost
    out[..., 0] = first
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def apply(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """r (N, 3, 3) times v (N, 3), written out so each row is computed alone."""
    return (r[:, :, 0] * v[:, 0:1] + r[:, :, 1] * v[:, 1:2] + r[:, :, 2] * v[:, 2:3])


def apply_transposed(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """r^T (N, 3, 3) times v (N, 3)."""
    return (r[:, 0, :] * v[:, 0:1] + r[:, 1, :] * v[:, 1:2] + r[:, 2, :] * v[:, 2:3])


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b for stacks of 3x3 matrices."""
    out = np.empty_like(a)
    for j in range(3):
        out[:, :, j] = apply(a, b[:, :, j])
    return out


def quaternions_from_matrices(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (N, 4) in x, y, z, w order, w >= 0."""
    m00, m11, m22 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    tr = m00 + m11 + m22
    q = np.empty((len(r), 4))
    cases = np.stack([tr, m00, m11, m22], axis=1).argmax(axis=1)
    for case in range(4):
        sel = cases == case
        if not sel.any():
            continue
        m = r[sel]
        if case == 0:
            s = np.sqrt(tr[sel] + 1.0) * 2
            q[sel] = np.stack([(m[:, 2, 1] - m[:, 1, 2]) / s, (m[:, 0, 2] - m[:, 2, 0]) / s,
                               (m[:, 1, 0] - m[:, 0, 1]) / s, 0.25 * s], axis=1)
        elif case == 1:
            s = np.sqrt(1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2]) * 2
            q[sel] = np.stack([0.25 * s, (m[:, 0, 1] + m[:, 1, 0]) / s,
                               (m[:, 0, 2] + m[:, 2, 0]) / s, (m[:, 2, 1] - m[:, 1, 2]) / s],
                              axis=1)
        elif case == 2:
            s = np.sqrt(1.0 + m[:, 1, 1] - m[:, 0, 0] - m[:, 2, 2]) * 2
            q[sel] = np.stack([(m[:, 0, 1] + m[:, 1, 0]) / s, 0.25 * s,
                               (m[:, 1, 2] + m[:, 2, 1]) / s, (m[:, 0, 2] - m[:, 2, 0]) / s],
                              axis=1)
        else:
            s = np.sqrt(1.0 + m[:, 2, 2] - m[:, 0, 0] - m[:, 1, 1]) * 2
            q[sel] = np.stack([(m[:, 0, 2] + m[:, 2, 0]) / s, (m[:, 1, 2] + m[:, 2, 1]) / s,
                               0.25 * s, (m[:, 1, 0] - m[:, 0, 1]) / s], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
    return q


def matrices_from_quaternions(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) from quaternions (N, 4) x, y, z, w."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - z * w)
    r[:, 0, 2] = 2 * (x * z + y * w)
    r[:, 1, 0] = 2 * (x * y + z * w)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - x * w)
    r[:, 2, 0] = 2 * (x * z - y * w)
    r[:, 2, 1] = 2 * (y * z + x * w)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def rotvecs_from_matrices(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (N, 3) of rotation matrices (N, 3, 3), angles in [0, pi]."""
    q = quaternions_from_matrices(r)  # w >= 0
    s = np.linalg.norm(q[:, :3], axis=1)
    angle = 2 * np.arctan2(s, q[:, 3])
    scale = np.where(s > 1e-12, angle / np.maximum(s, 1e-300), 2.0)
    return q[:, :3] * scale[:, None]


# quaternion helpers (x y z w, float64, vectorised over leading axes)


def dot_last(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(a * b).sum(-1) for float32/float64 a and b with the same last axis,
    component by component: the same products added in the same order
    (the same bits, but for the sign of a zero sum), several times faster
    than numpy's reduction over a short last axis (3 or 4) of a large array."""
    if a.shape[-1] != b.shape[-1]:
        raise ValueError(f"last axes differ: {a.shape} and {b.shape}")
    out = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        out += a[..., k] * b[..., k]
    return out


def norm_last(x: np.ndarray) -> np.ndarray:
    """np.linalg.norm(x, axis=-1) for real x, the same bits (dot_last)."""
    return np.sqrt(dot_last(x, x))


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def qconj(q: np.ndarray) -> np.ndarray:
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def qrotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors v (..., 3) by unit quaternions q (..., 4)."""
    u = q[..., :3]
    w = q[..., 3:4]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) between unit quaternions (..., 4), for q and -q
    alike, accurate near zero (2 arccos(a.b) is not: float32 keys 1 ulp apart
    would read as 0.04 degrees)."""
    s = np.where(dot_last(a, b)[..., None] < 0, -1.0, 1.0)
    d = norm_last(a - s * b)
    return 4.0 * np.arcsin(np.clip(0.5 * d, 0.0, 1.0))


def qnormalize(q: np.ndarray) -> np.ndarray:
    return q / norm_last(q)[..., None]


def continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs along `axis` (time) so consecutive quaternions have a
    non-negative dot product."""
    q = np.moveaxis(q, axis, 0)
    dots = (q[1:] * q[:-1]).sum(-1)
    sign = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    out = q.copy()
    out[1:] *= sign[..., None]
    return np.moveaxis(out, 0, axis)


def slerp(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Shortest-path slerp of unit quaternions (..., 4), t (...)."""
    d = dot_last(a, b)
    b = np.where(d[..., None] < 0, -b, b)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    small = theta < 1e-6
    st = np.where(small, 1.0, np.sin(theta))
    wa = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / st)
    wb = np.where(small, t, np.sin(t * theta) / st)
    return qnormalize(wa[..., None] * a + wb[..., None] * b)
