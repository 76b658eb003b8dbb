"""`treebake bake`, `export` and `preview`: a scene or grammar to a bake,
a bake to files."""

from __future__ import annotations

import itertools
import json
import re
import sys
from pathlib import Path

from .cli_grammar import warn_grammar_files
from .cli_progress import plural, progress_bar, stage_progress
from .errors import InputError, SceneError
from .fileio import output_folder
from .library import resolve
from .resources import DEFAULT_MAX_SEGMENTS, Budget, parse_size


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
    overrides = {key: value for key, flag in FLAGS.items()
                 if (value := getattr(args, flag.removeprefix("--"))) is not None}
    try:
        return load(p, overrides)
    except SceneError as exc:  # a flag's value is the flag's error, not the file's
        if exc.key in overrides and exc.message.startswith("= "):
            raise InputError(f"{FLAGS[exc.key]} {exc.message[2:]}") from None
        raise


FLAGS = {"duration": "--duration", "fps": "--fps", "seed": "--seed", "quality": "--quality",
         "wind.speed": "--wind"}  # scene key -> the `bake` flag that overrides it


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


def job_name(name: str) -> str:
    """`name` if it can be the job's output subfolder, else InputError."""
    if not name or any(c in name for c in "/\\") or name in (".", ".."):
        raise InputError(f"job name {name!r} cannot be a folder name (--name)")
    return name


def cmd_bake(args) -> int:
    import os

    from .bake_file import tree_field, tree_info
    from .export import check_options, remove_exports
    from .fileio import job_lock
    from .pipeline import bake_scene

    scene = load_job(args.job, args)
    warn_grammar_files([t.grammar for t in scene.trees], args.strict)
    out = Path(args.out) / job_name(args.name or scene.name)
    log = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr))
    progress = None if args.quiet else progress_bar("simulating")
    workers = (os.cpu_count() or 1) if args.workers is None else args.workers
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
    if args.scheduler:  # a bad address or a cluster of other versions: before any work
        if args.solver == "full":
            raise InputError("--scheduler spreads the planar LOD's chunks over a Dask cluster; "
                             "--solver full simulates the scene as one model, in one process")
        from .sim.distributed import check_versions, connect

        with connect(args.scheduler) as client:
            check_versions(client)
    budget = Budget(None if args.max_memory is None else parse_size(args.max_memory), out,
                    DEFAULT_MAX_SEGMENTS if args.max_segments is None else args.max_segments)
    if budget.max_segments < 1:
        raise InputError(f"--max-segments must be >= 1, got {args.max_segments}")
    opts = None
    if args.format is not None:  # checked now, not after the simulation
        opts = export_options(args, allow_none=True)
        check_options(opts)
    with job_lock(out):  # proves the folder writable; one run per job folder at a time
        path = out / f"{out.name}.npz"
        bake = bake_scene(scene, solver=args.solver, log=log, progress=progress,
                          workers=workers, timestep=timestep, budget=budget,
                          scheduler=args.scheduler, path=path)
        stale = remove_exports(out, path.name)  # exported from the bake just replaced
        if stale:
            log(f"removed {plural(stale, 'file')} exported from the previous bake in {out} "
                "(its manifest.json listed them)")
        exported = None
        if opts is not None and opts.formats:
            exported = run_export(bake, path, args.out, out.name, opts, args)
    t = bake.timing
    # from each tree's smallest entries: the bake is not read again
    sizes = [(len(tree_field(bake.trees, i, "seg_start")),
              "static" in tree_info(bake.trees, i))
             for i in range(len(bake.trees))]
    summary = {"bake": str(path), "trees": len(bake.trees),
               "simulated": sum(1 for _, static in sizes if not static),
               "segments": sum(n for n, _ in sizes),
               "frames": len(bake.times), "notes": bake.meta.get("notes", []),
               "wall_seconds": t.get("wall_seconds")}
    if exported is not None:
        summary["export"] = export_summary(exported)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"baked {plural(summary['trees'], 'tree')} ({summary['simulated']:,} simulated, "
              f"{plural(summary['segments'], 'segment')}), {plural(summary['frames'], 'frame')}"
              f" in {summary['wall_seconds']:.1f} s -> {path}")
        if exported is not None:
            print_export(exported)
    return 0


def export_options(args, allow_none: bool = False):
    """ExportOptions from the command line; an empty --format is an error
    (it used to export glb silently); allow_none: `npz` alone is fine
    (bake: the bake is all that is wanted)."""
    import math

    from .exchange.anim import ReduceOptions
    from .exchange.mesh import MeshOptions
    from .export import FORMATS, ExportOptions, parse_detail, parse_formats

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
        frame_start=args.frame_start, textures=not args.no_textures,
        trees_per_file=args.trees_per_file, usd_layers=args.usd_layers,
        workers=getattr(args, "workers", None), **parse_detail(args.detail))


