"""Sway measurements on baked motion: the field pull-and-release test.

Foresters measure a tree's first sway frequency and damping ratio by pulling
the stem sideways with a rope and letting go; we do the same in the
simulator (a scene `[[pull]]`) and read the free decay of the trunk's top.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .bake import TreeBake
from .rotations import apply, matrices_from_quaternions


def segment_ends(tree: TreeBake, segments: np.ndarray) -> np.ndarray:
    """World position (F, len(segments), 3) m of the end point of each segment."""
    segments = np.asarray(segments)
    rest = tree.points[tree.seg_end[segments]] - tree.points[tree.seg_start[segments]]
    frames = tree.positions.shape[0]
    out = np.empty((frames, len(segments), 3))
    for f in range(frames):
        r = matrices_from_quaternions(tree.rotations[f, segments].astype(float))
        out[f] = tree.positions[f, segments] + apply(r, rest)
    return out


def _crossings(t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Times (s) at which x crosses zero, linearly interpolated."""
    s = np.signbit(x)
    i = np.nonzero(s[1:] != s[:-1])[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


def frequency(t: np.ndarray, x: np.ndarray) -> float:
    """Dominant frequency (Hz) of an oscillation about its final mean, from
    the spacing of zero crossings. NaN if fewer than three crossings."""
    tail = x[len(x) // 2:]
    z = _crossings(t, x - float(np.mean(tail)))
    if len(z) < 3:
        return math.nan
    return (len(z) - 1) / (2.0 * (z[-1] - z[0]))


def damping_ratio(t: np.ndarray, x: np.ndarray, cycles: int = 3) -> float:
    """Damping ratio from the logarithmic decrement of the first `cycles`
    successive peaks of |x| (about the final mean), one per half cycle."""
    y = x - float(np.mean(x[len(x) // 2:]))
    z = _crossings(t, y)
    peaks = []
    for a, b in itertools.pairwise(z):
        sel = (t >= a) & (t <= b)
        if sel.any():
            peaks.append(float(np.abs(y[sel]).max()))
    peaks = peaks[: 2 * cycles + 1]
    if len(peaks) < 3 or min(peaks) <= 0:
        return math.nan
    # half-cycle decrement: ln(p_i / p_{i+1}) = pi zeta / sqrt(1 - zeta^2)
    delta = float(np.mean(np.log(np.asarray(peaks[:-1]) / np.asarray(peaks[1:]))))
    return delta / math.sqrt(math.pi**2 + delta**2)


@dataclass
class SwayResult:
    frequency: float  # Hz, measured after release
    damping: float  # damping ratio, measured
    rayleigh_frequency: float  # Hz, the rig's estimate (no simulation)
    height: float  # m
    dbh: float  # m
    force: float  # N, the pull
    deflection: float  # m, trunk top at release


def pull_release(grammar: str | Path, seed: int | None = None, quality: str = "default",
                 deflection: float = 0.01, at: float = 0.6, release: float = 3.0,
                 duration: float = 12.0, fps: float = 60.0, log=None,
                 progress=None) -> SwayResult:
    """Pull the trunk at `at` x height until its top has moved about
    `deflection` x height, release at `release` s, and measure the free
    sway of the trunk top in the pull's direction (still air, gravity on).
    `log` and `progress` as for pipeline.bake_scene (the simulation's)."""
    from .grow import grow
    from .pipeline import bake_scene
    from .quality import QUALITIES
    from .rig import RigOptions, build_rig
    from .scene import parse_scene

    tree = {"grammar": str(Path(grammar).resolve())}
    if seed is not None:
        tree["seed"] = seed
    raw = {"name": "pull-release", "duration": duration, "fps": fps, "tree": [tree],
           "quality": quality}
    scene = parse_scene(raw, file="<pull-release>")
    model = grow(scene)[0].model
    rig = build_rig(model, RigOptions(min_bone_length=QUALITIES[quality].bone_length
                                      * model.height))
    force = deflection * model.height / stem_compliance(rig, at)
    raw["pull"] = [{"tree": 0, "force": [force, 0.0, 0.0], "release": release, "at": at,
                    "ramp": release / 2}]
    scene = parse_scene(raw, file="<pull-release>")
    bake = bake_scene(scene, log=log, progress=progress)
    tb = bake.trees[0]
    x = segment_ends(tb, [model.main_stem()[-1]])[:, 0, 0]
    t = bake.times
    free = t > release + 0.05
    return SwayResult(frequency(t[free], x[free]), damping_ratio(t[free], x[free]),
                      rig.first_frequency, model.height, model.dbh(), force,
                      float(x[np.searchsorted(t, release)] - x[0]))


def stem_compliance(rig, at: float) -> float:
    """Horizontal deflection (m/N) of the main stem's top under a unit
    horizontal force on the stem bone at `at` x height, from the joint
    springs below it (small angles, everything else rigid)."""
    stem = rig.main_stem()
    load = rig.stem_bone_at(at)
    top = float(rig.tip[stem[-1], 2])
    z_load = float(rig.com[load, 2])
    below = stem[: int(np.nonzero(stem == load)[0][0]) + 1]
    z = rig.pivot[below, 2]
    return float(np.sum((z_load - z) * (top - z) / rig.k[below]))
