"""The `treebake` command line as a table: every command with its help,
description, arguments and examples (COMMANDS), and `build_parser`, which
turns the table into an argparse parser. The commands themselves live in
cli_tree, cli_bake, cli_batch and cli_suites; none imports simulation code
at start, so `treebake --help` is fast."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from . import __version__
from .cli_bake import cmd_bake, cmd_export, cmd_preview
from .cli_batch import cmd_batch, cmd_diff
from .cli_suites import cmd_accuracy, cmd_stability
from .cli_tree import cmd_derive, cmd_inspect, cmd_list, cmd_sway


@dataclass(frozen=True)
class Option:
    """One add_argument call: its flags (or positional name) and keywords."""

    flags: tuple[str, ...]
    settings: dict[str, Any]


def opt(*flags: str, **settings: Any) -> Option:
    """An Option written like the add_argument call it stands for."""
    return Option(flags, settings)


@dataclass(frozen=True)
class Group:
    """Options shown under their own title in the help page."""

    title: str
    options: tuple[Option, ...]


@dataclass(frozen=True)
class Command:
    """One subcommand: `run(args) -> exit code`, its arguments in help order,
    and parser defaults for options it does not take."""

    name: str
    run: Callable[[argparse.Namespace], int]
    help: str
    description: str
    arguments: tuple[Option | Group, ...]
    defaults: dict[str, Any] = field(default_factory=dict)


# names listed in help pages without importing the heavy modules on every
# start; tests/test_cli_errors.py checks them against accuracy.py and stress_cases.py
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

# the stress suite's measured cost (stress_plan.CPU_SECONDS; tests/test_stability_plan.py
# checks these against it)
STABILITY_FULL = ("1.9 h of CPU, as long in wall time on 2 idle cores (one process; the "
                  "felled willow alone takes 1.4 h)")
STABILITY_QUICK = "about 2 min on the bundled trees (26 of the 112 runs)"
STABILITY_QUICK_BUDGET = "135 CPU s (a run that would end past 5 min is skipped)"

QUALITY = ("draft", "default", "final")
OUT = opt("--out", default="out", help="output folder (default: out)")
JOB_NAME = opt("--name", help="job name: the output subfolder (default: the bake file's "
                               "name, so OUT/NAME/NAME.npz exports beside itself)")
QUIET = opt("-q", "--quiet", action="store_true", help="no progress on stderr")
STRICT = opt("--strict", action="store_true",
             help="grammar warnings (a module whose parameter count no production takes, "
                  "docs/grammar.md) are errors: exit 2 before any work")


def json_option(what: str) -> Option:
    """`--json`, with the command's own help text."""
    return opt("--json", action="store_true", help=what)


GRAMMAR_OPTIONS = (
    opt("grammar", help="grammar file (.lsys) or bundled grammar name (oak, forest/birch; "
                        "`treebake list`)"),
    opt("--seed", type=int, default=None, help="random seed (default: grammar's)"),
    opt("--iterations", "-n", type=int, default=None,
        help="derivation steps (default: grammar's)"),
    opt("--max-modules", type=int, default=None,
        help="cap on the derived string length (default 2,000,000)"),
    STRICT,
)

