"""The planar LOD's pymunk tier: each limb a 2D pymunk chain in its own
bending planes, built in build.py, rebuilt in 3D in kinematics.py, loaded in
forces.py, broken in breaking.py; this module runs it frame by frame. The
design and the measurements behind it: docs/physics.md, "The pymunk tier".
"""

from __future__ import annotations

import math
import time
from dataclasses import fields

import numpy as np
from pymunk import batch

from ...errors import SimulationError
from ...quality import Quality
from ...rotations import quaternions_from_matrices, rotvecs_from_matrices
from ...scene import Scene
from ..audit import Ledger, LoadWork, bone_energy, per_tree
from ..common import ProjectileTracks, SimTree, TreeMotion, locate, sub_frame_samples, tree_motion
from ..debris import Debris
from ..events import TIER, Event
from ..handoff import Engine, HandOff, Reason, TierReport
from ..hinges import hinges_from_pose
from ..loads import SceneLoads
from ..projectiles import Projectiles
from ..range import BACK_DETAIL, RETURN_DETAIL, ReturnWatch, in_return_range
from ..rules import BLAST_RING
from .breaking import ChainEvents
from .build import SPRING, ChainBuild
from .forces import ChainForces
from .kinematics import ChainKinematics
from .stats import StartState, Stats

MAX_JOINT_GAP = 0.01  # a pivot opened further (fraction of bone length) stops the bake


