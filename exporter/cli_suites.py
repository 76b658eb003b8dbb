"""`treebake accuracy` and `stability`: the LOD against the reference, and
the stress suite."""

from __future__ import annotations

import json
import sys
import time
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
    from .cli_progress import CaseDisplay
    from .stress import cpu_seconds, stability
    from .stress_cases import cases
    from .stress_plan import quick_cases

    grammar = None
    if args.grammar:
        from .library import resolve
        from .lsystem import load_grammar

        grammar = resolve(args.grammar, ("grammar",))
        load_grammar(grammar)  # a missing or broken grammar fails here, before any run
    names = [c.name for c in cases(True, grammar)]
    quick = quick_cases(grammar) if args.quick else names
    for n in args.case or []:
        if n not in names:
            raise InputError(f"unknown case {n!r} (choose from {', '.join(sorted(names))})")
        if n not in quick:
            raise InputError(f"case {n!r} is not in --quick's plan (its cases: "
                             f"{', '.join(quick)}); leave out --quick to run it")
    solvers = ("planar", "full") if args.solver == "both" else (args.solver,)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    levels = tuple(args.quality) if args.quality else None
    start, cpu = time.perf_counter(), cpu_seconds()
    results = stability(args.out, solvers=solvers, only=args.case,
                        levels=levels, log=log, engine=args.engine, quick=args.quick,
                        grammar=grammar, progress=CaseDisplay(quiet=args.quiet))
    failed = [r for r in results if not r.passed]
    if args.json:
        from dataclasses import asdict

        print(json.dumps([asdict(r) for r in results], default=str))
    else:
        print(f"{len(results) - len(failed)} of {len(results)} passed in "
              f"{time.perf_counter() - start:.0f} s ({cpu_seconds() - cpu:.0f} CPU s); "
              f"written {Path(args.out) / 'report.md'}, report.json")
    return 1 if failed else 0