EXPORT_OPTIONS = Group("export options", (
    opt("--split", action="store_true", help="glTF: one file per tree"),
    opt("--trees-per-file", type=int, default=None,
        help="glTF and OBJ: at most N trees a file, NAME.part0001.glb, ..., or an OBJ "
             "sequence per N trees, NAME.part0001.0001.obj, ... (default: one file or "
             "sequence up to 250 trees, 250 each beyond)"),
    opt("--usd-layers", choices=("auto", "one", "tree"), default="auto",
        help="USD: one file, or a root stage that loads a layer per tree as a payload "
             "(NAME.trees/TREE.usd); default auto: per tree past 100 trees"),
    opt("--no-leaves", action="store_true", help="no leaf quads"),
    opt("--no-textures", action="store_true",
        help="plain colour materials instead of the generated bark and leaf textures"),
    opt("--detail", default="default", metavar="LEVEL[,TREE=LEVEL...]",
        help="triangles and textures for the camera's distance: hero, default or far, for "
             "every tree, then per tree by name (e.g. far,oak=hero); export-time only, the bake "
             "is the same (default: default)"),
    opt("--radial", type=int, default=8, help="vertices around a bark ring, 3-64 (default 8)"),
    opt("--rings", type=int, default=1, help="bark rings per segment, 1-16 (default 1)"),
    opt("--position-tolerance", type=float, default=0.002,
        help="keyframe reduction: worst joint/tip position error, m (default 0.002)"),
    opt("--angle-tolerance", type=float, default=0.25,
        help="keyframe reduction: worst joint rotation error, degrees (default 0.25)"),
    opt("--no-reduce", action="store_true", help="keep every frame of every channel that changes"),
    opt("--stride", type=int, default=1, help="OBJ sequences: every n-th frame (default 1)"),
    opt("--size", type=int, default=256, help="preview panel size, px (default 256)"),
    opt("--frame-start", type=int, default=None,
        help="number of the first frame in every format (default: the scene's frame_start, 1)"),
))


def defaults_of(group: Group) -> dict[str, Any]:
    """{dest: default} of the group's options, as argparse would fill them in
    (store_true: False; no default: None)."""
    defaults = {}
    for o in group.options:
        unset = False if o.settings.get("action") == "store_true" else None
        defaults[o.flags[0].lstrip("-").replace("-", "_")] = o.settings.get("default", unset)
    return defaults


EXPORT_DEFAULTS = defaults_of(EXPORT_OPTIONS)  # `bake --format` exports with these

