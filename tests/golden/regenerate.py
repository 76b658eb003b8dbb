"""Regenerate the golden bakes, one at a time, showing what moved:

    python tests/golden/regenerate.py              # every golden, asking for each
    python tests/golden/regenerate.py sapling-box  # only this one
    python tests/golden/regenerate.py --yes        # replace without asking (scripts)

Only when a change of motion is intended (a physics fix, a new default):
each golden is baked fresh and compared with the committed one by
`treebake diff` (the report is printed, at test_golden.py's tolerances);
an unchanged one is kept, a changed one is replaced only when you say yes
(without a terminal and without --yes nothing is overwritten). Then commit
the new files with a note saying why. tests/test_golden.py bakes the same
scenes fresh and diffs them against these.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(ROOT))

from treebake.bake_file import save_bake
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene

# name: scene (paths relative to the repository root); kept small and short
GOLDEN = {
    "sapling-breeze": {"duration": 1.5, "fps": 12, "tree": [{"grammar": "grammars/sapling.lsys"}],
                       "wind": {"speed": 8.0, "turbulence": 0.3}},
    "palm-gale": {"duration": 1.0, "fps": 12, "tree": [{"grammar": "grammars/palm.lsys"}],
                  "wind": {"beaufort": "gale", "turbulence": 0.25, "ramp": 0.5}},
    "sapling-box": {"duration": 1.5, "fps": 12, "tree": [{"grammar": "grammars/sapling.lsys"}],
                    "projectile": [{"shape": "box", "size": 0.3, "mass": 20.0,
                                    "position": [-2.0, 0.0, 1.5], "velocity": [9.0, 0.0, 1.0],
                                    "time": 0.1}]},
}


def golden_scene(name: str):
    """The scene of a golden bake, with paths resolved from the repository."""
    return parse_scene(dict(GOLDEN[name], name=name), file=str(ROOT / f"{name}.toml"),
                       base=ROOT)


def _shown(path: Path) -> str:
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


TOLERANCES = ["--position-tolerance", "1e-4", "--angle-tolerance", "0.01"]  # test_golden's


def regenerate(name: str, assume_yes: bool, ask=input) -> str:
    """Bake one golden fresh, show `treebake diff` against the committed
    file, replace it if it changed and the user agrees. Returns what
    happened: "new", "unchanged", "replaced" or "kept"."""
    import os
    import tempfile

    from treebake.cli import main as cli

    target = HERE / f"{name}.npz"
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".npz", dir=HERE)
    os.close(fd)
    try:
        fresh = save_bake(bake_scene(golden_scene(name)), tmp)
        if not target.exists():
            os.replace(fresh, target)
            print(f"{name}: new, wrote {_shown(target)}")
            return "new"
        print(f"--- {name}: treebake diff {_shown(target)} <fresh bake>", flush=True)
        code = cli(["diff", str(target), str(fresh), *TOLERANCES])
        sys.stdout.flush()
        if code == 0:  # the motion is the golden's: keep the committed file, no churn
            print(f"{name}: motion unchanged, kept")
            return "unchanged"
        if not assume_yes:
            if not sys.stdin.isatty():
                print(f"{name}: changed; not replaced (no terminal to ask: pass --yes)")
                return "kept"
            if ask(f"replace {_shown(target)}? [y/N] ").strip().lower() != "y":
                print(f"{name}: kept")
                return "kept"
        os.replace(fresh, target)
        print(f"{name}: replaced {_shown(target)}")
        return "replaced"
    finally:
        Path(tmp).unlink(missing_ok=True)


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description="Regenerate golden bakes one at a time.")
    parser.add_argument("names", nargs="*", help=f"goldens (default: all): {', '.join(GOLDEN)}")
    parser.add_argument("--yes", action="store_true", help="replace changed ones without asking")
    args = parser.parse_args(argv)
    unknown = [n for n in args.names if n not in GOLDEN]
    if unknown:
        parser.error(f"unknown golden {', '.join(unknown)} (choose from {', '.join(GOLDEN)})")
    outcome = {name: regenerate(name, args.yes) for name in args.names or GOLDEN}
    print("; ".join(f"{k}: {v}" for k, v in outcome.items()))
    return 1 if "kept" in outcome.values() else 0


if __name__ == "__main__":
    sys.exit(main())
