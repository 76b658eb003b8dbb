"""Twig tubes: the `@twig` pieces of a tree (model.Twigs) drawn as thin
straight tubes of bark, each skinned rigidly to the segment it grows on.

A twig has half the bark's sides (at least 3) and no caps: a twig is a
few millimetres across, and its ends hide in its parent or its leaves.
Units: metres; UV v runs along the twig in bark tiles (`bark_tile` m)."""

from __future__ import annotations

import numpy as np

from ..model import Twigs


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def twig_sides(radial: int) -> int:
    """Sides of a twig's tube for bark rings of `radial` sides."""
    return max(3, radial // 2)


def twig_tubes(twigs: Twigs, radial: int, min_radius: float, bark_tile: float):
    """Positions (V, 3) m, normals, UVs (V, 2), joints and weights (V, 2:
    rigid on the twig's segment), triangles (T, 3) (outward winding) and
    tangents (V, 3) along +u (around the tube; N x T runs along the twig,
    +v) of every twig's tube. Empty arrays when there are no twigs."""
    n, k = len(twigs), twig_sides(radial)
    start = twigs.start.astype(np.float64)
    end = twigs.end.astype(np.float64)
    axis = _unit(end - start)
    ref = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    a = _unit(np.cross(axis, ref))
    b = np.cross(axis, a)  # a, b, axis right-handed: the ring turns from a to b
    phi = 2 * np.pi * np.arange(k + 1) / k
    cos, sin = np.cos(phi), np.sin(phi)
    cos[k], sin[k] = 1.0, 0.0  # the seam column repeats column 0 exactly
    radial_dir = cos[None, :, None] * a[:, None, :] + sin[None, :, None] * b[:, None, :]
    around = -sin[None, :, None] * a[:, None, :] + cos[None, :, None] * b[:, None, :]
    radius = np.maximum(0.5 * twigs.width.astype(np.float64), min_radius)[:, None, None]
    rings = [start[:, None, :] + radius * radial_dir, end[:, None, :] + radius * radial_dir]
    positions = np.stack(rings, 1).reshape(-1, 3)  # twig, ring (start, end), column
    normals = np.broadcast_to(radial_dir[:, None], (n, 2, k + 1, 3)).reshape(-1, 3)
    tangents = np.broadcast_to(around[:, None], (n, 2, k + 1, 3)).reshape(-1, 3)
    length = np.linalg.norm(end - start, axis=1) / bark_tile
    u = np.broadcast_to(np.arange(k + 1) / k, (n, 2, k + 1))
    v = np.broadcast_to(np.stack([np.zeros(n), length], 1)[:, :, None], (n, 2, k + 1))
    uvs = np.stack([u, v], -1).reshape(-1, 2)
    seg = np.repeat(twigs.segment.astype(np.int64), 2 * (k + 1))
    joints = np.stack([seg, seg], 1)
    weights = np.tile([1.0, 0.0], (len(seg), 1))
    base = (np.arange(n) * 2 * (k + 1))[:, None] + np.arange(k)  # (n, k): start ring
    top = base + k + 1
    faces = np.concatenate([np.stack([base, base + 1, top + 1], -1),
                            np.stack([base, top + 1, top], -1)], 1).reshape(-1, 3)
    return positions, normals, uvs, joints, weights, faces.astype(np.int64), tangents
