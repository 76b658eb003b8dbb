"""`treebake` command line. Thin: each subcommand parses options and calls
the pipeline. Exit codes: 0 ok, 1 failure, 2 bad usage or input."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import __version__
from .errors import InputError, TreebakeError
from .fileio import write_text


def _add_grammar_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("grammar", help="grammar file (.lsys)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: grammar's)")
    p.add_argument("--iterations", "-n", type=int, default=None,
                   help="derivation steps (default: grammar's)")
    p.add_argument("--max-modules", type=int, default=None,
                   help="cap on the derived string length (default 2,000,000)")


def _limits(args):
    from .lsystem import Limits

    if args.max_modules is None:
        return Limits()
    if args.max_modules < 1:
        raise InputError(f"--max-modules must be >= 1, got {args.max_modules}")
    return Limits(max_modules=args.max_modules)


def cmd_derive(args) -> int:
    from .lsystem import derive, format_modules, load_grammar

    grammar = load_grammar(args.grammar)
    d = derive(grammar, args.seed, args.iterations, _limits(args))
    text = format_modules(d.modules)
    if args.output:
        write_text(args.output, text + "\n")
    elif not args.stats_only:
        sys.stdout.write(text + "\n")
    counts = {}
    for sym, _ in d.modules:
        counts[sym] = counts.get(sym, 0) + 1
    stats = {"grammar": grammar.name, "seed": d.seed, "iterations": d.iterations,
             "modules": len(d.modules), "per_iteration": d.counts,
             "symbols": dict(sorted(counts.items())), "seconds": round(d.seconds, 4),
             "modules_per_second": round(d.modules_per_second)}
    print(json.dumps(stats) if args.json else
          f"{grammar.name}: {len(d.modules)} modules after {d.iterations} iterations "
          f"(seed {d.seed}) in {d.seconds:.3f} s, {d.modules_per_second:,.0f} modules/s",
          file=sys.stderr)
    return 0


def inspect_summary(model, derivation) -> dict:
    lo, hi = model.bounds()
    return {
        "name": model.name,
        "grammar": model.source.get("grammar_file"),
        "grammar_hash": model.source.get("grammar_hash"),
        "seed": derivation.seed,
        "iterations": derivation.iterations,
        "modules": len(derivation.modules),
        "limbs": len(model.limbs),
        "segments": model.n_segments,
        "leafy_segments": int((model.leaf > 0).sum()),
        "height_m": round(model.height, 4),
        "dbh_m": round(model.dbh(), 4),
        "wood_mass_kg": round(model.wood_mass(), 3),
        "bounds_m": [[round(float(v), 4) for v in lo], [round(float(v), 4) for v in hi]],
        "derive_seconds": round(derivation.seconds, 4),
    }


def cmd_inspect(args) -> int:
    from .lsystem import derive, load_grammar
    from .preview import model_preview
    from .turtle import interpret

    grammar = load_grammar(args.grammar)
    d = derive(grammar, args.seed, args.iterations, _limits(args))
    model = interpret(d.modules, grammar, seed=d.seed)
    summary = inspect_summary(model, d)
    out = Path(args.out) / grammar.name
    write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    image = model_preview(model, size=args.size)
    from .fileio import atomic_path

    with atomic_path(out / "preview.png") as tmp:
        image.save(tmp, format="PNG")
    if args.json:
        print(json.dumps(summary))
    else:
        for k, v in summary.items():
            print(f"{k:>16}: {v}")
        print(f"{'written':>16}: {out / 'summary.json'}, {out / 'preview.png'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="treebake",
        description="Grow trees from L-systems, simulate them, bake the motion to files.")
    parser.add_argument("--version", action="version", version=f"treebake {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("derive", help="derive a grammar and print the module string",
                       description="Derive a grammar; print the module string to stdout and "
                                   "statistics to stderr.")
    _add_grammar_options(p)
    p.add_argument("-o", "--output", help="write the string to this file instead of stdout")
    p.add_argument("--stats-only", action="store_true", help="print only the statistics")
    p.add_argument("--json", action="store_true", help="statistics as JSON")
    p.set_defaults(func=cmd_derive)

    p = sub.add_parser("inspect", help="tree statistics and a PNG preview",
                       description="Derive and interpret a grammar; print limb and segment "
                                   "counts, height, mass and bounds; write summary.json and "
                                   "preview.png (front and side) into OUT/<name>/.")
    _add_grammar_options(p)
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--size", type=int, default=512, help="preview panel size in pixels")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=cmd_inspect)

    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    start = time.perf_counter()
    try:
        code = args.func(args)
    except TreebakeError as exc:
        print(f"treebake: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("treebake: interrupted", file=sys.stderr)
        return 130
    if getattr(args, "verbose", False):
        print(f"done in {time.perf_counter() - start:.2f} s", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
