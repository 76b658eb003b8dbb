"""Running the planar LOD on many trees: in chunks, serially or in worker
processes, with the same result either way.

Within a chunk, every tree starts in the linear tier (linear.py) and moves
to a nonlinear engine — the pymunk tier (chains/) or the MuJoCo reference
(`engine_for`) — with its pose and spin when it leaves the linear range;
trees a projectile can reach start in the nonlinear engine, which owns the
projectiles. Where the reference fails, the pymunk tier takes its trees.
`Quality.tier = "pymunk"` keeps every tree in the pymunk tier.

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

import math
import os
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from ..errors import SimulationError
from ..scene import Scene
from . import chains  # chains.PymunkTier loads pymunk when a tree first needs it
from . import quality as quality_levels
from .chains import StartState, Stats
from .common import SimTree, TreeMotion, cap_note
from .debris import MAX_SPIN
from .events import BROKE, TIER, UPROOTED, Event
from .linear import BLAST_SPLIT, ERROR_TOLERANCE, RETURNABLE, HandOff, LinearStats, LinearTier
from .loads import SceneLoads
from .projectiles import projectile_reaches
from .quality import Quality, nonlinear_engine
from .solver import SolveResult, frame_timing

# the pymunk tier's substep and force rates for trees a projectile can
# reach, at least (Hz; `default`'s): a hit jolts the stem, and its chains
# feel their frame's jolt one update later. At draft's 480 and 60 Hz the
# sapling the `boxes` preset's first box breaks gained 3.5 % of its energy
# by that; at 960 and 60 Hz 1.4 %, at 960 and 120 Hz 0.7 %
HIT_SUBSTEP_RATE = 960.0
HIT_FORCE_RATE = 120.0
# what the articulated tier takes (linear.HandOff kinds): large motion, tips
# at the ground and joints near breaking (it hands a root near breaking on);
# a cut and projectiles need the pymunk tier's felling and hits
ARTICULATED_KINDS = ("turn", "cone", "ground", "break")
CHUNK_SEGMENTS = 2000  # segments per solver: big enough to amortise numpy, small to spread


@dataclass
class TierUse:
    """Which tier simulated a tree: "linear", "pymunk" or "linear, then
    pymunk" from `switch` s, and why."""

    tier: str
    switch: float | None = None
    reason: str = ""


