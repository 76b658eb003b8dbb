"""`treebake stability`: the stress suite, over both solvers and every
quality level of the planar LOD.

Each case is a tree built to be hard (stiffness up to x10^4, a twig of
1/10^4 of the trunk's mass per length, cones from 0.5 to 90 degrees, bones
drawn over each other, near-zero segments, a 1 mm segment between 1 m ones,
a 200-segment chain, wind to 70 m/s, blasts far beyond the presets,
ten-minute runs), forced for a while and then left alone; and events on the
production species (felling each, a crate breaking a stem, a blast breaking
branches, a tornado uprooting a tree). Measured on the baked motion
(independent of solver internals) and the bake's energy audit:

- finite: the bake completed with finite values (a solver stops with a
  SimulationError naming tree, segment and time otherwise: a fail);
- energy: the largest growth of windowed peak kinetic energy from one
  window to the next after the forcing stopped (must stay under
  ENERGY_TOLERANCE: no perpetual motion); in an event case where something
  broke or was cut, so that parts may still be falling then (an uprooted
  oak topples for 4 s, a cut clump's last culm leans over late), the rise
  of kinetic plus gravitational energy above its lowest since, as a
  fraction of the run's peak kinetic energy: a fall turns height into
  speed, a fault adds to both;
- gain: the energy audit's largest unexplained gain (sim/audit.py), as a
  fraction of the tree's energy and the work done on it (GAIN_TOLERANCE);
- gap: the largest distance between a segment's base and its parent
  segment's end over every frame, as a fraction of their mean length,
  measured on the bake (joints that broke excluded; GAP_TOLERANCE);
- rise: after a cut, how far the centre of mass of the tree's segments ever
  rises above its height at the cut (m; must stay under RISE_TOLERANCE);
- spin: the largest angular speed of any segment between frames (rad/s);
- rest: the time after the forcing stopped until kinetic energy stays
  below 0.1 % of its peak (s; "-" if it never does within the run).

What each solver adapted (inertia floors, capped loads, refined steps,
breaks) is listed from the bake's notes: never silent.

The full suite takes about two hours of CPU (CPU_SECONDS, measured;
docs/physics.md, "The stress suite's cost"). `--quick` (quick_plan) takes
the runs that found the most, most telling first (QUICK), up to
QUICK_BUDGET CPU s by those measurements, and says up front what does not
fit; on a grammar's tree (cases(grammar=...)) the runs are estimated from
the measured trees nearest in size.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from .bake import Bake
from .errors import SimulationError
from .fileio import write_text
from .library import grammar_path
from .pipeline import bake_scene
from .quality import QUALITIES
from .rotations import angle_between
from .scene import parse_scene
from .sim.audit import GAIN_TOLERANCE
from .sim.events import BROKE, CUT, UPROOTED
from .stress_cases import Case
from .stress_plan import LEVELS, QUICK_BUDGET, QUICK_LIMIT, plan, plan_summary, quick_plan
from .sway import segment_ends

ENERGY_TOLERANCE = 0.10  # a window's peak kinetic energy may exceed the previous one's by 10 %
GAP_TOLERANCE = 0.01  # joint gap, fraction of bone length
RISE_TOLERANCE = 0.05  # m: the centre of mass after a cut may not rise more
REST_FRACTION = 1e-3  # "at rest": kinetic energy below this fraction of its peak


@dataclass
class Result:
    case: str
    solver: str  # "planar <level>" or "full"
    what: str
    finite: bool
    energy_growth: float  # largest window-to-window growth after `quiet`, fraction
    gain: float  # the energy audit's unexplained gain, fraction
    gap: float  # fraction of bone length, measured on the bake
    rise: float  # m, centre of mass above its height at a cut (nan: no cut)
    spin: float  # rad/s
    rest: float  # s after `quiet`; inf if not within the run
    broken: int  # joints that broke
    seconds: float  # wall time of the bake
    passed: bool
    notes: list[str] = field(default_factory=list)
    error: str = ""
    engines: str = ""  # the tree's engines, as its bake records them (info["solver"])
    cpu: float = math.nan  # CPU s of the bake (this process, every thread, and its children)


def _segment_masses(bake: Bake) -> tuple[np.ndarray, np.ndarray]:
    """The first tree's segment midpoints per frame (F, S, 3) m and masses
    (S,) (solid cylinders of unit density), from the baked motion alone."""
    t = bake.trees[0]
    ends = segment_ends(t, np.arange(t.n_segments))
    length = np.linalg.norm(t.points[t.seg_end] - t.points[t.seg_start], axis=1)
    return 0.5 * (t.positions + ends), np.pi / 4 * t.width**2 * length


def kinetic_energy(bake: Bake) -> np.ndarray:
    """Translational kinetic energy per frame interval (relative units: solid
    cylinders of unit density), from the baked motion alone."""
    if bake.trees[0].static:
        return np.zeros(len(bake.times) - 1)
    mids, mass = _segment_masses(bake)
    v = np.diff(mids, axis=0) * bake.fps
    return 0.5 * (mass[None, :, None] * v * v).sum(axis=(1, 2))


def joint_gap(bake: Bake) -> float:
    """Largest distance between a segment's base and its parent segment's end
    over every frame, as a fraction of their mean length, on the baked motion
    alone; joints that broke (the bake's events) are left out."""
    t = bake.trees[0]
    if t.static:
        return 0.0
    broke = {e["segment"] for e in t.info.get("events", [])
             if e["kind"] in ("broke", "uprooted", "hinge snapped")}
    child = np.nonzero(t.seg_parent >= 0)[0]
    child = np.array([s for s in child if t.paths[s] not in broke], dtype=np.int64)
    if not len(child):
        return 0.0
    parent = t.seg_parent[child]
    ends = segment_ends(t, parent)
    length = np.linalg.norm(t.points[t.seg_end] - t.points[t.seg_start], axis=1)
    scale = np.maximum(0.5 * (length[child] + length[parent]), 1e-6)
    gap = np.linalg.norm(t.positions[:, child].astype(float) - ends, axis=-1) / scale
    return float(gap.max())


def centre_rise(bake: Bake) -> float:
    """After a cut: how far (m) the mass centre of the tree's segments
    rises above its height at the cut (nan without one)."""
    t = bake.trees[0]
    cut = next((e["time"] for e in t.info.get("events", []) if e["kind"] == "cut"), None)
    if cut is None or t.static:
        return math.nan
    mids, mass = _segment_masses(bake)
    z = (mids[..., 2] * mass).sum(1) / mass.sum()
    f = math.floor(cut * bake.fps)
    return float(z[f:].max() - z[f])


def gravitational_energy(bake: Bake) -> np.ndarray:
    """Gravitational energy per frame interval (the units of
    kinetic_energy, at the interval's mean height), from the bake alone."""
    if bake.trees[0].static:
        return np.zeros(len(bake.times) - 1)
    mids, mass = _segment_masses(bake)
    pe = float(bake.meta.get("gravity", 9.81)) * (mids[..., 2] * mass).sum(1)  # m/s^2
    return 0.5 * (pe[1:] + pe[:-1])


def event_growth(kinetic: np.ndarray, gravitational: np.ndarray, after: np.ndarray) -> float:
    """The largest rise of kinetic plus gravitational energy (per frame
    interval) above its lowest value since, over the intervals `after` the
    forcing stopped, as a fraction of the peak kinetic energy: a fall only
    trades one for the other."""
    if not after.any():
        return 0.0
    total = (kinetic + gravitational)[after]
    return float((total - np.minimum.accumulate(total)).max() / max(kinetic.max(), 1e-12))


def window_growth(kinetic: np.ndarray, t: np.ndarray, quiet: float) -> float:
    """The largest growth of the peak kinetic energy from one 1 s window to
    the next after `quiet` s (fraction), intervals ending at times t (s)."""
    starts = np.arange(quiet, t[-1] - 1.0 + 1e-9, 1.0)
    peaks = [kinetic[(t >= a) & (t < a + 1.0)].max() for a in starts]
    floor = REST_FRACTION * (kinetic.max() if len(kinetic) else 0.0)
    growth = 0.0
    for a, b in itertools.pairwise(peaks):
        if a > floor:  # growth between windows already at rest is round-off
            growth = max(growth, b / a - 1.0)
    return growth


def measure(bake: Bake, quiet: float, event: bool = False) -> tuple[float, float, float]:
    """Energy growth after `quiet` (of kinetic plus gravitational energy in
    an `event` case), largest spin (rad/s), time to rest (s)."""
    ke = kinetic_energy(bake)
    t = bake.times[1:]
    after = t >= quiet
    if event:
        growth = event_growth(ke, gravitational_energy(bake), after)
    else:
        growth = window_growth(ke, t, quiet)
    tree = bake.trees[0]
    rot = tree.rotations.astype(float)
    spin = 0.0
    if rot.shape[0] > 1:
        spin = float((angle_between(rot[1:], rot[:-1]) * bake.fps).max())
    peak = ke.max() if len(ke) else 0.0
    rest = math.inf
    if peak > 0 and after.any():
        still = ke < REST_FRACTION * peak
        idx = np.nonzero(after)[0]
        moving = idx[~still[idx]]
        if not len(moving):
            rest = 0.0
        elif moving[-1] < len(ke) - 1:
            rest = float(t[moving[-1] + 1] - quiet)
    elif peak == 0:
        rest = 0.0
    return growth, spin, rest


def run(case: Case, solver: str, level: str = "default", engine: str = "auto") -> Result:
    """Bake a case with a solver ("planar" at quality `level`, or "full").
    The planar LOD's `engine` for what leaves its linear tier: "auto" (the
    engine table, docs/physics.md), "pymunk" or "reference" (every reason)."""
    raw = dict(case.scene, duration=case.duration, fps=24.0, name=case.name)
    label = f"planar {level}" if solver == "planar" else solver
    quality = None
    if solver == "planar":
        quality = QUALITIES[level]
        if engine in ("pymunk", "reference"):
            quality = replace(quality, nonlinear=engine)
            label += f" {engine}"
    start, cpu = time.perf_counter(), cpu_seconds()
    try:
        from tempfile import TemporaryDirectory

        with TemporaryDirectory() as tmp:
            if case.grammar.startswith("species:"):
                path = grammar_path(case.grammar.split(":", 1)[1])
            elif case.grammar.startswith("file:"):
                path = Path(case.grammar.split(":", 1)[1])
            else:
                path = Path(tmp) / "g.lsys"
                path.write_text(case.grammar)
            raw["tree"] = [{"grammar": str(path)}]
            scene = parse_scene(raw, file=f"<stability {case.name}>")
            bake = bake_scene(scene, solver=solver, quality=quality)
    except SimulationError as exc:
        return Result(case.name, label, case.what, False, math.nan, math.nan, math.nan,
                      math.nan, math.nan, math.nan, 0, time.perf_counter() - start, False,
                      error=str(exc), cpu=cpu_seconds() - cpu)
    seconds, cpu = time.perf_counter() - start, cpu_seconds() - cpu
    finite = all(np.isfinite(t.positions).all() and np.isfinite(t.rotations).all()
                 for t in bake.trees)
    events = [e["kind"] for e in bake.trees[0].info.get("events", [])]
    broken = sum(1 for k in events if k in (BROKE, UPROOTED))
    # the fall's rule needs a fall: a tree that nothing broke or cut only
    # sways, trading energy with its springs' (which the bake cannot see),
    # and the reference's own sway after a crate too light to break the
    # oak rises 4-6 % by that rule; kinetic energy's windows judge a sway
    fell = case.event and (broken > 0 or CUT in events)
    growth, spin, rest = measure(bake, case.quiet, fell)
    audit = bake.meta.get("energy", {})
    gain = max((a["max_gain_fraction"] for a in audit.values()), default=0.0)
    gap = joint_gap(bake)
    rise = centre_rise(bake)
    passed = (finite and growth <= ENERGY_TOLERANCE and gap <= GAP_TOLERANCE
              and gain <= GAIN_TOLERANCE and not rise > RISE_TOLERANCE)
    return Result(case.name, label, case.what, finite, growth, gain, gap, rise, spin, rest,
                  broken, seconds, passed, list(bake.meta.get("notes", [])),
                  engines=bake.trees[0].info.get("solver", "static"), cpu=cpu)


def report_markdown(results: list[Result]) -> str:
    lines = ["# Stability: stress and event cases over both solvers", "",
             (f"Pass: finite; kinetic energy never grows by more than "
             f"{ENERGY_TOLERANCE:.0%} from one 1 s window to the next once the forcing stops "
             f"(in an event case where something broke or was cut, so that parts may "
             f"still be falling, kinetic plus "
             f"gravitational energy never rises by more than {ENERGY_TOLERANCE:.0%} of the "
             f"peak kinetic energy above its lowest since); "
             f"the energy audit's unexplained gain under {GAIN_TOLERANCE:.0%} of the tree's "
             f"energy and the work done on it; joint gaps, measured on the bake, under "
             f"{GAP_TOLERANCE:.0%} of bone length; after a cut, the centre of mass never "
             f"rises more than {RISE_TOLERANCE * 100:.0f} cm. The planar LOD runs at every "
             "quality level: its linear tier (implicit, unconditionally stable) and, for trees "
             "that leave the linear range, the MuJoCo reference at the level's step (the "
             "pymunk tier with `--engine pymunk`: rotary-inertia floor, loads capped by "
             "impulse, steps split during impulsive loads; docs/physics.md); joint gaps can "
             "open on the pymunk tier only."), "",
             ("| case | solver | pass | energy growth | audit gain | max gap | COM rise m | "
             "broken | max spin rad/s | rest after s | wall s | CPU s | what | adapted |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        rest = "-" if math.isinf(r.rest) else f"{r.rest:.1f}"
        rise = "-" if math.isnan(r.rise) else f"{r.rise:.3f}"
        # each note's headline only (before its details), once
        heads = dict.fromkeys(n.split(":")[0].split(" (")[0] for n in r.notes)
        notes = "; ".join(heads) or ("error: " + r.error if r.error else "")
        lines.append(f"| {r.case} | {r.solver} | {'PASS' if r.passed else 'FAIL'} | "
                     f"{r.energy_growth:.3g} | {r.gain:.3g} | {r.gap:.3g} | {rise} | "
                     f"{r.broken} | {r.spin:.3g} | {rest} | {r.seconds:.1f} | {r.cpu:.1f} | {r.what} | "
                     f"{notes} |")
    return "\n".join(lines) + "\n"


def cpu_seconds() -> float:
    """CPU s of this process (every thread) and its finished children."""
    total = time.process_time()
    try:
        import resource
    except ImportError:  # Windows: no children's times
        return total
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return total + children.ru_utime + children.ru_stime


def stability(out: str | Path = "out/stability", long: bool = True,
              solvers: tuple[str, ...] = ("planar", "full"), only: list[str] | None = None,
              levels: tuple[str, ...] | None = None, log=None, engine: str = "auto",
              quick: bool = False, grammar: str | Path | None = None, progress=None,
              budget: float = QUICK_BUDGET) -> list[Result]:
    """Run the cases (`only` these names) on the solvers, the planar LOD at
    `levels` (None: all; with `quick`, QUICK's) with its nonlinear `engine`
    (see run); on `grammar`'s tree for the cases on a species (see cases);
    `quick`: the budgeted selection (quick_plan; a run that would end past
    QUICK_LIMIT CPU s, by the CPU spent and its estimate, is skipped), else
    every run (plan, `long`). Says the plan and what it leaves out to `log`
    first; `progress(event, k, n, label, text)` hears "start" and "end" of
    the k-th of n runs (`log` gets the end lines without it). Writes
    OUT/report.json and report.md."""
    log = log or (lambda msg: None)
    if quick:
        runs, left = quick_plan(solvers, levels, only, grammar, budget)
    else:
        runs, left = plan(long, solvers, levels or LEVELS, only, grammar), []
    log(plan_summary(runs, left, quick, budget, engine))
    if progress is None:
        def progress(event, k, n, label, text):
            if event == "end":
                log(f"case {k}/{n} {label}: {text}")
    results = []
    # estimates of a tree the table has not measured can be low several
    # times over (the same blast sends one tree to the reference and leaves
    # another in the linear tier): a quick run that would end past twice
    # the budget (the 5 minutes) is skipped, not run
    limit, spent = (QUICK_LIMIT * budget / QUICK_BUDGET if quick else math.inf), 0.0
    for k, r in enumerate(runs, 1):
        if spent + (0.0 if math.isnan(r.estimate) else r.estimate) > limit:
            progress("end", k, len(runs), r.label,
                     f"skipped, {spent:.0f} CPU s spent of {limit:.0f} (the estimates were low)")
            continue
        about = "not estimated" if math.isnan(r.estimate) else f"about {r.estimate:.0f} CPU s"
        progress("start", k, len(runs), r.label, f"running, {about}")
        res = run(r.case, r.solver, r.level, engine)
        spent += res.cpu
        progress("end", k, len(runs), r.label, outcome(res))
        results.append(res)
    out = Path(out)
    write_text(out / "report.json", json.dumps([asdict(r) for r in results], indent=2,
                                               default=str) + "\n")
    write_text(out / "report.md", report_markdown(results))
    return results


def outcome(r: Result) -> str:
    """A run's result in a progress line: `passed, 2.1 s (CPU 0.6 s; ...)`."""
    text = (f"{'passed' if r.passed else 'FAILED'}, {r.seconds:.1f} s (CPU {r.cpu:.1f} s; "
            f"growth {r.energy_growth:.3g}, gain {r.gain:.3g}, gap {r.gap:.3g}, "
            f"spin {r.spin:.3g})")
    return text + (f": {r.error}" if r.error else "")


