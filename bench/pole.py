"""Cost of one long chain: the sway test (`treebake sway`, pull and release,
12 s at 60 fps) of a straight 2 m pole, 5 cm thick, green wood (E = 8 GPa,
800 kg/m^3, damping ratio 0.01, no drag), cut into 200, 500 and 2,000 bones,
every other setting the same.

For each: CPU seconds of the `treebake sway` command (user + system, as the
reaped child's: other work on a shared machine changes wall time, not
this), per bone and per bone and frame, and the measured first frequency
against Euler-Bernoulli's cantilever, f1 = 1.8751^2 / (2 pi) sqrt(E I /
(rho A L^4)) (no gravity: the pole's own weight lowers it by about 0.3 %).
Flat CPU per bone means the linear tier's step is linear in a chain's
length.

    python bench/pole.py [--bones 200 500 2000] [--quality default]
                         [--treebake PATH] [--json out/bench/pole.json]

`--treebake` runs another install's CLI (an older commit's venv) on the
same grammars, for before/after tables from one run on one machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LENGTH, DIAMETER, MODULUS, DENSITY = 2.0, 0.05, 8.0e9, 800.0  # m, m, Pa, kg/m^3
PER_STEP = 10  # segments a rewriting step adds (iterations are capped at 1,000)
FRAMES = 12 * 60  # the sway test's 12 s at 60 fps


def grammar_text(bones: int) -> str:
    """The pole in `bones` equal segments (one bone each at every quality:
    none merges segments), `PER_STEP` per rewriting step."""
    if bones % PER_STEP:
        raise SystemExit(f"--bones: {bones} is not a multiple of {PER_STEP}")
    steps = bones // PER_STEP
    segment = f"F({LENGTH / PER_STEP}/{steps})"
    return (f"density: {DENSITY}\nmodulus: {MODULUS}\ndamping: 0.01\ndrag: 0\nleaf drag: 0\n"
            f"iterations: {steps}\naxiom: !({DIAMETER})A({steps})\n"
            f"A(n) : n > 0 -> {segment * PER_STEP}A(n-1)\n")


def beam_f1() -> float:
    """First bending frequency (Hz) of the uniform cantilever, no gravity."""
    ei = MODULUS * math.pi * DIAMETER**4 / 64
    mass_per_length = DENSITY * math.pi * DIAMETER**2 / 4
    return 1.8751041**2 / (2 * math.pi) * math.sqrt(ei / (mass_per_length * LENGTH**4))


def run_sway(treebake: str, grammar: Path, quality: str) -> tuple[dict, float]:
    """The command's JSON result and its CPU seconds (user + system)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([treebake, "sway", str(grammar), "--quality", quality, "--json", "-q"],
                          capture_output=True, text=True, check=False)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{treebake} sway {grammar}: exit {done.returncode}\n{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads(done.stdout), cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bones", type=int, nargs="+", default=[200, 500, 2000])
    ap.add_argument("--quality", default="default")
    ap.add_argument("--treebake", default=shutil.which("treebake", path=os.path.dirname(
        sys.executable)) or "treebake", help="the treebake command to time")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "pole.json"))
    args = ap.parse_args()
    f_beam = beam_f1()
    rows = []
    print(f"{args.treebake} sway, quality {args.quality}; beam theory f1 = {f_beam:.4f} Hz")
    print(f"{'bones':>6} {'CPU s':>8} {'ms/bone':>8} {'us/bone/frame':>14} {'f1 Hz':>7} "
          f"{'f1 error':>9} {'zeta':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for bones in args.bones:
            grammar = Path(tmp) / f"pole{bones}.lsys"
            grammar.write_text(grammar_text(bones))
            result, cpu = run_sway(args.treebake, grammar, args.quality)
            f1 = result["frequency_hz"]
            row = {"bones": bones, "cpu_s": cpu, "cpu_s_per_bone": cpu / bones,
                   "cpu_s_per_bone_frame": cpu / (bones * FRAMES), "f1_hz": f1,
                   "beam_f1_hz": f_beam, "f1_error": f1 / f_beam - 1,
                   "damping": result["damping_ratio"], "quality": args.quality,
                   "treebake": args.treebake}
            rows.append(row)
            print(f"{bones:>6} {cpu:>8.2f} {1e3 * cpu / bones:>8.2f} "
                  f"{1e6 * row['cpu_s_per_bone_frame']:>14.2f} {f1:>7.4f} "
                  f"{100 * row['f1_error']:>8.2f}% {row['damping']:>6.4f}", flush=True)
    if len(rows) > 1:
        first, last = rows[0], rows[-1]
        print(f"CPU per bone, {last['bones']} against {first['bones']} bones: "
              f"{last['cpu_s_per_bone'] / first['cpu_s_per_bone']:.2f}x")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"rows": rows}, indent=2) + "\n")
    print(f"written {out}")


if __name__ == "__main__":
    main()
