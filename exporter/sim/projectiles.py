"""Projectiles (heavy boxes and spheres) for the planar LOD: they fly in 3D
under gravity at the force rate; a swept sphere-capsule test along each
step's path finds their hits on bones, which exchange an impulse with
restitution and Coulomb friction, both ways. Boxes collide as their
inscribed sphere but carry orientation and spin; the ground is z = 0."""

from __future__ import annotations

import numpy as np

from ..model import TreeModel
from ..rotations import cross
from ..scene import Scene

NEAR_MARGIN = 0.1  # m: what a hold's gravity and the bones' own motion may add
NEAR_SPEED = 1.0  # m/s: slower projectiles hit at the force rate


def closest_segment_points(p0, p1, q0, q1):
    """Closest points between segments p0-p1 (N, 3) and q0-q1 (N, 3): the
    parameters s, u in [0, 1] and the distance."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = (d1 * d1).sum(1)
    e = (d2 * d2).sum(1)
    f = (d2 * r).sum(1)
    c = (d1 * r).sum(1)
    b = (d1 * d2).sum(1)
    denom = a * e - b * b
    eps = 1e-12
    s = np.where(denom > eps, np.clip((b * f - c * e) / np.where(denom > eps, denom, 1), 0, 1),
                 0.0)
    s = np.where(a > eps, s, 0.0)
    u = np.where(e > eps, (b * s + f) / np.where(e > eps, e, 1), 0.0)
    # clamp u and recompute s
    u_lo, u_hi = u < 0, u > 1
    u = np.clip(u, 0, 1)
    s = np.where(u_lo & (a > eps), np.clip(-c / np.where(a > eps, a, 1), 0, 1), s)
    s = np.where(u_hi & (a > eps), np.clip((b - c) / np.where(a > eps, a, 1), 0, 1), s)
    cp = p0 + d1 * s[:, None]
    cq = q0 + d2 * u[:, None]
    return s, u, np.linalg.norm(cp - cq, axis=1), cp, cq


def bone_spheres(pose: dict, solver):
    """The bones' pivots and tips (B, 3) in `pose`, and the spheres that
    bound them: centres (B, 3) and radii (B,), m."""
    piv = pose["pivot"]
    tip = piv + np.einsum("bij,bj->bi", pose["rot"], solver.tip0 - solver.pivot0)
    return piv, tip, 0.5 * (piv + tip), 0.5 * np.linalg.norm(tip - piv, axis=1) + solver.radius


class Projectiles:
    """The scene's projectiles: their flight, hits and the track per frame."""

    def __init__(self, projectiles: list, frames: int):
        def each(name: str) -> np.ndarray:
            return np.array([getattr(x, name) for x in projectiles], dtype=float)

        self.shape = [x.shape for x in projectiles]
        self.size, self.mass, self.pos = each("size"), each("mass"), each("position")
        self.radius = self.size / 2
        self.vel = np.zeros_like(self.pos)
        self.launch_vel, self.time = each("velocity"), each("time")
        self.e, self.mu = each("restitution"), each("friction")  # restitution, Coulomb
        self.launched = np.zeros(len(self.mass), dtype=bool)
        self.quat = np.tile([0.0, 0.0, 0.0, 1.0], (len(self.mass), 1))
        self.spin = np.zeros_like(self.pos)
        self.inertia = np.where(np.array([s == "box" for s in self.shape]),
                                self.mass * self.size**2 / 6, 0.4 * self.mass * self.radius**2)
        self.track_pos = np.zeros((frames, len(self.mass), 3))
        self.track_quat = np.zeros((frames, len(self.mass), 4))
        self.track_pos[0] = self.pos
        self.track_quat[0] = self.quat
        self.hits = 0

    @classmethod
    def from_scene(cls, scene: Scene) -> Projectiles:
        """The scene's projectiles, tracked over its frames."""
        return cls(scene.projectiles, scene.frame_count)

    def record(self, frame: int) -> None:
        """Keep the pose at `frame`."""
        self.track_pos[frame] = self.pos
        self.track_quat[frame] = self.quat

    def advance(self, t: float, dt: float, pose: dict, solver) -> None:
        """Launch those due at `t` s and fly every launched one over `dt` s:
        hits on the solver's bones in `pose` (both ways), the ground, spin."""
        start = ~self.launched & (t >= self.time)
        self.vel[start] = self.launch_vel[start]
        self.launched |= start
        live = np.nonzero(self.launched)[0]
        if not len(live):
            return
        g = solver.loads.g
        for i in live:
            v = self.vel[i] + g * dt
            a, b = self.pos[i].copy(), self.pos[i] + v * dt
            hit = self._hit_bones(i, a, b, v, pose, solver)
            if hit is not None:
                s, v = hit
                b = a + (b - a) * s + v * dt * (1 - s)
            self.pos[i], self.vel[i] = b, v
            self._ground(i, dt, -float(g[2]))
            w = self.spin[i]
            if np.any(w):
                x, y, z, qw = self.quat[i]
                dq = 0.5 * dt * np.array([w[0] * qw + w[1] * z - w[2] * y,
                                          -w[0] * z + w[1] * qw + w[2] * x,
                                          w[0] * y - w[1] * x + w[2] * qw,
                                          -w[0] * x - w[1] * y - w[2] * z])
                q = self.quat[i] + dq
                self.quat[i] = q / np.linalg.norm(q)

    def near(self, pose, solver, hold: float) -> bool:
        """Whether a flying projectile (faster than NEAR_SPEED) may touch a
        bone within `hold` s (each bone's bounding sphere against the
        projectile's reach). One at rest by a tree is not: its contacts are
        slow, and it would hold the updates at every substep for the rest
        of the shot."""
        live = np.nonzero(self.launched & (np.linalg.norm(self.vel, axis=1) > NEAR_SPEED))[0]
        if not len(live):
            return False
        _, _, mid, half = bone_spheres(pose, solver)
        for i in live:
            reach = half + self.radius[i] + np.linalg.norm(self.vel[i]) * hold + NEAR_MARGIN
            if (np.linalg.norm(mid - self.pos[i], axis=1) < reach).any():
                return True
        return False

    def _hit_bones(self, i, a, b, v, pose, solver):
        """Hits of projectile i on its path a -> b (m) at velocity v (m/s):
        every bone its sphere touches takes an impulse, nearest along the
        path first, each against the velocity the ones before left it (with
        one hit per step, twigs in front shielded the stem: docs/physics.md,
        "Projectiles"). Returns the path fraction of the first hit and the
        velocity after all, or None."""
        piv, tip, mid, half = bone_spheres(pose, solver)
        reach = half + self.radius[i] + 0.5 * np.linalg.norm(b - a)
        near = np.nonzero(np.linalg.norm(mid - 0.5 * (a + b), axis=1) < reach)[0]
        if not len(near):
            return None
        m = len(near)
        s, _, dist, cp, cq = closest_segment_points(np.repeat(a[None], m, 0),
                                                    np.repeat(b[None], m, 0), piv[near], tip[near])
        touching = np.nonzero(dist < solver.radius[near] + self.radius[i])[0]
        first = None
        for k in touching[np.argsort(s[touching], kind="stable")]:
            after = self._impulse(i, int(near[k]), cp[k], cq[k], v, pose, solver)
            if after is not None:
                v = after
                first = float(s[k]) if first is None else first
        return None if first is None else (first, v)

    def _impulse(self, i, bone, on_path, on_bone, v, pose, solver):
        """Exchange an impulse between projectile i (velocity v, m/s) and a
        bone touching it (closest points on its path and on the bone, m),
        with restitution and Coulomb friction. Returns the projectile's new
        velocity, or None where the two already separate."""
        normal = on_path - on_bone
        nn = np.linalg.norm(normal)
        normal = normal / nn if nn > 1e-9 else -v / max(np.linalg.norm(v), 1e-9)
        v_bone = pose["vcog"][bone] + cross(pose["omega"][bone], on_bone - pose["cog"][bone])
        rel = v - v_bone
        vn = rel @ normal
        if vn >= 0:
            return None
        m_bone = solver.lump_mass[bone]
        reduced = 1.0 / (1.0 / self.mass[i] + 1.0 / m_bone)
        jn = -(1 + self.e[i]) * vn * reduced
        vt = rel - vn * normal
        st = np.linalg.norm(vt)
        jt = np.zeros(3) if st < 1e-9 else -vt / st * min(self.mu[i] * jn, reduced * st)
        impulse = jn * normal + jt  # on the projectile
        before = self._energy(i, v)
        v = v + impulse / self.mass[i]
        r = -normal * self.radius[i]
        self.spin[i] += cross(r, jt) / self.inertia[i]
        after = self._energy(i, v)
        solver.add_work(bone, max(before - after, 0.0))  # the most the tree can have got
        solver.apply_impulse(bone, -impulse, on_bone + normal * solver.radius[bone], pose)
        self.hits += 1
        return v

    def _energy(self, i: int, v: np.ndarray) -> float:
        """Kinetic energy (J) of projectile i at velocity v (m/s) and its spin."""
        return 0.5 * self.mass[i] * (v @ v) + 0.5 * self.inertia[i] * (self.spin[i] @ self.spin[i])

    def _ground(self, i: int, dt: float, gravity: float) -> None:
        """Projectile i on the ground (z = 0) over `dt` s: a bounce with its
        restitution and friction, and sliding friction under `gravity` m/s^2."""
        r = self.radius[i]
        if self.pos[i, 2] >= r:
            return
        self.pos[i, 2] = r
        vz = self.vel[i, 2]
        if vz < 0:
            self.vel[i, 2] = -self.e[i] * vz
            self._brake(i, self.mu[i] * (1 + self.e[i]) * -vz)
        if abs(self.vel[i, 2]) < 0.2:  # resting contact: friction and spin decay
            self._brake(i, self.mu[i] * gravity * dt)
            self.spin[i] *= 0.8

    def _brake(self, i: int, most: float) -> None:
        """Slow projectile i's horizontal velocity by at most `most` m/s."""
        vh = self.vel[i, :2]
        speed = np.linalg.norm(vh)
        if speed > 0:
            self.vel[i, :2] = vh - vh / speed * min(speed, most)


def projectile_reaches(scene: Scene, model: TreeModel) -> bool:
    """Whether a projectile's ballistic path passes near the tree."""
    lo, hi = model.bounds()
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi[:2] - lo[:2])) + 1.0
    g = scene.gravity
    for p in scene.projectiles:
        pos = np.array(p.position, dtype=float)
        vel = np.array(p.velocity, dtype=float)
        for _ in range(2000):  # ballistic path until it lands, 10 ms steps
            if np.linalg.norm(pos[:2] - centre[:2]) < radius + p.size and pos[2] < hi[2] + p.size:
                return True
            vel[2] -= g * 0.01
            pos += vel * 0.01
            if pos[2] < -1:
                break
    return False