class PymunkTier(ChainBuild, ChainKinematics, ChainForces, ChainEvents):
    """Simulate the active trees of one scene with the pymunk tier; with
    `throws`, the scene's projectiles too (not for trees handed over from
    the linear tier: no projectile can reach them)."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None, throws: bool = True):
        self.scene, self.quality, self.loads = scene, quality, loads
        self.throws = throws
        self.log = log or (lambda msg: None)
        self.stats = Stats()
        fps = scene.fps
        self.spf = max(1, round(quality.substep_rate / fps))  # substeps per frame
        self.h = 1.0 / (fps * self.spf)
        want = max(1, round(quality.substep_rate / quality.force_rate))
        divisors = [d for d in range(1, self.spf + 1) if self.spf % d == 0]
        self.update_every = min(divisors, key=lambda d: (abs(d - want), d))
        self.dt_update = self.h * self.update_every
        self.trees = [t for t in trees if t.active]
        self.cuts = any(t.cut is not None for t in self.trees)
        # the linear tier's step (s) if the trees may go back to it (scheduler.py), and
        # the frame, hinge angles and rates (2B,) where they did (then nothing is recorded)
        self.hand_back: float | None = None
        self.handed_back: tuple | None = None
        self.watch = ReturnWatch(scene.fps)  # back in the linear range?
        self._collect()
        self._chains()
        self._lumping()
        self._layout()
        self._space()

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index (in that tree) of a global bone."""
        return locate(self.trees, self.offsets, self.bone_tree, bone)

    def bone_path(self, bone: int) -> str:
        """A global bone's segment path in its tree."""
        ti = int(self.bone_tree[bone])
        return self.trees[ti].rig.model.segment_paths()[self.locate(bone)[1]]

    def advance_to(self, frame: int) -> list[HandOff]:
        """Step to `frame`, recording every frame: its trees, handed back to
        the linear tier, the frame they went back (handoff.Tier)."""
        out = []
        while self.frame < frame:
            self.frame += 1
            back = self.handed_back is None
            self.advance_frame(self.frame)
            if back and self.handed_back is not None:
                f, q, v = self.handed_back
                work = self.ledger.work[f]
                out += [HandOff(k, f / self.scene.fps, self.substep, q[2 * lo:2 * hi],
                                v[2 * lo:2 * hi], Reason.BACK, BACK_DETAIL, frame=f,
                                work=float(work[k]))
                        for k, (lo, hi) in enumerate(zip(self.offsets[:-1], self.offsets[1:]))]
        return out

    def report(self) -> TierReport:
        """Counts (deterministic), notes and timings (s) of the run."""
        st = self.stats
        stats = {f.name: getattr(st, f.name) for f in fields(st)
                 if f.name not in ("notes", "step_seconds", "update_seconds", "frame_seconds")}
        stats["segments"] = sum(t.rig.model.n_segments for t in self.trees)
        stats["substep"], stats["force_interval"] = self.h, self.dt_update
        stats["stability"] = self.quality.stability
        timing = {"step_seconds": st.step_seconds, "update_seconds": st.update_seconds,
                  "frame_seconds": st.frame_seconds,
                  "segment_steps": stats["segments"] * st.substeps}
        return TierReport(Engine.PYMUNK, stats, list(st.notes), timing)

    def tracks(self) -> ProjectileTracks | None:
        """The projectiles' flight, after the run; None without projectiles."""
        p = self.projectiles
        return None if p is None else ProjectileTracks(p.shape, p.size, p.track_pos,
                                                       p.track_quat)

    def begin(self, substep: int = 0, start: StartState | None = None) -> None:
        """Set up a run from substep `substep` (time substep x h), from rest
        or, with `start`, from a pose and spin handed over by the linear tier;
        the frame it starts in (or at) is recorded."""
        scene, n, nb, trees = self.scene, self.n, len(self.bodies), len(self.trees)
        self.quats = np.zeros((scene.frame_count, n, 4))
        self.pivots = np.zeros((scene.frame_count, n, 3))
        self.events: list[Event] = []
        self.cut_state: dict[int, str] = {}
        self.joint_alive = np.ones(n, dtype=bool)
        self.in_debris = np.zeros(n, dtype=bool)
        self.breakable = np.isfinite(self.strength[self.body_bone])
        self.pivot_alive = np.ones(nb, dtype=bool)
        self.rigid_root = np.full(nb, -1, dtype=np.int64)
        self.still_time = np.zeros(trees)
        self.quiet = self._quiet_times()
        self.samples: list = []  # this frame's update poses (time, rotations, pivots)
        self.extra: list[list] = [[] for _ in self.trees]  # kept sub-frame samples per tree
        self.debris = Debris(self.mass, self.inertia, self.com0, self.pivot0, self.tip0,
                             self.radius, scene.ground, self.loads.g)
        self.ledger = Ledger(scene.frame_count, trees)
        self.load_work = LoadWork()
        self.projectiles = Projectiles.from_scene(scene) if scene.projectiles and self.throws \
            else None
        if start is not None:
            self._hand_over(start)
        self.read()
        self.pose, self.prev, self.fresh = self.reconstruct(), None, True
        self.substep = self.next_update = self.last_update = substep
        self.contact_active = self.recoiling = False
        # _recoil's record: per bone, its velocity (m/s) relative to its stem and
        # that velocity's moment about the origin (m^2/s) at the last update
        self.recoil_v = np.full((n, 3), np.nan)
        self.recoil_l = np.full((n, 3), np.nan)
        self.free_pieces = self.bent = None  # forces.py's caches, with their _layout_key
        self.contact_dt = self.h  # s, the hold the ground's springs were last set for
        self.refine = 1
        first = self.start_frame = substep // self.spf  # the frame it starts in (or at)
        # the first frame whose pose is its own (one started between frames
        # records the hand-over's pose in the frame before)
        self.first_frame = first + (1 if substep % self.spf else 0)
        # the last frame advanced to: from rest frame 0; from a hand-over the
        # frame before the one it reaches first (at a frame: that frame again)
        self.frame = 0 if start is None else math.ceil(substep / self.spf - 1e-9) - 1
        self.quats[first] = quaternions_from_matrices(self.pose["rot"])
        self.pivots[first] = self.pose["pivot"]
        self._audit(first, self.pose)

    def advance_frame(self, f: int) -> None:
        """Step to frame f and record it (nothing once its trees went back
        to the linear tier)."""
        if self.handed_back is not None:
            self.stats.frame_seconds.append(0.0)  # frame timings stay aligned to the end
            return
        writes = batch.BodyFields.FORCE | batch.BodyFields.TORQUE
        t_frame = time.perf_counter()
        t = self.substep * self.h
        while self.substep < f * self.spf:
            if self.substep >= self.next_update:
                self._update(t)
            t0 = time.perf_counter()
            batch.set_space_bodies(self.space, writes, self.write_buf)
            if self.refine > 1:
                for _ in range(self.refine):  # forces are cleared after a step: set them again
                    self.space.step(self.h / self.refine)
                    batch.set_space_bodies(self.space, writes, self.write_buf)
                self.stats.refined += 1
            else:
                self.space.step(self.h)
            self.stats.step_seconds += time.perf_counter() - t0
            self.substep += 1
            self.stats.substeps += 1
            t = self.substep * self.h
        t0 = time.perf_counter()
        self._record_frame(f, t)
        self.stats.update_seconds += time.perf_counter() - t0
        self.stats.frame_seconds.append(time.perf_counter() - t_frame)
        self.stats.debris_clamped = self.debris.clamped

    def _update(self, t: float) -> None:
        """A load update at `t` s: the pose read and rebuilt (unless the
        frame's is fresh), cuts and breaks, then the forces, held for
        `update_every` substeps, or one while anything touches the ground, a
        free stem recoils, a blast pushes or its twigs ring, or a projectile
        is near (a stiff contact, a fast push or a hit needs it: "Bulk work")."""
        t0 = time.perf_counter()
        if not self.fresh:
            self.read()
            self.check(t)
            self.prev, self.pose = self.pose, self.reconstruct()
            self.samples.append((t, self.pose["rot"], self.pose["pivot"]))
        self.fresh = False
        if self.cuts:
            self.handle_cuts(t)
        if self.breakable.any():
            before = len(self.events)
            self.check_breaks(t, self.pose)
            if len(self.events) > before:
                self.pose = self.reconstruct()
        ahead = 1 if (self.contact_active or self.recoiling or self._blast_acting(t)
                      or self._projectile_near()) else self.update_every
        self.forces(t, self.pose, self.prev, max(self.substep - self.last_update, 1) * self.h,
                    ahead * self.h)
        self.last_update, self.next_update = self.substep, self.substep + ahead
        self.stats.updates += 1
        self.stats.update_seconds += time.perf_counter() - t0

    def _record_frame(self, f: int, t: float) -> None:
        """Read, check and record frame f at `t` s: its pose, the updates
        since the last frame as sub-frame samples, the energy audit, the
        projectiles; then sleep, and the hand back to the linear tier."""
        self.read()
        self.check(t)
        gap, body = self.joint_gap(worst=True)
        self.stats.max_joint_gap = max(self.stats.max_joint_gap, gap)
        if gap > MAX_JOINT_GAP:
            tree, seg = self.locate(int(self.body_bone[body]))
            raise SimulationError(f"a joint opened to {gap:.1%} of its bones' length (more than "
                                  f"{MAX_JOINT_GAP:.0%}: the pymunk tier cannot hold it; try "
                                  "--quality final or --solver full)", tree, seg, t)
        pose_frame = self.reconstruct()
        if self.substep >= self.next_update:  # the frame's pose is the next update's
            self.prev, self.pose, self.fresh = self.pose, pose_frame, True
        self.quats[f] = quaternions_from_matrices(pose_frame["rot"])
        self.pivots[f] = pose_frame["pivot"]
        if f > self.start_frame:  # fast turns get the updates between frames as samples
            sub_frame_samples(self.quats[f - 1], self.quats[f], self.samples, self.offsets,
                              self.extra)
        self.samples = []
        self._audit(f, pose_frame)
        if self.projectiles is not None:
            self.projectiles.record(f)
        self.settle(t, pose_frame, 1.0 / self.scene.fps)
        if self.hand_back is not None and self._back_in_range(t, pose_frame):
            self.handed_back = (f, *hinges_from_pose(self.bones, pose_frame["rot"],
                                                     pose_frame["omega"]))
            self.events.extend(Event(t, tr.name, TIER, "", RETURN_DETAIL) for tr in self.trees)

    def _back_in_range(self, t: float, pose: dict) -> bool:
        """Whether the trees have been back in the linear range for
        range.RETURN_WINDOW up to this frame (at t s): every joint holding,
        none cut, no projectile, nothing on the ground, every blast past,
        and the pose within range.in_return_range."""
        intact = not (not self.joint_alive.all() or self.in_debris.any() or self.cut_state
                      or self.projectiles is not None or self.contact_active
                      or not self.loads.blasts_passed(t, pose["com"], self._axes(pose),
                                                      self.props))
        if intact:
            q, v = hinges_from_pose(self.bones, pose["rot"], pose["omega"])
            intact = in_return_range(self.bones, pose["rot"], pose["pivot"], q, v,
                                     self.joint_moments(), self.hand_back)
        return self.watch.update(intact)

    def _audit(self, frame: int, pose: dict) -> None:
        """Record each tree's energy (audit.py): its bones' kinetic and
        gravitational energy (debris included), its live springs' and the
        ground's contact springs'; the debris' loads' work joins the ledger."""
        e = bone_energy(self.mass, self.inertia, pose["rot"], pose["com"], pose["vcom"],
                        pose["omega"], -self.loads.g[2])
        e += np.bincount(self.body_bone, self.spring_energy(), minlength=self.n)
        e += self.contact_energy(pose)
        self.ledger.add_work(self._per_tree(self.debris.work))
        self.debris.work[:] = 0.0
        self.ledger.record(frame, self._per_tree(e), self._per_tree(self.load_work.pending(
            pose["com"])))

    def spring_energy(self) -> np.ndarray:
        """Each body's joint spring's energy (J; 0 where its spring is gone):
        k (eps^2) / 2 with eps = a.angle - b.angle - rest, the angle each
        spring pulls toward zero (pymunk's DampedRotarySpring), from the
        angles just read (`state`; the anchor's is 0), not body by body
        through pymunk's properties (170,000 reads in a 10 s palm bake)."""
        alive = np.fromiter((joint[SPRING] is not None for joint in self.joints), bool,
                            len(self.joints))
        angle = self.state[:, 2]
        before = self.prev_body
        eps = np.where(before >= 0, angle[np.maximum(before, 0)], 0.0) - angle - self.rest
        return np.where(alive, 0.5 * self.k[self.body_bone] * eps * eps, 0.0)

    def _per_tree(self, values: np.ndarray) -> np.ndarray:
        """Per-bone values summed per tree."""
        return per_tree(values, self.bone_tree, len(self.trees))

    def _axes(self, pose: dict) -> np.ndarray:
        """The bones' unit axes (B, 3) in `pose`."""
        return pose["vec"] / np.maximum(self.length, 1e-12)[:, None]

    def _blast_acting(self, t: float) -> bool:
        """Whether a blast pushes the tier's bones within the next update's
        hold, or pushed them within BLAST_RING s (SceneLoads.blast_pushing,
        at the current pose): frame forces held over a hold reach ringing
        twigs late (docs/physics.md, "The twigs ring with their loads updated
        every substep")."""
        return bool(self.loads.explosions) and self.loads.blast_pushing(
            t, self.update_every * self.h, self.pose["com"], self._axes(self.pose), self.props,
            BLAST_RING)

    def _projectile_near(self) -> bool:
        """Whether a flying projectile may touch a bone within the next
        update's hold: updates then come every substep, so that a hit is
        found within a substep's flight and delivered over one."""
        return self.projectiles is not None and self.projectiles.near(
            self.pose, self, self.update_every * self.h)

    def add_work(self, bone: int, joules: float) -> None:
        """Energy given to a bone's tree from outside (a projectile's hit)."""
        self.add_tree_work(int(self.bone_tree[bone]), joules)

    def add_tree_work(self, tree: int, joules: float) -> None:
        """Energy given to a tree from outside (a feller's push)."""
        w = np.zeros(len(self.trees))
        w[tree] = joules
        self.ledger.add_work(w)

    def motions(self) -> list[TreeMotion]:
        """Per tree, the bones' motion at every frame recorded so far."""
        return [tree_motion(self.quats, self.pivots, slice(self.offsets[ti], self.offsets[ti + 1]),
                            [e for e in self.events if e.tree == tree.name], self.ledger, ti,
                            self.extra[ti])
                for ti, tree in enumerate(self.trees)]

    def _hand_over(self, start: StartState) -> None:
        """Put every body where the handed-over pose has its bone: each
        plane's angle (and rate) is the bone's rotation relative to its
        chain's frame projected on the plane's normal; pivots and velocities
        follow down each 2D chain, so the pivots start joined. (The planes
        hold no twist: a turn about a bone's own axis is dropped.)"""
        bb = self.body_bone
        frame = self.bone_frame[bb]
        has = frame >= 0
        fr = np.where(has[:, None, None], start.rot[np.maximum(frame, 0)], np.eye(3))
        w_frame = np.where(has[:, None], start.omega[np.maximum(frame, 0)], 0.0)
        rel = np.matmul(np.transpose(fr, (0, 2, 1)), start.rot[bb])
        angle = (rotvecs_from_matrices(rel) * self.body_n).sum(1)
        rate = (np.einsum("bji,bj->bi", fr, start.omega[bb] - w_frame) * self.body_n).sum(1)
        pos = self.q0.copy()
        vel = np.zeros((len(bb), 2))

        def turned(i: int, arm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """`arm` (m) turned by body i's angle, and its velocity (m/s) at i's rate."""
            c, s = math.cos(angle[i]), math.sin(angle[i])
            arm = np.array([c * arm[0] - s * arm[1], s * arm[0] + c * arm[1]])
            return arm, rate[i] * np.array([-arm[1], arm[0]])

        for i, j in enumerate(self.prev_body):  # a chain plane's bodies follow each other
            if j >= 0:
                arm, v = turned(j, self.q0[i] - self.q0[j])
                pos[i] = pos[j] + arm
                vel[i] = vel[j] + v
        for i, body in enumerate(self.bodies):
            body.angle = float(angle[i])
            body.position = tuple(pos[i].tolist())
            body.velocity = tuple((vel[i] + turned(i, self.cog2d0[i] - self.q0[i])[1]).tolist())
            body.angular_velocity = float(rate[i])

    def _quiet_times(self) -> np.ndarray:
        """Per tree, the time (s) after which no changing load reaches it
        (inf: wind, projectiles in the scene, pulls until their release)."""
        out = np.zeros(len(self.trees))
        for ti, tree in enumerate(self.trees):
            lo, hi = tree.rig.model.bounds()
            quiet = self.loads.quiet_after(0.5 * (lo + hi), 0.5 * float(np.linalg.norm(
                hi[:2] - lo[:2])), float(hi[2]))
            for p in tree.pulls:
                quiet = max(quiet, p.release)
            out[ti] = math.inf if self.scene.projectiles else quiet
        return out
