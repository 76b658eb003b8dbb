"""The order of the stages: grow, rig, simulate, bake. The CLI, batch runs
and benchmarks call `bake_scene`; each stage's work is in its own module
(grow.py, sim/rigging.py, sim/run.py, bake.py)."""

from __future__ import annotations

import time
from dataclasses import replace

from .bake import Bake, bake_from
from .grow import grow
from .quality import Quality
from .resources import Budget, check, estimate
from .scene import Scene
from .sim.rigging import rig_scene
from .sim.run import simulate, solver_kind
from .sim.solver import SolveResult


def bake_scene(scene: Scene, solver: str = "planar", quality: Quality | None = None,
               log=None, progress=None, workers: int = 1,
               timestep: float | None = None, budget: Budget | None = None,
               scheduler: str | None = None) -> Bake:
    """Grow, rig, simulate and bake a scene. `solver`: "planar" (the planar
    LOD) or "full" (the MuJoCo reference); `quality` overrides the scene's
    (and every tree's); `log(text)` hears what people should; `progress
    (done, total)` is called as the simulation goes; `workers` processes
    share the planar LOD's chunks; `timestep` (s) is the full reference's
    step (default: its own); `budget` what it may use (resources.Budget;
    default: the machine's available memory, 100,000 segments a tree): a
    bake that would not fit is refused (InputError) before it simulates;
    `scheduler` a Dask scheduler's address (tcp://HOST:PORT) whose workers
    simulate the planar LOD's chunks instead of local processes.
    Deterministic: the same inputs and versions give the same bake,
    whatever `workers`."""
    started = time.perf_counter()
    kind = solver_kind(solver)  # before any work: a bake never switches engines silently
    scene = scene if quality is None else replace(scene, quality=quality)
    budget = budget or Budget()
    grown = grow(scene, budget)
    rigged = rig_scene(scene, grown, quality, log)
    need = estimate(sum(t.rig.model.n_segments for t in rigged.trees if t.active),
                    sum(t.rig.model.n_segments for t in rigged.trees if not t.active),
                    scene.frame_count, workers)
    if log:
        log(need.line())
    check(need, budget)
    timing: dict = {"grow_seconds": round(time.perf_counter() - started, 3)}
    result = SolveResult({})
    if any(t.active for t in rigged.trees):
        result = simulate(kind, rigged, scene, workers, timestep, log, progress, scheduler)
        timing.update(result.timing)
    bake = bake_from(scene, kind, grown, rigged, result, timing)
    bake.timing["wall_seconds"] = round(time.perf_counter() - started, 3)
    return bake
