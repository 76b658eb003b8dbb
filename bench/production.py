"""Production jobs: cost and error of each solver setting against the truth.

The jobs a user bakes (spruce, oak and willow in grammar-job wind, a
50-tree forest in a strong breeze), each with every setting, each setting in
its own process (`--workers 1`), in one run:

- cost: CPU seconds of the whole process (what `/usr/bin/time` reports:
  start-up, growing, rigging, simulating, saving) and of the simulation
  alone (the bake's own timing); and the process's fixed cost, what it
  spends not simulating (the interpreter and numpy starting, the package's
  imports, the scene, growing and rigging, saving): the least a setting
  could cost with a solver that took no time, printed against the
  reference at 1/240 s;
- error: every segment's end over every frame against the truth — the MuJoCo
  reference with one bone per segment (`--quality final`) at 1/2000 s — as %
  of the tree's height: RMS and max, the median over trees for a forest.

As in `treebake accuracy`, the grammars are baked without breaking (no
rupture, strength or anchor): a break is a branching event after which two
runs need not follow each other, so errors would measure chaos.

    python bench/production.py [--jobs spruce oak willow forest50]
                               [--settings lod ref240 ref480] [--out out/bench]

Timings on a shared machine are noisy: read the ratios within one run.
"""

from __future__ import annotations

import argparse
import compileall
import importlib.util
import json
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

JOBS = {  # name: (scene keys, duration s)
    "spruce": ({"tree": [{"grammar": "grammars/spruce.lsys"}],
                "wind": {"speed": 6.7, "turbulence": 0.25}}, 4.0),
    "oak": ({"tree": [{"grammar": "grammars/oak.lsys"}],
             "wind": {"speed": 6.7, "turbulence": 0.25}}, 4.0),
    "willow": ({"tree": [{"grammar": "grammars/willow.lsys"}],
                "wind": {"speed": 12.0, "turbulence": 0.25}}, 6.0),
    "forest50": (None, 4.0),  # bench/forest.py's forest of 50 trees, no camera
}
SETTINGS = {  # name: bake_scene keyword arguments (quality: a level, or a level and changes)
    "lod": {"solver": "planar", "quality": "default"},
    "lod-draft": {"solver": "planar", "quality": "draft"},
    "lod-final": {"solver": "planar", "quality": "final"},
    # default with the linear tier at 1/60 s (the willow's twigs: its error is the step's)
    "lod-60hz": {"solver": "planar", "quality": ("default", {"linear_rate": 60.0})},
    "pymunk": {"solver": "planar", "quality": ("default", {"tier": "pymunk",
                                                          "bone_length": 1 / 30})},
    # the reference with 0.1.0's default bones (>= 1/30 of the height), as the issue measured
    "ref240": {"solver": "full", "quality": ("default", {"bone_length": 1 / 30}),
               "timestep": 1 / 240},
    "ref480": {"solver": "full", "quality": ("default", {"bone_length": 1 / 30}),
               "timestep": 1 / 480},
    "ref240-every": {"solver": "full", "quality": "final", "timestep": 1 / 240},
    "truth": {"solver": "full", "quality": "final", "timestep": 1 / 2000},
}


def unbreakable(grammar: str, folder: Path) -> str:
    """A copy of a grammar (path relative to the checkout) without breaking."""
    src = (ROOT / grammar).read_text().splitlines()
    keep = [ln for ln in src if ln.split(":")[0].strip() not in ("rupture", "strength", "anchor")]
    if len(keep) == len(src):
        raise ValueError(f"{grammar}: no rupture, strength or anchor line to remove")
    path = folder / grammar.replace("/", "_")
    path.write_text("\n".join(keep) + "\n")
    return str(path)


def job_scene(job: str, folder: Path):
    from treebake.scene import parse_scene

    keys, duration = JOBS[job]
    if keys is None:
        from forest import forest_scene

        raw = forest_scene(50, duration, culled=False)
        raw["forest"]["grammars"] = [unbreakable(str(Path(g).relative_to(ROOT)), folder)
                                     for g in raw["forest"]["grammars"]]
    else:
        raw = json.loads(json.dumps(keys))
        for t in raw["tree"]:
            t["grammar"] = unbreakable(t["grammar"], folder)
        raw.update(name=job, duration=duration)
    return parse_scene(raw, file=f"<production {job}>")


def run_one(job: str, setting: str, out: Path) -> dict:
    """Bake one job with one setting in this process; save the bake to `out`.
    Also where the process's CPU time went: start-up (the interpreter and
    numpy), the package's imports, the scene, the bake, the save."""
    started = time.process_time()  # the interpreter and this script's imports (numpy)
    from treebake.bake_file import save_bake
    from treebake.pipeline import bake_scene
    from treebake.quality import QUALITIES
    if setting.startswith("lod") or setting == "pymunk":
        from treebake.sim import lod  # noqa: F401 (imported by the bake: counted here)
    else:
        from treebake.sim import reference  # noqa: F401
    imported = time.process_time()

    kw = dict(SETTINGS[setting])
    level = kw["quality"]
    kw["quality"] = QUALITIES[level] if isinstance(level, str) else \
        replace(QUALITIES[level[0]], name="custom", **level[1])
    scene = job_scene(job, out.parent)
    cpu0 = time.process_time()
    bake = bake_scene(scene, workers=1, **kw)
    cpu = time.process_time() - cpu0
    cpu1 = time.process_time()
    save_bake(bake, out)
    saved = time.process_time() - cpu1
    t = bake.timing
    solvers: dict[str, int] = {}
    for tb in bake.trees:
        key = tb.info.get("solver", "static").split(" at ")[0]
        solvers[key] = solvers.get(key, 0) + 1
    return {"startup_cpu_seconds": round(started, 3),
            "import_cpu_seconds": round(imported - started, 3),
            "scene_cpu_seconds": round(cpu0 - imported, 3),
            "grow_seconds": t.get("grow_seconds", 0.0),  # growing and rigging (wall: one process)
            "save_cpu_seconds": round(saved, 3),
            "bake_cpu_seconds": round(cpu, 3),
            "solver_seconds": round(sum(t.get(k, 0.0) for k in (
                "step_seconds", "update_seconds", "build_seconds", "compile_seconds")), 3),
            "solvers": solvers, "notes": bake.meta.get("notes", [])}


