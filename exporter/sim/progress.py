"""Progress of the planar LOD for people: the work done and the work
planned, in units of one segment's frame in the linear tier, so that an ETA
counts what the nonlinear engines will still cost. The plan starts from
what the scene says (cuts and projectiles send trees to a nonlinear engine
at known times; a felled tree costs more once it falls) and follows the
hand-offs as they come."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..quality import Quality, TierPolicy
from ..scene import Scene
from .common import SimTree
from .handoff import Engine, Reason, engine_for
from .rules import FELL_NUDGE

# CPU per segment and frame, relative to the linear tier's, at `default`
# (docs/physics.md, "What each engine costs")
COST = {Engine.LINEAR: 1.0, Engine.PYMUNK: 40.0, Engine.REFERENCE: 25.0}


@dataclass(frozen=True)
class FallCost:
    """What a felled tree costs its engine once it falls, as multiples of
    its cost standing: `impact` times for `impact_time` s from when it
    leans `hinge_share` of its hinge angle (None: from when it reaches the
    ground), then `lying` times."""

    hinge_share: float | None
    impact: float
    impact_time: float
    lying: float


# the pymunk tier's steps split for the fast turn from a quarter of the
# hinge angle on; the reference's cost rises when the tree reaches the
# ground (its contacts and breaks), not when its hinge snaps
# (docs/physics.md, "What each engine costs")
FALL = {Engine.PYMUNK: FallCost(0.25, 7.0, 3.0, 3.0),
        Engine.REFERENCE: FallCost(None, 7.0, 2.0, 4.0)}
FORWARD_SECONDS = 0.5  # a worker's ticks to the parent at most this often


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
        """Chunk k is done: what its plan held beyond the work already told
        (ticks forwarded from a worker process, or none: a Dask task) is
        done too; later ticks of it are ignored."""
        c = self.chunks[k]
        if not c.finished:
            self.done += max(c.planned - c.ticked, 0.0)
            c.finished = True
        self.tell()

    def apply(self, k: int, event: str, engine: Engine, trees: list[int], frame: int) -> None:
        """A ForwardedPlan's call (`event` "start" or "tick") on chunk k's plan."""
        c = self.chunks[k]
        if not c.finished:
            (c.start if event == "start" else c.tick)(engine, trees, frame)

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
                cost = FALL[engine]
                lean = (math.pi / 2 if cost.hinge_share is None
                        else cost.hinge_share * math.radians(t.cut.hinge))
                fall = t.cut.time + lean_time(t, scene, lean)
                rest = min(frames - 1, int((fall + cost.impact_time) * scene.fps))
                self.size[i, min(frames - 1, int(fall * scene.fps)):rest] *= cost.impact
                self.size[i, rest:] *= cost.lying
                self.cost[i, f:] = COST[engine] * self.size[i, f:]
        self.cost[:, 0] = 0.0  # frame 0 is the rest pose
        self.counted = np.zeros(len(trees), dtype=np.int64)  # per tree, frames done
        self.planned = float(self.cost.sum())  # kept as the plan changes: told every frame
        self.ticked = 0.0  # the work its ticks told
        self.finished = False

    def start(self, engine: Engine, trees: list[int], frame: int) -> None:
        """Trees go to `engine` from `frame`: their plan from there."""
        f = max(frame, 1)
        self.cost[trees, f:] = COST[engine] * self.size[trees, f:]
        self.planned = float(self.cost.sum())
        self.owner.tell()

    def tick(self, engine: Engine, trees: list[int], frame: int) -> None:
        """`engine` stepped `trees` to `frame`: the frames since each tree's
        last tick are done (a frame counts once per tree: a run that starts
        before frames already done, after a restart or a failed reference
        run, does them again unpaid)."""
        new = np.array([i for i in trees if frame > self.counted[i]], dtype=np.int64)
        if len(new):
            work = 0.0
            for since in np.unique(self.counted[new]):  # trees that run together: one
                rows = new[self.counted[new] == since]
                work += float(self.cost[rows, since + 1:frame + 1].sum())
            self.counted[new] = frame
            self.ticked += work
            self.owner.done += work
            self.owner.tell()


_EVENTS = None  # a worker process's queue to the parent (forward_to)


def forward_to(events) -> None:
    """A worker process's initializer: ForwardedPlans put their calls on
    `events` (a multiprocessing queue the parent drains)."""
    global _EVENTS
    _EVENTS = events
    events.cancel_join_thread()  # progress left unread never holds up the worker's exit


class ForwardedPlan:
    """Chunk k's ChunkPlan in a worker process: its start calls, and a tick
    every FORWARD_SECONDS, put on the queue of `forward_to` for
    ChunkProgress.apply in the parent (a tick counts every frame since the
    last; the chunk's end counts the rest)."""

    def __init__(self, k: int):
        self.k = k
        self.sent = 0.0  # time.monotonic() of the last tick put

    def start(self, engine: Engine, trees: list[int], frame: int) -> None:
        _EVENTS.put((self.k, "start", engine, list(trees), frame))

    def tick(self, engine: Engine, trees: list[int], frame: int) -> None:
        now = time.monotonic()
        if now - self.sent >= FORWARD_SECONDS:
            self.sent = now
            _EVENTS.put((self.k, "tick", engine, list(trees), frame))


def lean_time(tree: SimTree, scene: Scene, lean: float) -> float:
    """Seconds from a tree's felling cut until it leans `lean` rad from
    upright (its hinge angle: the hinge snaps; pi/2: it lies on the
    ground), as a rigid rod of the tree's height tipping about its base
    from the feller's nudge: theta(t) = (w0 / lam) sinh(lam t), lam^2 =
    3 g / (2 H). For the ETA."""
    height = max(float(tree.rig.model.height), 0.1)
    lam = math.sqrt(3.0 * max(scene.gravity, 1e-3) / (2.0 * height))
    return math.asinh(lean * lam / FELL_NUDGE) / lam
