"""Axis conversion from our world (Z up, m) to Y-up formats (glTF, OBJ, USD):
(x, y, z) -> (x, z, -y), a proper rotation of -90 degrees about X, applied
the same way to points, vectors and quaternions (x y z w)."""

from __future__ import annotations

import numpy as np


def points_y_up(p: np.ndarray) -> np.ndarray:
    """(..., 3) Z-up points or vectors -> Y-up."""
    p = np.asarray(p)
    return np.stack([p[..., 0], p[..., 2], 0.0 - p[..., 1]], axis=-1)  # 0 - 0 is +0, not -0


def quats_y_up(q: np.ndarray) -> np.ndarray:
    """(..., 4) x y z w rotations in the Z-up frame -> the same rotations
    expressed in the Y-up frame (the vector part turns like a vector)."""
    q = np.asarray(q)
    return np.stack([q[..., 0], q[..., 2], 0.0 - q[..., 1], q[..., 3]], axis=-1)


def points_z_up(p: np.ndarray) -> np.ndarray:
    """(..., 3) Y-up points or vectors -> Z-up (the inverse of points_y_up)."""
    p = np.asarray(p)
    return np.stack([p[..., 0], 0.0 - p[..., 2], p[..., 1]], axis=-1)


def quats_z_up(q: np.ndarray) -> np.ndarray:
    """(..., 4) x y z w rotations in the Y-up frame -> the Z-up frame."""
    q = np.asarray(q)
    return np.stack([q[..., 0], 0.0 - q[..., 2], q[..., 1], q[..., 3]], axis=-1)
