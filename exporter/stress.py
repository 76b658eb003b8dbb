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
from .sway import segment_ends

ENERGY_TOLERANCE = 0.10  # a window's peak kinetic energy may exceed the previous one's by 10 %
GAP_TOLERANCE = 0.01  # joint gap, fraction of bone length
RISE_TOLERANCE = 0.05  # m: the centre of mass after a cut may not rise more
REST_FRACTION = 1e-3  # "at rest": kinetic energy below this fraction of its peak

WOOD = "density: 800\nmodulus: 8e9\ndamping: 0.05\n"
LEVELS = ("draft", "default", "final")  # the planar LOD's quality levels


@dataclass
class Case:
    name: str
    what: str
    grammar: str  # grammar text, or "species:NAME" for a bundled grammar
    scene: dict  # scene keys (the tree is added)
    quiet: float  # s: when the forcing has stopped
    duration: float
    long: bool = False  # part of the full run only
    event: bool = False  # an event case: breaks and falls are expected


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


def _sapling(extra: str = "", drop: tuple[str, ...] = ("rupture", "anchor")) -> str:
    lines = [ln for ln in grammar_path("sapling").read_text().splitlines()
             if not any(ln.startswith(d + ":") for d in drop)]
    return "\n".join(lines) + "\n" + extra


def _gust(speed: float, until: float) -> dict:
    return {"wind": {"speed": speed, "turbulence": 0.3, "ramp": 0.5, "end": until}}


