"""The pymunk tier's loads: external loads on every bone, carried to the
bodies they hang on as if rigid, ground contact, d'Alembert forces of the
moving frames and structural damping, written to the bodies in bulk (the
measurements behind each rule: docs/physics.md, "The pymunk tier")."""

from __future__ import annotations

import math

import numpy as np

from ...rotations import apply, apply_transposed, cross, rotvec_rate
from ..common import cap_loads, external_loads
from ..contact import effective_mass, ground_forces, stored_energy
from ..debris import summed
from ..rules import exact_decay
from ..stability import turned

# pymunk steps per substep ("Stability", other guards): at least REFINE while an
# impulsive load acts, and enough that no body turns more than REFINE_SPIN in
# one; at most MAX_REFINE, or GAP_REFINE once a pivot has opened past GAP_WATCH
REFINE = 16
REFINE_SPIN = 0.002  # rad
MAX_REFINE = 32
GAP_REFINE = 128
GAP_WATCH = 0.0025  # fraction of the bones' length (a quarter of tier.MAX_JOINT_GAP)
CONTACT_MARGIN = 0.05  # m: bones this close to the ground update every substep
CONTACT_LOOKAHEAD = 2.0  # so do bones that would reach it within this many force-rate holds


class ChainForces:
    """Loads and frame forces (mixed into PymunkTier)."""

    def forces(self, t: float, pose: dict, prev: dict | None, since: float, dt: float) -> None:
        """Evaluate every load at `t` s in `pose` and write the bodies'
        forces and torques (N, N m) to the force buffer, held for `dt` s;
        `prev` is the pose `since` s ago (None: no frame forces). Advances
        the projectiles and the debris over `dt`; sets `refine`."""
        limited = self.stats.limited
        force = self._external(t, pose, dt)
        p = self.projectiles
        hits = p.hits if p is not None else 0
        if p is not None:  # impulses on hit bones, both ways
            p.advance(t, dt, pose, self)
        self._choose_refine(limited, p is not None and p.hits > hits)
        if self.debris.count:
            self.debris.step(dt, lambda c, v, ax, start, h: self._debris_loads(t + start, c, v,
                                                                                ax, h))
            force[self.debris.bones] = 0.0
        ftot, torque = self._carried(pose, force)
        self._ground_contact(pose, dt, ftot, torque)
        f_b, t_b, spin = self._frame_forces(pose, prev, since, ftot, torque)
        self._recoil(pose)
        self._write_forces(pose, f_b, t_b, spin, dt)

    def _external(self, t: float, pose: dict, dt: float) -> np.ndarray:
        """The bones' loads (N at their COMs, gravity included, capped); the
        work of all but gravity goes to the ledger (debris counts its own)."""
        force = external_loads(self.loads, self.bones, t, pose["com"], pose["vcom"],
                               self._axes(pose), self.stats, self.locate, dt=dt, gravity=True)
        external = force - self.mass[:, None] * self.loads.g
        external[self.in_debris] = 0.0  # (Debris.work)
        self.ledger.add_work(self._per_tree(self.load_work.update(external, pose["com"])))
        return force

    def _choose_refine(self, limited: int, hit: bool) -> None:
        """Set `refine`, the pymunk steps per substep: a pivot drifts by about
        (omega h)^2 r per step, so step finer while an impulsive load acts (a
        blast front, a load capped since `limited` was counted, a `hit`) or
        anything spins fast."""
        spin = float(np.abs(self.state[self.in_space, 5]).max(initial=0.0))
        capped = self.stats.limited > limited
        impulsive = self.loads.blast_active or capped or hit
        want = max(REFINE if impulsive else 1, math.ceil(spin * self.h / REFINE_SPIN))
        cap = GAP_REFINE if want > MAX_REFINE and self.joint_gap() > GAP_WATCH else MAX_REFINE
        self.refine = int(min(cap, want))
        self.stats.max_refine = max(self.stats.max_refine, self.refine)
        if self.refine > 1:  # why, for the bake's note
            cause = ("a blast" if self.loads.blast_active else "a capped load" if capped
                     else "a hit" if impulsive else "a fast spin")
            self.stats.refined_by[cause] = self.stats.refined_by.get(cause, 0) + 1

    def _carried(self, pose: dict, force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per bone, the force (N) and torque about its lumped COG (N m) of
        its loads and those of the chains it carries, each where its COM
        would be if rigid (at the swinging one the reaction lacks its
        inertial half and pumps twigs: "Child → parent")."""
        cog = pose["cog"]
        ftot = force.copy()
        torque = cross(pose["com"] - cog, force)
        if len(self.pair_anc):
            a, d = self.pair_anc, self.pair_dsc
            rigid = pose["pivot"][a] + apply(pose["rot"][a], self.com0[d] - self.pivot0[a])
            ftot += summed(a, force[d], self.n)
            torque += summed(a, cross(rigid - cog[a], force[d]), self.n)
        return ftot, torque

    def _ground_contact(self, pose: dict, dt: float, ftot: np.ndarray,
                        torque: np.ndarray) -> None:
        """Add the ground's contact forces for a hold of `dt` s to `ftot`,
        `torque`; set `contact_active` and `grounded`, the trees whose stem
        lies on the ground (a root chain's bone touches it: a loose base is
        what it stands or pivots on, "Felling")."""
        self.grounded = np.zeros(len(self.trees), dtype=bool)
        if not self.scene.ground:
            return
        touching, self.contact_active = self._touching(pose)
        if touching is None:
            return
        owner, ends, radius, vel, m_eff, at_base = touching
        self.contact_dt = dt
        self._add_contact(owner, ends, ground_forces(ends, vel, radius, m_eff, dt), pose, ftot,
                          torque)
        stem = owner[(self.bone_frame[owner] < 0) & ~at_base]
        self.grounded[self.bone_tree[stem]] = True

    def _frame_forces(self, pose: dict, prev: dict | None, since: float, ftot: np.ndarray,
                      torque: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per body, the force and torque (N, N m, world) on its bone less
        the d'Alembert force of its frame's acceleration, and apart (for
        `_turning`) the frame's rotary d'Alembert torque about its normal.
        The frame moves as its bone's COM, a point of its wood, differenced
        from `prev` over `since` s ("Parent → child")."""
        bb = self.body_bone
        f_b, t_b = ftot[bb], torque[bb]
        frame = self.bone_frame[bb]
        moving = (frame >= 0) & ~self.in_debris[bb]
        spin = np.zeros(len(bb))
        if prev is None or not moving.any():
            return f_b, t_b, spin
        p, child = frame[moving], bb[moving]
        acc = (pose["vcom"][p] - prev["vcom"][p]) / since
        alpha = (pose["omega"][p] - prev["omega"][p]) / since
        w = pose["omega"][p]
        r = pose["cog"][child] - pose["com"][p]
        v_rel = pose["vcog"][child] - pose["vcom"][p] - cross(w, r)
        a_frame = acc + cross(alpha, r) + cross(w, cross(w, r)) + 2 * cross(w, v_rel)
        f_b[moving] -= self.lump_mass[child][:, None] * a_frame
        n_world = apply(pose["frame_rot"][bb][moving], self.body_n[moving])
        spin[moving] = -self.i_n[moving] * (alpha * n_world).sum(1)
        return f_b, t_b, spin

    def _write_forces(self, pose: dict, f_b: np.ndarray, t_b: np.ndarray, spin: np.ndarray,
                      dt: float) -> None:
        """Write each live body's force along e, d and torque to the force
        buffer, less structural damping (C = alpha M as an exact decay over
        `dt`: stiff limbs never overshoot), plus the impulses not delivered
        yet (hits, recoil) as forces over `dt` (a jump of one body's velocity
        outran the pivots' solver: "Projectiles")."""
        fr = pose["frame_rot"][self.body_bone]
        f_loc = apply_transposed(fr, f_b)
        t_loc = apply_transposed(fr, t_b)
        decay = exact_decay(self.body_alpha, dt)
        rel = self._bending_velocity(decay)
        fx = (f_loc * self.body_e).sum(1) - decay * self.body_mass * rel[:, 0]
        fy = (f_loc * self.body_d).sum(1) - decay * self.body_mass * rel[:, 1]
        tz = self._turning(pose, f_b, t_b, f_loc, t_loc) + spin - decay * self.i_eff * rel[:, 2]
        out, live, rows = self.force_rows, self.in_space, self.live_rows
        out[:] = 0.0
        out[rows] = np.stack([fx, fy, tz], 1)[live]
        if self.hit_impulse.any():
            out[rows] += self.hit_impulse[live] / dt
            self.hit_impulse[:] = 0.0

    def _turning(self, pose: dict, f_b: np.ndarray, t_b: np.ndarray, f_loc: np.ndarray,
                 t_loc: np.ndarray) -> np.ndarray:
        """The torque (N m) each body turns by in its plane under its bone's
        force and torque (f_b, t_b world; f_loc, t_loc in its frame): about
        its normal; in a row bent in two planes, n_i . J^T (step x what acts
        after it + arm x force + torque), less the moments pymunk's 2D pivots
        give those forces ("Loads on a bone bent in two planes")."""
        turn = (t_loc * self.body_n).sum(1)
        bent = self._bent_rows()
        if bent is None:
            return turn
        bones, row, pair, n, e, d, step, arm = bent
        ends = np.cumsum(np.bincount(row)) - 1

        def after(q: np.ndarray) -> np.ndarray:  # what acts after each bone in its row
            running = np.cumsum(q, axis=0)
            return running[ends][row] - running

        # in 3D, once per bone (its two planes share the row and its loads)
        force = f_b[pair[0]]
        moment = (cross(pose["vec"][bones], after(force))
                  + cross(pose["cog"][bones] - pose["pivot"][bones], force) + t_b[pair[0]])
        moment = apply_transposed(pose["frame_rot"][bones], moment)
        angle = self.state[pair, 2]
        moment = rotvec_rate(-(angle[0, :, None] * n[0] + angle[1, :, None] * n[1]),
                             moment)  # J(rho)^T = J(-rho)
        for k in range(2):  # each plane: less the force's moments in pymunk's 2D pose
            i = pair[k]
            fx, fy = (f_loc[i] * e[k]).sum(1), (f_loc[i] * d[k]).sum(1)
            gx, gy = after(fx), after(fy)
            (sx, sy), (ax, ay) = step[k], arm[k]
            c, sn = np.cos(angle[k]), np.sin(angle[k])
            turn[i] = ((moment * n[k]).sum(1)
                       - c * (sx * gy - sy * gx + ax * fy - ay * fx)
                       + sn * (sx * gx + sy * gy + ax * fx + ay * fy))
        return turn

    def _layout_key(self) -> tuple[int, ...]:
        """Counts of live pivots, debris bones, rows and planes: each only
        ever moves one way, so any break, part or plane gone changes it."""
        return (int(self.pivot_alive.sum()), int(self.in_debris.sum()),
                int(self.row_start.sum()), int(self.planes_of_bone.sum()))

    def _bent_rows(self) -> tuple | None:
        """The rows bent in two planes, debris left out (None: none): their
        bones, each one's row, its bodies in planes 0 and 1 (2, N), and per
        plane (2, N, ...) their normals, e, d, rest steps (pivot to tip) and
        COG arms in the plane. Cached until `_layout_key` changes."""
        key = self._layout_key()
        if self.bent is not None and self.bent[0] == key:
            return self.bent[1]
        bones, row = [], []
        for lv in self.levels:
            for r in range(len(lv["grid"])):
                mine = lv["grid"][r][lv["valid"][r]]
                mine = mine[~self.in_debris[mine]]
                if len(mine) and (self.planes_of_bone[mine] == 2).all():
                    bones += mine.tolist()
                    row += [row[-1] + 1 if row else 0] * len(mine)
        out = None
        if bones:
            bones = np.asarray(bones, dtype=np.int64)
            b0, b1, _ = self.plane_rows
            pair = np.stack([b0[bones], b1[bones]])
            e, d = self.body_e[pair], self.body_d[pair]
            rest = self.tip0[bones] - self.pivot0[bones]
            step = np.stack([np.stack([(rest * e[k]).sum(1), (rest * d[k]).sum(1)])
                             for k in range(2)])
            arm = np.stack([(self.cog2d0[pair[k]] - self.q0[pair[k]]).T for k in range(2)])
            out = (bones, np.asarray(row, dtype=np.int64), pair, self.body_n[pair], e, d,
                   step, arm)
        self.bent = (key, out)
        return out

    def _recoil(self, pose: dict) -> None:
        """A free stem's recoil ("A free stem's recoil"): what each chain on
        a free piece of stem off the ground changed its lumped momentum (and
        its moment) relative to the stem by since the last update goes back
        to the piece as an impulse; sets `recoiling` (updates every substep)."""
        top = self.top_stem
        piece_of, piece_rows = self._free_pieces()
        b = np.nonzero((self.bone_frame == top) & (piece_of[top] >= 0) & ~self.in_debris
                       & ~self.grounded[self.bone_tree[top]])[0]
        self.recoiling = bool(len(b))
        if not len(b):
            self.recoil_v[:] = np.nan
            return
        a = top[b]
        com, cog, vcom, omega = pose["com"], pose["cog"], pose["vcom"], pose["omega"]
        v_rel = pose["vcog"][b] - vcom[a] - cross(omega[a], cog[b] - com[a])
        l_rel = cross(cog[b], v_rel)
        last_v, last_l = self.recoil_v[b], self.recoil_l[b]
        self.recoil_v[:] = np.nan
        self.recoil_v[b], self.recoil_l[b] = v_rel, l_rel
        had = np.isfinite(last_v[:, 0])
        if not had.any():
            return
        # at today's lumped mass: what broke off since took its momentum along
        lumped = self.lump_mass[b[had], None]
        dp = -lumped * (v_rel - last_v)[had]  # N s, on the stem
        dl = -lumped * (l_rel - last_l)[had]  # N m s, about the origin
        self._push_pieces(piece_of[a[had]], dp, dl, piece_rows, pose)

    def _push_pieces(self, at: np.ndarray, dp: np.ndarray, dl: np.ndarray, piece_rows: tuple,
                     pose: dict) -> None:
        """Add impulses `dp` (N s), moments `dl` about the origin (N m s), on
        pieces `at` to `hit_impulse`, each spread over a piece's planes as a
        rigid change of its motion (on one bone it bent the stem)."""
        rows, group, piece = piece_rows  # bodies, their (piece, plane) group, its piece
        j = summed(at, dp, len(piece))[piece]  # per group
        l0 = summed(at, dl, len(piece))[piece]
        m, i_n = self.body_mass[rows], self.i_eff[rows]
        x = pose["cog"][self.body_bone[rows]]
        n = self.body_n[rows]
        total = np.bincount(group, m)
        c = summed(group, m[:, None] * x) / total[:, None]
        r = x - c[group]
        r -= (r * n).sum(1)[:, None] * n
        normal = n[np.searchsorted(group, np.arange(len(total)))]  # one plane per group
        w = (((l0 - cross(c, j)) * normal).sum(1)
             / np.bincount(group, m * (r * r).sum(1) + i_n))
        imp = m[:, None] * (j[group] / total[group, None] + w[group, None] * cross(n, r))
        self.hit_impulse[rows, 0] += (imp * self.body_e[rows]).sum(1)
        self.hit_impulse[rows, 1] += (imp * self.body_d[rows]).sum(1)
        self.hit_impulse[rows, 2] += i_n * w[group]

    def _free_pieces(self) -> tuple[np.ndarray, tuple]:
        """The free pieces of stem (a root chain's rows without their first
        pivot): per bone its piece (-1: none); the pieces' bodies, the group
        (a piece in one plane) of each and the piece of each group. Cached
        until `_layout_key` changes."""
        key = self._layout_key()
        if self.free_pieces is not None and self.free_pieces[0] == key:
            return self.free_pieces[1:]
        piece_of = np.full(self.n, -1)
        rows, group, piece = [], [], []
        for ci in self.root_chains:
            for bones in self._rows(ci):
                if self.pivot_alive[self.body_of[(int(bones[0]), 0)]]:
                    continue
                mine = bones[~self.in_debris[bones]]
                if not len(mine):
                    continue
                index = int(piece_of.max()) + 1
                piece_of[mine] = index
                for k in range(len(self.chain_planes[ci])):
                    plane = [self.body_of[(int(b), k)] for b in mine if k < self.planes_of_bone[b]]
                    if plane and self.in_space[plane].all():
                        rows += plane
                        group += [len(piece)] * len(plane)
                        piece.append(index)
        parts = (np.asarray(rows, dtype=np.int64), np.asarray(group, dtype=np.int64),
                 np.asarray(piece, dtype=np.int64))
        self.free_pieces = (key, piece_of, parts)
        return piece_of, parts

    def _bending_velocity(self, decay: np.ndarray) -> np.ndarray:
        """Each body's velocity (vx, vy, w) that structural damping (`decay`
        1/s per body) acts on: relative to its frame, and in a chain free at
        its root and off the ground relative to the chain's rigid motion too
        (its momenta weighted as the damping weighs each body: no net force
        or torque), so wood damps bending, not a stem's fall ("Felling")."""
        s = self.state
        out = s[:, 3:6].copy()
        free = np.nonzero((self.rigid_root >= 0)
                          & ~self.grounded[self.bone_tree[self.body_bone]])[0]
        if len(free):
            _, chain = np.unique(self.rigid_root[free], return_inverse=True)
            m, inertia = decay[free] * self.body_mass[free], decay[free] * self.i_eff[free]
            x, v, w = self._cogs(free), s[free, 3:5], s[free, 5]
            total = np.maximum(np.bincount(chain, m), 1e-300)  # undamped: no motion to fit

            def mean(q: np.ndarray) -> np.ndarray:  # mass-weighted, per chain
                return np.stack([np.bincount(chain, m * q[:, k]) for k in range(2)],
                                1) / total[:, None]

            r = x - mean(x)[chain]
            v_com = mean(v)[chain]
            u = v - v_com
            spin = np.bincount(chain, m * (r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0]) + inertia * w)
            turn = (spin / np.maximum(np.bincount(chain, m * (r * r).sum(1) + inertia),
                                      1e-300))[chain]
            out[free, 0] -= v_com[:, 0] - turn * r[:, 1]
            out[free, 1] -= v_com[:, 1] + turn * r[:, 0]
            out[free, 2] -= turn
        return out

    def _cogs(self, bodies: np.ndarray) -> np.ndarray:
        """The bodies' centres of gravity (N, 2) in their planes, m."""
        s = self.state
        return s[bodies, 0:2] + turned(s[bodies, 2], self.cog2d0[bodies] - self.q0[bodies])

    def _debris_loads(self, t: float, com: np.ndarray, vcom: np.ndarray, axis: np.ndarray,
                      hold: float) -> np.ndarray:
        """Loads on the debris bones (gravity, air, blasts), held `hold` s
        from t, capped."""
        d = self.debris.bones
        force = self.loads.forces(t, com, vcom, axis, self.props.take(d), dt=hold)
        return cap_loads(force, self.mass[d], t, self.stats, lambda i: self.locate(int(d[i])),
                         self.loads.blast_capped)

    def _add_contact(self, owner: np.ndarray, point: np.ndarray, f: np.ndarray, pose: dict,
                     ftot: np.ndarray, torque: np.ndarray) -> None:
        """Add contact forces f (N) at world points (m) to the touching bones
        and every bone they hang on (a crown propping up a fallen stem)."""
        bones, points, forces = [owner], [point], [f]
        up, idx = self.bone_frame[owner], np.arange(len(owner))
        while (up >= 0).any():
            keep = up >= 0
            idx, up = idx[keep], up[keep]
            bones.append(up)
            points.append(point[idx])
            forces.append(f[idx])
            up = self.bone_frame[up]
        b, p, fc = np.concatenate(bones), np.concatenate(points), np.concatenate(forces)
        ftot += summed(b, fc, self.n)
        torque += summed(b, cross(p - pose["cog"][b], fc), self.n)

    def _touching(self, pose: dict):
        """The chain bones' points in the ground (tips, and loose bases):
        their bones, points, radii (m), velocities (m/s), effective masses
        (kg) and which are a loose base, or None; and whether any point is
        within CONTACT_MARGIN or CONTACT_LOOKAHEAD holds of the ground (a
        fast one went a hold deep before the contact pushed: "Ground")."""
        tips = pose["pivot"] + apply(pose["rot"], self.tip0 - self.pivot0)
        loose = np.nonzero(~self.joint_alive)[0]
        ends = np.concatenate([tips, pose["pivot"][loose]])
        owner = np.concatenate([np.arange(self.n), loose])
        # never below the point's rest height: a freed base would start deep ("Felling")
        radius = np.minimum(self.radius[owner], np.maximum(np.concatenate(
            [self.tip0[:, 2], self.pivot0[loose, 2]]), 0.0))
        arm = ends - pose["cog"][owner]
        vel = pose["vcog"][owner] + cross(pose["omega"][owner], arm)
        reach = CONTACT_LOOKAHEAD * self.update_every * self.h
        low = ends[:, 2] + np.minimum(vel[:, 2], 0.0) * reach < radius + CONTACT_MARGIN
        near = (ends[:, 2] < radius) & ~self.in_debris[owner]
        active = bool((low & ~self.in_debris[owner]).any())
        if not near.any():
            return None, active
        at_base = (np.arange(len(owner)) >= self.n)[near]
        ends, owner, radius, arm = ends[near], owner[near], radius[near], arm[near]
        m_eff = effective_mass(self.lump_mass[owner], self.i_eff[self.body_of_bone0[owner]], arm)
        return (owner, ends, radius, vel[near], m_eff, at_base), active

    def contact_energy(self, pose: dict) -> np.ndarray:
        """Elastic energy (J) per bone in the ground's contact springs."""
        out = np.zeros(self.n)
        if not self.scene.ground:
            return out
        touching, _ = self._touching(pose)
        if touching is not None:
            owner, ends, radius, vel, m_eff, _ = touching
            np.add.at(out, owner, stored_energy(ends, vel[:, 2], radius, m_eff,
                                                self.contact_dt))
        out[self.debris.bones] += self.debris.contact_energy()
        return out

    def apply_impulse(self, bone: int, impulse: np.ndarray, point: np.ndarray,
                      pose: dict) -> None:
        """Apply a world impulse (N s) at a world point (m) to a bone: to its
        bodies over the next hold (forces), or at once to debris."""
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
            j2 = np.array([j @ e, j @ d])
            r = np.array([x @ e, x @ d]) - self._cogs(np.array([i]))[0]
            self.hit_impulse[i] += (j2[0], j2[1], r[0] * j2[1] - r[1] * j2[0])
