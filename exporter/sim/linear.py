"""The planar LOD's linear tier: whole trees stepped implicitly in joint
space (joint_space.py) while they stay in the linear range (range.py).

Stepping: Newmark's average-acceleration rule (the trapezoidal rule:
unconditionally stable, no numerical damping, period error (omega h)^2/12)
at the quality's `linear_rate`, finer for a stiff tree (STEP_TURN); the
loads are evaluated once per step at the predicted state, with gravity's
tangent stiffness in the implicit matrix. While a blast pushes the tier's
bones, steps are split in BLAST_SPLIT parts (the pulse lasts
milliseconds). After every step its local error is estimated at every
bone's tip; past ERROR_TOLERANCE of the tree's height the steps are split
in two from then on. Once a bone of the trees' mean pose (over MEAN_TIME)
has turned the quality's `relinearise` from the pose the system was
linearised at, it is linearised again there. A tree leaves the tier the
step it leaves the linear range (range.py; `_leaving`), with its pose, spin and
hinge state (handoff.HandOff). docs/physics.md, "The linear tier", has the
derivations and the measurements behind each constant.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import SimulationError
from ..quality import Quality
from ..rotations import matrices_from_quaternions
from ..scene import Scene
from .audit import Ledger, LoadWork, per_tree
from .common import Bones, SimTree, TreeMotion, external_loads, locate
from .handoff import Engine, HandOff, Reason, TierReport
from .hinges import pose_frames
from .joint_space import JointSpace
from .layout import ChainLayout
from .loads import SceneLoads, meets
from .range import BREAK_MARGIN, CONE_FRACTION, CONTACT_MARGIN, MAX_TURN
from .rules import BLAST_RING

BETA, GAMMA = 0.25, 0.5  # Newmark's average acceleration
BLAST_SPLIT = 32  # parts per step while a blast pushes (1.3 ms at 24 Hz)
ERROR_TOLERANCE = 5e-4  # a step's local error at a tip, as a fraction of its tree's height
MAX_PARTS = 8  # the most parts the error estimate splits a step into
REARM = 0.25  # it splits again once the estimate has been below this much of the tolerance
MEAN_TIME = 0.5  # s: the mean pose (for relinearising) averages the angles over this long
STEP_TURN = 0.3  # rad: the most a tree's first mode turns in one step


@dataclass
class LinearStats:
    steps: int = 0
    dofs: int = 0
    rebuilds: int = 0
    relinearised: int = 0
    limited: int = 0
    first_limit: tuple | None = None
    split: int = 0  # steps split while a blast pushed
    parts: int = 1  # parts every step is split into, for accuracy (ERROR_TOLERANCE)
    refined: list = field(default_factory=list)  # (time s, tree, segment, estimate) per split
    build_seconds: float = 0.0
    step_seconds: float = 0.0
    update_seconds: float = 0.0  # loads, range checks, error estimate, mean pose, recording
    frame_seconds: list[float] = field(default_factory=list)


class LinearTier:
    """The linear tier for some trees of one quality. `pymunk_substeps`: the
    pymunk tier's substeps per frame (a tree handed over at a step starts
    there at the substep at or before it). With `state` (hinge angles and
    rates (2B,), rad and rad/s from the grown shape), the trees start from
    it at frame `start_frame` (coming back from a nonlinear engine), else at
    rest at frame 0."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 pymunk_substeps: int, log=None, start_frame: int = 0,
                 state: tuple[np.ndarray, np.ndarray] | None = None):
        self.scene, self.quality, self.loads = scene, quality, loads
        self.log = log or (lambda msg: None)
        self.trees = list(trees)
        self.stats = LinearStats()
        # steps: the quality's rate, or finer for a stiff tree, so that its
        # first mode turns at most STEP_TURN per step (trapezoidal period
        # error (omega h)^2 / 12: 0.75 %)
        f1 = max((t.rig.first_frequency for t in trees), default=0.0)
        self.spf = max(1, math.ceil(quality.linear_rate / scene.fps - 1e-9),
                       math.ceil(2 * math.pi * f1 / (STEP_TURN * scene.fps) - 1e-9))
        self.ratio = pymunk_substeps / self.spf  # pymunk substeps per linear step
        self.h = 1.0 / (scene.fps * self.spf)
        frames = scene.frame_count
        self.every = Bones.of(self.trees)
        counts = np.diff(self.every.offsets)
        self.angles = [np.zeros((frames, 2 * int(c))) for c in counts]
        self.last_frame = np.full(len(self.trees), frames - 1)  # last frame each tree spent here
        self.members = list(range(len(self.trees)))
        self.ledger = Ledger(frames, len(self.trees))
        self.load_work = LoadWork(trapezoid=True)
        self.step = start_frame * self.spf  # whole steps done
        self.t = self.step * self.h
        self.part, self.parts = 0, 1  # parts of the current step done, and its parts
        self.blast_step = False
        self.before_blast: dict[int, HandOff] = {}  # tree -> its state as a blast arrived
        self.armed = True  # the error estimate may split the steps
        self._build(*(state if state is not None else (np.zeros(0), np.zeros(0))))
        self._record(start_frame)
        self.first_frame = self.frame = start_frame

    # ------------------------------------------------------------------
    # the system of the member trees

    def _build(self, q: np.ndarray, v: np.ndarray, q_mean: np.ndarray | None = None) -> None:
        """(Re)build the joint-space system of the member trees; `q`, `v`
        their state in the new numbering (empty: at rest), `q_mean` their
        mean pose (None: `q`)."""
        t0 = time.perf_counter()
        trees = [self.trees[i] for i in self.members]
        self.bones = b = Bones.of(trees)
        if not trees:
            self.model = None
            return
        layout = ChainLayout.of(trees, b.offsets, b.pivot0, b.tip0)
        hold = None if self.scene.prestress else np.zeros(2 * b.n)
        self.model = JointSpace(b, layout, self.loads.g, GAMMA * self.h, BETA * self.h * self.h,
                                hold)
        for k, t in enumerate(trees):  # a tree that lost parts keeps its springs' set
            if t.hold is not None:
                self.model.hold[2 * b.offsets[k]:2 * b.offsets[k + 1]] = t.hold
        n = self.model.n
        self._state = None
        self.q = q if len(q) else np.zeros(n)
        self.v = v if len(v) else np.zeros(n)
        self.q_mean = self.q.copy() if q_mean is None else q_mean
        self.a = self.model.mass_factor.solve(self.rhs(self.t, self.q, self.v))
        self.cone = np.repeat(b.cone, 2)
        self.tip_rest = b.tip0[:, 2]
        self.cut_time = np.array([trees[k].cut.time if trees[k].cut is not None else np.inf
                                  for k in range(len(trees))])
        self.tip_arm = (b.tip0 - b.pivot0).T.copy()
        # when blasts push these bones (at rest: the steps split then)
        self.blast_windows = self.loads.blast_windows(b.com0, self.model.axis0.T, b.props)
        top = np.zeros(len(trees))
        np.maximum.at(top, b.bone_tree, b.tip0[:, 2])
        low = np.full(len(trees), np.inf)
        np.minimum.at(low, b.bone_tree, b.pivot0[:, 2])
        self.bone_height = np.maximum(top - low, 1e-3)[b.bone_tree]  # m, its tree's
        self.stats.build_seconds += time.perf_counter() - t0
        self.stats.dofs = max(self.stats.dofs, n)

    def locate(self, bone: int) -> tuple[str, int]:
        return locate([self.trees[i] for i in self.members], self.bones.offsets,
                      self.bones.bone_tree, bone)

    def rhs(self, t: float, q: np.ndarray, v: np.ndarray, dt: float | None = None,
            record: bool = False):
        """The equations' right-hand side at time t and state (q, v), loads
        at the state's pose (blasts averaged over the next `dt` s)."""
        model, b = self.model, self.bones
        kin = model.kinematics(q, v)
        pose = model.pose(kin, q)
        dt = self.h if dt is None else dt
        # blasts: the impulse within this step, which ends at t
        com = pose.com.T
        force = external_loads(self.loads, b, t, com, pose.vcom.T, pose.axis.T, self.stats,
                               self.locate, dt=dt, blast_start=t - dt)
        if record:
            self.ledger.add_work(self._per_tree(self.load_work.update(force, com)))
        force += b.mass[:, None] * self.loads.g
        return model.rhs(np.ascontiguousarray(force.T), kin, pose, q)

    # ------------------------------------------------------------------
    # running

    def advance_to(self, frame: int) -> list[HandOff]:
        """Step to `frame`, recording every frame: the trees that left the
        tier meanwhile (handoff.Tier)."""
        out: list[HandOff] = []
        while self.frame < frame:
            self.frame += 1
            out += self.advance_frame(self.frame)
        return out

    def tracks(self) -> None:
        """No projectiles in the linear tier (handoff.Tier)."""
        return None

    def report(self) -> TierReport:
        """Counts (deterministic), notes and timings (s) of the run."""
        st = self.stats
        stats = {"steps": st.steps, "dofs": st.dofs, "rebuilds": st.rebuilds,
                 "relinearised": st.relinearised, "limited": st.limited, "split": st.split,
                 "max_parts": st.parts, "first_limit": st.first_limit, "refined": st.refined,
                 "step": self.h, "segments": sum(t.rig.model.n_segments for t in self.trees)}
        timing = {"step_seconds": st.step_seconds, "update_seconds": st.update_seconds,
                  "build_seconds": st.build_seconds, "frame_seconds": st.frame_seconds,
                  "segment_steps": stats["segments"] * st.steps}
        return TierReport(Engine.LINEAR, stats, [], timing)

    def advance_frame(self, f: int) -> list[HandOff]:
        """Step to frame f, record it; the trees that left the tier meanwhile."""
        t_frame = time.perf_counter()
        timed = self.stats.step_seconds + self.stats.update_seconds + self.stats.build_seconds
        out: list[HandOff] = []
        while self.step < f * self.spf and self.model is not None:
            out += self._step()
        self._record(f)
        took = time.perf_counter() - t_frame
        # range checks, the error estimate, the mean pose and recording count
        # as updates: the tier's timing is all of it
        self.stats.update_seconds += took - (self.stats.step_seconds + self.stats.update_seconds
                                             + self.stats.build_seconds - timed)
        self.stats.frame_seconds.append(took)
        return out

    def _step(self) -> list[HandOff]:
        """One step, or while a blast pushes its BLAST_SPLIT parts with the
        range checked after each (a joint's moment can pass its margin and
        its strength inside one step); the trees that left. A step left
        after a part resumes at the next part on the next call."""
        model = self.model
        t0 = time.perf_counter()
        if self.part == 0:
            self.blast_step = meets(self.blast_windows, self.t, self.h)
            self._keep_before_blast()
            self.parts = max(BLAST_SPLIT if self.blast_step else 1, self.stats.parts)
            if self.blast_step:
                self.stats.split += 1
        h = self.h / self.parts
        while self.part < self.parts:
            q, v, a = self.q, self.v, self.a
            self.part_start = (self.t, self.step, self.part, q, v, self.ledger.running.copy())
            q_pred = q + h * v + (0.5 - BETA) * h * h * a
            v_pred = v + (1 - GAMMA) * h * a
            t_end = self.step * self.h + (self.part + 1) * h
            rhs = self.rhs(t_end, q_pred, v_pred, h, record=True)
            t1 = time.perf_counter()
            factor = model.factor if self.parts == 1 else \
                model.factor_for(GAMMA * h, BETA * h * h)
            self.a = factor.solve(rhs)
            self.q = q_pred + BETA * h * h * self.a
            self.v = v_pred + GAMMA * h * self.a
            if self.part + 1 == self.parts and not self.blast_step:
                self._check_error(self.a - a, h, t_end)
            self.stats.update_seconds += t1 - t0
            self.stats.step_seconds += time.perf_counter() - t1
            t0 = time.perf_counter()
            if not np.all(np.isfinite(self.q)):
                tree, seg = self.locate(0)
                raise SimulationError("non-finite state in the linear tier", tree, seg, t_end)
            self.part += 1
            self.t = t_end
            self._state = None  # the new state's kinematics, evaluated when asked
            if self.part < self.parts:
                out = self._leaving()
                if out:
                    return out
        self.part = 0
        self.step += 1
        self.t = self.step * self.h
        self.stats.steps += 1
        out = self._leaving()
        if self.model is not None:
            self._follow_pose()
        return out

    def _follow_pose(self) -> None:
        """Linearise the equations again at the trees' mean pose (MEAN_TIME)
        once a bone of it has turned more than the quality's `relinearise`
        from the pose they were taken at."""
        self.q_mean += -math.expm1(-self.h / MEAN_TIME) * (self.q - self.q_mean)
        turn = self.model.turns(self.q_mean) - self.model.turn_at
        if (turn * turn).sum(0).max() <= self.quality.relinearise**2:
            return
        t0 = time.perf_counter()
        self.model.linearise_at(self.q_mean)
        self._state = None
        # the step's acceleration stays the next predictor's (solving for it
        # again costs a second factorisation for a change of 1 % of the error)
        self.stats.relinearised += 1
        self.stats.build_seconds += time.perf_counter() - t0

    def _check_error(self, da: np.ndarray, h: float, t: float) -> None:
        """Split the steps in two from now on if the step just taken (its
        last part of length h s, whose acceleration changed by `da`) erred
        past ERROR_TOLERANCE at some bone's tip."""
        if self.stats.parts >= MAX_PARTS:
            return
        shift = self.model.tip_shift(h * h / 12 * self.parts * da)
        error = np.sqrt((shift * shift).sum(0)) / self.bone_height
        worst = int(np.argmax(error))
        if error[worst] <= REARM * ERROR_TOLERANCE:
            self.armed = True
        elif error[worst] > ERROR_TOLERANCE and self.armed:
            # what rang before the split rings on (the rule adds no damping)
            # and is not the new step's error: split again only on a new
            # excursion, from below REARM of the tolerance
            self.armed = False
            self.stats.parts *= 2
            tree = self.trees[self.members[int(self.bones.bone_tree[worst])]]
            path = tree.rig.model.segment_paths()[self.locate(worst)[1]]
            self.stats.refined.append((t, tree.name, path, float(error[worst])))

    def _keep_before_blast(self) -> None:
        """Keep each member tree's state at the start of the step in which a
        blast reaches the first of their bones, until BLAST_RING s after its
        push on the last is over: a nonlinear engine takes a tree that
        leaves meanwhile from there (handoff.HandOff.restart; docs/
        physics.md, "Taken during a blast, a tree starts from where the
        blast found it")."""
        if not meets(self.blast_windows, self.t, self.h, BLAST_RING):
            self.before_blast = {}
            return
        if self.before_blast or self.model is None:
            return
        kin, _ = self.state()
        quats, _ = pose_frames(self.bones, self.q[None])
        rot = matrices_from_quaternions(quats[0])
        substep = int(self.step * self.ratio + 1e-9)
        for k, i in enumerate(self.members):
            lo, hi = self.bones.offsets[k], self.bones.offsets[k + 1]
            self.before_blast[i] = HandOff(
                i, self.t, substep, self.q[2 * lo:2 * hi].copy(), self.v[2 * lo:2 * hi].copy(),
                Reason.BLAST, "as the blast reached it", rot[lo:hi].copy(),
                kin[6:9, lo:hi].T.copy(), work=float(self.ledger.running[i]), step_length=self.h)

    def state(self):
        """Kinematics and pose of the current state (once per step)."""
        if self._state is None:
            kin = self.model.kinematics(self.q, self.v)
            self._state = (kin, self.model.pose(kin, self.q, loads=False))
        return self._state

    def _leaving(self) -> list[HandOff]:
        """Trees that left the linear range this step, handed over."""
        model, b, q = self.model, self.bones, self.q
        kin, pose = self.state()
        tip_z = pose.pivot[2] + (pose.rot[2] * self.tip_arm).sum(0)
        # in order of precedence: an event (near breaking, at the ground)
        # decides the engine before large motion does
        moment = model.bending_moment(q)
        checks = (
            (moment > BREAK_MARGIN * b.strength, Reason.NEAR_BREAK,
             f"a joint past {BREAK_MARGIN:.0%} of its strength"),
            (self.scene.ground & (tip_z < b.radius + CONTACT_MARGIN)
             & (tip_z < self.tip_rest - 1e-3), Reason.GROUND, "a tip reached the ground"),
            ((kin[0:3] * kin[0:3]).sum(0) > MAX_TURN**2, Reason.TURN,
             f"a bone turned past {MAX_TURN} rad"),
            ((np.abs(q) > CONE_FRACTION * self.cone).reshape(-1, 2).any(1), Reason.CONE,
             f"a hinge past {CONE_FRACTION:.0%} of its cone"))
        bad = checks[0][0] | checks[1][0] | checks[2][0] | checks[3][0]
        leaving = {}
        cut = self.cut_time <= self.t + 0.5 * self.h
        if bad.any() or cut.any():
            hit_tree = np.bincount(b.bone_tree, bad, minlength=len(self.members)) > 0
            for ti_local in np.nonzero(hit_tree | cut)[0]:
                tree = self.trees[self.members[ti_local]]
                if not hit_tree[ti_local]:
                    leaving[ti_local] = ("its felling cut", Reason.CUT)
                    continue
                lo, hi = b.offsets[ti_local], b.offsets[ti_local + 1]
                mask, kind, why = next(c for c in checks if c[0][lo:hi].any())
                first = int(lo + np.argmax(mask[lo:hi]))
                seg = self.locate(first)[1]
                leaving[ti_local] = (f"{tree.rig.model.segment_paths()[seg]}: {why}", kind)
        if not leaving:
            return []
        out = []
        quats, _ = pose_frames(b, q[None])
        rot_exact = matrices_from_quaternions(quats[0])[None]
        broken = np.bincount(b.bone_tree, moment > b.strength, minlength=len(self.members)) > 0
        for ti_local, (reason, why_kind) in leaving.items():
            ti_local = int(ti_local)
            lo, hi = b.offsets[ti_local], b.offsets[ti_local + 1]
            i = self.members[ti_local]
            # frames are recorded at whole steps, after the step's range check
            self.last_frame[i] = self.step // self.spf if self.part else \
                math.ceil(self.step / self.spf) - 1
            substep = int((self.step + self.part / self.parts) * self.ratio + 1e-9)
            restart = self.before_blast.get(i)
            if restart is None and broken[ti_local]:  # no engine takes a broken joint
                restart = self._part_start(ti_local, i)
            out.append(HandOff(i, self.t, substep, q[2 * lo:2 * hi].copy(),
                               self.v[2 * lo:2 * hi].copy(), why_kind, reason,
                               rot_exact[0, lo:hi].copy(), kin[6:9, lo:hi].T.copy(),
                               work=float(self.ledger.running[i]), step_length=self.h,
                               restart=restart))
        keep = [k for k in range(len(self.members)) if k not in leaving]
        dof = np.concatenate([np.arange(2 * b.offsets[k], 2 * b.offsets[k + 1]) for k in keep]) \
            if keep else np.zeros(0, dtype=np.int64)
        q, v, q_mean = self.q[dof], self.v[dof], self.q_mean[dof]
        self.members = [self.members[k] for k in keep]
        self.stats.rebuilds += 1
        self._build(q, v, q_mean)
        # the trees that stay keep their loads' last update: the work of the
        # next step is measured from it (docs/physics.md, "The work of the
        # trees that stay in the linear tier")
        self.load_work.keep(dof[0::2] // 2)
        return out

    def _part_start(self, ti_local: int, i: int) -> HandOff:
        """Tree i (member ti_local) as the step (or its part) began that just
        took one of its joints past its strength: where the nonlinear engine
        takes it from, so that it, not this tier, integrates the step."""
        t, step, part, q_all, v_all, running = self.part_start
        lo, hi = self.bones.offsets[ti_local], self.bones.offsets[ti_local + 1]
        kin = self.model.kinematics(q_all, v_all)
        quats, _ = pose_frames(self.bones, q_all[None])
        rot = matrices_from_quaternions(quats[0])
        substep = int((step + part / self.parts) * self.ratio + 1e-9)
        return HandOff(i, t, substep, q_all[2 * lo:2 * hi].copy(), v_all[2 * lo:2 * hi].copy(),
                       Reason.PAST_STRENGTH, "as the step began in which a joint passed its "
                       "strength", rot[lo:hi].copy(), kin[6:9, lo:hi].T.copy(),
                       work=float(running[i]), step_length=self.h)

    def _per_tree(self, per_bone: np.ndarray) -> np.ndarray:
        """Per-bone values summed into the tier's tree numbering."""
        out = np.zeros(len(self.trees))
        out[self.members] = per_tree(per_bone, self.bones.bone_tree, len(self.members))
        return out

    def _record(self, f: int) -> None:
        b = self.bones
        for k, i in enumerate(self.members):
            self.angles[i][f] = self.q[2 * b.offsets[k]:2 * b.offsets[k + 1]]
        if self.model is None:
            return
        model = self.model
        kin, pose = self.state()
        e = model.energy(kin, pose, self.q, -self.loads.g[2])
        energy = np.full(len(self.trees), np.nan)
        energy[self.members] = per_tree(e, b.bone_tree, len(self.members))
        self.ledger.record(f, energy)

    def motions(self) -> list[TreeMotion]:
        """Per tree, the motion of the frames it spent in this tier (others zero)."""
        frames = self.scene.frame_count
        every = self.every
        angles = np.concatenate(self.angles, axis=1) if self.angles else np.zeros((frames, 0))
        quats, piv = pose_frames(every, angles)  # every tree at once, level by level
        out = []
        for i in range(len(self.trees)):
            lo, hi = every.offsets[i], every.offsets[i + 1]
            last = int(self.last_frame[i]) + 1
            q, p = quats[:, lo:hi].copy(), piv[:, lo:hi].copy()
            q[last:] = 0.0
            p[last:] = 0.0
            out.append(TreeMotion(q, p, [], self.ledger.energy[:, i], self.ledger.work[:, i]))
        return out
