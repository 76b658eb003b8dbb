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

import itertools
import math
import time
from dataclasses import dataclass, field, fields

import numpy as np
import pymunk
from pymunk import batch

from ..errors import SimulationError
from ..rotations import (
    apply,
    apply_transposed,
    compose,
    cross,
    matrices_from_rotvec,
    quaternions_from_matrices,
)
from ..scene import Scene
from .quality import Quality
from .common import (
    MAX_ANGULAR_SPEED,
    Bones,
    SimTree,
    TreeMotion,
    cap_loads,
    locate,
)
from .contact import effective_mass, ground_forces
from .debris import SLEEP_TIME, Debris
from .loads import BoneProps, SceneLoads
from .projectiles import Projectiles
from .stability import chain_gaps, inertia_floor

EYE = np.eye(3)
PIVOT, SPRING, LIMIT = 0, 1, 2  # a body's joint constraints
REFINE = 8  # pymunk steps per substep at least, while an impulsive load acts
REFINE_SPIN = 0.002  # rad: the most a body may turn in one pymunk step
MAX_REFINE = 32  # pymunk steps per substep at most
CONTACT_MARGIN = 0.05  # m: bones this close to the ground update every substep
FELL_NUDGE = -0.05  # rad/s: the push at the cut, toward the felling direction
SETTLE_SPEED = 0.05  # m/s and rad/s: a fallen tree slower than this for SLEEP_TIME sleeps
STILL_SPEED = 0.005  # m/s and rad/s: the same for a standing tree no load reaches any more


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


def plane_direction(d: np.ndarray, load: np.ndarray | None) -> np.ndarray:
    """In-plane bending direction e (unit, perpendicular to the chord d)."""
    for cand in (load, np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]),
                 np.array([0.0, 1.0, 0.0])):
        if cand is None:
            continue
        e = cand - (cand @ d) * d
        n = np.linalg.norm(e)
        if n > 0.25:
            return e / n
    raise AssertionError("no perpendicular found")  # pragma: no cover


def apparent_mass(r: float, zeta: float) -> float:
    """The in-phase (real) part of the apparent mass of a damped oscillator
    driven at its base, per unit of its mass, at r = driving frequency /
    its own frequency: ((1 - r^2) + 4 zeta^2 r^2) / ((1 - r^2)^2 + 4 zeta^2 r^2),
    clipped to [1, 3]. Above 1 when the child is stiffer than the motion (it
    sways along, amplified): the one-way coupling's stand-in for the
    children's push back. A softer child would lag behind (below 1), but
    its frequency estimate ignores gravity's pendulum stiffness (hanging
    twigs), so it is carried as rigid instead."""
    q = 1.0 - r * r
    z = 4.0 * zeta * zeta * r * r
    return float(np.clip((q + z) / (q * q + z), 1.0, 3.0))