COMMANDS: tuple[Command, ...] = (
    Command(
        "derive", cmd_derive, "derive a grammar and print the module string",
        "Derive a grammar; print the module string to stdout and statistics to stderr.",
        (*GRAMMAR_OPTIONS,
         opt("-o", "--output", help="write the string to this file instead of stdout"),
         opt("--stats-only", action="store_true", help="print only the statistics"),
         json_option("statistics as JSON"))),
    Command(
        "inspect", cmd_inspect, "tree statistics and a PNG preview",
        "Derive and interpret a grammar; print limb and segment counts, height, mass and "
        "bounds; write summary.json and preview.png (front and side) into OUT/<name>/, <name> "
        "being the grammar's file name, as for `treebake bake`.",
        (*GRAMMAR_OPTIONS, OUT,
         opt("--name", help="the output subfolder (default: the grammar's file name: my.lsys "
                            "-> OUT/my/)"),
         opt("--size", type=int, default=512, help="preview panel size, px, 64-2048 (default 512)"),
         json_option("print the summary as JSON"))),
    Command(
        "bake", cmd_bake, "simulate a scene (or a grammar) and bake the motion",
        "Grow, rig and simulate the trees of a scene file (TOML, docs/scenes.md), or one "
        "grammar in a gusty breeze, and write the bake (.npz, docs/formats.md) into "
        "OUT/<name>/.",
        (opt("job", help="scene file (.toml), grammar (.lsys), a bundled grammar's name (oak) "
                         "or preset:NAME (preset:felling); `treebake list`"),
         OUT,
         opt("--name", help="job name: the output subfolder (default: the scene's name)"),
         opt("--solver", choices=("planar", "full"), default="planar",
             help="planar: the planar LOD (default): a linear tier for whole trees, with the "
                  "pymunk tier and the MuJoCo reference for trees that leave its range; full: "
                  "the MuJoCo reference for everything"),
         opt("--timestep", metavar="SECONDS",
             help="the full reference's step, e.g. 1/480 (default 1/2000)"),
         opt("--quality", choices=QUALITY,
             help="override the scene's quality level (default: the scene's, else default)"),
         opt("--duration", type=float,
             help="override the duration, s (default: the scene's; grammar jobs 10)"),
         opt("--fps", type=float,
             help="override the frame rate, frames/s (default: the scene's; grammar jobs 24)"),
         opt("--seed", type=int, help="override the seed (default: the scene's)"),
         opt("--wind", type=float, help="wind speed at 10 m, m/s (grammar jobs: default 6.7)"),
         opt("--workers", type=int, default=None,
             help="processes sharing the growing, rigging and simulation (default: the "
                  "machine's cores; the bake is the same with any number)"),
         opt("--scheduler", metavar="ADDRESS",
             help="simulate the planar LOD's chunks on the Dask cluster at tcp://HOST:PORT "
                  "(pip install 'treebake[dask]'; the bake is the same as a local one)"),
         opt("--max-memory", metavar="SIZE",
             help="refuse, before simulating, a bake whose estimated peak memory is larger, "
                  "e.g. 8G (default: the memory the machine has available)"),
         opt("--max-segments", type=int, default=None,
             help="segments a tree may have (default 100,000: a larger one is refused "
                  "as soon as it is derived)"),
         json_option("print the summary as JSON"),
         opt("-q", "--quiet", action="store_true", help="no progress or notes on stderr"),
         opt("--format", help="also export: comma-separated glb, gltf, obj, usd, usda, abc, "
                              "preview (default: the scene's `formats`, else only the .npz "
                              "bake)"),
         STRICT),
        defaults=EXPORT_DEFAULTS),
    Command(
        "export", cmd_export, "export a bake to glTF, OBJ sequences, USD, Alembic, previews",
        "Write a bake (.npz) as animated glTF 2.0 (.glb or .gltf+.bin), OBJ sequences, USD "
        "(needs usd-core), Alembic (needs treebake[alembic]) and previews into OUT/<name>/, "
        "with manifest.json "
        "(docs/formats.md).",
        (opt("bake", help="bake file (.npz) from `treebake bake`"),
         opt("--format", default="glb",
             help="comma-separated: glb, gltf, obj, usd, usda, abc, preview (default: glb)"),
         opt("--workers", type=int, default=None,
             help="processes writing USD tree layers and glTF files of many trees (default: "
                  "the machine's cores, one per 50 trees at most; the files are the same with "
                  "any number)"),
         OUT, JOB_NAME, EXPORT_OPTIONS, json_option("print the summary as JSON"), QUIET)),
    Command(
        "preview", cmd_preview, "contact sheet PNG and animated GIF of a bake",
        "Draw a bake from the front and the side (orthographic, no GPU): "
        "OUT/<name>/<name>.contact.png (12 frames) and <name>.gif (the whole bake).",
        (opt("bake", help="bake file (.npz)"), OUT, JOB_NAME,
         opt("--size", type=int, default=256, help="panel size, px (default 256)"),
         json_option("print the written files as JSON"), QUIET)),
    Command(
        "diff", cmd_diff, "compare two bakes (or glTF exports): which motion changed",
        "Compare two bakes (.npz) or two exported glTF files. Exit 0: within tolerance; 1: "
        "the motion differs; 2: not comparable frame by frame (other trees, segments or frames) "
        "or bad input.",
        (opt("a", help="first bake (.npz, .glb, .gltf)"), opt("b", help="second bake"),
         opt("--position-tolerance", type=float, default=1e-3,
             help="largest allowed position difference, m (default 0.001)"),
         opt("--angle-tolerance", type=float, default=0.1,
             help="largest allowed rotation difference, degrees (default 0.1)"),
         opt("--worst", type=int, default=5, help="how many worst segments to list (default 5)"),
         json_option("the report as JSON"),
         opt("--plot", help="write a PNG of the worst segments' error over time"))),
    Command(
        "batch", cmd_batch, "run many bakes from a job file, in parallel, resumably",
        "Run the jobs of a job file (TOML, docs/batch.md) in worker processes or on a Dask "
        "cluster. Finished jobs whose inputs did not change are skipped. Exit 0 if every job "
        "succeeded; 1 if one failed; 75 if another run was still writing one (rerun later).",
        (opt("jobs_file", help="job file (.toml)"), OUT,
         opt("--jobs", "-j", type=int, default=None,
             help="worker processes (default: the machine's cores)"),
         opt("--force", action="store_true", help="redo finished jobs too"),
         opt("--executor", choices=("process", "dask"), default="process",
             help="process: local worker processes (default); dask: a Dask cluster"),
         opt("--scheduler", help="Dask scheduler address, e.g. tcp://10.0.0.5:8786"),
         opt("--worker-timeout", type=float, default=120.0, metavar="SECONDS",
             help="Dask: fail the unfinished jobs after this long without any worker "
                  "(default 120)"),
         opt("--summary", help="summary JSON path (default: OUT/batch-summary.json)"),
         json_option("print the summary as JSON"), STRICT)),
    Command(
        "sway", cmd_sway, "pull-and-release test: first sway frequency and damping",
        "Pull a tree's main stem at 0.6 of its height until the top moves 1 % of the height, "
        "release it in still air, and measure the first sway frequency and damping ratio (the "
        "field method).",
        (opt("grammar", help="grammar file (.lsys) or bundled grammar name (oak)"),
         opt("--seed", type=int, default=None, help="random seed (default: grammar's)"),
         opt("--quality", choices=QUALITY, default="default",
             help="simulation quality level (default: default)"),
         json_option("print the result as JSON"), QUIET, STRICT)),
    Command(
        "list", cmd_list, "the bundled grammars and scene presets",
        "List the species grammars and scene presets that ship with treebake, by the names "
        "the commands accept: `treebake bake oak`, `treebake bake preset:felling`.",
        (opt("kind", nargs="?", choices=("grammars", "presets"), help="only these"),
         json_option("as JSON (with each file's path)"))),
    Command(
        "accuracy", cmd_accuracy, "error against run time: the LOD vs the full reference",
        "Bake species x scenarios with the full 3D reference at a fine step (the truth), then "
        "with every LOD setting and the reference at coarser steps; write OUT/report.md, "
        "report.json and plot.png (error against cost).",
        (opt("--out", default="out/accuracy", help="output folder (default: out/accuracy)"),
         opt("--species", nargs="*", metavar="NAME",
             help=f"species, any of: {', '.join(ACCURACY_SPECIES)} (default: sapling broadleaf "
                  "conifer)"),
         opt("--scenarios", nargs="*", metavar="NAME",
             help=f"scenarios, any of: {', '.join(ACCURACY_SCENARIOS)} (default: all)"),
         opt("--duration", type=float, default=5.0, help="seconds per case (default 5)"),
         opt("--production", action="store_true",
             help="add the production cases: oak, spruce, willow, palm and bamboo in breeze "
                  "and gale, a 50-tree forest in a strong breeze (about an hour)"),
         json_option("print the summary as JSON"), QUIET)),
    Command(
        "stability", cmd_stability, "stress suite: stiff, extreme and long cases, both solvers",
        "Run the stress cases (stiffness to x10^4, mass ratios to 1:10^4, cones 0.5-90 deg, "
        "overlapping and near-zero segments, a 200-segment chain, wind to 70 m/s, huge "
        "blasts, 10-minute runs) and the event cases (felling each species, a crate, a blast "
        "and a tornado breaking trees) on both solvers, the LOD at every quality level; write "
        "OUT/report.md and report.json. Exit 1 if a case fails. With GRAMMAR, the cases on a "
        "species' tree run on its tree instead. The full suite is "
        f"{STABILITY_FULL}; --quick is {STABILITY_QUICK}. One progress line per run on stderr.",
        (opt("grammar", nargs="?", metavar="GRAMMAR",
             help="grammar file (.lsys) or bundled grammar name: the cases on the sapling and "
                  "the species (wind, blasts, felling, crate, tornado, 10-minute runs) run on "
                  "its tree (default: the bundled trees)"),
         opt("--out", default="out/stability", help="output folder (default: out/stability)"),
         opt("--quick", action="store_true",
             help="the runs that found the most, most telling first (events, huge blasts, "
                  "70 m/s gusts, felling, at the levels that failed), within a budget of "
                  f"{STABILITY_QUICK_BUDGET}; on a large grammar what does not fit is left "
                  "out, said before the first run"),
         opt("--solver", choices=("planar", "full", "both"), default="both",
             help="planar: the LOD; full: the MuJoCo reference; both (default)"),
         opt("--quality", nargs="*", choices=QUALITY,
             help="the LOD's quality levels to run (default: all three; with --quick, each "
                  "quick run's own)"),
         opt("--engine", choices=("auto", "pymunk"), default="auto",
             help="auto (default): the engine table of docs/physics.md; pymunk: the pymunk "
                  "tier for everything that leaves the linear tier"),
         opt("--case", nargs="*", metavar="NAME",
             help="only these cases (quote names with spaces): "
                  f"{', '.join(repr(c) for c in STABILITY_CASES)} (default: all; with "
                  "--quick, the quick runs of these)"),
         json_option("print the results as JSON"), QUIET)),
)

