"""The full-3D reference: the rig in MuJoCo, to measure the planar LOD's
error and to give users the slow, accurate answer.

Model (one MuJoCo model per tree, stepped side by side: compile time grows
faster than linearly with the bodies in a model; trees a projectile can
reach share one model with the projectiles):

- One body per bone, nested as the rig's bones are. A body's frame sits at
  the bone's pivot with the world's orientation at rest, so its pose *is*
  the bake's (rotation relative to rest, pivot position). Mass, COM and the
  full inertia tensor are the rig's, set explicitly (never from geoms).
- The joint at a bone's base: two hinges at the pivot, both perpendicular to
  the bone's axis (swing without twist), each with the rig's stiffness k and
  range +-cone (so the cone is a square of side 2 cone in the two swing
  angles, not a circle). With `prestress`, spring references make the grown
  shape the static equilibrium under gravity: ref = (gravity torque at
  rest, MuJoCo's qfrc_bias) / k; a calm tree stays still to 1e-19 m.
- A capsule per bone, `bone_ratio` x its length, centred on it. It collides
  with the ground and projectiles (never with other bones) only when the
  scene has a ground and something can fall (projectiles, a cut, breakable
  joints); otherwise contacts are off. A capsule that reaches into the
  ground at rest never touches it (a stem's base, freed by felling or
  uprooting, would start deep in it and be thrown out: the energy audit's
  largest gain); a sphere of at most BASE_SPHERE resting on the ground at
  its lower end holds that end up instead (without it a felled oak's base
  went 0.43 m into the ground). Contacts have rolling friction (ROLLING):
  soft ground stops rolling sticks and balls.
- Gravity is MuJoCo's (the same vector as SceneLoads.g). Air, blasts,
  attractors and pulls (as the planar LOD's `pull_forces`) are world forces
  at the bones' COMs (`xfrc_applied`), evaluated at `force_rate` (500 Hz;
  drag and gusts change far slower; a blast's pulse is integrated exactly
  over the interval by SceneLoads, its rate capped at MAX_ACCELERATION x
  mass and the rest of its impulse delivered after) and held between (while
  a blast splits a model's step to BLAST_STEP, every substep); other
  loads capped at MAX_ACCELERATION x mass as in the planar LOD, and counted.
- Structural damping: the rig's mass-proportional damping of each bone's
  motion relative to its limb's frame (the bone the limb hangs on; the
  world for root limbs), with what the limb carries moving with it, as in
  the planar LOD's lumped bodies and in the Rayleigh quotient behind
  rig.alpha: in joint space, each limb's joints get -alpha M_LL qdot_L, with
  M_LL the limb's block of MuJoCo's mass matrix (its bones and all they
  carry, at the current pose) and qdot_L its own joint rates; alpha is
  replaced by (1 - exp(-alpha h)) / h (an exact decay over a step). Joint
  torques act on the frame bone too (reaction), and M_LL is positive
  definite, so the damping only ever removes energy. Applied every step as
  qfrc_applied (explicit; a Cartesian version held over 2 ms went unstable
  on a willow's light twigs carrying heavy curtains). On a model with free
  parts (broken off, uprooted, felled) the frame of a part's limbs gives
  way and its hinges move far less mass than M_LL: there the force is
  scaled down, when it must be, to the most a step can remove without
  overshoot (_stable_scale; counted); an uprooted palm in the hurricane
  had gained 1.7x its energy and broken apart before. Pulled and released
  in still air, the first-mode damping ratios come out near the grammars'
  (sapling 0.086, palm 0.081, oak 0.076 for 0.08, 0.08, 0.10; planar LOD
  0.090, 0.088, 0.120), frequencies within 1.2 % of the planar LOD's.

Integrator, measured on the 10 m x 0.2 m cantilever (E = 8 GPa, rho = 800
kg/m^3, 30 bones, no gravity, released from its static deflection under a
tip load; beam f1 = 0.8848 Hz; zeta = damping ratio of the free decay, all
of it numerical; MuJoCo's cost per body-step on this machine, one model):

    integrator     joint damping   h                f1 error   zeta    us/body-step
    euler          0               1/240 .. 1/4000  unstable
    implicitfast   0               1/240 .. 1/4000  unstable
    implicit       0               1/240 .. 1/4000  unstable
    rk4            0               1/240 .. 1/2000  unstable
    rk4            0               1/4000           -0.11 %    0.0001  3.5
    euler          k h / 2         1/240            -0.06 %    0.0049  1.1-1.3
    implicitfast   k h / 2         1/240            -0.06 %    0.0049  1.1-1.3
    implicit       k h / 2         1/240            -0.06 %    0.0049  7-9
    discrete       0               1/240            -0.01 %    0.0104  1.1-1.8
    discrete       0               1/480            -0.06 %    0.0049  1.1
    discrete       0               1/1000           -0.09 %    0.0022  1.1-1.4
    discrete       0               1/2000           -0.11 %    0.0011  1.0-1.3
    discrete       0               1/4000           -0.11 %    0.0007  0.9-1.1

(-0.11 % is the 30-bone chain's own error against the beam.) Only
`discrete` (the constraint solve and the velocity update in the metric
M + hD + h^2 K, i.e. implicit in the joint stiffness) is stable at wood
stiffness with no added damping; the others need joint damping c >= k h / 2,
a stiffness-proportional damping the rig does not have. Every stable choice
holds f1 within 0.15 % even at 1/240 s, so the step is set by the numerical
damping, zeta ~ pi f1 h for `discrete`: DEFAULT_TIMESTEP = 1/2000 s keeps it
near 0.001 at f1 ~ 1 Hz, small against trees' 0.05-0.3 (design.md); meta()
states it for each run, and TIMESTEPS lists coarser steps for the error-vs-
cost report. With the structural damping (zeta = 0.05) the cantilever decays
at 0.0518, and f1 moves by under 0.05 % for load rates from 240 Hz to every
step.

Cost (this machine, breeze with gusts, 1/2000 s steps, loads at 500 Hz, per
body-step): MuJoCo 1.1-1.7 us, the Python side (loads, damping, events)
0.5-1.9 us, falling with tree size: sapling (57 bones) 3.0 us in all, palm
(89) 3.3, oak (424) 2.1, spruce (506) 1.8, willow (1444, 12 breaks) 2.1;
about twice the planar LOD's wall time on the same pull-and-release scenes.
Models are stepped one after another in one thread, so results cannot
depend on timing: the same inputs give bit-identical bakes.

Events: felling removes the spring and limit of the cut root joint's
felling-direction hinge (the sideways hinge holds, like hinge wood) and
nudges the tree over; past `hinge` degrees of lean the root joint goes and
the tree falls free onto the ground. A joint whose bending moment (hinge
springs plus limit constraint forces) exceeds its `strength` breaks: the
bone and all it carries become a free part (a snapped branch, or an
uprooted tree). A part broken off a standing tree moves to that tree's
debris model (rebuilt; it is small) while its bodies stay in the tree's
model massless, frozen and inert, so a big tree is never recompiled for a
twig; a felled or uprooted tree, or a scene with projectiles, rebuilds its
model. Poses and velocities carry over exactly (1e-14). A free part's own
motion (its first bone's free joint) and a cut tree's felling hinge are not
damped, only their bending; a free part's first bone has its principal
moments of inertia floored at MIN_INERTIA_RATIO of the
largest, and a free part's spin is clamped at MAX_SPIN (counted), as the
planar LOD's debris: a thin stick would otherwise roll without bound (a
stick rolled under a sliding box). Where a free part spins faster than
SPIN_PER_STEP per step, its model's step is split into up to MAX_SUBSTEPS
(loads and damping held): stiff broken limbs rolling on the ground at
40-70 rad/s gained energy without bound at h = 2.1 ms, none at h/2. The
audit counts a free body's spin with the floored inertia its model has.
Bones of a free part are checked against
MAX_ANGULAR_SPEED relative to the part's first bone. Not modelled:
collisions between bones (of one tree or of different trees); projectiles'
air drag. Projectiles do collide with each other (the planar LOD's don't).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field, fields

import mujoco
import numpy as np

from ..bake import ObjectsBake
from ..errors import SimulationError
from ..rotations import cross
from ..scene import Scene
from .audit import Ledger, LoadWork, bone_energy, per_tree
from .common import (
    MAX_ANGULAR_SPEED,
    Bones,
    SimTree,
    TreeMotion,
    cap_loads,
    cap_note,
    locate,
    sub_frame_samples,
)
from .contact import FRICTION
from .debris import MAX_SPIN, MIN_INERTIA_RATIO
from .events import AT_REST, BROKE, CUT, HINGE, TIER, UPROOTED, Event
from .linear import BLAST_RING, BLAST_STEP, RETURN_DETAIL, RETURN_WINDOW, in_return_range
from .loads import SceneLoads, meets
from .projectiles import projectile_reaches
from .quality import Quality
from .solver import SolveResult, frame_timing

DEFAULT_TIMESTEP = 1 / 2000  # s
DEFAULT_FORCE_RATE = 500.0  # Hz
TIMESTEPS = {"fine": 1 / 4000, "default": 1 / 2000, "coarse": 1 / 1000, "draft": 1 / 480}
NUDGE = 0.05  # rad/s, the felling push at the cut
SETTLE_SPEED = 0.05  # m/s and rad/s: a fallen tree slower than this for SETTLE_TIME is at rest
SETTLE_TIME = 0.5  # s
TWIG_HZ = 50.0  # a twig's ringing under a blast front (the blast note's example)
SPIN_PER_STEP = 0.05  # rad: most a free part turns in one step (more: the step is split)
MAX_SUBSTEPS = 8
PROJECTILE_TIMECONST = 0.005  # s, contact stiffness of projectiles (MuJoCo solref)
ROLLING = 0.01  # m, rolling friction (torque / normal force): soft ground stops rolling
IN_GROUND = 4  # contype of a capsule in the ground at rest: projectiles hit it, the ground not
BASE_SPHERE = 0.01  # m: the most radius of the sphere that holds a buried capsule's lower end up
LIMIT = int(mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT)
XBODY = mujoco.mjtObj.mjOBJ_XBODY  # a body's frame (mjOBJ_BODY is its COM frame)
BAD = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
       mujoco.mjtWarning.mjWARN_BADQPOS)


def floored_inertia(inertia: np.ndarray) -> np.ndarray:
    """An inertia tensor (kg m^2) with its principal moments floored at
    MIN_INERTIA_RATIO of the largest, as the planar LOD's debris: a free
    thin stick would otherwise spin (roll) without bound about its own axis."""
    lam, vec = np.linalg.eigh(inertia)
    lam = np.maximum(lam, MIN_INERTIA_RATIO * lam[-1])
    return (vec * lam) @ vec.T


FREE_PART_COUNTS = ("broken", "clamped", "split", "damping_scaled", "blast_split")


def free_part_notes(stats: dict) -> list[str]:
    """The notes on breaks and on what free parts needed, from one run's
    `stats` or the sums of several runs' (the planar LOD's hand-overs)."""
    notes = []
    if stats["broken"]:
        joints = "joint" if stats["broken"] == 1 else "joints"
        notes.append(f"{stats['broken']} {joints} broke; the parts fell on as free bodies")
    if stats["clamped"]:
        notes.append(f"free parts' spin clamped at {MAX_SPIN:.0f} rad/s on {stats['clamped']} "
                     "body updates")
    if stats["split"]:
        notes.append(f"steps split in up to {MAX_SUBSTEPS} where free parts spun faster than "
                     f"{SPIN_PER_STEP:g} rad per step, on {stats['split']} model-steps")
    if stats.get("blast_split"):
        notes.append(f"steps split to at most {BLAST_STEP * 1e3:.4g} ms while a blast pushed or "
                     f"its twigs rang (until {BLAST_RING:g} s after its push), on "
                     f"{stats['blast_split']} model-steps")
    if stats["damping_scaled"]:
        notes.append(f"structural damping of free parts scaled down on "
                     f"{stats['damping_scaled']} steps, to what an explicit step can remove "
                     "without overshoot")
    return notes


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


@dataclass
class _Group:
    """One MuJoCo model: some trees' bones, maybe the projectiles."""

    trees: list[int]
    bones: np.ndarray  # global bone indices, in global order
    projectiles: bool
    ground: bool
    debris: bool = False  # parts broken off a tree
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
    # structural damping: entries (row dof, column dof, address in d.M, rate)
    # of each limb's block of the mass matrix, diagonal and below
    damp_row: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    damp_col: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    damp_adr: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    damp_alpha: np.ndarray = field(default_factory=lambda: np.zeros(0))  # 1/s
    # 1/s: alpha as an exact decay over damp_hold, the time (s) one evaluation
    # of the damping is held: the solver's step, or a substep while a blast rings
    damp_rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    damp_hold: float = 0.0
    damp_below: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    has_free: bool = False  # some bone is a free part's first (its damping is kept stable)
    substeps: int = 1  # MuJoCo steps per solver step (fast-spinning free parts, blasts)
    # a blast splits the step: loads and damping are worked out every substep (_blast_step)
    blast: bool = False
    # while a blast splits the step: each joint's largest bending moment (N m)
    # over the MuJoCo steps since the last break check, for the closest-to-
    # breaking record (a joint past its strength there is released at once,
    # _release; None: not tracked)
    peak: np.ndarray | None = None


