"""Wall time of a batch of bakes with one worker process and with several.

24 jobs (6 species x 2 scenes' forces x 2 seeds, 4 s at 24 fps, default
quality, each exported to glb) run with `--jobs 1` and then `--jobs N`
(default: the machine's cores) into fresh folders; the outputs must be
byte-identical. Prints both wall times and their ratio and writes
OUT/batch.json.

    python bench/batch.py [--jobs 2] [--duration 4] [--out out/bench]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ("oak", "spruce", "willow", "palm", "bamboo", "sapling")
SCENES = ("breeze", "gale")


def job_file(folder: Path, duration: float) -> Path:
    grammars = ", ".join(f'"{ROOT / "grammars" / f"{s}.lsys"}"' for s in SPECIES)
    scenes = ", ".join(f'"{ROOT / "presets" / f"{s}.toml"}"' for s in SCENES)
    text = (f'[defaults]\nquality = "default"\nformats = ["glb"]\nduration = {duration}\n\n'
            f"[[product]]\ngrammars = [{grammars}]\nscenes = [{scenes}]\nseeds = [1, 2]\n")
    path = folder / "jobs.toml"
    path.write_text(text)
    return path


def run(jobs_toml: Path, out: Path, jobs: int) -> float:
    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "treebake.cli", "batch", str(jobs_toml), "--out",
                    str(out), "--jobs", str(jobs)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def same_outputs(a: Path, b: Path) -> bool:
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file()
                   and p.name != "batch-summary.json")
    return files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file()
                           and p.name != "batch-summary.json") and all(
        filecmp.cmp(a / f, b / f, shallow=False) for f in files)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--out", default=str(ROOT / "out" / "bench"))
    args = ap.parse_args()
    out = Path(args.out)
    work = out / "batch"
    work.mkdir(parents=True, exist_ok=True)
    jobs_toml = job_file(work, args.duration)
    serial = run(jobs_toml, work / "jobs1", 1)
    parallel = run(jobs_toml, work / f"jobs{args.jobs}", args.jobs)
    done = json.loads((work / "jobs1" / "batch-summary.json").read_text())
    n = done["jobs"]
    if done["done"] != n:
        print(f"{n - done['done']} jobs did not finish: see {work / 'jobs1'}", file=sys.stderr)
        return 1
    identical = same_outputs(work / "jobs1", work / f"jobs{args.jobs}")
    result = {"jobs": n, "duration": args.duration, "workers": args.jobs,
              "wall_jobs1_s": round(serial, 2), f"wall_jobs{args.jobs}_s": round(parallel, 2),
              "speed_up": round(serial / parallel, 3), "identical_outputs": identical}
    print(f"{n} jobs: --jobs 1 {serial:.1f} s, --jobs {args.jobs} {parallel:.1f} s, "
          f"speed-up {serial / parallel:.2f}x; outputs identical: {identical}")
    (out / "batch.json").write_text(json.dumps(result, indent=2) + "\n")
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
