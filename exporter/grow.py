"""The grow stage: every tree of a scene derived from its grammar and
interpreted by the turtle, placed in the world."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from .forked import forked_map
from .lsystem import derive, load_grammar
from .model import TreeModel, placed
from .resources import Budget, too_many_segments
from .scene import Scene, TreeSpec
from .turtle import count_segments, interpret


@dataclass
class GrownTree:
    """A scene's tree as grown: its spec, its model (world coordinates, m),
    its grammar's hash, the seed it grew from, its grammar's path as the
    scene file names it (relative to the scene's folder, so that a bake
    does not depend on where it was made), its box and its height."""

    spec: TreeSpec
    model: TreeModel
    grammar_hash: str
    seed: int
    grammar: str
    bounds: tuple  # (lo, hi) (3,) m: the box the placed tree fills
    height: float  # m


def _as_named(grammar: Path, scene_file: str) -> str:
    try:
        return Path(os.path.relpath(grammar, Path(scene_file).resolve().parent)).as_posix()
    except ValueError:  # another drive
        return Path(grammar).name


def grow(scene: Scene, budget: Budget | None = None, workers: int = 1) -> list[GrownTree]:
    """Derive and interpret every tree of the scene, placed in the world.
    Identical (grammar, seed, iterations) are grown once. Each tree is
    derived and its segments counted against `budget` (resources.py)
    before it is drawn: a tree too large is refused in about the time its
    derivation takes. `workers` processes share the trees (forked.py); the
    trees are the same with any number."""
    budget = budget or Budget()
    named = {g: _as_named(g, scene.file) for g in dict.fromkeys(s.grammar for s in scene.trees)}
    grammars = {g: load_grammar(g) for g in named}
    seeds = [grammars[s.grammar].seed if s.seed is None else s.seed for s in scene.trees]
    keys = list(dict.fromkeys((s.grammar, seed, s.iterations)
                              for s, seed in zip(scene.trees, seeds)))

    def grown(key: tuple) -> TreeModel:
        grammar, seed, iterations = key
        modules = derive(grammars[grammar], seed, iterations).modules
        segments = count_segments(modules)
        if segments > budget.max_segments:
            raise too_many_segments(grammar, segments, budget)
        return interpret(modules, grammars[grammar], seed=seed)

    models = dict(zip(keys, forked_map(grown, keys, workers)))
    out = []
    for spec, seed in zip(scene.trees, seeds):
        g = grammars[spec.grammar]
        m = placed(models[(spec.grammar, seed, spec.iterations)], spec.position, spec.rotation)
        m.name = spec.name
        out.append(GrownTree(spec, m, g.source_hash, seed, named[spec.grammar], m.bounds(),
                             m.height))
    return out
