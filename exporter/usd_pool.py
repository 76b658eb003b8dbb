"""A shot's USD tree layers written by worker processes: each worker opens
the stored bake once (lazily: one tree in memory at a time), builds each
tree's mesh and writes its payload layer (exchange.usd.write_tree_layer);
the parent assembles the root stage in the trees' order. A layer depends
only on its tree, so the files are the same bytes as one process writes.

Memory: each worker holds one tree and its mesh (about 170 MB with USD's
libraries loaded); the parent holds the root stage."""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from .bake_file import load_bake
from .exchange.mesh import MeshOptions
from .exchange.usd import LayerSpec, LayerTask, TreeLayer, write_tree_layer
from .tree_meshes import TreeFacts, TreeMeshes

MIN_TREES_PER_WORKER = 50  # fewer trees a worker is not worth its start (about 1 s)
TASKS_PER_BATCH = 8  # trees sent to a worker at once


@dataclass(frozen=True)
class MeshSource:
    """What a worker needs to build the same meshes as the parent: the
    stored bake and TreeMeshes' settings."""

    bake_path: Path
    opts: MeshOptions
    detail: str
    detail_trees: tuple[tuple[str, str], ...]
    species: bool


def workers_for(trees: int, asked: int | None) -> int:
    """How many processes write `trees` tree layers: `asked` (None: the
    machine's cores), at most one per MIN_TREES_PER_WORKER trees."""
    cores = asked if asked is not None else (os.cpu_count() or 1)
    return max(1, min(cores, trees // MIN_TREES_PER_WORKER))


_STATE: dict = {}  # a worker's bake and meshes, opened once (the pool's initializer)


def _open(source: MeshSource) -> None:
    bake = load_bake(source.bake_path, lazy=True)
    _STATE["meshes"] = TreeMeshes(bake, source.opts, source.detail, source.detail_trees,
                                  source.species)


def _write(batch: list[LayerTask], spec: LayerSpec) -> list[tuple[TreeLayer, TreeFacts]]:
    meshes: TreeMeshes = _STATE["meshes"]
    out = []
    for task in batch:
        layer = write_tree_layer(meshes.bake, meshes[task.index], task, spec)
        out.append((layer, meshes.facts[task.index]))
    return out


def layer_writer(source: MeshSource, workers: int, facts: dict[int, TreeFacts]):
    """A LayerWriter (exchange.usd.export_usd's `write_layers`) that writes
    the layers in `workers` processes, yielding them in the tasks' order
    and noting each tree's facts in `facts` (for the manifest)."""

    def write(tasks: list[LayerTask], spec: LayerSpec) -> Iterator[TreeLayer]:
        batches = [tasks[k:k + TASKS_PER_BATCH] for k in range(0, len(tasks), TASKS_PER_BATCH)]
        # spawn: a fresh interpreter, nothing of the parent's USD state copied
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(workers, mp_context=context, initializer=_open,
                                 initargs=(source,)) as pool:
            # at most a few batches ahead of the one yielded: bounded memory
            pending = [(b, pool.submit(_write, b, spec)) for b in batches[:2 * workers]]
            following = 2 * workers
            while pending:
                batch, future = pending.pop(0)
                if following < len(batches):
                    pending.append((batches[following],
                                    pool.submit(_write, batches[following], spec)))
                    following += 1
                for task, (layer, fact) in zip(batch, future.result(), strict=True):
                    facts[task.index] = fact
                    yield layer

    return write