EXAMPLES = {
    "derive": "  treebake derive sapling --stats-only              # a bundled grammar by name\n"
              "  treebake derive my.lsys -n 4 -o my.txt            # or a grammar file\n",
    "inspect": "  treebake inspect oak            # out/oak/summary.json, preview.png\n"
               "  treebake inspect forest/birch --json --size 256\n",
    "bake": "  treebake bake preset:demo --format glb   # out/demo/demo.npz, demo.glb\n"
            "  treebake bake sapling --duration 4 --wind 12 --quality draft\n"
            "  treebake bake preset:gale --solver full --timestep 1/480 --name gale-ref\n"
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
            "  treebake sway spruce --quality final --json\n",
    "list": "  treebake list                  # bundled grammars and presets, by name\n"
            "  treebake list presets --json   # with each file's path\n",
    "accuracy": "  treebake accuracy --species sapling --scenarios breeze gale --duration 2\n",
    "stability": "  treebake stability --quick                  # a few minutes\n"
                 "  treebake stability oak --quick              # the oak's tree in the cases\n"
                 "  treebake stability --quick --solver planar\n"
                 "  treebake stability --case 'stiff x100' 'wind 70 m/s'\n",
}


class _HelpFormatter(argparse.HelpFormatter):
    """Wraps descriptions as usual; keeps the examples epilog as written."""

    def _fill_text(self, text, width, indent):
        if text.startswith("examples:"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


def build_parser() -> argparse.ArgumentParser:
    """The `treebake` parser, one subcommand per COMMANDS entry; a parsed
    command's `args.func(args)` runs it."""
    parser = argparse.ArgumentParser(
        prog="treebake",
        description="Grow trees from L-systems, simulate them, bake the motion to files.")
    parser.add_argument("--version", action="version", version=f"treebake {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command in COMMANDS:
        p = sub.add_parser(command.name, help=command.help, description=command.description,
                           formatter_class=_HelpFormatter,
                           epilog="examples:\n" + EXAMPLES[command.name])
        for argument in command.arguments:
            if isinstance(argument, Group):
                group = p.add_argument_group(argument.title)
                for o in argument.options:
                    group.add_argument(*o.flags, **o.settings)
            else:
                p.add_argument(*argument.flags, **argument.settings)
        p.set_defaults(func=command.run, command_parser=p, **command.defaults)
    return parser


def unknown_arguments(parser: argparse.ArgumentParser, extra: list[str]) -> str:
    """argparse's error for arguments `parser` does not take, with the
    closest of its options for each unknown one ("did you mean --format?")."""
    import difflib

    known = [o for a in parser._actions for o in a.option_strings]
    hints = []
    for token in extra:
        if token.startswith("-"):
            close = difflib.get_close_matches(token.split("=", 1)[0], known, n=1)
            hints += [f"{token}: did you mean {close[0]}?"] if close else []
    return "unrecognized arguments: " + " ".join(extra) + "".join(f"; {h}" for h in hints)
