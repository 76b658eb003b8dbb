"""Scene -> trees -> simulation -> Bake. The one place the stages meet;
the CLI, batch runs and benchmarks call `bake_scene`."""

from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from . import __version__
from .bake import Bake, tree_bake_from_model
from .errors import InputError
from .lsystem import derive, load_grammar
from .model import TreeModel, placed
from .rig import RigOptions, build_rig
from .rotations import qrotate
from .scene import Scene
from .sim.quality import QUALITIES, Quality
from .sim.audit import audit_motions, gain_notes
from .sim.common import SimTree, TreeMotion
from .sim.loads import SceneLoads
from .sim.projectiles import projectile_reaches
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


def tree_quality(scene: Scene, spec) -> Quality:
    return QUALITIES[spec.quality] if spec.quality else scene.quality


def prepare(scene: Scene, grown: list[GrownTree], loads: SceneLoads, quality: Quality | None,
            log=None) -> tuple[list[SimTree], list[Quality], dict[str, str], dict[str, int]]:
    """Rig every tree, give it its quality, and decide which need
    simulating. Static: trees the camera never sees (culling.py) and trees
    that no force reaches and start at rest (the prestress balances
    gravity). Trees the camera only ever sees from beyond `far` get its
    `far_quality`. Returns the trees, their qualities, why static ones are
    static, and how many trees each rule removed or coarsened."""
    log = log or (lambda msg: None)
    cuts = {c.tree: c for c in scene.cuts}
    pulls: dict[int, list] = {}
    for p in scene.pulls:
        pulls.setdefault(p.tree, []).append(p)
    bounds = [g.model.bounds() for g in grown]
    centres = np.array([0.5 * (lo + hi) for lo, hi in bounds])
    radii = np.array([0.5 * float(np.linalg.norm(hi - lo)) for lo, hi in bounds])
    seen = np.ones(len(grown), dtype=bool)
    far = np.zeros(len(grown), dtype=bool)
    if scene.camera is not None:
        from .culling import cull

        c = cull(scene.camera, scene.duration, centres, radii)
        seen, far = c.seen, c.nearest > scene.camera.far
    sim_trees, qualities, static = [], [], {}
    counts = {"unseen": 0, "far": 0, "no_force": 0}
    for i, g in enumerate(grown):
        m = g.model
        q = quality or tree_quality(scene, g.spec)
        if far[i] and quality is None and g.spec.quality is None and not scene.projectiles:
            q = QUALITIES[scene.camera.far_quality]
            counts["far"] += int(seen[i])
        lo, hi = bounds[i]
        reached = (not scene.prestress or i in cuts or i in pulls
                   or loads.quiet_after(centres[i], 0.5 * float(np.linalg.norm(hi[:2] - lo[:2])),
                                        float(hi[2])) > 0
                   or (scene.projectiles and projectile_reaches(scene, m)))
        active = bool(reached and seen[i])
        if not seen[i]:
            static[m.name] = "outside the camera's view for the whole shot"
            counts["unseen"] += 1
        elif not reached:
            static[m.name] = "no force reaches it (gravity is balanced by the prestress)"
            counts["no_force"] += 1
        rig = build_rig(m, RigOptions(min_bone_length=q.bone_length * max(m.height, 1e-3)))
        sim_trees.append(SimTree(m.name, rig, q.planes,
                                 load_direction(scene, loads, m, cuts.get(i), pulls.get(i)),
                                 cuts.get(i), pulls.get(i, []), active=active))
        qualities.append(q)
    if scene.camera is not None:
        log(f"culling: {counts['unseen']} trees never in view, {counts['far']} far "
            f"({scene.camera.far_quality}), {counts['no_force']} reached by no force")
    return sim_trees, qualities, static, counts


