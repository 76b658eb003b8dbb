"""`treebake` command line. Thin: each subcommand parses options and calls
the pipeline. Exit codes: 0 ok, 1 failure, 2 bad usage or input."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from . import __version__
from .errors import InputError, LimitError, TreebakeError
from .fileio import check_writable, check_writable_file, write_text
from .library import resolve


def _add_grammar_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("grammar", help="grammar file (.lsys) or bundled grammar name (oak, "
                                   "forest/birch; `treebake list`)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: grammar's)")
    p.add_argument("--iterations", "-n", type=int, default=None,
                   help="derivation steps (default: grammar's)")
    p.add_argument("--max-modules", type=int, default=None,
                   help="cap on the derived string length (default 2,000,000)")


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
    from .lsystem import load_grammar
    from .preview import model_preview
    from .turtle import interpret

    if not 64 <= args.size <= 2048:
        raise InputError(f"--size must be in 64..2048 px, got {args.size}")
    grammar = load_grammar(resolve(args.grammar, ("grammar",)))
    out = check_writable(Path(args.out) / grammar.name)
    d = _derive(grammar, args)
    model = interpret(d.modules, grammar, seed=d.seed)
    summary = inspect_summary(model, d)
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


def load_job(path: str, args):
    """A scene file, or a grammar baked alone in a default scene (a gusty
    moderate breeze unless --wind says otherwise). Command-line overrides
    are validated like the file's own keys."""
    from .scene import load_job as load

    if Path(path).suffix.lower() == ".npz":
        raise InputError(f"{path} is a bake, not a scene: `treebake bake` takes a scene (.toml) "
                         f"or a grammar (.lsys); to turn a bake into files use `treebake export "
                         f"{path}` (or `treebake preview {path}`)")
    p = resolve(path)  # a file, or a bundled grammar or preset by name
    if p.suffix.lower() not in (".toml", ".lsys"):
        raise InputError(f"{p}: `treebake bake` takes a scene file (.toml), a grammar (.lsys) "
                         "or a bundled name (oak, preset:felling; `treebake list`)")
    overrides = {k: v for k, v in (("duration", args.duration), ("fps", args.fps),
                                   ("seed", args.seed), ("quality", args.quality),
                                   ("wind.speed", args.wind)) if v is not None}
    return load(p, overrides)


def _parse_timestep(text: str) -> float:
    """'1/480' or '0.002' (s) -> seconds, within 1e-5..1/60 s."""
    try:
        num, _, den = text.partition("/")
        value = float(num) / float(den) if den else float(num)
    except (ValueError, ZeroDivisionError):
        raise InputError(f"--timestep = {text!r} is not a number of seconds "
                         "(e.g. 1/480 or 0.002)") from None
    if not 1e-5 <= value <= 1 / 60:
        raise InputError(f"--timestep = {text} s is outside 1e-5 .. 1/60 s")
    return value


def _job_name(name: str) -> str:
    if not name or any(c in name for c in "/\\") or name in (".", ".."):
        raise InputError(f"job name {name!r} cannot be a folder name (--name)")
    return name


def cmd_bake(args) -> int:
    import os

    from .bake import save_bake
    from .export import check_options
    from .fileio import job_lock
    from .pipeline import bake_scene

    scene = load_job(args.job, args)
    out = Path(args.out) / _job_name(args.name or scene.name)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    progress = None if args.quiet else _progress_bar("simulating")
    workers = args.workers or os.cpu_count() or 1
    if workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    timestep = None
    if args.timestep is not None:
        if args.solver != "full":
            raise InputError("--timestep is the full reference's step: use it with --solver full "
                             "(the planar LOD's steps come from --quality)")
        timestep = _parse_timestep(args.timestep)
    if args.format is None and scene.formats:
        args.format = ",".join(f for f in scene.formats if f != "npz")
    opts = None
    if args.format is not None:  # checked now, not after the simulation
        opts = _export_options(args, allow_none=True)
        check_options(opts)
    with job_lock(out):  # proves the folder writable; one run per job folder at a time
        bake = bake_scene(scene, solver=args.solver, log=log, progress=progress,
                          workers=workers, timestep=timestep)
        path = save_bake(bake, out / f"{out.name}.npz")
        exported = None
        if opts is not None and opts.formats:
            exported = _run_export(bake, path, args.out, out.name, opts, args)
    t = bake.timing
    summary = {"bake": str(path), "trees": len(bake.trees),
               "simulated": sum(1 for tb in bake.trees if not tb.static),
               "segments": sum(tb.n_segments for tb in bake.trees),
               "frames": len(bake.times), "notes": bake.meta.get("notes", []),
               "wall_seconds": t.get("wall_seconds")}
    if exported is not None:
        summary["export"] = _export_summary(exported)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"baked {_plural(summary['trees'], 'tree')} ({summary['simulated']} simulated, "
              f"{_plural(summary['segments'], 'segment')}), {_plural(summary['frames'], 'frame')}"
              f" in {summary['wall_seconds']:.1f} s -> {path}")
        if exported is not None:
            _print_export(exported)
    return 0


