"""Does the pymunk tier earn its place? The planar LOD's two nonlinear
engines on the same cases, against one truth, for the three reasons the
engine table (exporter/sim/handoff.py `engine_for`, docs/physics.md "Which
engine takes a tree") could give to the pymunk tier: a felling cut (`cut`),
a branch tip reaching the ground (`ground`) and a thrown object that can
reach the tree (`projectile`).

Each case bakes one scene three ways, one after another in this process
(`treebake.pipeline.bake_scene(..., workers=1)`):

- pymunk:    the LOD at `default` with every reason on the pymunk tier
             (`dataclasses.replace(QUALITIES["default"], nonlinear="pymunk")`);
- reference: the LOD at `default` with every reason on the MuJoCo reference
             (`nonlinear="reference"`, its step `reference_step`, 1/480 s);
- truth:     `bake_scene(scene, solver="full", quality=QUALITIES["final"],
             timestep=accuracy.TRUTH_STEP)`: the reference with one bone per
             segment at 1/2000 s, the truth of `treebake accuracy`.

Measured per case and setting: CPU seconds of the whole bake (growing and
rigging included; `time.process_time` around `bake_scene`; the LOD's
settings `--repeat` times, the least counts), the RMS and max
position error of every segment's end over every frame as % of the tree's
height against the truth (`accuracy.tree_errors`), and the engines each tree
ran on (`bake.trees[i].info["solver"]`), with a check that the case's reason
really went to the engine the setting asks for, and (JSON) the lowest any
segment end went (m; below 0: into the ground). Grammars lose their
breaking (`accuracy.unbreakable`), so errors measure accuracy, not chaos;
the ground cases' grammars keep a strength no joint reaches instead
(`never_breaking`): without a cut, a projectile or a finite strength the
reference, the LOD's and the truth's, has no ground contact at all
(`ground-spruce-nocontact` shows it). The setting `nonlinear = "auto"`
would pick is marked `(auto)`.

Cases (`--list`): cut-sapling, cut-spruce (presets/felling.toml, cut at
0.5 s, 4 s), cut-spruce-h15 (a 15 degree hinge: the stem falls free within
the 4 s), ground-spruce (gravity switched on at t = 0: the lowest branches
sag onto the ground), ground-spruce-nocontact, ground-spruce20 (not run
unless asked), projectile-sapling (accuracy.SCENARIOS["boxes"]),
projectile-oak (the 150 kg crate of accuracy.EVENT_CASES). About 9
minutes of CPU with the default 3 repeats (14 min wall with load waits).

    python bench/engines.py                       # the default cases (all but ground-spruce20)
    python bench/engines.py --cases cut-sapling projectile-sapling
    python bench/engines.py --list                # the cases and their scenes
    python bench/engines.py --repeat 3 --max-load 1.5 --max-wait 120 \
                            --json out/bench/engines.json

The machine may be shared: before each bake the script waits (up to
`--max-wait` s) for the 1-minute load average to fall below `--max-load`
and records it; costs are CPU seconds of this process, never wall time.
A bake that raises is recorded with its error and the run goes on.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from treebake.accuracy import SCENARIOS, TRUTH_STEP, tree_errors, unbreakable  # noqa: E402
from treebake.fileio import write_text  # noqa: E402
from treebake.pipeline import bake_scene  # noqa: E402
from treebake.quality import QUALITIES  # noqa: E402
from treebake.scene import parse_scene  # noqa: E402
from treebake.sim.handoff import Engine, Reason, engine_for  # noqa: E402
from treebake.sway import segment_ends  # noqa: E402

NEVER = 1e15  # Pa: a modulus of rupture no joint reaches (see `never_breaking`)

# name: (reason, scene keys around the trees; "grammar" a bundled species,
# made unbreakable; "never_breaking": True makes it `never_breaking` instead).
# The case's reason must show in info["solver"].
CASES = {
    "cut-sapling": (Reason.CUT, {
        "duration": 3.0, "tree": [{"grammar": "sapling"}],
        "cut": [{"tree": 0, "time": 0.5, "direction": 45.0, "hinge": 40.0}]}),
    # presets/felling.toml cut at 0.5 s, 4 s (the truth is costly): the
    # hinge snaps at ~3.7 s, the stem is still leaning at the end
    "cut-spruce": (Reason.CUT, {
        "duration": 4.0, "tree": [{"grammar": "spruce"}],
        "cut": [{"tree": 0, "time": 0.5, "direction": 45.0, "hinge": 40.0}]}),
    # a weaker hinge so that the stem falls free and meets the ground in 4 s
    "cut-spruce-h15": (Reason.CUT, {
        "duration": 4.0, "tree": [{"grammar": "spruce"}],
        "cut": [{"tree": 0, "time": 0.3, "direction": 45.0, "hinge": 15.0}]}),
    # The spruce's lowest drooping branches sag onto the ground when gravity
    # is switched on at t = 0 (no prestress): a hand-off for "a tip reached
    # the ground" at ~0.3 s. (A sapling or bamboo in a hurricane, the willow
    # in a gale and a sapling under a strong attractor leave for a bone
    # turning past 1 rad first, or never leave: not ground cases.)
    # `never_breaking`: with no cut, projectile or finite strength the
    # reference (the LOD's and the truth) builds its model without ground
    # contact (reference/model.py `_groups`), so with plain `unbreakable`
    # grammars both let the branch sink into the ground: that variant is
    # "ground-spruce-nocontact".
    "ground-spruce": (Reason.GROUND, {
        "duration": 3.0, "prestress": False,
        "tree": [{"grammar": "spruce", "never_breaking": True}]}),
    "ground-spruce-nocontact": (Reason.GROUND, {
        "duration": 3.0, "prestress": False, "tree": [{"grammar": "spruce"}]}),
    # two fewer growth steps (shorter branches, 780 segments instead of 946)
    "ground-spruce20": (Reason.GROUND, {
        "duration": 3.0, "prestress": False,
        "tree": [{"grammar": "spruce", "iterations": 20, "never_breaking": True}]}),
    "projectile-sapling": (Reason.PROJECTILE, {  # accuracy.SCENARIOS["boxes"]
        "duration": 3.0, "tree": [{"grammar": "sapling"}], **SCENARIOS["boxes"]}),
    "projectile-oak": (Reason.PROJECTILE, {  # accuracy.EVENT_CASES["crate into oak"]
        "duration": 3.0, "tree": [{"grammar": "oak"}],
        "projectile": [{"shape": "box", "size": 0.8, "mass": 150.0,
                        "position": [0.0, -9.0, 3.0], "velocity": [0.0, 11.0, 3.0],
                        "time": 0.5}]}),
}
DEFAULT_CASES = ["cut-sapling", "cut-spruce", "cut-spruce-h15", "ground-spruce",
                 "ground-spruce-nocontact", "projectile-sapling", "projectile-oak"]

DETAIL = {Reason.CUT: "its felling cut", Reason.GROUND: "a tip reached the ground"}


def settings() -> dict:
    """Setting name: bake_scene keyword arguments."""
    default = QUALITIES["default"]
    return {
        "pymunk": {"quality": dataclasses.replace(default, nonlinear="pymunk")},
        "reference": {"quality": dataclasses.replace(default, nonlinear="reference")},
        "truth": {"solver": "full", "quality": QUALITIES["final"], "timestep": TRUTH_STEP},
    }


def never_breaking(species: str, folder: Path) -> Path:
    """`accuracy.unbreakable`'s grammar with a modulus of rupture no joint
    reaches (NEVER): nothing breaks, but the strength is finite, so the
    reference collides the tree with the ground even without a cut or a
    projectile in the scene."""
    sub = folder / "never"
    sub.mkdir(exist_ok=True)
    path = sub / f"{species}.lsys"
    path.write_text(unbreakable(species, folder).read_text() + f"rupture: {NEVER:g}\n")
    return path


def case_scene(name: str, folder: Path, fps: float, duration: float | None = None):
    """The case's scene, every grammar without breaking (`duration`: instead
    of the case's own)."""
    _reason, keys = CASES[name]
    raw = json.loads(json.dumps(keys))
    if duration is not None:
        raw["duration"] = duration
    for t in raw["tree"]:
        make = never_breaking if t.pop("never_breaking", False) else unbreakable
        t["grammar"] = str(make(t["grammar"], folder))
    return parse_scene({"name": name, "fps": fps, **raw}, file=f"<bench engines {name}>")


