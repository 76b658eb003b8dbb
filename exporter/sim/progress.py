"""Progress of the planar LOD for people: the work done and the work
planned, in units of one segment's frame in the linear tier, so that an ETA
counts what the nonlinear engines will still cost. The plan starts from
what the scene says (cuts and projectiles send trees to a nonlinear engine
at known times; a felled tree costs more once it falls) and follows the
hand-offs as they come."""

from __future__ import annotations

import math

import numpy as np

from ..quality import Quality, TierPolicy
from ..scene import Scene
from .common import SimTree
from .handoff import Engine, Reason, engine_for
from .rules import FELL_NUDGE

# CPU per segment and frame, relative to the linear tier's, at `default`
# (docs/physics.md, "What each engine costs")
COST = {Engine.LINEAR: 1.0, Engine.PYMUNK: 40.0, Engine.REFERENCE: 25.0}
# a felled tree costs more once it falls (on the pymunk tier from when it
# leans a quarter of its hinge angle: its steps split for the fast turn; on
# the reference from when its hinge snaps): IMPACT times as much for
# IMPACT_TIME s (the fall, the breaks, the parts on the ground), then LYING
FAST_LEAN = {Engine.PYMUNK: 0.25, Engine.REFERENCE: 1.0}
IMPACT, IMPACT_TIME, LYING = 7.0, 3.0, 3.0


class ChunkProgress:
    """Reports (done, planned) to `report` as the chunks' tiers advance."""

    def __init__(self, trees: list[SimTree], plan: list[tuple[Quality, list[int]]],
                 scene: Scene, report):
        self.report = report
        self.done = 0.0
        self.chunks = [ChunkPlan([trees[i] for i in members], q, scene, self)
                       for q, members in plan]
        self.tell()  # nothing done yet: the simulation starts now

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

    def finish(self) -> None:
        """Every chunk is done: whatever the plan still held was not needed."""
        self.report(1.0, 1.0)


class ChunkPlan:
    """One chunk's planned work per tree and frame: its size (segments, more
    while a felled tree falls) times its engine's COST."""

    def __init__(self, trees: list[SimTree], quality: Quality, scene: Scene,
                 owner: ChunkProgress):
        self.owner = owner
        frames = scene.frame_count
        segments = np.array([t.rig.model.n_segments for t in trees], dtype=float)
        self.size = np.repeat(segments[:, None], frames, axis=1)
        start = Engine.PYMUNK if quality.tier is TierPolicy.PYMUNK else Engine.LINEAR
        self.cost = COST[start] * self.size
        for i, t in enumerate(trees):
            if t.cut is not None:  # known: it leaves for the cut's engine then, and falls
                engine = engine_for(Reason.CUT, quality)
                f = min(frames - 1, int(t.cut.time * scene.fps))
                fall = t.cut.time + lean_time(t, scene, FAST_LEAN[engine])
                rest = min(frames - 1, int((fall + IMPACT_TIME) * scene.fps))
                self.size[i, min(frames - 1, int(fall * scene.fps)):rest] *= IMPACT
                self.size[i, rest:] *= LYING
                self.cost[i, f:] = COST[engine] * self.size[i, f:]
        self.cost[:, 0] = 0.0  # frame 0 is the rest pose
        self.counted = np.zeros(len(trees), dtype=np.int64)  # per tree, frames done

    @property
    def planned(self) -> float:
        return float(self.cost.sum())

    def start(self, engine: Engine, trees: list[int], frame: int) -> None:
        """Trees go to `engine` from `frame`: their plan from there."""
        f = max(frame, 1)
        self.cost[trees, f:] = COST[engine] * self.size[trees, f:]
        self.owner.tell()

    def tick(self, engine: Engine, trees: list[int], frame: int) -> None:
        """`engine` stepped `trees` to `frame` (a frame counts once per tree:
        a run that starts before frames already done, after a restart or a
        failed reference run, does them again unpaid)."""
        new = [i for i in trees if frame > self.counted[i]]
        if new:
            self.counted[new] = frame
            self.owner.done += float(self.cost[new, frame].sum())
            self.owner.tell()


def lean_time(tree: SimTree, scene: Scene, share: float) -> float:
    """Seconds from a tree's felling cut until it leans `share` of its hinge
    angle (at 1 the hinge snaps and it falls free), as a rigid rod of the
    tree's height tipping about its base from the feller's nudge:
    theta(t) = (w0 / lam) sinh(lam t), lam^2 = 3 g / (2 H). For the ETA."""
    height = max(float(tree.rig.model.height), 0.1)
    lam = math.sqrt(3.0 * max(scene.gravity, 1e-3) / (2.0 * height))
    return math.asinh(share * math.radians(tree.cut.hinge) * lam / FELL_NUDGE) / lam