PLAIN_PROGRESS_SECONDS = 5.0  # without a terminal: a plain progress line this often


def _plain_interval() -> float:
    """Seconds between plain progress lines (TREEBAKE_PROGRESS_SECONDS overrides)."""
    import os

    try:
        return max(0.0, float(os.environ.get("TREEBAKE_PROGRESS_SECONDS", "")))
    except ValueError:
        return PLAIN_PROGRESS_SECONDS


def _progress_bar(label: str):
    """Progress on stderr: a redrawn bar on a terminal; elsewhere (logs, CI,
    `| tee`) a plain line every few seconds and one at the end."""
    start = time.perf_counter()
    tty = sys.stderr.isatty()
    last = [start]

    def show(done: int, total: int) -> None:
        elapsed = time.perf_counter() - start
        eta = elapsed / max(done, 1) * (total - done)
        if not tty:
            if done >= total:
                sys.stderr.write(f"{label}: {done}/{total} frames, done in {elapsed:.1f} s\n")
            elif time.perf_counter() - last[0] >= _plain_interval():
                last[0] = time.perf_counter()
                sys.stderr.write(f"{label}: {done}/{total} frames "
                                 f"({100 * done / max(total, 1):.0f} %), {eta:.0f} s left\n")
            else:
                return
            sys.stderr.flush()
            return
        width = 30
        filled = int(width * done / max(total, 1))
        sys.stderr.write(f"\r{label} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{done}/{total} frames, {eta:4.0f} s left ")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def _add_export_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("export options")
    g.add_argument("--split", action="store_true", help="glTF: one file per tree")
    g.add_argument("--no-leaves", action="store_true", help="no leaf quads")
    g.add_argument("--no-textures", action="store_true",
                   help="plain colour materials instead of the generated bark and leaf textures")
    g.add_argument("--radial", type=int, default=8,
                   help="vertices around a bark ring, 3-64 (default 8)")
    g.add_argument("--rings", type=int, default=1, help="bark rings per segment, 1-16 (default 1)")
    g.add_argument("--position-tolerance", type=float, default=0.002,
                   help="keyframe reduction: worst joint/tip position error, m (default 0.002)")
    g.add_argument("--angle-tolerance", type=float, default=0.25,
                   help="keyframe reduction: worst joint rotation error, degrees (default 0.25)")
    g.add_argument("--no-reduce", action="store_true",
                   help="keep every frame of every channel that changes")
    g.add_argument("--stride", type=int, default=1,
                   help="OBJ sequences: every n-th frame (default 1)")
    g.add_argument("--size", type=int, default=256, help="preview panel size, px (default 256)")
    g.add_argument("--frame-start", type=int, default=None,
                   help="number of the first frame in every format (default: the scene's "
                        "frame_start, 1)")


def _export_options(args, allow_none: bool = False):
    """ExportOptions from the command line; an empty --format is an error
    (it used to export glb silently); allow_none: `npz` alone is fine
    (bake: the bake is all that is wanted)."""
    import math

    from .exchange.anim import ReduceOptions
    from .exchange.mesh import MeshOptions
    from .export import FORMATS, ExportOptions, parse_formats

    text = getattr(args, "format", None)
    formats = parse_formats(text if text is not None else "glb")
    if not formats and not (allow_none and text and text.strip(" ,").lower() == "npz"):
        raise InputError(f"--format {text!r} names no export format; choose from: "
                         f"{', '.join(FORMATS)} (comma-separated)")
    return ExportOptions(
        formats=formats,
        mesh=MeshOptions(radial=args.radial, rings=args.rings, leaves=not args.no_leaves),
        reduce=ReduceOptions(position_tolerance=args.position_tolerance,
                             angle_tolerance=math.radians(args.angle_tolerance),
                             enabled=not args.no_reduce),
        split=args.split, obj_stride=args.stride, preview_size=args.size,
        frame_start=args.frame_start, textures=not args.no_textures)


