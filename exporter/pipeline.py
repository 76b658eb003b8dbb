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
from .bake import Bake, ObjectsBake, tree_bake_from_model
from .errors import InputError
from .lsystem import derive, load_grammar
from .model import TreeModel, placed
from .rig import RigOptions, build_rig
from .rotations import matrices_from_quaternions
from .scene import Scene
from .sim.quality import QUALITIES, Quality
from .sim.common import SimTree, TreeMotion, cap_note
from .sim.debris import MAX_SPIN
from .sim.loads import SceneLoads
from .sim.planar import MAX_REFINE
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


def projectile_reaches(scene: Scene, model: TreeModel) -> bool:
    """Whether a projectile's ballistic path passes near the tree."""
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


def _planar_notes(stats, quality: Quality, h: float) -> list[str]:
    """What the planar LOD adapted or clamped, in words (never silently)."""
    notes = []
    if stats.inertia_floored:
        notes.append(f"stability: rotary inertia raised on {stats.inertia_floored} of "
                     f"{stats.bodies} bodies (up to {stats.max_inertia_ratio:.1f}x) to keep "
                     f"omega*h <= {quality.stability:g} at h = {h * 1e3:.3f} ms")
    if stats.limited:
        notes.append(cap_note(stats))
    if stats.refined:
        notes.append(f"{stats.refined} substeps were split into up to {MAX_REFINE} steps while a "
                     "blast, a hit, a capped load or a fast spin acted (pivots drift with the "
                     "square of the step)")
    if stats.broken:
        notes.append(f"{stats.broken} joints broke; {stats.debris} parts fell off as debris")
    if stats.debris_clamped:
        notes.append(f"debris spin clamped at {MAX_SPIN:.0f} rad/s on {stats.debris_clamped} "
                     "body substeps")
    return notes


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
    if active and solver == "planar":
        from .sim.run import merge_stats, simulate

        motions, chunks = simulate(sim_trees, qualities, scene, extent, workers, log, progress)
        st = merge_stats(chunks)
        meta["substep"] = min(c.h for c in chunks)
        meta["force_interval"] = min(c.dt_update for c in chunks)
        meta["chunks"] = len(chunks)
        meta["stats"] = {k: v for k, v in asdict(st).items()
                         if k not in ("notes", "step_seconds", "update_seconds", "first_limit",
                                      "frame_seconds")}
        meta["stats"]["max_joint_gap"] = float(f"{st.max_joint_gap:.3g}")
        meta["notes"] = _planar_notes(st, q, meta["substep"])
        timing.update(step_seconds=round(st.step_seconds, 3),
                      update_seconds=round(st.update_seconds, 3),
                      segment_steps=sum(c.segments * c.stats.substeps for c in chunks),
                      **frame_timing(st.frame_seconds, round(1.0 / (scene.fps * meta["substep"]))))
        for c in chunks:
            if c.objects is not None:
                objects = ObjectsBake(*c.objects)
    elif active:
        try:
            from .sim.reference import ReferenceSolver
        except ImportError:
            raise InputError("--solver full needs MuJoCo: pip install 'treebake[reference]'") \
                from None
        ref = ReferenceSolver(sim_trees, scene, q, loads, log=log, timestep=timestep)
        for tree, motion in zip(active, ref.run(progress)):
            motions[tree.name] = motion
        meta.update(ref.meta())
        timing.update({k: round(v, 3) for k, v in ref.timing.items()})
        steps = np.asarray(ref.step_times)
        if len(steps):
            per_frame = steps[: len(steps) // ref.spf * ref.spf].reshape(-1, ref.spf).sum(1)
            timing.update(segment_steps=sum(t.rig.model.n_segments for t in active) * len(steps),
                          **frame_timing(per_frame, ref.spf))
        objects = ref.objects()
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
            info["events"] = motion.events
            pos, rot = segment_transforms(st_tree.rig, motion.quaternions, motion.pivots)
        trees.append(tree_bake_from_model(g.model, pos, rot, info))
    timing["wall_seconds"] = round(time.perf_counter() - started, 3)
    return Bake(np.arange(frames) / scene.fps, trees, meta, objects, timing)


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
    r = matrices_from_quaternions(q.reshape(-1, 4)).reshape(q.shape[0], len(sb), 3, 3)
    offset = rest_base - rig.pivot[sb]
    pos = pivots[:, sb] + np.einsum("fsij,sj->fsi", r, offset)
    return pos, q
