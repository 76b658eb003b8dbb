"""Scene -> trees -> simulation -> Bake. The one place the stages meet;
the CLI, batch runs and benchmarks call `bake_scene`."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import __version__
from .bake import Bake, ObjectsBake, tree_bake_from_model
from .lsystem import derive, load_grammar
from .model import TreeModel, placed
from .rig import RigOptions, build_rig
from .rotations import apply, matrices_from_quaternions
from .scene import QUALITIES, Quality, Scene
from .sim.loads import SceneLoads
from .turtle import interpret


@dataclass
class GrownTree:
    spec: object  # TreeSpec
    model: TreeModel  # placed in the world
    grammar_hash: str
    seed: int


def grow(scene: Scene) -> list[GrownTree]:
    """Derive and interpret every tree of the scene, placed in the world.
    Identical (grammar, seed, iterations) are derived once."""
    grammars: dict[Path, object] = {}
    cache: dict[tuple, TreeModel] = {}
    out = []
    for spec in scene.trees:
        g = grammars.get(spec.grammar)
        if g is None:
            g = grammars[spec.grammar] = load_grammar(spec.grammar)
        seed = g.seed if spec.seed is None else spec.seed
        key = (spec.grammar, seed, spec.iterations)
        model = cache.get(key)
        if model is None:
            d = derive(g, seed, spec.iterations)
            model = cache[key] = interpret(d.modules, g, seed=seed)
        m = placed(model, spec.position, spec.rotation)
        m.name = spec.name
        out.append(GrownTree(spec, m, g.source_hash, seed))
    return out


def _horizontal(v) -> np.ndarray | None:
    v = np.array([v[0], v[1], 0.0], dtype=float)
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else None


def load_direction(scene: Scene, loads: SceneLoads, model: TreeModel,
                   cut, pulls=None) -> np.ndarray | None:
    """The dominant horizontal load direction on a tree, used to orient the
    planar LOD's bending planes."""
    base = model.points[0]
    if cut is not None:
        a = math.radians(cut.direction)
        return np.array([math.cos(a), math.sin(a), 0.0])
    for p in pulls or []:
        d = _horizontal(p.force)
        if d is not None:
            return d
    if loads.wind is not None:
        return loads.wind.direction.copy()
    for e in loads.explosions:
        d = _horizontal(base - e.position)
        if d is not None:
            return d
    for v in loads.vortices:
        d = _horizontal(base[:2] - v.centre(v.time))
        if d is not None:
            return np.array([-d[1], d[0], 0.0])  # swirl is tangential
    for a in loads.attractors:
        d = _horizontal(a.position - base)
        if d is not None:
            return d
    for p in scene.projectiles:
        d = _horizontal(p.velocity)
        if d is not None:
            return d
    return None


def _projectile_reaches(scene: Scene, model: TreeModel) -> bool:
    lo, hi = model.bounds()
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi[:2] - lo[:2])) + 1.0
    g = scene.gravity
    for p in scene.projectiles:
        pos = np.array(p.position, dtype=float)
        vel = np.array(p.velocity, dtype=float)
        for _ in range(2000):  # ballistic path until it lands, 10 ms steps
            if np.linalg.norm(pos[:2] - centre[:2]) < radius + p.size and pos[2] < hi[2] + p.size:
                return True
            vel[2] -= g * 0.01
            pos += vel * 0.01
            if pos[2] < -1:
                break
    return False


def tree_quality(scene: Scene, spec) -> Quality:
    return QUALITIES[spec.quality] if spec.quality else scene.quality


