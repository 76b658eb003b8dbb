"""The articulated tier: the planar LOD's engine for trees in large motion
where MuJoCo is not installed.

A tree that leaves the linear tier for large motion (a bone turned past
linear.MAX_TURN, a hinge near its cone) comes here with its hinge angles and
rates, the linear tier's and the reference's coordinates, so the switch is
exact. Its bones are one articulated body, stepped with Featherstone's
algorithm (featherstone.py): every child pushes back on its parent, where
the pymunk tier's chains carry their children as rigid lumps (one-way
coupling, docs/physics.md), whose unpaid power m v_frame . a_rel was the
last source of unexplained energy on a blasted sapling.

Model (the reference's, reference.py): two hinges per joint, each with the
rig's stiffness k and the prestress that makes the grown shape the
equilibrium under gravity; structural damping -rate M_LL qd_L on each limb's
own hinges, rate = (1 - exp(-alpha h)) / h; a hinge past its cone meets a
critically damped spring (CONE_OMEGA against the joint's articulated
inertia). Loads (air, blasts, attractors, pulls) are world forces at the
bones' COMs, evaluated at FORCE_RATE at least (every step at 1/480 s) and
held; while a blast pushes or its twigs ring (linear.BLAST_RING) the step is
split to at most linear.BLAST_STEP with the loads evaluated every part, as
the reference's. The ground pushes on the tips in it (contact.py's penalty
springs, tuned to each bone's own free-body mass at the tip, a lower bound
of what the tree presents there, so they hold at the step).

Step: semi-implicit Euler (velocity, then angle) at `articulated_step`,
with the springs implicit in each hinge's own coordinate (an armature
h^2 k in the algorithm's joint inertia): a joint is stable at any step
against all it carries, so no rotary inertia is raised, and the step damps
a mode of f Hz by about pi f h, as MuJoCo's stiffness-implicit step.

Breaking: a joint past its strength breaks here at the step it passes it
(while a blast pushes or rings, the step is split to linear.BLAST_STEP, as
the reference's), and the part it held moves on as rigid debris
(debris.py) with the momentum it had; its bones stay in the articulated
body massless, springless and still, so the rest moves as if they were
gone. A root past its strength uproots the tree: the root's hinges hold
and hang on a free base (featherstone.py), which moves so that the tree
carries the momentum the loads gave it (`_base_velocity`), as a rigid
motion about the tree's centre of mass at the velocity of the step's middle
(`_move_bases`); its foot meets the ground. A tree leaves for the pymunk
tier (which fells) when its felling cut comes: `handed_on`, a
linear.HandOff, from where a blast under way found the tree (as the linear
tier's) or, once a part broke off, from where this tier took it: the
pymunk tier replays what broke. It goes back to the linear tier once it
has stayed in that tier's range for linear.RETURN_WINDOW, as from the
reference (never once a part broke off or it was uprooted).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import SimulationError
from ..rotations import compose, cross, matrices_from_rotvec, quaternions_from_matrices
from ..scene import Scene
from .audit import Ledger, LoadWork, bone_energy
from .common import (
    MAX_ANGULAR_SPEED,
    Bones,
    SimTree,
    TreeMotion,
    cap_loads,
    locate,
    sub_frame_samples,
)
from .contact import ground_forces, stored_energy
from .debris import MAX_SPIN, Debris
from .events import BROKE, TIER, UPROOTED, Event
from .featherstone import accelerations, kinematics
from .layout import ChainLayout
from .linear import (
    BLAST_RING,
    BLAST_STEP,
    RETURN_DETAIL,
    RETURN_WINDOW,
    HandOff,
    in_return_range,
)
from .loads import SceneLoads, meets
from .quality import Quality
from .solver import SolveResult, frame_timing

# A hinge past its cone meets a critically damped spring of this natural
# frequency against the joint's articulated inertia, taken implicitly. The
# reference's cones are MuJoCo's soft limits, which also cancel most of what
# pushes into them; a conifer 5 m from 50 kg of TNT (no ground, 4 s) was off
# the reference at 1/2000 s by at most 3.2 % of its height at 52.6 rad/s
# (MuJoCo's own spring: solref 0.02 s, impedance 0.95), 1.4 % at 150,
# 0.95 % at 400 and 1.2 % at 1000 rad/s (the MuJoCo engine: 1.1 %)
CONE_OMEGA = 400.0  # rad/s
CONE_DAMPING = 1.0  # damping ratio
FORCE_RATE = 500.0  # Hz, at least: the loads' updates (the reference's rate)
# kg m^2 on an uprooted root's two hinges, which then hold (qdd ~ 0): its
# free base turns instead (a trunk of 1.5 t and 15 m: 1e5 kg m^2 about its foot)
FROZEN = 1e12
# An uprooted tree's least rotary inertia, at least this fraction of its
# largest: a stem stripped of its limbs spins about its own axis with next to
# no inertia (3e-4 kg m^2 on a sapling's, 1300 times less than across it),
# and any explicit term on that spin (a tip's friction as it lands) ran away
# at 1/480 s. The spin of a round stem about its axis does not show.
TWIST_FLOOR = 0.01


def _skew(v: np.ndarray) -> np.ndarray:
    """The matrices (..., 3, 3) of v x (.) for vectors v (..., 3)."""
    out = np.zeros(v.shape + (3,))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return out - np.swapaxes(out, -1, -2)


def split_note(steps: int) -> str:
    """The bake's note on `steps` steps split while a blast acted."""
    return (f"articulated tier: steps split to at most {BLAST_STEP * 1e3:.4g} ms while a blast "
            f"pushed or its twigs rang (until {BLAST_RING:g} s after its push), on {steps} steps")


