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

import functools
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
from .library import grammar_path, grammars_folder
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
    grammar: str  # grammar text, "species:NAME" (a bundled grammar) or "file:PATH"
    scene: dict  # scene keys (the tree is added)
    quiet: float  # s: when the forcing has stopped
    duration: float
    long: bool = False  # part of the full run only
    event: bool = False  # an event case: breaks and falls are expected
    # the tree the case is about: "species:NAME" or "file:PATH" (its grammar,
    # strengths dropped or not); "" for a case's own small tree
    tree: str = ""

    @property
    def kind(self) -> str:
        """The case without its tree's name: what CPU_SECONDS knows it by."""
        return "felling" if self.name.startswith("felling ") else self.name


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


def _unbreakable(path: Path, drop: tuple[str, ...] = ("rupture", "anchor")) -> str:
    """A grammar's text without its strengths (nothing breaks, nothing uproots)."""
    lines = [ln for ln in path.read_text().splitlines()
             if not any(ln.startswith(d + ":") for d in drop)]
    return "\n".join(lines) + "\n"


def _gust(speed: float, until: float) -> dict:
    return {"wind": {"speed": speed, "turbulence": 0.3, "ramp": 0.5, "end": until}}


def bundled_name(grammar: str | Path) -> str | None:
    """A grammar file's bundled name (`oak`, `forest/birch`); None outside
    the bundle."""
    try:
        return Path(grammar).resolve().relative_to(grammars_folder().resolve()).with_suffix(
            "").as_posix()
    except ValueError:
        return None


def tree_name(grammar: str | Path) -> str:
    """How the cases name a tree grown from `grammar` (a file): a bundled
    grammar by its name, any other by its file's stem."""
    return bundled_name(grammar) or Path(grammar).stem


def cases(long: bool = True, grammar: str | Path | None = None) -> list[Case]:
    """The stress cases; `long` adds the ten-minute runs and the events on
    the big species. With `grammar` (a file), every case on a tree of the
    bundled species (the sapling's wind, blasts, tornado and ten-minute
    runs, the felling, the crate) runs on that grammar's tree instead, and
    the six fellings are one; the cases on their own small trees stay."""
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
    if grammar is None:
        small, plain = "sapling", _unbreakable(grammar_path("sapling"))
        a_small = "a sapling"
        fellings = (("sapling", False), ("spruce", False), ("oak", True), ("willow", True),
                    ("palm", True), ("bamboo", True))
        crate = "oak"

        def source(species: str) -> str:
            return f"species:{species}"
    else:
        path = Path(grammar).resolve()
        small = crate = tree_name(path)
        plain, fellings = _unbreakable(path), ((small, False),)
        a_small = f"the {small}"

        def source(species: str) -> str:
            return f"file:{path}"
    for speed in (45, 70):
        out.append(Case(f"wind {speed} m/s", f"{small} in {speed} m/s gusts (no breaking)",
                        plain, _gust(speed, 3.0), 4.0, 9.0, tree=source(small)))
    for charge, dist in ((2, 6), (50, 5), (500, 6)):
        out.append(Case(f"blast {charge} kg at {dist} m",
                        f"{charge} kg TNT {dist} m from {a_small} (no breaking)", plain,
                        {"explosion": [{"position": [dist, 0.0, 1.0], "time": 0.5,
                                        "charge": charge}]}, 1.5, 7.0, tree=source(small)))
    # events: breaking and felling with the species' own strengths
    for species, long_case in fellings:
        out.append(Case(f"felling {species}", f"{species} cut at its base, falls on its hinge",
                        source(species), {"cut": [{"tree": 0, "time": 0.5, "direction": 30.0}]},
                        7.0, 9.0, long=long_case, event=True, tree=source(species)))
    out.append(Case("crate breaks a stem", f"a 150 kg crate at 11 m/s into the {crate}'s stem",
                    source(crate), {"projectile": [{"shape": "box", "size": 0.8, "mass": 150.0,
                                                    "position": [0.0, -9.0, 3.0],
                                                    "velocity": [0.0, 11.0, 3.0],
                                                    "time": 0.5}]},
                    4.0, 6.0, long=True, event=True, tree=source(crate)))
    out.append(Case("blast breaks branches", f"10 kg TNT 4 m from {a_small}, breaking on",
                    source(small), {"explosion": [{"position": [4.0, 0.0, 1.0], "time": 0.5,
                                                   "charge": 10.0}]}, 3.0, 6.0, event=True,
                    tree=source(small)))
    out.append(Case("tornado uproots", f"an EF2 vortex through {a_small}, breaking on",
                    source(small), {"vortex": [{"start": [-30.0, 0.0], "velocity": [12.0, 0.0],
                                                "max_speed": 55.0, "core_radius": 15.0,
                                                "end": 4.0}]}, 4.0, 7.0, event=True,
                    tree=source(small)))
    out.append(Case("10 min gusty", "ten minutes of gusts, then ten seconds of calm",
                    plain, _gust(12, 600.0), 602.0, 612.0, long=True, tree=source(small)))
    out.append(Case("10 min calm", "ten minutes after a pull, prestressed, no wind",
                    plain, {"pull": [{"tree": 0, "force": [5.0, 0, 0], "release": 1.0}]},
                    1.0, 600.0, long=True, tree=source(small)))
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


