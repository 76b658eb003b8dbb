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
number of workers, local or on a Dask cluster (distributed.py). Scenes with projectiles (which can hit any tree) run as
one chunk."""

from __future__ import annotations

import os
from collections.abc import Iterator

from ..quality import Quality
from ..scene import Scene
from .common import SimTree
from .loads import SceneLoads
from .handoff import spans_text
from .notes import solve_result
from .progress import ChunkProgress, ForwardedPlan, forward_to
from .scheduler import ChunkResult, results_in_order, simulate_chunk
from .solver import SolveResult

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


def simulate(trees: list[SimTree], plan: list[tuple[Quality, list[int]]], scene: Scene,
             loads: SceneLoads, workers: int = 1, log=None,
             progress=None, scheduler: str | None = None) -> Iterator[ChunkResult]:
    """Each chunk of `plan` through its tiers, in `workers` processes or as
    tasks on the Dask scheduler at `scheduler` (distributed.py), yielded in
    plan order as they finish (a chunk's result is not kept once taken);
    `progress(done, total)` hears the planned work done (progress.py)."""
    tick = None if progress is None else ChunkProgress(trees, plan, scene, progress)
    if scheduler:
        from .distributed import run_chunks

        yield from run_chunks(scheduler, [([trees[i] for i in members], scene, q, loads)
                                          for q, members in plan], tick, log)
    else:
        yield from _simulate(trees, plan, scene, loads, workers, log, tick)
    if tick is not None:
        tick.finish()


def _simulate(trees, plan, scene, loads, workers, log, progress) -> Iterator[ChunkResult]:
    workers = max(1, min(workers, len(plan)))
    if workers == 1:
        for k, (q, members) in enumerate(plan):
            yield simulate_chunk([trees[i] for i in members], scene, q, loads, log,
                                 None if progress is None else progress.chunk(k))
            if progress is not None:  # what its plan still held was not needed
                progress.chunk_done(k)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    ctx = mp.get_context("fork" if os.name == "posix" else "spawn")
    # the workers tell their frames as they go (progress.ForwardedPlan): a
    # log is not silent while a chunk runs (30 s on preset:explosion)
    events = None if progress is None else ctx.Queue()
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                             initializer=None if events is None else forward_to,
                             initargs=() if events is None else (events,)) as pool:
        futures = [pool.submit(simulate_chunk, [trees[i] for i in members], scene, q, loads,
                               None, None if events is None else ForwardedPlan(k))
                   for k, (q, members) in enumerate(plan)]
        yield from results_in_order(futures, progress, events)


class PlanarLOD:
    """The product's solver: the scene's active trees in chunks (fixed by the
    scene), each through its tiers, in `workers` processes; the same bake
    for any number of workers."""

    def __init__(self, trees: list[SimTree], qualities: list[Quality], scene: Scene,
                 loads: SceneLoads, workers: int = 1, log=None, scheduler: str | None = None):
        self.trees, self.qualities, self.scene = trees, qualities, scene
        self.loads, self.workers, self.scheduler = loads, workers, scheduler
        self.log = log or (lambda msg: None)

    def run(self, progress=None, on_tree=None) -> SolveResult:
        """Simulate every chunk; `on_tree(index, motion, engines)` (solver.
        TreeSink) takes each tree's motion as its chunk finishes, and the
        result then keeps none."""
        plan = chunks(self.trees, self.qualities, whole=bool(self.scene.projectiles))
        results = []
        # the generator runs to its end (not zip's: it would stop one short of
        # the pool's shutdown and the progress's last word)
        for k, res in enumerate(simulate(self.trees, plan, self.scene, self.loads, self.workers,
                                         self.log, progress, self.scheduler)):
            members = plan[k][1]
            if on_tree is not None:
                for i, motion, spans in zip(members, res.motions, res.spans):
                    on_tree(i, motion, spans_text(spans))
                res.motions = [None] * len(members)  # taken: memory follows the chunk
            results.append(res)
        return solve_result(self.trees, plan, results, self.scene)