def _stage_progress():
    """Progress on stderr for export stages: a bar on a terminal, plain
    lines (every few seconds and at each stage's end) elsewhere."""
    start = time.perf_counter()
    tty = sys.stderr.isatty()
    last = [start]

    def show(stage: str, done: int, total: int) -> None:
        elapsed = time.perf_counter() - start
        if not tty:
            if done >= total or time.perf_counter() - last[0] >= _plain_interval():
                last[0] = time.perf_counter()
                sys.stderr.write(f"exporting {stage}: {done}/{total}, {elapsed:.1f} s\n")
                sys.stderr.flush()
            return
        width = 30
        filled = int(width * done / max(total, 1))
        sys.stderr.write(f"\rexporting {stage:<7} [{'#' * filled}{'.' * (width - filled)}] "
                         f"{done}/{total}  {elapsed:5.1f} s ")
        if done >= total:
            sys.stderr.write("\n")
        sys.stderr.flush()

    return show


def _run_export(bake, bake_path, out, name, opts, args):
    from .export import export_bake

    progress = None if getattr(args, "quiet", False) else _stage_progress()
    return export_bake(bake, out, name, opts, bake_path=bake_path, progress=progress)


def _export_summary(report) -> dict:
    m = report.manifest
    return {"folder": str(report.folder), "files": len(m["files"]),
            "bytes": m["total_bytes"], "animation": m.get("animation", {}),
            "sizes": m["sizes"]}


def _print_export(report) -> None:
    m = report.manifest
    a = m.get("animation")
    names = [e["path"] for e in m["files"]] + ["manifest.json"]
    print(f"exported {_plural(len(names), 'file')}, {m['total_bytes'] / 1e6:.1f} MB -> "
          f"{report.folder}: {', '.join(names)}")
    if a and a.get("keys_full"):
        print(f"keyframes: {a['keys_written']:,} of {a['keys_full']:,} written "
              f"({100 * a['keys_kept_fraction']:.1f} %), {a['channels_written']:,} of "
              f"{a['channels']:,} channels; worst error {a['max_position_error_m'] * 1e3:.3g} mm, "
              f"{a['max_angle_error_deg']:.3g} deg")


def cmd_export(args) -> int:
    from .bake import load_bake
    from .export import check_options
    from .fileio import job_lock

    path = Path(args.bake)
    if not path.is_file():
        raise InputError(f"{path}: bake file not found")
    opts = _export_options(args)
    check_options(opts)
    bake = load_bake(path)
    name = _job_name(args.name or str(bake.meta.get("scene") or "bake"))
    with job_lock(Path(args.out) / name):
        report = _run_export(bake, path, args.out, name, opts, args)
    if args.json:
        print(json.dumps(_export_summary(report)))
    else:
        _print_export(report)
    return 0


def cmd_preview(args) -> int:
    from .bake import load_bake
    from .export import write_previews

    path = Path(args.bake)
    if not path.is_file():
        raise InputError(f"{path}: bake file not found")
    if not 64 <= args.size <= 2048:
        raise InputError(f"--size must be in 64..2048 px, got {args.size}")
    bake = load_bake(path)
    name = _job_name(args.name or str(bake.meta.get("scene") or path.stem))
    folder = check_writable(Path(args.out) / name)
    stage = None if args.quiet else _stage_progress()
    progress = None if stage is None else (lambda d, t: stage("preview", d, t))
    files = write_previews(bake, folder, name, args.size, progress=progress)
    if args.json:
        print(json.dumps({"files": [str(f) for f in files]}))
    else:
        print("written: " + ", ".join(str(f) for f in files))
    return 0


