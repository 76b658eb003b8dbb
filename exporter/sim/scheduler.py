"""The planar LOD's scheduler: one chunk of trees through its tiers.

Every tree starts in the linear tier (trees a projectile can reach, and all
of them under `tier = "pymunk"`, in the nonlinear engine). A tier runs its
trees to the end of the shot and returns those that left it (hand-offs,
handoff.py); each goes to the one engine `handoff.engine_for` names for its
reason, from the state it left in (or where a blast under way found it),
and a tree a nonlinear engine hands back runs on in a linear tier of its
own. Trees leaving one tier in one frame at one substep for the pymunk tier
share a pymunk tier; every other run holds one tree. A reference run that
fails is run again on the pymunk tier. Each tree's motion is the frames of
each engine it was in, in order (`TreeRecord`)."""

from __future__ import annotations

import queue
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import SimulationError
from ..quality import Quality, TierPolicy
from ..scene import Scene
from .common import ProjectileTracks, SimTree, TreeMotion
from .events import TIER, Event
from .handoff import (
    RETURNABLE,
    Engine,
    HandOff,
    Reason,
    Tier,
    TierReport,
    TierSpan,
    engine_for,
)
from .loads import SceneLoads
from .projectiles import projectile_reaches
from .pruning import BoneMap, pruned_tree, standing_start
from .rules import HIT_FORCE_RATE, HIT_SUBSTEP_RATE


@dataclass
class Run:
    """Trees (chunk indices) for one engine, from rest at t = 0 (`starts`
    None) or from their hand-offs."""

    engine: Engine
    trees: list[int]
    starts: list[HandOff] | None = None


@dataclass
class ChunkResult:
    """A chunk's trees' motions and tier spans (in the chunk's order), what
    each tier run reported, and the projectiles' flight."""

    motions: list[TreeMotion]
    spans: list[list[TierSpan]]
    reports: list[TierReport]
    objects: ProjectileTracks | None = None


@dataclass
class TreeRecord:
    """One tree's shot so far: its motion (each engine's frames from where
    it took the tree), the engines it was in, and its tier events."""

    name: str
    motion: TreeMotion | None = None
    spans: list[TierSpan] = field(default_factory=list)
    switches: list[Event] = field(default_factory=list)
    bone_map: BoneMap | None = None  # once parts broke off: its runs' bones among the grown

    def take(self, m: TreeMotion, start: int, work_before: float, fps: float) -> None:
        """The frames from `start` on are m's; `work_before` J: the work
        done on the tree before m's engine took it (the audit goes on)."""
        if self.bone_map is not None:
            m = self.bone_map.grown(m, start)
        if self.motion is None:
            self.motion = m
            return
        mine = self.motion
        mine.quaternions[start:] = m.quaternions[start:]
        mine.pivots[start:] = m.pivots[start:]
        mine.events.extend(m.events)
        mine.energy[start:] = m.energy[start:]
        mine.work[start:] = m.work[start:] + work_before
        # sub-frame samples: the earlier engine's before `start`, m's after
        nb = mine.quaternions.shape[1]
        keep = mine.extra_times < start / fps

        def samples(mo: TreeMotion, rows) -> list[np.ndarray]:
            if mo.extra_quaternions is None:  # none kept
                return [np.zeros(0), np.zeros((0, nb, 4)), np.zeros((0, nb, 3))]
            return [mo.extra_times[rows], mo.extra_quaternions[rows], mo.extra_pivots[rows]]

        mine.extra_times, mine.extra_quaternions, mine.extra_pivots = (
            np.concatenate(pair) for pair in zip(samples(mine, keep),
                                                 samples(m, slice(None))))

    def finish(self) -> TreeMotion:
        """The motion, its tier switches among its events in time order."""
        self.motion.events = sorted(self.switches + self.motion.events, key=lambda e: e.time)
        return self.motion


