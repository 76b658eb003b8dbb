"""Force fields, evaluated in bulk on arrays of points and velocities.

All SI: positions m, velocities m/s, forces N, times s. World frame Z up.
Sources of the models and constants: docs/physics-sources.md.

- Wind: mean speed with a power-law profile, plus turbulence synthesised from
  the IEC 61400-1 Kaimal spectra (u, v, w components) by random-phase inverse
  FFT from a seeded generator, advected as frozen turbulence (Taylor) so that
  gusts sweep downwind through a forest; crosswind lanes one lateral length
  scale apart carry independent series, blended with cos/sin weights (which
  keep the variance).
- Drag: cross-flow drag on wood, 0.5*rho*Cd*D*l*|u_n|*u_n with the velocity
  of the air relative to the bone (so motion is damped by the air), and
  foliage drag with Vogel reconfiguration (Cd*A falls as (|u|/u0)^b above
  u0, streamlining).
- Explosion: Friedlander waveform with Kinney-Graham peak overpressure and
  positive-phase duration for a TNT-equivalent charge (Hopkinson-Cranz
  scaled distance), loading bones through the blast's dynamic pressure and a
  short diffraction (overpressure) pulse.
- Vortex: a moving combined Rankine vortex with radial inflow and updraft; it
  adds to the wind and loads trees through the same drag law.
- Attractor: an acceleration field toward a point, 1/r^2 outside a core.

Parameters a director animates (the wind's speed, heading and turbulence;
a vortex's path, strength and radius; an attractor's position and
strength) are a plain value or a keys.Keyed curve, evaluated at the time
each force is asked for: every engine asks here (sim/loads.py), so every
engine sees the keyed value at its own times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .keys import Keyed, largest, value_at

AIR_DENSITY = 1.2  # kg/m^3
SOUND_SPEED = 340.0  # m/s
ATMOSPHERE = 101_325.0  # Pa


# ---------------------------------------------------------------------------
# wind


def kaimal_spectrum(n: np.ndarray, sigma: float, length: float, mean: float) -> np.ndarray:
    """One-sided Kaimal spectrum S(n) (m^2/s^2 per Hz), IEC 61400-1 form:
    n*S/sigma^2 = (4*n*L/U) / (1 + 6*n*L/U)^(5/3)."""
    x = n * length / mean
    return sigma**2 * (4 * length / mean) / (1 + 6 * x) ** (5.0 / 3.0)


def synthesize(rng: np.random.Generator, count: int, dt: float, sigma: float, length: float,
               mean: float) -> np.ndarray:
    """A zero-mean Gaussian series of `count` samples at spacing `dt` with the
    Kaimal spectrum, by random-phase inverse FFT (periodic over count*dt)."""
    freqs = np.fft.rfftfreq(count, dt)
    spec = np.zeros_like(freqs)
    spec[1:] = kaimal_spectrum(freqs[1:], sigma, length, mean)
    df = 1.0 / (count * dt)
    amp = np.sqrt(spec * df / 2.0) * count  # rfft convention: var = sum over +-f
    phases = rng.uniform(0, 2 * np.pi, len(freqs))
    coeffs = amp * np.exp(1j * phases)
    coeffs[0] = 0.0
    if count % 2 == 0:
        coeffs[-1] = coeffs[-1].real  # the Nyquist term must be real
    series = np.fft.irfft(coeffs, count)
    return series


@dataclass
class Wind:
    """Mean wind `speed` (m/s) at `reference_height` (m) blowing toward
    `direction` (unit horizontal vector, or a Keyed heading in degrees
    counter-clockwise from +X), power-law `shear` exponent, and turbulence
    of intensity `turbulence` (sigma_u / U) with longitudinal length scale
    `length_scale` (m); sigma_v = 0.8 sigma_u, sigma_w = 0.5 sigma_u,
    L_v = L_u / 3, L_w = L_u / 12 (IEC 61400-1 ratios). `speed`,
    `direction` and `turbulence` may be keyed (keys.Keyed); `start`,
    `ramp` and `end` (s) fade the whole wind in and out on top of them.

    Keyed wind, and why its gusts stay right: the turbulence is synthesised
    once, as a frozen field (Taylor) with the Kaimal spectrum for the
    largest mean speed U_ref and the largest sigma_ref = I_ref U_ref of the
    keys (for a wind without keys, its own U and sigma: the field is the
    same as before keys existed). At time t it is read where the air that
    carries it has travelled, int_0^t U(s) ds (m), and scaled by
    sigma(t) / sigma_ref = I(t) U(t) / (I_ref U_ref). The Kaimal spectrum
    depends on frequency only through n L / U, so a frozen field of
    length scale L advected at U(t) gives a fixed point the Kaimal spectrum
    of U(t) at every speed; its variance follows sigma(t)^2 exactly. A
    keyed heading turns the field's axes with the wind about the middle of
    the synthesis box: gusts keep sweeping downwind; while it turns, a point
    at distance R from the middle sees the field slide past at R |dtheta/dt|
    on top of the wind (a few m/s for a 45 degree turn over 6 s at 30 m)."""

    speed: float | Keyed
    direction: np.ndarray | Keyed
    reference_height: float = 10.0
    shear: float = 0.14
    turbulence: float | Keyed = 0.0
    length_scale: float = 50.0
    start: float = 0.0  # s, wind ramps up over `ramp` seconds from here
    ramp: float = 2.0
    end: float = math.inf  # s, wind ramps down over `ramp` seconds from here

    def __post_init__(self):
        self.heading = self.direction if isinstance(self.direction, Keyed) else None
        if self.heading is not None:  # the direction of the strongest wind
            peak = (self.speed.times[int(np.argmax(self.speed.at(np.array(self.speed.times))))]
                    if isinstance(self.speed, Keyed) else self.heading.times[0])
            a = math.radians(self.heading.at(peak))
            self.direction = np.array([math.cos(a), math.sin(a), 0.0])
        self.direction = np.asarray(self.direction, dtype=float)
        self.direction = self.direction / np.linalg.norm(self.direction)
        self.cross = np.array([-self.direction[1], self.direction[0], 0.0])
        self.top_speed = largest(self.speed)  # m/s, U_ref
        self.top_turbulence = largest(self.turbulence)  # I_ref
        self._series = None
        self._origin = None  # the point a keyed heading turns the gust field about
        if isinstance(self.speed, Keyed):
            self._travel0 = self.speed.integral(0.0)

    def axes(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The unit horizontal vectors (3,) the wind blows toward at time t
        (s), and the one 90 degrees counter-clockwise from it."""
        if self.heading is None:
            return self.direction, self.cross
        a = math.radians(self.heading.at(t))
        c, s = math.cos(a), math.sin(a)
        return np.array([c, s, 0.0]), np.array([-s, c, 0.0])

    def _advected(self, t: float) -> float:
        """Where the frozen gust field is read at time t: the distance the
        air has travelled since t = 0 over U_ref (s; t itself for a steady
        mean speed)."""
        if not isinstance(self.speed, Keyed):
            return t
        return (self.speed.integral(t) - self._travel0) / self.top_speed

    def _gain(self, t: float) -> float:
        """sigma_u(t) / sigma_ref: the gusts' scale at time t (1 without keys)."""
        if not isinstance(self.speed, Keyed) and not isinstance(self.turbulence, Keyed):
            return 1.0
        return (value_at(self.turbulence, t) * value_at(self.speed, t)
                / (self.top_turbulence * self.top_speed))

    def _headings(self, duration: float, dt: float) -> np.ndarray:
        """Unit horizontal directions (M, 2) the wind takes over the shot."""
        times = np.union1d(np.arange(0.0, duration + dt, dt), self.heading.times)
        a = np.radians(self.heading.at(times))
        return np.stack([np.cos(a), np.sin(a)], axis=1)

    def prepare(self, rng: np.random.Generator, duration: float, extent: np.ndarray,
                dt: float = 0.05, period: float | None = None) -> None:
        """Synthesise the turbulence for a scene lasting `duration` s over the
        horizontal box `extent` = ((xmin, ymin), (xmax, ymax)) m; with a
        `period` (s, a loop: loop.py) the field read at t and t + period is
        the same (the series' length is the period, its spacing about `dt`)."""
        if self.top_turbulence <= 0 or self.top_speed <= 0:
            return
        lo, hi = np.asarray(extent, dtype=float)
        corners = np.array([[lo[0], lo[1]], [lo[0], hi[1]], [hi[0], lo[1]], [hi[0], hi[1]]])
        if self.heading is None:
            along = corners @ self.direction[:2]
            across = corners @ self.cross[:2]
        else:  # every heading the wind takes, the field turning about the box's middle
            middle = 0.5 * (lo + hi)
            self._origin = np.array([middle[0], middle[1], 0.0])
            heads = self._headings(duration, dt)
            along = (corners - middle) @ heads.T
            across = (corners - middle) @ np.stack([-heads[:, 1], heads[:, 0]], axis=1).T
        self._along0 = float(along.min())
        travel = (along.max() - along.min()) / self.top_speed
        if period is None:
            count = math.ceil((duration + travel + 10.0) / dt)
            count += count % 2
        else:  # the inverse FFT's series repeats over count * dt: make that the period
            count = 2 * max(1, round(period / (2 * dt)))
            dt = period / count
        lateral = self.length_scale / 3
        self._cross0 = float(across.min())
        self._lane = lateral
        lanes = math.ceil((across.max() - across.min()) / lateral) + 2
        sigma_u = self.top_turbulence * self.top_speed
        comps = ((sigma_u, self.length_scale), (0.8 * sigma_u, self.length_scale / 3),
                 (0.5 * sigma_u, self.length_scale / 12))
        self._series = np.stack([
            np.stack([synthesize(rng, count, dt, s, length, self.top_speed)
                      for s, length in comps], axis=-1)
            for _ in range(lanes)])  # (lanes, count, 3)
        self._pairs = np.concatenate([self._series[:-1], self._series[1:]], axis=2)
        self._dt = dt

    def _profile(self, z: np.ndarray, speed: float) -> np.ndarray:
        z = np.maximum(z, 0.5)
        return speed * (z / self.reference_height) ** self.shear

    def ramp_factor(self, t: float) -> float:
        """0 before `start` and after `end` + `ramp`, 1 in between, with
        smoothstep ramps (no jerk)."""
        if t <= self.start or t >= self.end + self.ramp:
            return 0.0
        if self.ramp <= 0:
            return 1.0
        x = min(1.0, (t - self.start) / self.ramp, (self.end + self.ramp - t) / self.ramp)
        return x * x * (3 - 2 * x)

    def velocity(self, points: np.ndarray, t: float) -> np.ndarray:
        """Air velocity (m/s) at `points` (N, 3) at time t (s), the keyed
        parameters taken at t."""
        scale = self.ramp_factor(t)
        if scale == 0.0:
            return np.zeros_like(points)
        direction, cross = self.axes(t)
        along_u = self._profile(points[:, 2], value_at(self.speed, t))
        out = np.empty_like(points)
        if self._series is None:
            out[:] = (scale * along_u)[:, None] * direction
            return out
        rel = points if self._origin is None else points - self._origin
        along = rel @ direction - self._along0
        # frozen turbulence: gusts move downwind
        pos = ((self._advected(t) + 5.0) - along / self.top_speed) / self._dt
        start = np.floor(pos)
        w = (pos - start)[:, None]
        count = self._series.shape[1]
        i0 = start.astype(np.int64) % count
        i1 = (i0 + 1) % count
        lane_pos = (rel @ cross - self._cross0) / self._lane
        l0 = np.clip(np.floor(lane_pos).astype(np.int64), 0, self._series.shape[0] - 2)
        # independent lanes blended with cos/sin weights, which keeps the
        # variance (linear weights would lower it by up to half between lanes);
        # a lane and the next are stored side by side, so two gathers fetch both
        lw = np.clip(lane_pos - l0, 0.0, 1.0) * (np.pi / 2)
        a = self._pairs[l0, i0]
        mix = a + w * (self._pairs[l0, i1] - a)  # (N, 6): lane, next lane
        fluct = np.cos(lw)[:, None] * mix[:, 0:3] + np.sin(lw)[:, None] * mix[:, 3:6]
        gain = self._gain(t)
        if gain != 1.0:
            fluct *= gain
        out[:] = (along_u + fluct[:, 0])[:, None] * direction + fluct[:, 1:2] * cross
        out[:, 2] += fluct[:, 2]
        if scale != 1.0:
            out *= scale
        return out