def cmd_diff(args) -> int:
    from .diff import diff_bakes, exit_code, format_report, load_any, plot_report

    a, b = load_any(args.a), load_any(args.b)
    report = diff_bakes(a, b, args.position_tolerance, args.angle_tolerance, args.worst)
    if args.plot:
        plot_report(report, a.times, args.plot)
    if args.json:
        print(json.dumps(report.as_dict()))
    else:
        print(format_report(report, args.a, args.b))
    return exit_code(report)


def cmd_batch(args) -> int:
    import os

    from .batch import format_table, load_jobs, run_batch, summary
    from .fileio import check_writable, check_writable_file

    jobs = load_jobs(args.jobs_file)
    workers = args.jobs or os.cpu_count() or 1
    if workers < 1:
        raise InputError(f"--jobs must be >= 1, got {args.jobs}")
    summary_path = Path(args.summary or Path(args.out) / "batch-summary.json")
    check_writable(args.out)
    check_writable_file(summary_path)
    show = _batch_display(len(jobs), quiet=args.json)
    start = time.perf_counter()
    results = run_batch(jobs, args.out, workers, args.force, args.executor, args.scheduler,
                        report=show, worker_timeout=args.worker_timeout)
    data = summary(results, time.perf_counter() - start, show.workers)
    write_text(summary_path, json.dumps(data, indent=2) + "\n")
    if args.json:
        print(json.dumps(data))
    else:
        print(format_table(results))
        line = (f"{data['done']} done, {data['skipped']} skipped, {data['failed']} failed")
        if data["interrupted"]:
            line += f", {data['interrupted']} interrupted"
        print(f"{line} in {data['wall_seconds']:.1f} s with {_plural(data['workers'], 'worker')}"
              f"; summary: {summary_path}")
    if data["interrupted"]:
        print("treebake: interrupted; rerun the same command to resume", file=sys.stderr)
        return 130
    return 1 if data["failed"] else 0


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


class _batch_display:
    """Progress of a batch on stderr: one line per finished (or retried) job;
    on a terminal a live line with every running job's frame count, else
    that status as a plain line every PLAIN_PROGRESS_SECONDS. Remembers
    the most workers the run reported (the summary's count)."""

    def __init__(self, total: int, quiet: bool = False) -> None:
        self.total, self.quiet = total, quiet
        self.tty = sys.stderr.isatty()
        self.running: dict[str, str] = {}
        self.finished = 0
        self.workers = 0
        self.last_plain = time.monotonic()

    def __call__(self, event: str, data) -> None:
        if event == "workers":
            self.workers = max(self.workers, int(data))
            return
        if event == "start":
            self.running[data] = "starting"
        elif event == "progress":
            name, done, frames = data
            self.running[name] = f"{done}/{frames}"
        elif event == "retry":
            self._line(f"[{self.finished}/{self.total}] {data[0]}: {data[1]}")
        elif event == "end":
            self.running.pop(data.name, None)
            self.finished += 1
            line = f"[{self.finished}/{self.total}] {data.name}: {data.status}"
            if data.message:
                line += f" ({data.message})"
            self._line(line)
        if self.quiet or not self.running:
            return
        live = "  ".join(f"{k} {v}" for k, v in sorted(self.running.items()))
        if self.tty:
            sys.stderr.write(f"\r\033[K[{self.finished}/{self.total}] {live}"[:200])
            sys.stderr.flush()
        elif time.monotonic() - self.last_plain >= _plain_interval():
            self.last_plain = time.monotonic()
            self._line(f"[{self.finished}/{self.total}] running: {live}"[:400])

    def _line(self, text: str) -> None:
        if self.quiet:
            return
        sys.stderr.write(("\r\033[K" if self.tty else "") + text + "\n")
        sys.stderr.flush()


