"""The full-3D reference: the rig in MuJoCo, to measure the planar LOD's
error and to give users the slow, accurate answer.

Model (one MuJoCo model per tree; trees a projectile can reach share one
with the projectiles, since compile time grows about quadratically with the
bodies in a model):

- One body per bone, nested as the rig's bones are. A body's frame sits at
  the bone's pivot with the world's orientation at rest, so its pose *is*
  the bake's (rotation relative to rest, pivot position). Mass, COM and the
  full inertia tensor are the rig's, set explicitly (never from geoms).
- The joint at a bone's base: two hinges at the pivot, both perpendicular to
  the bone's axis (swing without twist), each with the rig's stiffness k and
  range +-cone (so the cone is a square of side 2 cone in the two swing
  angles, not a circle). Spring references hold the grown shape in static
  equilibrium under gravity (`prestress`): ref = (gravity torque at rest) / k.
- A capsule per bone, `bone_ratio` x its length, centred on it. It collides
  (with the ground and projectiles, never with other bones) only when the
  scene has a ground and something can fall on it (projectiles, a cut,
  breakable joints); bones whose capsule pokes into the ground at rest do not
  touch the ground while their tree stands.
- Gravity is MuJoCo's (the same vector as SceneLoads.g). Air, blasts,
  attractors and pulls are world forces at the bones' COMs (`xfrc_applied`),
  re-evaluated every `force_every` steps and held between. External loads
  are capped at MAX_ACCELERATION x mass, as in the planar LOD, and counted.
- Structural damping: the rig's mass-proportional damping, relative to each
  bone's limb frame (the bone its limb hangs on; the world for root limbs):
  force -alpha m v_rel at the COM and torque -alpha I omega_rel, with
  alpha replaced by (1 - exp(-alpha h)) / h (an exact decay over a step).
  Applied every step as an external wrench, with the equal and opposite
  reaction on the frame bone, so it is an internal force that only ever
  removes energy. (The planar LOD applies it one way, without reaction.)

Integrator, measured on the 10 m x 0.2 m cantilever (E = 8 GPa, rho = 800
kg/m^3, 30 bones, no gravity, released from its static deflection under a
tip load; beam f1 = 0.8848 Hz; zeta = damping ratio of the free decay, all
of it numerical; cost per body-step on this machine, one model):

    integrator     joint damping   h        f1 error   zeta     us/body-step
    euler          0               <=1/4000 unstable
    implicitfast   0               <=1/4000 unstable
    implicit       0               <=1/2000 unstable
    rk4            0 or k h / 2    >=1/2000 unstable   (1/4000: -0.11 %)
    euler          k h / 2         1/240    -0.06 %    0.0049   1.1
    implicitfast   k h / 2         1/240    -0.06 %    0.0049   1.2
    implicit       k h / 2         1/240    -0.06 %    0.0049   6-7
    discrete       0               1/240    -0.01 %    0.0104   1.2
    discrete       0               1/480    -0.06 %    0.0049   1.3
    discrete       0               1/1000   -0.09 %    0.0022   1.1
    discrete       0               1/2000   -0.11 %    0.0011   1.0
    discrete       0               1/4000   -0.11 %    0.0007   0.9

(-0.11 % is the 30-bone chain's own error against the beam.) Only
`discrete` (the constraint solve and the velocity update in the metric
M + hD + h^2 K, i.e. implicit in the joint stiffness) is stable at wood
stiffness with no added damping; the others need joint damping c >= k h / 2,
a stiffness-proportional damping the rig does not have. Every stable choice
holds f1 within 0.15 % even at 1/240 s: the step is bounded by the numerical
damping instead, zeta ~ pi f1 h for `discrete`. DEFAULT_TIMESTEP = 1/2000 s
keeps it near 0.001 for f1 ~ 1 Hz (the structural damping of trees is
0.01-0.08); `TIMESTEPS` lists coarser steps for the error-vs-cost report, and
meta() states the added damping of each run.

Events: felling removes the cut root joint's felling-direction hinge spring
and limit (the sideways hinge holds, like hinge wood) and nudges the tree
over; past `hinge` degrees of lean the root joint is removed and the tree
falls free onto the ground. A joint whose bending moment (hinge springs plus
limit forces) exceeds its `strength` breaks: the bone and everything it
carries become a free body (a snapped branch, or an uprooted tree). Removing
a joint rebuilds that model (a few ms) and carries the state over exactly;
a freed part is then damped relative to its own first bone only (its rigid
motion is not damped), and its first bone's principal moments of inertia
are floored at MIN_INERTIA_RATIO of the largest (as the planar LOD's debris:
a thin stick would otherwise roll and spin about its own axis unboundedly). Not modelled: collisions between bones (also of
different trees), projectiles' air drag.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import mujoco
import numpy as np

from ..bake import ObjectsBake
from ..errors import SimulationError
from ..rotations import cross
from ..scene import Quality, Scene
from .common import MAX_ACCELERATION, MAX_ANGULAR_SPEED, SimTree, TreeMotion
from .contact import FRICTION
from .debris import MAX_SPIN, MIN_INERTIA_RATIO
from .loads import BoneProps, SceneLoads

DEFAULT_TIMESTEP = 1 / 2000  # s
DEFAULT_FORCE_RATE = 500.0  # Hz
TIMESTEPS = {"fine": 1 / 4000, "default": 1 / 2000, "coarse": 1 / 1000, "draft": 1 / 480}
NUDGE = 0.05  # rad/s, the felling push at the cut
SETTLE_SPEED = 0.05  # m/s and rad/s: a fallen tree slower than this for SETTLE_TIME is at rest
SETTLE_TIME = 0.5  # s
PROJECTILE_TIMECONST = 0.005  # s, contact stiffness of projectiles (MuJoCo solref)
ROLLING = 0.01  # m, rolling friction (torque / normal force): soft ground stops rolling
LIMIT = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
BAD = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
       mujoco.mjtWarning.mjWARN_BADQPOS)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def hinge_axes(axis: np.ndarray, toward: np.ndarray | None = None) -> np.ndarray:
    """Two unit hinge axes (2, 3) perpendicular to a bone `axis` and to each
    other. With `toward`, a positive turn of the first tips the bone toward
    it (the felling hinge); otherwise the first is horizontal when it can be."""
    for cand in ([toward] if toward is not None else []) + [np.array([0.0, 0.0, 1.0]),
                                                             np.array([1.0, 0.0, 0.0])]:
        e = np.cross(axis, cand)
        if np.linalg.norm(e) > 0.1:
            e1 = _unit(e)
            return np.stack([e1, np.cross(axis, e1)])
    raise AssertionError("no perpendicular found")  # pragma: no cover


def floored_inertia(inertia: np.ndarray) -> np.ndarray:
    """An inertia tensor (kg m^2) with its principal moments floored at
    MIN_INERTIA_RATIO of the largest, as the planar LOD's debris: a free
    thin stick would otherwise spin (roll) without bound about its own axis."""
    lam, vec = np.linalg.eigh(inertia)
    lam = np.maximum(lam, MIN_INERTIA_RATIO * lam[-1])
    return (vec * lam) @ vec.T


def restitution_damping(e: float) -> float:
    """Damping ratio of a linear contact whose coefficient of restitution is `e`."""
    if e <= 0:
        return 1.0
    if e >= 1:
        return 0.0
    ln = math.log(e)
    return -ln / math.sqrt(math.pi**2 + ln * ln)


@dataclass
class Stats:
    """What a run did (deterministic: no timings, which are in `timing`)."""

    steps: int = 0
    updates: int = 0
    models: int = 0
    bodies: int = 0
    rebuilds: int = 0
    limited: int = 0  # bone updates whose external load was capped
    clamped: int = 0  # updates at which a free part's spin was clamped to MAX_SPIN
    first_limit: tuple | None = None  # (tree, segment, time s, acceleration m/s^2)
    broken: int = 0


@dataclass
class _Group:
    """One MuJoCo model: some trees' bones, maybe the projectiles."""

    trees: list[int]
    bones: np.ndarray  # global bone indices, in global order
    projectiles: bool
    ground: bool
    model: mujoco.MjModel | None = None
    data: mujoco.MjData | None = None
    body: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    root_body: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    hinge_qpos: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    hinge_dof: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    hinge_jnt: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    jnt_row: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    free_qpos: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    free_dof: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    proj_body: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    proj_qpos: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    proj_dof: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def _cat(trees: list[SimTree], get) -> np.ndarray:
    return np.concatenate([np.asarray(get(t)) for t in trees]) if trees else np.zeros(0)