class PlanarSolver:
    """Simulate the active trees of one scene with the planar LOD."""

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

    # ------------------------------------------------------------------
    # construction

    def _collect(self) -> None:
        """The trees' rigs as global bone arrays (sim/common.py's Bones)."""
        self.bones = Bones.of(self.trees)
        for f in fields(Bones):  # as attributes: the solver reads them everywhere
            setattr(self, f.name, getattr(self.bones, f.name))
        self.n = self.bones.n
        self.stats.bones = self.n

    def _chains(self) -> None:
        """Each rig limb is a chain with one or two bending planes."""
        self.chain_bones: list[np.ndarray] = []
        self.chain_parent: list[int] = []  # the bone a chain hangs on, -1 = ground
        self.chain_tree: list[int] = []
        self.chain_planes: list[list[tuple[np.ndarray, np.ndarray]]] = []  # (e, d) per plane
        self.bone_chain = np.zeros(self.n, dtype=np.int64)
        for ti, t in enumerate(self.trees):
            o = int(self.offsets[ti])
            for limb in t.rig.limbs:
                bones = np.asarray(limb.bones) + o
                self.bone_chain[bones] = len(self.chain_bones)
                self.chain_bones.append(bones)
                self.chain_parent.append(limb.parent_bone + o if limb.parent_bone >= 0 else -1)
                self.chain_tree.append(ti)
                chord = self.tip0[bones[-1]] - self.pivot0[bones[0]]
                if np.linalg.norm(chord) < 1e-6:
                    chord = self.tip0[bones[0]] - self.pivot0[bones[0]]
                norm = np.linalg.norm(chord)
                d = chord / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])
                e = plane_direction(d, t.load_direction)
                planes = [(e, d)] if t.planes == 1 else [(e, d), (cross(e, d), d)]
                self.chain_planes.append(planes)
        self.chain_parent_arr = np.asarray(self.chain_parent, dtype=np.int64)
        self.chain_first = np.asarray([b[0] for b in self.chain_bones], dtype=np.int64)
        self.bone_frame = self.chain_parent_arr[self.bone_chain] if self.n else \
            np.zeros(0, dtype=np.int64)  # the bone whose frame a bone's chain moves in

    def _lumping(self) -> None:
        """Lumped bodies: a bone plus the chains attached to it, carried as
        if rigid. Each pair (attach bone a, descendant d) adds d to a's lump:
        its true mass for gravity and the prestress; for inertia, its mass
        times the apparent-mass factor of the child chain it hangs in
        (apparent_mass), so a soft crown slows the stem as it does when it
        sways along."""
        omega = np.concatenate([t.rig.limb_omega for t in self.trees]) if self.trees else \
            np.zeros(0)
        zeta = self.alpha[self.chain_first] / np.maximum(2 * omega, 1e-9)
        factor = np.ones(len(self.chain_bones))
        for ci, p in enumerate(self.chain_parent):
            if p >= 0:
                r = omega[self.bone_chain[p]] / max(omega[ci], 1e-9)
                factor[ci] = apparent_mass(r, zeta[ci]) \
                    if self.quality.coupling == "apparent" else 1.0
        anc, dsc, via = [], [], []
        for b in range(self.n):
            below, p = b, self.bone_frame[b]
            while p >= 0:
                anc.append(p)
                dsc.append(b)
                via.append(self.bone_chain[below])
                below, p = p, self.bone_frame[p]
        order = np.lexsort((dsc, anc))
        self.pair_anc = np.asarray(anc, dtype=np.int64)[order]
        self.pair_dsc = np.asarray(dsc, dtype=np.int64)[order]
        self.pair_weight = factor[np.asarray(via, dtype=np.int64)[order]] if anc else np.zeros(0)
        self.chain_factor = factor
        self._lump()

    def _lump(self) -> None:
        """Lumped masses, COGs and inertias from the current pairs."""
        n, m, c = self.n, self.mass, self.com0
        a, d, w = self.pair_anc, self.pair_dsc, self.pair_weight

        def add(own: np.ndarray, each: np.ndarray, weight: np.ndarray) -> np.ndarray:
            width = int(np.prod(own.shape[1:]))
            flat = each.reshape(len(each), width) * weight[:, None]
            out = own.reshape(n, width).copy()
            for k in range(out.shape[1]):
                out[:, k] += np.bincount(a, flat[:, k], minlength=n)
            return out.reshape(own.shape)

        ones = np.ones(len(a))
        self.true_mass = add(m, m[d], ones)
        self.true_cog0 = add(m[:, None] * c, m[d, None] * c[d], ones) / self.true_mass[:, None]
        lm = add(m, m[d], w)
        lmc = add(m[:, None] * c, m[d, None] * c[d], w)
        j_own = self.inertia + m[:, None, None] * (
            (c * c).sum(1)[:, None, None] * EYE - c[:, :, None] * c[:, None, :])
        lj = add(j_own, j_own[d], w)
        self.lump_mass = lm
        self.lump_cog0 = lmc / lm[:, None]
        g = self.lump_cog0
        self.lump_inertia = lj - lm[:, None, None] * (
            (g * g).sum(1)[:, None, None] * EYE - g[:, :, None] * g[:, None, :])

    def _levels(self) -> None:
        """Chains grouped by depth, for the 3D reconstruction level by level."""
        depth = []
        for p in self.chain_parent:
            depth.append(0 if p < 0 else depth[self.bone_chain[p]] + 1)
        self.chain_depth = np.asarray(depth, dtype=np.int64)
        self.row_start = np.zeros(self.n, dtype=bool)  # a bone starts a (sub)chain row
        self.row_start[self.chain_first] = True
        self._layout()

    def _layout(self) -> None:
        """Per depth, a padded grid (rows x length) of sub-chains (a chain
        splits into rows where a joint has broken), and the rest-pose
        quantities the reconstruction needs, computed once."""
        self.levels = []
        for depth in range(int(self.chain_depth.max()) + 1 if len(self.chain_depth) else 0):
            rows = []
            for ci in np.nonzero(self.chain_depth == depth)[0]:
                bones = self.chain_bones[ci]
                starts = [i for i, b in enumerate(bones) if self.row_start[b]]
                for a, z in zip(starts, [*starts[1:], len(bones)]):
                    rows.append(bones[a:z])
            grid = np.full((len(rows), max(len(r) for r in rows)), -1, dtype=np.int64)
            for i, r in enumerate(rows):
                grid[i, :len(r)] = r
            valid = grid >= 0
            bones = grid[valid]
            heads = grid[:, 0]
            p = self.bone_frame[bones]
            has = p >= 0
            first = self.chain_first[self.bone_chain[bones]]
            head_first = self.chain_first[self.bone_chain[heads]]
            self.levels.append({
                "grid": grid, "valid": valid, "bones": bones, "heads": heads,
                "head_pos": np.searchsorted(np.flatnonzero(valid.ravel()),
                                            np.arange(len(rows)) * grid.shape[1]),
                "p": p, "has": has, "pp": p[has], "any": bool(has.any()),
                "attach_rest": self.pivot0[first],
                "attach_arm": self.pivot0[first[has]] - self.pivot0[p[has]],
                "head_arm": self.pivot0[heads] - self.pivot0[head_first],
                "step": self.tip0[bones] - self.pivot0[bones]})
        self._refresh_cog()

    def _refresh_cog(self) -> None:
        """Rest offsets of the lumped COGs (they change when a part breaks off)."""
        arm = self.lump_cog0 - self.pivot0
        for level in self.levels:
            level["cog_arm"] = arm[level["bones"]]

    def _space(self) -> None:
        """pymunk bodies and joints, rest angles (prestress), stability rule."""
        q, h = self.quality, self.h
        space = pymunk.Space()
        space.iterations = q.iterations
        self.space = space
        body_bone, body_plane, e_rows, d_rows = [], [], [], []
        self.body_of: dict[tuple[int, int], int] = {}
        for ci, bones in enumerate(self.chain_bones):
            for k, (e, d) in enumerate(self.chain_planes[ci]):
                for b in bones:
                    self.body_of[(int(b), k)] = len(body_bone)
                    body_bone.append(int(b))
                    body_plane.append(k)
                    e_rows.append(e)
                    d_rows.append(d)
        nb = len(body_bone)
        self.stats.bodies = nb
        self.body_bone = np.asarray(body_bone, dtype=np.int64)
        self.body_plane = np.asarray(body_plane, dtype=np.int64)
        self.body_e = np.asarray(e_rows).reshape(nb, 3)
        self.body_d = np.asarray(d_rows).reshape(nb, 3)
        self.body_n = cross(self.body_e, self.body_d)
        self.planes_of_bone = np.maximum(np.bincount(self.body_bone, minlength=self.n), 1)
        self.body_of_bone0 = np.asarray([self.body_of[(b, 0)] for b in range(self.n)],
                                        dtype=np.int64)
        b1 = np.asarray([self.body_of.get((b, 1), -1) for b in range(self.n)], dtype=np.int64)
        self.plane_rows = (self.body_of_bone0, b1, np.nonzero(b1 >= 0)[0])
        first = self.chain_first[self.bone_chain[self.body_bone]]
        origin = self.pivot0[first]  # a chain's 2D origin: its base at rest

        def to2d(p):
            return np.stack([((p - origin) * self.body_e).sum(1),
                             ((p - origin) * self.body_d).sum(1)], 1)

        self.q0 = to2d(self.pivot0[self.body_bone])
        self.cog2d0 = to2d(self.lump_cog0[self.body_bone])
        lm = self.lump_mass[self.body_bone]
        self.i_n = np.einsum("bi,bij,bj->b", self.body_n, self.lump_inertia[self.body_bone],
                             self.body_n)
        prev = np.full(nb, -1, dtype=np.int64)
        for ci, bones in enumerate(self.chain_bones):
            for k in range(len(self.chain_planes[ci])):
                for a, b in itertools.pairwise(bones):
                    prev[self.body_of[(int(b), k)]] = self.body_of[(int(a), k)]
        self.prev_body = prev
        self.rest = self._prestress() if self.scene.prestress else np.zeros(nb)
        # stability rule: floor each body's rotary inertia by its stiffest joint
        kb = self.k[self.body_bone]
        k_max = kb.copy()
        has = prev >= 0
        np.maximum.at(k_max, prev[has], kb[has])
        floor = inertia_floor(k_max, h, q.stability)
        self.i_eff = np.maximum(np.maximum(self.i_n, floor), 1e-12)
        floored = floor > self.i_n
        self.stats.inertia_floored = int(floored.sum())
        self.stats.max_inertia_ratio = float(
            (self.i_eff / np.maximum(self.i_n, 1e-12)).max()) if nb else 1.0
        # damping: c = k h / 2 on the springs; mass-proportional alpha as an
        # exact exponential decay over a force interval
        c = 0.5 * h * kb
        self.body_alpha = self.alpha[self.body_bone]
        self.body_mass = lm
        # Chipmunk corrects 10 % of a joint's position error per 1/60 s by
        # default; fast spins drift pivots apart faster (the velocity
        # constraint is linear), so correct a fraction per substep instead
        error_bias = (1.0 - q.joint_correction) ** (1.0 / h)
        self.bodies: list[pymunk.Body] = []
        self.joints: list[list] = []
        static = space.static_body
        for i in range(nb):
            body = pymunk.Body(float(lm[i]), float(self.i_eff[i]))
            # the centre of gravity first: Chipmunk keeps the COG's world
            # position when it is set, so setting it after the position
            # would move the body's origin (the pivot) by -cog
            body.center_of_gravity = tuple((self.cog2d0[i] - self.q0[i]).tolist())
            body.position = tuple(self.q0[i].tolist())
            space.add(body)
            self.bodies.append(body)
            other = self.bodies[prev[i]] if prev[i] >= 0 else static
            b = int(self.body_bone[i])
            pivot = pymunk.PivotJoint(other, body, tuple(self.q0[i].tolist()))
            spring = pymunk.DampedRotarySpring(other, body, float(self.rest[i]), float(self.k[b]),
                                               float(c[i]))
            limit = pymunk.RotaryLimitJoint(other, body, -float(self.cone[b]),
                                            float(self.cone[b]))
            pivot.error_bias = limit.error_bias = error_bias
            space.add(pivot, spring, limit)
            self.joints.append([pivot, spring, limit])
        self.state = np.zeros((nb, 6))  # x, y, angle, vx, vy, w (pymunk's own order)
        self._buffers()

    def _prestress(self) -> np.ndarray:
        """Spring rest angles that hold every chain in its grown shape under
        gravity: each joint's rest angle is the gravity torque of everything
        outboard of it (lumped) over k. DampedRotarySpring drives
        (a.angle - b.angle) to the rest angle, a being the previous body."""
        g = self.loads.g
        rest = np.zeros(len(self.body_bone))
        g2d = np.stack([self.body_e @ g, self.body_d @ g], 1)
        first = self.chain_first[self.bone_chain[self.body_bone]]
        origin = self.pivot0[first]
        rel = self.true_cog0[self.body_bone] - origin
        cog2d = np.stack([(rel * self.body_e).sum(1), (rel * self.body_d).sum(1)], 1)
        lm = self.true_mass[self.body_bone]
        for ci, bones in enumerate(self.chain_bones):
            for k in range(len(self.chain_planes[ci])):
                idx = np.asarray([self.body_of[(int(b), k)] for b in bones])
                fx, fy = lm[idx] * g2d[idx, 0], lm[idx] * g2d[idx, 1]
                cx, cy = cog2d[idx, 0], cog2d[idx, 1]
                sfx = np.cumsum(fx[::-1])[::-1]
                sfy = np.cumsum(fy[::-1])[::-1]
                smo = np.cumsum((cx * fy - cy * fx)[::-1])[::-1]
                px, py = self.q0[idx, 0], self.q0[idx, 1]
                torque = smo - (px * sfy - py * sfx)  # about each pivot, CCW positive
                rest[idx] = torque / self.k[bones]
        return rest

    def _buffers(self) -> None:
        """Map pymunk's body order (it changes when bodies are removed) to ours."""
        buf = batch.Buffer()
        batch.get_space_bodies(self.space, batch.BodyFields.BODY_ID, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp)
        index = {body.id: i for i, body in enumerate(self.bodies)}
        self.row_of_body = np.full(len(self.bodies), -1, dtype=np.int64)
        for row, bid in enumerate(ids.tolist()):
            i = index.get(bid)
            if i is not None:
                self.row_of_body[i] = row
        self.in_space = self.row_of_body >= 0
        self.live_rows = self.row_of_body[self.in_space]
        self.read_buf = batch.Buffer()
        # the static body is an extra row once a constraint uses it
        self.force_rows = np.zeros((len(ids), 3))
        self.write_buf = batch.Buffer()
        self.write_buf.set_float_buf(self.force_rows)

    # ------------------------------------------------------------------
    # state

    def read(self) -> None:
        self.read_buf.clear()
        batch.get_space_bodies(self.space, batch.BodyFields.POSITION | batch.BodyFields.ANGLE
                               | batch.BodyFields.VELOCITY | batch.BodyFields.ANGULAR_VELOCITY,
                               self.read_buf)
        rows = np.frombuffer(self.read_buf.float_buf()).reshape(-1, 6)
        self.state[self.in_space] = rows[self.live_rows]

    def reconstruct(self) -> dict:
        """3D pose and velocity of every bone from the 2D chains, level by
        level from the roots (children ride on their parents); debris bones
        from their rigid bodies."""
        n, s = self.n, self.state
        b0, b1, two = self.plane_rows
        # plane 0 of every bone, plus plane 1 where a bone has one; the axial
        # (d) part is simulated in every plane: average it
        disp = s[:, 0:2] - self.q0
        rho = s[b0, 2:3] * self.body_n[b0]
        off = disp[b0, 0:1] * self.body_e[b0]
        vrel = s[b0, 3:4] * self.body_e[b0]
        wrel = s[b0, 5:6] * self.body_n[b0]
        axial = disp[b0, 1:2]
        v_axial = s[b0, 4:5]
        if len(two):
            c = b1[two]
            rho[two] += s[c, 2:3] * self.body_n[c]
            off[two] += disp[c, 0:1] * self.body_e[c]
            vrel[two] += s[c, 3:4] * self.body_e[c]
            wrel[two] += s[c, 5:6] * self.body_n[c]
            axial[two] = 0.5 * (axial[two] + disp[c, 1:2])
            v_axial[two] = 0.5 * (v_axial[two] + s[c, 4:5])
        off += axial * self.body_d[b0]
        vrel += v_axial * self.body_d[b0]
        own = matrices_from_rotvec(rho)
        rot = np.empty((n, 3, 3))
        pivot = np.empty((n, 3))
        vcog = np.empty((n, 3))
        omega = np.empty((n, 3))
        frame_rot = np.empty((n, 3, 3))
        attach = np.empty((n, 3))
        cog = np.empty((n, 3))
        vec = np.empty((n, 3))  # each bone's pivot-to-tip vector
        for lv in self.levels:
            bones, has, pp = lv["bones"], lv["has"], lv["pp"]
            rp = np.broadcast_to(EYE, (len(bones), 3, 3)).copy()
            at = lv["attach_rest"].copy()
            if lv["any"]:
                rp[has] = rot[pp]
                at[has] = pivot[pp] + apply(rot[pp], lv["attach_arm"])
            frame_rot[bones] = rp
            attach[bones] = at
            r = compose(rp, own[bones])
            rot[bones] = r
            # pivots: each row's head from its own state, the rest follow the chain
            grid, valid = lv["grid"], lv["valid"]
            h = lv["head_pos"]
            heads = lv["heads"]
            head = at[h] + apply(rp[h], lv["head_arm"] + off[heads])
            step = np.zeros(grid.shape + (3,))
            vec[bones] = step[valid] = apply(r, lv["step"])
            piv = head[:, None, :] + np.cumsum(step, axis=1) - step
            pivot[bones] = piv[valid]
            c = cog[bones] = pivot[bones] + apply(r, lv["cog_arm"])
            v = apply(rp, vrel[bones])
            w = apply(rp, wrel[bones])
            if lv["any"]:
                v[has] += vcog[pp] + cross(omega[pp], c[has] - cog[pp])
                w[has] += omega[pp]
            vcog[bones] = v
            omega[bones] = w
        if self.debris.count:
            d = self.debris.bones
            rot[d], pivot[d], vcom_d, omega[d] = self.debris.bone_poses()
            frame_rot[d] = EYE
            vec[d] = apply(rot[d], self.tip0[d] - self.pivot0[d])
        com = pivot + apply(rot, self.com0 - self.pivot0)
        vcom = vcog + cross(omega, com - cog)
        if self.debris.count:
            vcom[d] = vcom_d
            vcog[d] = vcom_d  # debris bones carry no lumped children
            cog[d] = com[d]
        return {"rot": rot, "pivot": pivot, "cog": cog, "com": com, "vcog": vcog, "vec": vec,
                "vcom": vcom, "omega": omega, "frame_rot": frame_rot, "attach": attach}

    # ------------------------------------------------------------------
    # loads

    def forces(self, t: float, pose: dict, prev: dict | None, since: float, dt: float) -> None:
        """Evaluate all loads at time t and write them into the force buffer,
        to be held for the next `dt` s; `prev` is the pose `since` s ago.
        Steps the debris over `dt` with them."""
        n = self.n
        rot, com, cog = pose["rot"], pose["com"], pose["cog"]
        axis = pose["vec"] / np.maximum(self.length, 1e-12)[:, None]
        force = self.loads.forces(t, com, pose["vcom"], axis, self.props, dt=dt)
        pulls = self.bones.pull_forces(t)
        if pulls is not None:
            force += pulls
        limited = self.stats.limited
        force = cap_loads(force, self.mass, t, self.stats, self.locate)
        hits = self.projectiles.hits if self.projectiles is not None else 0
        if self.projectiles is not None:  # impulses on hit bones, both ways
            self.projectiles.advance(t, dt, pose, self)
        # an impulsive load (a blast front, a hit, a capped load) spins parts
        # fast, and pivots drift by about (omega h)^2 r per step: step finer
        # meanwhile, and while anything spins fast, so that no body turns
        # more than REFINE_SPIN per step (up to MAX_REFINE steps a substep)
        spin = float(np.abs(self.state[self.in_space, 5]).max(initial=0.0))
        impulsive = self.loads.blast_active or self.stats.limited > limited or (
            self.projectiles is not None and self.projectiles.hits > hits)
        self.refine = int(min(MAX_REFINE, max(REFINE if impulsive else 1,
                                              math.ceil(spin * self.h / REFINE_SPIN))))
        if self.debris.count:
            self.debris.step(dt, lambda c, v, ax: self._debris_loads(t, c, v, ax, dt))
            force[self.debris.bones] = 0.0
        # Lumped: a body also carries the loads of the chains attached to it,
        # as if they were rigid: each acts where its COM would be if rigid.
        # (At their actual, swinging positions the parent would get the
        # gravity half of their reaction without the inertial half, a partial
        # coupling that pumps energy into hanging twigs.)
        ftot = force.copy()
        torque = cross(com - cog, force)  # about each lumped COG
        if len(self.pair_anc):
            a, d = self.pair_anc, self.pair_dsc
            rigid = pose["pivot"][a] + apply(rot[a], self.com0[d] - self.pivot0[a])
            pair_torque = cross(rigid - cog[a], force[d])
            for ax in range(3):
                ftot[:, ax] += np.bincount(a, force[d, ax], minlength=n)
                torque[:, ax] += np.bincount(a, pair_torque[:, ax], minlength=n)
        if self.scene.ground:
            contact = self._ground(pose, dt)
            if contact is not None:
                self._add_contact(contact, pose, ftot, torque)
        bb = self.body_bone
        f_b, t_b = ftot[bb], torque[bb]
        fr = pose["frame_rot"][bb]
        frame = self.bone_frame[bb]
        moving = (frame >= 0) & ~self.in_debris[bb]
        if prev is not None and moving.any():
            # d'Alembert forces of the parent bone's accelerating frame
            p = frame[moving]
            child = bb[moving]
            acc = (pose["vcog"][p] - prev["vcog"][p]) / since
            alpha = (pose["omega"][p] - prev["omega"][p]) / since
            w = pose["omega"][p]
            r = cog[child] - cog[p]
            v_rel = pose["vcog"][child] - pose["vcog"][p] - cross(w, r)
            a_frame = (acc + cross(alpha, r) + cross(w, cross(w, r))
                       + 2 * cross(w, v_rel))
            f_b[moving] -= self.lump_mass[child][:, None] * a_frame
            n_world = apply(fr[moving], self.body_n[moving])
            t_b[moving] -= (self.i_n[moving] * (alpha * n_world).sum(1))[:, None] * n_world
        f_loc = apply_transposed(fr, f_b)
        t_loc = apply_transposed(fr, t_b)
        # structural damping on the motion relative to the frame (pymunk's
        # velocities): C = alpha M, as an exact decay over the interval, so
        # that stiff, fast limbs can never overshoot
        s = self.state
        decay = -np.expm1(-self.body_alpha * dt) / dt
        fx = (f_loc * self.body_e).sum(1) - decay * self.body_mass * s[:, 3]
        fy = (f_loc * self.body_d).sum(1) - decay * self.body_mass * s[:, 4]
        tz = (t_loc * self.body_n).sum(1) - decay * self.i_eff * s[:, 5]
        out = self.force_rows
        out[:] = 0.0
        live = self.in_space
        out[self.live_rows, 0] = fx[live]
        out[self.live_rows, 1] = fy[live]
        out[self.live_rows, 2] = tz[live]

    def _debris_loads(self, t: float, com: np.ndarray, vcom: np.ndarray, axis: np.ndarray,
                      dt: float) -> np.ndarray:
        """Loads on the debris bones (gravity, air, blasts), capped."""
        d = self.debris.bones
        props = BoneProps(*(getattr(self.props, f)[d] for f in
                            ("mass", "wood_area", "leaf_area", "diameter", "cd_wood", "cd_leaf")))
        force = self.loads.forces(t, com, vcom, axis, props)
        return cap_loads(force, self.mass[d], t, self.stats, lambda i: self.locate(int(d[i])))

    def _add_contact(self, contact, pose: dict, ftot: np.ndarray, torque: np.ndarray) -> None:
        """Add ground contact forces to the touching bones and, through
        their joints, to every body they hang on (a crown propping up a
        fallen stem), each at the actual contact point."""
        owner, point, f = contact
        n, cog = self.n, pose["cog"]
        bones = [owner]
        points = [point]
        forces = [f]
        up = self.bone_frame[owner]
        idx = np.arange(len(owner))
        while True:
            keep = up >= 0
            if not keep.any():
                break
            idx, up = idx[keep], up[keep]
            bones.append(up)
            points.append(point[idx])
            forces.append(f[idx])
            up = self.bone_frame[up]
        b = np.concatenate(bones)
        p = np.concatenate(points)
        fc = np.concatenate(forces)
        tq = cross(p - cog[b], fc)
        for ax in range(3):
            ftot[:, ax] += np.bincount(b, fc[:, ax], minlength=n)
            torque[:, ax] += np.bincount(b, tq[:, ax], minlength=n)

    def _ground(self, pose: dict, dt: float):
        """Ground contacts of the chain bones: every bone's tip, and the
        base of every bone no longer held by its joint (a root bone's base
        is its anchor, not a contact); debris handles its own. Returns the
        touching bones, the contact points and the forces, or None."""
        tips = pose["pivot"] + apply(pose["rot"], self.tip0 - self.pivot0)
        loose = np.nonzero(~self.joint_alive)[0]
        ends = np.concatenate([tips, pose["pivot"][loose]])
        owner = np.concatenate([np.arange(self.n), loose])
        low = ends[:, 2] < self.radius[owner] + CONTACT_MARGIN
        near = (ends[:, 2] < self.radius[owner]) & ~self.in_debris[owner]
        self.contact_active = bool((low & ~self.in_debris[owner]).any())
        if not near.any():
            return None
        ends, owner = ends[near], owner[near]
        arm = ends - pose["cog"][owner]
        vel = pose["vcog"][owner] + cross(pose["omega"][owner], arm)
        m_eff = effective_mass(self.lump_mass[owner], self.i_eff[self.body_of_bone0[owner]], arm)
        f = ground_forces(ends, vel, self.radius[owner], m_eff, dt)
        return owner, ends, f

    def apply_impulse(self, bone: int, impulse: np.ndarray, point: np.ndarray,
                      pose: dict) -> None:
        """Apply a world impulse (N s) at a world point to a bone."""
        if self.in_debris[bone]:
            self.debris.impulse(int(np.nonzero(self.debris.bones == bone)[0][0]), impulse,
                                point)
            return
        fr = pose["frame_rot"][bone]
        j = fr.T @ impulse
        x = fr.T @ (point - pose["attach"][bone])
        for k in range(self.planes_of_bone[bone]):
            i = self.body_of[(bone, k)]
            e, d = self.body_e[i], self.body_d[i]
            self.bodies[i].apply_impulse_at_world_point((float(j @ e), float(j @ d)),
                                                        (float(x @ e), float(x @ d)))

    # ------------------------------------------------------------------
    # events: breaking and felling

    def check_breaks(self, t: float, pose: dict) -> None:
        """Break every joint whose bending moment exceeds its strength: the
        spring's moment in each plane, plus the cone limit's when engaged."""
        cand = np.nonzero(self.breakable)[0]
        if not len(cand):
            return
        s = self.state
        j = self.prev_body[cand]
        rel = s[cand, 2] - np.where(j >= 0, s[np.maximum(j, 0), 2], 0.0)
        moment = self.k[self.body_bone[cand]] * (rel + self.rest[cand])
        at_limit = np.abs(rel) > 0.98 * self.cone[self.body_bone[cand]]
        for i in np.nonzero(at_limit)[0]:
            limit = self.joints[cand[i]][LIMIT]
            if limit is not None:
                moment[i] += math.copysign(limit.impulse / self.h, moment[i])
        bones = self.body_bone[cand]
        total = np.sqrt(np.bincount(bones, moment * moment, minlength=self.n))
        over = np.nonzero((total > self.strength) & self.joint_alive & ~self.in_debris)[0]
        for b in over:
            if self.joint_alive[b] and not self.in_debris[b]:
                self.break_joint(int(b), t, pose, f"broke ({total[b]:.0f} N m > strength "
                                                  f"{self.strength[b]:.0f} N m)")

    def _remove_joint(self, body: int, which: tuple[int, ...] = (PIVOT, SPRING, LIMIT)) -> None:
        if PIVOT in which:
            self.pivot_alive[body] = False
        for w in which:
            c = self.joints[body][w]
            if c is not None:
                self.space.remove(c)
                self.joints[body][w] = None

    def break_joint(self, bone: int, t: float, pose: dict, why: str) -> None:
        """Remove the joint at a bone's base. In a root chain the part above
        falls on as a free planar chain; elsewhere the broken-off part (with
        everything it carries) becomes rigid debris."""
        self.joint_alive[bone] = False
        tree = self.locate(bone)[0]
        path = self.bone_path(bone)
        self.events.append((t, tree, f"{path}: {why}"))
        self.stats.broken += 1
        freed = self._outboard(bone)
        if self.parent[bone] < 0:  # uprooted
            self._rigid_lumps(int(self.bone_tree[bone]))
        if self.bone_frame[bone] < 0:
            for k in range(self.planes_of_bone[bone]):
                i = self.body_of[(bone, k)]
                self._remove_joint(i)
                self.breakable[i] = False
            self.row_start[bone] = True
            self._layout()
            self._fall_plane(self.chain_bones[self.bone_chain[bone]][freed[
                self.chain_bones[self.bone_chain[bone]]]])
        else:
            self._to_debris(freed, pose)
        self._unload(freed)

    def _fall_plane(self, bones: np.ndarray) -> None:
        """A stem that falls free turns through a large angle: two planes
        only combine small rotations, so from here it moves in its first
        plane (the load's, or the felling direction) alone; the small
        deflection it had in the other plane is dropped."""
        for b in bones:
            for k in range(1, self.planes_of_bone[b]):
                i = self.body_of[(int(b), k)]
                self._remove_joint(i)
                self.breakable[i] = False
                if self.in_space[i]:
                    self.space.remove(self.bodies[i])
                self.state[i] = [*self.q0[i], 0.0, 0.0, 0.0, 0.0]
            self.planes_of_bone[b] = 1
        b0, b1, _ = self.plane_rows
        b1 = b1.copy()
        b1[bones] = -1
        self.plane_rows = (b0, b1, np.nonzero(b1 >= 0)[0])
        self._buffers()

    def _outboard(self, bone: int) -> np.ndarray:
        """A bone and every bone it carries (later in its chain, and their
        attached chains)."""
        freed = np.zeros(self.n, dtype=bool)
        freed[bone] = True
        chain = self.chain_bones[self.bone_chain[bone]]
        freed[chain[np.nonzero(chain == bone)[0][0]:]] = True
        for b in range(bone + 1, self.n):  # parents precede children
            if not freed[b] and self.parent[b] >= 0 and freed[self.parent[b]]:
                freed[b] = True
        return freed

    def _to_debris(self, freed: np.ndarray, pose: dict, asleep: bool = False) -> None:
        bones = np.nonzero(freed & ~self.in_debris)[0]
        self.debris.add(bones, pose, asleep)
        self.in_debris[bones] = True
        self.stats.debris += 1
        for b in bones:
            for k in range(self.planes_of_bone[b]):
                i = self.body_of[(int(b), k)]
                self._remove_joint(i)
                self.breakable[i] = False
                if self.in_space[i]:
                    self.space.remove(self.bodies[i])
        self._buffers()

    def _unload(self, freed: np.ndarray) -> None:
        """The freed part no longer loads the chains it hung on: drop it from
        their lumps and load pairs."""
        keep = ~(freed[self.pair_dsc] & ~freed[self.pair_anc])
        changed = np.unique(self.pair_anc[~keep])
        self.pair_anc, self.pair_dsc = self.pair_anc[keep], self.pair_dsc[keep]
        self.pair_weight = self.pair_weight[keep]
        self._lump()
        for a in changed:
            self._relump(int(a))
        self._refresh_cog()

    def _relump(self, bone: int) -> None:
        """Give a body its new lumped mass after part of what it carried went."""
        cog, total = self.lump_cog0[bone], self.lump_mass[bone]
        for k in range(self.planes_of_bone[bone]):
            i = self.body_of[(bone, k)]
            body = self.bodies[i]
            e, dd = self.body_e[i], self.body_d[i]
            origin2d = self.pivot0[self.chain_first[self.bone_chain[bone]]]
            c2 = np.array([(cog - origin2d) @ e, (cog - origin2d) @ dd])
            floored = self.i_eff[i] > self.i_n[i]
            self.i_n[i] = float(self.body_n[i] @ self.lump_inertia[bone] @ self.body_n[i])
            if not floored:
                self.i_eff[i] = self.i_n[i]
            self.body_mass[i] = total
            body.mass = float(total)
            body.moment = float(self.i_eff[i])
            origin = body.position  # setting the COG moves the origin: restore it
            body.center_of_gravity = tuple((c2 - self.q0[i]).tolist())
            body.position = origin

    def settle(self, t: float, pose: dict, dt: float) -> None:
        """Put trees at rest to sleep, as one sleeping rigid body each: a
        fallen tree (stem off its root) slower than SETTLE_SPEED for
        SLEEP_TIME (lying on the ground it would keep the solver at contact
        rate), and a standing one slower than STILL_SPEED once no load that
        changes will reach it again (after a blast, a pull, a passing gust
        front)."""
        for ti in range(len(self.trees)):
            bones = np.arange(self.offsets[ti], self.offsets[ti + 1])
            awake = bones[~self.in_debris[bones]]
            if not len(awake):
                continue
            roots = bones[self.parent[bones] < 0]
            fallen = not self.joint_alive[roots].any()
            if fallen:
                limit = SETTLE_SPEED
            elif t >= self.quiet[ti] and self.trees[ti].cut is None:
                limit = STILL_SPEED
            else:
                self.still_time[ti] = 0.0
                continue
            speed = max(np.abs(pose["vcom"][awake]).max(), np.abs(pose["omega"][awake]).max())
            self.still_time[ti] = self.still_time[ti] + dt if speed < limit else 0.0
            if self.still_time[ti] > SLEEP_TIME:
                freed = np.zeros(self.n, dtype=bool)
                freed[awake] = True
                self._to_debris(freed, pose, asleep=True)
                what = "came to rest on the ground" if fallen else "at rest: asleep"
                self.events.append((t, self.trees[ti].name, what))

    def _nudge(self, root: int, w: float) -> None:
        """Turn a root chain (plane 0) as one rigid body about its pivot at
        `w` rad/s (negative tips the top toward +e): every body gets the
        velocity of that rotation, so the push is not undone by the joints."""
        pivot = self.bodies[self.body_of[(root, 0)]].position
        for b in self.chain_bones[self.bone_chain[root]]:
            body = self.bodies[self.body_of[(int(b), 0)]]
            cog = body.local_to_world(body.center_of_gravity)
            body.angular_velocity = w
            body.velocity = (-w * (cog.y - pivot.y), w * (cog.x - pivot.x))

    def _rigid_lumps(self, tree: int) -> None:
        """A falling tree turns as one body, not about its sway frequency: its
        children's apparent mass (a sway quantity) gives way to plain rigid
        lumping, or the fall would be slowed by their extra inertia."""
        lo, hi = self.offsets[tree], self.offsets[tree + 1]
        mine = (self.pair_anc >= lo) & (self.pair_anc < hi)
        if not mine.any() or np.all(self.pair_weight[mine] == 1.0):
            return
        self.pair_weight = np.where(mine, 1.0, self.pair_weight)
        self._lump()
        for a in np.unique(self.pair_anc[mine]):
            self._relump(int(a))
        self._refresh_cog()

    def handle_cuts(self, t: float) -> None:
        """Felling: at the cut the root joints lose spring and cone (the
        hinge holds) and the tree is nudged toward the felling direction;
        past `hinge` degrees of lean the hinge snaps and it falls free."""
        for ti, tree in enumerate(self.trees):
            cut = tree.cut
            if cut is None:
                continue
            roots = [int(self.chain_bones[ci][0]) for ci in range(len(self.chain_bones))
                     if self.chain_tree[ci] == ti and self.chain_parent[ci] < 0]
            state = self.cut_state.get(ti, "standing")
            if state == "standing" and t >= cut.time:
                self._rigid_lumps(ti)
                for b in roots:
                    # plane 0 contains the felling direction: the notch frees
                    # it; sideways (plane 1) the hinge wood still holds
                    i = self.body_of[(b, 0)]
                    self._remove_joint(i, (SPRING, LIMIT))
                    for k in range(self.planes_of_bone[b]):
                        self.breakable[self.body_of[(b, k)]] = False
                    self._nudge(b, FELL_NUDGE)
                self.cut_state[ti] = "hinged"
                self.events.append((t, tree.name, "cut at the base"))
            elif state == "hinged":
                lean = max(abs(self.state[self.body_of[(b, 0)], 2]) for b in roots)
                if lean > math.radians(cut.hinge):
                    for b in roots:
                        self.joint_alive[b] = False
                        for k in range(self.planes_of_bone[b]):
                            self._remove_joint(self.body_of[(b, k)])
                        self._fall_plane(self.chain_bones[self.bone_chain[b]])
                    self.cut_state[ti] = "falling"
                    self.events.append((t, tree.name, "hinge snapped"))

    # ------------------------------------------------------------------
    # checks and names

    def check(self, t: float) -> None:
        """Stop with a clear message when the state is not finite, or when a
        body spins faster than any part of a tree could (MAX_ANGULAR_SPEED)."""
        s = self.state
        bad = self.in_space & (~np.isfinite(s).all(1) | (np.abs(s[:, 5]) > MAX_ANGULAR_SPEED))
        if self.debris.count:
            wild = ~np.isfinite(self.debris.x).all(1)
            if wild.any():
                b = int(self.debris.bones[self.debris.owner == np.nonzero(wild)[0][0]][0])
                tree, seg = self.locate(b)
                raise SimulationError("non-finite debris state", tree, seg, t)
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            tree, seg = self.locate(int(self.body_bone[i]))
            what = ("non-finite state" if not np.isfinite(s[i]).all() else
                    f"angular speed {abs(s[i, 5]):.0f} rad/s > {MAX_ANGULAR_SPEED:.0f}")
            raise SimulationError(f"{what} (unstable; try a finer quality)", tree, seg, t)

    def joint_gap(self) -> float:
        """Largest separation of a live pivot, as a fraction of the mean
        length of the two bones it joins."""
        live = self.in_space & self.pivot_alive
        if not live.any():
            return 0.0
        prev = self.prev_body
        length = self.length[self.body_bone].copy()
        has = prev >= 0
        length[has] = 0.5 * (length[has] + length[prev[has]])
        gaps = chain_gaps(self.state, prev, self.q0, length)
        return float(gaps[live].max())

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index (in that tree) of a global bone."""
        return locate(self.trees, self.offsets, self.bone_tree, bone)

    def bone_path(self, bone: int) -> str:
        ti = int(self.bone_tree[bone])
        return self.trees[ti].rig.model.segment_paths()[self.locate(bone)[1]]

    # ------------------------------------------------------------------
    # running

    def run(self, progress=None) -> list[TreeMotion]:
        """Simulate the scene; per tree, the bones' motion at every frame."""
        scene = self.scene
        frames = scene.frame_count
        n = self.n
        quats = np.zeros((frames, n, 4))
        pivots = np.zeros((frames, n, 3))
        self.events: list[tuple[float, str, str]] = []
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
            events = [f"t = {et:.3f} s: {msg}" for et, name, msg in self.events
                      if name == tree.name]
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
