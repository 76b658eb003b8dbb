"""Progress of the planar LOD (sim/progress.py): chunks simulated in worker
processes tell their frames as they go, not only when they end (a bake of
preset:explosion printed nothing for 30 s, then "92 %" beside "done"), and
a tick counts every frame since the tree's last one."""

import numpy as np
import pytest
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.sim import lod, progress
from treebake.sim.handoff import Engine


def test_worker_chunks_report_their_frames_as_they_go(root, monkeypatch):
    monkeypatch.setattr(lod, "CHUNK_SEGMENTS", 60)  # the saplings in several chunks
    monkeypatch.setattr(progress, "FORWARD_SECONDS", 0.0)  # every tick (the workers fork)
    sapling = str(root / "grammars" / "sapling.lsys")
    scene = parse_scene({"tree": [{"grammar": sapling, "position": [5.0 * k, 0.0]}
                                  for k in range(3)],
                         "duration": 1.0, "fps": 24, "wind": {"speed": 8.0}}, file="<test>")
    told: list[tuple[float, float]] = []
    bake_scene(scene, workers=2, progress=lambda done, total: told.append((done, total)))
    shares = [d / t for d, t in told]
    assert shares[-1] == 1.0 and all(0.0 <= s <= 1.0 for s in shares)
    work = [d for d, _ in told[:-1]]  # the last is the finish's (1, 1)
    assert all(b >= a for a, b in zip(work, work[1:]))  # the work done never shrinks
    # the saplings stay on the linear tier: the plan never changes, and the
    # work told adds up to it, no chunk counted twice (its ticks and its end)
    assert len({t for _, t in told[:-1]}) == 1 and work[-1] == pytest.approx(told[-2][1], rel=1e-12)
    # besides the start, each chunk's end and the finish: the frames (24 a chunk)
    between = {round(s, 6) for s in shares if 0.0 < s < 1.0}
    assert len(between) > 3 * 6, sorted(between)


class _Owner:
    def __init__(self):
        self.done = 0.0

    def tell(self):
        pass


def _plan(owner):
    """A ChunkPlan's numbers without a scene: 3 trees, 10 frames, costs that
    differ per tree and frame (frame 0 costs nothing: the rest pose)."""
    plan = progress.ChunkPlan.__new__(progress.ChunkPlan)
    plan.owner = owner
    plan.size = np.arange(30, dtype=float).reshape(3, 10) + 1.0
    plan.cost = plan.size * np.array([[1.0], [2.0], [3.0]])
    plan.cost[:, 0] = 0.0
    plan.counted = np.zeros(3, dtype=np.int64)
    plan.planned = float(plan.cost.sum())
    plan.ticked, plan.finished = 0.0, False
    return plan


def test_a_tick_counts_every_frame_since_the_last_one():
    every, some = _Owner(), _Owner()
    a, b = _plan(every), _plan(some)
    for f in range(1, 10):
        a.tick(Engine.LINEAR, [0, 1, 2], f)
        if f % 4 == 0 or f == 9:
            b.tick(Engine.LINEAR, [0, 1, 2], f)
        if f in (4, 8, 9):
            assert every.done == some.done, f
    assert every.done == a.planned  # each frame of each tree once
    a.tick(Engine.LINEAR, [0, 1], 5)  # a frame already counted: unpaid
    assert every.done == a.planned
    c = _plan(_Owner())
    own = c.owner
    c.tick(Engine.LINEAR, [0], 3)
    c.tick(Engine.LINEAR, [0, 1], 6)  # tree 1 from frame 1, tree 0 from frame 4
    assert own.done == c.cost[0, 1:7].sum() + c.cost[1, 1:7].sum()