def reached(reason: Reason, engine: Engine, solver_text: str) -> bool:
    """Did `reason` send the tree to `engine`? info["solver"] reads "linear,
    then pymunk from 0.500 s (its felling cut)"; a tree a projectile can
    reach starts in its engine: "reference"."""
    if reason is Reason.PROJECTILE:
        return solver_text.split(",")[0].strip() == engine.value
    spans = [s.strip() for s in solver_text.split(", then ")]
    return any(s.startswith(f"{engine.value} from") and DETAIL[reason] in s for s in spans)


def wait_for_quiet(max_load: float, max_wait: float) -> float:
    """Wait (at most max_wait s) for the 1-minute load below max_load; the
    load when going on."""
    waited = 0.0
    load = os.getloadavg()[0]
    while load >= max_load and waited < max_wait:
        time.sleep(10.0)
        waited += 10.0
        load = os.getloadavg()[0]
    return load


def warm_up(folder: Path) -> None:
    """Import and first-call costs (pymunk, MuJoCo) out of the measurements:
    a short felling on each engine, untimed."""
    raw = {"name": "warm-up", "duration": 0.6, "fps": 30.0,
           "tree": [{"grammar": str(unbreakable("sapling", folder))}],
           "cut": [{"tree": 0, "time": 0.1}]}
    scene = parse_scene(raw, file="<bench engines warm-up>")
    for kw in settings().values():
        bake_scene(scene, workers=1, **kw)


