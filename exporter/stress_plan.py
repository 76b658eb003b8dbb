"""The stress suite's plan and cost: which runs `treebake stability` makes
(every case on every solver and level, or `--quick`'s budgeted selection),
and each run's CPU seconds estimated from measured runs (CPU_SECONDS),
scaled by bones to trees not measured."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

from .library import grammar_path
from .quality import QUALITIES
from .scene import parse_scene
from .stress_cases import Case, bundled_name, cases

LEVELS = ("draft", "default", "final")  # the planar LOD's quality levels

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
# for scaling a cost to another tree. The palm, bamboo, spruce and oak were
# measured as grammars at 1edc0e9 and redrawn since (issue 40: bones within
# 10 % at default): their runs are scaled by bones to the trees as bundled
# (estimate) until `treebake stability` measures them again
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
    measured (scaled by bones if its grammar was redrawn since), else
    scaled by (bones ratio)^BONES_POWER (bones at the run's level) from
    the measured trees next in size below and above it, the larger of the
    two (the same load costs trees of one size alike only roughly: a blast
    that breaks the sapling's joints sends it to the reference, the palm's
    it leaves in the linear tier). nan for a run the table does not know."""
    column = COLUMNS.index(f"planar {level}" if solver == "planar" else solver)
    known = {t: v[column] for t, v in CPU_SECONDS.get(case.kind, {}).items()
             if not math.isnan(v[column])}
    if not case.tree:
        return known.get("", math.nan)
    source, name = case.tree.split(":", 1)
    tree = name if source == "species" else bundled_name(name)
    at = 0 if column == 0 else 1
    if tree in known:
        # a bundled grammar redrawn since it was measured: its own run, scaled
        bones = max(tree_bones(case.tree)[at], 1) if source == "species" else BONES[tree][at]
        return START_CPU + (known[tree] - START_CPU) * (bones / BONES[tree][at]) ** BONES_POWER
    if not known:
        return math.nan
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