def run_export(bake, bake_path, out, name, opts, args):
    """export_bake into OUT/<name>/ with stage progress unless --quiet."""
    from .export import export_bake

    progress = None if getattr(args, "quiet", False) else stage_progress()
    return export_bake(bake, out, name, opts, bake_path=bake_path, progress=progress)


def export_summary(report) -> dict:
    """An export's folder, file count, bytes, animation and sizes, for --json."""
    m = report.manifest
    return {"folder": str(report.folder), "files": len(m["files"]),
            "bytes": m["total_bytes"], "animation": m.get("animation", {}),
            "sizes": m["sizes"]}


_NUMBERED = re.compile(r"(?P<head>.*?)(?P<number>\d+)(?P<tail>\D*)\Z")  # the last number


def file_list(names: list[str], most: int = 12, run: int = 3) -> str:
    """`names` for one line: each numbered sequence of `run` or more files
    (the same text around the last number) as one entry,
    `obj/felling.####.obj (289 files, 0001-0289)` (`*` for unpadded
    numbers of several widths; `step N` when every N-th), the rest by name,
    in first-seen order; past `most` entries, how many more."""
    groups: dict[tuple, list[str]] = {}
    for name in names:
        m = _NUMBERED.match(name)
        key = (m["head"], m["tail"]) if m else (name, None)
        groups.setdefault(key, []).append(name)
    entries = []
    for (head, tail), members in groups.items():
        if tail is None or len(members) < run:
            entries += members
            continue
        digits = [_NUMBERED.match(n)["number"] for n in members]
        widths = {len(d) for d in digits}
        mark = "#" * widths.pop() if len(widths) == 1 else "*"
        numbers = sorted(int(d) for d in digits)
        steps = {b - a for a, b in itertools.pairwise(numbers)}
        step = f", step {min(steps)}" if len(steps) == 1 and min(steps) > 1 else ""
        entries.append(f"{head}{mark}{tail} ({len(members)} files, "
                       f"{min(digits, key=int)}-{max(digits, key=int)}{step})")
    if len(entries) > most:
        more = len(entries) - most + 1
        entries = [*entries[:most - 1], f"... {more} more (manifest.json lists every file)"]
    return ", ".join(entries)


def print_export(report) -> None:
    """An export's files (numbered sequences as one entry each; manifest.json
    lists every file) and keyframe reduction, as text on stdout."""
    m = report.manifest
    a = m.get("animation")
    names = [e["path"] for e in m["files"]] + ["manifest.json"]
    print(f"exported {plural(len(names), 'file')}, {m['total_bytes'] / 1e6:.1f} MB -> "
          f"{report.folder}: {file_list(names)}")
    if a and a.get("keys_full"):
        print(f"keyframes: {a['keys_written']:,} of {a['keys_full']:,} written "
              f"({100 * a['keys_kept_fraction']:.1f} %), {a['channels_written']:,} of "
              f"{a['channels']:,} channels; worst error {a['max_position_error_m'] * 1e3:.3g} mm, "
              f"{a['max_angle_error_deg']:.3g} deg")


def cmd_export(args) -> int:
    from .bake_file import load_bake
    from .export import check_options
    from .fileio import job_lock

    path = Path(args.bake)
    if not path.is_file():
        raise InputError(f"{path}: bake file not found")
    opts = export_options(args)
    check_options(opts)
    bake = load_bake(path, lazy=True)  # the writers read a tree at a time
    name = job_name(args.name or path.stem)  # a bake's own folder: out/NAME/NAME.npz
    with job_lock(Path(args.out) / name):
        report = run_export(bake, path, args.out, name, opts, args)
    if args.json:
        print(json.dumps(export_summary(report)))
    else:
        print_export(report)
    return 0


def cmd_preview(args) -> int:
    from .bake_file import load_bake
    from .export import write_previews

    path = Path(args.bake)
    if not path.is_file():
        raise InputError(f"{path}: bake file not found")
    if not 64 <= args.size <= 2048:
        raise InputError(f"--size must be in 64..2048 px, got {args.size}")
    bake = load_bake(path)
    name = job_name(args.name or path.stem)
    stage = None if args.quiet else stage_progress()
    progress = None if stage is None else (lambda d, t: stage("preview", d, t))
    with output_folder(Path(args.out) / name) as folder:
        files = write_previews(bake, folder, name, args.size, progress=progress)
    if args.json:
        print(json.dumps({"files": [str(f) for f in files]}))
    else:
        print("written: " + file_list([str(f) for f in files]))
    return 0
