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

POSE_KEYS = ("rot", "pivot", "cog", "vcog", "vec", "omega", "frame_rot", "attach")


class ChainKinematics:
    """Reading state and reconstructing poses (mixed into PymunkTier)."""

    def read(self) -> None:
        """The live bodies' (x, y, angle, vx, vy, w) from pymunk into `state`."""
        self.read_buf.clear()
        batch.get_space_bodies(self.space, batch.BodyFields.POSITION | batch.BodyFields.ANGLE
                               | batch.BodyFields.VELOCITY | batch.BodyFields.ANGULAR_VELOCITY,
                               self.read_buf)
        rows = np.frombuffer(self.read_buf.float_buf()).reshape(-1, 6)
        self.state[self.in_space] = rows[self.live_rows]

    def reconstruct(self) -> dict:
        """Every bone's 3D pose and velocity from `state`: rotation relative
        to rest (B, 3, 3), pivot, lumped COG and COM (m), their velocities
        (m/s), angular velocity (rad/s), pivot-to-tip vector (m), the frame
        its chain moves in (rotation, attachment point); the chains level by
        level from the roots, debris bones from their rigid bodies."""
        n = self.n
        own, wrel, off, voff = self._bends()
        p = {k: np.empty((n, 3, 3) if k in ("rot", "frame_rot") else (n, 3)) for k in POSE_KEYS}
        for lv in self.levels:
            rp, step, piv = self._level_pose(lv, own, off, p)
            self._level_velocity(lv, rp, step, piv, wrel, voff, p)
        if self.debris.count:
            d = self.debris.bones
            p["rot"][d], p["pivot"][d], _, vcom_d, p["omega"][d] = self.debris.bone_poses()
            p["frame_rot"][d] = EYE
            p["vec"][d] = apply(p["rot"][d], self.tip0[d] - self.pivot0[d])
        p["com"] = p["pivot"] + apply(p["rot"], self.com0 - self.pivot0)
        p["vcom"] = p["vcog"] + cross(p["omega"], p["com"] - p["cog"])
        if self.debris.count:
            p["vcom"][d] = vcom_d
            p["vcog"][d] = vcom_d  # debris bones carry no lumped children
            p["cog"][d] = p["com"][d]
        return p

    def _bends(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per bone, from its bodies in each plane: its rotation in its frame
        (B, 3, 3), exp(rho) with rho = theta_0 n_0 (+ theta_1 n_1); its
        angular velocity there, J(rho) rho' (rho' alone is that rate only
        while the turn keeps its direction: "Planes"); its pivot's offset
        from rest and that offset's velocity in its frame (m, m/s; the axial
        part, simulated in every plane, averaged). A body's position is its
        origin (the pivot), its velocity its COG's."""
        s = self.state
        b0, b1, two = self.plane_rows
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
        return matrices_from_rotvec(rho), rotvec_rate(rho, rate), off, voff

    def _level_pose(self, lv: dict, own: np.ndarray, off: np.ndarray,
                    p: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Write one level's frames, rotations, pivots, steps and COGs into
        `p` (its parents' already there): each row's head pivot from its own
        state, the rest following the chain. Returns the frames' rotations,
        the steps and pivots in the level's grid."""
        bones, has, pp = lv["bones"], lv["has"], lv["pp"]
        rot, pivot = p["rot"], p["pivot"]
        rp = np.broadcast_to(EYE, (len(bones), 3, 3)).copy()
        at = lv["attach_rest"].copy()
        if lv["any"]:
            rp[has] = rot[pp]
            at[has] = pivot[pp] + apply(rot[pp], lv["attach_arm"])
        p["frame_rot"][bones] = rp
        p["attach"][bones] = at
        r = compose(rp, own[bones])
        rot[bones] = r
        h = lv["head_pos"]
        head = at[h] + apply(rp[h], lv["head_arm"] + off[lv["heads"]])
        step = np.zeros(lv["grid"].shape + (3,))
        p["vec"][bones] = step[lv["valid"]] = apply(r, lv["step"])
        piv = head[:, None, :] + np.cumsum(step, axis=1) - step
        pivot[bones] = piv[lv["valid"]]
        p["cog"][bones] = pivot[bones] + apply(r, lv["cog_arm"])
        return rp, step, piv

    def _level_velocity(self, lv: dict, rp: np.ndarray, step: np.ndarray, piv: np.ndarray,
                        wrel: np.ndarray, voff: np.ndarray, p: dict) -> None:
        """Write one level's angular velocities and COG velocities into `p`,
        following the chain as the pivots do: each row's head from its own
        body, the rest by the turn rates of the bones before them (a body's
        own axial velocity is averaged over two planes: "Velocities")."""
        bones, has, valid = lv["bones"], lv["has"], lv["valid"]
        omega, vcog, cog = p["omega"], p["vcog"], p["cog"]
        w = apply(rp, wrel[bones])
        if lv["any"]:
            w[has] += omega[lv["pp"]]
        omega[bones] = w
        h = lv["head_pos"]
        hp = piv[:, 0]
        hv = apply(rp[h], voff[lv["heads"]])
        fh = lv["p"][h]
        held = fh >= 0
        if held.any():
            f = fh[held]
            hv[held] += vcog[f] + cross(omega[f], hp[held] - cog[f])
        turn = np.zeros(lv["grid"].shape + (3,))
        turn[valid] = cross(w, step[valid])
        vp = hv[:, None, :] + np.cumsum(turn, axis=1) - turn
        vcog[bones] = vp[valid] + cross(w, cog[bones] - p["pivot"][bones])

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
