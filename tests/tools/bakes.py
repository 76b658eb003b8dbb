"""Short bakes of every preset for the export tests, baked once per test
session (cached here, shared by every tests/test_export_*.py)."""

from __future__ import annotations

import functools
import tomllib
from pathlib import Path

from treebake.bake import Bake
from treebake.pipeline import bake_scene
from treebake.scene import load_scene, parse_scene

ROOT = Path(__file__).resolve().parents[2]
PRESETS = ROOT / "presets"
# every preset; "forest" is replaced by a 20-tree forest of the same grammars
NAMES = sorted(p.stem for p in PRESETS.glob("*.toml"))
# long enough that each preset's event happens: boxes hit and break at 2.3 s,
# the explosion breaks twigs at 1.1 s, the felled tree starts to tip after its cut at 1 s,
# the storm rises from calm (4.7 m/s at 3 s)
DURATION = {"boxes": 2.5, "explosion": 1.5, "felling": 3.0, "storm": 3.0}


@functools.cache
def preset_bake(name: str, duration: float | None = None) -> Bake:
    d = duration or DURATION.get(name, 1.0)
    if name == "forest":
        return bake_scene(small_forest(d))
    return bake_scene(load_scene(PRESETS / f"{name}.toml", {"duration": d}))


def small_forest(duration: float):
    """presets/forest.toml with 20 trees on 60 m x 60 m (CI-sized)."""
    path = PRESETS / "forest.toml"
    raw = tomllib.loads(path.read_text())
    raw["duration"] = duration
    raw["forest"]["count"] = 20
    raw["forest"]["area"] = [60.0, 60.0]
    return parse_scene(raw, file=str(path), base=PRESETS, source_hash="forest-20")
