"""Parts broken off a tree: each moves on as one rigid body in 3D, with the
momentum it had, under gravity and air loads, stopped by the ground (penalty
contact at its bones' ends, contact.py), until it comes to rest and sleeps.
All debris bodies are integrated together with numpy."""

from __future__ import annotations

import numpy as np

from ..rotations import apply, compose, cross, matrices_from_rotvec
from .contact import Sunk, effective_mass, ground_forces, stored_energy
from .rules import MAX_SPIN, SETTLE_TIME, floored_inertia

MAX_STEP = 1 / 480  # s, the longest rigid-body step (a force update is split into these)
ROLLING = 2.0  # 1/s, decay of spin while touching the ground (rolling resistance)
SLEEP_SPEED = 0.02  # m/s and rad/s below which a grounded body may sleep


def summed(index: np.ndarray, values: np.ndarray, n: int = 0) -> np.ndarray:
    """The rows of `values` (N, 3) summed by `index`: (max(n, index + 1), 3)."""
    return np.stack([np.bincount(index, values[:, k], minlength=n) for k in range(3)], 1)


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
        new = {"bones": bones, "owner": np.full(len(bones), self.count), "rot0": rot,
               "arm_pivot": pose["pivot"][bones] - x, "x": x[None], "v": v[None],
               "r": eye[None], "w": w[None], "ang": (i_body @ w)[None], "m": [total],
               "i_body": i_body[None], "rest_time": [0.0], "asleep": [asleep]}
        for name, rows in new.items():
            setattr(self, name, np.concatenate([getattr(self, name), rows]))
        if asleep:
            self.v[-1] = self.w[-1] = self.ang[-1] = 0.0
        # the part's chain touched the ground at its bones' tips only, with
        # its own contact springs: ends already in the soil stay there
        pivot = pose["pivot"][bones]
        tip = pivot + apply(rot, self.tip0[bones] - self.pivot0[bones])
        self.sunk_pivot.extend(self.radius[bones] - pivot[:, 2])
        self.sunk_tip.extend(self.radius[bones] - tip[:, 2])

    def _per_body(self, owner: np.ndarray, force: np.ndarray,
                  arm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces (N) at `arm` (m) from their `owner` bodies' COMs summed per
        body, with their torques (N m) about the COM."""
        return summed(owner, force, self.count), summed(owner, cross(arm, force), self.count)

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

    def _placed(self) -> tuple[np.ndarray, np.ndarray]:
        """Every debris bone's rotation (rel. rest) and pivot (m)."""
        r = self.r[self.owner]
        return compose(r, self.rot0), self.x[self.owner] + apply(r, self.arm_pivot)

    def bone_poses(self) -> tuple[np.ndarray, ...]:
        """Rotation (rel. rest), pivot, COM (m), COM velocity (m/s) and
        angular velocity (rad/s) of every debris bone (`self.bones` order)."""
        rot, pivot = self._placed()
        com = pivot + apply(rot, self.com0[self.bones] - self.pivot0[self.bones])
        w = self.w[self.owner]
        vcom = self.v[self.owner] + cross(w, com - self.x[self.owner])
        return rot, pivot, com, vcom, w

    def step(self, dt: float, loads) -> None:
        """Advance all bodies by `dt` s. `loads(com, vcom, axis, start, h)`
        gives the world force (N, gravity included) on each debris bone at
        its COM, held over the substep [start, start + h] s (from the step's
        start); it and the ground contact are re-evaluated every substep
        (tumbling debris turns too fast for held loads: docs/physics.md,
        "Breaking")."""
        if not self.count:
            return
        substeps = max(1, round(dt / MAX_STEP))
        h = dt / substeps
        for k in range(substeps):
            awake = ~self.asleep
            if not awake.any():
                return
            rot, _, com, vcom, _ = self.bone_poses()
            axis = apply(rot, self.tip0[self.bones] - self.pivot0[self.bones])
            axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-12)
            bone_force = loads(com, vcom, axis, k * h, h)
            gravity = self.mass[self.bones, None] * self.g
            # the loads' work at the mean of the COM's velocities before and
            # after the substep, exact for its constant force
            external = bone_force - gravity
            arm = com - self.x[self.owner]  # the step's start's
            self.work[self.bones] += 0.5 * (external * vcom).sum(1) * h
            f, tq = self._per_body(self.owner, bone_force, arm)
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
            self.v[newly] = self.w[newly] = self.ang[newly] = 0.0
            self.asleep |= newly

    def _ends(self, shrink: bool = False):
        """Both ends of every debris bone (pivots, then tips), their owner
        bodies, contact radii (less their allowances; `shrink` updates
        those to the ends' present depths) and effective masses."""
        rot, pivot = self._placed()
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
        than one spring tuned to the body's whole mass: each is stable alone,
        but a limb lying along the ground touches at many ends at once, and
        their stiffness adds up past what the substep holds ("Ground")."""
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
        touching = np.bincount(owner, (f[:, 2] > 0).astype(float), minlength=self.count) > 0
        return *self._per_body(owner, f, arm), touching