def cmd_sway(args) -> int:
    from .sway import pull_release

    r = pull_release(resolve(args.grammar, ("grammar",)), seed=args.seed,
                     quality=args.quality)
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
    p.add_argument("--size", type=int, default=512,
                   help="preview panel size, px, 64-2048 (default 512)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("bake", help="simulate a scene (or a grammar) and bake the motion",
                       description="Grow, rig and simulate the trees of a scene file (TOML, "
                                   "docs/scenes.md), or one grammar in a gusty breeze, and "
                                   "write the bake (.npz, docs/formats.md) into OUT/<name>/.")
    p.add_argument("job", help="scene file (.toml), grammar (.lsys), a bundled grammar's name "
                               "(oak) or preset:NAME (preset:felling); `treebake list`")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--name", help="job name: the output subfolder (default: the scene's name)")
    p.add_argument("--solver", choices=("planar", "full"), default="planar",
                   help="planar: the fast pymunk LOD (default); full: the MuJoCo reference")
    p.add_argument("--timestep", metavar="SECONDS",
                   help="the full reference's step, e.g. 1/480 (default 1/2000)")
    p.add_argument("--quality", choices=("draft", "default", "final"),
                   help="override the scene's quality level (default: the scene's, else "
                        "default)")
    p.add_argument("--duration", type=float, help="override the duration, s (default: the "
                                                   "scene's; grammar jobs 10)")
    p.add_argument("--fps", type=float, help="override the frame rate, frames/s (default: the "
                                              "scene's; grammar jobs 24)")
    p.add_argument("--seed", type=int, help="override the seed (default: the scene's)")
    p.add_argument("--wind", type=float, help="wind speed at 10 m, m/s (grammar jobs: "
                                               "default 6.7)")
    p.add_argument("--workers", type=int, default=None,
                   help="processes sharing the simulation (default: the machine's cores; the "
                        "bake is the same with any number)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress or notes on stderr")
    p.add_argument("--format", help="also export: comma-separated glb, gltf, obj, usd, usda, "
                                    "preview (default: the scene's `formats`, else only the "
                                    ".npz bake)")
    p.set_defaults(func=cmd_bake, radial=8, rings=1, no_leaves=False, position_tolerance=0.002,
                   angle_tolerance=0.25, no_reduce=False, split=False, stride=1, size=256,
                   frame_start=None, no_textures=False)

    p = sub.add_parser("export", help="export a bake to glTF, OBJ sequences, USD, previews",
                       description="Write a bake (.npz) as animated glTF 2.0 (.glb or "
                                   ".gltf+.bin), OBJ sequences, USD (needs usd-core) and "
                                   "previews into OUT/<name>/, with manifest.json "
                                   "(docs/formats.md).")
    p.add_argument("bake", help="bake file (.npz) from `treebake bake`")
    p.add_argument("--format", default="glb",
                   help="comma-separated: glb, gltf, obj, usd, usda, preview (default: glb)")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--name", help="job name: the output subfolder (default: the bake's scene)")
    _add_export_options(p)
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("preview", help="contact sheet PNG and animated GIF of a bake",
                       description="Draw a bake from the front and the side (orthographic, "
                                   "no GPU): OUT/<name>/<name>.contact.png (12 frames) and "
                                   "<name>.gif (the whole bake).")
    p.add_argument("bake", help="bake file (.npz)")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--name", help="job name: the output subfolder (default: the bake's scene)")
    p.add_argument("--size", type=int, default=256, help="panel size, px (default 256)")
    p.add_argument("--json", action="store_true", help="print the written files as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_preview)

    p = sub.add_parser("diff", help="compare two bakes (or glTF exports): which motion changed",
                       description="Compare two bakes (.npz) or two exported glTF files. "
                                   "Exit 0: within tolerance; 1: the motion differs; 2: not "
                                   "the same trees (or bad input).")
    p.add_argument("a", help="first bake (.npz, .glb, .gltf)")
    p.add_argument("b", help="second bake")
    p.add_argument("--position-tolerance", type=float, default=1e-3,
                   help="largest allowed position difference, m (default 0.001)")
    p.add_argument("--angle-tolerance", type=float, default=0.1,
                   help="largest allowed rotation difference, degrees (default 0.1)")
    p.add_argument("--worst", type=int, default=5,
                   help="how many worst segments to list (default 5)")
    p.add_argument("--json", action="store_true", help="the report as JSON")
    p.add_argument("--plot", help="write a PNG of the worst segments' error over time")
    p.set_defaults(func=cmd_diff)

    p = sub.add_parser("batch", help="run many bakes from a job file, in parallel, resumably",
                       description="Run the jobs of a job file (TOML, docs/batch.md) in worker "
                                   "processes or on a Dask cluster. Finished jobs whose inputs "
                                   "did not change are skipped. Exit 0 if every job succeeded.")
    p.add_argument("jobs_file", help="job file (.toml)")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--jobs", "-j", type=int, default=None,
                   help="worker processes (default: the machine's cores)")
    p.add_argument("--force", action="store_true", help="redo finished jobs too")
    p.add_argument("--executor", choices=("process", "dask"), default="process",
                   help="process: local worker processes (default); dask: a Dask cluster")
    p.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--worker-timeout", type=float, default=120.0, metavar="SECONDS",
                   help="Dask: fail the unfinished jobs after this long without any worker "
                        "(default 120)")
    p.add_argument("--summary", help="summary JSON path (default: OUT/batch-summary.json)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=cmd_batch)

    p = sub.add_parser("sway", help="pull-and-release test: first sway frequency and damping",
                       description="Pull a tree's main stem at 0.6 of its height until the top "
                                   "moves 1 % of the height, release it in still air, and "
                                   "measure the first sway frequency and damping ratio (the "
                                   "field method).")
    p.add_argument("grammar", help="grammar file (.lsys) or bundled grammar name (oak)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: grammar's)")
    p.add_argument("--quality", choices=("draft", "default", "final"), default="default",
                   help="simulation quality level (default: default)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_sway)

    p = sub.add_parser("list", help="the bundled grammars and scene presets",
                       description="List the species grammars and scene presets that ship with "
                                   "treebake, by the names the commands accept: `treebake bake "
                                   "oak`, `treebake bake preset:felling`.")
    p.add_argument("kind", nargs="?", choices=("grammars", "presets"), help="only these")
    p.add_argument("--json", action="store_true", help="as JSON (with each file's path)")
    p.set_defaults(func=cmd_list)

    p = sub.add_parser("accuracy", help="error against run time: the LOD vs the full reference",
                       description="Bake species x scenarios with the full 3D reference at a "
                                   "fine step (the truth), then with every LOD setting and the "
                                   "reference at coarser steps; write OUT/report.md, "
                                   "report.json and plot.png (error against cost).")
    p.add_argument("--out", default="out/accuracy", help="output folder (default: out/accuracy)")
    p.add_argument("--species", nargs="*", metavar="NAME",
                   help=f"species, any of: {', '.join(ACCURACY_SPECIES)} (default: sapling "
                        "broadleaf conifer)")
    p.add_argument("--scenarios", nargs="*", metavar="NAME",
                   help=f"scenarios, any of: {', '.join(ACCURACY_SCENARIOS)} (default: all)")
    p.add_argument("--duration", type=float, default=5.0, help="seconds per case (default 5)")
    p.add_argument("--production", action="store_true",
                   help="add the production cases: oak, spruce, willow, palm and bamboo in "
                        "breeze and gale, a 50-tree forest in a strong breeze (about an hour)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_accuracy)

    p = sub.add_parser("stability", help="stress suite: stiff, extreme and long cases, both "
                                          "solvers",
                       description="Run the stress cases (stiffness to x10^4, mass ratios to "
                                   "1:10^4, cones 0.5-90 deg, overlapping and near-zero "
                                   "segments, a 200-segment chain, wind to 70 m/s, huge "
                                   "blasts, 10-minute runs) and the event cases (felling each "
                                   "species, a crate, a blast and a tornado breaking trees) on "
                                   "both solvers, the LOD at every quality level; write "
                                   "OUT/report.md and report.json. Exit 1 if a case fails.")
    p.add_argument("--out", default="out/stability", help="output folder (default: "
                                                          "out/stability)")
    p.add_argument("--quick", action="store_true", help="leave out the 10-minute runs")
    p.add_argument("--solver", choices=("planar", "full", "both"), default="both",
                   help="planar: the LOD; full: the MuJoCo reference; both (default)")
    p.add_argument("--quality", nargs="*", choices=("draft", "default", "final"),
                   help="the LOD's quality levels to run (default: all three)")
    p.add_argument("--engine", choices=("auto", "articulated", "pymunk"), default="auto",
                   help="the LOD's engine for what leaves its linear tier: auto (default: "
                        "the reference when MuJoCo is installed), articulated (with pymunk for "
                        "breaks, cuts and hits: what an install without the `reference` extra "
                        "runs) or pymunk (everything)")
    p.add_argument("--case", nargs="*", metavar="NAME",
                   help="only these cases (quote names with spaces): "
                        f"{', '.join(repr(c) for c in STABILITY_CASES)} (default: all; the long "
                        "ones (felling the big species, the crate, 10-minute runs) only without "
                        "--quick)")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_stability)

    for name, sp in sub.choices.items():
        sp.formatter_class = _HelpFormatter
        sp.epilog = "examples:\n" + EXAMPLES[name]
    return parser


# names listed in help pages without importing the heavy modules on every
# start; tests/test_cli_errors.py checks them against accuracy.py and stress.py
ACCURACY_SPECIES = ("sapling", "palm", "broadleaf", "conifer", "birch", "oak", "spruce",
                    "willow", "bamboo", "forest")
ACCURACY_SCENARIOS = ("calm", "breeze", "gusty", "gale", "strong breeze", "boxes", "explosion")
STABILITY_CASES = ("stiff x1", "stiff x100", "stiff x10000", "mass 1:10^2", "mass 1:10^4",
                   "cone 0.5 deg", "cone 5 deg", "cone 90 deg", "overlapping",
                   "near-zero segments", "1 mm between 1 m", "200-segment chain",
                   "wind 45 m/s", "wind 70 m/s", "blast 2 kg at 6 m", "blast 50 kg at 5 m",
                   "blast 500 kg at 6 m", "felling sapling", "felling spruce", "felling oak",
                   "felling willow", "felling palm", "felling bamboo", "crate breaks a stem",
                   "blast breaks branches", "tornado uproots", "10 min gusty", "10 min calm")

EXAMPLES = {
    "derive": "  treebake derive sapling --stats-only              # a bundled grammar by name\n"
              "  treebake derive grammars/oak.lsys -n 4 -o oak.txt  # or a grammar file\n",
    "inspect": "  treebake inspect oak            # out/oak/summary.json, preview.png\n"
               "  treebake inspect forest/birch --json --size 256\n",
    "bake": "  treebake bake preset:demo --format glb   # out/demo/demo.npz, demo.glb\n"
            "  treebake bake sapling --duration 4 --wind 12 --quality draft\n"
            "  treebake bake presets/gale.toml --solver full --timestep 1/480 --name gale-ref\n"
            "  treebake bake preset:felling --format glb,usd\n",
    "export": "  treebake export out/demo/demo.npz --format glb,usd\n"
              "  treebake export out/demo/demo.npz --format obj --stride 2 --name demo-obj\n"
              "  treebake export out/demo/demo.npz --format glb --no-textures --frame-start 0\n",
    "preview": "  treebake preview out/demo/demo.npz --size 384\n",
    "diff": "  treebake diff out/before/oak/oak.npz out/after/oak/oak.npz\n"
            "  treebake diff out/demo/demo.glb out/demo/demo.npz   # an export vs its bake\n"
            "  treebake diff a.npz b.npz --json --plot worst.png\n",
    "batch": "  treebake batch jobs.toml --out out/shots -j 2\n"
             "  treebake batch jobs.toml --out /shared/bakes --executor dask "
             "--scheduler tcp://head:8786\n",
    "sway": "  treebake sway oak\n"
            "  treebake sway grammars/spruce.lsys --quality final --json\n",
    "list": "  treebake list                  # bundled grammars and presets, by name\n"
            "  treebake list presets --json   # with each file's path\n",
    "accuracy": "  treebake accuracy --species sapling --scenarios breeze gale --duration 2\n",
    "stability": "  treebake stability --quick --solver planar\n"
                 "  treebake stability --case 'stiff x100' 'wind 70 m/s'\n",
}


class _HelpFormatter(argparse.HelpFormatter):
    """Wraps descriptions as usual; keeps the examples epilog as written."""

    def _fill_text(self, text, width, indent):
        if text.startswith("examples:"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    start = time.perf_counter()
    try:
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler below
    except TreebakeError as exc:
        print(f"treebake: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("treebake: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `treebake diff ... | head`: the reader left; not an error of ours
        _silence_stdout()
        return 141  # 128 + SIGPIPE, what a shell reports for a process killed by it
    except OSError as exc:  # disk full, a folder removed under us, ...: no traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"treebake: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    if getattr(args, "verbose", False):
        print(f"done in {time.perf_counter() - start:.2f} s", file=sys.stderr)
    return code


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush cannot
    raise BrokenPipeError again at exit."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
