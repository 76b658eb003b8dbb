"""Featherstone's articulated-body algorithm over trees of hinges, compiled
with numba: the kernels of the articulated tier (articulated.py).

Coordinates are the linear tier's and the reference's: bone b's joint is
two hinges at its pivot, dof 2b turning first about its axis as it sits in
the parent bone's frame, dof 2b + 1 about its axis after that turn. A dof's
parent dof is the one before it on the way to the root (2b's is the parent
bone's 2p + 1), and dofs are numbered parents first. Between a joint's two
hinges sits a massless body.

Spatial vectors are 6-rows (angular; linear) in world axes, taken at the
world origin (Featherstone 2008, "Rigid Body Dynamics Algorithms", ch. 2
and 7): a body's velocity is (omega, the velocity of its point at the
origin), so velocities and accelerations add down the tree without
shifting. Units: m, kg, s, rad, N, N m.

`accelerations` solves (M + diag(armature)) qdd = tau - bias(q, qd) + J^T f
in O(dofs): the armature carries what a step takes implicitly in each
hinge's own coordinate (its spring h^2 k), and gravity enters as the
base's acceleration.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _mat_vec(a, x, out):
    for i in range(a.shape[0]):
        s = 0.0
        for j in range(a.shape[1]):
            s += a[i, j] * x[j]
        out[i] = s


@njit(cache=True)
def _mat_mat(a, b, out):
    for i in range(a.shape[0]):
        for j in range(b.shape[1]):
            s = 0.0
            for k in range(a.shape[1]):
                s += a[i, k] * b[k, j]
            out[i, j] = s


@njit(cache=True)
def _dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@njit(cache=True)
def _solve(a, b, out):
    """x with a x = b for a small square `a` (Gaussian elimination with
    partial pivoting on copies; numba's np.linalg needs scipy)."""
    n = len(b)
    m = a.copy()
    x = b.copy()
    for c in range(n):
        r = c
        for i in range(c + 1, n):
            if abs(m[i, c]) > abs(m[r, c]):
                r = i
        if r != c:
            for j in range(n):
                m[c, j], m[r, j] = m[r, j], m[c, j]
            x[c], x[r] = x[r], x[c]
        for i in range(c + 1, n):
            f = m[i, c] / m[c, c]
            for j in range(c, n):
                m[i, j] -= f * m[c, j]
            x[i] -= f * x[c]
    for c in range(n - 1, -1, -1):
        s = x[c]
        for j in range(c + 1, n):
            s -= m[c, j] * out[j]
        out[c] = s / m[c, c]


@njit(cache=True)
def _turn(axis, angle, out):
    """Rotation matrix (3, 3) of `angle` rad about unit `axis` (Rodrigues)."""
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    x, y, z = axis[0], axis[1], axis[2]
    out[0, 0], out[0, 1], out[0, 2] = c + x * x * t, x * y * t - z * s, x * z * t + y * s
    out[1, 0], out[1, 1], out[1, 2] = y * x * t + z * s, c + y * y * t, y * z * t - x * s
    out[2, 0], out[2, 1], out[2, 2] = z * x * t - y * s, z * y * t + x * s, c + z * z * t


@njit(cache=True)
def _body_inertia(mass, com, inertia, out):
    """Spatial inertia (6, 6) at the origin of a body of `mass` kg with its
    centre of mass at `com` m and `inertia` (3, 3) kg m^2 about it."""
    cx = np.zeros((3, 3))
    cx[0, 1], cx[0, 2] = -com[2], com[1]
    cx[1, 0], cx[1, 2] = com[2], -com[0]
    cx[2, 0], cx[2, 1] = -com[1], com[0]
    for i in range(3):
        for j in range(3):
            cc = 0.0
            for k in range(3):
                cc += cx[i, k] * cx[k, j]
            out[i, j] = inertia[i, j] - mass * cc
            out[i, 3 + j] = mass * cx[i, j]
            out[3 + i, j] = -mass * cx[i, j]
            out[3 + i, 3 + j] = mass if i == j else 0.0


@njit(cache=True)
def _motion_cross(v, m, out):
    """v x m for spatial motion vectors (Featherstone's crm)."""
    a = np.empty(3)
    b = np.empty(3)
    _cross(v[:3], m[:3], a)
    out[:3] = a
    _cross(v[:3], m[3:], a)
    _cross(v[3:], m[:3], b)
    out[3:] = a + b


@njit(cache=True)
def _force_cross(v, f, out):
    """v x* f for a spatial motion v and force f (Featherstone's crf)."""
    a = np.empty(3)
    b = np.empty(3)
    _cross(v[:3], f[:3], a)
    _cross(v[3:], f[3:], b)
    out[:3] = a + b
    _cross(v[:3], f[3:], a)
    out[3:] = a


@njit(cache=True)
def kinematics(q, qd, dof_parent, rest_axis, bone_parent, pivot0, com_arm0, inertia0,
               rot, pivot, com, inertia, axis, vel, bias, floating, base_rot, base_pivot,
               base_vel):
    """Positions and velocities down the tree from hinge angles `q` and rates
    `qd` (D,): each dof's rotation relative to rest `rot` (D, 3, 3), pivot
    (D, 3), spatial axis (D, 6) and velocity (D, 6), its velocity-product
    acceleration `bias` (D, 6); each bone's COM (B, 3) and world inertia
    about it (B, 3, 3). A root bone b `floating` (B,) (uprooted) hangs its
    hinges on a free base: rotation `base_rot[b]` (3, 3) from rest, its
    pivot at `base_pivot[b]` m, spatial velocity `base_vel[b]` (6,)."""
    arm = np.empty(3)
    turned = np.empty(3)
    s = np.empty(3)
    r = np.empty((3, 3))
    frame_eye = np.eye(3)
    zero = np.zeros(6)
    for i in range(len(q)):
        b = i // 2
        if i % 2 == 0:
            pb = bone_parent[b]
            if pb < 0 and floating[b]:
                frame = base_rot[b]
                pivot[i] = base_pivot[b]
                v_parent = base_vel[b]
            elif pb < 0:
                frame = frame_eye
                pivot[i] = pivot0[b]
                v_parent = zero
            else:
                frame = rot[2 * pb + 1]
                arm[:] = pivot0[b] - pivot0[pb]
                _mat_vec(frame, arm, turned)
                pivot[i] = pivot[2 * pb + 1] + turned
                v_parent = vel[2 * pb + 1]
        else:
            frame = rot[i - 1]
            pivot[i] = pivot[i - 1]
            v_parent = vel[i - 1]
        _mat_vec(frame, rest_axis[i], s)
        axis[i, :3] = s
        _cross(pivot[i], s, turned)
        axis[i, 3:] = turned
        _turn(rest_axis[i], q[i], r)
        _mat_mat(frame, r, rot[i])
        vel[i] = v_parent + axis[i] * qd[i]
        _motion_cross(vel[i], axis[i] * qd[i], bias[i])
        if i % 2 == 1:
            _mat_vec(rot[i], com_arm0[b], turned)
            com[b] = pivot[i] + turned
            _mat_mat(rot[i], inertia0[b], r)
            for j in range(3):
                for k in range(3):
                    t = 0.0
                    for m in range(3):
                        t += r[j, m] * rot[i][k, m]
                    inertia[b, j, k] = t


@njit(cache=True)
def accelerations(dof_parent, frame_dof, same_limb, mass, com, inertia, axis, vel, bias, force,
                  torque, tau, armature, damp_rate, gravity, qd, past, h, cone_omega, cone_zeta,
                  cone_stiffness, art, art_bias, composite, momentum, qdd, floating, base_acc,
                  base_inertia):
    """Hinge accelerations `qdd` (D,) rad/s^2 from the state `kinematics`
    left, world `force` (B, 3) N at the bones' COMs and `torque` (B, 3) N m
    about them, hinge torques `tau` (D,) N m and `armature` (D,) kg m^2
    (both changed in place: damping and cones are added).

    Structural damping: each limb's block of the mass matrix times its own
    hinge rates, -damp_rate M_LL qd_L (the reference's), from the bones'
    velocities relative to their limb's frame bone (`frame_dof`: its dof
    2p + 1, -1 = the world), the side chains on a limb carried rigidly
    (`same_limb`: whether a dof is in its parent dof's limb).

    Cones: a hinge `past` its cone by that much (D,) rad (0: within it),
    at rates `qd` (D,) rad/s, meets a spring-damper of natural frequency
    `cone_omega` rad/s and damping ratio `cone_zeta` against the joint's
    articulated inertia, implicit over the step `h` s; the stiffness it
    had (N m/rad) goes to `cone_stiffness` (D,).

    A root bone b `floating` (B,) hangs on a free base (see `kinematics`):
    its spatial acceleration goes to `base_acc[b]` (6,), with gravity taken
    as the rest's, as the base's upward acceleration (the true one is
    base_acc[b] + (0, gravity)). The base is massless; what it carries is
    the tree's articulated inertia through the root's first hinge, which
    goes to `base_inertia[b]` (6, 6).

    Work arrays: art (D, 6, 6), art_bias (D, 6), composite (D, 6, 6),
    momentum (D, 6)."""
    n = len(qdd)
    tmp = np.empty(6)
    rel = np.empty(6)
    spin = np.empty(3)
    u_vec = np.empty(6)
    # outward: each body's own inertia and bias force (gyroscopic minus the loads)
    for i in range(n):
        art[i, :, :] = 0.0
        art_bias[i, :] = 0.0
        momentum[i, :] = 0.0
        if i % 2 == 1:
            b = i // 2
            _body_inertia(mass[b], com[b], inertia[b], art[i])
            _mat_vec(art[i], vel[i], tmp)
            _force_cross(vel[i], tmp, art_bias[i])
            _cross(com[b], force[b], spin)
            art_bias[i, :3] -= spin + torque[b]
            art_bias[i, 3:] -= force[b]
            fr = frame_dof[i]
            rel[:] = vel[i] if fr < 0 else vel[i] - vel[fr]
            _mat_vec(art[i], rel, momentum[i])
        composite[i] = art[i]
    # inward: composite inertias and each limb's momentum relative to its frame
    for i in range(n - 1, -1, -1):
        if damp_rate[i] > 0.0:
            tau[i] -= damp_rate[i] * _dot(axis[i], momentum[i])
        p = dof_parent[i]
        if p < 0:
            continue
        composite[p] += composite[i]
        if same_limb[i]:
            momentum[p] += momentum[i]
        elif p % 2 == 1:  # a side chain on bone p // 2, moving with it
            fr = frame_dof[p]
            rel[:] = vel[p] if fr < 0 else vel[p] - vel[fr]
            _mat_vec(composite[i], rel, tmp)
            momentum[p] += tmp
    # inward: articulated inertias
    u = np.empty(n)
    d = np.empty(n)
    big_u = np.empty((n, 6))
    for i in range(n - 1, -1, -1):
        _mat_vec(art[i], axis[i], u_vec)
        big_u[i] = u_vec
        d[i] = _dot(axis[i], u_vec)
        cone_stiffness[i] = 0.0
        if past[i] != 0.0:
            # q + h qd' past the cone, qd' the rate after the step
            k = d[i] * cone_omega * cone_omega
            c = 2.0 * cone_zeta * d[i] * cone_omega
            cone_stiffness[i] = k
            tau[i] -= k * past[i] + (h * k + c) * qd[i]
            armature[i] += h * h * k + h * c
        d[i] += armature[i]
        u[i] = tau[i] - _dot(axis[i], art_bias[i])
        p = dof_parent[i]
        if p < 0 and not floating[i // 2]:
            continue
        for j in range(6):
            for k in range(6):
                art[i, j, k] -= u_vec[j] * u_vec[k] / d[i]
        _mat_vec(art[i], bias[i], tmp)
        if p < 0:  # the free base's own equation: I_A a + p_A = 0
            base_inertia[i // 2] = art[i]
            _solve(art[i], -(art_bias[i] + tmp + u_vec * (u[i] / d[i])), base_acc[i // 2])
            continue
        art[p] += art[i]
        art_bias[p] += art_bias[i] + tmp + u_vec * (u[i] / d[i])
    # outward: accelerations (the base accelerates up at g: gravity)
    acc = momentum  # reused
    base = np.zeros(6)
    base[3:] = -gravity
    for i in range(n):
        p = dof_parent[i]
        if p < 0:
            a = (base_acc[i // 2] if floating[i // 2] else base) + bias[i]
        else:
            a = acc[p] + bias[i]
        qdd[i] = (u[i] - _dot(big_u[i], a)) / d[i]
        acc[i] = a + axis[i] * qdd[i]
