"""The reference's step loop: MuJoCo models stepped side by side, with the
loads, the structural damping, the splits that fast free parts and blasts
need, the energy audit, and the hand-back to the linear tier.

Each step: mj_step1 (kinematics); at load updates (every `force_every`
steps) read the bones, record a frame or a sub-frame sample, handle events
and write the held loads (xfrc_applied); every step the damping
(qfrc_applied); mj_step2. Models are stepped one after another in one
thread, so results never depend on timing. docs/physics.md ("The
reference") has the model, the integrator's measurements and the events."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from ...errors import SimulationError
from ...quality import Quality
from ...rotations import cross
from ...scene import Scene
from ..audit import Ledger, LoadWork, bone_energy, per_tree
from ..common import (
    MAX_ANGULAR_SPEED,
    SimTree,
    TreeMotion,
    external_loads,
    locate,
    sub_frame_samples,
    tree_motion,
)
from ..events import TIER, Event
from ..handoff import BrokenOff, HandOff, Reason
from ..loads import SceneLoads, meets
from ..range import BACK_DETAIL, RETURN_DETAIL, ReturnWatch, in_return_range
from ..rules import (
    BLAST_RING,
    BLAST_STEP,
    MAX_SPIN,
    SETTLE_SPEED,
    exact_decay,
    limb_damping,
)
from .events import ReferenceEvents
from .model import Group, ReferenceModels

DEFAULT_TIMESTEP = 1 / 2000  # s
DEFAULT_FORCE_RATE = 500.0  # Hz
TIMESTEPS = {"fine": 1 / 4000, "default": 1 / 2000, "coarse": 1 / 1000, "draft": 1 / 480}
SPIN_PER_STEP = 0.05  # rad: most a free part turns in one step (more: the step is split)
MAX_SUBSTEPS = 8
BAD = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
       mujoco.mjtWarning.mjWARN_BADQPOS)


@dataclass
class Stats:
    """What a run did (deterministic: no timings, which are in `timing`)."""

    steps: int = 0
    updates: int = 0
    bodies: int = 0
    rebuilds: int = 0  # models recompiled in place (felled, uprooted; projectile scenes)
    parts: int = 0  # parts broken off standing trees (into their trees' debris models)
    limited: int = 0  # bone updates whose external load was capped
    clamped: int = 0  # updates at which a free part's spin was clamped to MAX_SPIN
    damping_scaled: int = 0  # steps at which a model with free parts had its damping scaled down
    split: int = 0  # steps a model with fast-spinning free parts took in substeps
    blast_split: int = 0  # steps a model took in substeps while a blast pushed or rang
    # the largest bending moment any breakable joint reached, as a fraction of
    # its strength: (fraction, tree, segment path, time s); >= 1 where one broke
    closest: tuple | None = None
    first_limit: tuple | None = None  # (tree, segment, time s, acceleration m/s^2)
    broken: int = 0
    returned_broken: int = 0  # trees handed back without parts that broke off (pruning.py)


class ReferenceEngine(ReferenceModels, ReferenceEvents):
    """The active trees of a scene in MuJoCo, full 3D, from rest or from the
    linear tier's hinge angles and rates.

    `timestep` (s, default DEFAULT_TIMESTEP) is rounded so that a frame is
    a whole number of load intervals; `force_rate` (Hz, default
    DEFAULT_FORCE_RATE; inf = every step) is how often the loads are
    evaluated (the damping is every MuJoCo step). A model's step is split
    to at most rules.BLAST_STEP while a blast pushes its trees and their
    twigs ring (BLAST_RING). `touch_ground`: the ground stops the trees
    even where nothing can fall (a tree handed over for its tips at the
    ground). `throws`: it simulates the scene's projectiles (not for a tree
    handed over from the linear tier: no projectile can reach it). `quality`
    is only recorded: the rig's bones are already merged by it."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None, timestep: float | None = None, force_rate: float | None = None,
                 touch_ground: bool = False, throws: bool = True):
        self.scene, self.quality, self.loads = scene, quality, loads
        self.touch_ground = touch_ground  # the ground stops its trees even if nothing can fall
        self.throws = throws  # it simulates the scene's projectiles
        self.log = log or (lambda msg: None)
        self.trees = [t for t in trees if t.active]
        target = timestep or DEFAULT_TIMESTEP
        rate = DEFAULT_FORCE_RATE if force_rate is None else force_rate
        self.force_every = max(1, round(1.0 / (target * rate)))  # steps per force update
        # a frame is a whole number of force intervals
        self.spf = self.force_every * max(1, round(1.0 / (scene.fps * target
                                                          * self.force_every)))
        self.h = 1.0 / (scene.fps * self.spf)
        self.dt_force = self.h * self.force_every
        self.stats = Stats()
        self.timing = {"compile_seconds": 0.0, "step_seconds": 0.0, "update_seconds": 0.0}
        self.step_times: list[float] = []  # s, physics time of each step (for benchmarks)
        self.events: list[Event] = []
        self._collect()
        # MuJoCo steps per step while a blast pushes or rings, and when, per tree (s)
        self.blast_split = max(1, math.ceil(self.h / BLAST_STEP - 1e-9))
        tree_bones = [slice(self.offsets[ti], self.offsets[ti + 1])
                      for ti in range(len(self.trees))]
        self.blast_windows = [self.loads.blast_windows(self.com0[b], self.axis0[b],
                                                       self.props.take(b))
                              for b in tree_bones] if self.blast_split > 1 else []
        self._joints()
        self._groups()

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index (in that tree) of a global bone."""
        return locate(self.trees, self.offsets, self.bone_tree, bone)

    # ------------------------------------------------------------------
    # state, loads, damping

    def _read(self) -> None:
        """COM position and velocity, angular velocity and rotation of every
        bone, from each model's current kinematics (after mj_step1). The
        state arrays have an extra zero row: the world, as a frame."""
        for g in self.groups:
            self._read_group(g)

    def _read_group(self, g: Group) -> None:
        d, b, rows = g.data, g.body, g.bones
        com = d.xipos[b]
        cv = d.cvel[b]  # (rotation, translation) about the subtree COM of the root
        w = cv[:, :3]
        self.com[rows] = com
        self.omega[rows] = w
        self.vcom[rows] = cv[:, 3:] + cross(w, com - d.subtree_com[g.root_body])
        self.rot[rows] = d.xmat[b].reshape(-1, 3, 3)

    def _check(self, t: float) -> None:
        """Stop on a non-finite state or a bone spinning faster than
        MAX_ANGULAR_SPEED, naming the tree, a segment and the time. A bone of
        a free part (broken off, felled) is checked relative to the part's
        first bone, whose own tumbling is clamped instead (_clamp_spin)."""
        n = self.n
        w = self.omega[:n] - self.omega[np.where(self.piece_root >= 0, self.piece_root, n)]
        spin = np.einsum("bi,bi->b", w, w)
        bad = ~(spin <= MAX_ANGULAR_SPEED**2) | ~np.isfinite(self.com[:n]).all(1)
        warned = any(g.data.warning[kind].number > 0 for g in self.groups for kind in BAD)
        if not bad.any() and not warned:
            return
        bone = int(np.nonzero(bad)[0][0]) if bad.any() else 0
        tree, seg = self.locate(bone)
        what = (f"angular speed {math.sqrt(spin[bone]):.0f} rad/s > {MAX_ANGULAR_SPEED:.0f}"
                if np.isfinite(spin[bone]) and bad.any() else "non-finite state")
        raise SimulationError(f"{what} (unstable; try a smaller timestep)", tree, seg, t)

    def _clamp_spin(self) -> None:
        """Clamp the spin of free parts at rules.MAX_SPIN (counted in
        stats.clamped)."""
        for g in self.groups:
            free = np.nonzero(g.free_dof >= 0)[0]
            if not len(free):
                continue
            w = self.omega[g.bones[free]]
            fast = np.einsum("bi,bi->b", w, w) > MAX_SPIN**2
            for i in free[fast]:
                v = g.free_dof[i] + 3
                g.data.qvel[v:v + 3] *= MAX_SPIN / np.linalg.norm(g.data.qvel[v:v + 3])
                self.stats.clamped += 1

    def _blast_rings(self, g: Group, t: float) -> bool:
        """Whether a blast pushes the model's trees within the load interval
        from t (s), or their twigs still ring: until BLAST_RING s after."""
        return any(meets(self.blast_windows[ti], t, self.dt_force, BLAST_RING)
                   for ti in g.trees if ti < len(self.blast_windows))

    def _substeps(self) -> None:
        """The remaining substeps of models split for fast free parts (after
        their first), loads and damping held (models a blast splits step in
        _blast_step)."""
        for g in self.groups:
            if not g.blast:
                for _ in range(g.substeps - 1):
                    mujoco.mj_step(g.model, g.data)

    def _blast_step(self, g: Group, t: float, damped: bool, ready: bool) -> None:
        """One step (from t, s) of a model a blast splits, in its substeps,
        each with its own loads, damping and joint moments (`ready`: the
        first substep's mj_step1 is done): held over the whole step, the
        damping lags a ringing twig and pumps it, and the breaks depend on
        the load interval (docs/physics.md, "Loads every substep while a
        blast rings")."""
        h = self.h / g.substeps
        for k in range(g.substeps):
            if k or not ready:
                mujoco.mj_step1(g.model, g.data)
            self._read_group(g)
            self._track_peak(g, t + k * h)
            g.data.xfrc_applied[g.body, :3] = self._group_loads(g, t + k * h, h)
            if damped:
                self._damping(g)
            mujoco.mj_step2(g.model, g.data)

    def _group_loads(self, g: Group, t: float, dt: float) -> np.ndarray:
        """Air, blasts and pulls (N, world, at the COMs) on g's bones over
        [t, t + dt] (s), capped as `_external`'s, their work recorded (the
        other models' loads hold on)."""
        b = g.bones
        axis = np.einsum("bij,bj->bi", self.rot[b], self.axis0[b])
        force = external_loads(self.loads, self.bones, t, self.com[b], self.vcom[b], axis,
                               self.stats, lambda i: self.locate(int(b[i])), rows=b, dt=dt)
        work = self.load_work.update_rows(b, force, self.com[b])
        self.ledger.add_work(per_tree(work, self.bone_tree[b], len(self.trees)))
        return force

    def _external(self, t: float) -> np.ndarray:
        """Air, blasts, attractors and pulls (N, world, at the COMs), capped
        at MAX_ACCELERATION x mass; gravity is MuJoCo's."""
        n = self.n
        axis = self._axes()
        force = external_loads(self.loads, self.bones, t, self.com[:n], self.vcom[:n], axis,
                               self.stats, self.locate, dt=self.dt_force)
        self.ledger.add_work(per_tree(self.load_work.update(force, self.com[:n]),
                                      self.bone_tree, len(self.trees)))
        return force

    def _axes(self) -> np.ndarray:
        """The bones' unit axes (B, 3) in the world now."""
        return np.einsum("bij,bj->bi", self.rot, self.axis0)

    def _damping(self, g: Group) -> None:
        """Structural damping as generalized forces (qfrc_applied): each
        limb's joints get -rate M_LL qdot_L, M_LL the limb's block of the
        mass matrix (its bones and all they carry, at the current pose) and
        qdot_L its own joint rates: the rig's mass-proportional damping of
        every bone's motion relative to its limb's frame (the linear tier's
        C, joint_space.py). As joint torques it only removes energy."""
        d = g.data
        qv = d.qvel
        w = limb_damping(d.M[g.damp_adr], g.damp_rate)  # (entries of one limb only)
        tau = np.bincount(g.damp_row, w * qv[g.damp_col], minlength=len(qv))
        below = g.damp_below
        tau += np.bincount(g.damp_col[below], w[below] * qv[g.damp_row[below]],
                           minlength=len(qv))
        if g.has_free:
            scale = self._stable_scale(g, tau, qv)
            if scale < 1.0:
                tau = tau * scale
        np.negative(tau, out=d.qfrc_applied)

    def _stable_scale(self, g: Group, tau: np.ndarray, qv: np.ndarray) -> float:
        """The factor (<= 1) that keeps an explicit damping force D v from
        overshooting on a model with free parts, whose hinges move far less
        mass than the limb's block of M stands for. Over one step the
        damping changes the kinetic energy by -s h v.Dv + s^2 h^2
        (Dv).M^-1(Dv) / 2: s = min(1, v.Dv / (h (Dv).M^-1(Dv))) removes the
        most a step can and never adds any (docs/physics.md, "Free parts on
        the reference")."""
        lost = float(qv @ tau)  # v.Dv >= 0 (D is positive semidefinite)
        if lost <= 0.0:
            return 1.0
        y = np.ascontiguousarray(tau, dtype=float)[None, :]
        x = np.empty_like(y)
        mujoco.mj_solveM(g.model, g.data, x, y)
        curvature = g.damp_hold * float(y[0] @ x[0])
        if curvature <= lost:
            return 1.0
        self.stats.damping_scaled += 1
        return lost / curvature

    def _back_in_range(self, t: float, h_linear: float) -> bool:
        """Whether the trees have been back in the linear range for
        range.RETURN_WINDOW up to this frame (at t s): standing on their
        roots, none cut, no joint letting go, no projectile, every blast's
        push past, what broke off lying still (below rules.SETTLE_SPEED),
        and the standing bones' pose within range.in_return_range for a
        linear step of `h_linear` s."""
        n = self.n
        fallen = self.piece_root[:n] >= 0
        calm = not (self.released or any(self.cut_state)
                    or not all(self.attached[self._roots(ti)].all()
                               for ti in range(len(self.trees)))
                    or any(g.projectiles for g in self.groups)
                    or not self.loads.blasts_passed(t, self.com[:n], self._axes(), self.props))
        if calm and fallen.any():
            speed = np.maximum(np.abs(self.vcom[:n][fallen]).max(),
                               np.abs(self.omega[:n][fallen]).max())
            calm = bool(speed < SETTLE_SPEED)
        if calm:
            moment = np.zeros(n)
            for g in self.groups:
                moment[g.bones] = self._moments(g)
            calm = in_return_range(self.bones, self.rot[:n], self._pivots(), *self._hinges(),
                                   moment, h_linear, ~fallen if fallen.any() else None)
        return self.watch.update(calm)

    def _broken_off(self, ti: int, f: int) -> BrokenOff | None:
        """What tree ti, handed back at frame f (just recorded), has lost
        (None: nothing): its standing bones, the fallen ones' pose and
        energy there, and its springs' prestress (handoff.BrokenOff)."""
        lo, hi = int(self.offsets[ti]), int(self.offsets[ti + 1])
        fallen = self.piece_root[lo:hi] >= 0
        if not fallen.any():
            return None
        self.stats.returned_broken += 1
        energy = float(self.bone_energies[lo:hi][fallen].sum())  # as recorded at frame f
        hold = -(self.k[lo:hi] * self.springref[lo:hi]).reshape(-1)
        return BrokenOff(~fallen, self.quats[f, lo:hi].copy(), self.pivots[f, lo:hi].copy(),
                         energy, hold)

    def _hinges(self) -> tuple[np.ndarray, np.ndarray]:
        """The hinges' angles and rates (2B,), rad and rad/s from the grown
        shape: the linear tier's coordinates."""
        q, v = np.zeros((self.n, 2)), np.zeros((self.n, 2))
        for g in self.groups:
            has = g.hinge_qpos >= 0
            q[g.bones] = np.where(has, g.data.qpos[np.maximum(g.hinge_qpos, 0)], 0.0)
            v[g.bones] = np.where(has, g.data.qvel[np.maximum(g.hinge_dof, 0)], 0.0)
        return q.reshape(-1), v.reshape(-1)

    def _set_hinges(self, q: np.ndarray, v: np.ndarray, t: float) -> None:
        """Start from hinge angles q and rates v (2B,), at time t."""
        angles, rates = q.reshape(-1, 2), v.reshape(-1, 2)
        for g in self.groups:
            has = g.hinge_qpos >= 0
            g.data.qpos[g.hinge_qpos[has]] = angles[g.bones][has]
            g.data.qvel[g.hinge_dof[has]] = rates[g.bones][has]
            g.data.time = t
            mujoco.mj_forward(g.model, g.data)

    def _pivots(self) -> np.ndarray:
        out = np.zeros((self.n, 3))
        for g in self.groups:
            out[g.bones] = g.data.xpos[g.body]
        return out

    def _record(self, f: int) -> None:
        """Frame f's poses, and each tree's energy and work for the audit."""
        n = self.n
        springs = np.zeros(n)
        for g in self.groups:
            q = g.data.xquat[g.body][:, [1, 2, 3, 0]]
            q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
            self.quats[f, g.bones] = q
            self.pivots[f, g.bones] = g.data.xpos[g.body]
            has = g.hinge_qpos >= 0
            angle = np.where(has, g.data.qpos[np.maximum(g.hinge_qpos, 0)], 0.0)
            eps = np.where(has, angle - self.springref[g.bones], 0.0)
            springs[g.bones] = 0.5 * (self.k[g.bones] * eps * eps).sum(1)
        e = bone_energy(self.mass, self.model_inertia, self.rot, self.com[:n], self.vcom[:n],
                        self.omega[:n], -self.loads.g[2]) + springs
        self.bone_energies = e  # J per bone at frame f (what broke off keeps its share)
        self.ledger.record(f, per_tree(e, self.bone_tree, len(self.trees)),
                           per_tree(self.load_work.pending(self.com[:n]), self.bone_tree,
                                    len(self.trees)))

    def _split(self, t: float) -> None:
        """Split the step of models whose free parts spin fast into as many
        equal substeps as keep every free part's turn per substep under
        SPIN_PER_STEP (at most MAX_SUBSTEPS; loads and damping held;
        stats.split), and of models a blast pushes or whose twigs it rings
        to BLAST_STEP (stats.blast_split; loads, damping and the joints'
        peak moments every substep, `_blast_step`). docs/physics.md,
        "Fast-spinning free parts"."""
        if self.blast_split == 1 and not any(g.has_free for g in self.groups):
            return  # (every model steps whole: nothing can have split it)
        for gi, g in enumerate(self.groups):
            blast = self._blast_rings(g, t)
            n = self.blast_split if blast else 1
            if n > 1:
                self.stats.blast_split += 1
                if g.peak is None and (self.breakable[g.bones] & self.attached[g.bones]).any():
                    g.peak = np.zeros(len(g.bones))
            else:
                g.peak = None
            if g.has_free:
                bones = g.bones
                rows = bones[(self.piece_root[bones] >= 0) & (self.group_of_bone[bones] == gi)]
                w = self.omega[rows]
                fastest = math.sqrt(float(np.einsum("bi,bi->b", w, w).max())) \
                    if len(rows) else 0.0
                spin = min(MAX_SUBSTEPS, max(1, math.ceil(fastest * self.h / SPIN_PER_STEP)))
                if spin > 1:
                    self.stats.split += 1
                n = max(n, spin)
            g.blast = blast and n > 1
            hold = self.h / n if g.blast else self.h
            if n != g.substeps or hold != g.damp_hold:
                g.substeps, g.damp_hold = n, hold
                g.model.opt.timestep = self.h / n
                g.damp_rate = exact_decay(g.damp_alpha, hold)

    # ------------------------------------------------------------------
    # running

    def begin(self, start: float = 0.0, state: tuple[np.ndarray, np.ndarray] | None = None,
              hand_back: float | None = None) -> None:
        """Start from rest at t = 0, or with `state` from time `start` (s,
        rounded to a step) and the hinges' angles and rates (q, v: (2B,),
        bone b's hinges at 2b, 2b + 1, rad and rad/s from the grown shape)
        that the linear tier handed over: its coordinates are exactly these
        hinges; frames before are left zero. With `hand_back` (the linear
        tier's step, s), the run stops at the first frame at which its trees
        have stayed back in the linear range for range.RETURN_WINDOW
        (`_back_in_range`), handing them back."""
        frames = self.scene.frame_count
        n = self.n
        self.quats = np.zeros((frames, n, 4))
        self.pivots = np.zeros((frames, n, 3))
        self.com, self.vcom, self.omega = (np.zeros((n + 1, 3)) for _ in range(3))
        self.ledger = Ledger(frames, len(self.trees))
        self.load_work = LoadWork()
        self.rot = np.zeros((n, 3, 3))
        self.proj = next((g for g in self.groups if g.projectiles), None)
        n_proj = len(self.scene.projectiles) if self.proj is not None else 0
        self.track_pos = np.zeros((frames, n_proj, 3))
        self.track_quat = np.zeros((frames, n_proj, 4))
        self.launched = np.zeros(n_proj, dtype=bool)
        self.any_damping = bool((self.alpha > 0).any())
        self.last_step = (frames - 1) * self.spf
        self.hand_back = hand_back
        self.handed_back: list[HandOff] = []
        self.stopped = False  # at the last step, or handed back
        self.pending = False  # a step is half done: its frame recorded, its loads not yet
        self.watch = ReturnWatch(self.scene.fps)  # back in the linear range?
        self.samples: list = []
        self.extra: list[list] = [[] for _ in self.trees]
        self.step = 0
        if state is not None:
            self.step = min(round(start / self.h), self.last_step)
            self._set_hinges(*state, self.step * self.h)
        self.envelopes_off_in_ground()
        self.first_frame = math.ceil(self.step / self.spf - 1e-9)

    def advance_to(self, frame: int) -> list[HandOff]:
        """Step until `frame` is recorded (or the trees were handed back):
        the hand-backs, once."""
        end = min(frame * self.spf, self.last_step)
        while not self.stopped and self.step <= end:
            if not self.pending:
                if self._begin_step() or self.stopped:
                    continue
                self.pending = True
                if self.step == end:
                    break  # the frame is recorded; this step goes on at the next call
            self._end_step()
        out, self.handed_back = self.handed_back, []
        return out

    def _begin_step(self) -> bool:
        """The first half of the step from self.step: projectiles launched,
        kinematics, and at a load update the bones read, checked and
        recorded (a frame or a sub-frame sample). True if the step was taken
        whole (no update, no damping)."""
        step = self.step
        t = step * self.h
        self._t0 = time.perf_counter()
        if self.proj is not None and not self.launched.all():
            self._projectiles(self.proj, t, self.launched)
        self.update = step % self.force_every == 0
        if not self.update and not self.any_damping:
            for g in self.groups:
                if g.blast:
                    self._blast_step(g, t, self.any_damping, ready=False)
                else:
                    mujoco.mj_step(g.model, g.data)
            self._substeps()
            took = time.perf_counter() - self._t0
            self.timing["step_seconds"] += took
            self.step_times.append(took)
            self.stats.steps += 1
            self.step += 1
            return True
        for g in self.groups:
            mujoco.mj_step1(g.model, g.data)
        t1 = time.perf_counter()
        if self.update:
            self._read()
            self._check(t)
            if step % self.spf:  # between frames: a sample, kept where motion is fast
                self.samples.append((t, self.rot.copy(), self._pivots()))
            else:
                self._frame(step // self.spf, t)
        # s spent stepping and updating so far (the step may go on at the next call)
        self._begun = (t1 - self._t0, time.perf_counter() - t1)
        return False

    def _frame(self, f: int, t: float) -> None:
        """Record frame f (at t s); stop at the last, or hand the trees back."""
        self._record(f)
        if f > self.first_frame:  # (the frame before a run's first is not its own)
            sub_frame_samples(self.quats[f - 1], self.quats[f], self.samples, self.offsets,
                              self.extra)
        self.samples = []
        if self.proj is not None:
            self.track_pos[f] = self.proj.data.xpos[self.proj.proj_body]
            self.track_quat[f] = self.proj.data.xquat[self.proj.proj_body][:, [1, 2, 3, 0]]
        if f > 0:
            self._settle(t, 1.0 / self.scene.fps)
        if self.step == self.last_step:
            self.stopped = True
        elif self.hand_back is not None and self._back_in_range(t, self.hand_back):
            self.stopped = True
            q, v = self._hinges()
            self.events.extend(Event(t, tr.name, TIER, "", RETURN_DETAIL) for tr in self.trees)
            self.handed_back = [
                HandOff(ti, t, -1, q[2 * lo:2 * hi], v[2 * lo:2 * hi], Reason.BACK,
                        BACK_DETAIL, frame=f, work=float(self.ledger.work[f, ti]),
                        broken=self._broken_off(ti, f))
                for ti, (lo, hi) in enumerate(zip(self.offsets[:-1], self.offsets[1:]))]

    def _end_step(self) -> None:
        """The second half of the step: at a load update the events, the
        free parts' spin clamp, the splits and the loads; the damping; then
        mj_step2 (and the substeps of split models)."""
        step, t = self.step, self.step * self.h
        resumed = time.perf_counter()
        if self.update:
            if self._events(t):
                self._check(t)
            if not self.attached.all():
                self._clamp_spin()
            self._split(t)
            force = self._external(t)
            if self.proj is not None:
                self._projectile_work(self.proj)
            for g in self.groups:
                g.data.xfrc_applied[g.body, :3] = force[g.bones]
            self.stats.updates += 1
        if self.any_damping:
            for g in self.groups:
                self._damping(g)
        t2 = time.perf_counter()
        for g in self.groups:
            if g.blast:
                self._blast_step(g, t, self.any_damping, ready=True)
            else:
                mujoco.mj_step2(g.model, g.data)
        self._substeps()
        t3 = time.perf_counter()
        stepped, updated = self._begun
        self.timing["update_seconds"] += updated + (t2 - resumed)
        self.timing["step_seconds"] += stepped + (t3 - t2)
        self.step_times.append(stepped + updated + (t3 - resumed))
        self.stats.steps += 1
        self.step = step + 1
        self.pending = False

    def motions(self) -> list[TreeMotion]:
        """Per tree, its bones' motion at every frame recorded (zero before
        the run's start and after a hand-back), events, energy and work."""
        out = []
        for ti, tree in enumerate(self.trees):
            # (a joint released at a substep is recorded at the next check)
            events = sorted((e for e in self.events if e.tree == tree.name), key=lambda e: e.time)
            out.append(tree_motion(self.quats, self.pivots,
                                   slice(self.offsets[ti], self.offsets[ti + 1]), events,
                                   self.ledger, ti, self.extra[ti]))
        return out

    def tracks(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Projectile positions (F, P, 3) m and rotations (F, P, 4) x y z w,
        after the run; None without projectiles."""
        if not self.scene.projectiles or self.proj is None:
            return None
        return self.track_pos, self.track_quat