def run_case(name: str, folder: Path, fps: float, duration: float | None, max_load: float,
             max_wait: float, repeat: int, log) -> list[dict]:
    """The truth, then the LOD on each engine (`repeat` times: the least CPU
    time counts; the bake is deterministic), compared with the truth."""
    reason, _keys = CASES[name]
    scene = case_scene(name, folder, fps, duration)
    auto = engine_for(reason, QUALITIES["default"]).value
    bakes, rows = {}, []
    for label, kw in [("truth", settings()["truth"]),
                      *[(k, v) for k, v in settings().items() if k != "truth"]]:
        row = {"case": name, "reason": reason.value, "setting": label,
               "auto": label == auto, "duration_s": scene.duration, "load_1min": [],
               "cpu_s": math.nan, "cpu_s_runs": [], "rms_pct": math.nan, "max_pct": math.nan,
               "engines": [], "reason_on_engine": None, "error": ""}
        bake = None
        for _ in range(1 if label == "truth" else repeat):
            row["load_1min"].append(round(wait_for_quiet(max_load, max_wait), 2))
            start = time.process_time()
            try:
                bake = bake_scene(scene, workers=1, **kw)
            except Exception as exc:  # recorded, not fatal
                row["cpu_s_runs"].append(time.process_time() - start)
                row["error"] = f"{type(exc).__name__}: {exc}"
                row["traceback"] = traceback.format_exc(limit=6)
                bake = None
                break
            row["cpu_s_runs"].append(time.process_time() - start)
        row["cpu_s"] = min(row["cpu_s_runs"])
        if bake is None:
            log(f"  {name:<24} {label:<10} FAILED after {row['cpu_s']:.1f} cpu s: {row['error']}")
            rows.append(row)
            continue
        bakes[label] = bake
        row["engines"] = [t.info.get("solver", t.info.get("static", "")) for t in bake.trees]
        row["engine_cpu_s"] = {k: v.get("cpu_seconds") for k, v in
                               bake.timing.get("engines", {}).items()}
        row["segments"] = [t.n_segments for t in bake.trees]
        row["bones"] = [t.info.get("bones") for t in bake.trees]
        row["notes"] = list(bake.meta.get("notes", []))
        # the lowest any segment end went (m): below about 0, into the ground
        row["lowest_end_z_m"] = [float(segment_ends(t, np.arange(t.n_segments))[..., 2].min())
                                 for t in bake.trees]
        if label != "truth":
            row["reason_on_engine"] = all(reached(reason, Engine(label), s)
                                          for s in row["engines"])
        if "truth" in bakes:
            try:
                row["rms_pct"], row["max_pct"] = tree_errors(bake, bakes["truth"])
            except Exception as exc:
                row["error"] = f"errors: {type(exc).__name__}: {exc}"
        runs = ", ".join(f"{c:.2f}" for c in row["cpu_s_runs"])
        log(f"  {name:<24} {label:<10} {row['cpu_s']:8.2f} cpu s ({runs})  "
            f"{row['rms_pct']:8.3f} % rms {row['max_pct']:8.3f} % max  lowest end "
            f"{min(row['lowest_end_z_m']):+.3f} m  load {row['load_1min']}  "
            f"{'; '.join(row['engines'])}")
        rows.append(row)
    return rows


