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


def load_job(path: str, args) -> "Scene":
    """A scene file, or a grammar baked alone in a default scene (a gusty
    moderate breeze unless --wind says otherwise). Command-line overrides
    are validated like the file's own keys."""
    from .scene import load_scene, parse_scene

    p = Path(path)
    overrides = {k: v for k, v in (("duration", args.duration), ("fps", args.fps),
                                   ("seed", args.seed), ("quality", args.quality),
                                   ("wind.speed", args.wind)) if v is not None}
    if p.suffix != ".lsys":
        return load_scene(p, overrides)
    if not p.is_file():
        raise InputError(f"{p}: grammar file not found")
    raw = {"name": p.stem, "tree": [{"grammar": str(p.resolve())}],
           "wind": {"speed": overrides.pop("wind.speed", 6.7), "turbulence": 0.25}}
    raw.update(overrides)
    return parse_scene(raw, file=str(p))


def cmd_bake(args) -> int:
    from .bake import save_bake
    from .pipeline import bake_scene

    scene = load_job(args.job, args)
    out = Path(args.out) / (args.name or scene.name)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    progress = None if args.quiet else _progress_bar("simulating")
    bake = bake_scene(scene, solver=args.solver, log=log, progress=progress)
    path = save_bake(bake, out / f"{out.name}.npz")
    t = bake.timing
    summary = {"bake": str(path), "trees": len(bake.trees),
               "simulated": sum(1 for tb in bake.trees if not tb.static),
               "segments": sum(tb.n_segments for tb in bake.trees),
               "frames": len(bake.times), "notes": bake.meta.get("notes", []),
               "wall_seconds": t.get("wall_seconds")}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"baked {summary['trees']} trees ({summary['simulated']} simulated, "
              f"{summary['segments']} segments), {summary['frames']} frames in "
              f"{summary['wall_seconds']:.1f} s -> {path}")
    return 0


def _progress_bar(label: str):
    """A one-line progress display on stderr (only when it is a terminal)."""
    if not sys.stderr.isatty():
        return None
    start = time.perf_counter()

    def show(done: int, total: int) -> None:
        width = 30
        filled = int(width * done / max(total, 1))
        elapsed = time.perf_counter() - start
        eta = elapsed / max(done, 1) * (total - done)
        sys.stderr.write(f"\r{label} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{done}/{total} frames, {eta:4.0f} s left ")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


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

    p = sub.add_parser("bake", help="simulate a scene (or a grammar) and bake the motion",
                       description="Grow, rig and simulate the trees of a scene file (TOML, "
                                   "docs/scenes.md), or one grammar in a gusty breeze, and "
                                   "write the bake (.npz, docs/formats.md) into OUT/<name>/.")
    p.add_argument("job", help="scene file (.toml) or grammar (.lsys)")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--name", help="job name: the output subfolder (default: the scene's name)")
    p.add_argument("--solver", choices=("planar", "full"), default="planar",
                   help="planar: the fast pymunk LOD (default); full: the MuJoCo reference")
    p.add_argument("--quality", choices=("draft", "default", "final"),
                   help="override the scene's quality level")
    p.add_argument("--duration", type=float, help="override the duration, s")
    p.add_argument("--fps", type=float, help="override the frame rate, frames/s")
    p.add_argument("--seed", type=int, help="override the seed")
    p.add_argument("--wind", type=float, help="wind speed at 10 m, m/s (grammar jobs: "
                                               "default 6.7)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or notes on stderr")
    p.set_defaults(func=cmd_bake)

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
