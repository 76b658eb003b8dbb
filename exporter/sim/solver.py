"""One interface for both solvers: the planar LOD (lod.py) and the MuJoCo
reference (reference/) each take the scene's trees and return a
`SolveResult` from `run()`; pipeline.py knows nothing else about them."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from .common import ProjectileTracks, TreeMotion


@dataclass
class SolveResult:
    """What a solver gives back. `motions`: per simulated tree (by name);
    `objects`: the projectiles' flight, or None; `meta`: deterministic facts
    for the bake (settings, counts); `notes`: what the solver adapted,
    clamped or left out, in words; `tiers`: per tree, which engines moved
    it and when they took it, in words; `timing`: seconds and per-frame
    costs, never in the bake file."""

    motions: dict[str, TreeMotion]
    objects: ProjectileTracks | None = None
    meta: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    tiers: dict[str, str] = field(default_factory=dict)
    timing: dict = field(default_factory=dict)


class TreeSink(Protocol):
    """Takes one simulated tree as soon as its motion is final: its index
    among the scene's rigged trees, its motion, and in words the engines
    that moved it (SolveResult.tiers)."""

    def __call__(self, index: int, motion: TreeMotion, engines: str) -> None: ...


class Solver(Protocol):
    """A solver: `run(progress, on_tree)` simulates the scene's active
    trees; `progress(done, total)` is called as it goes (any units,
    growing); with `on_tree` (TreeSink) each tree's motion goes there as
    soon as it is final and the result's `motions` stays empty."""

    def run(self, progress=None, on_tree: TreeSink | None = None) -> SolveResult: ...


def frame_timing(frame_seconds, substeps_per_frame: int) -> dict:
    """Physics time per frame (mean, p95) and per substep of the finest
    level (the frame's time over its substeps), ms."""
    f = np.asarray(frame_seconds, dtype=float)
    if not len(f):
        return {}
    mean, p95 = float(f.mean()), float(np.percentile(f, 95))
    return {"frame_mean_ms": round(1e3 * mean, 4), "frame_p95_ms": round(1e3 * p95, 4),
            "substep_mean_ms": round(1e3 * mean / substeps_per_frame, 5),
            "substep_p95_ms": round(1e3 * p95 / substeps_per_frame, 5)}
