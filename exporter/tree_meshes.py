"""Every tree's mesh of a bake, built one at a time as a writer asks
(exchange.mesh.tree_mesh with the tree's detail level and species' bark),
and what the manifest says of each tree, noted as its mesh is built."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from .bake import Bake
from .bake_file import tree_info
from .exchange.bark import bark_colour, bark_material
from .exchange.mesh import MeshOptions, TreeMesh, broken_joints, detail_options, tree_mesh


@dataclass(frozen=True)
class TreeFacts:
    """What the manifest says of one tree, noted when its mesh is built."""

    inputs: dict  # name, grammar, its hash, seed, segments, static
    segments: int
    static: bool
    extra_samples: int
    leaf_quads: int
    vertices: int
    triangles: int
    broken_joints: int


class TreeMeshes(Sequence[TreeMesh]):
    """Every tree's mesh (exchange.mesh.tree_mesh), built when a writer asks
    for it (the last one kept), so an export holds one tree's mesh, not the
    shot's; what the manifest says of each tree is noted as it is built."""

    def __init__(self, bake: Bake, opts: MeshOptions, detail: str = "default",
                 detail_trees: tuple[tuple[str, str], ...] = (), species: bool = False):
        self.bake, self.opts = bake, opts
        self.detail, self.detail_trees = detail, dict(detail_trees)
        self.species = species  # bark materials per species (bark.bark_material)
        self.facts: dict[int, TreeFacts] = {}
        self._last: tuple[int, TreeMesh] | None = None

    def __len__(self) -> int:
        return len(self.bake.trees)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        i = range(len(self))[i]
        if self._last is None or self._last[0] != i:
            tree = self.bake.trees[i]
            broken = broken_joints(tree)
            info = dict(tree.info, name=tree.name)  # not read again from a stored bake
            mesh = tree_mesh(tree, self.tree_options(i, info), broken)
            self.facts[i] = TreeFacts(
                {"name": tree.name, "grammar": Path(str(tree.info.get("grammar", ""))).name,
                 "grammar_hash": tree.info.get("grammar_hash"), "seed": tree.info.get("seed"),
                 "segments": tree.n_segments, "static": tree.static},
                tree.n_segments, tree.static, len(tree.extra_times),
                sum(len(p.faces) // 2 for p in mesh.parts if p.material.startswith("leaf")),
                mesh.n_vertices, mesh.n_triangles, int(broken.sum()))
            self._last = (i, mesh)
        return self._last[1]

    def tree_options(self, i: int, info: dict | None = None) -> MeshOptions:
        """Tree i's mesh options: its detail level, its species' bark
        (`info`: tree i's, with its name; default: read from the bake)."""
        info = tree_info(self.bake.trees, i) if info is None else info
        name = str(info.get("name"))
        bark = bark_material(info.get("grammar")) if self.species else self.opts.bark
        rgb = bark_colour(bark) if self.species else self.opts.bark_rgb
        return detail_options(self.opts, self.detail_trees.get(name, self.detail), bark, rgb)

    def __iter__(self) -> Iterator[TreeMesh]:
        for i in range(len(self)):
            yield self[i]

    def all_facts(self) -> list[TreeFacts]:
        """Every tree's facts, in order (building the meshes no writer
        asked for)."""
        for i in range(len(self)):
            if i not in self.facts:
                self[i]
        return [self.facts[i] for i in range(len(self))]


def build_meshes(bake: Bake, opts: MeshOptions) -> tuple[list[TreeMesh], int]:
    """Every tree's mesh at once, and how many joints broke (split in the
    mesh): for scripts and checks; exports build them one at a time."""
    meshes = TreeMeshes(bake, opts)
    built = list(meshes)
    return built, sum(f.broken_joints for f in meshes.all_facts())