# ---------------------------------------------------------------------------
# drag


def drag(air: np.ndarray, vel: np.ndarray, axis: np.ndarray, wood_area: np.ndarray,
         leaf_area: np.ndarray, cd_wood: float, cd_leaf: float,
         vogel: float = -0.7, vogel_speed: float = 4.0) -> np.ndarray:
    """Aerodynamic force (N) on bones: cross-flow drag on wood
    0.5*rho*Cd*A*|u_n|*u_n with u_n the relative air velocity normal to the
    bone axis, plus foliage drag 0.5*rho*Cd*A*|u|*u*r(|u|) with Vogel
    reconfiguration r = (|u|/u0)^b above u0 (b < 0)."""
    rel = air - vel
    along = (rel * axis).sum(1, keepdims=True)
    normal = rel - along * axis
    speed_n = np.linalg.norm(normal, axis=1, keepdims=True)
    force = (0.5 * AIR_DENSITY * cd_wood) * wood_area[:, None] * speed_n * normal
    if np.any(leaf_area > 0):
        speed = np.linalg.norm(rel, axis=1, keepdims=True)
        recon = np.where(speed > vogel_speed,
                         (np.maximum(speed, vogel_speed) / vogel_speed) ** vogel, 1.0)
        force += (0.5 * AIR_DENSITY * cd_leaf) * leaf_area[:, None] * speed * recon * rel
    return force


