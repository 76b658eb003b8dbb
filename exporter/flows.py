"""Moving wind sources: a gust (a local pulse of air carried along a path)
and a rotor's downwash (the helicopter shot). Both are air velocity fields
(m/s) that SceneLoads.air_velocity adds to the wind and the vortices, so
every engine loads trees with them through the same drag law and the
energy audit counts their work.

All SI: positions m, velocities m/s, thrust N, times s; world frame Z up,
the ground at z = 0. Models and their sources: docs/physics.md ("Gusts and
downwash") and docs/physics-sources.md.

- Gust: u = speed(t) e(t) f(d / radius) h(t), d the distance (m) from the
  gust's centre, f its `profile` (`bump`: (1 - (d/radius)^2)^3 inside the
  radius, 0 beyond; `gaussian`: exp(-(d/radius)^2)), e(t) the smoothstep
  envelope of `time`, `ramp`, `end`, h(t) a unit horizontal heading: the
  keyed `direction`, or the path's direction of travel.
- Downwash: momentum theory gives the induced velocity at the disk
  v_i = sqrt(T / (2 rho pi R^2)); below the disk the wake speeds up to
  2 v_i along the axis as v_i (1 + s / sqrt(s^2 + R^2)) (s: depth below the
  disk, m); at the ground it turns into a radial wall jet whose peak speed
  falls as 2 v_i R / r, in a layer whose thickness grows with r so that the
  jet carries the rotor's thrust as momentum flux.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .forces import AIR_DENSITY
from .keys import Keyed, largest, value_at

TRAVEL_SPEED = 1.0  # m/s: below it a gust heading along its travel fades with the speed
# The wall jet's layer: its peak at height JET_LAYER x sqrt(r^2 + R^2), the
# value for which the jet's momentum flux beyond r ~ 2 R is the thrust
# (docs/physics.md, "Downwash")
JET_LAYER = math.exp(-2.0)  # = 1 / (4 int_0^inf (n e^(1-n))^2 dn) = 0.135


def envelope(t: float, start: float, ramp: float, end: float) -> float:
    """0 before `start` and after `end` + `ramp` (s), 1 in between, with
    smoothstep ramps of `ramp` s (C1: no jump in force or its rate)."""
    if t <= start or t >= end + ramp:
        return 0.0
    if ramp <= 0:
        return 1.0
    x = min(1.0, (t - start) / ramp, (end + ramp - t) / ramp)
    return x * x * (3 - 2 * x)


def _xy(path: Keyed) -> Keyed:
    """The horizontal (x, y) part of a keyed (x, y, z) path: each component
    is interpolated on its own, so it is the same curve seen from above."""
    return Keyed(path.times, tuple(tuple(v[:2]) for v in path.values), path.interpolation)


def _point_at(position, t: float) -> np.ndarray:
    return np.asarray(position.at(t) if isinstance(position, Keyed) else position, dtype=float)


def _closest(position, xy: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """A lower bound on the horizontal distance (m) from `xy` (N, 2) to a
    keyed or fixed (x, y, z) position between t0 and t1 (s)."""
    if isinstance(position, Keyed):
        return _xy(position).closest_distance(xy, t0, t1)
    return np.linalg.norm(xy - np.asarray(position, dtype=float)[:2], axis=1)


@dataclass
class Gust:
    """A pulse of air of peak speed `speed` (m/s, may be keyed) at its
    centre `position` (x, y, z) m (fixed or a keyed path), falling off with
    distance d (m) as `profile` says over `radius` (m), blowing toward the
    keyed or fixed heading `direction` (degrees counter-clockwise from +X),
    or with None along the path's horizontal direction of travel (scaled by
    min(1, travel speed / TRAVEL_SPEED): a source that stops makes no wind,
    and the heading never jumps). Active from `time` to `end` (s), with
    smoothstep ramps of `ramp` s."""

    position: np.ndarray | Keyed
    speed: float | Keyed
    radius: float
    direction: float | Keyed | None = None
    profile: str = "bump"
    time: float = 0.0
    ramp: float = 0.5
    end: float = math.inf

    def centre(self, t: float) -> np.ndarray:
        """The gust's centre (x, y, z) m at time t (s)."""
        return _point_at(self.position, t)

    def heading(self, t: float) -> np.ndarray:
        """The horizontal vector (2,) the air blows along at time t (s): unit
        for a given direction, at most unit along the travel."""
        if self.direction is not None:
            a = math.radians(value_at(self.direction, t))
            return np.array([math.cos(a), math.sin(a)])
        if not isinstance(self.position, Keyed):
            return np.zeros(2)
        v = np.asarray(self.position.derivative(t), dtype=float)[:2]
        return v / max(float(np.linalg.norm(v)), TRAVEL_SPEED)

    def shape(self, d: np.ndarray) -> np.ndarray:
        """The profile f at distances `d` (m) from the centre: 1 at 0."""
        x2 = (d / self.radius) ** 2
        if self.profile == "gaussian":
            return np.exp(-x2)
        return np.where(x2 < 1.0, (1.0 - np.minimum(x2, 1.0)) ** 3, 0.0)

    def air_velocity(self, points: np.ndarray, t: float) -> np.ndarray:
        """Air velocity (m/s) at `points` (N, 3) at time t (s)."""
        out = np.zeros_like(points)
        scale = envelope(t, self.time, self.ramp, self.end) * value_at(self.speed, t)
        if scale == 0.0:
            return out
        heading = self.heading(t)
        if not heading.any():
            return out
        d = np.linalg.norm(points - self.centre(t), axis=1)
        out[:, :2] = (scale * self.shape(d))[:, None] * heading
        return out

    def reach(self, slowest: float) -> float:
        """Distance (m) from the centre beyond which the air is slower than
        `slowest` m/s at every time (the radius for `bump`: nothing beyond)."""
        top = largest(self.speed)
        if self.profile == "bump" or top <= slowest:
            return self.radius
        return self.radius * math.sqrt(math.log(top / slowest))

    def reaches(self, xy: np.ndarray, radius: float, slowest: float, t1: float) -> bool:
        """Whether the gust can blow faster than `slowest` m/s anywhere in a
        vertical cylinder at `xy` (2,) m of `radius` m before t1 (s)."""
        if t1 <= self.time:
            return False
        d = _closest(self.position, np.asarray(xy, dtype=float)[None, :2], self.time, t1)[0]
        return d - radius < self.reach(slowest)


