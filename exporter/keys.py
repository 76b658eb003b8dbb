"""Keyed values: a force parameter that is one value for the whole shot, or
a curve through keys {time (s), value} that a director sets
(docs/scenes.md, "Keys").

A `Keyed` curve holds its first key's value before the first key and its
last key's after the last, and between keys interpolates

- `linear`: straight lines (C0; exact at the keys);
- `smooth`: the monotone piecewise cubic Hermite interpolant (PCHIP:
  Fritsch & Carlson 1980, with the Fritsch & Butland 1984 weighted
  harmonic mean of the neighbouring secants as the slope at an interior
  key, zero where they differ in sign) and zero slope at the first and
  last keys. It is C1 everywhere, the holds before and after included,
  and chosen over Catmull-Rom because it never overshoots: between two
  keys each component stays between their values, so a wind speed never
  dips below zero between keys that are zero and one, a radius never
  leaves its allowed range, and the largest key is the curve's largest
  value (what culling bounds use: `largest`). The price: a key where the
  curve turns (a local extremum) is flat;
- `step`: each key's value until the next key (exact; jumps at keys).

Values are numbers or vectors (a vortex's centre, an attractor's position:
each component interpolated on its own). Angles (`angular`, degrees) are
unwrapped before interpolating, so a heading turns the short way round
(350 -> 10 passes 0, not 180); an exact half turn goes clockwise.
Evaluation is vectorised over time: `at(times)` takes a number or an
array of times (s). Units are the parameter's own (m/s, m, degrees, m/s^2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

INTERPOLATIONS = ("linear", "smooth", "step")

Value = float | tuple[float, ...]


@dataclass(frozen=True)
class Keyed:
    """A curve through keys: `times` (s, strictly increasing, at least one)
    and `values` (numbers, or tuples of equal length for vectors), with an
    `interpolation` of INTERPOLATIONS; `angular`: values are angles in
    degrees, interpolated the short way round."""

    times: tuple[float, ...]
    values: tuple[Value, ...]
    interpolation: str = "linear"
    angular: bool = False
    _t: np.ndarray = field(init=False, repr=False, compare=False)  # (K,) s
    _v: np.ndarray = field(init=False, repr=False, compare=False)  # (K, D), angles unwrapped
    _d: np.ndarray = field(init=False, repr=False, compare=False)  # (K, D) slopes at keys, /s

    def __post_init__(self):
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation {self.interpolation!r} is not one of "
                             f"{', '.join(INTERPOLATIONS)}")
        if not self.times or len(self.times) != len(self.values):
            raise ValueError("a Keyed curve needs as many values as times, at least one")
        t = np.asarray(self.times, dtype=float)
        if np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
            raise ValueError("key times must be finite and strictly increasing")
        v = np.asarray(self.values, dtype=float)
        v = v.reshape(len(t), -1)
        if not np.all(np.isfinite(v)):
            raise ValueError("key values must be finite")
        if self.angular:  # each step the short way round: into [-180, 180)
            steps = (np.diff(v, axis=0) + 180.0) % 360.0 - 180.0
            v = np.concatenate([v[:1], v[:1] + np.cumsum(steps, axis=0)])
        object.__setattr__(self, "_t", t)
        object.__setattr__(self, "_v", v)
        object.__setattr__(self, "_d", _pchip_slopes(t, v) if self.interpolation == "smooth"
                           else np.zeros_like(v))

    @classmethod
    def constant(cls, value: Value) -> Keyed:
        """One key: the same value at every time."""
        return cls((0.0,), (value,))

    @property
    def scalar(self) -> bool:
        """Whether the values are numbers (not vectors)."""
        return not isinstance(self.values[0], tuple)

    def _locate(self, ts: np.ndarray):
        """Per time: the key at or before it (i, clipped to the keys), the
        next (j; j == i after the last key), the interval h (s; 0 after the
        last) and the fraction s in [0, 1] through it."""
        t = self._t
        i = np.clip(np.searchsorted(t, ts, side="right") - 1, 0, len(t) - 1)
        j = np.minimum(i + 1, len(t) - 1)
        h = t[j] - t[i]
        s = np.clip(np.divide(ts - t[i], h, out=np.zeros_like(ts), where=h > 0), 0.0, 1.0)
        return i, j, h[:, None], s[:, None]

    def _shape(self, t, out: np.ndarray):
        """(N, D) results as `t` was given: a number per scalar time for a
        scalar curve, (D,) for a vector one; (N,) or (N, D) for arrays."""
        if np.ndim(t) == 0:
            return float(out[0, 0]) if self.scalar else out[0]
        return out[:, 0] if self.scalar else out

    def at(self, t):
        """The value at time(s) `t` (s)."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        v = self._v
        i, j, h, s = self._locate(ts)
        if self.interpolation == "step" or len(v) == 1:
            out = v[i]
        elif self.interpolation == "linear":
            out = v[i] + s * (v[j] - v[i])
        else:
            # the cubic Hermite basis, h00 written as 1 - h01: exact on flat stretches
            s2 = s * s
            out = (v[i] + s2 * (3 - 2 * s) * (v[j] - v[i])
                   + h * (s * (1 - s) ** 2 * self._d[i] + s2 * (s - 1) * self._d[j]))
        return self._shape(t, out)

    def derivative(self, t):
        """The rate of change (unit/s) at time(s) `t`: 0 outside the keys
        and for `step`; at a key, a `linear` curve's slope after it."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        v = self._v
        i, j, h, s = self._locate(ts)
        inside = ((ts >= self._t[0]) & (ts < self._t[-1]))[:, None]
        safe = np.where(h > 0, h, 1.0)
        if self.interpolation == "step" or len(v) == 1:
            out = np.zeros((len(ts), v.shape[1]))
        elif self.interpolation == "linear":
            out = np.where(inside, (v[j] - v[i]) / safe, 0.0)
        else:
            s2 = s * s
            out = np.where(inside, (6 * s2 - 6 * s) * (v[i] - v[j]) / safe
                           + (3 * s2 - 4 * s + 1) * self._d[i] + (3 * s2 - 2 * s) * self._d[j],
                           0.0)
        return self._shape(t, out)

    def integral(self, t):
        """The integral of the curve (unit x s) from its first key to time(s)
        `t` (negative before it), exact for every interpolation."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        v, d, t0 = self._v, self._d, self._t
        hk = np.diff(t0)[:, None]
        if self.interpolation == "step":
            whole = hk * v[:-1]
        elif self.interpolation == "linear":
            whole = hk * 0.5 * (v[:-1] + v[1:])
        else:
            whole = hk * (0.5 * (v[:-1] + v[1:]) + hk * (d[:-1] - d[1:]) / 12.0)
        cum = np.concatenate([np.zeros((1, v.shape[1])), np.cumsum(whole, axis=0)])
        i, j, h, s = self._locate(ts)
        if self.interpolation == "step":
            part = h * s * v[i]
        elif self.interpolation == "linear":
            part = h * (s * v[i] + 0.5 * s * s * (v[j] - v[i]))
        else:
            s2, s3, s4 = s * s, s**3, s**4
            part = h * ((s - s3 + 0.5 * s4) * v[i] + (0.5 * s2 - 2 * s3 / 3 + 0.25 * s4) * h * d[i]
                        + (s3 - 0.5 * s4) * v[j] + (0.25 * s4 - s3 / 3) * h * d[j])
        before = (np.minimum(ts - t0[0], 0.0))[:, None] * v[0]
        after = (np.maximum(ts - t0[-1], 0.0))[:, None] * v[-1]
        return self._shape(t, cum[i] + part + before + after)

    def largest(self) -> np.ndarray:
        """The largest value of each component over all time (D,): the
        largest key's, as no interpolation overshoots its keys."""
        return self._v.max(axis=0)

    def smallest(self) -> np.ndarray:
        """The smallest value of each component over all time (D,)."""
        return self._v.min(axis=0)

    def closest_distance(self, points: np.ndarray, t0: float, t1: float) -> np.ndarray:
        """For a curve of (x, y) values (m): a lower bound on the distance
        (m) from each of `points` (N, 2) to the curve's values between
        times t0 and t1 (s); exact for `linear` (the polyline) and `step`
        (its keys), and for `smooth` the distance to the boxes two
        consecutive keys span (the monotone cubic stays within them)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        inner = self._t[(self._t > t0) & (self._t < t1)]
        knots = np.concatenate([[t0], inner, [t1]]) if t1 > t0 else np.array([t0])
        p = np.asarray(self.at(knots)).reshape(len(knots), 2)
        best = np.linalg.norm(points[:, None, :] - p[None], axis=2).min(axis=1)
        if len(p) == 1 or self.interpolation == "step":
            return best
        a, b = p[:-1], p[1:]
        rel = points[:, None, :] - a[None]  # (N, M, 2)
        if self.interpolation == "linear":
            ab = b - a
            denom = (ab * ab).sum(1)
            s = np.clip(np.divide((rel * ab).sum(2), denom, out=np.zeros(rel.shape[:2]),
                                  where=denom > 0), 0.0, 1.0)
            gap = rel - s[..., None] * ab
        else:
            lo, hi = np.minimum(a, b), np.maximum(a, b)
            gap = np.maximum(np.maximum(lo[None] - points[:, None, :],
                                        points[:, None, :] - hi[None]), 0.0)
        return np.minimum(best, np.linalg.norm(gap, axis=2).min(axis=1))


def _pchip_slopes(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Slopes (K, D) at the keys for the monotone cubic: zero at the ends
    and where the secants on either side differ in sign (or one is flat),
    else their weighted harmonic mean (Fritsch & Butland), which keeps each
    interval monotone."""
    d = np.zeros_like(v)
    if len(t) < 3:
        return d
    h = np.diff(t)[:, None]
    secant = np.diff(v, axis=0) / h
    a, b = secant[:-1], secant[1:]
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    same = a * b > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (w1 + w2) / (w1 / a + w2 / b)
    d[1:-1] = np.where(same, mean, 0.0)
    return d


# ---------------------------------------------------------------------------
# a parameter that is a plain value or a Keyed curve


Param = float | Keyed


def value_at(param, t: float):
    """A parameter's value at time t (s): itself when it is not keyed."""
    return param.at(t) if isinstance(param, Keyed) else param


def largest(param) -> float:
    """The largest value a scalar parameter takes over the shot."""
    return float(param.largest()[0]) if isinstance(param, Keyed) else param


def always_zero(param) -> bool:
    """Whether a parameter is zero at every time."""
    if isinstance(param, Keyed):
        return bool(np.all(param.largest() == 0) and np.all(param.smallest() == 0))
    return bool(np.all(np.asarray(param) == 0))
