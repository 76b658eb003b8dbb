"""Parts broken off a tree: each moves on as one rigid body in 3D.

A broken branch (and everything it carries) leaves its limb's moving frame
and its chain; from the break on it is a rigid body with the momentum it
had, falling under gravity, dragged by the air, and stopped by the ground
(penalty contact at its bones' ends, contact.py) until it comes to rest and
sleeps. All debris bodies are integrated together with numpy.
"""

from __future__ import annotations

import numpy as np

from ..rotations import apply, compose, cross, matrices_from_rotvec
from .contact import Sunk, effective_mass, ground_forces, stored_energy
from .rules import MAX_SPIN, SETTLE_TIME, floored_inertia

MAX_STEP = 1 / 480  # s, the longest rigid-body step (a force update is split into these)
ROLLING = 2.0  # 1/s, decay of spin while touching the ground (rolling resistance)
SLEEP_SPEED = 0.02  # m/s and rad/s below which a grounded body may sleep


class Debris:
    """Rigid debris bodies made of bones of a solver's global bone arrays."""

    def __init__(self, mass, inertia, com0, pivot0, tip0, radius, ground: bool,
                 g: np.ndarray):
        self.mass, self.inertia = mass, inertia
        self.com0, self.pivot0, self.tip0, self.radius = com0, pivot0, tip0, radius
        self.ground = ground
        self.g = g  # m/s^2, the scene's gravity
        self.bones = np.zeros(0, dtype=np.int64)  # bones in debris, in body order
        self.owner = np.zeros(0, dtype=np.int64)  # debris body of each of those bones
        self.rot0 = np.zeros((0, 3, 3))  # bone rotation (rel. rest) at the break
        self.arm_pivot = np.zeros((0, 3))  # bone pivot - body COM, at the break
        self.x = np.zeros((0, 3))  # body COM, m
        self.v = np.zeros((0, 3))  # m/s
        self.r = np.zeros((0, 3, 3))  # body rotation since the break
        self.w = np.zeros((0, 3))  # rad/s, world (follows from the angular momentum)
        self.ang = np.zeros((0, 3))  # angular momentum about the COM, N m s, world
        self.m = np.zeros(0)  # kg
        self.i_body = np.zeros((0, 3, 3))  # kg m^2 about the COM, frame at the break
        self.rest_time = np.zeros(0)  # s spent slow on the ground
        self.asleep = np.zeros(0, dtype=bool)
        self.clamped = 0  # body substeps whose spin was clamped to MAX_SPIN
        self.work = np.zeros(len(mass))  # J per bone: work of the loads other than gravity
        # ground allowances of each bone's two ends (contact.Sunk), body order
        self.sunk_pivot, self.sunk_tip = Sunk(), Sunk()
        self.contact_step = MAX_STEP  # s, the substep the contact springs were last set for

    @property
    def count(self) -> int:
        return len(self.m)

    def add(self, bones: np.ndarray, pose: dict, asleep: bool = False) -> None:
        """Make one rigid body of `bones`, moving as they move in `pose`
        (or, `asleep`, lying still until something hits it)."""
        rot = pose["rot"][bones]
        com = pose["com"][bones]
        m = self.mass[bones]
        total = float(m.sum())
        x = (m[:, None] * com).sum(0) / total
        v_b = pose["vcom"][bones]
        v = (m[:, None] * v_b).sum(0) / total
        d = com - x
        inertia_w = compose(compose(rot, self.inertia[bones]), np.transpose(rot, (0, 2, 1)))
        eye = np.eye(3)
        i_body = (inertia_w + m[:, None, None] * ((d * d).sum(1)[:, None, None] * eye
                                                 - d[:, :, None] * d[:, None, :])).sum(0)
        spin = np.einsum("bij,bj->bi", inertia_w, pose["omega"][bones])
        momentum = (cross(d, m[:, None] * (v_b - v)) + spin).sum(0)
        i_body = floored_inertia(i_body)
        w = np.linalg.solve(i_body, momentum)
        k = self.count
        self.bones = np.concatenate([self.bones, bones])
        self.owner = np.concatenate([self.owner, np.full(len(bones), k)])
        self.rot0 = np.concatenate([self.rot0, rot])
        self.arm_pivot = np.concatenate([self.arm_pivot, pose["pivot"][bones] - x])
        self.x = np.vstack([self.x, x])
        self.v = np.vstack([self.v, v])
        self.r = np.concatenate([self.r, eye[None]])
        self.w = np.vstack([self.w, w])
        self.ang = np.vstack([self.ang, i_body @ w])
        self.m = np.append(self.m, total)
        self.i_body = np.concatenate([self.i_body, i_body[None]])
        self.rest_time = np.append(self.rest_time, 0.0)
        self.asleep = np.append(self.asleep, asleep)
        if asleep:
            self.v[-1] = self.w[-1] = self.ang[-1] = 0.0
        # the part's chain touched the ground at its bones' tips only, with
        # its own contact springs: ends already in the soil stay there
        pivot = pose["pivot"][bones]
        tip = pivot + apply(rot, self.tip0[bones] - self.pivot0[bones])
        self.sunk_pivot.extend(self.radius[bones] - pivot[:, 2])
        self.sunk_tip.extend(self.radius[bones] - tip[:, 2])

    def loads(self, force: np.ndarray, com: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-body force and torque about the body COM from per-bone forces
        (debris bones' rows of solver arrays, in `self.bones` order) acting
        at `com`."""
        n = self.count
        f = np.stack([np.bincount(self.owner, force[:, a], minlength=n) for a in range(3)], 1)
        tq = cross(com - self.x[self.owner], force)
        t = np.stack([np.bincount(self.owner, tq[:, a], minlength=n) for a in range(3)], 1)
        return f, t

    def impulse(self, row: int, impulse: np.ndarray, point: np.ndarray) -> None:
        """Apply a world impulse (N s) at a world point to the body of the
        debris bone at `row` (of `self.bones`)."""
        k = int(self.owner[row])
        i_world = self.r[k] @ self.i_body[k] @ self.r[k].T
        self.v[k] += impulse / self.m[k]
        self.ang[k] += cross(point - self.x[k], impulse)
        self.w[k] = np.linalg.solve(i_world, self.ang[k])
        self.asleep[k] = False
        self.rest_time[k] = 0.0

    def bone_poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Rotation (rel. rest), pivot, COM velocity and angular velocity of
        every debris bone (in `self.bones` order)."""
        r = self.r[self.owner]
        rot = compose(r, self.rot0)
        pivot = self.x[self.owner] + apply(r, self.arm_pivot)
        com = pivot + apply(rot, self.com0[self.bones] - self.pivot0[self.bones])
        w = self.w[self.owner]
        vcom = self.v[self.owner] + cross(w, com - self.x[self.owner])
        return rot, pivot, vcom, w

    def step(self, dt: float, loads) -> None:
        """Advance all bodies by `dt` s. `loads(com, vcom, axis, start, h)`
        gives the world force (N, gravity included) on each debris bone at
        its COM, held over the substep [start, start + h] s (from the step's
        start); it and the ground contact are re-evaluated every substep (a
        light leafy stick tumbling in a gale turns too fast for held loads)."""
        if not self.count:
            return
        substeps = max(1, round(dt / MAX_STEP))
        h = dt / substeps
        for k in range(substeps):
            awake = ~self.asleep
            if not awake.any():
                return
            rot, pivot, vcom, _ = self.bone_poses()
            com = pivot + apply(rot, self.com0[self.bones] - self.pivot0[self.bones])
            axis = apply(rot, self.tip0[self.bones] - self.pivot0[self.bones])
            axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
            bone_force = loads(com, vcom, axis, k * h, h)
            gravity = self.mass[self.bones, None] * self.g
            # held over the substep: work = force x the COM's displacement,
            # at the mean of its velocities before and after (exact for the
            # step's constant force; the velocity before alone missed
            # m a^2 h^2 / 2 per substep: 2 J per ms on a blasted sapling's
            # ten broken twigs, pushed at 2000 m/s^2); the COM's arm from its
            # body's is the step's start's
            external = bone_force - gravity
            arm = com - self.x[self.owner]
            self.work[self.bones] += 0.5 * (external * vcom).sum(1) * h
            f, tq = self.loads(bone_force, com)
            touching = np.zeros(self.count, dtype=bool)
            if self.ground:
                cf, ct, touching = self._contact(h)
                f += cf
                tq += ct
            # angular momentum, not velocity, is integrated: explicit Euler on
            # Euler's equations (the gyroscopic term) gains energy for
            # unequal principal moments; with L the free tumble is exact
            self.v[awake] += (f / self.m[:, None] * h)[awake]
            self.ang[awake] += (tq * h)[awake]
            self.ang[touching] *= np.exp(-ROLLING * h)
            i_world = compose(compose(self.r, self.i_body), np.transpose(self.r, (0, 2, 1)))
            self.w = np.linalg.solve(i_world, self.ang[..., None])[..., 0]
            spin = np.linalg.norm(self.w, axis=1)
            fast = spin > MAX_SPIN
            if fast.any():  # a tumbling stick faster than this is not physical: count it
                scale = (MAX_SPIN / spin[fast])[:, None]
                self.w[fast] *= scale
                self.ang[fast] *= scale
                self.clamped += int(fast.sum())
            self.x[awake] += (self.v * h)[awake]
            turn = matrices_from_rotvec(self.w * h)
            self.r[awake] = compose(turn, self.r)[awake]
            v_end = self.v[self.owner] + cross(self.w[self.owner], arm)
            self.work[self.bones] += 0.5 * (external * v_end).sum(1) * h
            slow = touching & (np.linalg.norm(self.v, axis=1) < SLEEP_SPEED) & \
                (np.linalg.norm(self.w, axis=1) < SLEEP_SPEED)
            self.rest_time = np.where(slow, self.rest_time + h, 0.0)
            newly = slow & (self.rest_time > SETTLE_TIME)
            self.v[newly] = 0.0
            self.w[newly] = 0.0
            self.ang[newly] = 0.0
            self.asleep |= newly

    def _ends(self, shrink: bool = False):
        """Both ends of every debris bone (pivots, then tips), their owner
        bodies, contact radii (less their allowances; `shrink` updates
        those to the ends' present depths) and effective masses."""
        r = self.r[self.owner]
        rot = compose(r, self.rot0)
        pivot = self.x[self.owner] + apply(r, self.arm_pivot)
        tip = pivot + apply(rot, self.tip0[self.bones] - self.pivot0[self.bones])
        full = self.radius[self.bones]
        if shrink:
            radius = np.concatenate([self.sunk_pivot.radius(full, pivot),
                                     self.sunk_tip.radius(full, tip)])
        else:
            radius = np.concatenate([full - self.sunk_pivot.depth, full - self.sunk_tip.depth])
        ends = np.concatenate([pivot, tip])
        owner = np.concatenate([self.owner, self.owner])
        arm = ends - self.x[owner]
        i_min = np.linalg.eigvalsh(self.i_body)[:, 0]
        m_eff = effective_mass(self.m[owner], i_min[owner], arm)
        return ends, owner, radius, arm, m_eff * self._share(ends, owner, radius, m_eff)

    def _share(self, ends, owner, radius, m_eff) -> np.ndarray:
        """Per end, the factor (<= 1) on its spring's mass that keeps the
        springs of all of its body's ends in the ground together no stiffer
        than one spring tuned to the body's whole mass. Each end's spring
        is stable alone; a limb lying along the ground touches it at many
        ends at once, their stiffness adds up past what the substep holds,
        and the limb bounces off faster than it landed (a 9.4 kg willow
        limb: 11 -> 28 m/s)."""
        down = radius - ends[:, 2] > 0
        pressed = np.bincount(owner, np.where(down, m_eff, 0.0), minlength=self.count)
        return np.minimum(1.0, self.m / np.maximum(pressed, 1e-12))[owner]

    def contact_energy(self) -> np.ndarray:
        """Elastic energy (J) per debris bone (in `self.bones` order) held
        in its ends' ground springs (contact.stored_energy)."""
        if not self.count or not self.ground:
            return np.zeros(len(self.bones))
        ends, owner, radius, arm, m_eff = self._ends()
        rise = self.v[owner, 2] + cross(self.w[owner], arm)[:, 2]
        e = stored_energy(ends, rise, radius, m_eff, self.contact_step)
        return e[:len(self.bones)] + e[len(self.bones):]

    def _contact(self, h: float):
        """Ground forces and torques on each body from its bones' two ends."""
        ends, owner, radius, arm, m_eff = self._ends(shrink=True)
        vel = self.v[owner] + cross(self.w[owner], arm)
        self.contact_step = h
        f = ground_forces(ends, vel, radius, m_eff, h)
        n = self.count
        force = np.stack([np.bincount(owner, f[:, a], minlength=n) for a in range(3)], 1)
        tq = cross(arm, f)
        torque = np.stack([np.bincount(owner, tq[:, a], minlength=n) for a in range(3)], 1)
        touching = np.bincount(owner, (f[:, 2] > 0).astype(float), minlength=n) > 0
        return force, torque, touching