@dataclass
class Downwash:
    """A hovering rotor of radius `radius` (m) at `position` (x, y, z) m (its
    hub, z above the ground; fixed or a keyed path) giving `thrust` (N, may
    be keyed): the wake below it and the radial outwash over the ground,
    active from `time` to `end` (s) with smoothstep ramps of `ramp` s. The
    field is the hover's, carried with the rotor (no skew of the wake in
    forward flight). The wake turns into the outwash at height `floor` (m):
    0 over open ground; over a dense forest, about its canopy's top, which
    the wake cannot pass through: the outwash then blows across the crowns
    and the air below the floor is left still (a sheltered understorey)."""

    position: np.ndarray | Keyed
    thrust: float | Keyed
    radius: float
    time: float = 0.0
    ramp: float = 1.0
    end: float = math.inf
    floor: float = 0.0

    def hub(self, t: float) -> np.ndarray:
        """The rotor's hub (x, y, z) m at time t (s)."""
        return _point_at(self.position, t)

    def induced(self, thrust: float) -> float:
        """Momentum theory's induced velocity (m/s) at the disk for a thrust
        (N): v_i = sqrt(T / (2 rho A)), A = pi R^2."""
        return math.sqrt(max(thrust, 0.0) / (2 * AIR_DENSITY * math.pi * self.radius**2))

    def air_velocity(self, points: np.ndarray, t: float) -> np.ndarray:
        """Air velocity (m/s) at `points` (N, 3) at time t (s)."""
        out = np.zeros_like(points)
        scale = envelope(t, self.time, self.ramp, self.end)
        if scale == 0.0:
            return out
        v_i = scale * self.induced(value_at(self.thrust, t))
        if v_i == 0.0:
            return out
        hub = self.hub(t)
        big_r = self.radius
        d = points[:, :2] - hub[:2]
        x2 = (d * d).sum(1) / big_r**2  # (r / R)^2
        z = np.maximum(points[:, 2] - self.floor, 0.0)  # height above the floor, m
        # the wake: v_i at the disk, 2 v_i far below it, on the axis of a
        # uniformly loaded disk (the vortex cylinder); across the wake it falls
        # off smoothly past the contracted wake's R / sqrt(2); near the floor
        # it slows to nothing within about R / 2 as the flow turns outward
        depth = (hub[2] - self.floor - z) / big_r
        along = v_i * (1.0 + depth / np.sqrt(1.0 + depth * depth))
        across = np.exp(-x2 * x2)
        turning = -np.expm1(-(2.0 * z / big_r) ** 2)
        out[:, 2] = -along * across * turning
        # the wall jet: peak 2 v_i (1 - exp(-x^2)) / x, R / r far out (x = r / R),
        # 0 on the axis (the stagnation point); its height profile n e^(1 - n),
        # n = z / layer, peaks at the layer's height
        layer = JET_LAYER * big_r * np.sqrt(x2 + 1.0)
        n = z / layer
        rise = n * np.exp(1.0 - n)
        # (1 - exp(-x^2)) / x^2 -> 1 on the axis: the jet's speed per metre of d
        per_metre = np.where(x2 > 1e-12, -np.expm1(-x2) / np.maximum(x2, 1e-12), 1.0)
        out[:, :2] = d * ((2.0 * v_i / big_r) * per_metre * rise)[:, None]
        return out

    def reach(self, slowest: float) -> float:
        """Horizontal distance (m) from the hub beyond which the air is
        slower than `slowest` m/s at every time: past r = R both the wake's
        (2 v_i e^(-x^4)) and the jet's (2 v_i R / r) speed are below
        2 v_i R / r, so |u| < sqrt(2) 2 v_i R / r there."""
        top = 2.0 * self.induced(largest(self.thrust))
        return max(self.radius, math.sqrt(2.0) * top * self.radius / slowest)

    def reaches(self, xy: np.ndarray, radius: float, slowest: float, t1: float) -> bool:
        """Whether the downwash can blow faster than `slowest` m/s anywhere
        in a vertical cylinder at `xy` (2,) m of `radius` m before t1 (s)."""
        if t1 <= self.time:
            return False
        d = _closest(self.position, np.asarray(xy, dtype=float)[None, :2], self.time, t1)[0]
        return d - radius < self.reach(slowest)
