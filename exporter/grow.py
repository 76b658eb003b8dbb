"""The grow stage: every tree of a scene derived from its grammar and
interpreted by the turtle, placed in the world."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

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


def grow(scene: Scene, budget: Budget | None = None) -> list[GrownTree]:
    """Derive and interpret every tree of the scene, placed in the world.
    Identical (grammar, seed, iterations) are derived once. Every tree is
    derived and its segments counted against `budget` (resources.py)
    before any is drawn: a tree too large is refused in about the time the
    derivations take."""
    budget = budget or Budget()
    named = {g: _as_named(g, scene.file) for g in dict.fromkeys(s.grammar for s in scene.trees)}
    grammars: dict[Path, object] = {}
    derived: dict[tuple, object] = {}
    for spec in scene.trees:
        g = grammars.get(spec.grammar)
        if g is None:
            g = grammars[spec.grammar] = load_grammar(spec.grammar)
        seed = g.seed if spec.seed is None else spec.seed
        key = (spec.grammar, seed, spec.iterations)
        if key not in derived:
            derived[key] = derive(g, seed, spec.iterations)
    for (grammar, _, _), d in derived.items():
        segments = count_segments(d.modules)
        if segments > budget.max_segments:
            raise too_many_segments(grammar, segments, budget)
    cache: dict[tuple, TreeModel] = {}
    out = []
    for spec in scene.trees:
        g = grammars[spec.grammar]
        seed = g.seed if spec.seed is None else spec.seed
        key = (spec.grammar, seed, spec.iterations)
        model = cache.get(key)
        if model is None:
            model = cache[key] = interpret(derived[key].modules, g, seed=seed)
        m = placed(model, spec.position, spec.rotation)
        m.name = spec.name
        out.append(GrownTree(spec, m, g.source_hash, seed, named[spec.grammar], m.bounds(),
                             m.height))
    return out
