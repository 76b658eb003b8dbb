"""Seamless loops (scene key `loop = true`): the rules in one place.

A loop scene's `duration` is the loop's length T = N / fps (N = round
(duration x fps) frame intervals). Its bake has N + 1 frames, times 0 to
T, and the last frame is a copy of the first: a clip lasts exactly T, so
glTF players (three.js LoopRepeat) and USD/Alembic time ranges loop
without a hitch; a player that repeats frames plays 0 to N - 1
(docs/formats.md, "Loops").

How the motion is made periodic:

- The wind's turbulence is synthesised with period T (forces.Wind.prepare,
  `period`): the frozen field read at t and t + T is the same. Its mean
  speed, direction and turbulence must be plain values (keys are refused:
  a keyed wind is not periodic), and the wind has no `start` or `end`;
  its `ramp` rises from rest at t = 0 of the run-in, before the loop.
- Forces that cannot repeat (blasts, vortices, attractors, projectiles,
  cuts, pulls, and any other force table but `[wind]`) are refused.
- Run-in: the trees are simulated from rest for K whole loops before the
  loop that is baked (the wind being periodic, the loop's frames are those
  of the (K+1)-th period), so the transient from rest has decayed. K is
  chosen before the simulation from the trees' damping: the slowest
  structural decay time tau = 2 / alpha_min (s; rig.py's mass-
  proportional damping alpha = 2 zeta omega_limb), K T >= ramp +
  tau ln(1 / RESIDUAL), at least one loop, at most MAX_RUN_IN s (or
  the ramp, if longer: the loop never sees it).
  Deterministic; air drag only damps the transient further.
- Phase: a tree's `phase` p (s; a forest's trees draw one from the scene's
  seed) shifts its loop cyclically by k = round(p fps) frames: frame f of
  the phased tree is frame (f + k) mod N of the unphased one (p seconds
  ahead). Exact for a periodic motion.
- Seam: per segment, how far the simulated motion at the loop's end
  (time T after its first frame) is from the first frame, in position (m)
  and rotation (rad), and how far the angular velocity arriving at the
  end is from the one arriving at the start (rad/s): the jumps a player
  shows when it wraps (the copy of frame 0 hides the first two, the third
  is what a rate shows). Each over the largest frame-to-frame step (change
  of angular velocity) within the loop; the worst ratio over segments and
  trees goes into the bake's meta (`loop.seam`); <= 1 passes. (The step
  from frame N - 1 to frame 0 against the other steps is not the measure:
  in an exactly periodic motion it is one of the loop's own steps, the
  largest for some segments, so it fails a perfect loop by chance.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from .keys import Keyed

RESIDUAL = 1e-2  # the share of the transient from rest left when the loop starts
MAX_RUN_IN = 120.0  # s, the run-in's cap (whole loops, at least one)
MIN_FRAMES = 4  # frame intervals a loop needs at least
PHASE_STREAM = 0x100F  # seeds the forest's phases apart from every other draw
# scene tables a loop may have besides the forces: everything else that
# acts is refused (a future force table is refused until it is made periodic)
QUIET_TABLES = {"tree", "forest", "wind", "camera", "quality", "formats"}
WIND_FIXED = ("speed", "beaufort", "direction", "turbulence")  # no keys in a loop
WIND_REFUSED = ("start", "end")


def period(scene) -> float | None:
    """A loop scene's period T = N / fps (s); None when it does not loop."""
    if not getattr(scene, "loop", False):
        return None
    return (scene.frame_count - 1) / scene.fps


def validate(scene, raw: dict, fail: Callable[[str, str], Exception], tables: dict) -> None:
    """Check a parsed scene's loop keys (`raw` its file's table, `tables`
    the top-level keys' Key records, `fail(key, message)` the parser's
    error): a `phase` needs `loop = true`, is 0 <= phase < duration, and a
    loop refuses what cannot repeat. Then give the forest's trees their
    random phases."""
    trees = raw.get("tree", [])
    trees = trees if isinstance(trees, list) else [trees]
    for i, t in enumerate(trees):
        if isinstance(t, dict) and "phase" in t:
            key = f"tree[{i}].phase"
            if not scene.loop:
                raise fail(key, "needs `loop = true` (a phase offsets a tree's loop)")
            if not 0.0 <= scene.trees[i].phase < scene.duration:
                raise fail(key, f"= {scene.trees[i].phase:g} s must be in [0, duration = "
                                f"{scene.duration:g} s)")
    if not scene.loop:
        return
    if scene.frame_count - 1 < MIN_FRAMES:
        raise fail("duration", f"= {scene.duration:g} s is {scene.frame_count - 1} frame "
                               f"intervals at fps = {scene.fps:g}; a loop needs at least "
                               f"{MIN_FRAMES}")
    for name, key in tables.items():
        if name in raw and key.kind == "table" and name not in QUIET_TABLES:
            raise fail(name, "cannot repeat: a loop scene (loop = true) takes trees, a "
                             "[forest], a periodic [wind] and a [camera] only")
    wind = raw.get("wind")
    if isinstance(wind, dict):
        for name in WIND_FIXED:
            if isinstance(getattr(scene.wind, name if name != "beaufort" else "speed", None),
                          Keyed) and name in wind:
                raise fail(f"wind.{name}", "takes one value in a loop scene (keys are not "
                                           "periodic)")
        for name in WIND_REFUSED:
            if name in wind:
                raise fail(f"wind.{name}", "is not allowed in a loop scene: the wind blows "
                                           "for the whole loop (`ramp` rises in the run-in)")
    rng = np.random.default_rng([scene.seed, PHASE_STREAM])
    for t in scene.trees:
        if t.phase is None:  # a forest's tree: a phase of its own from the seed
            t.phase = float(rng.uniform(0.0, scene.duration))


