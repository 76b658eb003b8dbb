"""The planar LOD: each limb is a 2D pymunk chain in its own bending plane.

Design (docs/physics.md has the derivations and measurements):

- One pymunk body per bone and plane, a `PivotJoint` at each junction, a
  `DampedRotarySpring` toward the rest angle and a `RotaryLimitJoint` for the
  cone. With `planes = 2` a limb bends in two perpendicular planes whose
  deflections combine into a 3D rotation without twist.
- The plane of a limb contains its chord d and the component of the tree's
  dominant load perpendicular to d (wind, felling or blast direction; gravity
  when the limb lies along it). Projecting positions and forces onto the
  plane makes torques about its normal exact at the rest pose.
- A child limb's chain lives in its parent bone's moving frame: its bodies
  carry their deflection relative to the parent, gravity and air loads are
  rotated into that frame, and the frame's acceleration enters as an
  inertial (d'Alembert) force, so children ride on their parents.
- Child to parent: a parent body carries the mass and inertia of the limbs
  attached to it as if rigid, and the resultant force and moment of their
  loads, so crown mass lowers the trunk's frequency and crown drag bends it.
  The children's own swaying does not push back (one-way coupling); the
  accuracy report measures what that costs against the MuJoCo reference.
- Prestress: spring rest angles are offset so the grown shape is the
  equilibrium under gravity (scene `prestress = true`).
- Stability: pymunk applies the rotary spring explicitly, using only the two
  bodies' own moments of inertia; a joint is stable while
  h * sqrt(k (1/I_a + 1/I_b)) stays below about 1-2. A rotary-inertia floor
  I >= 2 k (h / s)^2 (s = quality.stability) keeps it there at any substep;
  the added inertia and the first-frequency shift it causes are reported.
- Loads, contacts and inertial forces are evaluated with numpy on all bones
  at `force_rate` and held between evaluations; bodies are read and written
  through `pymunk.batch`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pymunk
import pymunk.batch as batch

from ..errors import SimulationError
from ..rig import Rig, subtree_sums
from ..rotations import apply, apply_transposed, compose, matrices_from_rotvec
from ..scene import Quality, Scene
from .common import MAX_ACCELERATION, MAX_ANGULAR_SPEED, SimTree, TreeMotion
from .loads import BoneProps, SceneLoads
from .projectiles import Projectiles

EYE = np.eye(3)


@dataclass
class Stats:
    substeps: int = 0
    updates: int = 0
    bodies: int = 0
    bones: int = 0
    step_seconds: float = 0.0
    update_seconds: float = 0.0
    inertia_floored: int = 0
    max_inertia_ratio: float = 1.0
    max_joint_gap: float = 0.0  # largest pivot separation / bone length seen at a frame
    limited: int = 0  # bone updates whose load was capped at MAX_ACCELERATION
    first_limit: tuple | None = None  # (tree, segment, time s, acceleration m/s^2)
    notes: list[str] = field(default_factory=list)


def _perp(v: np.ndarray, d: np.ndarray) -> np.ndarray:
    return v - (v @ d) * d


def plane_basis(d: np.ndarray, load: np.ndarray | None) -> np.ndarray:
    """In-plane bending direction e (unit, perpendicular to d) for a limb
    with chord direction d under a dominant horizontal load direction."""
    for cand in (load, np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]),
                 np.array([0.0, 1.0, 0.0])):
        if cand is None:
            continue
        e = _perp(np.asarray(cand, dtype=float), d)
        n = np.linalg.norm(e)
        if n > 0.25:
            return e / n
    raise AssertionError("no perpendicular found")  # pragma: no cover


class PlanarSolver:
    """Simulate trees of one scene with the planar LOD."""

    def __init__(self, trees: list[SimTree], scene: Scene, quality: Quality, loads: SceneLoads,
                 log=None):
        self.scene = scene
        self.quality = quality
        self.two_way = False  # see _flex_reaction; chosen by the accuracy report
        self.loads = loads
        self.log = log or (lambda msg: None)
        self.trees = trees
        self.stats = Stats()
        fps = scene.fps
        self.spf = max(1, int(round(quality.substep_rate / fps)))
        self.h = 1.0 / (fps * self.spf)
        want = max(1, int(round(self.spf * fps / quality.force_rate)))
        divisors = [d for d in range(1, self.spf + 1) if self.spf % d == 0]
        self.update_every = min(divisors, key=lambda d: (abs(d - want), d))
        self.dt_update = self.h * self.update_every
        self._build()

    # ------------------------------------------------------------------
    # construction

    def _build(self) -> None:
        trees = [t for t in self.trees if t.active]
        offs = np.cumsum([0] + [t.rig.n_bones for t in trees])
        self.tree_offsets = offs
        self.active_trees = trees
        cat = lambda f: np.concatenate([f(t.rig) for t in trees]) if trees else np.zeros(0)  # noqa: E731
        n = int(offs[-1])
        self.n = n
        self.pivot0 = cat(lambda r: r.pivot).reshape(n, 3)
        self.tip0 = cat(lambda r: r.tip).reshape(n, 3)
        self.com0 = cat(lambda r: r.com).reshape(n, 3)
        self.mass = cat(lambda r: r.mass)
        self.inertia = cat(lambda r: r.inertia).reshape(n, 3, 3)
        self.k = cat(lambda r: r.k)
        # Spring damping c = k h / 2 gives a mode of frequency w the damping
        # ratio w h / 4: negligible for the sway modes, up to s/4 for the
        # highest chain modes (w h <= s after the inertia floor), which would
        # otherwise ring undamped. Chipmunk applies it as an exact decay.
        self.c = 0.5 * self.h * cat(lambda r: r.k)
        self.alpha = cat(lambda r: r.alpha)
        self.cone = cat(lambda r: r.cone)
        self.strength = cat(lambda r: r.strength)
        self.radius = cat(lambda r: r.radius)
        self.bone_tree = np.concatenate([np.full(t.rig.n_bones, i) for i, t in enumerate(trees)]) \
            if trees else np.zeros(0, dtype=np.int64)
        self.parent = np.concatenate([np.where(t.rig.bone_parent >= 0, t.rig.bone_parent + o, -1)
                                      for t, o in zip(trees, offs)]) if trees else np.zeros(0, int)
        self.props = BoneProps(
            mass=self.mass, wood_area=cat(lambda r: r.wood_area),
            leaf_area=cat(lambda r: r.leaf_area), diameter=2 * self.radius,
            cd_wood=np.concatenate([np.full(t.rig.n_bones, t.rig.drag) for t in trees])
            if trees else np.zeros(0),
            cd_leaf=np.concatenate([np.full(t.rig.n_bones, t.rig.leaf_drag) for t in trees])
            if trees else np.zeros(0))
        self.stats.bones = n

        # limbs -> chains (one per plane)
        self.limb_parent: list[int] = []  # bone the limb hangs on, -1 ground
        self.limb_bones: list[np.ndarray] = []
        self.limb_tree: list[int] = []
        self.limb_d: list[np.ndarray] = []
        self.limb_e: list[list[np.ndarray]] = []
        self.bone_limb = np.empty(n, dtype=np.int64)
        self.bone_index = np.empty(n, dtype=np.int64)  # position within its limb
        for ti, (t, o) in enumerate(zip(trees, offs)):
            load = t.load_direction
            for limb in t.rig.limbs:
                bones = np.asarray(limb.bones) + o
                li = len(self.limb_bones)
                self.limb_bones.append(bones)
                self.limb_parent.append(limb.parent_bone + o if limb.parent_bone >= 0 else -1)
                self.limb_tree.append(ti)
                self.bone_limb[bones] = li
                self.bone_index[bones] = np.arange(len(bones))
                chord = self.tip0[bones[-1]] - self.pivot0[bones[0]]
                if np.linalg.norm(chord) < 1e-6:
                    chord = self.tip0[bones[0]] - self.pivot0[bones[0]]
                d = chord / max(np.linalg.norm(chord), 1e-12)
                if np.linalg.norm(chord) < 1e-9:
                    d = np.array([0.0, 0.0, 1.0])
                e1 = plane_basis(d, load)
                es = [e1] if t.planes == 1 else [e1, np.cross(e1, d)]
                self.limb_d.append(d)
                self.limb_e.append(es)
        self._lumping()
        self._levels()
        self._space()
        self._pulls(trees, offs)

    def _pulls(self, trees: list[SimTree], offs: np.ndarray) -> None:
        """Rope pulls: each acts on the bone of the tree's first root limb
        that spans `at` x the tree height."""
        self.pull_list = []
        for t, o in zip(trees, offs):
            if not t.pulls:
                continue
            rig = t.rig
            for pull in t.pulls:
                bone = rig.stem_bone_at(pull.at)
                self.pull_list.append((int(bone + o), np.asarray(pull.force, dtype=float),
                                       pull.ramp, pull.release))

    def pull_forces(self, t: float) -> np.ndarray | None:
        """World force (N) of active pulls on each bone, or None."""
        active = [(b, f, ramp, rel) for b, f, ramp, rel in self.pull_list if t < rel]
        if not active:
            return None
        out = np.zeros((self.n, 3))
        for b, f, ramp, _ in active:
            out[b] += f * (min(1.0, t / ramp) if ramp > 0 else 1.0)
        return out

    def _lumping(self) -> None:
        """Lumped body properties (bone + child limbs, rigid) and the pairs
        (ancestor attach bone, bone) that carry loads up the hierarchy."""
        n = self.n
        m, c = self.mass, self.com0
        j_own = self.inertia + m[:, None, None] * (
            (c * c).sum(1)[:, None, None] * EYE - c[:, :, None] * c[:, None, :])
        sub_m = subtree_sums(self.parent, m)
        sub_mc = subtree_sums(self.parent, m[:, None] * c)
        sub_j = subtree_sums(self.parent, j_own.reshape(n, 9)).reshape(n, 3, 3)
        lm, lmc, lj = m.copy(), m[:, None] * c, j_own.copy()
        child_first = [b for b in range(n) if self.parent[b] >= 0
                       and self.bone_limb[self.parent[b]] != self.bone_limb[b]]
        for b in child_first:
            p = self.parent[b]
            lm[p] += sub_m[b]
            lmc[p] += sub_mc[b]
            lj[p] += sub_j[b]
        self.lump_mass = lm
        self.lump_cog0 = lmc / lm[:, None]
        cg = self.lump_cog0
        self.lump_inertia = lj - lm[:, None, None] * (
            (cg * cg).sum(1)[:, None, None] * EYE - cg[:, :, None] * cg[:, None, :])
        # pairs: every bone's loads also go to each ancestor attach bone
        anc, dsc = [], []
        for b in range(n):
            limb = self.bone_limb[b]
            p = self.limb_parent[limb]
            while p >= 0:
                anc.append(p)
                dsc.append(b)
                p = self.limb_parent[self.bone_limb[p]]
        self.pair_anc = np.asarray(anc, dtype=np.int64)
        self.pair_dsc = np.asarray(dsc, dtype=np.int64)
        order = np.lexsort((self.pair_dsc, self.pair_anc))
        self.pair_anc, self.pair_dsc = self.pair_anc[order], self.pair_dsc[order]

    def _levels(self) -> None:
        """Limbs grouped by depth for level-by-level 3D reconstruction; each
        level keeps a padded (chains x length) layout for per-row cumsums."""
        depth = []
        for li, p in enumerate(self.limb_parent):
            depth.append(0 if p < 0 else depth[self.bone_limb[p]] + 1)
        self.limb_depth = np.asarray(depth)
        self.chain_start = np.zeros(self.n, dtype=bool)  # bone starts a (sub)chain
        for bones in self.limb_bones:
            self.chain_start[bones[0]] = True
        self._layout()

    def _layout(self) -> None:
        """Rows = sub-chains (a limb splits into several when a joint breaks)."""
        levels = []
        for depth in range(int(self.limb_depth.max()) + 1 if len(self.limb_depth) else 0):
            rows = []
            for li in np.nonzero(self.limb_depth == depth)[0]:
                bones = self.limb_bones[li]
                starts = [i for i, b in enumerate(bones) if self.chain_start[b]]
                for a, z in zip(starts, starts[1:] + [len(bones)]):
                    rows.append(bones[a:z])
            width = max(len(r) for r in rows)
            grid = np.full((len(rows), width), -1, dtype=np.int64)
            for i, r in enumerate(rows):
                grid[i, :len(r)] = r
            valid = grid >= 0
            levels.append((grid, valid, grid[valid]))
        self.levels = levels

    def _space(self) -> None:
        q = self.quality
        h = self.h
        space = pymunk.Space()
        space.iterations = q.iterations
        self.space = space
        bodies, body_bone, body_plane = [], [], []
        self.body_e, self.body_n = [], []
        for li, bones in enumerate(self.limb_bones):
            for k, e in enumerate(self.limb_e[li]):
                for b in bones:
                    body_bone.append(b)
                    body_plane.append(k)
        self.body_bone = np.asarray(body_bone, dtype=np.int64)
        self.body_plane = np.asarray(body_plane, dtype=np.int64)
        nb = len(self.body_bone)
        self.stats.bodies = nb
        limb = self.bone_limb[self.body_bone]
        d = np.asarray(self.limb_d)[limb] if nb else np.zeros((0, 3))
        e = np.asarray([self.limb_e[li][k] for li, k in zip(limb, self.body_plane)]) \
            if nb else np.zeros((0, 3))
        self.body_d, self.body_e = d, e
        self.body_n = np.cross(e, d) if nb else np.zeros((0, 3))
        planes_of_bone = np.bincount(self.body_bone, minlength=self.n)
        self.planes_of_bone = np.maximum(planes_of_bone, 1)
        # chain origin: the limb's base (rest)
        origin = self.pivot0[np.asarray([self.limb_bones[li][0] for li in limb], dtype=np.int64)] \
            if nb else np.zeros((0, 3))
        self.body_origin = origin
        rel = lambda p: np.stack([((p - origin) * e).sum(1), ((p - origin) * d).sum(1)], 1)  # noqa: E731
        self.q0 = rel(self.pivot0[self.body_bone])
        self.cog2d0 = rel(self.lump_cog0[self.body_bone])
        lm = self.lump_mass[self.body_bone]
        i_n = np.einsum("bi,bij,bj->b", self.body_n, self.lump_inertia[self.body_bone], self.body_n)
        # gravity prestress: torque about each joint from the chain outboard of it
        g2d = np.stack([(self.loads.g * e).sum(1), (self.loads.g * d).sum(1)], 1)
        self.body_of = {}  # (bone, plane) -> body index
        for i, (b, k) in enumerate(zip(self.body_bone, self.body_plane)):
            self.body_of[(int(b), int(k))] = i
        self.rest = np.zeros(nb)
        if self.scene.prestress:
            for li, bones in enumerate(self.limb_bones):
                for k in range(len(self.limb_e[li])):
                    idx = [self.body_of[(int(b), k)] for b in bones]
                    fx = lm[idx] * g2d[idx, 0]
                    fy = lm[idx] * g2d[idx, 1]
                    cx, cy = self.cog2d0[idx, 0], self.cog2d0[idx, 1]
                    # outboard sums (suffix) of force and moment about the origin
                    sfx = np.cumsum(fx[::-1])[::-1]
                    sfy = np.cumsum(fy[::-1])[::-1]
                    smo = np.cumsum((cx * fy - cy * fx)[::-1])[::-1]
                    px, py = self.q0[idx, 0], self.q0[idx, 1]
                    tau = smo - (px * sfy - py * sfx)  # about each pivot, CCW positive
                    self.rest[idx] = tau / self.k[bones]
        # rotary-inertia floor for stability of the explicit spring
        kb = self.k[self.body_bone]
        kmax = kb.copy()
        nxt = {}
        for li, bones in enumerate(self.limb_bones):
            for k in range(len(self.limb_e[li])):
                for a, b in zip(bones[:-1], bones[1:]):
                    ia, ib = self.body_of[(int(a), k)], self.body_of[(int(b), k)]
                    kmax[ia] = max(kmax[ia], self.k[b])
                    nxt[ib] = ia
        floor = 2.0 * kmax * (h / q.stability) ** 2
        i_eff = np.maximum(i_n, floor)
        i_eff = np.maximum(i_eff, 1e-12)
        self.i_eff, self.i_n = i_eff, i_n
        floored = floor > i_n
        self.stats.inertia_floored = int(floored.sum())
        self.stats.max_inertia_ratio = float((i_eff / np.maximum(i_n, 1e-12)).max()) if nb else 1.0
        c_eff = self.c[self.body_bone]

        # Chipmunk corrects 10 % of a joint's position error per 1/60 s by
        # default; fast spins drift pivots apart faster than that (the
        # velocity constraint is linear), so correct a fraction per substep.
        error_bias = (1.0 - q.joint_correction) ** (1.0 / h)
        self.bodies = []
        self.joints: dict[int, list] = {}  # body index -> [pivot, spring, limit]
        static = space.static_body
        for i in range(nb):
            b = int(self.body_bone[i])
            body = pymunk.Body(float(lm[i]), float(i_eff[i]))
            # the centre of gravity first: Chipmunk keeps the COG's world
            # position when it is set, so setting it after the position
            # would move the body's origin (the pivot) by -cog
            body.center_of_gravity = (float(self.cog2d0[i, 0] - self.q0[i, 0]),
                                      float(self.cog2d0[i, 1] - self.q0[i, 1]))
            body.position = (float(self.q0[i, 0]), float(self.q0[i, 1]))
            space.add(body)
            self.bodies.append(body)
            prev = self.bodies[nxt[i]] if i in nxt else static
            anchor = (float(self.q0[i, 0]), float(self.q0[i, 1]))
            pivot = pymunk.PivotJoint(prev, body, anchor)
            spring = pymunk.DampedRotarySpring(prev, body, float(self.rest[i]), float(self.k[b]),
                                               float(c_eff[i]))
            cone = float(self.cone[b])
            limit = pymunk.RotaryLimitJoint(prev, body, -cone, cone)
            pivot.error_bias = limit.error_bias = error_bias
            space.add(pivot, spring, limit)
            self.joints[i] = [pivot, spring, limit]
        self.prev_body = np.array([nxt.get(i, -1) for i in range(nb)], dtype=np.int64)
        self.pivot_alive = np.ones(nb, dtype=bool)
        self.bone_length = np.linalg.norm(self.tip0 - self.pivot0, axis=1)
        # Damping is held over a force interval: use the rate that brings a
        # velocity to exactly exp(-alpha dt) of itself over the interval, so
        # very stiff (fast, heavily damped) limbs can never overshoot.
        dt = self.dt_update
        alpha = -np.expm1(-self.alpha[self.body_bone] * dt) / dt
        self.alpha_m = alpha * lm
        self.alpha_i = alpha * i_eff
        self._buffers()

    def _buffers(self) -> None:
        """Map pymunk's body order (which changes on removal) to our indices."""
        buf = batch.Buffer()
        batch.get_space_bodies(self.space, batch.BodyFields.BODY_ID, buf)
        ids = np.frombuffer(buf.int_buf(), dtype=np.uintp).copy()
        index = {body.id: i for i, body in enumerate(self.bodies)}
        self.rows = len(ids)
        self.row_of_body = np.full(len(self.bodies), -1, dtype=np.int64)
        for row, bid in enumerate(ids):
            i = index.get(int(bid))
            if i is not None:
                self.row_of_body[i] = row
        self.in_space = self.row_of_body >= 0
        self.read_buf = batch.Buffer()
        self.force_rows = np.zeros((self.rows, 3))
        self.write_buf = batch.Buffer()
        self.write_buf.set_float_buf(self.force_rows)
        self.state = np.zeros((len(self.bodies), 6))  # x, y, angle, vx, vy, w
        self.frozen_state = None

    # ------------------------------------------------------------------
    # state

    def read(self) -> None:
        buf = self.read_buf
        buf.clear()
        batch.get_space_bodies(self.space, batch.BodyFields.POSITION | batch.BodyFields.ANGLE
                               | batch.BodyFields.VELOCITY | batch.BodyFields.ANGULAR_VELOCITY, buf)
        rows = np.frombuffer(buf.float_buf()).reshape(-1, 6)
        live = self.in_space
        self.state[live] = rows[self.row_of_body[live]]

    def reconstruct(self) -> dict:
        """3D pose and velocity of every bone from the 2D chains, level by
        level from the roots (children ride on their parents)."""
        n, s = self.n, self.state
        bb = self.body_bone
        delta = s[:, 2]
        rho = np.zeros((n, 3))
        for ax in range(3):
            rho[:, ax] = np.bincount(bb, delta * self.body_n[:, ax], minlength=n)
        disp2 = s[:, 0:2] - self.q0  # pivot displacement in the plane
        wy = 1.0 / self.planes_of_bone[bb]
        off = np.zeros((n, 3))
        vrel = np.zeros((n, 3))
        wrel = np.zeros((n, 3))
        # COG velocity in the chain frame: pymunk's velocity is the COG's
        for ax in range(3):
            off[:, ax] = np.bincount(bb, disp2[:, 0] * self.body_e[:, ax]
                                     + wy * disp2[:, 1] * self.body_d[:, ax], minlength=n)
            vrel[:, ax] = np.bincount(bb, s[:, 3] * self.body_e[:, ax]
                                      + wy * s[:, 4] * self.body_d[:, ax], minlength=n)
            wrel[:, ax] = np.bincount(bb, s[:, 5] * self.body_n[:, ax], minlength=n)
        rot = np.empty((n, 3, 3))
        pivot = np.empty((n, 3))
        vcog = np.empty((n, 3))
        omega = np.empty((n, 3))
        frame_rot = np.empty((n, 3, 3))
        attach_all = np.empty((n, 3))
        own = matrices_from_rotvec(rho)
        for grid, valid, bones in self.levels:
            limbs = self.bone_limb[bones]
            pb = np.asarray(self.limb_parent)[limbs]
            has_p = pb >= 0
            rp = np.broadcast_to(EYE, (len(bones), 3, 3)).copy()
            rp[has_p] = rot[pb[has_p]]
            frame_rot[bones] = rp
            first = np.asarray([self.limb_bones[li][0] for li in limbs])
            attach = self.pivot0[first].copy()
            if has_p.any():
                p = pb[has_p]
                attach[has_p] = apply(rot[p], self.pivot0[first[has_p]] - self.pivot0[p]) + pivot[p]
            r = compose(rp, own[bones])
            rot[bones] = r
            attach_all[bones] = attach
            free = attach + apply(rp, self.pivot0[bones] - self.pivot0[first] + off[bones])
            step = apply(r, self.tip0[bones] - self.pivot0[bones])
            g_step = np.zeros(grid.shape + (3,))
            g_step[valid] = step
            g_free = np.zeros(grid.shape + (3,))
            g_free[valid] = free
            cum = np.cumsum(g_step, axis=1) - g_step
            g_piv = g_free[:, :1, :] + cum
            pivot[bones] = g_piv[valid]
            # velocities: parent frame motion at the COG plus motion in the frame
            cog = pivot[bones] + apply(r, self.lump_cog0[bones] - self.pivot0[bones])
            v = apply(rp, vrel[bones])
            w = apply(rp, wrel[bones])
            if has_p.any():
                p = pb[has_p]
                cog_p = pivot[p] + apply(rot[p], self.lump_cog0[p] - self.pivot0[p])
                v[has_p] += vcog[p] + np.cross(omega[p], cog[has_p] - cog_p)
                w[has_p] += omega[p]
            vcog[bones] = v
            omega[bones] = w
        cog = pivot + apply(rot, self.lump_cog0 - self.pivot0)
        com = pivot + apply(rot, self.com0 - self.pivot0)
        vcom = vcog + np.cross(omega, com - cog)
        return {"rot": rot, "pivot": pivot, "cog": cog, "com": com, "vcog": vcog,
                "vcom": vcom, "omega": omega, "frame_rot": frame_rot, "attach": attach_all}

    # ------------------------------------------------------------------
    # forces

    def forces(self, t: float, pose: dict, prev: dict | None) -> None:
        """Evaluate all loads at time t and write them into the force buffer."""
        n = self.n
        rot, com, cog = pose["rot"], pose["com"], pose["cog"]
        axis = apply(rot, self.tip0 - self.pivot0)
        lengths = np.linalg.norm(axis, axis=1, keepdims=True)
        axis = np.divide(axis, lengths, out=np.zeros_like(axis), where=lengths > 0)
        force = self.loads.forces(t, com, pose["vcom"], axis, self.props, dt=self.dt_update)
        pulls = self.pull_forces(t)
        if pulls is not None:
            force += pulls
        force = self._cap(force, t)
        # moment about the world origin of each bone's own loads
        moment = np.cross(com, force)
        if self.scene.ground:
            gf, gm = self._ground(pose)
            if gf is not None:
                force = force + gf
                moment = moment + gm
        if self.projectiles is not None:
            self.projectiles.advance(t, self.dt_update, pose, self)
        # lumped: each body also carries the loads of the limbs attached to it
        ftot, mtot = force.copy(), moment.copy()
        if len(self.pair_anc):
            for ax in range(3):
                ftot[:, ax] += np.bincount(self.pair_anc, force[self.pair_dsc, ax], minlength=n)
                mtot[:, ax] += np.bincount(self.pair_anc, moment[self.pair_dsc, ax], minlength=n)
        torque = mtot - np.cross(cog, ftot)  # about each lumped COG
        if self.two_way and len(self.pair_anc):
            dev_f, dev_m = self._flex_reaction(pose)
            ftot += dev_f
            torque += dev_m
        bb = self.body_bone
        f_b, t_b = ftot[bb], torque[bb]
        # inertial force of the parent's accelerating frame (child chains)
        limb_parent = np.asarray(self.limb_parent)[self.bone_limb[bb]]
        child = limb_parent >= 0
        if prev is not None and child.any():
            p = limb_parent[child]
            acc = (pose["vcog"][p] - prev["vcog"][p]) / self.dt_update
            alpha = (pose["omega"][p] - prev["omega"][p]) / self.dt_update
            w = pose["omega"][p]
            r = cog[bb[child]] - cog[p]
            a_frame = acc + np.cross(alpha, r) + np.cross(w, np.cross(w, r))
            m = self.lump_mass[bb[child]]
            f_b[child] -= m[:, None] * a_frame
            n_world = apply(pose["frame_rot"][bb[child]], self.body_n[child])
            t_b[child] -= (self.i_n[child] * (alpha * n_world).sum(1))[:, None] * n_world
        fr = pose["frame_rot"][bb]
        f_loc = apply_transposed(fr, f_b)
        t_loc = apply_transposed(fr, t_b)
        out = self.force_rows
        out[:] = 0.0
        live = self.in_space
        rows = self.row_of_body[live]
        # structural damping, mass-proportional, on the motion relative to the
        # chain's frame (the body velocities pymunk holds): C = alpha M
        v = self.state
        a_m = self.alpha_m
        out[rows, 0] = ((f_loc * self.body_e).sum(1) - a_m * v[:, 3])[live]
        out[rows, 1] = ((f_loc * self.body_d).sum(1) - a_m * v[:, 4])[live]
        out[rows, 2] = ((t_loc * self.body_n).sum(1) - self.alpha_i * v[:, 5])[live]

    def _cap(self, force: np.ndarray, t: float) -> np.ndarray:
        """Cap each bone's external load at MAX_ACCELERATION x its mass.

        Loads that would accelerate a bone faster (a blast at a few metres,
        thousands of g on a twig) break real wood, and in Chipmunk they pull
        joints apart faster than its iterations can hold them. Capping the
        input keeps the constraints consistent; every cap is counted and
        reported with the first tree, segment and time."""
        acc = np.linalg.norm(force, axis=1) / np.maximum(self.mass, 1e-9)
        over = acc > MAX_ACCELERATION
        if not over.any():
            return force
        idx = np.nonzero(over)[0]
        if not self.stats.limited:
            tree, seg = self.locate(int(idx[0]))
            self.stats.first_limit = (tree, seg, t, float(acc[idx[0]]))
        self.stats.limited += len(idx)
        out = force.copy()
        out[idx] *= (MAX_ACCELERATION / acc[idx])[:, None]
        return out

    def _flex_reaction(self, pose: dict) -> tuple[np.ndarray, np.ndarray]:
        """What the attached limbs' flexing does to the bone they hang on.

        A body carries its child limbs as if rigid (their mass is lumped into
        it, which keeps the coupling stable); the rest of their reaction is
        the rate of change of their momentum relative to that rigid motion:
        F = -dP_rel/dt, M = -dL_rel/dt about the body's COG. Taken as a
        difference over the last force interval (one interval late); the
        feedback gain is m_child / m_lumped < 1, so it stays bounded."""
        a, d = self.pair_anc, self.pair_dsc
        n = self.n
        r = pose["com"][d] - pose["cog"][a]
        v_rigid = pose["vcog"][a] + np.cross(pose["omega"][a], r)
        p_rel = self.mass[d, None] * (pose["vcom"][d] - v_rigid)
        rot = pose["rot"][d]
        dw = pose["omega"][d] - pose["omega"][a]
        spin = apply(rot, np.einsum("bij,bj->bi", self.inertia[d], apply_transposed(rot, dw)))
        l_rel = np.cross(r, p_rel) + spin
        big_p = np.zeros((n, 3))
        big_l = np.zeros((n, 3))
        for ax in range(3):
            big_p[:, ax] = np.bincount(a, p_rel[:, ax], minlength=n)
            big_l[:, ax] = np.bincount(a, l_rel[:, ax], minlength=n)
        prev = self._rel_momentum
        self._rel_momentum = (big_p, big_l)
        if prev is None:
            return np.zeros((n, 3)), np.zeros((n, 3))
        return -(big_p - prev[0]) / self.dt_update, -(big_l - prev[1]) / self.dt_update

    def _ground(self, pose: dict):
        """Penalty contact of bone ends with the ground (z = 0): spring-damper
        normal force, Coulomb friction; stiffness scaled to each bone's mass
        so that the explicit update stays stable."""
        ends = np.concatenate([pose["pivot"], pose["pivot"] + apply(pose["rot"],
                                                                     self.tip0 - self.pivot0)])
        r = np.concatenate([self.radius, self.radius])
        depth = r - ends[:, 2]
        hit = depth > 0
        if not hit.any():
            return None, None
        idx = np.nonzero(hit)[0]
        bone = idx % self.n
        p = ends[idx]
        v = pose["vcog"][bone] + np.cross(pose["omega"][bone], p - pose["cog"][bone])
        m = np.maximum(self.mass[bone], 1e-3)
        omega_c = 0.5 / self.dt_update
        kc = m * omega_c**2
        cc = 2 * 0.7 * m * omega_c
        normal = np.maximum(kc * depth[idx] - cc * v[:, 2], 0.0)
        vt = v[:, :2]
        speed = np.linalg.norm(vt, axis=1)
        friction = np.minimum(0.6 * normal, cc * speed)
        ft = -vt / np.maximum(speed, 1e-9)[:, None] * friction[:, None]
        f = np.zeros((len(idx), 3))
        f[:, :2] = ft
        f[:, 2] = normal
        force = np.zeros((self.n, 3))
        moment = np.zeros((self.n, 3))
        mo = np.cross(p, f)
        for ax in range(3):
            force[:, ax] = np.bincount(bone, f[:, ax], minlength=self.n)
            moment[:, ax] = np.bincount(bone, mo[:, ax], minlength=self.n)
        return force, moment

    # ------------------------------------------------------------------
    # events: breaking and felling

    def joint_moment(self, b_bodies: np.ndarray) -> np.ndarray:
        """Spring moment (N m) at the joints of the given bodies."""
        a = self.state[:, 2]
        prev = self.prev_body[b_bodies]
        rel = a[b_bodies] - np.where(prev >= 0, a[np.maximum(prev, 0)], 0.0)
        # DampedRotarySpring's torque is k ((a - b) - rest) with a the previous body
        return self.k[self.body_bone[b_bodies]] * (rel + self.rest[b_bodies])

    def check_breaks(self, t: float) -> None:
        if not self.breakable.any():
            return
        bodies = np.nonzero(self.breakable)[0]
        m = self.joint_moment(bodies)
        bones = self.body_bone[bodies]
        total = np.sqrt(np.bincount(bones, m * m, minlength=self.n))
        over = np.nonzero((total > self.strength) & self.joint_alive)[0]
        for b in over:
            self.break_joint(int(b), t, f"joint broke (moment {total[b]:.0f} N m > "
                                        f"strength {self.strength[b]:.0f} N m)")

    def _remove(self, body: int, which: tuple[int, ...] = (0, 1, 2)) -> None:
        if 0 in which:
            self.pivot_alive[body] = False
        for w in which:
            c = self.joints[body][w]
            if c is not None:
                self.space.remove(c)
                self.joints[body][w] = None

    def break_joint(self, bone: int, t: float, why: str) -> None:
        """Remove the joint at a bone's base in every plane; the bones outboard
        become a free chain and stop loading the limbs they hung on."""
        self.joint_alive[bone] = False
        self._rel_momentum = None  # the lumping changes: restart the difference
        for k in range(self.planes_of_bone[bone]):
            i = self.body_of[(bone, k)]
            self._remove(i)
            self.breakable[i] = False
        tree = self.active_trees[self.bone_tree[bone]].name
        path = self.bone_path(bone)
        self.events.append((t, tree, f"{path}: {why}"))
        self.log(f"t = {t:.3f} s: {tree} {path}: {why}")
        self.chain_start[bone] = True
        self._layout()
        # the freed subtree no longer loads the limbs above the break
        freed = np.zeros(self.n, dtype=bool)
        freed[bone] = True
        for b in range(bone + 1, self.n):
            p = self.parent[b]
            if p >= 0 and freed[p]:
                freed[b] = True
        keep = ~(freed[self.pair_dsc] & ~freed[self.pair_anc])
        changed = np.unique(self.pair_anc[~keep])
        self.pair_anc, self.pair_dsc = self.pair_anc[keep], self.pair_dsc[keep]
        for a in changed:
            self._relump(int(a), freed)

    def _relump(self, bone: int, freed: np.ndarray) -> None:
        """Recompute a body's lumped mass after part of what it carried fell off."""
        sel = np.concatenate([[bone], self.pair_dsc[self.pair_anc == bone]])
        sel = sel[~freed[sel] | (sel == bone)]
        m = self.mass[sel]
        c = self.com0[sel]
        total = m.sum()
        cog = (m[:, None] * c).sum(0) / total
        d = c - cog
        inertia = (self.inertia[sel] + m[:, None, None] * (
            (d * d).sum(1)[:, None, None] * EYE - d[:, :, None] * d[:, None, :])).sum(0)
        self.lump_mass[bone] = total
        self.lump_cog0[bone] = cog
        self.lump_inertia[bone] = inertia
        for k in range(self.planes_of_bone[bone]):
            i = self.body_of[(bone, k)]
            body = self.bodies[i]
            e, dd, o = self.body_e[i], self.body_d[i], self.body_origin[i]
            c2 = np.array([(cog - o) @ e, (cog - o) @ dd])
            i_n = float(self.body_n[i] @ inertia @ self.body_n[i])
            self.i_n[i] = i_n
            body.mass = float(total)
            body.moment = float(max(i_n, self.i_eff[i] if self.i_eff[i] > self.i_n[i] else i_n))
            origin = body.position  # setting the COG moves the origin; restore it
            body.center_of_gravity = (float(c2[0] - self.q0[i, 0]), float(c2[1] - self.q0[i, 1]))
            body.position = origin

    def bone_path(self, bone: int) -> str:
        tree = self.active_trees[self.bone_tree[bone]]
        local = bone - self.tree_offsets[self.bone_tree[bone]]
        seg = int(np.nonzero(tree.rig.seg_bone == local)[0][0])
        return tree.rig.model.segment_paths()[seg]

    def handle_cuts(self, t: float) -> None:
        for ti, tree in enumerate(self.active_trees):
            cut = tree.cut
            if cut is None:
                continue
            roots = [int(self.limb_bones[li][0]) for li in range(len(self.limb_bones))
                     if self.limb_tree[li] == ti and self.limb_parent[li] < 0]
            state = self.cut_state.get(ti, "standing")
            if state == "standing" and t >= cut.time:
                for b in roots:
                    for k in range(self.planes_of_bone[b]):
                        i = self.body_of[(b, k)]
                        self._remove(i, (1, 2))  # spring and cone go; the hinge stays
                        self.breakable[i] = False
                    # a nudge toward the felling direction (plane 0 contains it)
                    body = self.bodies[self.body_of[(b, 0)]]
                    body.angular_velocity = -0.05
                self.cut_state[ti] = "hinged"
                self.events.append((t, tree.name, "cut at the base"))
                self.log(f"t = {t:.3f} s: {tree.name} cut")
            elif state == "hinged":
                lean = max(abs(self.state[self.body_of[(b, 0)], 2]) for b in roots)
                if lean > math.radians(cut.hinge):
                    for b in roots:
                        self.joint_alive[b] = False
                        for k in range(self.planes_of_bone[b]):
                            self._remove(self.body_of[(b, k)], (0,))
                    self.cut_state[ti] = "falling"
                    self.events.append((t, tree.name, "hinge snapped"))
                    self.log(f"t = {t:.3f} s: {tree.name} hinge snapped")

    def apply_impulse(self, bone: int, impulse: np.ndarray, point: np.ndarray,
                      pose: dict) -> None:
        """Apply a world impulse (N s) at a world point to a bone's bodies."""
        fr = pose["frame_rot"][bone]
        j = fr.T @ impulse
        x = fr.T @ (point - pose["attach"][bone])
        for k in range(self.planes_of_bone[bone]):
            i = self.body_of[(bone, k)]
            e, d = self.body_e[i], self.body_d[i]
            self.bodies[i].apply_impulse_at_world_point((float(j @ e), float(j @ d)),
                                                        (float(x @ e), float(x @ d)))

    # ------------------------------------------------------------------
    # running

    def joint_gap(self) -> float:
        """Largest separation of a live pivot joint, as a fraction of the
        mean length of the two bones it joins (0 for a perfect chain)."""
        live = self.in_space & self.pivot_alive
        if not live.any():
            return 0.0
        i = np.nonzero(live)[0]
        j = self.prev_body[i]
        pos = self.state[i, 0:2]
        expect = self.q0[i].copy()
        has = j >= 0
        jj = j[has]
        c, s = np.cos(self.state[jj, 2]), np.sin(self.state[jj, 2])
        arm = self.q0[i[has]] - self.q0[jj]
        expect[has] = self.state[jj, 0:2] + np.stack([c * arm[:, 0] - s * arm[:, 1],
                                                       s * arm[:, 0] + c * arm[:, 1]], 1)
        length = self.bone_length[self.body_bone[i]]
        length[has] = 0.5 * (length[has] + self.bone_length[self.body_bone[jj]])
        gap = np.linalg.norm(pos - expect, axis=1) / np.maximum(length, 1e-9)
        return float(gap.max())

    def check(self, t: float) -> None:
        """Stop with a clear message when the state is not finite, or when a
        body spins faster than any part of a tree could (MAX_ANGULAR_SPEED)."""
        s = self.state
        live = self.in_space
        bad = live & (~np.isfinite(s).all(1) | (np.abs(s[:, 5]) > MAX_ANGULAR_SPEED))
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            tree, seg = self.locate(int(self.body_bone[i]))
            what = ("non-finite state" if not np.isfinite(s[i]).all() else
                    f"angular speed {abs(s[i, 5]):.0f} rad/s > {MAX_ANGULAR_SPEED:.0f}")
            raise SimulationError(f"{what} (unstable; try a finer quality)", tree, seg, t)

    def locate(self, bone: int) -> tuple[str, int]:
        """The tree name and a segment index (in that tree) of a global bone."""
        ti = int(self.bone_tree[bone])
        tree = self.active_trees[ti]
        local = bone - self.tree_offsets[ti]
        return tree.name, int(np.nonzero(tree.rig.seg_bone == local)[0][0])

    def run(self, progress=None) -> list[TreeMotion]:
        import time

        scene = self.scene
        frames = scene.frame_count
        n = self.n
        quats = np.zeros((frames, n, 4))
        pivots = np.zeros((frames, n, 3))
        self.events: list[tuple[float, str, str]] = []
        self.cut_state: dict[int, str] = {}
        self.joint_alive = np.ones(n, dtype=bool)
        self.breakable = np.isfinite(self.strength[self.body_bone]) if n else np.zeros(0, bool)
        self.projectiles = Projectiles.from_scene(scene) if scene.projectiles else None
        self._rel_momentum = None
        from ..rotations import quaternions_from_matrices

        t = 0.0
        prev = None
        self.read()
        pose = self.reconstruct()
        quats[0] = quaternions_from_matrices(pose["rot"])
        pivots[0] = pose["pivot"]
        substep = 0
        fresh = True  # the pose was just reconstructed at a frame boundary
        for f in range(1, frames):
            for _ in range(self.spf):
                if substep % self.update_every == 0:
                    t0 = time.perf_counter()
                    if not fresh:
                        self.read()
                        self.check(t)
                        prev, pose = pose, self.reconstruct()
                    fresh = False
                    self.handle_cuts(t)
                    self.forces(t, pose, prev)
                    self.check_breaks(t)
                    self.stats.updates += 1
                    self.stats.update_seconds += time.perf_counter() - t0
                t0 = time.perf_counter()
                batch.set_space_bodies(self.space, batch.BodyFields.FORCE
                                       | batch.BodyFields.TORQUE, self.write_buf)
                self.space.step(self.h)
                self.stats.step_seconds += time.perf_counter() - t0
                substep += 1
                t = substep * self.h
            self.read()
            self.check(t)
            self.stats.max_joint_gap = max(self.stats.max_joint_gap, self.joint_gap())
            prev, pose = pose, self.reconstruct()
            fresh = True
            quats[f] = quaternions_from_matrices(pose["rot"])
            pivots[f] = pose["pivot"]
            if self.projectiles is not None:
                self.projectiles.record(f)
            if progress is not None:
                progress(f, frames - 1)
        self.stats.substeps = substep
        out = []
        for ti, tree in enumerate(self.active_trees):
            a, b = self.tree_offsets[ti], self.tree_offsets[ti + 1]
            ev = [f"t = {et:.3f} s: {msg}" for et, tn, msg in self.events if tn == tree.name]
            out.append(TreeMotion(quats[:, a:b], pivots[:, a:b], ev))
        return out
