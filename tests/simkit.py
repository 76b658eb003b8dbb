"""Helpers for physics tests: bake a grammar written inline, read motion back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from treebake.bake import Bake, TreeBake
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.sway import segment_ends

BARE = "drag: 0\nleaf drag: 0\n"  # no air: analytic comparisons


def bake_text(tmp_path: Path, grammar: str, solver: str = "planar", **scene) -> Bake:
    """Write `grammar` to a file and bake one tree of it in a scene built
    from the keyword arguments (TOML keys of docs/scenes.md)."""
    path = tmp_path / "g.lsys"
    path.write_text(grammar)
    raw = {"tree": [{"grammar": str(path)}], "ground": False}
    raw.update(scene)
    return bake_scene(parse_scene(raw, file="<test>"), solver=solver)


def tip(tree: TreeBake, segment: int = -1) -> np.ndarray:
    """World position (F, 3) of the end of a segment (default: the last)."""
    s = segment % tree.n_segments
    return segment_ends(tree, [s])[:, 0]
