"""The planar LOD: each limb is a 2D pymunk chain in its own bending plane.

docs/physics.md has the derivations and the measurements behind each choice.

- Chains: a chain is a limb of the rig (a limb and its continuations,
  rig.physics_chains). One pymunk body per bone and plane, a `PivotJoint` at
  each junction, a `DampedRotarySpring` toward the rest angle and a
  `RotaryLimitJoint` for the cone. With `planes = 2` a chain bends in two
  perpendicular planes whose deflections combine into a 3D rotation without
  twist; with 1, in the plane of the dominant load.
- Planes: a chain's plane contains its chord d and the component of the
  tree's dominant horizontal load perpendicular to d (wind, pull, felling or
  blast direction), falling back to gravity, then to the world axes.
- Parent to child: a child chain lives in the moving frame of the bone it
  hangs on. Its bodies hold their motion relative to that frame; gravity and
  air loads are rotated into it, and the frame's acceleration enters as
  d'Alembert forces (translation, Euler, centrifugal and Coriolis terms), so
  children ride on their parents.
- Child to parent: a body carries the limbs attached to it as if they were
  rigid: their mass and inertia are lumped into it and their loads act on it
  at the positions they would have if rigid. Their own swaying does not push
  back (one-way coupling; the accuracy report measures what it costs). An
  axis that forks sympodially is one chain, so a decurrent crown's main
  axes do bend together.
- Prestress: spring rest angles are offset so that the grown shape is the
  equilibrium under gravity (scene `prestress = true`).
- Stability: stability.py (the rotary-inertia floor); spring damping
  c = k h / 2 damps the highest chain modes (omega h / 4) and barely touches
  the sway; structural damping is mass-proportional (rig.alpha) and applied
  as an exact exponential decay over each force interval.
- Breaking: a joint whose bending moment (spring plus cone limit) exceeds
  its strength is removed. In a root chain the part above falls on as a
  free planar chain (a snapped or uprooted stem); elsewhere the part broken
  off becomes rigid debris (debris.py). Felling removes a root joint's
  spring and cone at the cut (the hinge holds), then the hinge when the lean
  passes `hinge` degrees.
- Cost: loads, inertial forces and contacts are evaluated with numpy on all
  bones at `force_rate` and held between evaluations; bodies are read and
  written in bulk through `pymunk.batch`; nothing loops over bodies in Python
  in the step.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from pymunk import batch

from ...rotations import quaternions_from_matrices
from ...scene import Scene
from ..common import SimTree, TreeMotion, locate
from ..debris import Debris
from ..events import Event
from ..loads import SceneLoads
from ..projectiles import Projectiles
from ..quality import Quality
from .breaking import ChainEvents
from .build import ChainBuild
from .forces import ChainForces
from .kinematics import ChainKinematics


@dataclass
class Stats:
    """What a run did, for the bake's metadata and the console."""

    substeps: int = 0
    updates: int = 0
    bodies: int = 0
    bones: int = 0
    step_seconds: float = 0.0  # pymunk stepping and batch writes
    update_seconds: float = 0.0  # reads, reconstruction, loads, events
    inertia_floored: int = 0  # bodies whose rotary inertia the stability rule raised
    max_inertia_ratio: float = 1.0
    max_joint_gap: float = 0.0  # largest pivot separation / bone length at a frame
    limited: int = 0  # bone updates whose load was capped at MAX_ACCELERATION
    first_limit: tuple | None = None  # (tree, segment, time s, acceleration m/s^2)
    refined: int = 0  # substeps split into finer steps (blasts, hits, caps, fast spins)
    broken: int = 0
    debris: int = 0
    debris_clamped: int = 0  # debris body substeps whose spin was clamped (debris.MAX_SPIN)
    notes: list[str] = field(default_factory=list)
    frame_seconds: list[float] = field(default_factory=list)  # physics time of each frame