@dataclass
class ChunkResult:
    motions: list[TreeMotion]
    stats: Stats  # the pymunk tier's (all its instances in the chunk)
    linear: list[LinearStats]  # the linear tier's, then those of trees given back to it
    tiers: list[TierUse]
    h: float  # the pymunk tier's substep, s
    dt_update: float  # its load interval, s
    linear_step: float | None  # the linear tier's step, s
    segments: int
    segment_steps: int  # simulated segments x steps (each tier at its own step)
    objects: tuple | None = None  # projectile tracks (shapes, sizes, positions, rotations)
    reference: list = field(default_factory=list)  # SolveResults of the reference's runs
    came_back: list = field(default_factory=list)  # (time s, tree): back to the linear tier
    articulated: list = field(default_factory=list)  # SolveResults of the articulated tier's runs


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
    log = log or (lambda msg: None)
    loads = SceneLoads(scene, extent)
    frames = scene.frame_count
    substeps = max(1, round(quality.substep_rate / scene.fps))  # the pymunk tier's per frame
    engine = "pymunk" if quality.tier == "pymunk" else nonlinear_engine(quality)

    def engine_for(kind: str) -> str:
        """A cut and a tip at the ground go to the pymunk tier, robust at
        every step (a cut at `final` to the reference: quality.cut_engine);
        large motion in the wind, a joint near breaking and trees a
        projectile can reach go to the reference when it is the engine: its
        hinges are the linear tier's coordinates, at a coarse step it beats
        pymunk there (out/accuracy: boxes 0.16 % RMS at 1/480 s against
        0.56 % at about the same cost; a crate smashes the sapling as in the
        truth, where the planar chains lost one twig), and where a blast
        breaks branches the planar chains gained 0.1-3 % of energy the loads
        did not supply (sapling, 6-15 kg at 3-5 m), the reference none.
        The articulated tier (no MuJoCo) takes large motion, tips at the
        ground and joints near breaking, in the same coordinates (it breaks
        them as the reference does); what is cut, and trees a projectile can
        reach, go to the pymunk tier."""
        if engine == "articulated":
            return "articulated" if kind in ARTICULATED_KINDS else "pymunk"
        if engine == "reference" and quality.nonlinear == "auto" and \
                kind not in ("turn", "cone", "break", "projectile") and \
                not (kind == "cut" and quality.cut_engine == "nonlinear"):
            return "pymunk"
        return engine

    if quality.tier == "pymunk":
        in_nonlinear = [True] * len(trees)
    else:
        in_nonlinear = [bool(scene.projectiles) and projectile_reaches(scene, t.rig.model)
                        for t in trees]
    lin_idx = [i for i, p in enumerate(in_nonlinear) if not p]
    lin = LinearTier([trees[i] for i in lin_idx], scene, quality, loads, substeps, log) \
        if lin_idx else None
    pym: list[tuple[chains.PymunkTier, list[int]]] = []
    # (trees, start s, (q, v) or None, the HandOff or None, work done before, J)
    ref_runs: list[tuple] = []
    first = [i for i, p in enumerate(in_nonlinear) if p]
    if first and engine_for("projectile") == "pymunk":
        hit, note = quality, None
        if scene.projectiles and (quality.substep_rate < HIT_SUBSTEP_RATE
                                  or quality.force_rate < HIT_FORCE_RATE):
            hit = replace(quality, substep_rate=max(quality.substep_rate, HIT_SUBSTEP_RATE),
                          force_rate=max(quality.force_rate, HIT_FORCE_RATE))
            note = (f"trees a projectile can reach stepped at {hit.substep_rate:.0f} Hz with "
                    f"loads at {hit.force_rate:.0f} Hz on the pymunk tier, not "
                    f"{quality.substep_rate:.0f} and {quality.force_rate:.0f} (its hits jolt "
                    "the stems between coarser updates)")
        tier = chains.PymunkTier([trees[i] for i in first], scene, hit, loads, log=log)
        if note is not None:
            tier.stats.notes.append(note)
        tier.begin()
        pym.append((tier, first))
    elif first:
        ref_runs.append((first, 0.0, None, None, 0.0, "reference"))
    uses = [TierUse(engine_for("projectile") if p else "linear") for p in in_nonlinear]

    def pymunk_from(group: list[tuple[int, HandOff, HandOff]],
                    f: int) -> tuple[chains.PymunkTier, list[int]]:
        """A pymunk tier for trees (i, hand-off, the state it starts from)
        starting at one substep, brought up to frame f - 1."""
        members = [i for i, _, _ in group]
        tier = chains.PymunkTier([trees[i] for i in members], scene, quality, loads, log=log)
        substep = group[0][2].substep
        tier.begin(substep, StartState(np.concatenate([st.rot for _, _, st in group]),
                                       np.concatenate([st.omega for _, _, st in group])))
        if all(ho.kind in RETURNABLE for _, ho, _ in group):
            tier.hand_back = group[0][1].step_length
        for ff in range(math.ceil(substep / tier.spf - 1e-9), f):  # from before a blast
            tier.advance_frame(ff)
        return tier, members

    handed: list = []
    linear_work: dict[int, float] = {}  # J done on a tree in the linear tier before it left

    def from_blast(ho: HandOff, why: str) -> tuple[HandOff, str]:
        """The state an engine takes a tree from that left at `ho` for
        `why`: where a blast under way found it (linear.py,
        `_keep_before_blast`), else `ho`; and the reason to give."""
        start = ho if ho.before_blast is None else ho.before_blast
        return start, why if start is ho else \
            f"{why} at {ho.time:.3f} s; taken from {start.time:.3f} s, {start.reason}"

    def leaves(i: int, ho: HandOff) -> tuple[str, HandOff]:
        """Tree i left a linear tier (`ho`): its engine, recorded and logged,
        and the state that engine starts from: a tree that leaves while a
        blast is under way is taken from where the blast found it (linear.py,
        `_keep_before_blast`). The pymunk tier cannot take a blast's impulse
        half delivered; the linear tier, linearised at its step, rang the
        twigs differently from the nonlinear engines (the `explosion`
        preset's oak broke 4 joints on MuJoCo, where the reference breaks 7;
        from the blast's arrival, 7)."""
        to = engine_for(ho.kind)
        start, reason = from_blast(ho, ho.reason)
        u = uses[i]
        uses[i] = TierUse(f"linear, then {to}", round(start.time, 6), reason) \
            if u.switch is None else \
            TierUse(f"{u.tier}, then {to}", u.switch,
                    f"{u.reason}; to {to} at {start.time:.3f} s: {reason}")
        handed.append(Event(start.time, trees[i].name, TIER, "", f"to {to}: {reason}"))
        log(f"t = {ho.time:.3f} s: {trees[i].name} leaves the linear tier ({reason})")
        return to, start

    for f in range(1, frames):
        if lin is not None:
            to_pymunk: dict[int, list] = {}  # substep -> hand-offs: one pymunk tier each
            for ho in lin.advance_frame(f):
                i = lin_idx[ho.tree]
                to, start = leaves(i, ho)
                linear_work[i] = start.work
                if to == "pymunk":
                    to_pymunk.setdefault(start.substep, []).append((i, ho, start))
                else:  # its hinges are the linear tier's coordinates
                    if start is not ho:  # why it left, and its return, are ho's
                        start = replace(start, reason=ho.reason, kind=ho.kind,
                                        step_length=ho.step_length, before_blast=start)
                    ref_runs.append(([i], start.time, (start.q, start.v), start, start.work, to))
            for group in to_pymunk.values():
                pym.append(pymunk_from(group, f))
        for tier, _ in pym:
            tier.advance_frame(f)
        if progress is not None:
            progress(f, frames - 1)
    # each tree's frames: the linear tier's until it left, the nonlinear engine's after
    motions: list[TreeMotion | None] = [None] * len(trees)
    if lin is not None:
        for k, m in enumerate(lin.motions()):
            motions[lin_idx[k]] = m

    def take(i: int, m: TreeMotion, start: int, work_before: float) -> None:
        """Tree i's frames from `start` on are m's; `work_before` J: the
        work done on it before m's engine took it (the audit goes on)."""
        if motions[i] is None:
            motions[i] = m
            return
        mine = motions[i]
        mine.quaternions[start:] = m.quaternions[start:]
        mine.pivots[start:] = m.pivots[start:]
        mine.events.extend(m.events)
        mine.energy[start:] = m.energy[start:]
        mine.work[start:] = m.work[start:] + work_before
        # sub-frame samples: the earlier engine's before `start`, m's after
        nb = mine.quaternions.shape[1]
        keep = mine.extra_times < start / scene.fps

        def samples(mo: TreeMotion, rows) -> list[np.ndarray]:
            if mo.extra_quaternions is None:  # none kept
                return [np.zeros(0), np.zeros((0, nb, 4)), np.zeros((0, nb, 3))]
            return [mo.extra_times[rows], mo.extra_quaternions[rows], mo.extra_pivots[rows]]

        mine.extra_times, mine.extra_quaternions, mine.extra_pivots = (
            np.concatenate(pair) for pair in zip(samples(mine, keep),
                                                 samples(m, slice(None))))

    returns: list[tuple[int, int, np.ndarray, np.ndarray]] = []  # (tree, frame, q, v)

    def take_pymunk(tier: chains.PymunkTier, members: list[int], works: list[float]) -> None:
        """A pymunk tier's frames for its trees; those it gave back queued."""
        start = tier.first_frame + (1 if tier.substep_start % tier.spf else 0)
        for i, m, w in zip(members, tier.motions(), works):
            take(i, m, start, w)
        if tier.handed_back is not None:
            f_back, q, v = tier.handed_back
            for k, i in enumerate(members):
                lo, hi = 2 * tier.offsets[k], 2 * tier.offsets[k + 1]
                returns.append((i, f_back, q[lo:hi], v[lo:hi]))

    for tier, members in pym:
        take_pymunk(tier, members, [linear_work.get(i, 0.0) for i in members])

    def linear_from(i: int, f_back: int, q: np.ndarray, v: np.ndarray, work_before: float):
        """Tree i in a linear tier of its own from frame f_back, with the
        nonlinear engine's hinge angles and rates there (no jump),
        to the end or until it leaves again: then to the reference (a run
        queued) or a pymunk tier (run here), `work_before` J plus the tier's
        own carried over. The tier and those pymunk tiers."""
        t_back = f_back / scene.fps
        log(f"t = {t_back:.3f} s: {trees[i].name} is back in the linear range: "
            "the linear tier takes it again")
        uses[i] = TierUse(f"{uses[i].tier}, then linear", uses[i].switch,
                          f"{uses[i].reason}; back at {t_back:.3f} s")
        tier = LinearTier([trees[i]], scene, quality, loads, substeps, log, f_back, (q, v))
        later = []
        for f in range(f_back + 1, frames):
            for ho in tier.advance_frame(f):
                to, start = leaves(i, ho)
                work = work_before + start.work
                if to == "pymunk":
                    p_tier, _ = pymunk_from([(i, ho, start)], f)
                    for ff in range(f, frames):
                        p_tier.advance_frame(ff)
                    later.append((p_tier, [i], work))
                else:
                    ref_runs.append(([i], ho.time, (ho.q, ho.v), ho, work, to))
        return tier, later

    objects = None
    ref_stats = []
    # each return: (time s, tree, the stats of the linear tier it came back to)
    returned: list[tuple[float, int, LinearStats]] = []

    def back_to_linear(i: int, f_back: int, q: np.ndarray, v: np.ndarray) -> None:
        """Tree i back in a linear tier from frame f_back (linear_from)."""
        work_back = float(motions[i].work[f_back])
        tier, later = linear_from(i, f_back, q, v, work_back)
        returned.append((f_back / scene.fps, i, tier.stats))
        take(i, tier.motions()[0], f_back, work_back)
        for p_tier, p_members, p_work in later:
            pym.append((p_tier, p_members))
            take_pymunk(p_tier, p_members, [p_work])

    articulated_results: list[SolveResult] = []

    def on_to_pymunk(i: int, on: HandOff, why: str) -> tuple[HandOff, str]:
        """Tree i from the articulated tier to a pymunk tier run to the end,
        from `on` (or where a blast under way found it; work counted from
        the bake's start): the state it starts from and the reason given."""
        start, reason = from_blast(on, why)
        if motions[i] is not None:  # what the articulated tier broke, the pymunk tier replays
            motions[i].events = [e for e in motions[i].events
                                 if e.kind not in (BROKE, UPROOTED) or e.time < start.time]
        handed.append(Event(start.time, trees[i].name, TIER, "", f"to pymunk: {reason}"))
        p_tier, _ = pymunk_from([(i, on, start)], frames)
        pym.append((p_tier, [i]))
        take_pymunk(p_tier, [i], [start.work])
        return start, reason

    def articulated_run(i: int, ho: HandOff, work_before: float) -> None:
        """Tree i in the articulated tier from its hand-over `ho` (J done on
        it before: `work_before`), to the end, back to the linear tier or
        on to the pymunk tier."""
        from .articulated import ArticulatedTier  # numba, loaded when a tree first needs it

        # the work counted from the bake's start (the linear tier counts from its own)
        before = ho.before_blast
        ho = replace(ho, work=work_before, before_blast=None if before is None else
                     replace(before, work=work_before - ho.work + before.work))
        tier = ArticulatedTier([trees[i]], scene, quality, loads)
        try:
            result = tier.run(ho.time, (ho.q, ho.v), ho.step_length, ho.before_blast,
                              work_before)
        except SimulationError as exc:  # the pymunk tier takes the tree from the hand-over
            log(f"{trees[i].name}: the articulated tier failed ({exc}); the pymunk tier "
                "takes over")
            uses[i] = TierUse(uses[i].tier.rsplit(", then articulated", 1)[0] + ", then pymunk",
                              uses[i].switch, uses[i].reason + "; the articulated tier failed")
            on_to_pymunk(i, ho, f"the articulated tier failed ({exc.message})")
            return
        articulated_results.append(result)
        take(i, result.motions[trees[i].name], tier.first_frame, work_before)
        if result.handed_back is not None:
            back_to_linear(i, *result.handed_back)
            return
        on = result.handed_on
        if on is None:
            return
        start, reason = on_to_pymunk(i, on, on.reason)
        uses[i] = TierUse(f"{uses[i].tier}, then pymunk", uses[i].switch,
                          f"{uses[i].reason}; to pymunk at {start.time:.3f} s: {reason}")
        log(f"t = {on.time:.3f} s: {trees[i].name} leaves the articulated tier ({reason})")

    k = 0
    # trees given back may leave again: returns and reference runs are appended
    while returns or k < len(ref_runs):
        if returns:
            back_to_linear(*returns.pop(0))
            continue
        members, t0, state, ho, work_before, to = ref_runs[k]
        k += 1
        if to == "articulated":
            articulated_run(members[0], ho, work_before)
            continue
        from .reference import ReferenceSolver

        ref = ReferenceSolver([trees[i] for i in members], scene, quality, loads, log=log,
                              timestep=quality.reference_step)
        # a tree taken for large motion or a moment near breaking comes back
        # once it is in the linear range again (not with projectiles about)
        back = ho.step_length if ho is not None and ho.kind in RETURNABLE else None
        try:
            result = ref.run(None, t0, state, hand_back=back)
        except SimulationError as exc:
            # the reference at a coarse step could not hold it: the pymunk tier takes the
            # trees from the hand-over (or from the start: trees a projectile reaches)
            log(f"{', '.join(trees[i].name for i in members)}: the reference failed ({exc}); "
                "the pymunk tier takes over")
            tier = chains.PymunkTier([trees[i] for i in members], scene, quality, loads, log=log)
            if ho is None:
                tier.begin()
            else:
                tier.begin(ho.substep, StartState(ho.rot, ho.omega))
            for f in range(1 if ho is None else math.ceil(ho.substep / tier.spf - 1e-9), frames):
                tier.advance_frame(f)
            pym.append((tier, members))
            take_pymunk(tier, members, [work_before] * len(members))
            for i in members:
                uses[i] = TierUse("pymunk (the reference failed)") if ho is None else \
                    TierUse(uses[i].tier.rsplit(", then reference", 1)[0] + ", then pymunk",
                            uses[i].switch, uses[i].reason + "; the reference failed")
            continue
        ref_stats.append(result)
        # progress for logs: the linear tier's frames are done long before these
        names = [trees[i].name for i in members]
        log(f"reference: {names[0]}{f' and {len(names) - 1} more' if len(names) > 1 else ''} "
            f"simulated from t = {t0:.2f} s in "
            f"{sum(result.timing.get(k, 0.0) for k in TIMED):.1f} s")
        start = math.ceil(round(t0 / ref.h) / ref.spf - 1e-9)
        for i in members:
            take(i, result.motions[trees[i].name], start, work_before)
        if result.objects is not None:
            o = result.objects
            objects = (o.shapes, o.sizes, o.positions, o.rotations)
        if result.handed_back is not None:
            (i,) = members
            back_to_linear(i, *result.handed_back)
    for i, tree in enumerate(trees):  # switches first at a time, in the order they came
        mine = [e for e in handed if e.tree == tree.name]
        if mine:
            motions[i].events = sorted(mine + motions[i].events, key=lambda ev: ev.time)
    stats = merge_stats([tier.stats for tier, _ in pym])
    for tier, _ in pym:
        if tier.projectiles is not None:
            p = tier.projectiles
            objects = (p.shape, p.size, p.track_pos, p.track_quat)
    h = min([1.0 / (scene.fps * substeps)] + [tier.h for tier, _ in pym])
    pym_h = pym[0][0] if pym else None
    steps = sum(sum(trees[i].rig.model.n_segments for i in members) * tier.stats.substeps
                for tier, members in pym)
    if lin is not None:
        steps += sum(trees[i].rig.model.n_segments for i in lin_idx) * lin.stats.steps
    steps += sum(r.timing.get("segment_steps", 0) for r in ref_stats + articulated_results)
    steps += sum(trees[i].rig.model.n_segments * st.steps for _, i, st in returned)
    linear = ([lin.stats] if lin is not None else []) + [st for _, _, st in returned]
    return ChunkResult(motions, stats, linear, uses, h,
                       pym_h.dt_update if pym_h is not None else h,
                       lin.h if lin is not None else None,
                       sum(t.rig.model.n_segments for t in trees), steps, objects, ref_stats,
                       [(t, trees[i].name) for t, i, _ in returned], articulated_results)


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
            frames = scene.frame_count - 1
            for k, fut in enumerate(futures):
                results[k] = fut.result()
                if progress is not None:  # the bake's frames, in chunks' shares
                    progress((k + 1) * frames // len(plan), frames)
    motions = {}
    for (_, members), res in zip(plan, results):
        for i, motion in zip(members, res.motions):
            motions[trees[i].name] = motion
    return motions, results


def _chunk_progress(progress, k: int, total: int):
    if progress is None:
        return None

    def tick(done: int, frames: int) -> None:  # the bake's frames, in chunks' shares
        progress((k * frames + done) // total, frames)

    return tick


TIMED = ("step_seconds", "update_seconds")  # a reference run's cost (compiling is in updates)


def merge_stats(stats: list[Stats]) -> Stats:
    """One Stats for several pymunk tiers: counts add up, extremes take the worst."""
    out = Stats()
    worst = {"max_inertia_ratio", "max_joint_gap", "max_refine"}
    for r in stats:
        for f in fields(Stats):
            a, b = getattr(out, f.name), getattr(r, f.name)
            if f.name in worst:
                setattr(out, f.name, max(a, b))
            elif f.name == "first_limit":
                if b is not None and (a is None or b[2] < a[2]):
                    out.first_limit = b
            elif f.name == "substeps":
                out.substeps = max(a, b)
            elif f.name == "notes":
                out.notes = a + b
            elif f.name == "frame_seconds":  # a tier started late covers the last frames
                n = max(len(a), len(b))
                out.frame_seconds = list(np.pad(a, (n - len(a), 0)) + np.pad(b, (n - len(b), 0)))
            else:
                setattr(out, f.name, a + b)
    return out


class PlanarLOD:
    """The product's solver: the scene's active trees in chunks (fixed by the
    scene), each chunk in its linear and pymunk tiers, in `workers`
    processes; the same bake for any number of workers."""

    def __init__(self, trees: list[SimTree], qualities: list[Quality], scene: Scene,
                 extent: np.ndarray, workers: int = 1, log=None):
        self.trees, self.qualities, self.scene = trees, qualities, scene
        self.extent, self.workers = extent, workers
        self.log = log or (lambda msg: None)

    def run(self, progress=None) -> SolveResult:
        scene = self.scene
        motions, chunks = simulate(self.trees, self.qualities, scene, self.extent, self.workers,
                                   self.log, progress)
        st = merge_stats([c.stats for c in chunks])
        lin = [s for c in chunks for s in c.linear]
        quality = next(q for t, q in zip(self.trees, self.qualities) if t.active)
        meta = {"substep": min(c.h for c in chunks),
                "force_interval": min(c.dt_update for c in chunks), "chunks": len(chunks)}
        steps = [c.linear_step for c in chunks if c.linear_step is not None]
        if steps:
            meta["linear_step"] = min(steps)
        stats = {k: v for k, v in asdict(st).items()
                 if k not in ("notes", "step_seconds", "update_seconds", "first_limit",
                              "frame_seconds")}
        stats["max_joint_gap"] = float(f"{st.max_joint_gap:.3g}")
        stats["linear_steps"] = sum(s.steps for s in lin)
        stats["linear_rebuilds"] = sum(s.rebuilds for s in lin)
        stats["linear_relinearised"] = sum(s.relinearised for s in lin)
        stats["linear_limited"] = sum(s.limited for s in lin)
        stats["linear_split"] = sum(s.split for s in lin)
        stats["linear_parts"] = max((s.parts for s in lin), default=1)
        meta["stats"] = stats
        tiers = {}
        for (_, members), c in zip(chunks_plan(self.trees, self.qualities, scene), chunks):
            for i, use in zip(members, c.tiers):
                tiers[self.trees[i].name] = use.tier if use.switch is None else \
                    f"{use.tier} at {use.switch:.3f} s ({use.reason})"
        arts = [r for c in chunks for r in c.articulated]
        # the articulated tier's capped loads join the others' note
        capped = [Stats(limited=r.meta["stats"]["limited"],
                        first_limit=r.meta["stats"]["first_limit"])
                  for r in arts if r.meta["stats"]["limited"]]
        notes = lod_notes(st, lin, quality, meta["substep"], capped)
        fallback = sum(("pymunk" in use.tier or "articulated" in use.tier)
                       for c in chunks for use in c.tiers)
        if fallback and quality.tier == "auto" and quality.nonlinear == "auto" \
                and not quality_levels.reference_available():
            notes.append(f"nonlinear engines: the articulated tier and pymunk for {fallback} "
                         f"tree{'s' if fallback > 1 else ''}, as MuJoCo is not installed "
                         "(pip install 'treebake[reference]': the reference, more accurate "
                         "for hits and felling)")
        if arts:
            meta["articulated_runs"] = len(arts)
            meta["articulated_step"] = min(r.meta["step"] for r in arts)
            for key in ("steps", "split", "updates"):
                stats[f"articulated_{key}"] = sum(r.meta["stats"][key] for r in arts)
            # what a run handed on broke, the pymunk tier replayed (and counted)
            kept = [r.meta["stats"] for r in arts if r.handed_on is None]
            broken, parts = sum(k["broken"] for k in kept), sum(k["debris"] for k in kept)
            stats["broken"] += broken
            stats["debris"] += parts
            if broken:
                from .articulated import broken_note

                notes.append(broken_note(broken, parts,
                                         sum(k["debris_clamped"] for k in kept),
                                         sum(k["uprooted"] for k in kept),
                                         sum(k["twist_raised"] for k in kept)))
            if stats["articulated_split"]:  # one note for all runs, the counts summed
                from .articulated import split_note

                notes.append(split_note(stats["articulated_split"]))
        refs = [r for c in chunks for r in c.reference]
        back = sorted(b for c in chunks for b in c.came_back)
        stats["returned"] = len(back)
        if back:
            notes.append(f"{len(back)} tree{'s' if len(back) > 1 else ''} came back to the "
                         f"linear tier, back in its range (first: "
                         f"{back[0][1]} at t = {back[0][0]:.3f} s)")
        if refs:
            meta["reference_runs"] = len(refs)
            meta["reference_step"] = quality.reference_step
            # joints the reference broke after a hand-off count with the pymunk tier's
            stats["broken"] += sum(r.meta["stats"]["broken"] for r in refs)
            stats["debris"] += sum(r.meta["stats"]["parts"] for r in refs)
            closest = [r.meta["stats"]["closest_to_breaking"] for r in refs
                       if "closest_to_breaking" in r.meta["stats"]]
            if closest:  # any joint the reference ran, broken ones included (the tiers keep none)
                stats["closest_to_breaking"] = max(closest, key=lambda c: c["fraction"])
            from .reference import FREE_PART_COUNTS, free_part_notes

            # one set of notes for all hand-overs: the same words once, the counts summed
            own = [set(free_part_notes(r.meta["stats"])) for r in refs]
            notes += list(dict.fromkeys(n for r, o in zip(refs, own) for n in r.notes
                                        if n not in o))
            notes += free_part_notes({k: sum(r.meta["stats"][k] for r in refs)
                                      for k in FREE_PART_COUNTS})
        step = (sum(s.step_seconds for s in lin) + st.step_seconds
                + sum(r.timing.get("step_seconds", 0.0) for r in refs + arts))
        update = (sum(s.update_seconds for s in lin) + st.update_seconds
                  + sum(r.timing.get("update_seconds", 0.0) + r.timing.get("compile_seconds", 0.0)
                        for r in refs + arts))
        frame_seconds = np.zeros(scene.frame_count - 1)
        for s in [st, *lin]:
            if len(s.frame_seconds):  # a pymunk tier started late covers the last frames
                frame_seconds[len(frame_seconds) - len(s.frame_seconds):] += s.frame_seconds
        substeps = round(1.0 / (scene.fps * meta["substep"]))
        timing = {"step_seconds": round(step, 3), "update_seconds": round(update, 3),
                  "build_seconds": round(sum(s.build_seconds for s in lin), 3),
                  "segment_steps": sum(c.segment_steps for c in chunks),
                  **frame_timing(frame_seconds, substeps)}
        objects = None
        for c in chunks:
            if c.objects is not None:
                from ..bake import ObjectsBake

                objects = ObjectsBake(*c.objects)
        return SolveResult(motions, objects, meta, notes, tiers, timing)


def chunks_plan(trees: list[SimTree], qualities: list[Quality], scene: Scene):
    return chunks(trees, qualities, whole=bool(scene.projectiles))


def lod_notes(stats: Stats, linear: list[LinearStats], quality: Quality, h: float,
              capped: list[Stats] = ()) -> list[str]:
    """What the planar LOD adapted or clamped, in words (never silently);
    `capped`: the other tiers' counts of capped loads."""
    notes = []
    if stats.inertia_floored:
        notes.append(f"stability: rotary inertia raised on {stats.inertia_floored} of "
                     f"{stats.bodies} pymunk bodies (up to {stats.max_inertia_ratio:.1f}x) to "
                     f"keep omega*h <= {quality.stability:g} at h = {h * 1e3:.3f} ms")
    limited = [s for s in [stats, *linear, *capped] if s.limited]
    if limited:
        first = min(limited, key=lambda s: s.first_limit[2])
        merged = Stats(limited=sum(s.limited for s in limited), first_limit=first.first_limit)
        notes.append(cap_note(merged))
    split = sum(s.split for s in linear)
    if split:
        notes.append(f"{split} linear steps were split in {BLAST_SPLIT} while a blast pushed")
    refined = [r for s in linear for r in s.refined]
    if refined:
        t, tree, path, error = min(refined)
        parts = max(s.parts for s in linear)
        notes.append(f"linear steps split in up to {parts} for accuracy from t = {t:.3f} s "
                     f"(the step's error estimate at {tree} {path}: {error:.2%} of its height, "
                     f"past {ERROR_TOLERANCE:.2%})")
    if stats.refined:
        notes.append(f"{stats.refined} substeps were split into up to {stats.max_refine} steps "
                     "while a blast, a hit, a capped load or a fast spin acted (pivots drift "
                     "with the square of the step)")
    notes += list(dict.fromkeys(stats.notes))
    if stats.broken:
        notes.append(f"{stats.broken} joints broke; {stats.debris} parts fell off as debris")
    if stats.debris_clamped:
        notes.append(f"debris spin clamped at {MAX_SPIN:.0f} rad/s on {stats.debris_clamped} "
                     "body substeps")
    return notes