def cases(long: bool = True) -> list[Case]:
    """The stress cases; `long` adds the ten-minute runs and the events on
    the big species."""
    twig = "axiom: !(0.5)F(2)F(2)[&(60){k}@cone({cone})!({d})F(0.15)F(0.15)@leaves(1)F(0.1)]\n"
    out = []
    for factor in (1, 100, 10_000):
        k = "" if factor == 1 else f"@stiffness({1.6e3 * factor:g})"
        out.append(Case(f"stiff x{factor}", f"twig joints {factor}x the wood's stiffness",
                        WOOD + twig.format(k=k, cone=30, d=0.02), _gust(30, 2.0), 3.0, 8.0))
    for ratio, d in (("1:10^2", 0.05), ("1:10^4", 0.005)):
        out.append(Case(f"mass {ratio}", f"twig/trunk mass per length {ratio}, 2 deg cone, "
                        "stiff spring", WOOD + twig.format(k="@stiffness(2e4)", cone=2, d=d),
                        _gust(30, 2.0), 3.0, 8.0))
    for cone in (0.5, 5, 90):
        out.append(Case(f"cone {cone} deg", f"cone half-angle {cone} deg in a gale",
                        WOOD + twig.format(k="", cone=cone, d=0.02), _gust(30, 2.0), 3.0, 8.0))
    out.append(Case("overlapping", "limbs drawn over each other and folded back",
                    WOOD + "axiom: !(0.2)F(1)F(1)[!(0.05)F(1)][!(0.05)F(1)][!(0.05)F(1)]"
                           "[&(179)!(0.05)F(0.8)F(0.8)][&(90)!(0.04)F(0.5)&(180)F(0.5)]\n",
                    _gust(25, 2.0), 3.0, 8.0))
    out.append(Case("near-zero segments", "segments of 0, 1e-6 and 1e-4 m among normal ones",
                    WOOD + "axiom: !(0.2)F(1)F(0)F(1e-6)F(1)[&(45)!(0.03)F(1e-4)F(0.5)F(1e-6)"
                           "F(0.5)]F(1e-4)F(1)\n", _gust(25, 2.0), 3.0, 8.0))
    out.append(Case("1 mm between 1 m", "a 1 mm segment between 1 m ones, a branch on it, "
                    "pulled, then calm", WOOD + "axiom: !(0.1)F(1)F(1)!(0.05)F(0.001)"
                    "[&(50)!(0.03)F(1)F(1)]!(0.05)F(1)F(1)\n",
                    {"pull": [{"tree": 0, "force": [40.0, 0, 0], "release": 1.0, "at": 1.0,
                               "ramp": 0.5}]}, 1.0, 6.5))
    out.append(Case("200-segment chain", "a 5 m x 5 cm chain of 200 segments pulled with 7 N, "
                    "then released", WOOD + "axiom: !(0.05)" + "F(0.025)" * 200 + "\n",
                    {"pull": [{"tree": 0, "force": [7.0, 0, 0], "release": 1.5, "at": 1.0,
                               "ramp": 0.5}]}, 1.5, 6.5))
    for speed in (45, 70):
        out.append(Case(f"wind {speed} m/s", f"sapling in {speed} m/s gusts (no breaking)",
                        _sapling(), _gust(speed, 3.0), 4.0, 9.0))
    for charge, dist in ((2, 6), (50, 5), (500, 6)):
        out.append(Case(f"blast {charge} kg at {dist} m",
                        f"{charge} kg TNT {dist} m from a sapling (no breaking)", _sapling(),
                        {"explosion": [{"position": [dist, 0.0, 1.0], "time": 0.5,
                                        "charge": charge}]}, 1.5, 7.0))
    # events: breaking and felling with the species' own strengths
    for species, long_case in (("sapling", False), ("spruce", False), ("oak", True),
                               ("willow", True), ("palm", True), ("bamboo", True)):
        out.append(Case(f"felling {species}", f"{species} cut at its base, falls on its hinge",
                        f"species:{species}", {"cut": [{"tree": 0, "time": 0.5,
                                                        "direction": 30.0}]},
                        7.0, 9.0, long=long_case, event=True))
    out.append(Case("crate breaks a stem", "a 150 kg crate at 11 m/s into the oak's stem",
                    "species:oak", {"projectile": [{"shape": "box", "size": 0.8, "mass": 150.0,
                                                    "position": [0.0, -9.0, 3.0],
                                                    "velocity": [0.0, 11.0, 3.0],
                                                    "time": 0.5}]},
                    4.0, 6.0, long=True, event=True))
    out.append(Case("blast breaks branches", "10 kg TNT 4 m from a sapling, breaking on",
                    "species:sapling", {"explosion": [{"position": [4.0, 0.0, 1.0], "time": 0.5,
                                                       "charge": 10.0}]}, 3.0, 6.0, event=True))
    out.append(Case("tornado uproots", "an EF2 vortex through a sapling, breaking on",
                    "species:sapling", {"vortex": [{"start": [-30.0, 0.0], "velocity": [12.0, 0.0],
                                                    "max_speed": 55.0, "core_radius": 15.0,
                                                    "end": 4.0}]}, 4.0, 7.0, event=True))
    out.append(Case("10 min gusty", "ten minutes of gusts, then ten seconds of calm",
                    _sapling(), _gust(12, 600.0), 602.0, 612.0, long=True))
    out.append(Case("10 min calm", "ten minutes after a pull, prestressed, no wind",
                    _sapling(), {"pull": [{"tree": 0, "force": [5.0, 0, 0], "release": 1.0}]},
                    1.0, 600.0, long=True))
    return [c for c in out if long or not c.long]


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
    start = time.perf_counter()
    try:
        from tempfile import TemporaryDirectory

        with TemporaryDirectory() as tmp:
            if case.grammar.startswith("species:"):
                path = grammar_path(case.grammar.split(":", 1)[1])
            else:
                path = Path(tmp) / "g.lsys"
                path.write_text(case.grammar)
            raw["tree"] = [{"grammar": str(path)}]
            scene = parse_scene(raw, file=f"<stability {case.name}>")
            bake = bake_scene(scene, solver=solver, quality=quality)
    except SimulationError as exc:
        return Result(case.name, label, case.what, False, math.nan, math.nan, math.nan,
                      math.nan, math.nan, math.nan, 0, time.perf_counter() - start, False,
                      error=str(exc))
    seconds = time.perf_counter() - start
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
                  engines=bake.trees[0].info.get("solver", "static"))


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
             "broken | max spin rad/s | rest after s | wall s | what | adapted |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        rest = "-" if math.isinf(r.rest) else f"{r.rest:.1f}"
        rise = "-" if math.isnan(r.rise) else f"{r.rise:.3f}"
        # each note's headline only (before its details), once
        heads = dict.fromkeys(n.split(":")[0].split(" (")[0] for n in r.notes)
        notes = "; ".join(heads) or ("error: " + r.error if r.error else "")
        lines.append(f"| {r.case} | {r.solver} | {'PASS' if r.passed else 'FAIL'} | "
                     f"{r.energy_growth:.3g} | {r.gain:.3g} | {r.gap:.3g} | {rise} | "
                     f"{r.broken} | {r.spin:.3g} | {rest} | {r.seconds:.1f} | {r.what} | "
                     f"{notes} |")
    return "\n".join(lines) + "\n"


def stability(out: str | Path = "out/stability", long: bool = True,
              solvers: tuple[str, ...] = ("planar", "full"), only: list[str] | None = None,
              levels: tuple[str, ...] = LEVELS, log=None, engine: str = "auto") -> list[Result]:
    """Run the cases (`only` these names) on the solvers, the planar LOD at
    `levels` with its nonlinear `engine` (see run); write OUT/report.json
    and report.md."""
    log = log or (lambda msg: None)
    results = []
    for case in cases(long):
        if only and case.name not in only:
            continue
        runs = [("planar", lv) for lv in levels if "planar" in solvers]
        if "full" in solvers:
            runs.append(("full", "default"))
        for solver, level in runs:
            r = run(case, solver, level, engine)
            log(f"{case.name:<22} {r.solver:<19} {'PASS' if r.passed else 'FAIL'}  growth "
                f"{r.energy_growth:.3g}  gain {r.gain:.3g}  gap {r.gap:.3g}  "
                f"spin {r.spin:.3g}  {r.seconds:.1f} s" + (f"  {r.error}" if r.error else ""))
            results.append(r)
    out = Path(out)
    write_text(out / "report.json", json.dumps([asdict(r) for r in results], indent=2,
                                               default=str) + "\n")
    write_text(out / "report.md", report_markdown(results))
    return results
