"""What every solver takes and returns: trees to simulate and their motion."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..rig import Rig

MAX_ANGULAR_SPEED = 200.0  # rad/s: beyond this a bone is taken to be unstable
MAX_ACCELERATION = 2000.0  # m/s^2: external loads on a bone are capped here (reported)


@dataclass
class SimTree:
    """A rigged tree placed in the world, with what the scene does to it."""

    name: str
    rig: Rig  # in world coordinates
    planes: int = 1  # planar LOD only: bending planes per limb
    load_direction: np.ndarray | None = None  # unit horizontal, for plane choice
    cut: object | None = None  # scene CutSpec
    pulls: list = field(default_factory=list)  # scene PullSpecs on this tree
    active: bool = True


@dataclass
class TreeMotion:
    """Per-bone world motion at each frame: rotation relative to the rest
    pose as quaternions (F, B, 4) x y z w, and pivot positions (F, B, 3) m."""

    quaternions: np.ndarray
    pivots: np.ndarray
    events: list[str] = field(default_factory=list)
