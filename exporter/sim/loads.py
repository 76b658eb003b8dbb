"""A scene's force fields combined into one evaluator on bone arrays, shared
by the planar LOD and the MuJoCo reference so both see identical loads."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..forces import Attractor, Explosion, Vortex, Wind, drag
from ..scene import Scene

# Below these, a field is taken not to move a tree (used to skip simulation).
MIN_PRESSURE = 200.0  # Pa, explosion peak overpressure
MIN_AIR_SPEED = 0.5  # m/s, vortex air speed
BLAST_SAMPLES = 16  # midpoint samples of a blast's force over a held interval


@dataclass
class BoneProps:
    """Per-bone constants the loads need (arrays over all bones)."""

    mass: np.ndarray  # kg
    wood_area: np.ndarray  # m^2
    leaf_area: np.ndarray  # m^2
    diameter: np.ndarray  # m
    cd_wood: np.ndarray  # drag coefficient
    cd_leaf: np.ndarray


class SceneLoads:
    """External loads of a scene. `gravity` is always included; prestress
    (the grown shape is the equilibrium under gravity) is the solver's job."""

    def __init__(self, scene: Scene, extent: np.ndarray | None = None):
        self.scene = scene
        self.g = np.array([0.0, 0.0, -scene.gravity])
        self.blast_active = False  # did the last `forces` call feel a blast
        rng = np.random.default_rng(scene.seed)
        self.wind = None
        if scene.wind is not None and scene.wind.speed > 0:
            w = scene.wind
            a = math.radians(w.direction)
            self.wind = Wind(w.speed, np.array([math.cos(a), math.sin(a), 0.0]),
                             w.reference_height, w.shear, w.turbulence, w.length_scale,
                             w.start, w.ramp, w.end)
            if extent is None:
                extent = np.array([[-10.0, -10.0], [10.0, 10.0]])
            self.wind.prepare(rng, scene.duration, extent)
        self.explosions = [Explosion(np.array(e.position), e.time, e.charge)
                           for e in scene.explosions]
        self.vortices = [Vortex(np.array(v.start), np.array(v.velocity), v.max_speed,
                                v.core_radius, v.time, v.end, v.inflow, v.updraft, v.clockwise)
                         for v in scene.vortices]
        self.attractors = [Attractor(np.array(a.position), a.strength, a.radius, a.time, a.end)
                           for a in scene.attractors]

    @property
    def has_flow(self) -> bool:
        return self.wind is not None or bool(self.vortices)

    def air_velocity(self, points: np.ndarray, t: float) -> np.ndarray:
        air = np.zeros_like(points)
        if self.wind is not None:
            air += self.wind.velocity(points, t)
        for v in self.vortices:
            air += v.air_velocity(points, t)
        return air

    def forces(self, t: float, com: np.ndarray, vel: np.ndarray, axis: np.ndarray,
               props: BoneProps, include_gravity: bool = True, dt: float = 0.0,
               blast_start: float | None = None) -> np.ndarray:
        """World force (N) at each bone's centre of mass: gravity, drag
        against the air (still air included: it damps motion), blasts,
        attractors. A solver that holds the result for `dt` seconds gets the
        blast force averaged over [t, t + dt] (or [blast_start, blast_start
        + dt]: the implicit tier's step that ends at t): a blast's positive
        phase lasts milliseconds, and a sample held over the interval would
        miss it or overstate its impulse."""
        air = self.air_velocity(com, t)
        force = _drag_per_bone(air, vel, axis, props)
        self.blast_active = False
        if include_gravity:
            force += props.mass[:, None] * self.g
        t_blast = t if blast_start is None else blast_start
        for e in self.explosions:
            if t_blast + dt < e.time:
                continue
            samples = BLAST_SAMPLES if dt > 0 else 1
            for ts in t_blast + dt * (np.arange(samples) + 0.5) / samples if dt > 0 else [t]:
                blast = e.force(com, ts, axis, props.wood_area, props.leaf_area,
                                props.diameter, 1.2)
                if blast.any():
                    self.blast_active = True
                    force += blast / samples
        for a in self.attractors:
            force += props.mass[:, None] * a.acceleration(com, t)
        return force

    def blast_near(self, t: float, dt: float) -> bool:
        """Whether a blast's pulse may load something within [t, t + dt]: from
        its detonation until its front has run past MIN_PRESSURE (at the
        speed of sound) and its positive phase is over."""
        for e in self.explosions:
            end = e.time + e.reach(MIN_PRESSURE) / 300.0 + 0.05
            if t + dt >= e.time and t <= end:
                return True
        return False

    def blasts_passed(self, t: float, points: np.ndarray) -> bool:
        """Whether every blast's pulse has passed all `points` (N, 3) m by t s."""
        return all(e.passed(points) < t for e in self.explosions)

    def quiet_after(self, centre: np.ndarray, radius: float, height: float) -> float:
        """Time (s) after which no time-varying load reaches a tree whose
        crown fits in a vertical cylinder (centre xy, radius, height): 0 if
        none ever does, inf if one lasts all scene (wind)."""
        quiet = 0.0
        if self.wind is not None:
            quiet = self.wind.end + self.wind.ramp
        for e in self.explosions:
            d = max(0.0, float(np.linalg.norm(e.position[:2] - centre[:2])) - radius)
            if d < e.reach(MIN_PRESSURE):
                quiet = max(quiet, e.time + d / 300.0 + 2.0)
        for v in self.vortices:
            # outside the core the swirl falls as 1/r: reach where it drops below MIN_AIR_SPEED
            reach = v.core_radius * v.max_speed / MIN_AIR_SPEED
            t1 = min(v.end, self.scene.duration)
            if v.distance_at_closest(centre[None, :2], v.time, t1)[0] - radius < reach:
                quiet = max(quiet, t1)
        for a in self.attractors:
            if a.strength != 0:
                quiet = max(quiet, min(a.end, self.scene.duration))
        return quiet


def _drag_per_bone(air, vel, axis, props: BoneProps) -> np.ndarray:
    """Drag with per-bone coefficients (species differ in a forest)."""
    return drag(air, vel, axis, props.wood_area * props.cd_wood, props.leaf_area * props.cd_leaf,
                1.0, 1.0)
