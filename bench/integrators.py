"""Which implicit rule for the linear tier: error per unit of cost.

Newmark's average acceleration (the trapezoidal rule: second order, no
numerical damping) against backward Euler (Newmark with gamma = 1, beta =
1/2: first order, damping a mode of frequency w by about w h / 2 per unit
time) at 24, 48 and 96 steps per second, on production jobs (bench/
production.py's, without breaking), errors of every segment's end against
the every-segment reference at 1/2000 s. (Exact modal integration is left
out: the limbs' damping is not proportional, so it needs a complex
eigendecomposition of the whole tree, O(n^3) per tree and per topology
change; the trapezoidal rule's period error at 24 Hz on a 0.5 Hz sway is
(omega h)^2 / 12 = 0.07 %.)

    python bench/integrators.py [--jobs spruce oak] [--out out/bench]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

RULES = {"trapezoidal": (0.25, 0.5), "backward Euler": (0.5, 1.0)}


def main() -> None:
    import treebake.sim.linear as linear
    from production import job_scene, tree_errors
    from treebake.pipeline import bake_scene
    from treebake.quality import QUALITIES

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--jobs", nargs="*", default=["spruce", "oak"])
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for job in args.jobs:
            scene = job_scene(job, Path(tmp))
            truth = bake_scene(scene, solver="full", quality=QUALITIES["final"],
                               timestep=1 / 2000)
            for rule, (beta, gamma) in RULES.items():
                linear.BETA, linear.GAMMA = beta, gamma
                for rate in (24.0, 48.0, 96.0):
                    q = replace(QUALITIES["default"], linear_rate=rate, name="custom")
                    cpu = time.process_time()
                    bake = bake_scene(scene, quality=q)
                    cpu = time.process_time() - cpu
                    rms, _ = tree_errors(bake, truth)
                    t = bake.timing
                    solver = t["step_seconds"] + t["update_seconds"] + t["build_seconds"]
                    row = {"job": job, "rule": rule, "rate_hz": rate,
                           "rms_pct": round(float(np.median(rms)), 5),
                           "bake_cpu_s": round(cpu, 3), "solver_s": round(solver, 3)}
                    rows.append(row)
                    print(f"{job:<8} {rule:<15} {rate:>5.0f} Hz  {row['rms_pct']:.4f} % rms  "
                          f"solver {solver:.3f} s", flush=True)
    linear.BETA, linear.GAMMA = RULES["trapezoidal"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "integrators.json").write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