class ReferenceSolver:
    """Simulate the active trees of a scene in MuJoCo, full 3D.

    `timestep` (s, default DEFAULT_TIMESTEP; TIMESTEPS for the accuracy
    report) is rounded so that a frame is a whole number of force
    intervals; `force_rate` (Hz, default DEFAULT_FORCE_RATE; inf = every
    step) is how often the loads are evaluated (damping is every MuJoCo
    step). A model's step is split to at most BLAST_STEP while a blast
    pushes its trees and their twigs ring (BLAST_RING). `quality` is the planar LOD's
    and only recorded: the rig's bones are already merged by it
    (bone_length)."""

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
        self.events: list[Event] = []
        self._collect()
        # MuJoCo steps per step while a blast pushes or rings (BLAST_RING),
        # and when, per tree (s)
        self.blast_split = max(1, math.ceil(self.h / BLAST_STEP - 1e-9))
        tree_bones = [slice(self.offsets[ti], self.offsets[ti + 1])
                      for ti in range(len(self.trees))]
        self.blast_windows = [self.loads.blast_windows(self.com0[b], self.axis0[b],
                                                       self.props.take(b))
                              for b in tree_bones] if self.blast_split > 1 else []
        self._joints()
        self._groups()
        self.track_pos = self.track_quat = None

    # ------------------------------------------------------------------
    # construction

    def _collect(self) -> None:
        """The trees' rigs as global bone arrays (sim/common.py's Bones)."""
        trees = self.trees
        self.bones = Bones.of(trees)
        for f in fields(Bones):
            setattr(self, f.name, getattr(self.bones, f.name))
        n = self.n = self.bones.n
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
        reference (set from gravity once the models exist)."""
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
        self.cut_state = ["standing" if t.cut is not None else "" for t in self.trees]
        self.still_time = np.zeros(len(self.trees))
        self.settled = np.zeros(len(self.trees), dtype=bool)
        # bones whose rest capsule reaches into the ground do not touch it while standing
        ratio = np.repeat([t.rig.options.bone_ratio for t in self.trees],
                          [t.rig.n_bones for t in self.trees])
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
            shared = [ti for ti, t in enumerate(self.trees)
                      if projectile_reaches(scene, t.rig.model)]
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

    def _compile(self, g: _Group, sources: list[_Group] | None = None) -> None:
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
            self.model_inertia[b] = i
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
            # a capsule in the ground at rest never touches it (IN_GROUND: the
            # projectiles still do): freed (felled, uprooted) it would start
            # deep in it and be thrown out. A small sphere resting on the
            # ground at its lower end holds it up instead: without one a
            # felled spruce's base went 0.37 m into the ground and a crate's
            # uprooted oak sank 0.81 m
            buried = g.ground and self.in_ground[b]
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                          fromto=np.concatenate([lo * v, hi * v]),
                          size=[max(float(self.radius[b]), 1e-4), 0, 0],
                          contype=(IN_GROUND if buried else 1) if collide else 0,
                          conaffinity=0, condim=6, friction=[FRICTION, 0.005, ROLLING])
            if buried:
                rho = min(max(float(self.radius[b]), 1e-4), BASE_SPHERE)
                low = v if self.tip0[b, 2] < self.pivot0[b, 2] else np.zeros(3)
                body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[rho, 0, 0],
                              pos=low + np.array([0.0, 0.0, rho]), contype=1, conaffinity=0,
                              condim=6, friction=[FRICTION, 0.005, ROLLING])
            bodies[b] = body
        if g.projectiles:
            for i, pr in enumerate(self.scene.projectiles):
                body = world.add_body(name=f"p{i}", pos=pr.position)
                body.explicitinertial = True
                body.mass = pr.mass
                body.ipos = [0.0, 0.0, 0.0]
                moment = pr.mass * pr.size**2 / 6 if pr.shape == "box" else \
                    0.4 * pr.mass * (pr.size / 2) ** 2
                body.fullinertia = [moment, moment, moment, 0, 0, 0]
                body.add_freejoint(name=f"pf{i}")
                body.add_geom(
                    type=mujoco.mjtGeom.mjGEOM_BOX if pr.shape == "box"
                    else mujoco.mjtGeom.mjGEOM_SPHERE,
                    size=[pr.size / 2] * 3, contype=2, conaffinity=3 | IN_GROUND, priority=1,
                    condim=6,
                    friction=[pr.friction, 0.005, ROLLING],
                    solref=[max(PROJECTILE_TIMECONST, 2 * self.h),
                            restitution_damping(pr.restitution)])
        g.model = spec.compile()
        g.data = mujoco.MjData(g.model)
        self._index(g)
        if sources:
            self._transfer(g, sources)
        self.timing["compile_seconds"] += time.perf_counter() - t0

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
        g.has_free = bool((g.free_dof >= 0).any())
        g.substeps, g.peak, g.blast, g.damp_hold = 1, None, False, self.h
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
        self._damping_pairs(g)

    def _damping_pairs(self, g: _Group) -> None:
        """The entries of each limb's block of the mass matrix (M's sparse
        lower triangle, rows and columns both hinge dofs of one limb): see
        _damping."""
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
        g.damp_rate = -np.expm1(-g.damp_alpha * g.damp_hold) / g.damp_hold
        g.damp_below = g.damp_row != g.damp_col

    def _transfer(self, g: _Group, sources: list[_Group]) -> None:
        """Carry the state over to g's new model from the groups that held
        its bones (their kinematics and velocities current): hinges by
        value, newly freed bones from their bodies' poses and velocities,
        projectiles by value."""
        d = g.data
        d.time = sources[0].data.time
        res = np.zeros(6)
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
                q, v = g.free_qpos[i], g.free_dof[i]
                if q < 0:
                    continue
                qo, vo, body = src.free_qpos[r], src.free_dof[r], int(src.body[r])
                if qo >= 0:
                    d.qpos[q:q + 7] = data.qpos[qo:qo + 7]
                    d.qvel[v:v + 6] = data.qvel[vo:vo + 6]
                    continue
                d.qpos[q:q + 3] = data.xpos[body]
                d.qpos[q + 3:q + 7] = data.xquat[body]
                mujoco.mj_objectVelocity(src.model, data, XBODY, body, res, 0)
                d.qvel[v:v + 3] = res[3:]  # the body frame origin's, world
                d.qvel[v + 3:v + 6] = data.xmat[body].reshape(3, 3).T @ res[:3]  # local
            if g.projectiles and src.projectiles:
                for qn, vn, qo, vo in zip(g.proj_qpos, g.proj_dof, src.proj_qpos, src.proj_dof):
                    d.qpos[qn:qn + 7] = data.qpos[qo:qo + 7]
                    d.qvel[vn:vn + 6] = data.qvel[vo:vo + 6]

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

    def _split(self, t: float) -> None:
        """Split the step of models whose free parts spin fast: a stiff
        broken limb rolling on the ground at 40-70 rad/s gained energy
        without bound at h = 2.1 ms (tornado: a broadleaf's stem pieces,
        x3 in 1 s, with no load doing work; at h/2 it decays). The model
        steps in as many equal substeps as keep every free part's turn per
        substep under SPIN_PER_STEP (at most MAX_SUBSTEPS), loads and
        damping held; counted in stats.split. And of models a blast pushes
        or whose twigs it rings (`_blast_rings`), to BLAST_STEP, counted in
        stats.blast_split: loads and damping worked out again every substep
        (`_blast_step`), and the joints' bending moments tracked over every
        substep (`_Group.peak`), so that a twig's peak between two checks is
        not missed."""
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
                g.damp_rate = -np.expm1(-g.damp_alpha * hold) / hold

    def _blast_rings(self, g: _Group, t: float) -> bool:
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

    def _blast_step(self, g: _Group, t: float, damped: bool, ready: bool) -> None:
        """One step (from t, s) of a model a blast splits, in its substeps,
        each with its own loads, damping and joint moments (`ready`: the
        first substep's mj_step1 is done). Held over a step split 67 times
        (the LOD's 1/480 s), the damping lagged a twig's ringing at hundreds
        of Hz by more than half a period and pumped it (the `explosion`
        preset's oak broke 22 joints at 1/64000 s instead of 7); and the
        loads, held over the load interval, gave a violent blast's breaks
        by that interval (50 kg of TNT 3 m from a sapling: 16 joints at
        2 ms, 24 at 2.5 ms, 20-22 with the loads updated every step)."""
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

    def _group_loads(self, g: _Group, t: float, dt: float) -> np.ndarray:
        """Air, blasts and pulls (N, world, at the COMs) on g's bones over
        [t, t + dt] (s), capped as `_external`'s, their work recorded (the
        other models' loads hold on)."""
        b = g.bones
        axis = np.einsum("bij,bj->bi", self.rot[b], self.axis0[b])
        force = self.loads.forces(t, self.com[b], self.vcom[b], axis, self.props.take(b),
                                  include_gravity=False, dt=dt)
        pulls = self.bones.pull_forces(t)
        if pulls is not None:
            force += pulls[b]
        force = cap_loads(force, self.mass[b], t, self.stats, lambda i: self.locate(int(b[i])),
                          self.loads.blast_capped)
        work = self.load_work.update_rows(b, force, self.com[b])
        self.ledger.add_work(per_tree(work, self.bone_tree[b], len(self.trees)))
        return force

    def _track_peak(self, g: _Group, t: float) -> None:
        """Keep each joint's largest bending moment (N m) while a blast
        splits g's step, and release those past their strength at this
        substep (at t, s)."""
        if g.peak is None:
            return
        moment = self._moments(g)
        np.maximum(g.peak, moment, out=g.peak)
        over = self.breakable[g.bones] & self.attached[g.bones] & \
            (moment > self.strength[g.bones])
        if over.any():
            self._release(g, over, moment, t)

    def _release(self, g: _Group, over: np.ndarray, moment: np.ndarray, t: float) -> None:
        """The joints of g's bones `over` (mask) passed their strength at a
        blast's substep (at t, s): from the next substep they carry no
        moment (springs and limits off, a free pivot, undamped), and their
        parts leave the model at the next break check (`_events`), which
        dates the break t. A joint that goes only at the check (every 2 ms)
        kept loading its parent up to 2 ms past its strength, and which of
        the `explosion` preset's sapling's marginal twigs went depended on
        the check interval: 13 of the reference's, 17 of the LOD's, against
        15 with every step checked (docs/physics.md, "Breaks at the
        substep")."""
        self._closest(g, over, moment, t)
        m = g.model
        for i in np.nonzero(over)[0]:
            b = int(g.bones[i])
            jnt = g.hinge_jnt[i][g.hinge_jnt[i] >= 0]
            m.jnt_stiffness[jnt] = 0.0
            m.jnt_limited[jnt] = 0
            self.k[b] = 0.0
            self.breakable[b] = False
            self.damped[b] = False
            self.released.append((t, b, float(moment[i])))
        self._damping_pairs(g)

    def _external(self, t: float) -> np.ndarray:
        """Air, blasts, attractors and pulls (N, world, at the COMs), capped
        at MAX_ACCELERATION x mass; gravity is MuJoCo's."""
        n = self.n
        axis = self._axes()
        force = self.loads.forces(t, self.com[:n], self.vcom[:n], axis, self.props,
                                  include_gravity=False, dt=self.dt_force)
        pulls = self.bones.pull_forces(t)
        if pulls is not None:
            force += pulls
        force = cap_loads(force, self.mass, t, self.stats, self.locate, self.loads.blast_capped)
        self.ledger.add_work(per_tree(self.load_work.update(force, self.com[:n]),
                                      self.bone_tree, len(self.trees)))
        return force

    def _axes(self) -> np.ndarray:
        """The bones' unit axes (B, 3) in the world now."""
        return np.einsum("bij,bj->bi", self.rot, self.axis0)

    def _damping(self, g: _Group) -> None:
        """Structural damping as generalized forces (qfrc_applied): each
        limb's joints get -rate M_LL qdot_L, M_LL the limb's block of the
        mass matrix (its own bones and all they carry, at the current pose)
        and qdot_L its own joint rates. This is the rig's mass-proportional
        damping of every bone's motion relative to its limb's frame, with
        what the limb carries moving with it (the planar LOD's lumped
        bodies, and the Rayleigh quotient behind rig.alpha), so each limb's
        fundamental gets the grammar's damping ratio; as joint torques it
        acts with equal and opposite reaction on the frame bone and only
        ever removes energy (M_LL is positive definite)."""
        d = g.data
        qv = d.qvel
        w = d.M[g.damp_adr] * g.damp_rate
        tau = np.bincount(g.damp_row, w * qv[g.damp_col], minlength=len(qv))
        below = g.damp_below
        tau += np.bincount(g.damp_col[below], w[below] * qv[g.damp_row[below]],
                           minlength=len(qv))
        if g.has_free:
            scale = self._stable_scale(g, tau, qv)
            if scale < 1.0:
                tau = tau * scale
        np.negative(tau, out=d.qfrc_applied)

    def _stable_scale(self, g: _Group, tau: np.ndarray, qv: np.ndarray) -> float:
        """The factor (<= 1) that keeps an explicit damping force D v from
        overshooting on a model with free parts. A limb's block of M stands
        for what its hinges move while its frame holds; on a part whose first
        bone is free (broken off, uprooted, felled) the frame gives way and
        the hinges move far less mass: at an uprooted bamboo culm's base many
        times less, and the explicit damping blew up (hurricane, 1/2000 s:
        3e4 rad/s within 4 ms). Over one step the damping changes the
        kinetic energy by -s h v.Dv + s^2 h^2 (Dv).M^-1(Dv) / 2: the scale
        s = min(1, v.Dv / (h (Dv).M^-1(Dv))) removes the most energy a step
        can, never adds any, and is 1 wherever the step resolves the
        damping (every standing tree)."""
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
        model changed (their state must be read again)."""
        freed: dict[int, list[int]] = {}  # group -> bones whose joint went
        for ti, tree in enumerate(self.trees):
            state = self.cut_state[ti]
            if not state or state == "falling":
                continue
            roots = self._roots(ti)
            gi = int(self.group_of_bone[roots[0]])
            g = self.groups[gi]
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
                    self.damped[b, 0] = False  # the hinge turns freely
                self._damping_pairs(g)
                self.cut_state[ti] = "hinged"
                self.events.append(Event(t, tree.name, CUT, self._path(roots[0]),
                                         "the hinge holds"))
            elif state == "hinged":
                lean = g.data.qpos[g.hinge_qpos[rows, 0]]
                if lean.max() > math.radians(tree.cut.hinge):
                    self.attached[roots] = False
                    self.cut_state[ti] = "falling"
                    self.events.append(Event(t, tree.name, HINGE, self._path(roots[0]),
                                             f"lean {math.degrees(lean.max()):.0f} deg"))
                    freed.setdefault(gi, []).extend(int(b) for b in roots)
        for tb, b, moment_b in self.released:
            self._broke(tb, b, moment_b)
            freed.setdefault(int(self.group_of_bone[b]), []).append(b)
        self.released = []
        for gi, g in enumerate(self.groups):
            cand = self.breakable[g.bones] & self.attached[g.bones]
            if not cand.any():
                continue
            moment = self._moments(g)
            if g.peak is not None:  # a blast splits the step: its substeps' peaks too
                np.maximum(moment, g.peak, out=moment)
                g.peak[:] = 0.0
            self._closest(g, cand, moment, t)
            over = np.nonzero(cand & (moment > self.strength[g.bones]))[0]
            for i in over:
                b = int(g.bones[i])
                self.breakable[b] = False
                self._broke(t, b, float(moment[i]))
                freed.setdefault(gi, []).append(b)
        out = []
        if freed:
            self._pieces()
            count = sum(len(v) for v in freed.values())
            self.log(f"t = {t:.3f} s: {count} joints went")
        for gi in sorted(freed):
            out.extend(self._detach(gi, freed[gi]))
        for g in out:
            mujoco.mj_step1(g.model, g.data)
            self._read_group(g)
        return out

    def _broke(self, t: float, b: int, moment: float) -> None:
        """The joint at bone b's base went at t (s) under `moment` (N m)."""
        self.attached[b] = False
        ti, seg = int(self.bone_tree[b]), self.locate(b)[1]
        why = f"{moment:.0f} N m > strength {self.strength[b]:.0f} N m"
        kind = UPROOTED if self.parent[b] < 0 else BROKE
        self.events.append(Event(t, self.trees[ti].name, kind, self.paths[ti][seg], why))
        self.stats.broken += 1

    def _closest(self, g: _Group, cand: np.ndarray, moment: np.ndarray, t: float) -> None:
        """Keep the largest moment / strength of the group's breakable joints."""
        frac = np.where(cand, moment / np.maximum(self.strength[g.bones], 1e-12), 0.0)
        i = int(np.argmax(frac))
        if self.stats.closest is None or frac[i] > self.stats.closest[0]:
            b = int(g.bones[i])
            ti, seg = int(self.bone_tree[b]), self.locate(b)[1]
            self.stats.closest = (float(frac[i]), self.trees[ti].name, self.paths[ti][seg], t)

    def _detach(self, gi: int, freed: list[int]) -> list[_Group]:
        """The joints at the base of `freed` bones of group gi are gone.
        Parts broken off a standing tree move to the tree's debris model
        (rebuilt with them; it is small), and their bodies in the tree's
        model become massless, inert and frozen, so that a big tree is
        never recompiled for a twig. A felled or uprooted tree, a part
        breaking up further, or a scene with projectiles (which must reach
        every part) rebuilds the group's own model. Returns the changed
        groups."""
        g = self.groups[gi]
        if g.projectiles or g.debris or any(self.parent[b] < 0 for b in freed):
            self._compile(g, [dataclasses.replace(g)])
            self.stats.rebuilds += 1
            return [g]
        ti = g.trees[0]
        parts = np.unique(np.concatenate([np.nonzero(self._outboard(b))[0] for b in freed]))
        di = self.debris_of.get(ti)
        sources = [dataclasses.replace(g)]
        if di is None:
            di = self.debris_of[ti] = len(self.groups)
            self.groups.append(_Group([ti], parts, False, g.ground, debris=True))
        else:
            sources.append(dataclasses.replace(self.groups[di]))
            self.groups[di].bones = np.union1d(self.groups[di].bones, parts)
        debris = self.groups[di]
        self._compile(debris, sources)
        self._inert(g, parts)
        self._index(g)
        self.group_of_bone[parts] = di
        self.stats.parts += len(freed)
        return [g, debris]

    def _inert(self, g: _Group, bones: np.ndarray) -> None:
        """Bodies that left a model stay in it massless, frozen and without
        springs, limits, contacts or loads (their dofs keep a unit armature
        so that the mass matrix stays regular): the rest moves exactly as
        if they had been removed."""
        m, d = g.model, g.data
        rows = np.searchsorted(g.bones, bones)
        body = g.body[rows]
        m.body_mass[body] = 0.0
        m.body_inertia[body] = 0.0
        dof = g.hinge_dof[rows][g.hinge_dof[rows] >= 0]
        m.dof_armature[dof] = 1.0
        d.qvel[dof] = 0.0
        jnt = g.hinge_jnt[rows][g.hinge_jnt[rows] >= 0]
        m.jnt_stiffness[jnt] = 0.0
        m.jnt_limited[jnt] = 0
        geom = m.body_geomadr[body]
        m.geom_contype[geom] = 0
        m.geom_conaffinity[geom] = 0
        d.xfrc_applied[body] = 0.0
        g.bones = np.setdiff1d(g.bones, bones)

    def _path(self, bone: int) -> str:
        """The limb path of a global bone's first segment."""
        return self.paths[int(self.bone_tree[bone])][self.locate(int(bone))[1]]

    def _roots(self, ti: int) -> np.ndarray:
        sl = np.arange(self.offsets[ti], self.offsets[ti + 1])
        return sl[self.parent[sl] < 0]

    def _pieces(self) -> None:
        """The first bone of the free part each bone is in (-1: on a root
        that still stands)."""
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
                self.events.append(Event(t, self.trees[ti].name, AT_REST, "",
                                         "came to rest on the ground"))

    # ------------------------------------------------------------------
    # running

    def run(self, progress=None, start: float = 0.0,
            state: tuple[np.ndarray, np.ndarray] | None = None,
            hand_back: float | None = None) -> SolveResult:
        """Simulate the scene; per active tree, the bones' motion at every frame.
        With `state`, from time `start` (s, rounded to a step) and the
        hinges' angles and rates (q, v: (2B,), bone b's hinges at 2b, 2b + 1,
        rad and rad/s from the grown shape) the linear tier handed over: its
        coordinates are exactly these hinges. Frames before are left zero.
        With `hand_back` (the linear tier's step, s), the run stops at the
        first frame at which its trees have stayed back in the linear range
        for linear.RETURN_WINDOW (`_back_in_range`); the result's `handed_back`
        holds that frame and the hinges' angles and rates there.

        Each step: mj_step1 (kinematics), then, at force updates, read the
        bones, record a frame, handle events and write the held loads
        (xfrc_applied); every step the damping (qfrc_applied); mj_step2."""
        scene = self.scene
        frames = scene.frame_count
        n = self.n
        quats = np.zeros((frames, n, 4))
        pivots = np.zeros((frames, n, 3))
        self.com, self.vcom, self.omega = (np.zeros((n + 1, 3)) for _ in range(3))
        self.ledger = Ledger(frames, len(self.trees))
        self.load_work = LoadWork()
        self.rot = np.zeros((n, 3, 3))
        proj = next((g for g in self.groups if g.projectiles), None)
        n_proj = len(scene.projectiles) if proj is not None else 0
        self.track_pos = np.zeros((frames, n_proj, 3))
        self.track_quat = np.zeros((frames, n_proj, 4))
        launched = np.zeros(n_proj, dtype=bool)
        damped = bool((self.alpha > 0).any())
        steps = (frames - 1) * self.spf
        self.step_times: list[float] = []  # s, physics time of each step (for benchmarks)
        first = 0
        back = None  # (frame, q, v) where the trees went back to the linear tier
        self.returning = 0.0  # s the trees have been back in the linear range
        self.samples: list = []
        self.extra: list[list] = [[] for _ in self.trees]
        if state is not None:
            first = min(round(start / self.h), steps)
            self._set_hinges(*state, first * self.h)
        for step in range(first, steps + 1):
            t = step * self.h
            t0 = time.perf_counter()
            if n_proj and not launched.all():
                self._projectiles(proj, t, launched)
            update = step % self.force_every == 0
            if not update and not damped:
                for g in self.groups:
                    if g.blast:
                        self._blast_step(g, t, damped, ready=False)
                    else:
                        mujoco.mj_step(g.model, g.data)
                self._substeps()
                self.timing["step_seconds"] += time.perf_counter() - t0
                self.step_times.append(time.perf_counter() - t0)
                self.stats.steps += 1
                continue
            for g in self.groups:
                mujoco.mj_step1(g.model, g.data)
            t1 = time.perf_counter()
            if update:
                self._read()
                self._check(t)
                if step % self.spf:  # between frames: a sample, kept where motion is fast
                    self.samples.append((t, self.rot.copy(), self._pivots()))
                else:
                    f = step // self.spf
                    self._record(f, quats, pivots)
                    if f > first // self.spf:
                        sub_frame_samples(quats[f - 1], quats[f], self.samples, self.offsets,
                                          self.extra)
                    self.samples = []
                    if proj is not None:
                        self.track_pos[f] = proj.data.xpos[proj.proj_body]
                        self.track_quat[f] = proj.data.xquat[proj.proj_body][:, [1, 2, 3, 0]]
                    if f > 0:
                        self._settle(t, 1.0 / scene.fps)
                        if progress is not None:
                            progress(f, frames - 1)
                    if step == steps:
                        break
                    if hand_back is not None and self._back_in_range(t, hand_back):
                        back = (f, *self._hinges())
                        self.events.extend(Event(t, tr.name, TIER, "", RETURN_DETAIL)
                                           for tr in self.trees)
                        break
                if self._events(t):
                    self._check(t)
                if not self.attached.all():
                    self._clamp_spin()
                self._split(t)
                force = self._external(t)
                if proj is not None:
                    self._projectile_work(proj)
                for g in self.groups:
                    g.data.xfrc_applied[g.body, :3] = force[g.bones]
                self.stats.updates += 1
            if damped:
                for g in self.groups:
                    self._damping(g)
            t2 = time.perf_counter()
            for g in self.groups:
                if g.blast:
                    self._blast_step(g, t, damped, ready=True)
                else:
                    mujoco.mj_step2(g.model, g.data)
            self._substeps()
            t3 = time.perf_counter()
            self.timing["update_seconds"] += t2 - t1
            self.timing["step_seconds"] += (t1 - t0) + (t3 - t2)
            self.step_times.append(t3 - t0)
            self.stats.steps += 1
        motions = {}
        for ti, tree in enumerate(self.trees):
            a, b = self.offsets[ti], self.offsets[ti + 1]
            # (a joint released at a substep is recorded at the next check)
            events = sorted((e for e in self.events if e.tree == tree.name), key=lambda e: e.time)
            extra = self.extra[ti]
            motions[tree.name] = TreeMotion(
                quats[:, a:b], pivots[:, a:b], events, self.ledger.energy[:, ti],
                self.ledger.work[:, ti], np.array([e[0] for e in extra]),
                np.array([e[1] for e in extra]).reshape(-1, b - a, 4),
                np.array([e[2] for e in extra]).reshape(-1, b - a, 3))
        meta = self.meta()
        notes = meta.pop("notes")
        timing = {k: round(v, 3) for k, v in self.timing.items()}
        steps = np.asarray(self.step_times)
        if len(steps):
            per_frame = steps[: len(steps) // self.spf * self.spf].reshape(-1, self.spf).sum(1)
            timing.update(segment_steps=sum(t.rig.model.n_segments for t in self.trees)
                          * len(steps), **frame_timing(per_frame, self.spf))
        return SolveResult(motions, self.objects(), meta, notes,
                           {t.name: "reference" for t in self.trees}, timing, back)

    def _back_in_range(self, t: float, h_linear: float) -> bool:
        """Whether the trees have been back in the linear tier's range, with
        margin, for RETURN_WINDOW s up to this frame (at t s): every joint
        holding and none cut, no projectile, every blast's pulse past; and
        its pose within linear.in_return_range for a linear step of
        `h_linear` s (motion that step resolves: a blast's twig ringing
        stays here until it has died down)."""
        if (not self.attached.all() or self.released or any(self.cut_state)
                or any(g.projectiles for g in self.groups)
                or not self.loads.blasts_passed(t, self.com[:self.n], self._axes(),
                                                self.props)):
            self.returning = 0.0
            return False
        n = self.n
        moment = np.zeros(n)
        for g in self.groups:
            moment[g.bones] = self._moments(g)
        ok = in_return_range(self.bones, self.rot[:n], self._pivots(), *self._hinges(), moment,
                             h_linear)
        self.returning = self.returning + 1.0 / self.scene.fps if ok else 0.0
        return self.returning >= RETURN_WINDOW - 1e-9

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

    def _record(self, f: int, quats: np.ndarray, pivots: np.ndarray) -> None:
        n = self.n
        springs = np.zeros(n)
        for g in self.groups:
            q = g.data.xquat[g.body][:, [1, 2, 3, 0]]
            q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
            quats[f, g.bones] = q
            pivots[f, g.bones] = g.data.xpos[g.body]
            has = g.hinge_qpos >= 0
            angle = np.where(has, g.data.qpos[np.maximum(g.hinge_qpos, 0)], 0.0)
            eps = np.where(has, angle - self.springref[g.bones], 0.0)
            springs[g.bones] = 0.5 * (self.k[g.bones] * eps * eps).sum(1)
        e = bone_energy(self.mass, self.model_inertia, self.rot, self.com[:n], self.vcom[:n],
                        self.omega[:n], -self.loads.g[2]) + springs
        self.ledger.record(f, per_tree(e, self.bone_tree, len(self.trees)),
                           per_tree(self.load_work.pending(self.com[:n]), self.bone_tree,
                                    len(self.trees)))

    def _projectile_work(self, g: _Group) -> None:
        """Energy the projectiles lose while touching a tree: the most that
        tree can have got from them (the audit's work)."""
        m, d = g.model, g.data
        energy = np.zeros(len(g.proj_body))
        for i, (body, dof) in enumerate(zip(g.proj_body, g.proj_dof)):
            v = d.qvel[dof:dof + 6]
            inertia = m.body_inertia[body]
            energy[i] = (0.5 * m.body_mass[body] * (v[:3] @ v[:3])
                         + 0.5 * (inertia * v[3:] * v[3:]).sum()
                         - m.body_mass[body] * (self.loads.g @ d.xpos[body]))
        last = getattr(self, "_proj_energy", None)
        self._proj_energy = energy
        if last is None:
            return
        bone_of_body = {int(b): int(bone) for b, bone in zip(g.body, g.bones)}
        work = np.zeros(len(self.trees))
        for c in d.contact[:d.ncon]:
            b1, b2 = int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])
            for pb, other in ((b1, b2), (b2, b1)):
                hit = np.nonzero(g.proj_body == pb)[0]
                if len(hit) and other in bone_of_body:
                    i = int(hit[0])
                    ti = int(self.bone_tree[bone_of_body[other]])
                    work[ti] = max(work[ti], last[i] - energy[i])
        self.ledger.add_work(np.maximum(work, 0.0))

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
        return locate(self.trees, self.offsets, self.bone_tree, bone)

    def objects(self) -> ObjectsBake | None:
        """Projectile tracks, after run()."""
        if not self.scene.projectiles or self.track_pos is None:
            return None
        p = self.scene.projectiles
        return ObjectsBake([x.shape for x in p], np.asarray([x.size for x in p]),
                           self.track_pos, self.track_quat)

    def meta(self) -> dict:
        """Settings, counts and notes for the bake's metadata (deterministic)."""
        st = self.stats
        # the same words in every run at one step, so that the planar LOD's
        # many hand-overs merge into one set of notes (free_part_notes)
        notes = [(f"reference: MuJoCo {mujoco.__version__}, discrete (stiffness-implicit) "
                  f"integrator, h = {self.h * 1e3:.4g} ms, loads every "
                  f"{self.dt_force * 1e3:.4g} ms: numerical damping adds about "
                  f"{math.pi * self.h:.2g} x f (Hz) to the damping ratio of a mode of "
                  "frequency f"),
                 ("reference: joints are two perpendicular hinges (no twist); the cone limit "
                  "is a square in the two swing angles; bones of different trees do not collide")]
        if self.scene.explosions:
            h = self.h / self.blast_split  # s, the step while a blast pushes and rings
            notes.append(f"reference: while a blast pushes and for {BLAST_RING:g} s after, the "
                         f"step is {h * 1e3:.4g} ms, which damps a twig ringing at {TWIG_HZ:g} Hz "
                         f"by about {math.pi * TWIG_HZ * h:.2g} (ratio), with the loads updated "
                         "every step; a joint past its strength at any of those steps lets go "
                         "there")
        if st.limited:
            notes.append(cap_note(st))
        stats = {"steps": st.steps, "updates": st.updates, "models": len(self.groups),
                 "bodies": st.bodies, "bones": self.n, "rebuilds": st.rebuilds,
                 "parts": st.parts, "limited": st.limited, "broken": st.broken,
                 "clamped": st.clamped, "damping_scaled": st.damping_scaled,
                 "split": st.split, "blast_split": st.blast_split}
        if st.closest is not None:
            frac, tree, path, when = st.closest
            stats["closest_to_breaking"] = {"fraction": round(frac, 4), "tree": tree,
                                            "segment": path, "time_s": round(when, 4)}
        notes += free_part_notes(stats)
        return {"substep": self.h, "force_interval": self.dt_force,
                "integrator": "discrete", "stats": stats, "notes": notes}