# The suite's cost: CPU s of each run, one after another in one process, as
# `treebake stability` (engine auto) ran them on a 2-core machine shared
# with other work (the larger of two runs where there were two; they
# differed by up to 25 %), by the case's kind and tree ("" for a case's
# own small tree): planar draft, default, final, full (docs/physics.md,
# "The stress suite's cost"). The bundled suite's runs are all here; the
# other species' are QUICK's runs on them (`treebake stability NAME`),
# and the spruce's blast breaking branches on the reference was stopped
# after 1790 s (at least that). NA: not measured.
COLUMNS = ("planar draft", "planar default", "planar final", "full")
NA = math.nan  # not measured
CPU_SECONDS: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "stiff x1": {"": (1.6, 1.6, 1.4, 0.8)},
    "stiff x100": {"": (1.4, 1.3, 1.3, 0.9)},
    "stiff x10000": {"": (1.7, 1.3, 1.4, 0.8)},
    "mass 1:10^2": {"": (1.3, 1.3, 1.6, 1.4)},
    "mass 1:10^4": {"": (1.4, 1.9, 2, 0.9)},
    "cone 0.5 deg": {"": (1.4, 1.7, 1.6, 0.9)},
    "cone 5 deg": {"": (1.4, 1.5, 1.6, 1)},
    "cone 90 deg": {"": (1.7, 1.5, 1.5, 0.9)},
    "overlapping": {"": (1.5, 1.6, 1.9, 1.2)},
    "near-zero segments": {"": (2.1, 1.6, 1.3, 1)},
    "1 mm between 1 m": {"": (0.4, 0.4, 0.5, 0.7)},
    "200-segment chain": {"": (0.1, 0.8, 1.3, 71.9)},
    "wind 45 m/s": {"sapling": (0.6, 0.8, 1.3, 2.4)},
    "wind 70 m/s": {"sapling": (0.6, 0.9, 1.3, 2.3), "palm": (0.6, NA, NA, 6.9),
        "bamboo": (6.1, NA, NA, 65.9), "oak": (1.6, NA, NA, 22.3), "spruce": (1.3, NA, NA, 37.2),
        "willow": (4.6, NA, NA, NA)},
    "blast 2 kg at 6 m": {"sapling": (0.8, 0.8, 1.5, 3.5)},
    "blast 50 kg at 5 m": {"sapling": (4.3, 5.1, 5.5, 6.7), "palm": (0.6, NA, 4.2, NA),
        "bamboo": (8.1, NA, 51.7, NA), "oak": (4.8, NA, 13, NA), "spruce": (157.8, NA, 273.2, NA),
        "willow": (8.9, NA, NA, NA)},
    "blast 500 kg at 6 m": {"sapling": (13.8, 14.3, 16, 14.9), "palm": (2.3, NA, NA, NA),
        "bamboo": (19.9, NA, NA, NA), "oak": (22.7, NA, NA, NA), "spruce": (162.7, NA, NA, NA),
        "willow": (25.7, NA, NA, NA)},
    "felling": {"sapling": (1.1, 2.6, 3.8, 6.3), "palm": (2, 8.4, 13.9, 24.6),
        "bamboo": (3, 25.7, 46.2, 86.3), "oak": (4.9, 44.3, 62.9, 103.9),
        "spruce": (6.2, 46.5, 90.1, 136.3), "willow": (35.8, 1477.1, 1450.2, 2059.4)},
    "crate breaks a stem": {"sapling": (1.3, NA, NA, NA), "palm": (1.5, NA, NA, NA),
        "bamboo": (2.9, NA, NA, NA), "oak": (1.9, 12.6, 50.4, 62.9), "spruce": (5.3, NA, NA, NA),
        "willow": (3.2, NA, NA, NA)},
    "blast breaks branches": {"sapling": (6, 6.4, 8.5, 10.2), "palm": (0.6, NA, NA, 13.5),
        "bamboo": (5.1, NA, NA, 54.3), "oak": (5.2, NA, NA, 44.7), "spruce": (17.9, NA, NA, 1790),
        "willow": (4.4, NA, NA, NA)},
    "tornado uproots": {"sapling": (1.3, 3.5, 4.7, 5.5), "palm": (1.5, 9.6, NA, NA),
        "bamboo": (2.5, 21.6, NA, NA), "oak": (6.9, 45.6, NA, NA), "spruce": (7.3, 104.7, NA, NA),
        "willow": (31.8, NA, NA, NA)},
    "10 min gusty": {"sapling": (27.9, 30.3, 68.2, 187.9)},
    "10 min calm": {"sapling": (28.5, 25.8, 53.2, 143.6)},
}
# the measured trees' bones (planar draft, and default, final and full),
# for scaling a cost to another tree
BONES: dict[str, tuple[int, int]] = {"sapling": (39, 57), "palm": (52, 149), "bamboo": (196, 588),
    "oak": (246, 767), "spruce": (203, 946), "willow": (566, 2818)}
