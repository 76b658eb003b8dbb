"""`treebake accuracy` and `stability`: the LOD against the reference, and
the stress suite."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .errors import InputError


def cmd_accuracy(args) -> int:
    from .accuracy import SCENARIOS, SPECIES, accuracy

    for name, known, what in ((args.species, SPECIES, "species"),
                              (args.scenarios, SCENARIOS, "scenario")):
        for v in name or []:
            if v not in known:
                raise InputError(f"unknown {what} {v!r} (choose from {', '.join(known)})")
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    data = accuracy(args.out, args.species, args.scenarios, args.duration,
                    production=args.production, log=log)
    if args.json:
        print(json.dumps(data["summary"]))
    else:
        for s in data["summary"]:
            rms = s["rms_position_pct"]
            dominated = f"  dominated by {', '.join(s['dominated_by'])}" if s["dominated_by"] \
                else ""
            print(f"{s['class']:<17} {s['setting']:<31} {s['cpu_per_sim_second'] or 0:8.3f} "
                  f"cpu s/s {rms if rms is not None else float('nan'):8.4f} % rms{dominated}")
        print(f"written {Path(args.out) / 'report.md'}, report.json, plot.png")
    return 0


def cmd_stability(args) -> int:
    from .stress import cases, stability

    names = {c.name for c in cases(True)}
    for n in args.case or []:
        if n not in names:
            raise InputError(f"unknown case {n!r} (choose from {', '.join(sorted(names))})")
    solvers = ("planar", "full") if args.solver == "both" else (args.solver,)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    levels = tuple(args.quality) if args.quality else ("draft", "default", "final")
    results = stability(args.out, long=not args.quick, solvers=solvers, only=args.case,
                        levels=levels, log=log, engine=args.engine)
    failed = [r for r in results if not r.passed]
    if args.json:
        from dataclasses import asdict

        print(json.dumps([asdict(r) for r in results], default=str))
    else:
        print(f"{len(results) - len(failed)} of {len(results)} passed; "
              f"written {Path(args.out) / 'report.md'}, report.json")
    return 1 if failed else 0