def bake_scene(scene: Scene, solver: str = "planar", quality: Quality | None = None,
               log=None, progress=None) -> Bake:
    """Grow, rig, simulate and bake a scene."""
    log = log or (lambda msg: None)
    started = time.perf_counter()
    q = quality or scene.quality
    if quality is not None:
        scene = replace(scene, quality=quality)
    grown = grow(scene)
    lo = np.min([g.model.points.min(0) for g in grown], axis=0)
    hi = np.max([g.model.points.max(0) for g in grown], axis=0)
    loads = SceneLoads(scene, np.array([lo[:2] - 20, hi[:2] + 20]))
    cuts = {c.tree: c for c in scene.cuts}
    pulls: dict[int, list] = {}
    for p in scene.pulls:
        pulls.setdefault(p.tree, []).append(p)
    from .sim.common import SimTree
    from .sim.planar import PlanarSolver

    sim_trees = []
    static_reasons = {}
    for i, g in enumerate(grown):
        m = g.model
        tq = tree_quality(scene, g.spec) if quality is None else q
        height = max(m.height, 1e-3)
        rig = build_rig(m, RigOptions(min_bone_length=tq.bone_length * height))
        tlo, thi = m.bounds()
        centre = 0.5 * (tlo + thi)
        radius = 0.5 * float(np.linalg.norm(thi[:2] - tlo[:2]))
        reached = (not scene.prestress or i in cuts or i in pulls
                   or loads.quiet_after(centre, radius, float(thi[2])) > 0
                   or (scene.projectiles and _projectile_reaches(scene, m)))
        if not reached:
            static_reasons[m.name] = "no force reaches it (gravity is balanced by prestress)"
        sim_trees.append(SimTree(m.name, rig, tq.planes,
                                 load_direction(scene, loads, m, cuts.get(i), pulls.get(i)),
                                 cuts.get(i), pulls.get(i, []), active=bool(reached)))
    active = [t for t in sim_trees if t.active]
    log(f"{len(grown)} trees, {len(active)} simulated, "
        f"{sum(t.rig.n_bones for t in active)} bones, quality {q.name}")
    frames = scene.frame_count
    times = np.arange(frames) / scene.fps
    meta = {
        "tool": f"treebake {__version__}", "scene": scene.name, "scene_hash": scene.source_hash,
        "fps": scene.fps, "duration": scene.duration, "seed": scene.seed, "solver": solver,
        "quality": q.__dict__, "prestress": scene.prestress, "gravity": scene.gravity,
    }
    motions = {}
    objects = None
    if active:
        if solver == "planar":
            sim = PlanarSolver(sim_trees, scene, q, loads, log=log)
            st = sim.stats
            if st.inertia_floored:
                msg = (f"stability: rotary inertia raised on {st.inertia_floored} of {st.bodies}"
                       f" bodies (up to {st.max_inertia_ratio:.1f}x) to keep "
                       f"h*omega <= {q.stability} at h = {sim.h * 1e3:.3f} ms")
                log(msg)
                st.notes.append(msg)
            for tree, motion in zip(active, sim.run(progress)):
                motions[tree.name] = motion
            meta["substep"] = sim.h
            meta["force_interval"] = sim.dt_update
            meta["stats"] = {"bodies": st.bodies, "bones": st.bones, "substeps": st.substeps,
                             "updates": st.updates, "step_seconds": round(st.step_seconds, 3),
                             "update_seconds": round(st.update_seconds, 3),
                             "inertia_floored": st.inertia_floored,
                             "max_inertia_ratio": round(st.max_inertia_ratio, 3),
                             "max_joint_gap": float(f"{st.max_joint_gap:.3g}")}
            meta["notes"] = st.notes
            if sim.projectiles is not None:
                pr = sim.projectiles
                objects = ObjectsBake(pr.shape, pr.size, pr.track_pos, pr.track_quat)
        else:
            from .sim.reference import ReferenceSolver

            ref = ReferenceSolver(sim_trees, scene, q, loads, log=log)
            for tree, motion in zip(active, ref.run(progress)):
                motions[tree.name] = motion
            meta.update(ref.meta())
            objects = ref.objects()
    trees = []
    for g, st_tree in zip(grown, sim_trees):
        info = {"grammar": str(g.spec.grammar), "grammar_hash": g.grammar_hash, "seed": g.seed,
                "first_frequency_hz": round(st_tree.rig.first_frequency, 5),
                "bones": st_tree.rig.n_bones}
        motion = motions.get(g.model.name)
        if motion is None:
            info["static"] = static_reasons.get(g.model.name, "not simulated")
            pos, rot = segment_transforms(st_tree.rig, None, None)
        else:
            info["events"] = motion.events
            pos, rot = segment_transforms(st_tree.rig, motion.quaternions, motion.pivots)
        trees.append(tree_bake_from_model(g.model, pos, rot, info))
    meta["wall_seconds"] = round(time.perf_counter() - started, 3)
    return Bake(times, trees, meta, objects)


def segment_transforms(rig, quats: np.ndarray | None, pivots: np.ndarray | None):
    """Per-segment base positions (F, S, 3) and rotations (F, S, 4) from
    per-bone motion; segments of a merged bone move with it."""
    model = rig.model
    sb = rig.seg_bone
    rest_base = model.points[model.seg_start]
    if quats is None:
        rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, model.n_segments, 1))
        return rest_base[None].copy(), rot
    frames = quats.shape[0]
    pos = np.empty((frames, model.n_segments, 3))
    rot = np.empty((frames, model.n_segments, 4))
    offset = rest_base - rig.pivot[sb]
    for f in range(frames):
        q = quats[f][sb]
        pos[f] = pivots[f][sb] + apply(matrices_from_quaternions(q), offset)
        rot[f] = q
    return pos, rot
