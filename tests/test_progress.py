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


def test_a_chunk_run_in_this_process_is_told_done_when_it_ends(monkeypatch):
    """As a worker's chunk is (results_in_order): what its plan still holds
    when it ends (frames no tier ticked) counts as done then, not only at
    the bake's end (preset:explosion with --workers 1 stood at 64 % until
    it finished)."""
    calls = []

    class Told:
        def chunk(self, k):
            calls.append(("plan", k))
            return f"plan {k}"

        def chunk_done(self, k):
            calls.append(("done", k))

    def simulate_chunk(trees, scene, quality, loads, log, plan):
        calls.append(("run", plan))
        return plan

    monkeypatch.setattr(lod, "simulate_chunk", simulate_chunk)
    plan = [("q", [0]), ("q", [1, 2])]
    out = list(lod._simulate(["a", "b", "c"], plan, None, None, 1, None, Told()))
    assert out == ["plan 0", "plan 1"]
    assert calls == [("plan", 0), ("run", "plan 0"), ("done", 0),
                     ("plan", 1), ("run", "plan 1"), ("done", 1)]


def test_a_tree_leaving_a_tier_is_planned_on_its_next_engine_at_once():
    """The plan follows a tree to the engine that takes it as it leaves,
    not when that engine's run starts (after the rest of the chunk's run:
    preset:explosion's trees waited 3-19 s on the linear tier's cost)."""
    from types import SimpleNamespace

    from treebake.quality import QUALITIES
    from treebake.sim.handoff import Reason
    from treebake.sim.scheduler import Chunk, Run

    told = []

    class Plan:
        def start(self, engine, trees, frame):
            told.append(("start", engine, trees, frame))

        def tick(self, engine, trees, frame):
            told.append(("tick", engine, trees, frame))

    leaving = SimpleNamespace(tree=1, reason=Reason.TURN, offset_work=lambda joules: "handoff")

    class Tier:
        first_frame = 1

        def advance_to(self, f):
            return [leaving] if f == 2 else []

    chunk = Chunk.__new__(Chunk)
    chunk.progress, chunk.last_frame, chunk.work_before = Plan(), 3, {}
    chunk.quality = QUALITIES["default"]
    chunk.trees = [SimpleNamespace(rig=SimpleNamespace(model=SimpleNamespace(n_segments=5)))] * 2
    out, _ = chunk.advance(Tier(), Run(Engine.LINEAR, [0, 1]))
    assert out == [["handoff"]]
    assert told == [("start", Engine.LINEAR, [0, 1], 1), ("tick", Engine.LINEAR, [0, 1], 1),
                    ("start", Engine.REFERENCE, [1], 2), ("tick", Engine.LINEAR, [0], 2),
                    ("tick", Engine.LINEAR, [0], 3)]


def test_a_felled_trees_fall_is_timed_by_a_tipping_rod():
    """lean_time against the rod's equation integrated step by step
    (theta'' = lam^2 theta, from the feller's nudge), to its hinge angle
    and to the ground; the reference's costly frames start at the ground."""
    import math
    from types import SimpleNamespace

    from treebake.sim.rules import FELL_NUDGE

    tree = SimpleNamespace(rig=SimpleNamespace(model=SimpleNamespace(height=16.5)),
                           cut=SimpleNamespace(hinge=40.0))
    scene = SimpleNamespace(gravity=9.81)
    lam2 = 3.0 * 9.81 / (2.0 * 16.5)
    theta, rate, t, dt, reached = 0.0, FELL_NUDGE, 0.0, 1e-5, {}
    while theta < math.pi / 2:  # semi-implicit Euler
        rate += lam2 * theta * dt
        theta += rate * dt
        t += dt
        for lean in (math.radians(40.0), math.pi / 2):
            if theta >= lean and lean not in reached:
                reached[lean] = t
    for lean, when in reached.items():
        assert progress.lean_time(tree, scene, lean) == pytest.approx(when, abs=1e-3)
    assert progress.FALL[Engine.REFERENCE].hinge_share is None  # from the ground
