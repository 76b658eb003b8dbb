"""The grow stage: every tree of a scene derived from its grammar and
interpreted by the turtle, placed in the world."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .lsystem import derive, load_grammar
from .model import TreeModel, placed
from .scene import Scene, TreeSpec
from .turtle import interpret


@dataclass
class GrownTree:
    """A scene's tree as grown: its spec, its model (world coordinates, m),
    its grammar's hash and the seed it grew from."""

    spec: TreeSpec
    model: TreeModel
    grammar_hash: str
    seed: int

    def grammar_label(self, scene_file: str) -> str:
        """The grammar's path as the scene file names it (relative to the
        scene's folder), so a bake does not depend on where it was made."""
        try:
            return Path(os.path.relpath(self.spec.grammar,
                                        Path(scene_file).resolve().parent)).as_posix()
        except ValueError:  # another drive
            return Path(self.spec.grammar).name


def grow(scene: Scene) -> list[GrownTree]:
    """Derive and interpret every tree of the scene, placed in the world.
    Identical (grammar, seed, iterations) are derived once."""
    grammars: dict[Path, object] = {}
    cache: dict[tuple, TreeModel] = {}
    out = []
    for spec in scene.trees:
        g = grammars.get(spec.grammar)
        if g is None:
            g = grammars[spec.grammar] = load_grammar(spec.grammar)
        seed = g.seed if spec.seed is None else spec.seed
        key = (spec.grammar, seed, spec.iterations)
        model = cache.get(key)
        if model is None:
            d = derive(g, seed, spec.iterations)
            model = cache[key] = interpret(d.modules, g, seed=seed)
        m = placed(model, spec.position, spec.rotation)
        m.name = spec.name
        out.append(GrownTree(spec, m, g.source_hash, seed))
    return out


def extent(grown: list[GrownTree], margin: float = 20.0) -> np.ndarray:
    """The horizontal box ((xmin, ymin), (xmax, ymax)) m the trees stand in,
    widened by `margin` m: where the wind's turbulence is synthesised."""
    lo = np.min([g.model.points.min(0) for g in grown], axis=0)
    hi = np.max([g.model.points.max(0) for g in grown], axis=0)
    return np.array([lo[:2] - margin, hi[:2] + margin])