def table(rows: list[dict]) -> str:
    lines = ["| case | setting | CPU s | RMS % | max % | engines |", "|---|---|---|---|---|---|"]
    for r in rows:
        setting = r["setting"] + (" (auto)" if r["auto"] else "")
        if r["reason_on_engine"] is False:
            setting += " [reason NOT on this engine]"
        if r["error"] and not r["engines"]:
            lines.append(f"| {r['case']} | {setting} | {r['cpu_s']:.2f} | - | - | "
                         f"failed: {r['error']} |")
            continue
        err = "truth" if r["setting"] == "truth" else f"{r['rms_pct']:.3g}"
        mx = "truth" if r["setting"] == "truth" else f"{r['max_pct']:.3g}"
        lines.append(f"| {r['case']} | {setting} | {r['cpu_s']:.2f} | {err} | {mx} | "
                     f"{'; '.join(r['engines'])}{' (' + r['error'] + ')' if r['error'] else ''} |")
    return "\n".join(lines)


def _clean(obj):
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_clean(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", choices=list(CASES), default=DEFAULT_CASES,
                    metavar="CASE", help=f"cases to run (default: {' '.join(DEFAULT_CASES)}; "
                    f"all: {' '.join(CASES)})")
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds of every case (default: each case's own, 3-4 s)")
    ap.add_argument("--max-load", type=float, default=1.5,
                    help="wait before each bake for the 1-minute load below this")
    ap.add_argument("--max-wait", type=float, default=120.0,
                    help="longest wait (s) for a quiet machine before each bake")
    ap.add_argument("--repeat", type=int, default=3,
                    help="bakes of each LOD setting (the least CPU time counts; the truth once)")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "engines.json"))
    ap.add_argument("--list", action="store_true", help="print the cases and exit")
    args = ap.parse_args()
    if args.list:
        for name, (reason, keys) in CASES.items():
            print(f"{name} ({reason.value}): {json.dumps(keys)}")
        return 0

    def log(msg):
        print(msg, flush=True)

    rows: list[dict] = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        warm_up(folder)
        for name in args.cases:
            log(f"{name} ({CASES[name][0].value}):")
            rows += run_case(name, folder, args.fps, args.duration, args.max_load, args.max_wait,
                             args.repeat, log)
            write_text(args.json, json.dumps(_clean(_payload(args, rows)), indent=2) + "\n")
    print()
    print(table(rows))
    print(f"\n(auto): the engine nonlinear = \"auto\" picks at `default`. CPU s: the whole bake, "
          f"one process; errors: every segment end, every frame, % of tree height, against "
          f"the reference with one bone per segment at {TRUTH_STEP:g} s "
          f"({time.perf_counter() - started:.0f} s wall in all)")
    write_text(args.json, json.dumps(_clean(_payload(args, rows)), indent=2) + "\n")
    print(f"written {args.json}")
    return 0 if all(not r["error"] and r["reason_on_engine"] is not False for r in rows) else 1


def _payload(args, rows: list[dict]) -> dict:
    s = settings()
    meta = {"truth_step": TRUTH_STEP, "fps": args.fps, "duration_override": args.duration,
            "cases": args.cases,
            "scenes": {n: {"reason": CASES[n][0].value, **CASES[n][1]} for n in args.cases},
            "settings": {k: {"solver": v.get("solver", "planar"),
                             "quality": dataclasses.asdict(v["quality"]),
                             "timestep": v.get("timestep")} for k, v in s.items()},
            "cpu": "time.process_time around bake_scene, workers=1, one process",
            "max_load": args.max_load, "max_wait": args.max_wait, "repeat": args.repeat}
    return {"meta": meta, "rows": rows}


if __name__ == "__main__":
    sys.exit(main())
