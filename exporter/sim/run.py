"""Running the planar LOD on many trees: in chunks, serially or in worker
processes, with the same result either way.

Trees do not interact in the planar LOD (projectiles aside), but a solver
makes some decisions for all its trees at once (loads re-evaluated every
substep while anything touches the ground; steps split while a blast acts),
so a tree's motion depends on which trees share its solver. Chunks are
therefore fixed by the scene alone — trees grouped by quality level, then
split in scene order into chunks of about CHUNK_SEGMENTS segments — and a
parallel run only changes which process simulates a chunk, never the
chunks: bit-identical bakes with any number of workers. Scenes with
projectiles (which can hit any tree) run as one chunk.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, fields

import numpy as np

from ..scene import Scene
from .quality import Quality
from .common import SimTree, TreeMotion
from .loads import SceneLoads
from .chains import PymunkTier, Stats

CHUNK_SEGMENTS = 2000  # segments per solver: big enough to amortise numpy, small to spread


@dataclass
class ChunkResult:
    motions: list[TreeMotion]
    stats: Stats
    h: float
    dt_update: float
    segments: int
    objects: tuple | None = None  # projectile tracks (shapes, sizes, positions, rotations)


def chunks(trees: list[SimTree], qualities: list[Quality],
           whole: bool) -> list[tuple[Quality, list[int]]]:
    """Indices of active trees, grouped by quality, in chunks of about
    CHUNK_SEGMENTS segments (or one chunk per quality when `whole`)."""
    groups: dict[str, tuple[Quality, list[int]]] = {}
    for i, (t, q) in enumerate(zip(trees, qualities)):
        if t.active:
            groups.setdefault(repr(q), (q, []))[1].append(i)
    out = []
    for q, members in groups.values():
        current: list[int] = []
        size = 0
        for i in members:
            n = trees[i].rig.model.n_segments
            if current and not whole and size + n > CHUNK_SEGMENTS:
                out.append((q, current))
                current, size = [], 0
            current.append(i)
            size += n
        if current:
            out.append((q, current))
    return out


def _simulate_chunk(trees: list[SimTree], scene: Scene, quality: Quality,
                    extent: np.ndarray, log=None, progress=None) -> ChunkResult:
    loads = SceneLoads(scene, extent)
    sim = PymunkTier(trees, scene, quality, loads, log=log)
    motions = sim.run(progress)
    objects = None
    if sim.projectiles is not None:
        p = sim.projectiles
        objects = (p.shape, p.size, p.track_pos, p.track_quat)
    return ChunkResult(motions, sim.stats, sim.h, sim.dt_update,
                       sum(t.rig.model.n_segments for t in trees), objects)


def simulate(trees: list[SimTree], qualities: list[Quality], scene: Scene, extent: np.ndarray,
             workers: int = 1, log=None, progress=None) -> tuple[dict[str, TreeMotion],
                                                                 list[ChunkResult]]:
    """Motions of the active trees (by name) and each chunk's result."""
    plan = chunks(trees, qualities, whole=bool(scene.projectiles))
    results: list[ChunkResult | None] = [None] * len(plan)
    workers = max(1, min(workers, len(plan)))
    if workers == 1:
        for k, (q, members) in enumerate(plan):
            tick = _chunk_progress(progress, k, len(plan))
            results[k] = _simulate_chunk([trees[i] for i in members], scene, q, extent, log,
                                         tick)
    else:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        ctx = mp.get_context("fork" if os.name == "posix" else "spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            futures = [pool.submit(_simulate_chunk, [trees[i] for i in members], scene, q,
                                   extent) for q, members in plan]
            for k, fut in enumerate(futures):
                results[k] = fut.result()
                if progress is not None:
                    progress(k + 1, len(plan))
    motions = {}
    for (_, members), res in zip(plan, results):
        for i, motion in zip(members, res.motions):
            motions[trees[i].name] = motion
    return motions, results


def _chunk_progress(progress, k: int, total: int):
    if progress is None:
        return None

    def tick(done: int, frames: int) -> None:
        progress(k * frames + done, total * frames)

    return tick


def merge_stats(results: list[ChunkResult]) -> Stats:
    """One Stats for all chunks: counts add up, extremes take the worst."""
    out = Stats()
    worst = {"max_inertia_ratio", "max_joint_gap"}
    for r in results:
        for f in fields(Stats):
            a, b = getattr(out, f.name), getattr(r.stats, f.name)
            if f.name in worst:
                setattr(out, f.name, max(a, b))
            elif f.name == "first_limit":
                if b is not None and (a is None or b[2] < a[2]):
                    out.first_limit = b
            elif f.name == "substeps":
                out.substeps = max(a, b)
            elif f.name == "notes":
                out.notes = a + b
            elif f.name == "frame_seconds":  # chunks cover the same frames: times add up
                out.frame_seconds = list(np.add(a, b)) if a else list(b)
            else:
                setattr(out, f.name, a + b)
    return out
