"""The pymunk tier's construction: chains of 2D bodies, one per bone and
bending plane, with pivots, damped rotary springs and cone limits; what a
body carries (lumping), the grids the reconstruction walks, the prestress
and the stability rule (stability.py)."""

from __future__ import annotations

from dataclasses import fields

import numpy as np
import pymunk
from pymunk import batch

from ...rotations import cross
from ..common import Bones
from ..layout import ChainLayout
from ..stability import inertia_floor

EYE = np.eye(3)
PIVOT, SPRING, LIMIT = 0, 1, 2  # a body's joint constraints
# s: the springs' damping is c = k h_c / 2, h_c the substep or this if longer: the
# twigs' only damping, which a finer step must not lessen ("Spring damping")
SPRING_DAMPING_STEP = 1 / 1000


def apparent_mass(r: float, zeta: float) -> float:
    """The in-phase apparent mass, per unit mass, of a damped oscillator
    driven at its base at r = driving / own frequency, clipped to [1, 3]: a
    stiffer child sways along, amplified (the one-way coupling's stand-in
    for its push back); a softer one is carried as rigid (its frequency
    estimate ignores gravity's pendulum stiffness)."""
    q = 1.0 - r * r
    z = 4.0 * zeta * zeta * r * r
    return float(np.clip((q + z) / (q * q + z), 1.0, 3.0))


