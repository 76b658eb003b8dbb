"""The pymunk tier's kinematics: the bodies' state read in bulk, and the 3D
pose and velocity of every bone rebuilt from its chains' 2D states, level by
level from the roots (children ride on their parents)."""

from __future__ import annotations

import numpy as np
from pymunk import batch

from ...errors import SimulationError
from ...rotations import apply, compose, cross, matrices_from_rotvec, rotvec_rate
from ..common import MAX_ANGULAR_SPEED
from ..stability import chain_gaps
from .build import EYE


class ChainKinematics:
    """Reading state and reconstructing poses (mixed into PymunkTier)."""

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
        # (d) part is simulated in every plane: average it. A body's
        # position is its origin (the pivot) and its velocity its centre of
        # gravity's: the origin moves at v - w x (cog - origin)
        disp = s[:, 0:2] - self.q0
        arm = self._cogs(np.arange(len(s))) - s[:, 0:2]
        v_origin = s[:, 3:5] + s[:, 5:6] * np.stack([arm[:, 1], -arm[:, 0]], 1)
        rho = s[b0, 2:3] * self.body_n[b0]
        off = disp[b0, 0:1] * self.body_e[b0]
        voff = v_origin[b0, 0:1] * self.body_e[b0]
        rate = s[b0, 5:6] * self.body_n[b0]
        axial = disp[b0, 1:2]
        v_axial = v_origin[b0, 1:2]
        if len(two):
            c = b1[two]
            rho[two] += s[c, 2:3] * self.body_n[c]
            off[two] += disp[c, 0:1] * self.body_e[c]
            voff[two] += v_origin[c, 0:1] * self.body_e[c]
            rate[two] += s[c, 5:6] * self.body_n[c]
            axial[two] = 0.5 * (axial[two] + disp[c, 1:2])
            v_axial[two] = 0.5 * (v_axial[two] + v_origin[c, 1:2])
        off += axial * self.body_d[b0]
        voff += v_axial * self.body_d[b0]
        # the bone turns by exp(rho) in its frame: bent in two planes, its
        # angular velocity is not rho's rate (the children riding on it
        # turned at the wrong rate: docs/physics.md, "Planes")
        wrel = rotvec_rate(rho, rate)
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
            w = apply(rp, wrel[bones])
            if lv["any"]:
                w[has] += omega[pp]
            omega[bones] = w
            # velocities follow the chain as its pivots do: each row's head
            # pivot from its own body, the rest by the turn rates of the bones
            # before them (a body's own axial velocity would be averaged over
            # two planes, wrong once one plane turns far: a felled stem)
            hp = piv[:, 0]
            hv = apply(rp[h], voff[heads])
            fh = lv["p"][h]
            held = fh >= 0
            if held.any():
                f = fh[held]
                hv[held] += vcog[f] + cross(omega[f], hp[held] - cog[f])
            turn = np.zeros(grid.shape + (3,))
            turn[valid] = cross(w, step[valid])
            vp = hv[:, None, :] + np.cumsum(turn, axis=1) - turn
            vcog[bones] = vp[valid] + cross(w, c - pivot[bones])
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

    def joint_gap(self, worst: bool = False):
        """Largest separation of a live pivot, as a fraction of the mean
        length of the two bones it joins (and, with `worst`, its body)."""
        live = self.in_space & self.pivot_alive
        if not live.any():
            return (0.0, 0) if worst else 0.0
        prev = self.prev_body
        length = self.length[self.body_bone].copy()
        has = prev >= 0
        length[has] = 0.5 * (length[has] + length[prev[has]])
        gaps = np.where(live, chain_gaps(self.state, prev, self.q0, length), 0.0)
        body = int(np.argmax(gaps))
        return (float(gaps[body]), body) if worst else float(gaps[body])

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
