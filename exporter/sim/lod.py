"""The planar LOD as a solver (solver.Solver): the scene's active trees in
chunks, each through its tiers (scheduler.py), serially or in worker
processes with the same result, and what the runs report, merged.

Trees do not interact in the planar LOD (projectiles aside), but a tier
makes some decisions for all its trees at once (loads every substep while
anything touches the ground; steps split while a blast acts), so a tree's
motion depends on which trees share its tier. Chunks are therefore fixed by
the scene alone — trees grouped by quality level, then split in scene order
into chunks of about CHUNK_SEGMENTS segments — and a parallel run only
changes which process simulates a chunk: bit-identical bakes with any
number of workers. Scenes with projectiles (which can hit any tree) run as
one chunk."""

from __future__ import annotations

import os

import numpy as np

from ..quality import Quality
from ..scene import Scene
from .common import SimTree
from .handoff import Engine, Reason, TierReport, TierSpan
from .notes import lod_notes, merge_stats
from .progress import ChunkProgress
from .scheduler import ChunkResult, simulate_chunk
from .solver import SolveResult, frame_timing

CHUNK_SEGMENTS = 2000  # segments per chunk: big enough to amortise numpy, small to spread


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


def _run_chunk(trees, scene, quality, extent, log=None, progress=None) -> ChunkResult:
    return simulate_chunk(trees, scene, quality, extent, log, progress)


def simulate(trees: list[SimTree], plan: list[tuple[Quality, list[int]]], scene: Scene,
             extent: np.ndarray, workers: int = 1, log=None,
             progress: ChunkProgress | None = None) -> list[ChunkResult]:
    """Each chunk of `plan` through its tiers, in `workers` processes."""
    workers = max(1, min(workers, len(plan)))
    if workers == 1:
        return [_run_chunk([trees[i] for i in members], scene, q, extent, log,
                           None if progress is None else progress.chunk(k))
                for k, (q, members) in enumerate(plan)]
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("fork" if os.name == "posix" else "spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = [pool.submit(_run_chunk, [trees[i] for i in members], scene, q, extent)
                   for q, members in plan]
        results = []
        for k, fut in enumerate(futures):
            results.append(fut.result())
            if progress is not None:
                progress.chunk_done(k)
    return results


def spans_text(spans: list[TierSpan]) -> str:
    """Which engines moved a tree and from when, in words: "linear, then
    reference from 1.234 s (trunk/2:0: a joint past 80% of its strength)"."""
    first = spans[0]
    parts = [f"{first.engine.value} ({first.detail})" if first.detail else first.engine.value]
    parts += [f"{s.engine.value} from {s.start:.3f} s ({s.detail})" for s in spans[1:]]
    return ", then ".join(parts)


class PlanarLOD:
    """The product's solver: the scene's active trees in chunks (fixed by the
    scene), each through its tiers, in `workers` processes; the same bake
    for any number of workers."""

    def __init__(self, trees: list[SimTree], qualities: list[Quality], scene: Scene,
                 extent: np.ndarray, workers: int = 1, log=None):
        self.trees, self.qualities, self.scene = trees, qualities, scene
        self.extent, self.workers = extent, workers
        self.log = log or (lambda msg: None)

    def run(self, progress=None) -> SolveResult:
        plan = chunks(self.trees, self.qualities, whole=bool(self.scene.projectiles))
        tick = None if progress is None else ChunkProgress(self.trees, plan, self.scene,
                                                           progress)
        results = simulate(self.trees, plan, self.scene, self.extent, self.workers, self.log,
                           tick)
        if tick is not None:
            tick.finish()
        motions, tiers = {}, {}
        for (_, members), res in zip(plan, results):
            for i, motion, spans in zip(members, res.motions, res.spans):
                motions[self.trees[i].name] = motion
                tiers[self.trees[i].name] = spans_text(spans)
        reports = [r for res in results for r in res.reports]
        returned = sum(s.reason is Reason.BACK for res in results for spans in res.spans
                       for s in spans)
        meta, notes = summarise(reports, returned)
        meta["chunks"] = len(plan)
        objects = next((res.objects for res in results if res.objects is not None), None)
        return SolveResult(motions, objects, meta, notes, tiers, _timing(reports, self.scene))


def summarise(reports: list[TierReport], returned: int) -> tuple[dict, list[str]]:
    """The bake's meta (each engine's counts summed over its runs; breaks,
    debris and returns over all) and its notes."""
    by_engine = {e: [r for r in reports if r.engine is e] for e in Engine}
    stats = {e.value: merge_stats([r.stats for r in rs]) for e, rs in by_engine.items() if rs}
    lin, pym, ref = (stats.get(e.value) for e in Engine)
    meta: dict = {"runs": {e.value: len(rs) for e, rs in by_engine.items() if rs}}
    if lin:
        meta["linear_step"] = lin["step"]
    if pym:
        meta["substep"], meta["force_interval"] = pym["substep"], pym["force_interval"]
    if ref:
        meta["reference_step"] = ref["step"]
    meta["stats"] = {"broken": (ref["broken"] if ref else 0) + (pym["broken"] if pym else 0),
                     "debris": (ref["parts"] if ref else 0) + (pym["debris"] if pym else 0),
                     "returned": returned, **stats}
    if ref and "closest_to_breaking" in ref:
        meta["stats"]["closest_to_breaking"] = ref["closest_to_breaking"]
    return meta, lod_notes(stats, reports, returned)


def _timing(reports: list[TierReport], scene: Scene) -> dict:
    """Seconds spent stepping and updating (loads, checks, events) over all
    runs, per-frame costs of the linear and pymunk tiers, and the simulated
    segment-steps."""
    step = sum(r.timing.get("step_seconds", 0.0) for r in reports)
    update = sum(r.timing.get("update_seconds", 0.0) + r.timing.get("compile_seconds", 0.0)
                 for r in reports)
    frame_seconds = np.zeros(scene.frame_count - 1)
    for r in reports:
        f = r.timing.get("frame_seconds")
        if f is not None and len(f):  # a tier started late covers the last frames
            f = np.asarray(f[-len(frame_seconds):])
            frame_seconds[len(frame_seconds) - len(f):] += f
    engines = {e.value: {"cpu_seconds": round(sum(r.timing["cpu_seconds"] for r in rs), 3),
                         "segment_frames": sum(r.timing["segment_frames"] for r in rs)}
               for e in Engine if (rs := [r for r in reports if r.engine is e])}
    return {"engines": engines, "step_seconds": round(step, 3), "update_seconds": round(update, 3),
            "build_seconds": round(sum(r.timing.get("build_seconds", 0.0) for r in reports), 3),
            "segment_steps": sum(r.timing.get("segment_steps", 0) for r in reports),
            **frame_timing(frame_seconds, 1)}