def bake_scene(scene: Scene, solver: str = "planar", quality: Quality | None = None,
               log=None, progress=None, workers: int = 1,
               timestep: float | None = None) -> Bake:
    """Grow, rig, simulate and bake a scene. `quality` overrides the scene's
    (and every tree's); `workers` processes share the planar LOD's chunks;
    `timestep` (s) is the full reference's step (default: its own).
    Deterministic: the same inputs give the same bake, whatever `workers`."""
    log = log or (lambda msg: None)
    started = time.perf_counter()
    if quality is not None:
        scene = replace(scene, quality=quality)
    q = scene.quality
    grown = grow(scene)
    lo = np.min([g.model.points.min(0) for g in grown], axis=0)
    hi = np.max([g.model.points.max(0) for g in grown], axis=0)
    extent = np.array([lo[:2] - 20, hi[:2] + 20])
    loads = SceneLoads(scene, extent)
    sim_trees, qualities, static, culled = prepare(scene, grown, loads, quality, log)
    active = [t for t in sim_trees if t.active]
    log(f"{len(grown)} trees, {len(active)} simulated, "
        f"{sum(t.rig.n_bones for t in active)} bones, solver {solver}, quality {q.name}")
    frames = scene.frame_count
    meta = {
        "tool": f"treebake {__version__}", "scene": scene.name, "scene_hash": scene.source_hash,
        "fps": scene.fps, "duration": scene.duration, "seed": scene.seed, "solver": solver,
        "quality": asdict(q), "prestress": scene.prestress, "gravity": scene.gravity,
        "culling": culled,  # trees removed or coarsened by each rule
        "frame_start": scene.frame_start,  # the exporters' number of frame 0
    }
    timing: dict = {"grow_seconds": round(time.perf_counter() - started, 3)}
    motions: dict[str, TreeMotion] = {}
    objects = None
    tiers: dict[str, str] = {}
    if active:
        if solver == "planar":
            from .sim.lod import PlanarLOD

            sim = PlanarLOD(sim_trees, qualities, scene, extent, workers, log)
        else:
            try:
                from .sim.reference import ReferenceSolver
            except ImportError:
                raise InputError("--solver full needs MuJoCo: pip install "
                                 "'treebake[reference]'") from None
            sim = ReferenceSolver(sim_trees, scene, q, loads, log=log, timestep=timestep)
        result = sim.run(progress)
        motions, objects, tiers = result.motions, result.objects, result.tiers
        meta.update(result.meta)
        meta["energy"] = audit_motions(motions, scene.fps)
        meta["notes"] = result.notes + gain_notes(meta["energy"])
        timing.update(result.timing)
    for note in meta.get("notes", []):
        log(note)
    trees = []
    for g, st_tree in zip(grown, sim_trees):
        info = {"grammar": _relative(g.spec.grammar, scene.file), "grammar_hash": g.grammar_hash,
                "seed": g.seed,
                "first_frequency_hz": round(st_tree.rig.first_frequency, 5),
                "bones": st_tree.rig.n_bones}
        motion = motions.get(g.model.name)
        if motion is None:
            info["static"] = static.get(g.model.name, "not simulated")
            pos, rot = segment_transforms(st_tree.rig, None, None)
        else:
            info["solver"] = tiers.get(g.model.name, solver)
            info["events"] = [e.record() for e in motion.events]
            pos, rot = segment_transforms(st_tree.rig, motion.quaternions, motion.pivots)
        tb = tree_bake_from_model(g.model, pos, rot, info)
        if motion is not None and len(motion.extra_times):  # fast turns: sub-frame samples
            extra_pos, extra_rot = segment_transforms(st_tree.rig, motion.extra_quaternions,
                                                      motion.extra_pivots)
            tb = replace(tb, extra_times=motion.extra_times,
                         extra_positions=extra_pos.astype(np.float32),
                         extra_rotations=extra_rot.astype(np.float32))
        trees.append(tb)
    timing["wall_seconds"] = round(time.perf_counter() - started, 3)
    return Bake(np.arange(frames) / scene.fps, trees, meta, objects, timing)


def _relative(path: Path, scene_file: str) -> str:
    """A grammar's path as the scene file names it (relative to the scene's
    folder), so a bake does not depend on where the checkout lives."""
    try:
        return Path(os.path.relpath(path, Path(scene_file).resolve().parent)).as_posix()
    except ValueError:  # another drive
        return Path(path).name


def segment_transforms(rig, quats: np.ndarray | None, pivots: np.ndarray | None):
    """Per-segment base positions (F, S, 3) and rotations (F, S, 4) from
    per-bone motion; segments of a merged bone move with it."""
    model = rig.model
    sb = rig.seg_bone
    rest_base = model.points[model.seg_start]
    if quats is None:
        rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, model.n_segments, 1))
        return rest_base[None].copy(), rot
    q = quats[:, sb]  # (F, S, 4)
    # each segment's base turned about its bone's pivot (rotating the one
    # vector by the quaternion: no matrices, 0.2x the time on a willow)
    pos = pivots[:, sb] + qrotate(q, rest_base - rig.pivot[sb])
    return pos, q
