"""The pymunk tier's plain records: what a run did, and the pose it starts
from (no pymunk here: the linear tier's runs read them without loading it)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Stats:
    """What a run did, for the bake's metadata and the console."""

    substeps: int = 0
    updates: int = 0
    bodies: int = 0
    bones: int = 0
    step_seconds: float = 0.0  # pymunk stepping and batch writes
    update_seconds: float = 0.0  # reads, reconstruction, loads, events
    inertia_floored: int = 0  # bodies whose rotary inertia the stability rule raised
    max_inertia_ratio: float = 1.0
    max_joint_gap: float = 0.0  # largest pivot separation / bone length at a frame
    limited: int = 0  # bone updates whose load was capped at MAX_ACCELERATION
    first_limit: tuple | None = None  # (tree, segment, time s, acceleration m/s^2)
    refined: int = 0  # substeps split into finer steps (blasts, hits, caps, fast spins)
    max_refine: int = 1  # the most steps a substep was split into
    refined_by: dict = field(default_factory=dict)  # load updates that split, by cause
    broken: int = 0
    debris: int = 0
    debris_clamped: int = 0  # debris body substeps whose spin was clamped (debris.MAX_SPIN)
    notes: list[str] = field(default_factory=list)
    frame_seconds: list[float] = field(default_factory=list)  # physics time of each frame


@dataclass
class StartState:
    """A pose handed over by the linear tier, per bone of the tier's trees:
    rotation relative to rest (B, 3, 3) and world angular velocity (B, 3),
    rad/s."""

    rot: np.ndarray
    omega: np.ndarray