class Chunk:
    """The trees of one chunk, what moves them, and their records."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality,
                 loads: SceneLoads, log=None, progress=None):
        # (a copy: a tree that lost parts runs on as its standing part)
        self.trees, self.scene, self.quality = list(trees), scene, quality
        self.loads = loads
        self.log = log or (lambda msg: None)
        self.progress = progress
        self.last_frame = scene.frame_count - 1
        self.records = [TreeRecord(t.name) for t in trees]
        self.reports: list[TierReport] = []
        self.objects: ProjectileTracks | None = None
        self.work_before: dict[int, float] = {}  # J done on a tree before its current run

    def first_runs(self) -> list[Run]:
        """The linear tier for every tree, but those that start in the
        nonlinear engine (a projectile can reach them; `tier = "pymunk"`)."""
        scene = self.scene
        start_nonlinear = [self.quality.tier is TierPolicy.PYMUNK or (
            bool(scene.projectiles) and projectile_reaches(scene, t.rig.model))
            for t in self.trees]
        engine = engine_for(Reason.PROJECTILE, self.quality)
        runs = [Run(Engine.LINEAR, [i for i, s in enumerate(start_nonlinear) if not s]),
                Run(engine, [i for i, s in enumerate(start_nonlinear) if s])]
        for i, s in enumerate(start_nonlinear):
            self.records[i].spans.append(TierSpan(engine if s else Engine.LINEAR))
        return [r for r in runs if r.trees]

    def execute(self, run: Run) -> list[Run]:
        """Run `run` to the end of the shot; record its motions; the runs
        its hand-offs call for (a failed reference run: the pymunk tier)."""
        try:
            cpu = time.process_time()
            tier = open_tier(run, self)
            leaving, segment_frames = self.advance(tier, run)
            cpu = time.process_time() - cpu
        except SimulationError as exc:
            if run.engine is not Engine.REFERENCE:
                raise
            self.log(f"{', '.join(self.trees[i].name for i in run.trees)}: the reference "
                     f"failed ({exc}); the pymunk tier takes over")
            for i in run.trees:
                record = self.records[i]
                last = record.spans[-1]
                why = f"{last.detail}; the reference failed" if last.detail else \
                    "the reference failed"
                record.spans[-1] = replace(last, engine=Engine.PYMUNK, detail=why)
                if run.starts is not None:  # its tier event names the engine that runs it
                    record.switches[-1] = replace(record.switches[-1],
                                                  detail=f"to {Engine.PYMUNK.value}: {why}")
            return [replace(run, engine=Engine.PYMUNK)]
        for i, m in zip(run.trees, tier.motions()):
            self.records[i].take(m, tier.first_frame, self.work_before.get(i, 0.0),
                                 self.scene.fps)
        report = tier.report()
        report.timing.update(cpu_seconds=cpu, segment_frames=segment_frames)
        self.reports.append(report)
        if run.starts is None:  # the run that throws the projectiles
            self.objects = tier.tracks() or self.objects
        return self.follow(run, leaving)

    def advance(self, tier: Tier, run: Run) -> tuple[list[list[HandOff]], int]:
        """Step a tier frame by frame to the end: per frame, the hand-offs
        (their work counted from the bake's start); and the segment-frames
        it ran."""
        out = []
        live = list(run.trees)
        if self.progress is not None:
            self.progress.start(run.engine, live, tier.first_frame)
        segment_frames = 0
        segments = sum(self.trees[i].rig.model.n_segments for i in live)  # while `live` stays
        for f in range(tier.first_frame, self.last_frame + 1):
            segment_frames += segments
            left = tier.advance_to(f)
            if left:
                out.append([ho.offset_work(self.work_before.get(run.trees[ho.tree], 0.0))
                            for ho in left])
                gone = {run.trees[ho.tree] for ho in left}
                if self.progress is not None:  # planned on its next engine now, not
                    for ho in left:  # when that engine's run starts (after this one)
                        self.progress.start(engine_for(ho.reason, self.quality),
                                            [run.trees[ho.tree]], f)
                live = [i for i in live if i not in gone]
                segments = sum(self.trees[i].rig.model.n_segments for i in live)
            if self.progress is not None:
                self.progress.tick(run.engine, live, f)
        return out, segment_frames

    def follow(self, run: Run, leaving: list[list[HandOff]]) -> list[Run]:
        """The runs that take the trees that left `run` (hand-offs grouped
        by frame): a pymunk tier per substep, every other engine per tree."""
        runs = []
        for frame in leaving:
            to_pymunk: dict[int, list[HandOff]] = {}
            for ho in frame:
                i = run.trees[ho.tree]
                start = self.switch(i, ho)
                engine = engine_for(ho.reason, self.quality)
                if engine is Engine.PYMUNK:
                    to_pymunk.setdefault(start.substep, []).append(replace(start, tree=i))
                else:
                    runs.append(Run(engine, [i], [replace(start, tree=i)]))
            runs += [Run(Engine.PYMUNK, [s.tree for s in group], group)
                     for group in to_pymunk.values()]
        return runs

    def switch(self, i: int, ho: HandOff) -> HandOff:
        """Tree i left its tier at `ho`: the engine that takes it recorded
        (a span, a tier event) and the state it starts from."""
        engine = engine_for(ho.reason, self.quality)
        start = ho.origin()
        why = ho.detail if start is ho else (
            f"{ho.detail} at {ho.time:.3f} s; taken from {start.time:.3f} s, "
            f"{ho.restart.detail}")
        self.work_before[i] = start.work
        if ho.broken is not None:  # it runs on as its standing part
            record = self.records[i]
            if record.bone_map is None:
                record.bone_map = BoneMap.whole(self.trees[i].rig.n_bones)
            record.bone_map.lose(ho.broken)
            self.trees[i] = pruned_tree(self.trees[i], ho.broken)
            start = standing_start(start)
        if ho.reason is not Reason.BACK:
            self.records[i].switches.append(Event(start.time, self.trees[i].name, TIER, "",
                                                  f"to {engine.value}: {why}"))
        self.records[i].spans.append(TierSpan(engine, round(start.time, 6), ho.reason, why))
        return start

    def result(self) -> ChunkResult:
        return ChunkResult([r.finish() for r in self.records], [r.spans for r in self.records],
                           self.reports, self.objects)


def open_tier(run: Run, chunk: Chunk) -> Tier:
    """The tier (handoff.Tier) for a run, started from rest or its hand-offs."""
    trees = [chunk.trees[i] for i in run.trees]
    scene, quality, loads, log = chunk.scene, chunk.quality, chunk.loads, chunk.log
    starts = run.starts
    if run.engine is Engine.LINEAR:
        from .linear import LinearTier

        substeps = max(1, round(quality.substep_rate / scene.fps))  # the pymunk tier's
        if starts is None:
            return LinearTier(trees, scene, quality, loads, substeps, log)
        (back,) = starts
        return LinearTier(trees, scene, quality, loads, substeps, log, back.frame,
                          (back.q, back.v))
    returnable = quality.hand_back and starts is not None and all(
        s.reason in RETURNABLE for s in starts)
    if run.engine is Engine.REFERENCE:
        from .reference import ReferenceTier

        start = None if starts is None else starts[0]
        return ReferenceTier(trees, scene, quality, loads, start,
                             start.step_length if returnable else None, log)
    return pymunk_tier(trees, scene, quality, loads, starts, returnable, log)


def pymunk_tier(trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                starts: list[HandOff] | None, returnable: bool, log):
    """A pymunk tier from rest (trees a projectile can reach run at least at
    rules.HIT_SUBSTEP_RATE and HIT_FORCE_RATE) or from hand-offs at one
    substep (their trees may go back to the linear tier if `returnable`)."""
    from .chains import PymunkTier, StartState

    note = None
    if starts is None and scene.projectiles and (quality.substep_rate < HIT_SUBSTEP_RATE
                                                 or quality.force_rate < HIT_FORCE_RATE):
        quality = replace(quality, substep_rate=max(quality.substep_rate, HIT_SUBSTEP_RATE),
                          force_rate=max(quality.force_rate, HIT_FORCE_RATE))
        note = (f"pymunk tier: trees a projectile can reach stepped at "
                f"{quality.substep_rate:.0f} Hz with loads at {quality.force_rate:.0f} Hz (its "
                "hits jolt the stems between coarser updates)")
    tier = PymunkTier(trees, scene, quality, loads, log=log, throws=starts is None)
    if note is not None:
        tier.stats.notes.append(note)
    if starts is None:
        tier.begin()
        return tier
    tier.begin(starts[0].substep, StartState(np.concatenate([s.rot for s in starts]),
                                             np.concatenate([s.omega for s in starts])))
    if returnable:
        tier.hand_back = starts[0].step_length
    return tier


def simulate_chunk(trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                   log=None, progress=None) -> ChunkResult:
    """Every tree of a chunk through its tiers, from rest to the end."""
    chunk = Chunk(trees, scene, quality, loads, log, progress)
    queue = deque(chunk.first_runs())
    while queue:
        queue.extend(chunk.execute(queue.popleft()))
    return chunk.result()


def results_in_order(futures: list, progress=None, events=None) -> Iterator[ChunkResult]:
    """The chunks' results in plan order (local or Dask futures alike),
    `progress.chunk_done(k)` as each comes; each future is let go once its
    result is taken, so finished chunks are not held. `events`: a queue of
    the workers' progress (progress.ForwardedPlan), applied while waiting."""
    for k in range(len(futures)):
        fut, futures[k] = futures[k], None
        while events is not None and not fut.done():
            try:
                progress.apply(*events.get(timeout=0.2))
            except queue.Empty:
                pass
        yield fut.result()
        if hasattr(fut, "release"):  # Dask: the worker may forget it too
            fut.release()
        del fut
        if progress is not None:
            progress.chunk_done(k)