def frontal_areas(axis: np.ndarray, direction: np.ndarray, wood_area: np.ndarray,
                  leaf_area: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The areas (m^2) of wood and of foliage a bone along unit `axis`
    (N, 3) presents to a flow along unit `direction` (N, 3)."""
    cos = np.abs((axis * direction).sum(1))
    sin = np.sqrt(np.clip(1 - cos * cos, 0.0, 1.0))
    return wood_area * sin, 0.5 * leaf_area


# ---------------------------------------------------------------------------
# explosion


def _moments(beta: np.ndarray | float, x: np.ndarray, k_max: int) -> list[np.ndarray]:
    """int_0^x u^k e^(-beta u) du for k = 0 .. k_max <= 2 (beta > 0), on one
    exponential."""
    y = beta * x
    e = np.exp(-y)
    out = [(1 - e) / beta, (1 - e * (1 + y)) / beta**2]
    if k_max == 2:
        out.append((2 - e * (y * y + 2 * y + 2)) / beta**3)
    return out


def kinney_graham_overpressure(z: np.ndarray) -> np.ndarray:
    """Peak side-on overpressure ratio p_s/p_a for a TNT free-air burst at
    scaled distance z (m/kg^(1/3)), Kinney & Graham (1985)."""
    z = np.maximum(z, 0.05)
    num = 808.0 * (1 + (z / 4.5) ** 2)
    den = np.sqrt((1 + (z / 0.048) ** 2) * (1 + (z / 0.32) ** 2) * (1 + (z / 1.35) ** 2))
    return num / den


def kinney_graham_duration(z: np.ndarray, charge: float) -> np.ndarray:
    """Positive-phase duration (s) at scaled distance z for `charge` kg TNT,
    Kinney & Graham (1985): t_d / W^(1/3) in ms."""
    z = np.maximum(z, 0.05)
    ms = 980.0 * (1 + (z / 0.54) ** 10) / ((1 + (z / 0.02) ** 3) * (1 + (z / 0.74) ** 6)
                                          * np.sqrt(1 + (z / 6.9) ** 2))
    return ms * 1e-3 * charge ** (1.0 / 3.0)


@dataclass
class Explosion:
    """A free-air burst of `charge` kg TNT equivalent at `position` (m) at
    time `time` (s)."""

    position: np.ndarray
    time: float
    charge: float
    decay: float = 1.5  # Friedlander decay coefficient (dimensionless)

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=float)

    def front(self, points: np.ndarray):
        """At `points` (N, 3) m: the unit radial direction, the peak
        overpressure and dynamic pressure (Pa), the positive phase's
        duration and the front's arrival (s)."""
        r_vec = points - self.position
        r = np.maximum(np.linalg.norm(r_vec, axis=1), 1e-3)
        z = r / self.charge ** (1.0 / 3.0)
        ps = kinney_graham_overpressure(z) * ATMOSPHERE
        mach = np.sqrt(1 + 6.0 / 7.0 * ps / ATMOSPHERE)  # Rankine-Hugoniot shock Mach
        qs = 2.5 * ps**2 / (7 * ATMOSPHERE + ps)
        return (r_vec / r[:, None], ps, qs, kinney_graham_duration(z, self.charge),
                self.time + r / (SOUND_SPEED * mach))

    def loads(self, points: np.ndarray, t: float):
        """Overpressure p (Pa), dynamic pressure q (Pa) and unit radial
        direction at `points` at time t, and the front's arrival (s)."""
        direction, ps, qs, td, arrival = self.front(points)
        tau = t - arrival
        active = (tau >= 0) & (tau <= td)
        x = np.where(active, tau / td, 1.0)
        wave = np.where(active, (1 - x) * np.exp(-self.decay * x), 0.0)
        return ps * wave, qs * wave**2, direction, arrival

    def force(self, points: np.ndarray, t: float, axis: np.ndarray, wood_area: np.ndarray,
              leaf_area: np.ndarray, diameter: np.ndarray, cd_wood, cd_leaf) -> np.ndarray:
        """Blast force (N) on members at `points` (N, 3) m along `axis`: the
        drag of the dynamic pressure q with the members' own coefficients,
        as the wind's drag takes them (wood `cd_wood` on its frontal area,
        foliage `cd_leaf` on its leaf area; arrays or numbers), plus the
        overpressure's diffraction pulse p on the frontal area, which clears
        in about three transit times of the member (3 D / c)."""
        p, q, direction, arrival = self.loads(points, t)
        wood, leaf = frontal_areas(axis, direction, wood_area, leaf_area)
        clearing = np.exp(-np.maximum(t - arrival, 0.0) / np.maximum(3 * diameter / SOUND_SPEED,
                                                                      1e-5))
        return (q * (cd_wood * wood + cd_leaf * leaf_area)
                + p * clearing * (wood + leaf))[:, None] * direction

    def impulse(self, points: np.ndarray, t: float, axis: np.ndarray, wood_area: np.ndarray,
                leaf_area: np.ndarray, diameter: np.ndarray, cd_wood, cd_leaf):
        """The impulse (N s, (N, 3)) `force` has delivered at each point from
        its front's arrival to time t, for members held in their present
        orientation (exact: the Friedlander pulse and the diffraction's
        clearing integrate in closed form), the front's arrival and the
        positive phase's duration (N,) s."""
        (impulse,), arrival, td = self.impulses(points, (t,), axis, wood_area, leaf_area,
                                                diameter, cd_wood, cd_leaf)
        return impulse, arrival, td

    def impulses(self, points: np.ndarray, times, axis: np.ndarray, wood_area: np.ndarray,
                 leaf_area: np.ndarray, diameter: np.ndarray, cd_wood, cd_leaf):
        """`impulse` at each of `times` (s) for the same members: a list of
        (N, 3) N s, the arrival and the duration (N,) s. The front and the
        areas are the same at every time and are worked out once (a blast's
        load over a hold is the difference of two impulses)."""
        direction, ps, qs, td, arrival = self.front(points)
        clear = np.maximum(3 * diameter / SOUND_SPEED, 1e-5)
        beta = self.decay + td / clear
        wood, leaf = frontal_areas(axis, direction, wood_area, leaf_area)
        on_drag = cd_wood * wood + cd_leaf * leaf_area
        on_pulse = wood + leaf
        out = []
        for t in times:
            x = np.clip((t - arrival) / td, 0.0, 1.0)
            # int_0^x (1-u) e^(-b u) du, and int_0^x (1-u)^2 e^(-2 b u) du
            m0, m1, m2 = _moments(2 * self.decay, x, 2)
            drag = qs * td * (m0 - 2 * m1 + m2)
            p0, p1 = _moments(beta, x, 1)
            pulse = ps * td * (p0 - p1)
            out.append((on_drag * drag + pulse * on_pulse)[:, None] * direction)
        return out, arrival, td

    def reach(self, threshold: float = 500.0) -> float:
        """Distance (m) beyond which the peak overpressure is below
        `threshold` Pa (used to skip trees the blast cannot move)."""
        lo, hi = 0.01, 1e5
        w13 = self.charge ** (1.0 / 3.0)
        for _ in range(60):
            mid = math.sqrt(lo * hi)
            if kinney_graham_overpressure(np.array([mid / w13]))[0] * ATMOSPHERE > threshold:
                lo = mid
            else:
                hi = mid
        return hi


# ---------------------------------------------------------------------------
# vortex and attractor


@dataclass
class Vortex:
    """A combined Rankine vortex (tornado) moving from `start` (x, y, m) with
    `velocity` (vx, vy, m/s), or along a keyed `path` of (x, y) (m; then
    `start` and `velocity` are not used and the air moves with the path's
    rate), from `time` to `end` (s). Tangential speed peaks at `max_speed`
    (m/s) at `core_radius` (m), both possibly keyed; radial inflow is
    `inflow` x tangential speed outside the core, updraft `updraft` x max
    speed inside it. Counter-clockwise seen from above unless `clockwise`."""

    start: np.ndarray
    velocity: np.ndarray
    max_speed: float | Keyed
    core_radius: float | Keyed
    time: float = 0.0
    end: float = math.inf
    inflow: float = 0.5
    updraft: float = 0.5
    clockwise: bool = False
    path: Keyed | None = None

    def __post_init__(self):
        self.start = np.asarray(self.start, dtype=float)[:2]
        self.velocity = np.asarray(self.velocity, dtype=float)[:2]

    def _clamp(self, t: float) -> float:
        return min(max(t, self.time), self.end)

    def centre(self, t: float) -> np.ndarray:
        """The vortex's centre (x, y) m at time t (s)."""
        if self.path is not None:
            return self.path.at(self._clamp(t))
        return self.start + self.velocity * (min(max(t, self.time), self.end) - self.time)

    def translation(self, t: float) -> np.ndarray:
        """The centre's velocity (x, y) m/s at time t (s), which the air
        around it shares."""
        return self.velocity if self.path is None else self.path.derivative(self._clamp(t))

    def reach_speed(self) -> float:
        """The largest max_speed x core_radius over the shot (m^2/s): the
        swirl outside the core is this over r, at most."""
        return largest(self.core_radius) * largest(self.max_speed)

    def air_velocity(self, points: np.ndarray, t: float) -> np.ndarray:
        """Air velocity (m/s) at `points` (N, 3) at time t (s), the keyed
        parameters taken at t."""
        if t < self.time or t > self.end:
            return np.zeros_like(points)
        max_speed = value_at(self.max_speed, t)
        d = points[:, :2] - self.centre(t)
        r = np.maximum(np.linalg.norm(d, axis=1), 1e-6)
        rc = value_at(self.core_radius, t)
        v_t = np.where(r < rc, max_speed * r / rc, max_speed * rc / r)
        radial = d / r[:, None]
        tangent = np.stack([-radial[:, 1], radial[:, 0]], axis=1)
        if self.clockwise:
            tangent = -tangent
        v_r = np.where(r < rc, 0.0, -self.inflow * v_t)
        w = self.updraft * max_speed * np.exp(-((r / rc) ** 2))
        out = np.zeros_like(points)
        out[:, :2] = tangent * v_t[:, None] + radial * v_r[:, None] + self.translation(t)
        out[:, 2] = w
        return out

    def distance_at_closest(self, xy: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """Smallest horizontal distance (m) from each point to the vortex
        centre between t0 and t1 (s); for a keyed path a lower bound
        (Keyed.closest_distance), never more than the truth, so culling
        never drops a tree the vortex reaches."""
        if self.path is not None:
            return self.path.closest_distance(xy, self._clamp(t0), self._clamp(t1))
        a = self.centre(t0)
        b = self.centre(t1)
        ab = b - a
        denom = float(ab @ ab)
        s = np.zeros(len(xy)) if denom == 0 else np.clip(((xy - a) @ ab) / denom, 0, 1)
        closest = a + s[:, None] * ab
        return np.linalg.norm(xy - closest, axis=1)


@dataclass
class Attractor:
    """Acceleration toward `position` (m): `strength` m/s^2 at `radius` m,
    falling as 1/r^2 outside and linearly to zero inside (a uniform sphere's
    gravity), active from `time` to `end` (s). `position` (x, y, z) and
    `strength` may be keyed."""

    position: np.ndarray | Keyed
    strength: float | Keyed
    radius: float = 1.0
    time: float = 0.0
    end: float = math.inf

    def __post_init__(self):
        if not isinstance(self.position, Keyed):
            self.position = np.asarray(self.position, dtype=float)

    def position_at(self, t: float) -> np.ndarray:
        """The point (x, y, z) m at time t (s)."""
        return self.position.at(t) if isinstance(self.position, Keyed) else self.position

    def acceleration(self, points: np.ndarray, t: float) -> np.ndarray:
        """Acceleration (m/s^2) at `points` (N, 3) at time t (s)."""
        if t < self.time or t > self.end:
            return np.zeros_like(points)
        d = self.position_at(t) - points
        r = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        strength = value_at(self.strength, t)
        mag = np.where(r > self.radius, strength * (self.radius / r) ** 2,
                       strength * r / self.radius)
        return d / r[:, None] * mag[:, None]
