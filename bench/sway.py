"""Pull-and-release test of every species: first sway frequency and damping
ratio measured in the simulator, next to the rig's Rayleigh estimate and the
sanity bands of docs/physics-sources.md.

    python bench/sway.py [--quality default] [--json out/bench/sway.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_physics_realism import ESTIMATE_BANDS, FIELD_BANDS, INTACT_CROWN_DAMPING
from treebake.fileio import write_text
from treebake.sway import pull_release


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quality", default="default")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "sway.json"))
    args = ap.parse_args()
    rows = []
    print(f"{'species':<16} {'H m':>5} {'DBH m':>6} {'f1 Hz':>6} {'band':>11} {'Rayleigh':>8} "
          f"{'zeta':>5} {'band':>10} {'s':>5}")
    bands = {**FIELD_BANDS, **ESTIMATE_BANDS}
    z_lo, z_hi = INTACT_CROWN_DAMPING
    for species, (f_lo, f_hi) in sorted(bands.items()):
        t0 = time.perf_counter()
        r = pull_release(ROOT / "grammars" / f"{species}.lsys", quality=args.quality)
        row = {"species": species, "height_m": r.height, "dbh_m": r.dbh,
               "frequency_hz": r.frequency, "band_hz": [f_lo, f_hi],
               "rayleigh_hz": r.rayleigh_frequency, "damping": r.damping,
               "damping_band": [z_lo, z_hi], "seconds": time.perf_counter() - t0}
        rows.append(row)
        print(f"{species:<16} {r.height:>5.1f} {r.dbh:>6.3f} {r.frequency:>6.3f} "
              f"{f_lo:>5.2f}-{f_hi:<5.2f} {r.rayleigh_frequency:>8.3f} {r.damping:>5.3f} "
              f"{z_lo:>4.2f}-{z_hi:<4.2f} {row['seconds']:>5.1f}", flush=True)
    write_text(args.json, json.dumps(rows, indent=2) + "\n")
    print(f"written {args.json}")


if __name__ == "__main__":
    main()