@dataclass
class Seam:
    """How close a loop's seam is, worst over segments (`seam` below): the
    jump at the seam over the largest frame-to-frame step (change) within
    the loop, for positions, rotations and rotation rates (<= 1: the seam
    is no larger than a step the motion takes anyway)."""

    position: float = 0.0
    rotation: float = 0.0
    rate: float = 0.0
    position_m: float = 0.0  # m, the worst segment's distance from its start a loop later
    rate_jump: float = 0.0  # rad/s, the worst segment's change of angular velocity there

    @property
    def passes(self) -> bool:
        return max(self.position, self.rotation, self.rate) <= 1.0

    def worst(self, other: Seam) -> Seam:
        return Seam(*(max(a, b) for a, b in zip(self.record().values(), other.record().values())))

    def record(self) -> dict:
        return {"position": _figure(self.position), "rotation": _figure(self.rotation),
                "rate": _figure(self.rate), "position_m": _figure(self.position_m),
                "rate_jump": _figure(self.rate_jump)}


def _figure(x: float) -> float:
    """Three significant digits: enough to read, the same on every machine."""
    return float(f"{x:.3g}")


def _ratio(jump: np.ndarray, largest: np.ndarray, floor: float) -> tuple[float, int]:
    """The worst jump / largest-step ratio over segments (S,), a segment
    whose largest step is under `floor` (it does not move: numerical
    noise) left out, and that segment."""
    r = np.where(largest > floor, jump / np.maximum(largest, floor), 0.0)
    s = int(np.argmax(r))
    return float(r[s]), s


def angular_velocities(rot: np.ndarray, fps: float) -> np.ndarray:
    """World angular velocity (rad/s) over each interval between the
    frames of unit quaternions `rot` (F, S, 4) x y z w: (F - 1, S, 3)."""
    from .rotations import qconj, qmul

    q = rot.astype(np.float64)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    d = qmul(q[1:], qconj(q[:-1]))
    d = np.where(d[..., 3:4] < 0, -d, d)
    s = np.linalg.norm(d[..., :3], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, d[..., 3:4])
    return d[..., :3] * np.where(s > 1e-15, angle / np.maximum(s, 1e-300), 2.0) * fps


def seam(positions: np.ndarray, rotations: np.ndarray, first: int, n: int, fps: float) -> Seam:
    """The seam of the loop of `n` intervals from frame `first` (>= 1) of a
    simulation's positions (F, S, 3) m and rotations (F, S, 4), F > first +
    n: per segment, how far the motion at the loop's end (frame first + n)
    is from its start (frame first), in position (m) and rotation (rad), and
    how far the angular velocity arriving at the end is from the one
    arriving at the start (rad/s), each over the largest frame-to-frame
    step (change of angular velocity) within the loop."""
    from .rotations import angle_between

    end = first + n
    pos = positions[first - 1:end + 1].astype(np.float64)  # the frame before the loop too
    step = np.linalg.norm(np.diff(pos[1:], axis=0), axis=-1).max(axis=0)  # (S,)
    gap = np.linalg.norm(pos[-1] - pos[1], axis=-1)
    floor = 4.0 * float(np.spacing(np.float32(np.abs(pos).max(initial=1.0))))
    p, seg = _ratio(gap, step, floor)
    q = rotations[first - 1:end + 1].astype(np.float64)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    turn = angle_between(q[1:-1], q[2:]).max(axis=0)
    r, _ = _ratio(angle_between(q[-1], q[1]), turn, 1e-6)
    w = angular_velocities(q, fps)  # (n + 1, S, 3): w[0] arrives at the start, w[-1] at the end
    change = np.linalg.norm(np.diff(w, axis=0), axis=-1).max(axis=0)
    jump = np.linalg.norm(w[-1] - w[0], axis=-1)
    rate, rs = _ratio(jump, change, 1e-6 * fps)
    return Seam(p, r, rate, float(gap[seg]), float(jump[rs]))


