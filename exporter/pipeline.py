"""The order of the stages: grow, rig, simulate, bake. The CLI, batch runs
and benchmarks call `bake_scene`; each stage's work is in its own module
(grow.py, sim/rigging.py, sim/run.py, bake.py)."""

from __future__ import annotations

import time
from dataclasses import asdict, replace

import numpy as np

from . import __version__
from .bake import Bake, ObjectsBake, tree_bake_from_motion
from .grow import GrownTree, extent, grow
from .quality import Quality
from .scene import Scene
from .sim.events import summary
from .sim.loads import SceneLoads
from .sim.rigging import RiggedScene, rig_scene
from .sim.run import SolverKind, require_mujoco, simulate, solver_for
from .sim.solver import SolveResult
from .versions import runtime_versions


def bake_scene(scene: Scene, solver: str = "planar", quality: Quality | None = None,
               log=None, progress=None, workers: int = 1,
               timestep: float | None = None) -> Bake:
    """Grow, rig, simulate and bake a scene. `solver`: "planar" (the planar
    LOD) or "full" (the MuJoCo reference); `quality` overrides the scene's
    (and every tree's); `workers` processes share the planar LOD's chunks;
    `timestep` (s) is the full reference's step (default: its own).
    Deterministic: the same inputs and versions give the same bake,
    whatever `workers`."""
    log = log or (lambda msg: None)
    started = time.perf_counter()
    kind = SolverKind(solver)
    require_mujoco()  # before any work: a bake never switches engines silently
    if quality is not None:
        scene = replace(scene, quality=quality)
    grown = grow(scene)
    box = extent(grown)
    loads = SceneLoads(scene, box)
    rigged = rig_scene(scene, grown, loads, quality, log)
    log(f"{len(grown)} trees, {len(rigged.active)} simulated, "
        f"{sum(t.rig.n_bones for t in rigged.active)} bones, solver {kind}, "
        f"quality {scene.quality.name}")
    meta = bake_meta(scene, kind, rigged)
    timing: dict = {"grow_seconds": round(time.perf_counter() - started, 3)}
    result = SolveResult({})
    if rigged.active:
        sim = solver_for(kind, rigged, scene, loads, box, workers, timestep, log)
        result = simulate(sim, scene.fps, progress)
        meta.update(result.meta, notes=result.notes)
        timing.update(result.timing)
    for line in summary({name: m.events for name, m in result.motions.items()}):
        log(line)
    for note in result.notes:
        log(note)
    trees = bake_trees(grown, rigged, result, scene.file, kind)
    o = result.objects
    objects = None if o is None else ObjectsBake(o.shapes, o.sizes, o.positions, o.rotations)
    timing["wall_seconds"] = round(time.perf_counter() - started, 3)
    return Bake(np.arange(scene.frame_count) / scene.fps, trees, meta, objects, timing)


def bake_meta(scene: Scene, kind: SolverKind, rigged: RiggedScene) -> dict:
    """The bake's deterministic facts before simulating: what made it (the
    versions that decide its motion), the scene, its settings, and the
    trees culling left out."""
    return {
        "tool": f"treebake {__version__}", "versions": runtime_versions(),
        "scene": scene.name, "scene_hash": scene.source_hash,
        "fps": scene.fps, "duration": scene.duration, "seed": scene.seed, "solver": str(kind),
        "quality": asdict(scene.quality), "prestress": scene.prestress, "gravity": scene.gravity,
        "culling": rigged.culled,  # trees removed or coarsened by each rule
        "frame_start": scene.frame_start,  # the exporters' number of frame 0
    }


def bake_trees(grown: list[GrownTree], rigged: RiggedScene, result: SolveResult,
               scene_file: str, kind: SolverKind) -> list:
    """Every tree's bake (bake.TreeBake), with what made it: grammar, seed,
    frequency, bones, and for a simulated tree the engines and its events."""
    trees = []
    for g, sim_tree in zip(grown, rigged.trees):
        info = {"grammar": g.grammar_label(scene_file), "grammar_hash": g.grammar_hash,
                "seed": g.seed, "first_frequency_hz": round(sim_tree.rig.first_frequency, 5),
                "bones": sim_tree.rig.n_bones}
        motion = result.motions.get(g.model.name)
        if motion is None:
            info["static"] = rigged.static.get(g.model.name, "not simulated")
        else:
            info["solver"] = result.tiers.get(g.model.name, str(kind))
            info["events"] = [e.record() for e in motion.events]
        trees.append(tree_bake_from_motion(g.model, sim_tree.rig, motion, info))
    return trees
