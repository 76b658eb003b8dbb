"""The pymunk tier's loads: external loads on every bone, carried down to
the bodies they hang on as if rigid, ground contact, d'Alembert forces of
the moving frames and structural damping, written to the bodies in bulk."""

from __future__ import annotations

import math

import numpy as np

from ...rotations import apply, apply_transposed, cross, rotvec_rate
from ..audit import per_tree
from ..common import cap_loads, external_loads
from ..contact import effective_mass, ground_forces, stored_energy
from ..rules import exact_decay

REFINE = 16  # pymunk steps per substep at least, while an impulsive load acts (8 let a
# hit open a twig's joint 1.1 %)
REFINE_SPIN = 0.002  # rad: the most a body may turn in one pymunk step
MAX_REFINE = 32  # pymunk steps per substep at most, while the pivots hold
GAP_REFINE = 128  # ... once a pivot has opened past GAP_WATCH
GAP_WATCH = 0.0025  # fraction of the bones' length (a quarter of tier.MAX_JOINT_GAP)
CONTACT_MARGIN = 0.05  # m: bones this close to the ground update every substep
CONTACT_LOOKAHEAD = 2.0  # so do bones that would reach it within this many force-rate holds


class ChainForces:
    """Loads and frame forces (mixed into PymunkTier)."""

    def forces(self, t: float, pose: dict, prev: dict | None, since: float, dt: float) -> None:
        """Evaluate all loads at time t and write them into the force buffer,
        to be held for the next `dt` s; `prev` is the pose `since` s ago.
        Steps the debris over `dt` with them."""
        n = self.n
        rot, com, cog = pose["rot"], pose["com"], pose["cog"]
        axis = self._axes(pose)
        limited = self.stats.limited
        force = external_loads(self.loads, self.bones, t, com, pose["vcom"], axis, self.stats,
                               self.locate, dt=dt, gravity=True)
        external = force - self.mass[:, None] * self.loads.g
        external[self.in_debris] = 0.0  # debris counts its own (Debris.work)
        self.ledger.add_work(per_tree(self.load_work.update(external, com), self.bone_tree,
                                      len(self.trees)))
        hits = self.projectiles.hits if self.projectiles is not None else 0
        if self.projectiles is not None:  # impulses on hit bones, both ways
            self.projectiles.advance(t, dt, pose, self)
        # an impulsive load (a blast front, a hit, a capped load) spins parts
        # fast, and pivots drift by about (omega h)^2 r per step: step finer
        # meanwhile, and while anything spins fast, so that no body turns
        # more than REFINE_SPIN per step (up to MAX_REFINE steps a substep;
        # up to GAP_REFINE once a pivot has opened past GAP_WATCH: a twig a
        # blast spins at 300 rad/s opened its pivot from 0.5 % to 1.1 % within
        # one frame at MAX_REFINE, and stopped the bake)
        spin = float(np.abs(self.state[self.in_space, 5]).max(initial=0.0))
        impulsive = self.loads.blast_active or self.stats.limited > limited or (
            self.projectiles is not None and self.projectiles.hits > hits)
        want = max(REFINE if impulsive else 1, math.ceil(spin * self.h / REFINE_SPIN))
        cap = MAX_REFINE
        if want > MAX_REFINE and self.joint_gap() > GAP_WATCH:
            cap = GAP_REFINE
        self.refine = int(min(cap, want))
        self.stats.max_refine = max(self.stats.max_refine, self.refine)
        if self.refine > 1:  # why, for the bake's note
            cause = ("a blast" if self.loads.blast_active else "a capped load"
                     if self.stats.limited > limited else "a hit" if impulsive else "a fast spin")
            self.stats.refined_by[cause] = self.stats.refined_by.get(cause, 0) + 1
        if self.debris.count:
            self.debris.step(dt, lambda c, v, ax, start, h: self._debris_loads(t + start, c, v,
                                                                                ax, h))
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
        self.grounded = np.zeros(len(self.trees), dtype=bool)
        if self.scene.ground:
            contact = self._ground(pose, dt)
            if contact is not None:
                owner, point, f, at_base = contact
                self._add_contact(owner, point, f, pose, ftot, torque)
                # a stem lies on the ground once a root chain's bone touches
                # it; its loose base on the ground is only what it stands or
                # pivots on (an uprooted tree's fall stays undamped by it)
                stem = owner[(self.bone_frame[owner] < 0) & ~at_base]
                self.grounded[self.bone_tree[stem]] = True
        bb = self.body_bone
        f_b, t_b = ftot[bb], torque[bb]
        fr = pose["frame_rot"][bb]
        frame = self.bone_frame[bb]
        moving = (frame >= 0) & ~self.in_debris[bb]
        spin = np.zeros(len(bb))  # N m: each body's rotary d'Alembert torque, about its normal
        if prev is not None and moving.any():
            # d'Alembert forces of the parent bone's accelerating frame, from
            # the motion of its own COM (a material point: the lumped COG
            # moves within the body when a part breaks off, and its velocity
            # jumps by omega x the shift, which is no acceleration)
            p = frame[moving]
            child = bb[moving]
            acc = (pose["vcom"][p] - prev["vcom"][p]) / since
            alpha = (pose["omega"][p] - prev["omega"][p]) / since
            w = pose["omega"][p]
            r = cog[child] - com[p]
            v_rel = pose["vcog"][child] - pose["vcom"][p] - cross(w, r)
            a_frame = (acc + cross(alpha, r) + cross(w, cross(w, r))
                       + 2 * cross(w, v_rel))
            f_b[moving] -= self.lump_mass[child][:, None] * a_frame
            # (about each plane's own normal: kept out of t_b, which must be
            # the same in both planes of a bone for _turning)
            n_world = apply(fr[moving], self.body_n[moving])
            spin[moving] = -self.i_n[moving] * (alpha * n_world).sum(1)
        self._recoil(pose)
        f_loc = apply_transposed(fr, f_b)
        t_loc = apply_transposed(fr, t_b)
        # structural damping on the motion relative to the frame (pymunk's
        # velocities): C = alpha M, as an exact decay over the interval, so
        # that stiff, fast limbs can never overshoot
        decay = exact_decay(self.body_alpha, dt)
        rel = self._bending_velocity(decay)
        fx = (f_loc * self.body_e).sum(1) - decay * self.body_mass * rel[:, 0]
        fy = (f_loc * self.body_d).sum(1) - decay * self.body_mass * rel[:, 1]
        tz = self._turning(pose, f_b, t_b, f_loc, t_loc) + spin - decay * self.i_eff * rel[:, 2]
        out = self.force_rows
        out[:] = 0.0
        live = self.in_space
        out[self.live_rows, 0] = fx[live]
        out[self.live_rows, 1] = fy[live]
        out[self.live_rows, 2] = tz[live]
        if self.hit_impulse.any():
            # a projectile's hits reach the bodies as forces over this hold
            # (one substep while a projectile is near): as a jump of one
            # body's velocity, a box's hit on a sapling's stem outran the
            # pivots' solver and opened a joint 1.4 %. (A body broken off
            # since its hit gets none of it: the ledger counted it as work,
            # so that can only show as a loss.)
            out[self.live_rows] += self.hit_impulse[live] / dt
            self.hit_impulse[:] = 0.0

    def _turning(self, pose: dict, f_b: np.ndarray, t_b: np.ndarray, f_loc: np.ndarray,
                 t_loc: np.ndarray) -> np.ndarray:
        """The torque (N m) each body turns by in its plane, under the force
        and torque on its bone (N, N m: f_b, t_b in the world, f_loc, t_loc
        in its frame): about its plane's normal, and in a row that bends in
        two planes, what makes each plane's angle take the loads' work on
        the 3D pose.

        A bone bent in both planes turns by exp(rho), rho = theta_0 n_0 +
        theta_1 n_1, at J(rho) rho' (kinematics.py): its angle theta_i
        turns it about J n_i, and with it everything after it in its row,
        whose pivots move by (J n_i) x (its step) per radian. The loads'
        generalized force on theta_i is therefore n_i . J^T (step x what
        acts after it + arm x its force + its torque), in 3D. pymunk takes
        the body's force at its COG and the row's forces after it through
        its 2D pivots, so the torque it gets is that less their moments in
        its plane; in one plane the two are the same, and it is the torque
        about n. (Taken about n in each plane alone, what a 70 m/s gust did
        on the two planes was not its work on the pose: the stress suite's
        sapling gained 3.1 % of its energy.)"""
        turn = (t_loc * self.body_n).sum(1)
        bent = self._bent_rows()
        if bent is None:
            return turn
        bones, row, pair, n, e, d, step, arm = bent
        s = self.state
        ends = np.cumsum(np.bincount(row)) - 1

        def after(q: np.ndarray) -> np.ndarray:  # what acts after each bone in its row
            running = np.cumsum(q, axis=0)
            return running[ends][row] - running

        # in 3D, once per bone (its two planes share the row and its loads)
        force = f_b[pair[0]]
        moment = (cross(pose["vec"][bones], after(force))
                  + cross(pose["cog"][bones] - pose["pivot"][bones], force) + t_b[pair[0]])
        moment = apply_transposed(pose["frame_rot"][bones], moment)
        angle = s[pair, 2]
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
        """What the chains' layout is taken at: counts of live pivots, debris
        bones, rows and planes, each of which only ever moves one way, so
        any break, part or plane gone changes it."""
        return (int(self.pivot_alive.sum()), int(self.in_debris.sum()),
                int(self.row_start.sum()), int(self.planes_of_bone.sum()))

    def _bent_rows(self) -> tuple | None:
        """The rows that bend in two planes (None: none): their bones, each
        row's in chain order; the index of the row each is in; each one's
        body in plane 0 and in plane 1 (2, N); and per plane (2, N, ...)
        the bodies' normals, axes e and d, and their rest steps (pivot to
        tip) and COG arms in the plane. Bones gone to debris are left out
        (they end their rows). Kept until a joint, a part or a plane goes
        (a part's going moves its carriers' COGs)."""
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
        """A free stem's recoil from what hangs on it. A stem carries its
        chains as if rigid (one-way coupling), so their momentum relative to
        it is momentum no body gave up: in a falling stem's fast frame it
        shows as energy, sum m v_frame . v_rel, 4 % of a tornado-uprooted
        broadleaf's. What that momentum and its angular momentum changed by
        since the last update goes back to the stem as an impulse, spread as
        a change of its rigid motion (at the bone it hangs on, it would bend
        the stem against a heavy limb at the limb's own frequency), and
        delivered over the next hold as the projectiles' hits are. Only on
        a free piece of stem (uprooted, felled, snapped), whose speed makes
        that error large, and not while it lies on the ground; meanwhile
        the loads update every substep
        (`recoiling`): the recoil reaches the chains a hold later, and a
        hold's lag against a crown that weighs like the stem makes the loop
        pump."""
        top = self.top_stem
        piece_of, piece_rows = self._free_pieces()
        # the chains hanging on the stem itself, each carrying what hangs on
        # it as rigid: their own children's motion relative to them, put back
        # on the stem as well, made a tornado-uprooted broadleaf 1.2 times its
        # energy within 0.2 s. Not while the stem lies on the ground (as in
        # _bending_velocity): the soil takes what its limbs push it with, and
        # the ground's stiff springs turn the stem's motion round within a
        # few substeps, faster than a recoil a substep late can follow: as
        # the `tornado` preset's broadleaf_5 landed and bounced, its recoil
        # gave the stem 30 kJ in 10 ms (3.3 % of its energy; 11 % at 1920 Hz)
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
        # per piece: the impulse and its moment about the origin; spread over
        # each of its planes' bodies as a rigid change of motion about their
        # centre of mass
        rows, group, piece = piece_rows  # bodies, their (piece, plane) group, its piece
        pieces = len(piece)
        at = piece_of[a[had]]
        j = np.stack([np.bincount(at, dp[:, k], minlength=pieces) for k in range(3)], 1)
        l0 = np.stack([np.bincount(at, dl[:, k], minlength=pieces) for k in range(3)], 1)
        j, l0 = j[piece], l0[piece]  # per group
        m, i_n = self.body_mass[rows], self.i_eff[rows]
        x = pose["cog"][self.body_bone[rows]]
        n = self.body_n[rows]
        total = np.bincount(group, m)
        c = np.stack([np.bincount(group, m * x[:, k]) for k in range(3)], 1) / total[:, None]
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
        """The free pieces of stem (a root chain's rows whose first pivot is
        gone): per bone, the index of its piece (-1: none); and the pieces'
        bodies, the group (a piece in one plane) of each, and the piece of
        each group. Kept until a joint or a part goes."""
        key = self._layout_key()
        if self.free_pieces is not None and self.free_pieces[0] == key:
            return self.free_pieces[1:]
        piece_of = np.full(self.n, -1)
        rows, group, piece = [], [], []
        for ci in self.root_chains:
            bones = self.chain_bones[ci]
            starts = np.nonzero(self.row_start[bones])[0]
            for lo, hi in zip(starts, [*starts[1:], len(bones)], strict=True):
                if self.pivot_alive[self.body_of[(int(bones[lo]), 0)]]:
                    continue
                mine = bones[lo:hi][~self.in_debris[bones[lo:hi]]]
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
        1/s per body) acts on: relative to its frame, and in a chain whose
        root joint is cut or gone (a felled or uprooted stem), relative to
        the chain's rigid motion as well while it falls: wood damps bending,
        not a stem's fall. That rigid motion has the chain's momentum and
        angular momentum about its centre of mass, weighted as the damping
        weighs each body (decay times mass and inertia), so the damping
        forces add up to no force and no torque on the chain and only ever
        take energy out. (Relative to the turn of its root body instead, a
        root body spun by the ground's contact dragged the rest along: at
        `draft` the stress suite's blasted sapling gained 1.2x its energy,
        its tornado-uprooted one 1.9x.)"""
        s = self.state
        out = s[:, 3:6].copy()
        # (once its stem lies on the ground, the soil takes part: damped whole)
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
        c, sn = np.cos(s[bodies, 2]), np.sin(s[bodies, 2])
        arm = self.cog2d0[bodies] - self.q0[bodies]
        return s[bodies, 0:2] + np.stack([c * arm[:, 0] - sn * arm[:, 1],
                                          sn * arm[:, 0] + c * arm[:, 1]], 1)

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
        """Add ground contact forces f (N) at world points (m) to the
        touching bones and, through their joints, to every body they hang on
        (a crown propping up a fallen stem), each at the actual contact point."""
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
        """Ground contacts of the chain bones (`_touching`), and their forces
        for an update held dt s. Returns the touching bones, the contact
        points (m), the forces (N) and which points are a loose base, or None."""
        touching, self.contact_active = self._touching(pose)
        if touching is None:
            return None
        owner, ends, radius, vel, m_eff, at_base = touching
        self.contact_dt = dt
        return owner, ends, ground_forces(ends, vel, radius, m_eff, dt), at_base

    def _touching(self, pose: dict):
        """The chain bones' points in the ground: every bone's tip, and the
        base of every bone no longer held by its joint (a root bone's base
        is its anchor, not a contact); debris handles its own. Returns their
        bones, points, radii (m), velocities (m/s), effective masses (kg)
        and which are a loose base, or None; and whether any
        comes within CONTACT_MARGIN of the ground, or would reach it within
        CONTACT_LOOKAHEAD updates at its speed."""
        tips = pose["pivot"] + apply(pose["rot"], self.tip0 - self.pivot0)
        loose = np.nonzero(~self.joint_alive)[0]
        ends = np.concatenate([tips, pose["pivot"][loose]])
        owner = np.concatenate([np.arange(self.n), loose])
        # a contact sphere never reaches below where its point sat at rest: a
        # stem's base at z = 0 freed from its stump would otherwise start a
        # radius deep in the ground and be thrown up by the penalty spring
        radius = np.minimum(self.radius[owner], np.maximum(np.concatenate(
            [self.tip0[:, 2], self.pivot0[loose, 2]]), 0.0))
        # a point falling fast reaches the ground within one update held at
        # the force rate: it went a hold's fall deep before the contact
        # pushed (at draft, a tornado-broken sapling stem's loose base
        # 0.16 m within one 20.8 ms hold) and was thrown back out with
        # more than it brought (3.2 % of the tree's energy)
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
        """Elastic energy (J) per bone held in the ground's contact springs,
        the chains' (at the hold they were last set for) and the debris'."""
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
