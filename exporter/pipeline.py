"""The order of the stages: grow, rig, simulate, bake. The CLI, batch runs
and benchmarks call `bake_scene`; each stage's work is in its own module
(grow.py, sim/rigging.py, sim/run.py, bake.py)."""

from __future__ import annotations

import contextlib
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from . import loop
from .bake import Bake, TreeBaker, TreeStore, bake_meta, objects_bake, static_tree_bake
from .bake_file import BakeWriter, load_bake
from .grow import grow
from .quality import Quality
from .resources import Budget, check, estimate
from .scene import Scene
from .sim.rigging import rig_scene
from .sim.run import segments_held, simulate, solver_kind
from .sim.solver import SolveResult
from .versions import runtime_versions

ANNOUNCE_TREES = 500  # a shot this large takes seconds to grow and rig (10,000 trees: 12 s)


def bake_scene(scene: Scene, solver: str = "planar", quality: Quality | None = None,
               log=None, progress=None, workers: int = 1,
               timestep: float | None = None, budget: Budget | None = None,
               scheduler: str | None = None, path: str | Path | None = None) -> Bake:
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
    `path`: write the bake there (bake_file.py) tree by tree as the
    simulation finishes them, and return it read lazily from the file:
    memory follows the chunk, not the shot. Without it the Bake is in
    memory. Deterministic: the same inputs and versions give the same bake
    (and the same bytes, saved or streamed), whatever `workers`."""
    started = time.perf_counter()
    kind = solver_kind(solver)  # before any work: a bake never switches engines silently
    versions = runtime_versions()  # what makes the motion, as the bake starts
    scene = scene if quality is None else replace(scene, quality=quality)
    budget = budget or Budget()
    if log and len(scene.trees) >= ANNOUNCE_TREES:  # else the log is silent until the plan line
        log(f"growing and rigging {len(scene.trees):,} trees")
    grown = grow(scene, budget, workers)
    rigged = rig_scene(scene, grown, quality, log, workers)
    looping = loop.plan(scene, [t.rig for t in rigged.trees if t.active],
                        scene.wind.ramp if scene.wind else 0.0)
    run = scene if looping is None else looping.sim_scene(scene)  # with the loop's run-in
    animated = sum(t.rig.model.n_segments for t in rigged.trees if t.active)
    need = estimate(animated, sum(t.rig.model.n_segments for t in rigged.trees if not t.active),
                    run.frame_count, workers,
                    None if path is None else segments_held(kind, scene, workers))
    if log:
        log(need.line())
    check(need, budget)
    timing: dict = {"grow_seconds": round(time.perf_counter() - started, 3)}
    times = np.arange(scene.frame_count) / scene.fps
    with contextlib.ExitStack() as stack:
        if path is None:
            store = TreeStore(len(grown))
        else:
            store = stack.enter_context(BakeWriter(path, times, len(grown)))
        for i, (g, t) in enumerate(zip(grown, rigged.trees)):
            if not t.active:
                store.add(i, static_tree_bake(g, t.rig, rigged.static.get(t.name,
                                                                          "not simulated")))
        take = TreeBaker(grown, [t.rig for t in rigged.trees], store, looping,
                         [t.phase for t in scene.trees])
        result = SolveResult({})
        if any(t.active for t in rigged.trees):
            result = simulate(kind, rigged, run, workers, timestep, log, progress, scheduler,
                              on_tree=take)
            timing.update(result.timing)
        objects = objects_bake(result.objects)
        meta = bake_meta(scene, kind, rigged, result, versions)
        if looping is not None:
            meta["loop"] = looping.meta()
            meta["notes"] = meta.get("notes", []) + looping.notes()
            for line in [looping.line(), *looping.notes()] if log else ():
                log(line)
        store.finish(meta, objects)
    if path is None:
        bake = Bake(times, store.trees, meta, objects, order=store.order)
    else:
        bake = load_bake(path, lazy=True)
    bake.timing = dict(timing, wall_seconds=round(time.perf_counter() - started, 3))
    return bake