@dataclass
class LoopPlan:
    """A loop scene's run: `loops` whole loops of run-in, then the baked
    loop of `frames` intervals (N); what each tree's window came to."""

    period: float  # s, T
    frames: int  # N
    loops: int  # K, of run-in
    fps: float
    seams: dict[str, Seam] = field(default_factory=dict)
    phases: dict[str, int] = field(default_factory=dict)  # frames each tree is shifted by

    @property
    def run_in(self) -> float:
        """The run-in (s) before the loop's first frame."""
        return self.loops * self.period

    def sim_scene(self, scene):
        """The scene the solver runs: the run-in and the loop, K + 1 periods."""
        return replace(scene, duration=(self.loops + 1) * self.period)

    def window(self, tree, phase: float):
        """A simulated tree's bake (bake.TreeBake over the run-in and the
        loop) cut to the loop: its N distinct frames shifted by the phase
        (s), the first repeated as frame N; its seam kept. Static trees
        (one frame) pass unchanged."""
        if tree.static:
            return tree
        n, first = self.frames, self.loops * self.frames
        k = round(phase * self.fps) % n
        pos = tree.positions[first:first + n]
        rot = tree.rotations[first:first + n]
        self.seams[tree.name] = seam(tree.positions, tree.rotations, first, n, self.fps)
        self.phases[tree.name] = k
        order = (np.arange(n + 1) + k) % n
        info = dict(tree.info, loop={"phase_frames": k, "seam": self.seams[tree.name].record()})
        start = first / self.fps
        t = tree.extra_times
        inside = (t > start) & (t < start + self.period)
        shifted = (t[inside] - start - k / self.fps) % self.period
        sort = np.argsort(shifted, kind="stable")
        return replace(tree, positions=pos[order], rotations=rot[order], info=info,
                       extra_times=shifted[sort],
                       extra_positions=tree.extra_positions[inside][sort],
                       extra_rotations=tree.extra_rotations[inside][sort])

    def meta(self) -> dict:
        """The bake's meta `loop`: period, run-in, and the seam, worst over
        trees (which tree is worst, and whether it passes)."""
        worst, tree = Seam(), None
        for name, s in self.seams.items():
            if tree is None or max(s.position, s.rotation, s.rate) > max(
                    worst.position, worst.rotation, worst.rate):
                tree = name
            worst = worst.worst(s)
        return {"period_s": self.period, "frames": self.frames + 1,
                "run_in_s": round(self.run_in, 6), "run_in_loops": self.loops,
                "seam": dict(worst.record(), worst_tree=tree, passes=worst.passes)}

    def line(self) -> str:
        """The loop in one line for people: period, run-in, the seam."""
        m = self.meta()
        seam = m["seam"]
        return (f"loop: {self.period:g} s ({m['frames']} frames, the last the first again), "
                f"run-in {self.run_in:g} s ({self.loops} loops); seam {seam['position']:.2g} "
                f"(position), {seam['rotation']:.2g} (rotation), {seam['rate']:.2g} (rotation "
                "rate) x the largest frame-to-frame step")

    def notes(self) -> list[str]:
        """What people should hear: a seam that does not pass."""
        m = self.meta()["seam"]
        if m["passes"]:
            return []
        return [f"loop seam: the step across the seam is {m['position']:.2f} x (position), "
                f"{m['rotation']:.2f} x (rotation), {m['rate']:.2f} x (rotation rate) the "
                f"largest elsewhere (worst tree {m['worst_tree']!r}); a longer run-in or a "
                "calmer wind would close it"]


def decay_time(rigs) -> float:
    """The slowest structural decay time (s) of `rigs`' bones: 2 / alpha,
    alpha (1/s) the mass-proportional damping (rig.py); 0 without any."""
    alphas = [float(r.alpha[r.alpha > 0].min()) for r in rigs if np.any(r.alpha > 0)]
    return 2.0 / min(alphas) if alphas else 0.0


def plan(scene, rigs, ramp: float) -> LoopPlan | None:
    """The loop's plan for a scene (None: it does not loop): the run-in
    from the active trees' rigs and the wind's `ramp` (s)."""
    t = period(scene)
    if t is None:
        return None
    need = ramp + decay_time(rigs) * math.log(1.0 / RESIDUAL)
    loops = min(math.ceil(need / t - 1e-9), math.ceil(MAX_RUN_IN / t))
    loops = max(1, loops, math.ceil(ramp / t - 1e-9))  # the wind's ramp never reaches the loop
    return LoopPlan(t, scene.frame_count - 1, loops, scene.fps)
