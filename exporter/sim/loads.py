"""A scene's force fields (forces.py, flows.py) combined into one evaluator on bone arrays, shared
by the planar LOD and the MuJoCo reference so both see identical loads.
Keyed parameters (keys.Keyed) are taken at the time each engine asks
(`forces`, `air_velocity`); where a bound over the shot is needed (which
trees a force can reach) the largest key is used."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import loop
from ..flows import Downwash, Gust
from ..forces import Attractor, Explosion, Vortex, Wind, drag
from ..keys import Keyed, always_zero, largest
from ..scene import Scene

# Below these, a field is taken not to move a tree (used to skip simulation).
MIN_PRESSURE = 200.0  # Pa, explosion peak overpressure
MIN_AIR_SPEED = 0.5  # m/s, air speed of a vortex, a gust, a downwash
# A blast's push is capped at MAX_ACCELERATION x each bone's mass and what
# the cap holds back is delivered after at the same rate: the bone gets the
# pulse's whole impulse, whatever an engine holds its loads for
# (docs/physics.md, "A blast's push is capped in rate, not in impulse")
MAX_ACCELERATION = 2000.0  # m/s^2: external loads on a bone are capped here (reported)


@dataclass
class BoneProps:
    """Per-bone constants the loads need (arrays over all bones)."""

    mass: np.ndarray  # kg
    wood_area: np.ndarray  # m^2
    leaf_area: np.ndarray  # m^2
    diameter: np.ndarray  # m
    cd_wood: np.ndarray  # drag coefficient
    cd_leaf: np.ndarray

    def take(self, index) -> BoneProps:
        """These constants for some of the bones (an index or a mask)."""
        return BoneProps(self.mass[index], self.wood_area[index], self.leaf_area[index],
                         self.diameter[index], self.cd_wood[index], self.cd_leaf[index])


class SceneLoads:
    """External loads of a scene. `gravity` is always included; prestress
    (the grown shape is the equilibrium under gravity) is the solver's job."""

    def __init__(self, scene: Scene, extent: np.ndarray | None = None):
        self.scene = scene
        self.g = np.array([0.0, 0.0, -scene.gravity])
        self.blast_active = False  # did the last `forces` call feel a blast
        self.blast_capped = np.zeros(0)  # m/s^2, per bone: its capped blast (0: none)
        rng = np.random.default_rng(scene.seed)
        self.wind = None
        if scene.wind is not None and largest(scene.wind.speed) > 0:
            w, period = scene.wind, loop.period(scene)
            if isinstance(w.direction, Keyed):
                direction = w.direction
            else:
                a = math.radians(w.direction)
                direction = np.array([math.cos(a), math.sin(a), 0.0])
            self.wind = Wind(w.speed, direction, w.reference_height, w.shear, w.turbulence,
                             w.length_scale, w.start, w.ramp, w.end)
            if extent is None:
                extent = np.array([[-10.0, -10.0], [10.0, 10.0]])
            self.wind.prepare(rng, scene.duration, extent, period=period)
        self.explosions = [Explosion(np.array(e.position), e.time, e.charge)
                           for e in scene.explosions]
        self.vortices = [Vortex(np.array(v.start if v.path is None else v.path.values[0]),
                                np.array(v.velocity), v.max_speed, v.core_radius, v.time, v.end,
                                v.inflow, v.updraft, v.clockwise, v.path)
                         for v in scene.vortices]
        self.gusts = [Gust(g.position if isinstance(g.position, Keyed) else np.array(g.position),
                           g.speed, g.radius, g.direction, g.profile, g.time, g.ramp, g.end)
                      for g in scene.gusts]
        self.downwashes = [Downwash(d.position if isinstance(d.position, Keyed)
                                    else np.array(d.position), d.thrust, d.radius, d.time,
                                    d.ramp, d.end, d.floor)
                           for d in scene.downwashes]
        self.attractors = [Attractor(a.position if isinstance(a.position, Keyed)
                                     else np.array(a.position), a.strength, a.radius, a.time,
                                     a.end)
                           for a in scene.attractors]

    def dominant_direction(self, base: np.ndarray, cut=None, pulls=()) -> np.ndarray | None:
        """The unit horizontal direction the pymunk tier lays a tree's
        bending planes along, for a tree standing at `base` (m): the first
        of its felling cut's, a pull's, the wind's, a blast's (away from
        it), a vortex's swirl, a gust's heading at its start, a downwash's
        outwash (away from its hub at its start), an attractor's, a
        projectile's flight; None if none has one."""
        if cut is not None:
            a = math.radians(cut.direction)
            return np.array([math.cos(a), math.sin(a), 0.0])
        for p in pulls:
            if (d := _horizontal(p.force)) is not None:
                return d
        if self.wind is not None:
            return self.wind.direction.copy()
        for e in self.explosions:
            if (d := _horizontal(base - e.position)) is not None:
                return d
        for v in self.vortices:
            if (d := _horizontal(base[:2] - v.centre(v.time))) is not None:
                return np.array([-d[1], d[0], 0.0])  # the swirl is tangential
        for g in self.gusts:
            if (d := _horizontal(g.heading(g.time + g.ramp))) is not None:
                return d
        for w in self.downwashes:
            if (d := _horizontal(base - w.hub(w.time))) is not None:
                return d
        for a in self.attractors:
            if (d := _horizontal(a.position_at(a.time) - base)) is not None:
                return d
        for p in self.scene.projectiles:
            if (d := _horizontal(p.velocity)) is not None:
                return d
        return None

    def air_velocity(self, points: np.ndarray, t: float) -> np.ndarray:
        """Air velocity (m/s) at `points` (N, 3) m at time t (s): the wind,
        the vortices, the gusts and the downwash, summed."""
        air = np.zeros_like(points)
        if self.wind is not None:
            air += self.wind.velocity(points, t)
        for v in self.vortices:
            air += v.air_velocity(points, t)
        for source in (*self.gusts, *self.downwashes):
            air += source.air_velocity(points, t)
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
        miss it or overstate its impulse: the pulse is integrated exactly and
        its rate capped (MAX_ACCELERATION, the rest delivered after);
        `blast_capped` (B,) m/s^2 is the mean acceleration the pulse asked
        of each bone over its part of the hold, where past the cap (else 0)."""
        air = self.air_velocity(com, t)
        force = _drag_per_bone(air, vel, axis, props)
        self.blast_active = False
        if include_gravity:
            force += props.mass[:, None] * self.g
        self.blast_capped = np.zeros(len(com))
        t_blast = t if blast_start is None else blast_start
        for e in self.explosions:
            if t_blast + dt < e.time:
                continue
            args = (axis, props.wood_area, props.leaf_area, props.diameter, props.cd_wood,
                    props.cd_leaf)
            if dt <= 0:  # a sample (rigid debris), capped at the rate
                blast = e.force(com, t, *args)
                asked = np.linalg.norm(blast, axis=1) / props.mass
                over = asked > MAX_ACCELERATION
                blast[over] *= (MAX_ACCELERATION / asked[over])[:, None]
            else:
                (i0, i1), arrival, duration = e.impulses(com, (t_blast, t_blast + dt), *args)
                if not i1.any():
                    continue
                blast = (self._capped(i1, t_blast + dt - arrival, props.mass)
                         - self._capped(i0, t_blast - arrival, props.mass)) / dt
                # what the pulse asked: its mean acceleration over its part of the hold
                within = np.minimum(t_blast + dt, arrival + duration) - np.maximum(t_blast,
                                                                                  arrival)
                asked = np.where(within > 0, np.linalg.norm(i1 - i0, axis=1) / (
                    props.mass * np.maximum(within, 1e-12)), 0.0)
                over = asked > MAX_ACCELERATION
            self.blast_active = self.blast_active or bool(blast.any())
            np.maximum(self.blast_capped, np.where(over, asked, 0.0), out=self.blast_capped)
            force += blast
        for a in self.attractors:
            force += props.mass[:, None] * a.acceleration(com, t)
        return force

    @staticmethod
    def _capped(impulse: np.ndarray, since: np.ndarray, mass: np.ndarray) -> np.ndarray:
        """A pulse's cumulative impulse (N s, (N, 3)) as the cap delivers it:
        its own `impulse` so far, but at most MAX_ACCELERATION x mass x the
        time `since` its front arrived (s)."""
        size = np.linalg.norm(impulse, axis=1)
        limit = mass * MAX_ACCELERATION * np.maximum(since, 0.0)
        scale = np.where(size > limit, limit / np.maximum(size, 1e-300), 1.0)
        return impulse * scale[:, None]

    def blast_windows(self, com: np.ndarray, axis: np.ndarray,
                      props: BoneProps) -> list[tuple[float, float]]:
        """When each blast pushes these bones (at `com` (B, 3) m along
        `axis`), s: from its front's arrival at the first until its pulse,
        and the capped push that delivers the rest of its impulse, are over
        at the last."""
        out = []
        for e in self.explosions:
            total, arrival, duration = e.impulse(com, math.inf, axis, props.wood_area,
                                                 props.leaf_area, props.diameter, props.cd_wood,
                                                 props.cd_leaf)
            pushed = np.linalg.norm(total, axis=1) / (props.mass * MAX_ACCELERATION)
            out.append((float(arrival.min(initial=np.inf)),
                        float((arrival + np.maximum(duration, pushed)).max(initial=e.time))))
        return out

    def blast_pushing(self, t: float, dt: float, com: np.ndarray, axis: np.ndarray,
                      props: BoneProps, after: float = 0.0) -> bool:
        """Whether a blast pushes any of these bones within [t, t + dt] s
        (or pushed them within `after` s before)."""
        return meets(self.blast_windows(com, axis, props), t, dt, after)

    def blasts_passed(self, t: float, com: np.ndarray, axis: np.ndarray,
                      props: BoneProps) -> bool:
        """Whether every blast's push on these bones is over by t s."""
        return all(last < t for _, last in self.blast_windows(com, axis, props))

    def quiet_after(self, centre: np.ndarray, radius: float, height: float) -> float:
        """Time (s) after which no time-varying load reaches a tree whose
        crown fits in a vertical cylinder (centre xy, radius, height): 0 if
        none ever does, inf if one lasts all scene (wind). Keyed strengths
        and radii count at their largest, keyed paths at their closest."""
        quiet = 0.0
        if self.wind is not None:
            quiet = self.wind.end + self.wind.ramp
        for e in self.explosions:
            d = max(0.0, float(np.linalg.norm(e.position[:2] - centre[:2])) - radius)
            if d < e.reach(MIN_PRESSURE):
                quiet = max(quiet, e.time + d / 300.0 + 2.0)
        for v in self.vortices:
            # outside the core the swirl falls as 1/r: reach where it drops below MIN_AIR_SPEED
            reach = v.reach_speed() / MIN_AIR_SPEED
            t1 = min(v.end, self.scene.duration)
            if v.distance_at_closest(centre[None, :2], v.time, t1)[0] - radius < reach:
                quiet = max(quiet, t1)
        for source in (*self.gusts, *self.downwashes):
            # both last until `end` + `ramp`; a keyed path counts where it comes closest
            t1 = min(source.end + source.ramp, self.scene.duration)
            if source.reaches(centre[:2], radius, MIN_AIR_SPEED, t1):
                quiet = max(quiet, t1)
        for a in self.attractors:
            if not always_zero(a.strength):
                quiet = max(quiet, min(a.end, self.scene.duration))
        return quiet


def _horizontal(v) -> np.ndarray | None:
    """The unit horizontal part of a vector, None if it has none."""
    v = np.array([v[0], v[1], 0.0], dtype=float)
    n = np.linalg.norm(v)
    return v / n if n > 1e-9 else None


def meets(windows, t: float, dt: float, after: float = 0.0) -> bool:
    """Whether [t, t + dt] s meets any of the (first, last) windows (s),
    each extended by `after` s (blast_windows; a blast's ringing)."""
    return any(t + dt >= first and t <= last + after for first, last in windows)


def _drag_per_bone(air, vel, axis, props: BoneProps) -> np.ndarray:
    """Drag with per-bone coefficients (species differ in a forest)."""
    return drag(air, vel, axis, props.wood_area * props.cd_wood, props.leaf_area * props.cd_leaf,
                1.0, 1.0)
