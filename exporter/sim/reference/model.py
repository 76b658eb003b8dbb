"""The reference's MuJoCo models: which trees share one, and building them
from the rig (bodies, hinges, capsules, projectiles), their addresses, the
structural damping's entries, and a state carried from old models to new.

One body per bone, nested as the rig's bones are, its frame at the bone's
pivot with the world's orientation at rest (so its pose is the bake's);
mass, COM and full inertia are the rig's. The joint at a bone's base is two
hinges perpendicular to the bone (common.hinge_axes), each with the rig's
stiffness and range +-cone. A capsule per bone collides with projectiles;
where the scene has a ground and something can fall (a cut, projectiles,
breakable joints) or the tree came for its tips at the ground, a second
capsule per bone around all its bark and leaf cards (its envelope) holds
the mesh out of the ground (docs/physics.md, "The reference")."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..common import Bones
from ..contact import FRICTION
from ..projectiles import projectile_reaches
from ..rules import Felling, exact_decay, floored_inertia

PROJECTILE_TIMECONST = 0.005  # s, contact stiffness of projectiles (MuJoCo solref)
ROLLING = 0.01  # m, rolling friction (torque / normal force): soft ground stops rolling
IN_GROUND = 4  # contype of a capsule in the ground at rest: projectiles hit it, the ground not
BASE_SPHERE = 0.01  # m: the most radius of the sphere that holds a buried capsule's lower end up
GROUND_ONLY = 8  # contype of a bone's envelope: the ground holds it up, projectiles pass it
CLEARANCE = 0.001  # m: an envelope shortened off the ground at its pivot stops this far above it
DISC = 0.005  # m, half the thickness of the disc that holds a stem's base ring out of the ground
# s, the ground's contact time constant (MuJoCo solref) with the envelopes:
# MuJoCo's default 0.02 s let a felled spruce's top sink 0.1 m as it landed
GROUND_TIMECONST = 0.005
XBODY = mujoco.mjtObj.mjOBJ_XBODY  # a body's frame (mjOBJ_BODY is its COM frame)


def _ints() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


@dataclass
class Group:
    """One MuJoCo model: some trees' bones (global indices, in order), maybe
    the projectiles, with the addresses of its bodies, hinges and free
    joints, and the structural damping's mass-matrix entries."""

    trees: list[int]
    bones: np.ndarray
    projectiles: bool
    ground: bool
    debris: bool = False  # parts broken off a tree
    model: mujoco.MjModel | None = None
    data: mujoco.MjData | None = None
    body: np.ndarray = field(default_factory=_ints)
    root_body: np.ndarray = field(default_factory=_ints)
    hinge_qpos: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    hinge_dof: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    hinge_jnt: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    jnt_row: np.ndarray = field(default_factory=_ints)  # joint -> row * 2 + hinge
    free_qpos: np.ndarray = field(default_factory=_ints)
    free_dof: np.ndarray = field(default_factory=_ints)
    proj_body: np.ndarray = field(default_factory=_ints)
    proj_qpos: np.ndarray = field(default_factory=_ints)
    proj_dof: np.ndarray = field(default_factory=_ints)
    # structural damping: entries (row dof, column dof, address in d.M) of
    # each limb's block of the mass matrix, diagonal and below, their alpha
    # (1/s) and that as an exact decay over damp_hold s (the step or a
    # blast's substep)
    damp_row: np.ndarray = field(default_factory=_ints)
    damp_col: np.ndarray = field(default_factory=_ints)
    damp_adr: np.ndarray = field(default_factory=_ints)
    damp_alpha: np.ndarray = field(default_factory=lambda: np.zeros(0))
    damp_rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    damp_hold: float = 0.0
    damp_below: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    has_free: bool = False  # some bone is a free part's first (its damping is kept stable)
    substeps: int = 1  # MuJoCo steps per solver step (fast-spinning free parts, blasts)
    blast: bool = False  # a blast splits the step: loads and damping every substep
    # while a blast splits the step: each joint's largest bending moment (N m)
    # since the last break check (None: not tracked)
    peak: np.ndarray | None = None