def measure(job: str, setting: str, folder: Path) -> dict:
    """run_one in a fresh process; its whole CPU time from the parent."""
    path = folder / f"{job}-{setting}.npz"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, __file__, "--one", job, setting, str(path)],
                          capture_output=True, text=True, check=False, cwd=ROOT)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{job} {setting}: {done.stderr[-3000:]}")
    row = json.loads(done.stdout.strip().splitlines()[-1])
    row["process_cpu_seconds"] = round(after.ru_utime + after.ru_stime
                                       - before.ru_utime - before.ru_stime, 3)
    row["path"] = str(path)
    return row


def tree_errors(a, truth) -> tuple[list[float], list[float]]:
    """Per tree: RMS and max error of every segment's end, % of height."""
    from treebake.sway import segment_ends

    rms, mx = [], []
    for ta, tt in zip(a.trees, truth.trees):
        if tt.static and ta.static:
            continue
        frames = len(truth.times)

        def ends(tb):
            e = segment_ends(tb, np.arange(tb.n_segments))
            return np.repeat(e, frames, axis=0) if tb.static else e

        d = np.linalg.norm(ends(ta) - ends(tt), axis=-1)
        h = max(tt.height, 1e-9)
        rms.append(100 * float(np.sqrt(np.mean(d * d))) / h)
        mx.append(100 * float(d.max()) / h)
    return rms, mx


def fixed_cost(row: dict) -> float:
    """CPU s of a process that is not simulating: start-up, imports, the
    scene, growing and rigging, saving."""
    return round(sum(row[k] for k in ("startup_cpu_seconds", "import_cpu_seconds",
                                       "scene_cpu_seconds", "grow_seconds",
                                       "save_cpu_seconds")), 3)


def floor(job: str, rows: list[dict]) -> None:
    """Print each LOD setting's cost against the reference at 1/240 s, and
    the least it could reach with a solver that cost nothing (its fixed
    cost alone)."""
    ref = next((r for r in rows if r["setting"] == "ref240"), None)
    if ref is None:
        return
    for r in rows:
        if r["setting"].startswith("lod") or r["setting"] == "pymunk":
            print(f"  {job} {r['setting']}: {r['process_cpu_seconds'] / ref['process_cpu_seconds']:.2f}x "
                  f"ref240's process CPU; with a free solver "
                  f"{r['fixed_cpu_seconds'] / ref['process_cpu_seconds']:.2f}x "
                  f"(start-up {r['startup_cpu_seconds']:.2f}, imports {r['import_cpu_seconds']:.2f}, "
                  f"growing {r['grow_seconds']:.2f}, saving {r['save_cpu_seconds']:.2f} s)",
                  flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", nargs="*", default=list(JOBS), choices=list(JOBS))
    ap.add_argument("--settings", nargs="*", default=["lod", "pymunk", "ref240", "ref480"],
                    choices=[s for s in SETTINGS if s != "truth"])
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    ap.add_argument("--one", nargs=3, metavar=("JOB", "SETTING", "PATH"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(run_one(args.one[0], args.one[1], Path(args.one[2]))))
        return
    from treebake.bake_file import load_bake

    # an installed package has its bytecode compiled (pip does it); without
    # it (PYTHONDONTWRITEBYTECODE, a fresh checkout) every process here would
    # compile the package's source again: 0.07 s of CPU each on this machine
    package = importlib.util.find_spec("treebake").submodule_search_locations[0]
    compileall.compile_dir(package, quiet=1)
    rows = []
    print(f"{'job':<9} {'setting':<13} {'process CPU s':>13} {'fixed s':>7} {'bake CPU s':>10} "
          f"{'solver s':>8} {'RMS %':>8} {'max %':>8}  tiers", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for job in args.jobs:
            truth_row = measure(job, "truth", folder)
            truth = load_bake(truth_row["path"])
            for setting in ["truth", *args.settings]:
                r = truth_row if setting == "truth" else measure(job, setting, folder)
                rms, mx = tree_errors(load_bake(r["path"]), truth)
                r.update(job=job, setting=setting,
                         rms_pct=round(float(np.median(rms)), 5) if rms else 0.0,
                         max_pct=round(float(np.median(mx)), 5) if mx else 0.0,
                         worst_rms_pct=round(max(rms), 5) if rms else 0.0,
                         worst_max_pct=round(max(mx), 5) if mx else 0.0)
                r.pop("path")
                r["fixed_cpu_seconds"] = fixed_cost(r)
                rows.append(r)
                print(f"{job:<9} {setting:<13} {r['process_cpu_seconds']:>13.2f} "
                      f"{r['fixed_cpu_seconds']:>7.2f} "
                      f"{r['bake_cpu_seconds']:>10.2f} {r['solver_seconds']:>8.2f} "
                      f"{r['rms_pct']:>8.4f} {r['max_pct']:>8.3f}  {r['solvers']}", flush=True)
            floor(job, [r for r in rows if r["job"] == job])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "production.json").write_text(json.dumps({"rows": rows}, indent=2) + "\n")
    print(f"written {out / 'production.json'}")


if __name__ == "__main__":
    main()