class PymunkTier(ChainBuild, ChainKinematics, ChainForces, ChainEvents):
    """Simulate the active trees of one scene with the pymunk tier."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None):
        self.scene, self.quality, self.loads = scene, quality, loads
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
        self._collect()
        self._chains()
        self._lumping()
        self._levels()
        self._space()

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index (in that tree) of a global bone."""
        return locate(self.trees, self.offsets, self.bone_tree, bone)

    def bone_path(self, bone: int) -> str:
        ti = int(self.bone_tree[bone])
        return self.trees[ti].rig.model.segment_paths()[self.locate(bone)[1]]

    def run(self, progress=None) -> list[TreeMotion]:
        """Simulate the scene; per tree, the bones' motion at every frame."""
        scene = self.scene
        frames = scene.frame_count
        n = self.n
        quats = np.zeros((frames, n, 4))
        pivots = np.zeros((frames, n, 3))
        self.events: list[Event] = []
        self.cut_state: dict[int, str] = {}
        self.joint_alive = np.ones(n, dtype=bool)
        self.in_debris = np.zeros(n, dtype=bool)
        self.breakable = np.isfinite(self.strength[self.body_bone])
        self.pivot_alive = np.ones(len(self.bodies), dtype=bool)
        self.still_time = np.zeros(len(self.trees))
        self.quiet = self._quiet_times()
        self.debris = Debris(self.mass, self.inertia, self.com0, self.pivot0, self.tip0,
                             self.radius, scene.ground)
        self.projectiles = Projectiles.from_scene(scene) if scene.projectiles else None
        writes = batch.BodyFields.FORCE | batch.BodyFields.TORQUE
        self.read()
        pose = self.reconstruct()
        prev = None
        quats[0] = quaternions_from_matrices(pose["rot"])
        pivots[0] = pose["pivot"]
        substep, t, fresh = 0, 0.0, True
        next_update, last_update = 0, 0
        self.contact_active = False
        self.refine = 1
        for f in range(1, frames):
            t_frame = time.perf_counter()
            for _ in range(self.spf):
                if substep >= next_update:
                    t0 = time.perf_counter()
                    if not fresh:
                        self.read()
                        self.check(t)
                        prev, pose = pose, self.reconstruct()
                    fresh = False
                    if self.cut_list:
                        self.handle_cuts(t)
                    if self.breakable.any():
                        before = len(self.events)
                        self.check_breaks(t, pose)
                        if len(self.events) > before:
                            self.log(f"t = {t:.3f} s: {len(self.events) - before} joints broke")
                            pose = self.reconstruct()
                    # contact needs a stiff spring, and only an update every
                    # substep affords one: while anything touches the
                    # ground, update at the substep rate
                    ahead = 1 if self.contact_active else self.update_every
                    self.forces(t, pose, prev, max(substep - last_update, 1) * self.h,
                                ahead * self.h)
                    last_update, next_update = substep, substep + ahead
                    self.stats.updates += 1
                    self.stats.update_seconds += time.perf_counter() - t0
                t0 = time.perf_counter()
                batch.set_space_bodies(self.space, writes, self.write_buf)
                if self.refine > 1:
                    for _ in range(self.refine):  # forces persist? set them every step
                        self.space.step(self.h / self.refine)
                        batch.set_space_bodies(self.space, writes, self.write_buf)
                    self.stats.refined += 1
                else:
                    self.space.step(self.h)
                self.stats.step_seconds += time.perf_counter() - t0
                substep += 1
                t = substep * self.h
            t0 = time.perf_counter()
            self.read()
            self.check(t)
            self.stats.max_joint_gap = max(self.stats.max_joint_gap, self.joint_gap())
            pose_frame = self.reconstruct()
            if substep >= next_update:  # the frame's pose is the next update's
                prev, pose, fresh = pose, pose_frame, True
            quats[f] = quaternions_from_matrices(pose_frame["rot"])
            pivots[f] = pose_frame["pivot"]
            if self.projectiles is not None:
                self.projectiles.record(f)
            self.settle(t, pose_frame, 1.0 / scene.fps)
            self.stats.update_seconds += time.perf_counter() - t0
            self.stats.frame_seconds.append(time.perf_counter() - t_frame)
            if progress is not None:
                progress(f, frames - 1)
        self.stats.substeps = substep
        self.stats.debris_clamped = self.debris.clamped
        out = []
        for ti, tree in enumerate(self.trees):
            a, b = self.offsets[ti], self.offsets[ti + 1]
            events = [e for e in self.events if e.tree == tree.name]
            out.append(TreeMotion(quats[:, a:b], pivots[:, a:b], events))
        return out

    def _quiet_times(self) -> np.ndarray:
        """Per tree, the time (s) after which no changing load reaches it
        (inf: wind, projectiles in the scene, pulls until their release)."""
        out = np.zeros(len(self.trees))
        for ti, tree in enumerate(self.trees):
            m = tree.rig.model
            lo, hi = m.bounds()
            quiet = self.loads.quiet_after(0.5 * (lo + hi), 0.5 * float(np.linalg.norm(
                hi[:2] - lo[:2])), float(hi[2]))
            for p in tree.pulls:
                quiet = max(quiet, p.release)
            out[ti] = math.inf if self.scene.projectiles else quiet
        return out

    @property
    def cut_list(self) -> bool:
        return any(t.cut is not None for t in self.trees)