START_CPU = 0.3  # s: a bake's start-up, whatever its tree
# a run's CPU grows as the tree's bones to about this power: from the
# sapling to the bamboo the same run costs 0.7-1.4 powers of the bones
# ratio, from the oak to the willow felled at default 2.7; scaling is from
# the nearest measured trees, so the power matters little inside their range
BONES_POWER = 1.5

# `--quick`: the runs that found the most per CPU second, most telling
# first, as (kind, solver, level, the bundled tree it takes without a
# grammar). The suite's failures (git log, docs/physics.md) were in events
# and big loads on the nonlinear engines, most at draft (the coarsest step)
# and final: the blasted sapling (1.2x its energy at draft), the tornado
# (1.9x at draft, 2.1x at default), felled trees landing (the sapling 2.4 %
# at draft and 2.3 % at final, the willow 5.6 % at draft), the 70 m/s gust
# (3.1 %), the 500 kg blast (4.7 %), the 50 kg blast (a joint gap at draft,
# 2.1 % at final), the crate's oak sunk 0.81 m into the ground. No failure
# of the cases on their own small trees (stiffness, mass ratios, cones,
# tiny segments) is recorded; they cost about 1 s each and come last.
# With a grammar its tree takes every tree's place (two fellings at draft
# are one run). Runs past QUICK_BUDGET are left out, said up front.
# CPU s of the estimates: a run's CPU varies by 10-25 % from one run to the
# next and the command's start-up takes 3 s, so that the measured CPU stays
# near 150 s, half the 5 minutes of wall time (one process, 2 idle cores)
QUICK_BUDGET = 135.0
QUICK_LIMIT = 300.0  # CPU s: the 5 minutes; no quick run starts that would end past them
QUICK: tuple[tuple[str, str, str, str], ...] = (
    ("blast breaks branches", "planar", "draft", "sapling"),
    ("tornado uproots", "planar", "draft", "sapling"),
    ("felling", "planar", "draft", "spruce"),
    ("wind 70 m/s", "planar", "draft", "sapling"),
    ("blast 500 kg at 6 m", "planar", "draft", "sapling"),
    ("crate breaks a stem", "planar", "draft", "oak"),
    ("felling", "planar", "final", "sapling"),
    ("blast 50 kg at 5 m", "planar", "final", "sapling"),
    ("tornado uproots", "planar", "default", "sapling"),
    ("felling", "planar", "default", "sapling"),
    ("felling", "full", "default", "sapling"),
    ("blast breaks branches", "full", "default", "sapling"),
    ("wind 70 m/s", "full", "default", "sapling"),
    ("blast 50 kg at 5 m", "planar", "draft", "sapling"),
    ("felling", "planar", "draft", "willow"),
    ("1 mm between 1 m", "planar", "draft", ""),
    ("near-zero segments", "planar", "draft", ""),
    ("stiff x10000", "planar", "draft", ""),
    ("mass 1:10^4", "planar", "draft", ""),
    ("cone 0.5 deg", "planar", "draft", ""),
    ("overlapping", "planar", "draft", ""),
    ("200-segment chain", "planar", "final", ""),
    ("stiff x10000", "full", "default", ""),
    ("mass 1:10^4", "full", "default", ""),
    ("near-zero segments", "full", "default", ""),
    ("1 mm between 1 m", "full", "default", ""),
)


