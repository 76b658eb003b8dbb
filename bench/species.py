"""Species check of every bundled species (treebake.species): the largest
own-weight margin and its joint, the mean wind (at 10 m, gust factor 2
included) at which the first limb (> 2 cm) and the first twig break, and
the largest bend / cone and bone turn at the top of Beaufort 6. Static, no
simulation: seconds. The rules are in docs/physics-sources.md section 8.

    python bench/species.py [--json out/bench/species.json] [SPECIES ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from treebake import species  # noqa: E402
from treebake.fileio import write_text  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("species", nargs="*", help="bundled names or .lsys files (default: all)")
    ap.add_argument("--json", default=str(ROOT / "out" / "bench" / "species.json"))
    args = ap.parse_args()
    names = args.species or species.bundled()
    checks, rows = [], []
    t0 = time.perf_counter()
    for name in names:
        c = species.check(name)
        checks.append(c)
        rows.append(c.as_dict())
    print(species.format_table(checks))
    print(f"limb: first joint > {species.LIMB * 100:.0f} cm to break (rule: not below "
          f"{species.NEAR_GALE} m/s); twig: first joint <= {species.LIMB * 100:.0f} cm "
          f"(Beaufort 8 = {species.GALE} m/s); bend: angle / cone, turn: rad, at "
          f"{species.STRONG_BREEZE} m/s; gust factor {species.GUST} on the drag "
          f"({time.perf_counter() - t0:.1f} s)")
    for c in checks:
        for problem in c.problems():
            print(f"FAIL {c.name}: {problem}")
    meta = {"gust_factor": species.GUST, "static_margin_max": species.STATIC_MARGIN,
            "limb_diameter_m": species.LIMB, "limb_break_min_m_s": species.NEAR_GALE,
            "something_breaks_by_m_s": species.HURRICANE,
            "bend_fraction_max": species.BEND_FRACTION, "bend_wind_m_s": species.STRONG_BREEZE}
    write_text(args.json, json.dumps({"rules": meta, "species": rows}, indent=2) + "\n")
    print(f"written {args.json}")
    return 0 if all(c.passes for c in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