def broken_note(broken: int, parts: int, clamped: int, uprooted: int = 0,
                twist: int = 0) -> str:
    """The bake's note on joints the articulated tier broke (`clamped`:
    debris body substeps whose spin was clamped, debris.MAX_SPIN;
    `uprooted`: roots among them; `twist`: times an uprooted tree's spin
    inertia about its stem was raised, TWIST_FLOOR)."""
    roots = ""
    if uprooted:
        roots = (f" ({uprooted} of them roots: uprooted, the tree flew on a free base"
                 + (f"; its spin inertia about its stem raised to {TWIST_FLOOR:.0%} of its "
                    f"largest {twist} times" if twist else "") + ")")
    spin = f"; debris spin clamped at {MAX_SPIN:.0f} rad/s on {clamped} body substeps" \
        if clamped else ""
    return (f"articulated tier: {broken} joints broke{roots}; {parts} parts fell off as "
            f"rigid debris{spin}")


@dataclass
class ArticulatedStats:
    """What a run did (deterministic: no timings)."""

    steps: int = 0
    split: int = 0  # steps split while a blast pushed or rang
    updates: int = 0  # load evaluations
    limited: int = 0  # bone updates whose load was capped (common.cap_loads)
    first_limit: tuple | None = None  # (tree, segment, time s, m/s^2)
    broken: int = 0  # joints broken
    debris: int = 0  # parts broken off, each a rigid body
    uprooted: int = 0  # roots broken (among `broken`)
    twist_raised: int = 0  # uprooted trees' spin inertia raised (TWIST_FLOOR)


