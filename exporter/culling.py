"""Camera-aware culling, exact for offline work: the whole shot is known in
advance, so a tree the camera never sees is never simulated, and a tree that
stays far away for the whole shot is simulated at a coarser quality.

The camera moves linearly between its keys (position and target, m) and
holds its first and last keys outside them. Its view is a cone around the
viewing direction: half the horizontal field of view plus `margin`, widened
to cover a 16:9 frame's corners (vertical and diagonal extents), so the test
never culls what a frame could show. A tree is a sphere around its bounding
box; it is seen at an instant if any part of that sphere is in the cone.
The shot is sampled every 1/20 s and at every key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .scene import CameraSpec

SAMPLE_RATE = 20.0  # camera samples per second of the shot
ASPECT = 16.0 / 9.0  # frame width / height the field of view is widened for


@dataclass
class CullResult:
    seen: np.ndarray  # (T,) bool: inside the widened view at some instant
    nearest: np.ndarray  # (T,) m: closest approach of the camera to the tree's sphere


def camera_path(camera: CameraSpec, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera positions and unit viewing directions (N, 3) over the shot."""
    keys = camera.keys
    key_t = np.array([k[0] for k in keys])
    times = np.union1d(np.linspace(0.0, duration, max(2, int(duration * SAMPLE_RATE) + 1)),
                       key_t[(key_t >= 0) & (key_t <= duration)])
    pos = np.stack([np.interp(times, key_t, [k[1][a] for k in keys]) for a in range(3)], 1)
    tgt = np.stack([np.interp(times, key_t, [k[2][a] for k in keys]) for a in range(3)], 1)
    look = tgt - pos
    norm = np.linalg.norm(look, axis=1, keepdims=True)
    look = np.divide(look, norm, out=np.tile([1.0, 0.0, 0.0], (len(look), 1)), where=norm > 0)
    return pos, look


def half_angle(camera: CameraSpec) -> float:
    """The view cone's half angle (rad): the frame's diagonal plus the margin."""
    h = math.radians(camera.fov) / 2
    diagonal = math.atan(math.tan(h) * math.hypot(1.0, 1.0 / ASPECT))
    return min(diagonal + math.radians(camera.margin), math.pi)


def cull(camera: CameraSpec, duration: float, centres: np.ndarray,
         radii: np.ndarray) -> CullResult:
    """Which trees (spheres: centres (T, 3) m, radii (T,) m) the camera ever
    sees, and how close it ever comes to each."""
    pos, look = camera_path(camera, duration)
    cone = half_angle(camera)
    rel = centres[None, :, :] - pos[:, None, :]  # (N, T, 3)
    dist = np.linalg.norm(rel, axis=2)
    along = (rel * look[:, None, :]).sum(2)
    angle = np.arccos(np.clip(along / np.maximum(dist, 1e-9), -1.0, 1.0))
    # the sphere reaches into the cone if its angular radius covers the gap
    reach = np.arcsin(np.clip(radii[None, :] / np.maximum(dist, 1e-9), 0.0, 1.0))
    inside = (dist <= radii[None, :]) | (angle - reach <= cone)
    nearest = np.maximum(dist - radii[None, :], 0.0).min(axis=0)
    return CullResult(inside.any(axis=0), nearest)