@dataclass
class Run:
    """One bake of the suite: a case on a solver ("planar" at `level`, or
    "full"), with its estimated CPU s."""

    case: Case
    solver: str
    level: str = "default"
    estimate: float = math.nan

    @property
    def label(self) -> str:
        return f"{self.case.name}, {self.solver_label}"

    @property
    def solver_label(self) -> str:
        return f"planar {self.level}" if self.solver == "planar" else self.solver


def cpu_seconds() -> float:
    """CPU s of this process (every thread) and its finished children."""
    total = time.process_time()
    try:
        import resource
    except ImportError:  # Windows: no children's times
        return total
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return total + children.ru_utime + children.ru_stime


@functools.lru_cache(maxsize=16)
def tree_bones(tree: str) -> tuple[int, int]:
    """Bones of the tree a case's `tree` grows (its grammar as bundled or in
    a file) at draft, and at default (final and the full reference rig it
    as default does: one bone per segment)."""
    from .grow import grow
    from .rig import RigOptions, build_rig

    kind, name = tree.split(":", 1)
    path = grammar_path(name) if kind == "species" else Path(name)
    scene = parse_scene({"name": "bones", "tree": [{"grammar": str(path)}]}, file="<bones>")
    model = grow(scene)[0].model
    out = []
    for level in ("draft", "default"):
        length = QUALITIES[level].bone_length * max(model.height, 1e-3)
        out.append(int(build_rig(model, RigOptions(min_bone_length=length)).seg_bone.max()) + 1)
    return out[0], out[1]


def estimate(case: Case, solver: str, level: str = "default") -> float:
    """CPU s of a run, from CPU_SECONDS: as measured if its tree was
    measured, else scaled by (bones ratio)^BONES_POWER (bones at the run's
    level) from the measured trees next in size below and above it, the
    larger of the two (the same load costs trees of one size alike only
    roughly: a blast that breaks the sapling's joints sends it to the
    reference, the palm's it leaves in the linear tier). nan for a run the
    table does not know."""
    column = COLUMNS.index(f"planar {level}" if solver == "planar" else solver)
    known = {t: v[column] for t, v in CPU_SECONDS.get(case.kind, {}).items()
             if not math.isnan(v[column])}
    if not case.tree:
        return known.get("", math.nan)
    source, name = case.tree.split(":", 1)
    tree = name if source == "species" else bundled_name(name)
    if tree in known:
        return known[tree]
    if not known:
        return math.nan
    at = 0 if column == 0 else 1
    bones = max(tree_bones(case.tree)[at], 1)
    below = [t for t in known if BONES[t][at] <= bones]
    above = [t for t in known if BONES[t][at] >= bones]
    near = {max(below, key=lambda t: BONES[t][at])} if below else set()
    near |= {min(above, key=lambda t: BONES[t][at])} if above else set()
    return max(START_CPU + (known[t] - START_CPU) * (bones / BONES[t][at]) ** BONES_POWER
               for t in near)


