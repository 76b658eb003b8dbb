"""Regenerate the golden bakes: python tests/golden/regenerate.py

Only when a change of motion is intended (a physics fix, a new default):
then commit the new files with a note saying why. tests/test_golden.py
bakes the same scenes fresh and diffs them against these with
`treebake diff`.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(ROOT))

from treebake.bake import save_bake
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


def main() -> None:
    for name in GOLDEN:
        path = save_bake(bake_scene(golden_scene(name)), HERE / f"{name}.npz")
        print(f"wrote {path.relative_to(ROOT)} ({path.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