class ArticulatedTier:
    """Trees (handed over by the linear tier) stepped as articulated bodies."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads):
        self.trees, self.scene, self.quality, self.loads = trees, scene, quality, loads
        b = self.bones = Bones.of(trees)
        nb = self.n = b.n
        if np.any(b.parent >= np.arange(nb)):
            raise AssertionError("bones must come after their parents")  # pragma: no cover
        layout = ChainLayout.of(trees, b.offsets, b.pivot0, b.tip0)
        nd = 2 * nb
        self.dof_parent = np.empty(nd, dtype=np.int64)
        self.dof_parent[0::2] = np.where(b.parent >= 0, 2 * b.parent + 1, -1)
        self.dof_parent[1::2] = np.arange(0, nd, 2)
        frame = np.repeat(layout.bone_frame, 2)
        self.frame_dof = np.where(frame >= 0, 2 * frame + 1, -1)
        chain = np.repeat(layout.bone_chain, 2)
        self.same_limb = (self.dof_parent >= 0) & (chain == chain[np.maximum(self.dof_parent, 0)])
        self.rest_axis = np.ascontiguousarray(b.hinges.reshape(nd, 3))
        self.com_arm0 = b.com0 - b.pivot0
        self.k = np.repeat(b.k, 2).astype(float)
        self.cone = np.repeat(b.cone, 2).astype(float)
        self.alpha = np.repeat(b.alpha, 2).astype(float)
        self._rates: dict[float, np.ndarray] = {}  # step (s) -> damping rate (_damp_rate)
        self.tip_arm = b.tip0 - b.pivot0
        # a tip's contact sphere never reaches below where it grew (chains/forces.py)
        self.contact_radius = np.minimum(b.radius, np.maximum(b.tip0[:, 2], 0.0))
        # a frame is a whole number of steps (a hand-on starts the pymunk
        # tier at the substep nearest its time)
        self.spf = max(1, round(1.0 / (scene.fps * quality.articulated_step)))
        self.h = 1.0 / (scene.fps * self.spf)
        self.contact_h = self.h  # s, the last step's: the hold the ground's springs are set for
        self.force_every = max(1, math.floor(1.0 / (self.h * FORCE_RATE)))
        self.blast_windows = [loads.blast_windows(b.com0[lo:hi], self.tip_arm[lo:hi]
                                                  / np.maximum(b.length[lo:hi], 1e-12)[:, None],
                                                  b.props.take(slice(lo, hi)))
                              for lo, hi in zip(b.offsets[:-1], b.offsets[1:])]
        self.cut_time = np.array([t.cut.time if t.cut is not None else np.inf for t in trees])
        # what breaks: the model's mass and inertia (0 on bones broken off),
        # each bone's joint holding, its part's rigid body
        self.mass, self.inertia0 = b.mass.copy(), b.inertia.copy()
        self.gone = np.zeros(nb, dtype=bool)
        self.breakable = np.isfinite(b.strength)
        # an uprooted root's free base (featherstone.kinematics): rotation
        # from rest, pivot (m), spatial velocity and acceleration (at the origin)
        self.floating = np.zeros(nb, dtype=bool)
        self.root_of = np.arange(nb)  # each bone's root bone (parents precede children)
        for i in range(nb):
            if b.parent[i] >= 0:
                self.root_of[i] = self.root_of[b.parent[i]]
        self.base_rot = np.tile(np.eye(3), (nb, 1, 1))
        self.base_pivot = b.pivot0.copy()
        self.base_vel, self.base_acc = np.zeros((nb, 6)), np.zeros((nb, 6))
        self.base_inertia = np.zeros((nb, 6, 6))  # kg, kg m, kg m^2: what the base carries
        # each free base's tree's spatial momentum at the origin (N m s; N s):
        # the loads' impulses change it, nothing inside the tree does
        self.base_momentum = np.zeros((nb, 6))
        self.tree_rows: dict[int, np.ndarray] = {}  # a free base's tree's bones
        self.armature = np.zeros(nd)  # kg m^2 a bone broken off keeps on its hinges
        self.debris = Debris(b.mass, b.inertia, b.com0, b.pivot0, b.tip0, b.radius,
                             scene.ground, loads.g)
        self.stats = ArticulatedStats()
        self.timing = {"step_seconds": 0.0, "update_seconds": 0.0}
        self._buffers()
        self.q, self.qd = np.zeros(nd), np.zeros(nd)
        self._kinematics()
        # the prestress: the grown shape is the equilibrium under gravity
        self.hold = self._gravity_torque() if scene.prestress else np.zeros(nd)

    # ------------------------------------------------------------------
    # state

    def _buffers(self) -> None:
        """The kernels' state and work arrays (featherstone.py), allocated once."""
        nb, nd = self.n, 2 * self.n
        self.rot = np.zeros((nd, 3, 3))
        self.pivot = np.zeros((nd, 3))
        self.com = np.zeros((nb, 3))
        self.inertia = np.zeros((nb, 3, 3))
        self.axis = np.zeros((nd, 6))
        self.vel = np.zeros((nd, 6))
        self.bias = np.zeros((nd, 6))
        self.work_arrays = (np.zeros((nd, 6, 6)), np.zeros((nd, 6)), np.zeros((nd, 6, 6)),
                            np.zeros((nd, 6)))
        self.qdd = np.zeros(nd)
        self.cone_stiffness = np.zeros(nd)  # N m/rad, the cones' as the last step set them

    def _kinematics(self, q: np.ndarray | None = None) -> None:
        """The pose and velocities from the angles (`q`, default self.q)."""
        b = self.bones
        kinematics(self.q if q is None else q, self.qd, self.dof_parent, self.rest_axis,
                   b.parent, b.pivot0, self.com_arm0, self.inertia0, self.rot, self.pivot,
                   self.com, self.inertia, self.axis, self.vel, self.bias, self.floating,
                   self.base_rot, self.base_pivot, self.base_vel)

    def _gravity_torque(self) -> np.ndarray:
        """Gravity's torque (D,) N m on each hinge in the current pose."""
        b = self.bones
        sub_m = b.mass.copy()
        sub_mc = b.mass[:, None] * self.com
        for i in range(self.n - 1, -1, -1):
            p = b.parent[i]
            if p >= 0:
                sub_m[p] += sub_m[i]
                sub_mc[p] += sub_mc[i]
        bone = np.repeat(np.arange(self.n), 2)
        lever = sub_mc[bone] - sub_m[bone][:, None] * self.pivot
        return (self.axis[:, :3] * np.cross(lever, self.loads.g)).sum(1)

    def bone_rot(self) -> np.ndarray:
        """Each bone's rotation relative to rest (B, 3, 3): its second hinge's."""
        return self.rot[1::2]

    def bone_pivot(self) -> np.ndarray:
        """Each bone's pivot (B, 3) m."""
        return self.pivot[1::2]

    def omega(self) -> np.ndarray:
        """Each bone's angular velocity (B, 3) rad/s, world axes."""
        return self.vel[1::2, :3]

    def vcom(self) -> np.ndarray:
        """Each bone's COM velocity (B, 3) m/s (its spatial velocity at the COM)."""
        v = self.vel[1::2]
        return v[:, 3:] + cross(v[:, :3], self.com)

    def _axes(self) -> np.ndarray:
        """Each bone's unit axis (B, 3) now."""
        a = np.einsum("bij,bj->bi", self.bone_rot(), self.tip_arm)
        return a / np.maximum(self.bones.length, 1e-12)[:, None]

    def moments(self) -> np.ndarray:
        """Bending moment (B,) N m at each joint: springs and cones (as the
        last step stiffened them)."""
        mom = self.k * self.q + self.hold + self.cone_stiffness * self.past_cone()
        return np.sqrt((mom.reshape(-1, 2) ** 2).sum(1))

    def energy(self) -> np.ndarray:
        """Per bone (B,) J: kinetic, gravitational (above z = 0), springs and
        cones; a bone broken off: its rigid body's share, with its ends'
        ground springs."""
        b = self.bones
        e = bone_energy(self.mass, self.inertia0, self.bone_rot(), self.com, self.vcom(),
                        self.omega(), -self.loads.g[2])
        mom = self.k * self.q + self.hold
        past = self.past_cone()
        spring = np.divide(0.5 * mom * mom, self.k, out=np.zeros_like(mom), where=self.k > 0) \
            + 0.5 * self.cone_stiffness * past * past
        e += spring.reshape(-1, 2).sum(1)
        if self.debris.count:
            d = self.debris.bones
            rot, pivot, vcom, w = self.debris.bone_poses()
            com = pivot + np.einsum("bij,bj->bi", rot, self.com_arm0[d])
            e[d] = bone_energy(b.mass[d], b.inertia[d], rot, com, vcom, w, -self.loads.g[2]) \
                + self.debris.contact_energy()
        return e

    def poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Each bone's rotation (B, 3, 3) relative to rest and pivot (B, 3) m:
        the articulated body's, a broken-off part's its rigid body's."""
        rot, pivot = self.bone_rot(), self.bone_pivot()
        if self.debris.count:
            rot, pivot = rot.copy(), pivot.copy()
            d = self.debris.bones
            rot[d], pivot[d], _, _ = self.debris.bone_poses()
        return rot, pivot

    # ------------------------------------------------------------------
    # stepping

    def step(self, h: float, force: np.ndarray) -> None:
        """One step of h s under world forces (B, 3) N at the COMs (and the
        ground's at the tips in it, evaluated now)."""
        torque = np.zeros((self.n, 3))
        # (a tip that comes down after a blast's short steps meets springs
        # set for this step: the audit counted 4.8 kJ out of one set for
        # 1/32000 s)
        self.contact_h = h
        contact = self._contact(h)
        if contact is not None:
            bones, arm, push = contact
            force = force.copy()
            np.add.at(force, bones, push)
            np.add.at(torque, bones, np.cross(arm, push))
        q, qd, k = self.q, self.qd, self.k
        fl = np.nonzero(self.floating)[0]
        for r in fl:
            self.base_momentum[r] += h * self._wrench(r, force, torque)
        tau = -k * (q + h * qd) - self.hold
        armature = h * h * k + self.armature
        past = self.past_cone()
        rate = self._damp_rate(h)
        accelerations(self.dof_parent, self.frame_dof, self.same_limb, self.mass, self.com,
                      self.inertia, self.axis, self.vel, self.bias, force, torque, tau, armature,
                      rate, self.loads.g, qd, past, h, CONE_OMEGA, CONE_DAMPING,
                      self.cone_stiffness, *self.work_arrays, self.qdd, self.floating,
                      self.base_acc, self.base_inertia)
        self.qd = qd + h * self.qdd
        if len(fl):
            # each free base moves at the velocity that gives its tree the
            # momentum the loads gave it, taken at the middle of the step
            # (the base's own equation, integrated as it turns, gained 10 %
            # of a spinning tree's energy in 0.5 s; the velocity at the
            # step's start pumped a tumbling sapling into spinning about
            # its trunk, where its energy is largest for its momentum)
            rot0, pivot0 = self.base_rot[fl].copy(), self.base_pivot[fl].copy()
            centre = np.array([self._centre(r) for r in fl])
            self._base_velocity(fl, q)
            self._move_bases(fl, rot0, pivot0, centre, centre, 0.5 * h)
            self._base_velocity(fl, q + 0.5 * h * self.qd)
            middle = np.array([self._centre(r) for r in fl])
            self._move_bases(fl, rot0, pivot0, centre, middle, h)
        self.q = q + h * self.qd
        if len(fl):  # (its own pass at the new angles, the bases at rest)
            self._base_velocity(fl, self.q)
        self._kinematics()

    def _base_velocity(self, fl: np.ndarray, q: np.ndarray) -> None:
        """Set the free bases `fl`' velocities so that their trees, at angles
        `q` (rad) and the rates now, carry `base_momentum` (leaves the
        kinematics at the bases' rest)."""
        self.base_vel[fl] = 0.0
        self._kinematics(q)
        for r in fl:
            rows = self.tree_rows[r]
            self.base_vel[r] = np.linalg.solve(self._spatial_inertia(rows),
                                               self.base_momentum[r] - self._momentum(rows))

    def _move_bases(self, fl: np.ndarray, rot0: np.ndarray, pivot0: np.ndarray,
                    centre: np.ndarray, at: np.ndarray, dt: float) -> None:
        """The free bases `fl` moved for dt s from rotations `rot0` and pivots
        `pivot0` (m) as rigid motions: turned about their trees' centres of
        mass `centre` (m) where the step starts, which move at the bases'
        velocities where they are `at` (m; the velocity is a twist about the
        origin: taken at the start's centre for the middle's velocity, a
        tree thrown at 19 m/s and 6 rad/s left its line by 7 cm in 0.5 s)."""
        w, v_origin = self.base_vel[fl, :3], self.base_vel[fl, 3:]
        turn = matrices_from_rotvec(w * dt)
        shift = dt * (v_origin + cross(w, at))
        self.base_pivot[fl] = centre + shift + np.einsum("bij,bj->bi", turn, pivot0 - centre)
        self.base_rot[fl] = compose(turn, rot0)

    def _centre(self, root: int) -> np.ndarray:
        """The centre of mass (3,) m of the free tree on base `root`."""
        rows = self.tree_rows[root]
        return self.mass[rows] @ self.com[rows] / self.mass[rows].sum()

    def _spatial_inertia(self, rows: np.ndarray) -> np.ndarray:
        """The bones `rows`' spatial inertia (6, 6) at the origin, as one
        rigid body (kg m^2, kg m, kg)."""
        m, c = self.mass[rows], self.com[rows]
        skew = _skew(c)
        out = np.zeros((6, 6))
        out[:3, :3] = (self.inertia[rows] - m[:, None, None] * skew @ skew).sum(0)
        out[:3, 3:] = (m[:, None, None] * skew).sum(0)
        out[3:, :3] = -out[:3, 3:]
        out[3:, 3:] = m.sum() * np.eye(3)
        return out

    def _momentum(self, rows: np.ndarray) -> np.ndarray:
        """The bones `rows`' spatial momentum (6,) at the origin: angular
        about it (N m s), linear (N s)."""
        w = self.vel[2 * rows + 1, :3]
        linear = self.mass[rows, None] * self.vcom()[rows]
        angular = np.einsum("bij,bj->bi", self.inertia[rows], w) + cross(self.com[rows], linear)
        return np.concatenate([angular.sum(0), linear.sum(0)])

    def _wrench(self, root: int, force: np.ndarray, torque: np.ndarray) -> np.ndarray:
        """The loads' and gravity's spatial force (6,) at the origin on the
        tree of free base `root` (N m; N), `force` (B, 3) N at the COMs and
        `torque` (B, 3) N m about them."""
        rows = self.tree_rows[root]
        f = force[rows] + self.mass[rows, None] * self.loads.g
        moment = torque[rows].sum(0) + cross(self.com[rows], f).sum(0)
        return np.concatenate([moment, f.sum(0)])

    def _damp_rate(self, h: float) -> np.ndarray:
        """The damping rate (D,) 1/s of a step of h s: (1 - exp(-alpha h)) / h,
        an exact decay over the step (one array per step length, kept)."""
        if h not in self._rates:
            self._rates[h] = np.where(self.alpha > 0, -np.expm1(-self.alpha * h) / h, 0.0)
        return self._rates[h]

    def _touching(self):
        """The bones whose tips are in the ground: their indices, tip
        points, arms from their COMs (m), the tips' velocities (m/s),
        contact radii (m) and effective masses (kg; `_tip_mass`, the bone
        alone and free: below what the tree presents, so a spring tuned to
        it holds at the step; an uprooted foot's, the tree's), or None."""
        if not self.scene.ground:
            return None
        tip_z = self._tips_z()
        near = np.nonzero((tip_z < self.contact_radius) & ~self.gone)[0]
        # an uprooted stem's foot, a point (it grew at the ground)
        foot = np.nonzero(self.floating & (self.bone_pivot()[:, 2] < 0.0))[0]
        if not len(near) and not len(foot):
            return None
        rot = self.bone_rot()[near]
        tips = self.bone_pivot()[near] + np.einsum("bij,bj->bi", rot, self.tip_arm[near])
        bones = np.concatenate([near, foot])
        points = np.concatenate([tips, self.bone_pivot()[foot]])
        radius = np.concatenate([self.contact_radius[near], np.zeros(len(foot))])
        arm = points - self.com[bones]
        vel = self.vcom()[bones] + np.cross(self.omega()[bones], arm)
        m_eff = np.empty(len(bones))
        m_eff[:len(near)] = self._tip_mass(near, arm[:len(near)])
        for k, r in enumerate(foot, start=len(near)):
            # the mass the tree presents at its foot, in the direction it
            # yields most (a culm standing up is its whole mass pushed up,
            # a quarter of it pushed sideways: friction tuned to the first
            # spun an uprooted bamboo culm to 3000 rad/s)
            push = np.vstack([_skew(points[k]), np.eye(3)])  # unit forces there, at the origin
            mobility = push.T @ np.linalg.solve(self.base_inertia[r], push)
            m_eff[k] = 1.0 / float(np.linalg.eigvalsh(mobility)[-1])
        return bones, points, arm, vel, radius, m_eff

    def _tip_mass(self, near: np.ndarray, arm: np.ndarray) -> np.ndarray:
        """The mass (kg) each bone `near`, alone and free, presents at the
        point `arm` (m) from its COM, in the direction it yields most: a
        lower bound of what the tree presents there. (Taken with the bone's
        least moment whatever the direction, it was the tip's mass pushed
        round the bone's own axis: a palm's fronds landed on springs so soft
        that 32 of its joints broke where the reference breaks 100.)"""
        skew = _skew(arm)
        mobility = np.eye(3) / self.bones.mass[near][:, None, None] \
            + skew.transpose(0, 2, 1) @ np.linalg.inv(self.inertia[near] + 1e-12 * np.eye(3)) @ skew
        return 1.0 / np.linalg.eigvalsh(mobility)[:, -1]

    def _contact(self, h: float):
        """The ground's forces (N) on the tips in it, for a step of h s:
        (bones, arms from their COMs (m), forces), or None."""
        touching = self._touching()
        if touching is None:
            return None
        bones, tips, arm, vel, radius, m_eff = touching
        return bones, arm, ground_forces(tips, vel, radius, m_eff, h)

    def contact_energy(self) -> float:
        """What the ground's springs hold (J; contact.stored_energy)."""
        touching = self._touching()
        if touching is None:
            return 0.0
        _, tips, _, vel, radius, m_eff = touching
        return float(stored_energy(tips, vel[:, 2], radius, m_eff, self.contact_h).sum())

    def past_cone(self) -> np.ndarray:
        """How far (D,) rad each hinge is past its cone (0 within it)."""
        # (no inf - inf on the hinges without a cone: held or broken off)
        return np.sign(self.q) * np.maximum(np.abs(self.q) - self.cone, 0.0)

    # ------------------------------------------------------------------
    # the run

    def run(self, start: float, state: tuple[np.ndarray, np.ndarray],
            hand_back: float | None = None, before_blast: HandOff | None = None,
            work_start: float = 0.0) -> SolveResult:
        """Simulate from `start` s (rounded to a step) and hinge angles and
        rates `state` (q, v: (2B,) rad, rad/s from the grown shape), with
        `work_start` J done on the tree before. Frames before are left zero.
        With `hand_back` (the linear tier's step, s) the run stops once the
        tree has stayed in the linear range for RETURN_WINDOW: the result's
        `handed_back` is (frame, q, v) there. When an event needs the pymunk
        tier, it stops there: `handed_on` is a HandOff (work: J since the
        bake's start; from `before_blast` if a blast under way found the
        tree before this tier took it)."""
        (tree,) = self.trees  # lod.py gives each run one tree
        scene, h, spf = self.scene, self.h, self.spf
        frames = scene.frame_count
        steps = (frames - 1) * spf
        n = self.n
        quats, pivots = np.zeros((frames, n, 4)), np.zeros((frames, n, 3))
        self.ledger = Ledger(frames, 1)
        load_work = LoadWork()
        events: list[Event] = []
        extra: list[list] = [[]]
        samples: list = []
        first = min(round(start / h), steps)
        self.q, self.qd = state[0].astype(float).copy(), state[1].astype(float).copy()
        self._kinematics()
        self.returning = 0.0
        self.before_blast = before_blast
        self.taken = before_blast if before_blast is not None else \
            self._state(first * h, "as the articulated tier took it", "taken", hand_back,
                        work_start)
        handed_on = back = None
        force = np.zeros((n, 3))
        blast = False
        frame_seconds = []
        t_frame = time.perf_counter()
        for step in range(first, steps + 1):
            t = step * h
            t0 = time.perf_counter()
            if step % spf == 0:
                f = step // spf
                self._record(f, quats, pivots, load_work)
                if f > first // spf:
                    sub_frame_samples(quats[f - 1], quats[f], samples, self.bones.offsets, extra)
                    frame_seconds.append(time.perf_counter() - t_frame)
                    t_frame = time.perf_counter()
                samples = []
                if step == steps:
                    break
                if hand_back is not None and self._back_in_range(t, hand_back):
                    back = (f, self.q.copy(), self.qd.copy())
                    events.append(Event(t, tree.name, TIER, "", RETURN_DETAIL))
                    break
            elif step % self.force_every == 0:
                samples.append((t, *(a.copy() for a in self.poses())))
            self._check(t)
            leaving = self._leaving(t)
            if leaving is not None:
                handed_on = self._hand_off(t, *leaving, hand_back, work_start)
                break
            if step % self.force_every == 0 or step == first:
                # held until the next update (the first one, to the interval's end)
                hold = (self.force_every - step % self.force_every) * h
                blast = any(meets(w, t, hold, BLAST_RING) for w in self.blast_windows)
                self._keep_before_blast(t, blast, hand_back, work_start)
                if not blast:
                    force = self._loads(t, hold, load_work)
            t1 = time.perf_counter()
            if blast:
                parts = math.ceil(h / BLAST_STEP - 1e-9)
                self.stats.split += 1
                for k in range(parts):
                    t_k = t + k * h / parts
                    force = self._loads(t_k, h / parts, load_work)
                    self.step(h / parts, force)
                    self._step_debris(t_k, h / parts)
                    self._break(t_k + h / parts, events)
            else:
                self.step(h, force)
                self._step_debris(t, h)
                self._break(t + h, events)
            self.stats.steps += 1
            self.timing["update_seconds"] += t1 - t0
            self.timing["step_seconds"] += time.perf_counter() - t1
        motion = TreeMotion(quats, pivots, events, self.ledger.energy[:, 0],
                            self.ledger.work[:, 0],
                            np.array([e[0] for e in extra[0]]),
                            np.array([e[1] for e in extra[0]]).reshape(-1, n, 4),
                            np.array([e[2] for e in extra[0]]).reshape(-1, n, 3))
        st = self.stats
        notes = [split_note(st.split)] if st.split else []
        if st.broken and handed_on is None:  # (handed on: the pymunk tier replays the blast)
            notes.append(broken_note(st.broken, st.debris, self.debris.clamped, st.uprooted,
                                     st.twist_raised))
        timing = {k: round(v, 3) for k, v in self.timing.items()}
        timing.update(segment_steps=tree.rig.model.n_segments * st.steps,
                      **frame_timing(frame_seconds, spf))
        meta = {"step": h, "stats": {"steps": st.steps, "split": st.split, "updates": st.updates,
                                     "limited": st.limited, "first_limit": st.first_limit,
                                     "broken": st.broken, "debris": st.debris,
                                     "uprooted": st.uprooted, "twist_raised": st.twist_raised,
                                     "debris_clamped": self.debris.clamped}}
        result = SolveResult({tree.name: motion}, None, meta, notes, {tree.name: "articulated"},
                             timing, back, handed_on)
        self.first_frame = math.ceil(first / spf - 1e-9)
        return result

    def _record(self, f: int, quats: np.ndarray, pivots: np.ndarray, load_work: LoadWork) -> None:
        """Frame f's pose and the audit's energy (J) and pending work."""
        rot, pivots[f] = self.poses()
        quats[f] = quaternions_from_matrices(rot)
        self.ledger.add_work(np.array([self.debris.work.sum()]))
        self.debris.work[:] = 0.0
        self.ledger.record(f, np.array([self.energy().sum() + self.contact_energy()]),
                           np.array([load_work.pending(self.com).sum()]))

    def _loads(self, t: float, hold: float, load_work: LoadWork) -> np.ndarray:
        """World loads (B, 3) N at the COMs held for `hold` s from t, capped
        (common.cap_loads), their work on the ledger."""
        b = self.bones
        on = np.nonzero(~self.gone)[0]  # (the parts broken off: their rigid bodies')
        force = self.loads.forces(t, self.com[on], self.vcom()[on], self._axes()[on],
                                  b.props.take(on), include_gravity=False, dt=hold)
        pulls = b.pull_forces(t)
        if pulls is not None:
            force += pulls[on]
        force = cap_loads(force, b.mass[on], t, self.stats, lambda i: self.locate(int(on[i])),
                          self.loads.blast_capped)
        if len(on) < self.n:
            rows, force = force, np.zeros((self.n, 3))
            force[on] = rows
        self.ledger.add_work(np.array([load_work.update(force, self.com).sum()]))
        self.stats.updates += 1
        return force

    def _step_debris(self, t: float, dt: float) -> None:
        """The parts broken off over dt s from t: gravity, air and blasts on
        their bones (capped), and the ground."""
        if not self.debris.count:
            return
        d = self.debris.bones
        props, mass = self.bones.props.take(d), self.bones.mass[d]

        def loads(com, vcom, axis, start, hold):
            force = self.loads.forces(t + start, com, vcom, axis, props, dt=hold)
            return cap_loads(force, mass, t + start, self.stats,
                             lambda i: self.locate(int(d[i])), self.loads.blast_capped)

        self.debris.step(dt, loads)

    def _break(self, t: float, events: list[Event]) -> None:
        """Break, at t s, every joint past its strength; a root's uproots
        the tree (`_uproot`). The part a joint held becomes a rigid body
        with its momentum (debris.py); its bones stay in the articulated
        body without mass, springs, cones or damping and still, each hinge
        with a unit armature (kg m^2) to keep the algorithm regular, so the
        rest moves as if they were gone."""
        moment = self.moments()
        over = np.nonzero(self.breakable & (moment > self.bones.strength))[0]
        if not len(over):
            return
        pose = {"rot": self.bone_rot(), "pivot": self.bone_pivot(), "com": self.com,
                "vcom": self.vcom(), "omega": self.omega()}
        paths = self.trees[0].rig.model.segment_paths()
        for b in over:
            if self.gone[b]:  # in a part broken off above it at this step
                continue
            if self.bones.parent[b] < 0:
                self._uproot(int(b))
                self.stats.uprooted += 1
            else:
                self._to_debris(int(b), pose)
            events.append(Event(t, self.trees[0].name,
                                UPROOTED if self.bones.parent[b] < 0 else BROKE,
                                paths[self.locate(int(b))[1]],
                                f"{moment[b]:.0f} N m > strength "
                                f"{self.bones.strength[b]:.0f} N m"))
            self.stats.broken += 1
        self._rates.clear()
        self._kinematics()
        for r, rows in self.tree_rows.items():  # what flies on (the parts took theirs)
            self.base_momentum[r] = self._momentum(rows)
            self._floor_twist(r)

    def _to_debris(self, bone: int, pose: dict) -> None:
        """The part `bone` holds leaves as one rigid body (`_break`)."""
        part = self._outboard(bone)
        self.debris.add(part, pose)
        self.gone[part] = True
        self.breakable[part] = False
        dof = np.concatenate([2 * part, 2 * part + 1])
        self.k[dof] = self.hold[dof] = self.alpha[dof] = self.qd[dof] = 0.0
        self.cone[dof] = np.inf
        self.armature[dof] = 1.0
        self.mass[part] = 0.0
        self.inertia0[part] = 0.0
        self.stats.debris += 1

    def _uproot(self, root: int) -> None:
        """The root `root` leaves the ground: its two hinges hold (FROZEN
        armature, no springs, cones or damping) and hang on a free base
        that starts where the root's pivot is, moving as the root's body
        does (its momentum kept), and turns and flies from there."""
        dof = np.array([2 * root, 2 * root + 1])
        # the limb the root heads (its frame the world) loses its structural
        # damping: relative to the world it would brake the flight, and
        # relative to the root's light body its explicit reaction throws
        # that body about (an explicit damping holds only against a frame
        # far heavier than what it damps: an uprooted palm gained 10.9 kJ
        # in 8 ms). The limbs on it keep theirs, against their own frames.
        mine = np.repeat(self.root_of == root, 2) & (self.frame_dof < 0)
        self.alpha[mine] = 0.0
        self._rates.clear()
        self.base_vel[root] = self.vel[2 * root + 1]
        self.base_rot[root] = np.eye(3)
        self.base_pivot[root] = self.bones.pivot0[root]
        self.floating[root] = True
        self.breakable[root] = False
        self.k[dof] = self.hold[dof] = self.alpha[dof] = self.qd[dof] = 0.0
        self.cone[dof] = np.inf
        self.armature[dof] = FROZEN
        self.tree_rows[root] = np.nonzero(self.root_of == root)[0]
        self.base_momentum[root] = self._momentum(self.tree_rows[root])  # (unchanged)
        self._floor_twist(root)

    def _floor_twist(self, root: int) -> None:
        """Raise the least rotary inertia of the free tree on base `root`
        (its spin about its stem) to TWIST_FLOOR of its largest, on the
        root bone; the base's velocity then carries the same momentum (the
        spin slows: no energy is made)."""
        rows = self.tree_rows[root]
        skew = _skew(self._centre(root))  # (the origin to the centre)
        about_centre = self._spatial_inertia(rows)[:3, :3] + self.mass[rows].sum() * skew @ skew
        values, axes = np.linalg.eigh(about_centre)
        short = TWIST_FLOOR * values[2] - values[0]  # kg m^2
        if short <= 0.0:
            return
        self.stats.twist_raised += 1
        a = self.bone_rot()[root].T @ axes[:, 0]  # the stem's axis in the root's rest frame
        self.inertia0[root] += short * np.outer(a, a)
        self._kinematics()
        self._base_velocity(np.array([root]), self.q)
        self._kinematics()

    def _outboard(self, bone: int) -> np.ndarray:
        """The bones (indices) of the part `bone` holds: it and all it
        carries that has not broken off."""
        part = np.zeros(self.n, dtype=bool)
        part[bone] = True
        parent = self.bones.parent
        for b in range(bone + 1, self.n):  # parents precede children
            if parent[b] >= 0 and part[parent[b]] and not self.gone[b]:
                part[b] = True
        return np.nonzero(part)[0]

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index of a bone."""
        return locate(self.trees, self.bones.offsets, self.bones.bone_tree, bone)

    def _check(self, t: float) -> None:
        """Stop on a non-finite state or a bone spinning faster than
        MAX_ANGULAR_SPEED, naming the tree, a segment and the time (lod.py
        then gives the tree to the pymunk tier from its hand-over)."""
        w = self.omega()
        spin = np.einsum("bi,bi->b", w, w)
        bad = ~(spin <= MAX_ANGULAR_SPEED**2) | ~np.isfinite(self.com).all(1)
        if self.debris.count:  # a part broken off: its rigid body's
            bad[self.debris.bones] = ~np.isfinite(self.debris.x[self.debris.owner]).all(1)
        if not bad.any():
            return
        bone = int(np.argmax(bad))
        fast = MAX_ANGULAR_SPEED**2 < spin[bone] < np.inf
        what = (f"angular speed {math.sqrt(spin[bone]):.0f} rad/s > {MAX_ANGULAR_SPEED:.0f}"
                if fast else "non-finite state")
        raise SimulationError(f"{what} in the articulated tier", *self.locate(bone), t)

    def _tips_z(self) -> np.ndarray:
        """Height (B,) m of each bone's tip."""
        return self.bone_pivot()[:, 2] + np.einsum("bj,bj->b", self.bone_rot()[:, 2],
                                                   self.tip_arm)

    def _leaving(self, t: float) -> tuple[str, str] | None:
        """(reason, kind) if an event needs the pymunk tier at t s (the
        felling cut: joints break and roots uproot here), else None."""
        if self.cut_time[0] <= t + 0.5 * self.h:
            return "its felling cut", "cut"
        return None

    def _state(self, t: float, reason: str, kind: str, hand_back: float | None,
               work_start: float) -> HandOff:
        substep = round(t * self.quality.substep_rate)
        return HandOff(0, substep, t, self.bone_rot().copy(), self.omega().copy(), self.q.copy(),
                       self.qd.copy(), reason, kind, hand_back or 0.0,
                       work_start + float(self.ledger.running[0]))

    def _hand_off(self, t: float, reason: str, kind: str, hand_back: float | None,
                  work_start: float) -> HandOff:
        """Where the pymunk tier takes the tree: from where a blast under way
        found it, or, once a part broke off, from where this tier took it
        (`before_blast`: the pymunk tier replays what broke)."""
        ho = self._state(t, reason, kind, hand_back, work_start)
        changed = self.gone.any() or self.floating.any()
        ho.before_blast = self.taken if changed else self.before_blast
        return ho

    def _keep_before_blast(self, t: float, blast: bool, hand_back: float | None,
                           work_start: float) -> None:
        """The state a blast found the tree in, kept until BLAST_RING after its
        push (linear.LinearTier._keep_before_blast: the pymunk tier starts a
        tree handed on during a blast from there)."""
        if not blast:
            self.before_blast = None
        elif self.before_blast is None:
            self.before_blast = self._state(t, "as the blast reached it", "blast", hand_back,
                                            work_start)

    def _back_in_range(self, t: float, h_linear: float) -> bool:
        """Whether the tree has stayed in the linear tier's range (with its
        margin: linear.in_return_range) for RETURN_WINDOW s up to t, every
        blast's push past, and nothing broken off."""
        if self.gone.any() or self.floating.any() or \
                not self.loads.blasts_passed(t, self.com, self._axes(), self.bones.props):
            self.returning = 0.0
            return False
        ok = in_return_range(self.bones, self.bone_rot(), self.bone_pivot(), self.q, self.qd,
                             self.moments(), h_linear)
        self.returning = self.returning + 1.0 / self.scene.fps if ok else 0.0
        return self.returning >= RETURN_WINDOW - 1e-9