def plan(long: bool = True, solvers: tuple[str, ...] = ("planar", "full"),
         levels: tuple[str, ...] = LEVELS, only: list[str] | None = None,
         grammar: str | Path | None = None) -> list[Run]:
    """The full suite's runs (without `long`: no ten-minute runs, no events
    on the big species): every case on the solvers, the planar LOD at each
    of `levels`; `only` these case names."""
    runs = []
    for case in cases(long, grammar):
        if only and case.name not in only:
            continue
        if "planar" in solvers:
            runs += [Run(case, "planar", lv) for lv in levels]
        if "full" in solvers:
            runs.append(Run(case, "full"))
    for r in runs:
        r.estimate = estimate(r.case, r.solver, r.level)
    return runs


def quick_plan(solvers: tuple[str, ...] = ("planar", "full"),
               levels: tuple[str, ...] | None = None, only: list[str] | None = None,
               grammar: str | Path | None = None,
               budget: float = QUICK_BUDGET) -> tuple[list[Run], list[Run]]:
    """`--quick`: QUICK's runs on the solvers (the planar ones at `levels`
    if given, else at QUICK's), `only` these case names, in QUICK's order,
    each taken while the estimates so far fit `budget` (CPU s). Returns the
    runs and those left out (over the budget or not estimated)."""
    by_name = {c.name: c for c in cases(True, grammar)}
    chosen: list[Run] = []
    seen = set()
    for kind, solver, level, species in QUICK:
        if solver not in solvers:
            continue
        case = next((c for c in by_name.values() if c.kind == kind and (
            grammar is not None or not c.tree or c.tree == f"species:{species}")), None)
        if case is None or (only and case.name not in only):
            continue
        for lv in (levels or (level,)) if solver == "planar" else ("default",):
            if (case.name, solver, lv) not in seen:
                seen.add((case.name, solver, lv))
                chosen.append(Run(case, solver, lv, estimate(case, solver, lv)))
    runs, left, total = [], [], 0.0
    for r in chosen:
        if not math.isnan(r.estimate) and total + r.estimate <= budget:
            runs.append(r)
            total += r.estimate
        else:
            left.append(r)
    return runs, left


def quick_cases(grammar: str | Path | None = None) -> list[str]:
    """The names of the cases QUICK can run (at some solver and level)."""
    runs, left = quick_plan(grammar=grammar, budget=math.inf)
    return list(dict.fromkeys(r.case.name for r in runs + left))


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


def plan_summary(runs: list[Run], left: list[Run], quick: bool, budget: float,
                 engine: str = "auto") -> str:
    """What a plan will run and cost, and what it leaves out, said before it
    runs: `quick: 26 runs of 16 cases, about 117 s of CPU (budget 135 s)`."""
    total = sum(r.estimate for r in runs if not math.isnan(r.estimate))
    unknown = sum(1 for r in runs if math.isnan(r.estimate))
    n, cases_ = len(runs), len({r.case.name for r in runs})
    line = (f"{'quick: ' if quick else ''}{n} run{'s' * (n != 1)} of {cases_} "
            f"case{'s' * (cases_ != 1)}, about {_duration(total)} of CPU")
    if unknown:
        line += f" and {unknown} runs not estimated"
    if quick:
        line += f" (budget {_duration(budget)})"
    if engine != "auto":
        line += f"; estimated for --engine auto, not {engine}"
    if left:
        line += ("\nleft out, over the budget: "
                 + "; ".join(f"{r.label} (about {_duration(r.estimate)})" for r in left))
    return line


def _duration(seconds: float) -> str:
    """`45 s`, `135 s`, `29.8 min`, `1.3 h`."""
    if math.isnan(seconds):
        return "unknown"
    if seconds < 600:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min" if seconds < 6000 else f"{seconds / 3600:.1f} h"
