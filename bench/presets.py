"""Bake every preset and report the cost: wall time, simulated seconds,
segments, and microseconds per segment-step (simulated segments x substeps);
each engine's CPU per segment-frame (the planar LOD: which engine costs
what, the weights of its progress estimate); and the energy audit: the
largest unexplained gain of any tree (as a fraction of its energy and the
work done on it; the bake warns past 2 %) and the joints broken.

    python bench/presets.py [--quality default] [--solver planar|full] [--only NAME ...]
                            [--engine pymunk|reference] [--json out/bench/presets.json]

Timings are from one run on a shared machine: compare ratios, not absolutes.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from treebake.fileio import write_text
from treebake.pipeline import bake_scene
from treebake.quality import QUALITIES
from treebake.scene import load_scene
from treebake.sim.events import BROKE, UPROOTED


def bench(path: Path, quality: str | None, solver: str = "planar", engine: str = "auto") -> dict:
    scene = load_scene(path, {"quality": quality} if quality else None)
    level = None
    if engine != "auto" and solver == "planar":
        level = dataclasses.replace(scene.quality, nonlinear=engine)
    started = time.perf_counter()
    cpu = time.process_time()
    bake = bake_scene(scene, solver=solver, quality=level)
    cpu = time.process_time() - cpu
    wall = time.perf_counter() - started
    t = bake.timing
    simulated = [tb for tb in bake.trees if not tb.static]
    steps = t.get("segment_steps", 0)
    audit = bake.meta.get("energy", {})
    worst = max(audit, key=lambda n: audit[n]["max_gain_fraction"], default=None)
    broken = sum(1 for tb in bake.trees for e in tb.info.get("events", [])
                 if e["kind"] in (BROKE, UPROOTED))
    return {
        "preset": path.stem, "quality": scene.quality.name, "trees": len(bake.trees),
        "simulated_trees": len(simulated), "segments": sum(tb.n_segments for tb in bake.trees),
        "simulated_segments": sum(tb.n_segments for tb in simulated),
        "simulated_seconds": scene.duration, "wall_seconds": round(wall, 3),
        "cpu_seconds": round(cpu, 3),
        "physics_seconds": round(t.get("step_seconds", 0) + t.get("update_seconds", 0), 3),
        "us_per_segment_step": round(1e6 * wall / steps, 3) if steps else None,
        "solver": solver, "engine": engine, "broken_joints": broken,
        "worst_gain_fraction": audit[worst]["max_gain_fraction"] if worst else 0.0,
        "worst_gain_tree": worst, "worst_gain_at_s": audit[worst]["at_s"] if worst else None,
        "engines": {e: {**v, "us_per_segment_frame": round(
            1e6 * v["cpu_seconds"] / max(v["segment_frames"], 1), 1)}
            for e, v in t.get("engines", {}).items()},
        "versions": bake.meta.get("versions", {}),
        "notes": bake.meta.get("notes", []),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quality", choices=tuple(QUALITIES))
    ap.add_argument("--solver", choices=("planar", "full"), default="planar")
    ap.add_argument("--only", nargs="*", help="preset names")
    ap.add_argument("--engine", choices=["auto", "pymunk", "reference"], default="auto",
                    help="the planar LOD's nonlinear engine: auto (the engine table of "
                         "docs/physics.md), or pymunk or reference for every reason")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "presets.json"))
    args = ap.parse_args()
    rows = []
    print(f"{'preset':<11} {'trees':>5} {'sim':>4} {'segments':>8} {'sim s':>6} {'wall s':>7} "
          f"{'cpu s':>7} {'us/seg-step':>11} {'broken':>6} {'worst gain':>10}  tree  "
          f"engines: us per segment-frame")
    for path in sorted((ROOT / "presets").glob("*.toml")):
        if args.only and path.stem not in args.only:
            continue
        r = bench(path, args.quality, args.solver, args.engine)
        rows.append(r)
        us = f"{r['us_per_segment_step']:.3f}" if r["us_per_segment_step"] else "-"
        print(f"{r['preset']:<11} {r['trees']:>5} {r['simulated_trees']:>4} {r['segments']:>8} "
              f"{r['simulated_seconds']:>6.1f} {r['wall_seconds']:>7.2f} {r['cpu_seconds']:>7.2f} "
              f"{us:>11} "
              f"{r['broken_joints']:>6} {r['worst_gain_fraction']:>10.2%}  {r['worst_gain_tree']}  "
              + ", ".join(f"{e} {v['us_per_segment_frame']:g}" for e, v in r["engines"].items()),
              flush=True)
    write_text(args.json, json.dumps(rows, indent=2) + "\n")
    print(f"written {args.json}")


if __name__ == "__main__":
    main()
