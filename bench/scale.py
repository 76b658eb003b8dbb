"""Film-scale shots: the forest preset's three species at its density
(a square grown with the count), a strong breeze, 10 s at 24 fps, every
tree simulated, baked and then exported, each as its own `treebake`
command, as a user runs them.

For each count and step (bake, then each export format): wall time, CPU
time of the command and every process it started (reaped children
included), the peak of the summed RSS of the command's whole process tree
(sampled every 0.05 s from /proc), and the size of what it wrote. Cost per
tree beside each, so flat scaling reads as a flat column. For USD, the
seconds a fresh process takes to open the root stage with its payloads
unloaded (`root_open_s` in the JSON).

    python bench/scale.py [--counts 250 1000 2500 5000 10000] [--formats usd glb]
                          [--workers 2] [--treebake PATH] [--json out/bench/scale.json]

`--treebake` runs another install's CLI (an older commit's venv) on the
same scenes, for before/after tables from one run on one machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ("conifer", "broadleaf", "birch")
DENSITY = 250 / (160.0 * 160.0)  # trees per m^2: the forest preset's


def scene_text(count: int, duration: float) -> str:
    """The scene file of `count` forest trees at the preset's density."""
    side = math.sqrt(count / DENSITY)
    grammars = ", ".join(f'"{ROOT / "grammars" / "forest" / f"{g}.lsys"}"' for g in SPECIES)
    return (f'name = "forest{count}"\nduration = {duration}\nfps = 24.0\nseed = 3\n\n'
            '[wind]\nbeaufort = "strong breeze"\ndirection = 30.0\nturbulence = 0.3\n'
            'length_scale = 60.0\n\n'
            f'[forest]\ngrammars = [{grammars}]\ncount = {count}\n'
            f'area = [{side:.3f}, {side:.3f}]\nmin_spacing = 6.0\n')


def tree_rss(pid: int) -> int:
    """Summed RSS (B) of `pid` and all its descendants now."""
    children: dict[int, list[int]] = {}
    rss: dict[int, int] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                fields = f.read().rsplit(b")", 1)[1].split()
            ppid, pages = int(fields[1]), int(fields[21])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(entry))
        rss[int(entry)] = pages * os.sysconf("SC_PAGE_SIZE")
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        total += rss.get(p, 0)
        todo += children.get(p, [])
    return total


def run(cmd: list[str], cwd: Path) -> dict:
    """Run `cmd`; its wall, CPU (with reaped children) and peak summed RSS."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    peak = 0
    while True:
        peak = max(peak, tree_rss(proc.pid))
        done, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if done:
            break
        time.sleep(0.05)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    out, err = proc.stdout.read().decode(), proc.stderr.read().decode()
    if proc.returncode:
        raise RuntimeError(f"{' '.join(cmd)}: exit {proc.returncode}\n{err[-3000:]}")
    return {"wall_s": round(wall, 2), "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
            "peak_rss_mb": round(peak / 2**20, 1), "stdout": out}


def size_of(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def measure(treebake: str, count: int, formats: list[str], workers: int, duration: float,
            work: Path) -> list[dict]:
    """Bake `count` trees, then export each format from the bake."""
    scene = work / f"forest{count}.toml"
    scene.write_text(scene_text(count, duration))
    out = work / "out"
    rows = []
    r = run([treebake, "bake", str(scene), "--out", str(out), "--workers", str(workers), "-q"],
            work)
    bake = out / f"forest{count}" / f"forest{count}.npz"
    rows.append({"trees": count, "step": "bake", **_row(r, count, size_of(bake))})
    for fmt in formats:
        dest = work / f"export-{fmt}"
        r = run([treebake, "export", str(bake), "--out", str(dest), "--format", fmt, "-q"], work)
        rows.append({"trees": count, "step": f"export {fmt}",
                     **_row(r, count, size_of(dest) - _textures(dest))})
        if fmt == "usd":
            rows[-1]["root_open_s"] = open_unloaded(dest / f"forest{count}" / f"forest{count}.usd")
        shutil.rmtree(dest)
    shutil.rmtree(out)
    return rows


def open_unloaded(path: Path) -> float:
    """Seconds to open a USD stage with its payloads unloaded, as a DCC
    first opens a shot (in a fresh process: no layer cached)."""
    code = ("import sys, time; from pxr import Usd; t = time.perf_counter(); "
            "Usd.Stage.Open(sys.argv[1], Usd.Stage.LoadNone); print(time.perf_counter() - t)")
    done = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                          text=True, check=True)
    return round(float(done.stdout.strip().splitlines()[-1]), 3)


def _textures(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("textures/*") if p.is_file())


def _row(r: dict, count: int, size: int) -> dict:
    return {"wall_s": r["wall_s"], "cpu_s": r["cpu_s"], "peak_rss_mb": r["peak_rss_mb"],
            "size_mb": round(size / 2**20, 1),
            "wall_ms_per_tree": round(1e3 * r["wall_s"] / count, 2),
            "cpu_ms_per_tree": round(1e3 * r["cpu_s"] / count, 2)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", type=int, nargs="*", default=[250, 1000, 2500, 5000, 10000])
    ap.add_argument("--formats", nargs="*", default=["usd", "glb"])
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--treebake", default=shutil.which("treebake") or "treebake",
                    help="the treebake command to measure (default: the one on PATH)")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "scale.json"))
    args = ap.parse_args()
    rows = []
    print(f"{'trees':>6} {'step':<11} {'wall s':>8} {'cpu s':>8} {'peak MB':>8} {'size MB':>8} "
          f"{'wall ms/tree':>12} {'cpu ms/tree':>11}", flush=True)
    with tempfile.TemporaryDirectory(prefix="treebake-scale-") as tmp:
        for count in args.counts:
            for row in measure(args.treebake, count, args.formats, args.workers, args.duration,
                               Path(tmp)):
                rows.append(row)
                print(f"{row['trees']:>6} {row['step']:<11} {row['wall_s']:>8.1f} "
                      f"{row['cpu_s']:>8.1f} {row['peak_rss_mb']:>8.0f} {row['size_mb']:>8.1f} "
                      f"{row['wall_ms_per_tree']:>12.1f} {row['cpu_ms_per_tree']:>11.1f}",
                      flush=True)
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"treebake": args.treebake, "workers": args.workers,
                               "duration_s": args.duration, "rows": rows}, indent=2) + "\n")
    print(f"written {out}")


if __name__ == "__main__":
    sys.exit(main())