def restitution_damping(e: float) -> float:
    """Damping ratio of a linear contact whose coefficient of restitution is `e`."""
    if e <= 0:
        return 1.0
    if e >= 1:
        return 0.0
    ln = math.log(e)
    return -ln / math.sqrt(math.pi**2 + ln * ln)


class ReferenceModels:
    """Building and rebuilding the models (mixed into the reference engine)."""

    def _collect(self) -> None:
        """The trees' rigs as global bone arrays (common.Bones), the limb of
        every bone, and the bones' rest axes."""
        trees = self.trees
        self.bones = b = Bones.of(trees)
        self.n = n = b.n
        self.offsets, self.bone_tree, self.parent = b.offsets, b.bone_tree, b.parent
        self.pivot0, self.tip0, self.com0, self.props = b.pivot0, b.tip0, b.com0, b.props
        self.mass, self.inertia, self.strength, self.radius = b.mass, b.inertia, b.strength, \
            b.radius
        self.alpha, self.length = b.alpha, b.length
        self.limb = np.zeros(n, dtype=np.int64)  # limb of each bone, numbered across trees
        limbs = 0
        for ti, t in enumerate(trees):
            o = int(self.offsets[ti])
            self.limb[o:o + t.rig.n_bones] = t.rig.bone_limb + limbs
            limbs += len(t.rig.limbs)
        v = self.tip0 - self.pivot0
        self.axis0 = np.divide(v, self.length[:, None], out=np.tile([0.0, 0.0, 1.0], (n, 1)),
                               where=self.length[:, None] > 0)
        self.paths = [t.rig.model.segment_paths() for t in trees]
        # the inertia each body has in its model (a free part's is floored):
        # the audit measures the energy the model holds
        self.model_inertia = self.inertia.copy()

    def _joints(self) -> None:
        """Per bone, the two hinges' axes, stiffness, range and spring
        reference (set from gravity once the models exist), and which joints
        hold, may break and are damped."""
        n = self.n
        self.hinge_axis = self.bones.hinges
        self.k = np.repeat(self.bones.k[:, None], 2, axis=1)  # per hinge
        self.cone = np.repeat(self.bones.cone[:, None], 2, axis=1)
        self.springref = np.zeros((n, 2))
        self.damped = np.ones((n, 2), dtype=bool)  # hinges the structural damping acts on
        self.attached = np.ones(n, dtype=bool)  # the joint at the bone's base holds
        # joints that passed their strength within a blast's split step
        # (_release): (time s, bone, moment N m), their parts leave at the next check
        self.released: list[tuple[float, int, float]] = []
        self.piece_root = np.full(n, -1, dtype=np.int64)  # first bone of a free part, -1
        self.breakable = np.isfinite(self.strength)
        self.cut_state = [Felling.STANDING if t.cut is not None else None for t in self.trees]
        self.still_time = np.zeros(len(self.trees))
        self.settled = np.zeros(len(self.trees), dtype=bool)
        # bones whose rest capsule reaches into the ground do not touch it while standing
        ratio = np.repeat([t.rig.options.bone_ratio for t in self.trees],
                          [t.rig.n_bones for t in self.trees])
        mid = 0.5 * (self.pivot0 + self.tip0)
        half = (0.5 * ratio * self.length)[:, None] * self.axis0
        low = np.minimum((mid - half)[:, 2], (mid + half)[:, 2]) - self.radius
        self.in_ground = low < 0.0
        # where each root's felling hinge turns, in its bone's frame (m): the
        # stem's edge on the falling side once cut (_fell), else its pivot
        self.hinge_pos = np.zeros((n, 3))
        self._envelopes()

    def _envelopes(self) -> None:
        """Per bone, the capsule around its bark rings and the physics' leaf
        cards (two of `leaf size` per leafy segment, rig.py; the exporters'
        foliage reaches farther and is not held up, docs/look.md): radius
        `reach` (m) about the line from
        `reach_from` (m along the bone from its pivot) to its tip. Where it
        would reach below the ground at the pivot at rest (a stem's base),
        it starts a radius up the bone, so that it only touches the ground
        once the bone has turned."""
        self.reach = np.zeros(self.n)
        self.base_radius = np.zeros(self.n)  # m, the bark's radius at the bone's pivot
        for ti, t in enumerate(self.trees):
            m, o = t.rig.model, int(self.offsets[ti])
            p0, p1 = m.points[m.seg_start], m.points[m.seg_end]
            length = np.linalg.norm(p1 - p0, axis=1)
            # a ring inside a limb is at most the larger of its two segments'
            parent = np.maximum(m.seg_parent, 0)
            same = (m.seg_parent >= 0) & (m.seg_limb[parent] == m.seg_limb)
            width = np.maximum(m.width, np.where(same, m.width[parent], 0.0))
            half = 0.5 * np.where(m.leaf > 0, m.leaf_size, 0.0)
            # a card's corner: half its edge across the segment, and along it
            # beyond the segment's end where the card is longer than it
            card = np.hypot(half, np.maximum(half - 0.5 * length, 0.0))
            bone = t.rig.seg_bone + o
            off = np.zeros(len(bone))
            for end in (p0, p1):  # how far the segment's ends lie off the bone's line
                v = end - self.pivot0[bone]
                along = np.einsum("ij,ij->i", v, self.axis0[bone])
                off = np.maximum(off, np.linalg.norm(v - along[:, None] * self.axis0[bone],
                                                     axis=1))
            np.maximum.at(self.reach, bone, off + np.maximum(0.5 * width, card))
            first = np.full(t.rig.n_bones, len(bone))
            np.minimum.at(first, t.rig.seg_bone, np.arange(len(bone)))
            self.base_radius[o:o + t.rig.n_bones] = 0.5 * width[first]
        self.reach = np.maximum(self.reach, self.radius)
        low_pivot = self.pivot0[:, 2] <= self.tip0[:, 2]
        start = np.where(low_pivot & (self.pivot0[:, 2] - self.reach < 0.0),
                         self.reach + CLEARANCE, 0.0)
        self.reach_from = np.where(start < self.length, start, 0.0)
        # off: in the ground at the start; and a stem's base: standing, it
        # turns about its centre (the root plate's give), where its rim must
        # go into the ground; a cut moves that hinge to the rim (_fell) and
        # turns the base's envelope on
        self.envelope_on = ~((self.reach_from > 0) & (self.parent < 0))
        # (the envelopes and the ground share it: MuJoCo mixes the two geoms')
        self.solref = [max(GROUND_TIMECONST, 2 * self.h), 1.0]

    def _groups(self) -> None:
        """Which trees share a model (one per tree; trees a projectile can
        reach share one with the projectiles, where this engine throws
        them), then build them all; spring references from the gravity
        torques at rest (prestress)."""
        scene = self.scene
        projectiles = bool(scene.projectiles)
        shared: list[int] = []
        if projectiles and self.throws:
            shared = [ti for ti, t in enumerate(self.trees)
                      if projectile_reaches(scene, t.rig.model)]
        self.groups: list[Group] = []
        falls = bool(scene.projectiles) or any(t.cut is not None for t in self.trees)
        for ti in range(len(self.trees)):
            if ti in shared:
                continue
            bones = np.arange(self.offsets[ti], self.offsets[ti + 1])
            ground = scene.ground and (self.touch_ground or falls
                                       or bool(self.breakable[bones].any()))
            self.groups.append(Group([ti], bones, False, ground))
        if projectiles and self.throws:
            bones = np.concatenate([np.arange(self.offsets[ti], self.offsets[ti + 1])
                                    for ti in shared] + [_ints()])
            self.groups.append(Group(shared, bones.astype(np.int64), True, scene.ground))
        self.group_of_bone = np.zeros(self.n, dtype=np.int64)
        self.debris_of: dict[int, int] = {}  # tree -> its debris group
        for gi, g in enumerate(self.groups):
            self.group_of_bone[g.bones] = gi
        for g in self.groups:
            self._compile(g)
        if scene.prestress:
            for g in self.groups:
                self._prestress(g)
        self.stats.bodies = sum(g.model.nbody - 1 for g in self.groups)

    def _compile(self, g: Group, sources: list[Group] | None = None) -> None:
        """Build a group's model; with `sources` (the groups that held its
        bones, kinematics and velocities current), carry the state over."""
        t0 = time.perf_counter()
        spec = mujoco.MjSpec()
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
        spec.compiler.balanceinertia = True
        spec.compiler.degree = False  # ranges in radians
        opt = spec.option
        opt.timestep = self.h
        opt.integrator = mujoco.mjtIntegrator.mjINT_DISCRETE
        opt.gravity = self.loads.g
        opt.disableflags = int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
        collide = g.ground or g.projectiles
        if not collide:
            opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        world = spec.worldbody
        if g.ground:
            world.add_geom(name="ground", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1],
                           contype=2, conaffinity=1 | GROUND_ONLY, condim=6,
                           friction=[FRICTION, 0.005, ROLLING], solref=self.solref)
        bodies: dict[int, mujoco.MjsBody] = {}
        for b in g.bones.tolist():
            p = int(self.parent[b])
            held = self.attached[b] and p >= 0
            bodies[b] = self._add_bone(bodies[p] if held else world, b,
                                       self.pivot0[b] - (self.pivot0[p] if held else 0.0),
                                       collide, g.ground, g.ground and self.in_ground[b])
        if g.projectiles:
            for i, pr in enumerate(self.scene.projectiles):
                self._add_projectile(world, i, pr)
        g.model = spec.compile()
        g.data = mujoco.MjData(g.model)
        self._index(g)
        if sources:
            self._transfer(g, sources)
        self.timing["compile_seconds"] += time.perf_counter() - t0

    def _add_bone(self, parent, b: int, pos: np.ndarray, collide: bool, ground: bool,
                  buried: bool):
        """Bone b's body under `parent` at `pos` (m, in the parent's frame):
        its inertia, its joint (two hinges, or a free joint once broken
        off), its capsule, with a `ground` its envelope (_envelopes) and,
        where the capsule is in the ground at rest (`buried`), the small
        sphere that holds its lower end up."""
        body = parent.add_body(name=f"b{b}", pos=pos)
        body.explicitinertial = True
        body.mass = float(self.mass[b])
        body.ipos = self.com0[b] - self.pivot0[b]
        i = self.inertia[b] if self.attached[b] else floored_inertia(self.inertia[b])
        self.model_inertia[b] = i
        body.fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
        if self.attached[b]:
            for k in range(2):
                limited = math.isfinite(self.cone[b, k])
                body.add_joint(
                    name=f"j{b}_{k}", type=mujoco.mjtJoint.mjJNT_HINGE,
                    pos=self.hinge_pos[b] if k == 0 else np.zeros(3),
                    axis=self.hinge_axis[b, k], stiffness=float(self.k[b, k]),
                    springref=float(self.springref[b, k]),
                    limited=mujoco.mjtLimited.mjLIMITED_TRUE if limited
                    else mujoco.mjtLimited.mjLIMITED_FALSE,
                    range=[-float(self.cone[b, k]), float(self.cone[b, k])] if limited
                    else [0.0, 0.0])
        else:
            body.add_freejoint(name=f"f{b}")
        ratio = self.trees[self.bone_tree[b]].rig.options.bone_ratio
        lo, hi = 0.5 * (1 - ratio), 0.5 * (1 + ratio)
        v = self.tip0[b] - self.pivot0[b]
        # a capsule in the ground at rest never touches it (IN_GROUND: the
        # projectiles still do): freed (felled, uprooted) it would start deep
        # in it and be thrown out; the sphere holds that end up instead
        # with an envelope the ground holds the envelope, not this capsule
        body.add_geom(name=f"c{b}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                      fromto=np.concatenate([lo * v, hi * v]),
                      size=[max(float(self.radius[b]), 1e-4), 0, 0],
                      contype=(IN_GROUND if buried or (ground and self.envelope_on[b]) else 1)
                      if collide else 0,
                      conaffinity=0, condim=6, friction=[FRICTION, 0.005, ROLLING])
        if ground:
            a = v / max(float(self.length[b]), 1e-12)
            body.add_geom(name=f"e{b}", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                          fromto=np.concatenate([self.reach_from[b] * a, v]),
                          size=[float(self.reach[b]), 0, 0],
                          contype=GROUND_ONLY if self.envelope_on[b] else 0,
                          conaffinity=0, condim=6, friction=[FRICTION, 0.005, ROLLING],
                          solref=self.solref)
        if buried:
            rho = min(max(float(self.radius[b]), 1e-4), BASE_SPHERE)
            low = v if self.tip0[b, 2] < self.pivot0[b, 2] else np.zeros(3)
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[rho, 0, 0],
                          pos=low + np.array([0.0, 0.0, rho]), contype=1, conaffinity=0,
                          condim=6, friction=[FRICTION, 0.005, ROLLING])
        if ground and self.reach_from[b] > 0:
            # the envelope starts a radius up a stem's base: a disc on the
            # base ring holds the ring's rim out of the ground once it turns
            a = v / max(float(self.length[b]), 1e-12)
            quat = np.zeros(4)
            mujoco.mju_quatZ2Vec(quat, a)
            body.add_geom(name=f"d{b}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                          size=[float(self.base_radius[b]), DISC, 0], pos=DISC * a, quat=quat,
                          contype=GROUND_ONLY if self.envelope_on[b] else 0, conaffinity=0,
                          condim=6, friction=[FRICTION, 0.005, ROLLING], solref=self.solref)
        return body

    def envelopes_off_in_ground(self) -> None:
        """At the start (from rest or a hand-off), envelopes already in the
        ground (a twig hanging to it, a tip the linear tier bent onto it)
        would be thrown out: they stay off for the run, and their bones'
        capsules take the ground as before."""
        for g in self.groups:
            if not g.ground:
                continue
            m, d = g.model, g.data
            mujoco.mj_kinematics(m, d)
            for b in g.bones.tolist():
                e = m.geom(f"e{b}").id
                axis = d.geom_xmat[e].reshape(3, 3)[:, 2]
                ends = d.geom_xpos[e] + np.outer([-m.geom_size[e, 1], m.geom_size[e, 1]], axis)
                low = ends[:, 2].min() - m.geom_size[e, 0]
                disc = m.geom(f"d{b}").id if self.reach_from[b] > 0 else -1
                if disc >= 0:  # its rim's lowest point
                    az = abs(d.geom_xmat[disc].reshape(3, 3)[2, 2])
                    low = min(low, d.geom_xpos[disc, 2] - DISC * az
                              - m.geom_size[disc, 0] * math.sqrt(max(1.0 - az * az, 0.0)))
                if low < -CLEARANCE:
                    self.envelope_on[b] = False
                    m.geom_contype[e] = 0
                    if disc >= 0:
                        m.geom_contype[disc] = 0
                    if not self.in_ground[b]:
                        m.geom_contype[m.geom(f"c{b}").id] = 1

    def _add_projectile(self, world, i: int, pr) -> None:
        """Projectile i (scene ProjectileSpec `pr`) as a free box or ball."""
        body = world.add_body(name=f"p{i}", pos=pr.position)
        body.explicitinertial = True
        body.mass = pr.mass
        body.ipos = [0.0, 0.0, 0.0]
        moment = pr.mass * pr.size**2 / 6 if pr.shape == "box" else \
            0.4 * pr.mass * (pr.size / 2) ** 2
        body.fullinertia = [moment, moment, moment, 0, 0, 0]
        body.add_freejoint(name=f"pf{i}")
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX if pr.shape == "box" else mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[pr.size / 2] * 3, contype=2, conaffinity=3 | IN_GROUND, priority=1, condim=6,
            friction=[pr.friction, 0.005, ROLLING],
            solref=[max(PROJECTILE_TIMECONST, 2 * self.h), restitution_damping(pr.restitution)])

    def _index(self, g: Group) -> None:
        """Body, joint, qpos and dof addresses of the group's bones."""
        m = g.model
        nb = len(g.bones)
        g.body = np.asarray([m.body(f"b{b}").id for b in g.bones.tolist()], dtype=np.int64)
        g.root_body = m.body_rootid[g.body].astype(np.int64)
        g.hinge_jnt = np.full((nb, 2), -1, dtype=np.int64)
        g.free_qpos = np.full(nb, -1, dtype=np.int64)
        g.free_dof = np.full(nb, -1, dtype=np.int64)
        for i, b in enumerate(g.bones.tolist()):
            if self.attached[b]:
                g.hinge_jnt[i] = [m.joint(f"j{b}_{k}").id for k in range(2)]
            else:
                j = m.joint(f"f{b}").id
                g.free_qpos[i], g.free_dof[i] = m.jnt_qposadr[j], m.jnt_dofadr[j]
        g.has_free = bool((g.free_dof >= 0).any())
        g.substeps, g.peak, g.blast, g.damp_hold = 1, None, False, self.h
        has = g.hinge_jnt >= 0
        g.hinge_qpos = np.where(has, m.jnt_qposadr[np.maximum(g.hinge_jnt, 0)], -1)
        g.hinge_dof = np.where(has, m.jnt_dofadr[np.maximum(g.hinge_jnt, 0)], -1)
        g.jnt_row = np.full(m.njnt, -1, dtype=np.int64)
        rows = np.nonzero(has)
        g.jnt_row[g.hinge_jnt[rows]] = rows[0] * 2 + rows[1]
        if g.projectiles:
            p = len(self.scene.projectiles)
            g.proj_body = np.asarray([m.body(f"p{i}").id for i in range(p)], dtype=np.int64)
            jnt = [m.joint(f"pf{i}").id for i in range(p)]
            g.proj_qpos = m.jnt_qposadr[jnt].astype(np.int64)
            g.proj_dof = m.jnt_dofadr[jnt].astype(np.int64)
        self._damping_pairs(g)

    def _damping_pairs(self, g: Group) -> None:
        """The entries of each limb's block of the mass matrix (M's sparse
        lower triangle, rows and columns both damped hinge dofs of one limb):
        the structural damping's (stepper.py, `_damping`)."""
        m = g.model
        limb = np.full(m.nv, -1, dtype=np.int64)
        rate = np.zeros(m.nv)
        has = (g.hinge_dof >= 0) & self.damped[g.bones]
        rows = np.nonzero(has)[0]
        limb[g.hinge_dof[has]] = self.limb[g.bones[rows]]
        rate[g.hinge_dof[has]] = self.alpha[g.bones[rows]]
        nnz = m.M_rownnz
        row = np.repeat(np.arange(m.nv), nnz)
        first = np.cumsum(nnz) - nnz  # each row's first entry, counted densely
        adr = np.repeat(m.M_rowadr, nnz) + np.arange(len(row)) - np.repeat(first, nnz)
        col = m.M_colind[adr]
        keep = (limb[row] >= 0) & (limb[row] == limb[col]) & (rate[row] > 0)
        g.damp_row, g.damp_col, g.damp_adr = row[keep], col[keep], adr[keep]
        g.damp_alpha = rate[g.damp_row]
        g.damp_rate = exact_decay(g.damp_alpha, g.damp_hold)
        g.damp_below = g.damp_row != g.damp_col

    def _transfer(self, g: Group, sources: list[Group]) -> None:
        """Carry the state over to g's new model from the groups that held
        its bones (their kinematics and velocities current): hinges by
        value, newly freed bones from their bodies' poses and velocities,
        projectiles by value."""
        d = g.data
        d.time = sources[0].data.time
        for src in sources:
            data = src.data
            dst = np.nonzero(np.isin(g.bones, src.bones))[0]
            rows = np.searchsorted(src.bones, g.bones[dst])
            q_new, v_new = g.hinge_qpos[dst], g.hinge_dof[dst]
            q_old, v_old = src.hinge_qpos[rows], src.hinge_dof[rows]
            keep = (q_new >= 0) & (q_old >= 0)
            d.qpos[q_new[keep]] = data.qpos[q_old[keep]]
            d.qvel[v_new[keep]] = data.qvel[v_old[keep]]
            for i, r in zip(dst, rows):
                if g.free_qpos[i] >= 0:
                    self._transfer_free(g, i, src, r)
            if g.projectiles and src.projectiles:
                for qn, vn, qo, vo in zip(g.proj_qpos, g.proj_dof, src.proj_qpos, src.proj_dof):
                    d.qpos[qn:qn + 7] = data.qpos[qo:qo + 7]
                    d.qvel[vn:vn + 6] = data.qvel[vo:vo + 6]

    def _transfer_free(self, g: Group, i: int, src: Group, r: int) -> None:
        """Row i of g, a free body, from row r of `src`: its free joint's
        state, or (newly freed) its body's pose and velocity there."""
        d, data = g.data, src.data
        q, v = g.free_qpos[i], g.free_dof[i]
        qo, vo, body = src.free_qpos[r], src.free_dof[r], int(src.body[r])
        if qo >= 0:
            d.qpos[q:q + 7] = data.qpos[qo:qo + 7]
            d.qvel[v:v + 6] = data.qvel[vo:vo + 6]
            return
        res = np.zeros(6)
        d.qpos[q:q + 3] = data.xpos[body]
        d.qpos[q + 3:q + 7] = data.xquat[body]
        mujoco.mj_objectVelocity(src.model, data, XBODY, body, res, 0)
        d.qvel[v:v + 3] = res[3:]  # the body frame origin's, world
        d.qvel[v + 3:v + 6] = data.xmat[body].reshape(3, 3).T @ res[:3]  # local

    def _prestress(self, g: Group) -> None:
        """Spring references that make the rest pose the static equilibrium
        under gravity: k (0 - ref) + bias = 0 at q = 0, v = 0."""
        m, d = g.model, g.data
        mujoco.mj_forward(m, d)
        has = g.hinge_dof >= 0
        bias = np.where(has, d.qfrc_bias[np.maximum(g.hinge_dof, 0)], 0.0)
        k = self.k[g.bones]
        ref = np.divide(bias, k, out=np.zeros_like(bias), where=k > 0)
        tree_of = self.bone_tree[g.bones]
        for ti in np.unique(tree_of):
            hold = self.trees[ti].hold
            if hold is not None:  # a tree that lost parts keeps its springs' set
                rows = np.nonzero(tree_of == ti)[0]
                local = g.bones[rows] - self.offsets[ti]
                ref[rows] = np.divide(-hold.reshape(-1, 2)[local], k[rows],
                                      out=np.zeros((len(rows), 2)), where=k[rows] > 0)
        self.springref[g.bones] = ref
        m.qpos_spring[g.hinge_qpos[has]] = ref[has]
        mujoco.mj_resetData(m, d)
