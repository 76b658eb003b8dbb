"""One interface for both solvers: the planar LOD (lod.py) and the MuJoCo
reference (reference.py) each take the scene's trees and return a
`SolveResult` from `run()`; pipeline.py knows nothing else about them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from .common import TreeMotion


@dataclass
class SolveResult:
    """What a solver gives back. `motions`: per simulated tree (by name);
    `objects`: projectile tracks (bake.ObjectsBake) or None; `meta`:
    deterministic facts for the bake (settings, counts); `notes`: what the
    solver adapted, clamped or left out, in words; `tiers`: per tree, which
    solver or tier moved it (and when it switched); `timing`: seconds and
    per-frame costs, never in the bake file. `handed_back`: where a run
    for the planar LOD stopped because its trees went back to the linear
    tier: (frame, hinge angles (2B,) rad, rates (2B,) rad/s), else None;
    `handed_on` likewise where it stopped for the pymunk tier."""

    motions: dict[str, TreeMotion]
    objects: object | None = None
    meta: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    tiers: dict[str, str] = field(default_factory=dict)
    timing: dict = field(default_factory=dict)
    handed_back: tuple | None = None
    handed_on: object | None = None  # linear.HandOff: where the articulated tier's run stopped
    # for an event only the pymunk tier handles (a joint near breaking, the ground, a cut)


class Solver(Protocol):
    def run(self, progress=None) -> SolveResult: ...


def frame_timing(frame_seconds, substeps_per_frame: int) -> dict:
    """Physics time per frame (mean, p95) and per substep of the finest
    level (the frame's time over its substeps), ms."""
    import numpy as np

    f = np.asarray(frame_seconds, dtype=float)
    if not len(f):
        return {}
    mean, p95 = float(f.mean()), float(np.percentile(f, 95))
    return {"frame_mean_ms": round(1e3 * mean, 4), "frame_p95_ms": round(1e3 * p95, 4),
            "substep_mean_ms": round(1e3 * mean / substeps_per_frame, 5),
            "substep_p95_ms": round(1e3 * p95 / substeps_per_frame, 5)}
