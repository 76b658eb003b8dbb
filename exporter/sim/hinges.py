"""Hinge coordinates: every joint is two hinges at its bone's pivot
(common.hinge_axes), composed down the tree, as MuJoCo composes them. The
linear tier's state and the reference's joints are these angles; the
pymunk tier converts to and from them."""

from __future__ import annotations

import numpy as np

from ..rotations import qmul_rows, qrotate_rows
from .common import Bones


def pose_frames(bones: Bones, qs: np.ndarray):
    """World rotations relative to rest as unit quaternions (F, B, 4), x y z
    w with w >= 0, and pivots (F, B, 3) of every bone from hinge angles
    (F, 2B): each joint turns its bone by its first hinge, then its second
    (about the axes as they sit in the parent's frame), composed down the
    tree, as MuJoCo composes two hinges. Computed as rows (structure of
    arrays), one depth of the tree at a time."""
    frames = qs.shape[0]
    nb = bones.n
    axes = bones.hinges
    half = 0.5 * qs.reshape(frames, nb, 2)
    rot = np.empty((4, frames, nb))
    piv = np.empty((3, frames, nb))
    parent, depth = bones.parent, bones.depth
    for d in range(int(depth.max()) + 1 if nb else 0):
        b = np.nonzero(depth == d)[0]
        own = None
        for k in range(2):
            s, c = np.sin(half[:, b, k]), np.cos(half[:, b, k])
            hinge = np.concatenate([s[None] * axes[b, k].T[:, None, :], c[None]])
            own = hinge if own is None else qmul_rows(own, hinge)
        if d == 0:
            rot[:, :, b] = own
            piv[:, :, b] = bones.pivot0[b].T[:, None, :]
        else:
            p = parent[b]
            fr = rot[:, :, p]
            rot[:, :, b] = qmul_rows(fr, own)
            arm = np.broadcast_to((bones.pivot0[b] - bones.pivot0[p]).T[:, None, :],
                                  (3, frames, len(b)))
            piv[:, :, b] = piv[:, :, p] + qrotate_rows(fr, arm)
    rot *= np.where(rot[3] < 0, -1.0, 1.0)
    return rot.transpose(1, 2, 0), piv.transpose(1, 2, 0)


def hinges_from_pose(bones: Bones, rot: np.ndarray, omega: np.ndarray):
    """The hinge angles q and rates v (2B,), rad and rad/s, of bones whose
    rotations relative to rest are `rot` (B, 3, 3) and world angular
    velocities `omega` (B, 3) rad/s: the inverse of pose_frames. Each joint's
    turn relative to its parent, L = R_parent^T R = Rot(n0, q0) Rot(n1, q1),
    takes the bone's axis a (n0, n1, a orthonormal, n1 = a x n0) to
    sin q1 n0 - cos q1 sin q0 n1 + cos q1 cos q0 a; its relative spin in the
    parent's rest frame is q0' n0 + q1' Rot(n0, q0) n1. A twist about the
    bone (which these hinges cannot hold) is dropped."""
    nb = bones.n
    has = bones.parent >= 0
    p = np.maximum(bones.parent, 0)
    frame = np.where(has[:, None, None], rot[p], np.eye(3))
    w_parent = np.where(has[:, None], omega[p], 0.0)
    local = np.einsum("bji,bjk->bik", frame, rot)  # R_parent^T R
    n0, n1 = bones.hinges[:, 0], bones.hinges[:, 1]
    axis = np.cross(n0, n1)  # a = n0 x n1 for n1 = a x n0
    turned = np.einsum("bij,bj->bi", local, axis)
    q1 = np.arcsin(np.clip((turned * n0).sum(1), -1.0, 1.0))
    q0 = np.arctan2(-(turned * n1).sum(1), (turned * axis).sum(1))
    w = np.einsum("bji,bj->bi", frame, omega - w_parent)  # relative spin, parent's rest frame
    c, s = np.cos(q0)[:, None], np.sin(q0)[:, None]
    n1_turned = c * n1 + s * np.cross(n0, n1)  # Rot(n0, q0) n1 (n0 . n1 = 0)
    q = np.stack([q0, q1], 1).reshape(2 * nb)
    v = np.stack([(w * n0).sum(1), (w * n1_turned).sum(1)], 1).reshape(2 * nb)
    return q, v


