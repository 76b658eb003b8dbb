"""A shot's files written by worker processes: USD tree layers
(exchange.usd.write_tree_layer) and glTF files of many trees
(exchange.gltf.write_gltf_file). Each worker opens the stored bake once
(lazily: the trees it is given, as it needs them) and builds their meshes;
the parent takes the results in order (the USD root stage, the glTF
keyframe report). A layer or file depends only on its trees, so the bytes
are those one process writes.

Memory: a USD worker holds one tree and its mesh (about 170 MB with USD's
libraries loaded); a glTF worker one file's trees (about 1 GB for 250
forest trees)."""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from .bake_file import load_bake
from .exchange.gltf import GltfFile, GltfSettings, GltfWritten, write_gltf_file
from .exchange.mesh import MeshOptions
from .exchange.usd import LayerSpec, LayerTask, TreeLayer, write_tree_layer
from .heap import keep_heap_top
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
    keep_heap_top()
    bake = load_bake(source.bake_path, lazy=True)
    _STATE["meshes"] = TreeMeshes(bake, source.opts, source.detail, source.detail_trees,
                                  source.species)


def _write_layers(batch: list[LayerTask], spec: LayerSpec) -> list[tuple[TreeLayer, dict]]:
    meshes: TreeMeshes = _STATE["meshes"]
    out = []
    for task in batch:
        layer = write_tree_layer(meshes.bake, meshes[task.index], task, spec)
        out.append((layer, {task.index: meshes.facts[task.index]}))
    return out


def _write_gltf(batch: list[GltfFile], settings: GltfSettings) -> list[tuple[GltfWritten, dict]]:
    meshes: TreeMeshes = _STATE["meshes"]
    out = []
    for job in batch:
        written = write_gltf_file(meshes.bake, meshes, job, settings)
        out.append((written, {i: meshes.facts[i] for i in job.trees}))
    return out


def _in_order(source: MeshSource, workers: int, work, batches: list[list], settings,
              facts: dict[int, TreeFacts]) -> Iterator:
    """`work(batch, settings)` over the batches in `workers` processes, a
    few batches ahead of the one yielded (bounded memory); each result in
    order, its trees' facts noted in `facts`."""
    # spawn: a fresh interpreter, nothing of the parent's USD state copied
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_open,
                             initargs=(source,)) as pool:
        ahead = 2 * workers
        pending = [pool.submit(work, b, settings) for b in batches[:ahead]]
        following = ahead
        while pending:
            done = pending.pop(0).result()
            if following < len(batches):
                pending.append(pool.submit(work, batches[following], settings))
                following += 1
            for result, noted in done:
                facts.update(noted)
                yield result


def layer_writer(source: MeshSource, workers: int, facts: dict[int, TreeFacts]):
    """A LayerWriter (exchange.usd.export_usd's `write_layers`) that writes
    the layers in `workers` processes, yielding them in the tasks' order
    and noting each tree's facts in `facts` (for the manifest)."""

    def write(tasks: list[LayerTask], spec: LayerSpec) -> Iterator[TreeLayer]:
        batches = [tasks[k:k + TASKS_PER_BATCH] for k in range(0, len(tasks), TASKS_PER_BATCH)]
        return _in_order(source, workers, _write_layers, batches, spec, facts)

    return write


def file_writer(source: MeshSource, workers: int, facts: dict[int, TreeFacts]):
    """A FileWriter (exchange.gltf.export_gltf's `write_files`): each glTF
    file in a worker process, yielded in the files' order, each tree's
    facts noted in `facts`."""

    def write(jobs: list[GltfFile], settings: GltfSettings) -> Iterator[GltfWritten]:
        return _in_order(source, workers, _write_gltf, [[job] for job in jobs], settings, facts)

    return write