class ChainBuild:
    """Construction and re-lumping (mixed into PymunkTier)."""

    def _collect(self) -> None:
        """The trees' rigs as global bone arrays (sim/common.py's Bones)."""
        self.bones = Bones.of(self.trees)
        for f in fields(Bones):  # as attributes: the solver reads them everywhere
            setattr(self, f.name, getattr(self.bones, f.name))
        self.stats.bones = self.n

    def _chains(self) -> None:
        """Each rig limb is a chain (layout.py) with one or two bending planes."""
        lay = ChainLayout.of(self.trees, self.offsets, self.pivot0, self.tip0)
        self.chain_bones = lay.chain_bones
        self.chain_parent = lay.chain_parent.tolist()  # the bone a chain hangs on, -1 = ground
        self.chain_tree = lay.chain_tree.tolist()
        self.chain_depth = lay.chain_depth
        self.chain_planes = []  # (e, d) per plane
        for ci, (e, d) in enumerate(zip(lay.chain_e, lay.chain_d)):
            planes = self.trees[self.chain_tree[ci]].planes
            self.chain_planes.append([(e, d)] if planes == 1 else [(e, d), (cross(e, d), d)])
        self.bone_chain = lay.bone_chain
        self.chain_first = lay.chain_first
        self.bone_frame = lay.bone_frame  # the bone whose frame a bone's chain moves in
        self.top_stem = np.arange(self.n)  # the stem bone (root chain) a bone hangs on
        for b in range(self.n):  # parents precede children
            if self.bone_frame[b] >= 0:
                self.top_stem[b] = self.top_stem[self.bone_frame[b]]
        self.root_chains = [ci for ci, p in enumerate(self.chain_parent) if p < 0]
        self.row_start = np.zeros(self.n, dtype=bool)  # a bone starts a row (_layout)
        self.row_start[self.chain_first] = True

    def _lumping(self) -> None:
        """Lumped bodies: a bone plus the chains attached to it, carried as
        if rigid. Each pair (attach bone a, descendant d) adds d to a's lump:
        its true mass for gravity and the prestress, and for inertia its
        mass times its child chain's apparent_mass factor."""
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

    def _layout(self) -> None:
        """Per chain depth, a padded grid (rows x length) of rows (a chain
        splits where a joint has broken) and the rest-pose quantities the
        reconstruction needs."""
        self.levels = []
        for depth in range(int(self.chain_depth.max()) + 1 if len(self.chain_depth) else 0):
            rows = [r for ci in np.nonzero(self.chain_depth == depth)[0] for r in self._rows(ci)]
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

    def _rows(self, ci: int) -> list[np.ndarray]:
        """Chain ci's rows, in order: it splits where a joint has broken."""
        bones = self.chain_bones[ci]
        starts = np.nonzero(self.row_start[bones])[0].tolist()
        return [bones[a:z] for a, z in zip(starts, [*starts[1:], len(bones)])]

    def _refresh_cog(self) -> None:
        """Rest offsets of the lumped COGs (they change when a part breaks off)."""
        arm = self.lump_cog0 - self.pivot0
        for level in self.levels:
            level["cog_arm"] = arm[level["bones"]]

    def _space(self) -> None:
        """The bodies, their rest angles (prestress) and inertias (the
        stability rule), and the pymunk space that steps them."""
        self._bodies()
        nb = len(self.body_bone)
        self.rest = self._prestress() if self.scene.prestress else np.zeros(nb)
        self._floor_inertia()
        self._fill_space()
        self.state = np.zeros((nb, 6))  # x, y, angle, vx, vy, w (pymunk's own order)
        # N s, N s, N m s not yet delivered: projectiles' hits, a free stem's recoil (forces.py)
        self.hit_impulse = np.zeros((nb, 3))
        self._buffers()

    def _bodies(self) -> None:
        """One body per bone and plane, a chain plane's in chain order: its
        bone, the body before it (-1: the anchor), plane axes e, d, normal
        n, rest pivot `q0` and lumped COG `cog2d0` in its plane (m) and
        rotary inertia `i_n` about n (kg m^2)."""
        self.body_of: dict[tuple[int, int], int] = {}
        body_bone, prev, e_rows, d_rows = [], [], [], []
        for ci, bones in enumerate(self.chain_bones):
            for k, (e, d) in enumerate(self.chain_planes[ci]):
                for j, b in enumerate(bones):
                    self.body_of[(int(b), k)] = len(body_bone)
                    prev.append(len(body_bone) - 1 if j else -1)
                    body_bone.append(int(b))
                    e_rows.append(e)
                    d_rows.append(d)
        nb = self.stats.bodies = len(body_bone)
        self.body_bone = np.asarray(body_bone, dtype=np.int64)
        self.prev_body = np.asarray(prev, dtype=np.int64)
        self.body_e = np.asarray(e_rows).reshape(nb, 3)
        self.body_d = np.asarray(d_rows).reshape(nb, 3)
        self.body_n = cross(self.body_e, self.body_d)
        self.planes_of_bone = np.maximum(np.bincount(self.body_bone, minlength=self.n), 1)
        self.body_of_bone0 = np.asarray([self.body_of[(b, 0)] for b in range(self.n)],
                                        dtype=np.int64)
        b1 = np.asarray([self.body_of.get((b, 1), -1) for b in range(self.n)], dtype=np.int64)
        self.plane_rows = (self.body_of_bone0, b1, np.nonzero(b1 >= 0)[0])
        self.q0 = self._in_planes(self.pivot0[self.body_bone])
        self.cog2d0 = self._in_planes(self.lump_cog0[self.body_bone])
        self.i_n = np.einsum("bi,bij,bj->b", self.body_n, self.lump_inertia[self.body_bone],
                             self.body_n)

    def _in_planes(self, points: np.ndarray) -> np.ndarray:
        """World points (one per body) in the bodies' planes (N, 2), m."""
        origin = self.pivot0[self.chain_first[self.bone_chain[self.body_bone]]]
        return np.stack([((points - origin) * self.body_e).sum(1),
                         ((points - origin) * self.body_d).sum(1)], 1)

    def _floor_inertia(self) -> None:
        """The stability rule: `i_eff`, each body's rotary inertia raised to
        the inertia_floor of the stiffest joint it touches."""
        prev = self.prev_body
        kb = self.k[self.body_bone]
        k_max = kb.copy()
        has = prev >= 0
        np.maximum.at(k_max, prev[has], kb[has])
        floor = inertia_floor(k_max, self.h, self.quality.stability)
        self.i_eff = np.maximum(np.maximum(self.i_n, floor), 1e-12)
        self.stats.inertia_floored = int((floor > self.i_n).sum())
        self.stats.max_inertia_ratio = float(
            (self.i_eff / np.maximum(self.i_n, 1e-12)).max()) if len(prev) else 1.0

    def _fill_space(self) -> None:
        """The pymunk space: each body at rest, joined to the one before it
        (or the anchor) by a pivot, a damped spring and a cone limit."""
        q, h = self.quality, self.h
        space = self.space = pymunk.Space()
        space.iterations = q.iterations
        c = 0.5 * max(h, SPRING_DAMPING_STEP) * self.k[self.body_bone]  # N m s/rad
        self.body_alpha = self.alpha[self.body_bone]
        self.body_mass = self.lump_mass[self.body_bone]
        # a share of a joint's error per substep, not Chipmunk's per 1/60 s: fast spins drift
        error_bias = (1.0 - q.joint_correction) ** (1.0 / h)
        self.bodies: list[pymunk.Body] = []
        self.joints: list[list] = []
        for i, b in enumerate(self.body_bone.tolist()):
            body = pymunk.Body(float(self.body_mass[i]), float(self.i_eff[i]))
            # the COG first: setting it keeps its world position, moving the origin
            body.center_of_gravity = tuple((self.cog2d0[i] - self.q0[i]).tolist())
            body.position = tuple(self.q0[i].tolist())
            space.add(body)
            self.bodies.append(body)
            other = self.bodies[self.prev_body[i]] if self.prev_body[i] >= 0 else \
                space.static_body
            pivot = pymunk.PivotJoint(other, body, tuple(self.q0[i].tolist()))
            spring = pymunk.DampedRotarySpring(other, body, float(self.rest[i]), float(self.k[b]),
                                               float(c[i]))
            limit = pymunk.RotaryLimitJoint(other, body, -float(self.cone[b]),
                                            float(self.cone[b]))
            pivot.error_bias = limit.error_bias = error_bias
            space.add(pivot, spring, limit)
            self.joints.append([pivot, spring, limit])

    def _prestress(self) -> np.ndarray:
        """Spring rest angles (rad) that hold every chain in its grown shape
        under gravity: the gravity torque of everything outboard of a joint
        over its k (DampedRotarySpring drives a.angle - b.angle to it)."""
        g = self.loads.g
        rest = np.zeros(len(self.body_bone))
        g2d = np.stack([self.body_e @ g, self.body_d @ g], 1)
        cog2d = self._in_planes(self.true_cog0[self.body_bone])
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
            # keep the origin, and give the new COG the velocity the wood there
            # had (pymunk's is the COG's), or the break would jolt what stays
            origin, before = body.position, body.local_to_world(body.center_of_gravity)
            body.center_of_gravity = tuple((c2 - self.q0[i]).tolist())
            self.cog2d0[i] = c2  # what _cogs reads (damping, hits, velocities)
            body.position = origin
            shift = body.local_to_world(body.center_of_gravity) - before
            w = body.angular_velocity
            body.velocity += (-w * shift.y, w * shift.x)