class ReferenceSolver:
    """Simulate the active trees of a scene in MuJoCo, full 3D.

    `timestep` (s) is rounded so that a frame is a whole number of force
    intervals; `force_rate` (Hz; inf = every step) is how often loads and
    damping are re-evaluated (and held between)."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None, timestep: float | None = None, force_rate: float | None = None):
        self.scene, self.quality, self.loads = scene, quality, loads
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
        self.events: list[tuple[float, int, str]] = []
        self._collect()
        self._joints()
        self._groups()
        self.track_pos = self.track_quat = None

    # ------------------------------------------------------------------
    # construction

    def _collect(self) -> None:
        """The trees' rigs as global bone arrays (trees in order)."""
        trees = self.trees
        self.offsets = np.cumsum([0] + [t.rig.n_bones for t in trees])
        n = self.n = int(self.offsets[-1])
        self.pivot0 = _cat(trees, lambda t: t.rig.pivot).reshape(n, 3)
        self.tip0 = _cat(trees, lambda t: t.rig.tip).reshape(n, 3)
        self.com0 = _cat(trees, lambda t: t.rig.com).reshape(n, 3)
        self.mass = _cat(trees, lambda t: t.rig.mass)
        self.inertia = _cat(trees, lambda t: t.rig.inertia).reshape(n, 3, 3)
        self.radius = _cat(trees, lambda t: t.rig.radius)
        self.alpha = _cat(trees, lambda t: t.rig.alpha)
        self.strength = _cat(trees, lambda t: t.rig.strength)
        self.bone_tree = _cat(trees, lambda t: np.full(t.rig.n_bones, trees.index(t))).astype(int)
        self.parent = np.full(n, -1, dtype=np.int64)
        self.frame = np.full(n, -1, dtype=np.int64)  # limb frame bone, -1 = world
        for ti, t in enumerate(trees):
            o = int(self.offsets[ti])
            rig = t.rig
            self.parent[o:o + rig.n_bones] = np.where(rig.bone_parent >= 0, rig.bone_parent + o, -1)
            limb_frame = np.asarray([limb.parent_bone for limb in rig.limbs], dtype=np.int64)
            f = limb_frame[rig.bone_limb]
            self.frame[o:o + rig.n_bones] = np.where(f >= 0, f + o, -1)
        v = self.tip0 - self.pivot0
        length = np.linalg.norm(v, axis=1)
        self.length = length
        self.axis0 = np.divide(v, length[:, None], out=np.tile([0.0, 0.0, 1.0], (n, 1)),
                               where=length[:, None] > 0)
        self.props = BoneProps(
            mass=self.mass, wood_area=_cat(trees, lambda t: t.rig.wood_area),
            leaf_area=_cat(trees, lambda t: t.rig.leaf_area), diameter=2 * self.radius,
            cd_wood=_cat(trees, lambda t: np.full(t.rig.n_bones, t.rig.drag)),
            cd_leaf=_cat(trees, lambda t: np.full(t.rig.n_bones, t.rig.leaf_drag)))
        self.pulls = []
        for ti, t in enumerate(trees):
            for pull in t.pulls:
                bone = t.rig.stem_bone_at(pull.at) + int(self.offsets[ti])
                self.pulls.append((bone, np.asarray(pull.force, dtype=float), pull.ramp,
                                   pull.release))
        self.paths = [t.rig.model.segment_paths() for t in trees]

    def _joints(self) -> None:
        """Per bone, the two hinges' axes, stiffness, range and spring
        reference (set from gravity once the models exist)."""
        n = self.n
        self.hinge_axis = np.empty((n, 2, 3))
        toward = [None] * n
        for ti, t in enumerate(self.trees):
            if t.cut is not None:
                a = math.radians(t.cut.direction)
                for b in np.nonzero(self.parent[self.offsets[ti]:self.offsets[ti + 1]] < 0)[0]:
                    toward[int(b) + int(self.offsets[ti])] = np.array([math.cos(a), math.sin(a),
                                                                       0.0])
        for b in range(n):
            self.hinge_axis[b] = hinge_axes(self.axis0[b], toward[b])
        k = _cat(self.trees, lambda t: t.rig.k)
        cone = _cat(self.trees, lambda t: t.rig.cone)
        self.k = np.repeat(k[:, None], 2, axis=1)
        self.cone = np.repeat(cone[:, None], 2, axis=1)
        self.springref = np.zeros((n, 2))
        self.attached = np.ones(n, dtype=bool)  # the joint at the bone's base holds
        self.piece_root = np.full(n, -1, dtype=np.int64)  # first bone of a free part, -1
        self.breakable = np.isfinite(self.strength)
        self.cut_state = ["standing" if t.cut is not None else "" for t in self.trees]
        self.still_time = np.zeros(len(self.trees))
        self.settled = np.zeros(len(self.trees), dtype=bool)
        # bones whose rest capsule reaches into the ground do not touch it while standing
        ratio = _cat(self.trees, lambda t: np.full(t.rig.n_bones, t.rig.options.bone_ratio))
        mid = 0.5 * (self.pivot0 + self.tip0)
        half = (0.5 * ratio * self.length)[:, None] * self.axis0
        low = np.minimum((mid - half)[:, 2], (mid + half)[:, 2]) - self.radius
        self.in_ground = low < 0.0

    def _groups(self) -> None:
        """Which trees share a model, then build them all; spring references
        from the gravity torques at rest (prestress)."""
        scene = self.scene
        projectiles = bool(scene.projectiles)
        shared: list[int] = []
        if projectiles:
            from ..pipeline import _projectile_reaches

            shared = [ti for ti, t in enumerate(self.trees)
                      if _projectile_reaches(scene, t.rig.model)]
        self.groups: list[_Group] = []
        falls = bool(scene.projectiles) or any(t.cut is not None for t in self.trees)
        for ti in range(len(self.trees)):
            if ti in shared:
                continue
            bones = np.arange(self.offsets[ti], self.offsets[ti + 1])
            ground = scene.ground and (falls or bool(self.breakable[bones].any()))
            self.groups.append(_Group([ti], bones, False, ground))
        if projectiles:
            bones = np.concatenate([np.arange(self.offsets[ti], self.offsets[ti + 1])
                                    for ti in shared] + [np.zeros(0, dtype=np.int64)])
            self.groups.append(_Group(shared, bones.astype(np.int64), True, scene.ground))
        self.group_of_tree = np.zeros(len(self.trees), dtype=np.int64)
        for gi, g in enumerate(self.groups):
            self.group_of_tree[g.trees] = gi
        for g in self.groups:
            self._compile(g)
        if scene.prestress:
            for g in self.groups:
                self._prestress(g)
        self.stats.models = len(self.groups)
        self.stats.bodies = sum(g.model.nbody - 1 for g in self.groups)

    def _compile(self, g: _Group) -> None:
        """Build (or rebuild, carrying the state over) a group's model."""
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
                           contype=2, conaffinity=1, condim=6,
                           friction=[FRICTION, 0.005, ROLLING])
        bodies: dict[int, mujoco.MjsBody] = {}
        for b in g.bones.tolist():
            p = int(self.parent[b])
            held = self.attached[b] and p >= 0
            parent = bodies[p] if held else world
            pos = self.pivot0[b] - (self.pivot0[p] if held else 0.0)
            body = parent.add_body(name=f"b{b}", pos=pos)
            body.explicitinertial = True
            body.mass = float(self.mass[b])
            body.ipos = self.com0[b] - self.pivot0[b]
            i = self.inertia[b] if self.attached[b] else floored_inertia(self.inertia[b])
            body.fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
            if self.attached[b]:
                for k in range(2):
                    limited = math.isfinite(self.cone[b, k])
                    body.add_joint(
                        name=f"j{b}_{k}", type=mujoco.mjtJoint.mjJNT_HINGE,
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
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                          fromto=np.concatenate([lo * v, hi * v]),
                          size=[max(float(self.radius[b]), 1e-4), 0, 0],
                          contype=1 if collide else 0, conaffinity=0, condim=6,
                          friction=[FRICTION, 0.005, ROLLING])
            if g.ground and self.in_ground[b] and self._standing(b):
                spec.add_exclude(bodyname1="world", bodyname2=f"b{b}")
            bodies[b] = body
        if g.projectiles:
            for i, pr in enumerate(self.scene.projectiles):
                body = world.add_body(name=f"p{i}", pos=pr.position)
                body.explicitinertial = True
                body.mass = pr.mass
                moment = pr.mass * pr.size**2 / 6 if pr.shape == "box" else \
                    0.4 * pr.mass * (pr.size / 2) ** 2
                body.fullinertia = [moment, moment, moment, 0, 0, 0]
                body.add_freejoint(name=f"pf{i}")
                body.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_BOX if pr.shape == "box"
                    else mujoco.mjtGeom.mjGEOM_SPHERE,
                    size=[pr.size / 2] * 3, contype=2, conaffinity=3, priority=1, condim=6,
                    friction=[pr.friction, 0.005, ROLLING],
                    solref=[max(PROJECTILE_TIMECONST, 2 * self.h),
                            restitution_damping(pr.restitution)])
        model = spec.compile()
        data = mujoco.MjData(model)
        old = (g.model, g.data, g.body.copy(), g.hinge_qpos.copy(), g.hinge_dof.copy(),
               g.free_qpos.copy(), g.free_dof.copy(), g.proj_qpos.copy(), g.proj_dof.copy())
        g.model, g.data = model, data
        self._index(g)
        if old[0] is not None:
            self._transfer(g, *old)
        self.timing["compile_seconds"] += time.perf_counter() - t0

    def _standing(self, b: int) -> bool:
        """The bone's tree still stands on all its roots."""
        ti = int(self.bone_tree[b])
        sl = slice(int(self.offsets[ti]), int(self.offsets[ti + 1]))
        roots = self.parent[sl] < 0
        return bool(self.attached[sl][roots].all())

    def _index(self, g: _Group) -> None:
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
        has = g.hinge_jnt >= 0
        g.hinge_qpos = np.where(has, m.jnt_qposadr[np.maximum(g.hinge_jnt, 0)], -1)
        g.hinge_dof = np.where(has, m.jnt_dofadr[np.maximum(g.hinge_jnt, 0)], -1)
        g.jnt_row = np.full(m.njnt, -1, dtype=np.int64)  # joint -> row * 2 + hinge
        rows = np.nonzero(has)
        g.jnt_row[g.hinge_jnt[rows]] = rows[0] * 2 + rows[1]
        if g.projectiles:
            p = len(self.scene.projectiles)
            g.proj_body = np.asarray([m.body(f"p{i}").id for i in range(p)], dtype=np.int64)
            jnt = [m.joint(f"pf{i}").id for i in range(p)]
            g.proj_qpos = m.jnt_qposadr[jnt].astype(np.int64)
            g.proj_dof = m.jnt_dofadr[jnt].astype(np.int64)

    def _transfer(self, g: _Group, model, data, body, hinge_qpos, hinge_dof, free_qpos,
                  free_dof, proj_qpos, proj_dof) -> None:
        """Carry the state of the old model (kinematics and velocities
        current) over to the new one: hinges by value, newly freed bones
        from their bodies' poses and velocities."""
        d = g.data
        d.time = data.time
        keep = (g.hinge_qpos >= 0) & (hinge_qpos >= 0)
        d.qpos[g.hinge_qpos[keep]] = data.qpos[hinge_qpos[keep]]
        d.qvel[g.hinge_dof[keep]] = data.qvel[hinge_dof[keep]]
        res = np.zeros(6)
        for i in np.nonzero(g.free_qpos >= 0)[0]:
            q, v = g.free_qpos[i], g.free_dof[i]
            if free_qpos[i] >= 0:
                d.qpos[q:q + 7] = data.qpos[free_qpos[i]:free_qpos[i] + 7]
                d.qvel[v:v + 6] = data.qvel[free_dof[i]:free_dof[i] + 6]
                continue
            d.qpos[q:q + 3] = data.xpos[body[i]]
            d.qpos[q + 3:q + 7] = data.xquat[body[i]]
            mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, int(body[i]), res, 0)
            d.qvel[v:v + 3] = res[3:]
            d.qvel[v + 3:v + 6] = data.xmat[body[i]].reshape(3, 3).T @ res[:3]
        for q_new, v_new, q_old, v_old in zip(g.proj_qpos, g.proj_dof, proj_qpos, proj_dof):
            d.qpos[q_new:q_new + 7] = data.qpos[q_old:q_old + 7]
            d.qvel[v_new:v_new + 6] = data.qvel[v_old:v_old + 6]

    def _prestress(self, g: _Group) -> None:
        """Spring references that make the rest pose the static equilibrium
        under gravity: k (0 - ref) + bias = 0 at q = 0, v = 0."""
        m, d = g.model, g.data
        mujoco.mj_forward(m, d)
        has = g.hinge_dof >= 0
        bias = np.where(has, d.qfrc_bias[np.maximum(g.hinge_dof, 0)], 0.0)
        k = self.k[g.bones]
        ref = np.divide(bias, k, out=np.zeros_like(bias), where=k > 0)
        self.springref[g.bones] = ref
        m.qpos_spring[g.hinge_qpos[has]] = ref[has]
        mujoco.mj_resetData(m, d)

    # ------------------------------------------------------------------
    # state and loads

    def _read(self) -> None:
        """COM position and velocity, angular velocity and rotation of every
        bone, from each model's current kinematics (after mj_step1). The
        state arrays have an extra zero row: the world, as a frame."""
        for g in self.groups:
            self._read_group(g)

    def _read_group(self, g: _Group) -> None:
        d, b, rows = g.data, g.body, g.bones
        com = d.xipos[b]
        cv = d.cvel[b]
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
        warned = any(g.data.warning[w].number > 0 for g in self.groups for w in BAD)
        if not bad.any() and not warned:
            return
        bone = int(np.nonzero(bad)[0][0]) if bad.any() else 0
        tree, seg = self.locate(bone)
        what = (f"angular speed {math.sqrt(spin[bone]):.0f} rad/s > {MAX_ANGULAR_SPEED:.0f}"
                if np.isfinite(spin[bone]) and bad.any() else "non-finite state")
        raise SimulationError(f"{what} (unstable; try a smaller timestep)", tree, seg, t)

    def _clamp_spin(self) -> None:
        """Clamp the spin of free parts at MAX_SPIN (as the planar LOD's
        debris): a stick rolled under a sliding box would spin without
        bound. Counted in stats.clamped."""
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

    def pull_forces(self, t: float) -> np.ndarray | None:
        """World force (N) of the pulls acting at time t on each bone, or None."""
        active = [(b, f, ramp) for b, f, ramp, release in self.pulls if t < release]
        if not active:
            return None
        out = np.zeros((self.n, 3))
        for b, f, ramp in active:
            out[b] += f * (min(1.0, t / ramp) if ramp > 0 else 1.0)
        return out

    def _external(self, t: float) -> np.ndarray:
        """Air, blasts, attractors and pulls (N, world, at the COMs), capped
        at MAX_ACCELERATION x mass; gravity is MuJoCo's."""
        n = self.n
        axis = np.einsum("bij,bj->bi", self.rot, self.axis0)
        force = self.loads.forces(t, self.com[:n], self.vcom[:n], axis, self.props,
                                  include_gravity=False, dt=self.dt_force)
        pulls = self.pull_forces(t)
        if pulls is not None:
            force += pulls
        acc = np.linalg.norm(force, axis=1) / np.maximum(self.mass, 1e-9)
        over = acc > MAX_ACCELERATION
        if over.any():
            idx = np.nonzero(over)[0]
            if not self.stats.limited:
                tree, seg = self.locate(int(idx[0]))
                self.stats.first_limit = (tree, seg, round(t, 4), round(float(acc[idx[0]]), 1))
            self.stats.limited += len(idx)
            force[idx] *= (MAX_ACCELERATION / acc[idx])[:, None]
        return force

    def _damping(self, wrench: np.ndarray) -> None:
        """Add the mass-proportional structural damping to `wrench` (n + 1,
        6: force, torque about the COM, world): on each bone's motion
        relative to its frame bone, with the reaction on the frame bone."""
        n = self.n
        fi = self.frame_row
        com, w = self.com[:n], self.omega[:n]
        wf = self.omega[fi]
        arm = com - self.com[fi]
        w_rel = w - wf
        v_rel = self.vcom[:n] - self.vcom[fi] - cross(wf, arm)
        rot = self.rot
        local = np.einsum("bji,bj->bi", rot, w_rel)
        iw = np.einsum("bij,bj->bi", rot, np.einsum("bij,bj->bi", self.inertia, local))
        own = np.empty((n, 6))
        own[:, :3] = -self.damp_mass[:, None] * v_rel
        own[:, 3:] = -self.damp[:, None] * iw
        wrench[:n] += own
        react = -own
        react[:, 3:] -= cross(arm, own[:, :3])
        np.add.at(wrench, fi, react)

    # ------------------------------------------------------------------
    # events

    def _moments(self, g: _Group) -> np.ndarray:
        """Bending moment (N m) at each of the group's joints: the hinge
        springs plus the limit constraint forces (0 where detached)."""
        d = g.data
        has = g.hinge_qpos >= 0
        q = np.where(has, d.qpos[np.maximum(g.hinge_qpos, 0)], 0.0)
        torque = np.where(has, -self.k[g.bones] * (q - self.springref[g.bones]), 0.0)
        rows = np.nonzero(d.efc_type == LIMIT)[0]
        if len(rows):
            slot = g.jnt_row[d.efc_id[rows]]
            flat = torque.reshape(-1)
            np.add.at(flat, slot, -np.sign(q.reshape(-1)[slot]) * d.efc_force[rows])
        return np.sqrt((torque * torque).sum(1))

    def _events(self, t: float) -> list[_Group]:
        """Cuts, hinge snaps and breaks at time t; returns the groups whose
        model was rebuilt (their state must be read again)."""
        changed: set[int] = set()
        for ti, tree in enumerate(self.trees):
            state = self.cut_state[ti]
            if not state or state == "falling":
                continue
            g = self.groups[self.group_of_tree[ti]]
            roots = self._roots(ti)
            rows = np.searchsorted(g.bones, roots)
            if state == "standing" and t >= tree.cut.time:
                m, d = g.model, g.data
                for r, b in zip(rows, roots):
                    j = g.hinge_jnt[r, 0]
                    self.k[b, 0] = 0.0
                    self.cone[b, 0] = math.inf
                    m.jnt_stiffness[j] = 0.0
                    m.jnt_limited[j] = 0
                    d.qvel[g.hinge_dof[r, 0]] += NUDGE
                    self.breakable[b] = False
                    self._reframe(int(b))
                self.cut_state[ti] = "hinged"
                self.events.append((t, ti, "cut at the base"))
            elif state == "hinged":
                lean = g.data.qpos[g.hinge_qpos[rows, 0]]
                if lean.max() > math.radians(tree.cut.hinge):
                    self.attached[roots] = False
                    self.cut_state[ti] = "falling"
                    self.events.append((t, ti, "hinge snapped"))
                    changed.add(int(self.group_of_tree[ti]))
        for gi, g in enumerate(self.groups):
            cand = self.breakable[g.bones] & self.attached[g.bones]
            if not cand.any():
                continue
            moment = self._moments(g)
            over = np.nonzero(cand & (moment > self.strength[g.bones]))[0]
            for i in over:
                b = int(g.bones[i])
                self.attached[b] = False
                self.breakable[b] = False
                self._reframe(b)
                ti, seg = int(self.bone_tree[b]), self.locate(b)[1]
                why = (f"{self.paths[ti][seg]}: broke ({moment[i]:.0f} N m > strength "
                       f"{self.strength[b]:.0f} N m)")
                self.events.append((t, ti, why))
                self.stats.broken += 1
                changed.add(gi)
        out = []
        for gi in sorted(changed):
            g = self.groups[gi]
            self._compile(g)
            self.stats.rebuilds += 1
            mujoco.mj_step1(g.model, g.data)
            self._read_group(g)
            out.append(g)
        return out

    def _roots(self, ti: int) -> np.ndarray:
        sl = np.arange(self.offsets[ti], self.offsets[ti + 1])
        return sl[self.parent[sl] < 0]

    def _reframe(self, bone: int) -> None:
        """The joint at `bone`'s base is going: the bone and everything it
        carries are damped relative to the bone (not the world, nor a frame
        they no longer hang on), so their rigid motion is not damped."""
        piece = self._outboard(bone)
        outside = piece & ((self.frame < 0) | ~piece[np.maximum(self.frame, 0)])
        self.frame[outside] = bone
        self._update_decay()
        for b in range(self.n):  # parents precede children
            p = self.parent[b]
            self.piece_root[b] = b if not self.attached[b] else \
                (self.piece_root[p] if p >= 0 else -1)

    def _outboard(self, bone: int) -> np.ndarray:
        out = np.zeros(self.n, dtype=bool)
        out[bone] = True
        for b in range(bone + 1, self.n):  # parents precede children
            p = self.parent[b]
            if p >= 0 and out[p] and self.attached[b]:
                out[b] = True
        return out

    def _update_decay(self) -> None:
        """Damping coefficient per bone as an exact decay over a force
        interval (1/s); zero for a bone that is its own frame."""
        decay = -np.expm1(-self.alpha * self.dt_force) / self.dt_force
        self.damp = np.where(self.frame == np.arange(self.n), 0.0, decay)
        self.damp_mass = self.damp * self.mass
        self.frame_row = np.where(self.frame >= 0, self.frame, self.n)

    def _settle(self, t: float, dt: float) -> None:
        """A tree off its roots that has lain still for SETTLE_TIME is at rest."""
        for ti in range(len(self.trees)):
            roots = self._roots(ti)
            if self.settled[ti] or self.attached[roots].all():
                continue
            sl = slice(int(self.offsets[ti]), int(self.offsets[ti + 1]))
            speed = max(np.abs(self.vcom[sl]).max(), np.abs(self.omega[sl]).max())
            self.still_time[ti] = self.still_time[ti] + dt if speed < SETTLE_SPEED else 0.0
            if self.still_time[ti] > SETTLE_TIME:
                self.settled[ti] = True
                self.events.append((t, ti, "came to rest on the ground"))

    # ------------------------------------------------------------------
    # running

    def run(self, progress=None) -> list[TreeMotion]:
        """Simulate the scene; per active tree, the bones' motion at every frame."""
        scene = self.scene
        frames = scene.frame_count
        n = self.n
        quats = np.zeros((frames, n, 4))
        pivots = np.zeros((frames, n, 3))
        self.com, self.vcom, self.omega = (np.zeros((n + 1, 3)) for _ in range(3))
        self.rot = np.zeros((n, 3, 3))
        self._update_decay()
        proj = next((g for g in self.groups if g.projectiles), None)
        n_proj = len(scene.projectiles) if proj is not None else 0
        self.track_pos = np.zeros((frames, n_proj, 3))
        self.track_quat = np.zeros((frames, n_proj, 4))
        launched = np.zeros(n_proj, dtype=bool)
        damped = bool((self.alpha > 0).any())
        wrench = np.zeros((n + 1, 6))
        steps = (frames - 1) * self.spf
        for step in range(steps + 1):
            t = step * self.h
            t0 = time.perf_counter()
            if n_proj and not launched.all():
                self._projectiles(proj, t, launched)
            if step % self.force_every:
                for g in self.groups:
                    mujoco.mj_step(g.model, g.data)
                self.timing["step_seconds"] += time.perf_counter() - t0
                self.stats.steps += 1
                continue
            for g in self.groups:
                mujoco.mj_step1(g.model, g.data)
            t1 = time.perf_counter()
            self._read()
            self._check(t)
            if step % self.spf == 0:
                f = step // self.spf
                self._record(f, quats, pivots)
                if proj is not None:
                    self.track_pos[f] = proj.data.xpos[proj.proj_body]
                    self.track_quat[f] = proj.data.xquat[proj.proj_body][:, [1, 2, 3, 0]]
                if f > 0:
                    self._settle(t, 1.0 / scene.fps)
                    if progress is not None:
                        progress(f, frames - 1)
                if step == steps:
                    break
            if self._events(t):
                self._check(t)
            if self.stats.rebuilds:
                self._clamp_spin()
            wrench[:] = 0.0
            wrench[:n, :3] = self._external(t)
            if damped:
                self._damping(wrench)
            for g in self.groups:
                g.data.xfrc_applied[g.body] = wrench[g.bones]
            self.stats.updates += 1
            t2 = time.perf_counter()
            for g in self.groups:
                mujoco.mj_step2(g.model, g.data)
            t3 = time.perf_counter()
            self.timing["update_seconds"] += t2 - t1
            self.timing["step_seconds"] += (t1 - t0) + (t3 - t2)
            self.stats.steps += 1
        out = []
        for ti, tree in enumerate(self.trees):
            a, b = self.offsets[ti], self.offsets[ti + 1]
            events = [f"t = {et:.3f} s: {msg}" for et, i, msg in self.events if i == ti]
            out.append(TreeMotion(quats[:, a:b], pivots[:, a:b], events))
        return out

    def _record(self, f: int, quats: np.ndarray, pivots: np.ndarray) -> None:
        for g in self.groups:
            q = g.data.xquat[g.body][:, [1, 2, 3, 0]]
            q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
            quats[f, g.bones] = q
            pivots[f, g.bones] = g.data.xpos[g.body]

    def _projectiles(self, g: _Group, t: float, launched: np.ndarray) -> None:
        """Hold projectiles still until their launch time, then throw them."""
        d = g.data
        for i, pr in enumerate(self.scene.projectiles):
            if launched[i]:
                continue
            q, v = g.proj_qpos[i], g.proj_dof[i]
            d.qpos[q:q + 7] = [*pr.position, 1.0, 0.0, 0.0, 0.0]
            d.qvel[v:v + 6] = 0.0
            if t >= pr.time:
                d.qvel[v:v + 3] = pr.velocity
                launched[i] = True

    # ------------------------------------------------------------------
    # reporting

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index (in that tree) of a global bone."""
        ti = int(self.bone_tree[bone])
        tree = self.trees[ti]
        local = bone - int(self.offsets[ti])
        return tree.name, int(np.nonzero(tree.rig.seg_bone == local)[0][0])

    def objects(self) -> ObjectsBake | None:
        """Projectile tracks, after run()."""
        if not self.scene.projectiles or self.track_pos is None:
            return None
        p = self.scene.projectiles
        return ObjectsBake([x.shape for x in p], np.asarray([x.size for x in p]),
                           self.track_pos, self.track_quat)

    def meta(self) -> dict:
        """Settings, counts and notes for the bake's metadata (deterministic)."""
        f1 = max((t.rig.first_frequency for t in self.trees), default=0.0)
        st = self.stats
        notes = [(f"reference: MuJoCo {mujoco.__version__}, discrete (stiffness-implicit) "
                  f"integrator, h = {self.h * 1e3:.4g} ms, loads every "
                  f"{self.dt_force * 1e3:.4g} ms: numerical damping adds about "
                  f"{math.pi * f1 * self.h:.2g} to the damping ratio of a {f1:.3g} Hz mode"),
                 ("reference: joints are two perpendicular hinges (no twist); the cone limit "
                  "is a square in the two swing angles; bones of different trees do not collide")]
        if st.limited:
            tree, seg, t, acc = st.first_limit
            notes.append(f"loads capped at {MAX_ACCELERATION:.0f} m/s^2 on {st.limited} bone "
                         f"updates (first: tree {tree!r}, segment {seg}, t = {t:.3f} s, "
                         f"{acc:.0f} m/s^2)")
        if st.broken:
            notes.append(f"{st.broken} joints broke; the parts fell on as free bodies")
        if st.clamped:
            notes.append(f"free parts' spin clamped at {MAX_SPIN:.0f} rad/s on {st.clamped} "
                         "body updates")
        stats = {"steps": st.steps, "updates": st.updates, "models": st.models,
                 "bodies": st.bodies, "bones": self.n, "rebuilds": st.rebuilds,
                 "limited": st.limited, "broken": st.broken, "clamped": st.clamped}
        return {"substep": self.h, "force_interval": self.dt_force,
                "integrator": "discrete", "stats": stats, "notes": notes}
