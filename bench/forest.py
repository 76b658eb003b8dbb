"""The thesis' forest experiment on our tools.

Forests of 0, 50, ..., 250 trees (the three forest species, 22-34 segments,
~28 on average, scattered with a minimum spacing over a fixed 160 m x 160 m),
a strong breeze with gusts (nothing sleeps), 10 simulated seconds at 24 fps,
a camera walking into the forest, turning a full circle and out the far
side. Each count runs with each setting, each in its own process (so peak
memory is that run's):

- `lod-culled`: the planar LOD at default quality with all culling (trees
  the camera never sees are static, far ones at draft quality) and the
  machine's cores as workers: what a user gets (its peak memory is the main
  process's; each worker holds a chunk);
- `lod`: the planar LOD, no culling, one process: the pure cost;
- `reference`: the full 3D reference (MuJoCo), no culling, at its cheapest
  step that is still accurate (below).

First a calibration on 50 trees, 4 s, grammars without breaking (a break is
a branching event; errors would measure chaos): the truth (the reference,
one bone per segment, 1/2000 s) against the reference at 1/120, 1/240 and
1/480 s and the LOD, errors of every segment's end as % of tree height
(median over trees); the reference's step for the scaling runs is the
cheapest whose median RMS stays within 0.05 % of height. Error sits next to
cost in the tables.

For each run: physics time per frame and per substep (mean, p95),
microseconds per segment-step equivalent at 960 Hz (physics time /
simulated segments x 960 x simulated seconds: the same yardstick for
solvers with different steps), wall time of the whole bake including the
export to glb, peak memory. Ratios LOD/reference come from the same run. A
plot of physics time per simulated second against tree count sits next to
the thesis' (PhysX 2009, one step per 1/30 s frame assumed).

    python bench/forest.py [--counts 0 50 100 150 200 250] [--duration 10]
                           [--settings lod-culled lod reference] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

SETTINGS = ("lod-culled", "lod", "reference")
THESIS = {  # trees: (ms per physics step with culling, without), PhysX on a Pentium 4
    50: (7.3, 22.7), 100: (14.9, 49.1), 250: (39.2, 127.7)}
CAMERA = {"fov": 60.0, "margin": 10.0, "far": 60.0, "far_quality": "draft", "keys": [
    {"time": 0.0, "position": [-100.0, 0.0, 2.0], "target": [0.0, 0.0, 2.0]},
    {"time": 3.0, "position": [-10.0, 0.0, 2.0], "target": [40.0, 0.0, 2.0]},
    {"time": 4.0, "position": [0.0, 0.0, 2.0], "target": [0.0, 40.0, 2.0]},
    {"time": 5.0, "position": [0.0, 0.0, 2.0], "target": [-40.0, 0.0, 2.0]},
    {"time": 6.0, "position": [0.0, 0.0, 2.0], "target": [0.0, -40.0, 2.0]},
    {"time": 7.0, "position": [10.0, 0.0, 2.0], "target": [40.0, 0.0, 2.0]},
    {"time": 10.0, "position": [100.0, 0.0, 2.0], "target": [200.0, 0.0, 2.0]}]}


def forest_scene(count: int, duration: float, culled: bool) -> dict:
    grammars = [str(ROOT / "grammars" / "forest" / f"{g}.lsys")
                for g in ("conifer", "broadleaf", "birch")]
    raw = {"name": f"forest{count}", "duration": duration, "fps": 24.0, "seed": 3,
           "wind": {"beaufort": "strong breeze", "direction": 30.0, "turbulence": 0.3,
                    "length_scale": 60.0}}
    if count:
        raw["forest"] = {"grammars": grammars, "count": count, "area": [160.0, 160.0],
                         "min_spacing": 6.0}
    else:  # an empty forest: one far-away tree the wind never reaches (static)
        raw["tree"] = [{"grammar": grammars[0], "position": [5000.0, 5000.0]}]
        raw.pop("wind")
    if culled:
        raw["camera"] = CAMERA
    return raw


ACCURATE_PCT = 0.05  # median RMS error (% of height) a reference step must stay within
STEPS = {"1/120": 1 / 120, "1/240": 1 / 240, "1/480": 1 / 480}


def calibrate(log=print) -> dict:
    """Errors and costs on 50 trees, 4 s, against the every-segment truth;
    the cheapest accurate reference step."""
    import tempfile

    import numpy as np

    sys.path.insert(0, str(ROOT / "bench"))
    from production import tree_errors, unbreakable
    from treebake.pipeline import bake_scene
    from treebake.quality import QUALITIES
    from treebake.scene import parse_scene

    with tempfile.TemporaryDirectory() as tmp:
        raw = forest_scene(50, 4.0, culled=False)
        raw["forest"]["grammars"] = [unbreakable(str(Path(g).relative_to(ROOT)), Path(tmp))
                                     for g in raw["forest"]["grammars"]]
        scene = parse_scene(raw, file="<forest calibration>")

        def timed(**kw):
            cpu = time.process_time()
            bake = bake_scene(scene, workers=1, **kw)
            return bake, time.process_time() - cpu

        truth, _ = timed(solver="full", quality=QUALITIES["final"], timestep=1 / 2000)
        rows = {}
        for name, kw in [("lod", {}), *[(f"reference {k}", {"solver": "full", "timestep": h})
                                        for k, h in STEPS.items()]]:
            bake, cpu = timed(**kw)
            rms, mx = tree_errors(bake, truth)
            rows[name] = {"cpu_seconds": round(cpu, 3), "rms_pct": round(float(np.median(rms)), 5),
                          "max_pct": round(float(np.median(mx)), 5)}
            log(f"calibration {name:<18} {cpu:7.2f} cpu s  {rows[name]['rms_pct']:.4f} % rms")
    ok = [k for k in STEPS if rows[f"reference {k}"]["rms_pct"] <= ACCURATE_PCT]
    step = max(ok, key=lambda k: STEPS[k]) if ok else "1/480"
    return {"rows": rows, "reference_step": step}


def run_one(count: int, setting: str, duration: float, workers: int,
            step: float = 1 / 240) -> dict:
    """Bake (and export to glb) one configuration in this process."""
    from treebake.bake_file import save_bake
    from treebake.export import ExportOptions, export_bake
    from treebake.pipeline import bake_scene
    from treebake.scene import parse_scene

    scene = parse_scene(forest_scene(count, duration, setting == "lod-culled"),
                        file=f"<forest {count}>")
    solver = "full" if setting == "reference" else "planar"
    start = time.perf_counter()
    cpu0 = time.process_time()
    bake = bake_scene(scene, solver=solver, workers=workers if setting == "lod-culled" else 1,
                      timestep=step if solver == "full" else None)
    with tempfile.TemporaryDirectory() as tmp:
        t_export = time.perf_counter()
        path = save_bake(bake, Path(tmp) / "forest.npz")
        export_bake(bake, tmp, "forest", ExportOptions(formats=("glb",)))
        export_seconds = time.perf_counter() - t_export
        digest = __import__("hashlib").sha256(path.read_bytes()).hexdigest()
    wall = time.perf_counter() - start
    t = bake.timing
    physics = sum(t.get(k, 0.0) for k in ("step_seconds", "update_seconds", "build_seconds",
                                           "compile_seconds"))
    steps = sum(tb.n_segments for tb in bake.trees if not tb.static) * 960 * duration
    simulated = [tb for tb in bake.trees if not tb.static]
    return {
        "trees": count, "setting": setting, "simulated_trees": len(simulated),
        "segments": sum(tb.n_segments for tb in bake.trees),
        "simulated_segments": sum(tb.n_segments for tb in simulated),
        "physics_seconds": round(physics, 3), "cpu_seconds": round(time.process_time() - cpu0, 3),
        "frame_mean_ms": t.get("frame_mean_ms", 0.0), "frame_p95_ms": t.get("frame_p95_ms", 0.0),
        "substep_mean_ms": t.get("substep_mean_ms", 0.0),
        "substep_p95_ms": t.get("substep_p95_ms", 0.0),
        "us_per_segment_step": round(1e6 * physics / steps, 4) if steps else None,
        "physics_per_sim_second": round(physics / duration, 4),
        "export_seconds": round(export_seconds, 3), "wall_seconds": round(wall, 3),
        "grow_seconds": t.get("grow_seconds"), "bake_sha256": digest,
        "peak_memory_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "culling": bake.meta.get("culling"),
    }


def measure(count: int, setting: str, duration: float, workers: int, step: str) -> dict:
    """run_one in a fresh process (its own peak memory)."""
    cmd = [sys.executable, __file__, "--one", str(count), setting, "--duration", str(duration),
           "--workers", str(workers), "--step", step]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False, cwd=ROOT)
    if done.returncode != 0:
        raise RuntimeError(f"{setting} {count}: {done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def fit(xs: list[float], ys: list[float]) -> tuple[float, float]:
    import numpy as np

    if len(xs) < 2:
        return float("nan"), float("nan")
    slope, intercept = np.polyfit(xs, ys, 1)
    return float(slope), float(intercept)


def plot(rows: list[dict], path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for setting, style in zip(SETTINGS, ("o-", "s-", "^-")):
        rs = sorted((r for r in rows if r["setting"] == setting), key=lambda r: r["trees"])
        if rs:
            ax.plot([r["trees"] for r in rs], [r["physics_per_sim_second"] for r in rs], style,
                    label={"lod-culled": "planar LOD, culled, all cores",
                           "lod": "planar LOD, no culling, 1 core",
                           "reference": "MuJoCo reference, no culling"}[setting])
    xs = sorted(THESIS)
    ax.plot(xs, [THESIS[x][0] * 30 / 1e3 for x in xs], "k--", label="thesis, culled (PhysX)")
    ax.plot(xs, [THESIS[x][1] * 30 / 1e3 for x in xs], "k:", label="thesis, no culling")
    ax.set_xlabel("trees")
    ax.set_ylabel("physics time per simulated second, s")
    ax.set_title("forest in a strong breeze, 10 s")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120, metadata={"Software": None})
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", type=int, nargs="*", default=[0, 50, 100, 150, 200, 250])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--settings", nargs="*", default=list(SETTINGS), choices=SETTINGS)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    ap.add_argument("--step", default=None, help="the reference's step, e.g. 1/240 (default: "
                                                   "calibrated)")
    ap.add_argument("--one", nargs=2, metavar=("COUNT", "SETTING"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        num, den = args.step.split("/")
        print(json.dumps(run_one(int(args.one[0]), args.one[1], args.duration, args.workers,
                                 float(num) / float(den))))
        return
    cal = calibrate() if args.step is None else {"reference_step": args.step, "rows": {}}
    step = cal["reference_step"]
    print(f"reference step for the scaling runs: {step} s (the cheapest within "
          f"{ACCURATE_PCT} % median RMS of the truth)")
    rows = []
    head = (f"{'trees':>5} {'setting':<11} {'sim':>4} {'segs':>5} {'frame ms':>9} {'p95':>7} "
            f"{'substep ms':>10} {'p95':>7} {'us/seg-step':>11} {'wall s':>7} {'MB':>6}")
    print(head)
    for count in args.counts:
        for setting in args.settings:
            r = measure(count, setting, args.duration, args.workers, step)
            rows.append(r)
            us = f"{r['us_per_segment_step']:.3f}" if r["us_per_segment_step"] else "-"
            print(f"{count:>5} {setting:<11} {r['simulated_trees']:>4} "
                  f"{r['simulated_segments']:>5} {r['frame_mean_ms']:>9.2f} "
                  f"{r['frame_p95_ms']:>7.2f} {r['substep_mean_ms']:>10.4f} "
                  f"{r['substep_p95_ms']:>7.4f} {us:>11} {r['wall_seconds']:>7.1f} "
                  f"{r['peak_memory_mb']:>6.0f}", flush=True)
    summary = {}
    for setting in args.settings:
        rs = [r for r in rows if r["setting"] == setting and r["trees"] > 0]
        summary[setting] = dict(zip(("slope_s_per_tree", "intercept_s"), fit(
            [r["trees"] for r in rs], [r["physics_per_sim_second"] for r in rs])))
    for count in args.counts:
        by = {r["setting"]: r for r in rows if r["trees"] == count}
        if "reference" in by and count:
            for s in ("lod", "lod-culled"):
                if s in by and by[s]["physics_seconds"]:
                    by[s]["reference_over_lod_physics"] = round(
                        by["reference"]["physics_seconds"] / by[s]["physics_seconds"], 2)
                    if by[s]["us_per_segment_step"]:
                        by[s]["reference_over_lod_per_segment_step"] = round(
                            by["reference"]["us_per_segment_step"] / by[s]["us_per_segment_step"],
                            2)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "forest.json").write_text(json.dumps({"calibration": cal, "rows": rows,
                                                 "fit": summary, "thesis": THESIS},
                                                indent=2) + "\n")
    plot(rows, out / "forest.png")
    print("linear fit, physics s per simulated s = slope x trees + intercept:")
    for setting, f in summary.items():
        print(f"  {setting:<11} slope {f['slope_s_per_tree']:.4g} s/tree, "
              f"intercept {f['intercept_s']:.4g} s")
    print(f"written {out / 'forest.json'}, {out / 'forest.png'}")


if __name__ == "__main__":
    main()
