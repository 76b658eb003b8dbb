"""Progress of the planar LOD for people: the work done and the work
planned, in units of one segment's frame in the linear tier, so that an ETA
counts what the nonlinear engines will still cost. The plan starts from
what the scene says (cuts and projectiles send trees to a nonlinear engine
at known times) and follows the hand-offs as they come."""

from __future__ import annotations

import numpy as np

from ..quality import Quality, TierPolicy
from ..scene import Scene
from .common import SimTree
from .handoff import Engine, Reason, engine_for

# CPU per segment and frame, relative to the linear tier's, at `default`
# (docs/physics.md, "What each engine costs"; bench/presets.py)
COST = {Engine.LINEAR: 1.0, Engine.PYMUNK: 40.0, Engine.REFERENCE: 25.0}


class ChunkProgress:
    """Reports (done, planned) to `report` as the chunks' tiers advance."""

    def __init__(self, trees: list[SimTree], plan: list[tuple[Quality, list[int]]],
                 scene: Scene, report):
        self.report, self.frames = report, scene.frame_count - 1
        self.done = 0.0
        self.chunks = [ChunkPlan([trees[i] for i in members], q, scene, self)
                       for q, members in plan]

    @property
    def planned(self) -> float:
        return sum(c.planned for c in self.chunks)

    def chunk(self, k: int) -> ChunkPlan:
        return self.chunks[k]

    def chunk_done(self, k: int) -> None:
        """A chunk simulated elsewhere (a worker process) is done, as planned."""
        self.done += self.chunks[k].planned
        self.tell()

    def tell(self) -> None:
        self.report(self.done, max(self.planned, self.done))


class ChunkPlan:
    """One chunk's planned cost per tree and frame (segments x COST)."""

    def __init__(self, trees: list[SimTree], quality: Quality, scene: Scene,
                 owner: ChunkProgress):
        self.owner, self.quality = owner, quality
        frames = scene.frame_count
        self.segments = np.array([t.rig.model.n_segments for t in trees], dtype=float)
        start = Engine.PYMUNK if quality.tier is TierPolicy.PYMUNK else Engine.LINEAR
        self.cost = np.full((len(trees), frames), COST[start]) * self.segments[:, None]
        for i, t in enumerate(trees):
            if t.cut is not None:  # known: it leaves for the cut's engine then
                f = min(frames - 1, int(t.cut.time * scene.fps))
                self.cost[i, f:] = COST[engine_for(Reason.CUT, quality)] * self.segments[i]
        self.cost[:, 0] = 0.0  # frame 0 is the rest pose

    @property
    def planned(self) -> float:
        return float(self.cost.sum())

    def start(self, engine: Engine, trees: list[int], frame: int) -> None:
        """Trees go to `engine` from `frame`: their plan from there."""
        self.cost[trees, max(frame, 1):] = COST[engine] * self.segments[trees, None]
        self.owner.tell()

    def tick(self, engine: Engine, trees: list[int], frame: int) -> None:
        """`engine` stepped `trees` to `frame`."""
        if frame > 0:
            self.owner.done += float(self.cost[trees, frame].sum())
            self.owner.tell()
