"""The reference as a solver (`--solver full`: every tree from rest to the
end) and as a tier of the planar LOD (a tree from a hand-off, maybe back),
and what its runs report."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from ...quality import Quality
from ...scene import Scene
from ..common import ProjectileTracks, SimTree, cap_note
from ..handoff import Engine, HandOff, Reason, TierReport
from ..loads import SceneLoads
from ..rules import BLAST_RING, BLAST_STEP, MAX_SPIN, broken_note
from ..solver import SolveResult, frame_timing
from .stepper import MAX_SUBSTEPS, SPIN_PER_STEP, ReferenceEngine

TWIG_HZ = 50.0  # a twig's ringing under a blast front (the blast note's example)


def engine_notes(engine: ReferenceEngine) -> list[str]:
    """What a run's settings mean for its motion, in words: the same words
    for every run at one step, so that the LOD's runs merge into one set."""
    h = engine.h
    notes = [(f"reference: MuJoCo {mujoco.__version__}, discrete (stiffness-implicit) "
              f"integrator, h = {h * 1e3:.4g} ms, loads every {engine.dt_force * 1e3:.4g} ms: "
              f"numerical damping adds about {math.pi * h:.2g} x f (Hz) to the damping ratio "
              "of a mode of frequency f"),
             ("reference: joints are two perpendicular hinges (no twist); the cone limit is a "
              "square in the two swing angles; bones of different trees do not collide")]
    if engine.scene.explosions:
        hb = h / engine.blast_split  # s, the step while a blast pushes and rings
        notes.append(f"reference: while a blast pushes and for {BLAST_RING:g} s after, the step "
                     f"is {hb * 1e3:.4g} ms, which damps a twig ringing at {TWIG_HZ:g} Hz by "
                     f"about {math.pi * TWIG_HZ * hb:.2g} (ratio), with the loads updated every "
                     "step; a joint past its strength at any of those steps lets go there")
    return notes


def count_notes(stats: dict) -> list[str]:
    """What free parts and blasts needed, from one run's counts or the sums
    of several runs' (breaks and capped loads have their own notes)."""
    notes = []
    if stats["clamped"]:
        notes.append(f"reference: free parts' spin clamped at {MAX_SPIN:.0f} rad/s on "
                     f"{stats['clamped']} body updates")
    if stats["split"]:
        notes.append(f"reference: steps split in up to {MAX_SUBSTEPS} where free parts spun "
                     f"faster than {SPIN_PER_STEP:g} rad per step, on {stats['split']} "
                     "model-steps")
    if stats["blast_split"]:
        notes.append(f"reference: steps split to at most {BLAST_STEP * 1e3:.4g} ms while a "
                     f"blast pushed or its twigs rang (until {BLAST_RING:g} s after its push), "
                     f"on {stats['blast_split']} model-steps")
    if stats["damping_scaled"]:
        notes.append(f"reference: structural damping of free parts scaled down on "
                     f"{stats['damping_scaled']} steps, to what an explicit step can remove "
                     "without overshoot")
    return notes


def report(engine: ReferenceEngine) -> TierReport:
    """A run's counts (they add up over the LOD's runs), the first capped
    load, the joint that came closest to breaking, its setting notes and
    timings (s)."""
    st = engine.stats
    stats = {"steps": st.steps, "updates": st.updates, "models": len(engine.groups),
             "bodies": st.bodies, "bones": engine.n, "rebuilds": st.rebuilds,
             "parts": st.parts, "limited": st.limited, "broken": st.broken,
             "clamped": st.clamped, "damping_scaled": st.damping_scaled, "split": st.split,
             "blast_split": st.blast_split, "first_limit": st.first_limit, "step": engine.h}
    if st.returned_broken:  # (only where it happened: bakes without it keep their bytes)
        stats["returned_broken"] = st.returned_broken
    if st.closest is not None:
        frac, tree, path, when = st.closest
        stats["closest_to_breaking"] = {"fraction": round(frac, 4), "tree": tree,
                                        "segment": path, "time_s": round(when, 4)}
    timing = {k: round(v, 3) for k, v in engine.timing.items()}
    steps = np.asarray(engine.step_times)
    if len(steps):
        spf = engine.spf
        per_frame = steps[: len(steps) // spf * spf].reshape(-1, spf).sum(1)
        timing.update(segment_steps=sum(t.rig.model.n_segments for t in engine.trees)
                      * len(steps), **frame_timing(per_frame, spf))
    return TierReport(Engine.REFERENCE, stats, engine_notes(engine), timing)


class ReferenceTier:
    """The reference as a tier of the planar LOD (handoff.Tier): some trees
    from rest (those a projectile can reach) or one tree from a hand-off,
    handed back to the linear tier once back in its range when `hand_back`
    (the linear tier's step, s) is given."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 start: HandOff | None = None, hand_back: float | None = None, log=None):
        self.engine = ReferenceEngine(trees, scene, quality, loads, log=log,
                                      timestep=quality.reference_step,
                                      touch_ground=start is not None
                                      and start.reason is Reason.GROUND,
                                      throws=start is None)
        if start is None:
            self.engine.begin()
        else:
            self.engine.begin(start.time, (start.q, start.v), hand_back)
        self.first_frame = self.engine.first_frame

    def advance_to(self, frame: int) -> list[HandOff]:
        return self.engine.advance_to(frame)

    def motions(self):
        return self.engine.motions()

    def report(self) -> TierReport:
        return report(self.engine)

    def tracks(self) -> ProjectileTracks | None:
        return tracks(self.engine)


def tracks(engine: ReferenceEngine) -> ProjectileTracks | None:
    """The projectiles' flight, after a run; None without projectiles."""
    got = engine.tracks()
    if got is None:
        return None
    p = engine.scene.projectiles
    return ProjectileTracks([x.shape for x in p], np.asarray([x.size for x in p]), *got)


class ReferenceSolver:
    """`--solver full` (solver.Solver): the scene's active trees in MuJoCo
    from rest to the end, at `timestep` s (default stepper.DEFAULT_TIMESTEP)
    with loads every 1/`force_rate` s."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None, timestep: float | None = None, force_rate: float | None = None):
        self.engine = ReferenceEngine(trees, scene, quality, loads, log, timestep, force_rate)
        self.index = {t.name: i for i, t in enumerate(trees)}

    def run(self, progress=None, on_tree=None) -> SolveResult:
        """Simulate the shot as one model; with `on_tree` (solver.TreeSink)
        each tree's motion goes there at the end and the result keeps none."""
        engine = self.engine
        engine.begin()
        frames = engine.scene.frame_count
        engine.advance_to(0)  # the rest pose (a one-frame scene has no other)
        for f in range(1, frames):
            engine.advance_to(f)
            if progress is not None:
                progress(f, frames - 1)
        rep = report(engine)
        notes = rep.notes + [n for n in (cap_note(rep.stats["limited"], rep.stats["first_limit"]),
                                         broken_note({"reference": rep.stats["broken"]}))
                             if n] + count_notes(rep.stats)
        meta = {"substep": engine.h, "force_interval": engine.dt_force, "integrator": "discrete",
                "stats": {k: v for k, v in rep.stats.items() if k != "first_limit"}}
        motions = {t.name: m for t, m in zip(engine.trees, engine.motions())}
        if on_tree is not None:
            for name, motion in motions.items():
                on_tree(self.index[name], motion, Engine.REFERENCE.value)
            motions = {}
        return SolveResult(motions, tracks(engine), meta, notes,
                           {t.name: Engine.REFERENCE.value for t in engine.trees}, rep.timing)
