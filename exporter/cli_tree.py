"""`treebake derive`, `inspect`, `sway` and `list`: one grammar's string,
tree, sway, and the bundled grammars and presets."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .cli_bake import job_name
from .cli_grammar import warn_grammar, warn_grammar_files
from .errors import InputError, LimitError
from .fileio import atomic_path, check_writable_file, output_folder, write_text
from .library import resolve


def _derive(grammar, args):
    """derive() with the command's limits; a module-limit error names the
    option that raises it (only derive and inspect have it)."""
    from .lsystem import derive

    try:
        return derive(grammar, args.seed, args.iterations, _limits(args))
    except LimitError as exc:
        if "modules" not in str(exc):
            raise
        raise LimitError(f"{exc}, or raise --max-modules") from None


def _limits(args):
    from .lsystem import Limits

    if args.max_modules is None:
        return Limits()
    if args.max_modules < 1:
        raise InputError(f"--max-modules must be >= 1, got {args.max_modules}")
    return Limits(max_modules=args.max_modules)


def cmd_derive(args) -> int:
    from .lsystem import format_modules, load_grammar

    if args.output:
        check_writable_file(args.output)
    grammar = load_grammar(resolve(args.grammar, ("grammar",)))
    warn_grammar(grammar, args.strict)
    d = _derive(grammar, args)
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
    lo, hi = model.drawn_bounds()
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
        "twigs": len(model.twigs),  # drawn only (`@twig`): not simulated
        "height_m": round(model.height, 4),
        "dbh_m": round(model.dbh(), 4),
        "wood_mass_kg": round(model.wood_mass(), 3),
        "bounds_m": [[round(float(v), 4) for v in lo], [round(float(v), 4) for v in hi]],
        "derive_seconds": round(derivation.seconds, 4),
    }


def cmd_inspect(args) -> int:
    from .lsystem import load_grammar
    from .preview import model_preview
    from .turtle import interpret

    if not 64 <= args.size <= 2048:
        raise InputError(f"--size must be in 64..2048 px, got {args.size}")
    path = resolve(args.grammar, ("grammar",))
    grammar = load_grammar(path)
    warn_grammar(grammar, args.strict)
    # the folder `treebake bake` writes for this grammar: its file name, not
    # the free-text `name:` inside it
    # (removed again if it is new and the derivation fails: no empty folder)
    with output_folder(Path(args.out) / job_name(args.name or path.stem)) as out:
        d = _derive(grammar, args)
        model = interpret(d.modules, grammar, seed=d.seed)
        summary = inspect_summary(model, d)
        write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
        image = model_preview(model, size=args.size)
        with atomic_path(out / "preview.png") as tmp:
            image.save(tmp, format="PNG")
    if args.json:
        print(json.dumps(summary))
    else:
        for k, v in summary.items():
            print(f"{k:>16}: {v}")
        print(f"{'written':>16}: {out / 'summary.json'}, {out / 'preview.png'}")
    return 0


def cmd_sway(args) -> int:
    from .cli_progress import progress_bar
    from .sway import pull_release

    path = resolve(args.grammar, ("grammar",))
    warn_grammar_files([path], args.strict)
    # as `treebake bake`: a bar on a terminal, else a plain line every few
    # seconds and one at the end; notes on stderr; -q for neither
    log = None if args.quiet else (lambda m: print(m, file=sys.stderr))
    progress = None if args.quiet else progress_bar("simulating")
    r = pull_release(path, seed=args.seed, quality=args.quality, log=log, progress=progress)
    data = {"grammar": args.grammar, "height_m": round(r.height, 3), "dbh_m": round(r.dbh, 4),
            "frequency_hz": round(r.frequency, 4), "damping_ratio": round(r.damping, 4),
            "rayleigh_frequency_hz": round(r.rayleigh_frequency, 4), "pull_n": round(r.force, 1),
            "deflection_m": round(r.deflection, 4)}
    if args.json:
        print(json.dumps(data))
    else:
        print(f"{Path(args.grammar).stem}: H {r.height:.1f} m, DBH {r.dbh:.3f} m; pulled "
              f"{r.force:.0f} N to {r.deflection:.3f} m and released: first sway "
              f"{r.frequency:.3f} Hz (rig estimate {r.rayleigh_frequency:.3f} Hz), damping "
              f"ratio {r.damping:.3f}")
    return 0


def cmd_list(args) -> int:
    from . import library

    entries = [*library.grammars(), *library.presets()]
    entries = [e for e in entries if args.kind in (None, e.kind + "s")]
    if args.json:
        print(json.dumps([{"kind": e.kind, "name": e.name, "path": str(e.path),
                           "description": e.description} for e in entries]))
        return 0
    for kind, how in (("grammar", "treebake bake NAME"), ("preset", "treebake bake preset:NAME")):
        group = [e for e in entries if e.kind == kind]
        if group:
            print(f"{kind}s ({how}):")
            width = max(len(e.name) for e in group)
            for e in group:
                text = e.description if len(e.description) <= 72 else \
                    e.description[:71].rstrip() + "…"
                print(f"  {e.name:<{width}}  {text}")
    return 0
