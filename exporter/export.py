"""Export a Bake to files: glTF (.glb / .gltf), OBJ sequences, USD, Alembic, previews,
into `out/<job>/` with a `manifest.json` (inputs, hashes, settings, files,
frame range, sizes, keyframe reduction). The CLI's `export` and
`bake --format` call `export_bake`. docs/formats.md describes every file.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from . import __version__
from .bake import Bake
from .bake_file import StoredTrees, check_finite, tree_info, tree_leaf_fields
from .errors import InputError, TreebakeError
from .exchange.anim import ReduceOptions
from .exchange.textures import TextureMap
from .exchange.mesh import DETAIL, MeshOptions, TreeMesh, part_materials_of
from .fileio import atomic_path, write_bytes, write_text
from .heap import keep_heap_top
from .sampling import FAST_TURN_DEG
from .tree_meshes import TreeFacts, TreeMeshes

FORMATS = ("glb", "gltf", "obj", "usd", "usda", "abc", "preview")
MAX_FRAME_START = 1_000_000
ALIASES = {"npz": None}  # the bake itself: always written by `treebake bake`

Progress = Callable[[str, int, int], None]  # (stage, done, total)


@dataclass(frozen=True)
class ExportOptions:
    """formats: any of FORMATS; split: one glTF file per tree;
    trees_per_file: glTF files of at most that many trees (None: one file
    up to GLTF_TREES_PER_FILE trees, files of that many beyond); usd_layers:
    "one" file, or a root stage with a payload layer per "tree" ("auto":
    per tree past USD_LAYER_TREES trees);
    obj_stride: write every n-th frame of OBJ sequences; preview_size: px
    per view panel; frame_start: the number of the bake's first frame in
    every format (None: the bake's, from its scene; default 1); textures:
    generated bark and leaf-card textures (False: plain colours); detail:
    the level (mesh.DETAIL: hero, default, far) of every tree's bark tubes,
    foliage cards and textures, `detail_trees` ((tree name, level), ...)
    overriding it per tree (geometry only: textures follow `detail`).
    Export-time only: the bake does not depend on it. workers: processes
    writing a stored bake's USD tree layers and glTF files (export_pool.py;
    the same bytes)."""

    formats: tuple[str, ...] = ("glb",)
    mesh: MeshOptions = field(default_factory=MeshOptions)
    reduce: ReduceOptions = field(default_factory=ReduceOptions)
    split: bool = False
    obj_stride: int = 1
    preview_size: int = 256
    frame_start: int | None = None
    textures: bool = True
    trees_per_file: int | None = None  # glTF: at most this many trees a file (None: auto)
    usd_layers: str = "auto"  # "one" file, a layer per "tree", or "auto"
    detail: str = "default"  # mesh.DETAIL level
    detail_trees: tuple[tuple[str, str], ...] = ()  # (tree name, level) overrides
    # processes writing USD tree layers (None: the cores; the CLI's default). 1 by
    # default: more start fresh interpreters (spawn), which import a calling
    # script's __main__, so a script asks for them under `if __name__ == ...`
    workers: int | None = 1


# a shot of more trees is written as glTF files of this many trees and as a
# USD root stage with a payload layer per tree: an export holds one file's
# trees, a DCC opens the stage at once (set per export: --trees-per-file,
# --usd-layers)
GLTF_TREES_PER_FILE = 250
USD_LAYER_TREES = 100


@dataclass
class ExportReport:
    folder: Path
    manifest: dict
    files: list[Path] = field(default_factory=list)


def parse_formats(text: str | list[str] | tuple[str, ...]) -> tuple[str, ...]:
    """"glb,obj" -> ("glb", "obj"), checked; "npz" is accepted and dropped."""
    items = text.split(",") if isinstance(text, str) else list(text)
    out: list[str] = []
    for raw in items:
        f = raw.strip().lower()
        if not f:
            continue
        if f in ALIASES:
            continue
        if f not in FORMATS:
            how = " (comma-separated)" if isinstance(text, str) else ""
            raise InputError(f"unknown export format {raw!r}; choose from: "
                             f"{', '.join(FORMATS)}{how}, or npz (the bake itself)")
        if f not in out:
            out.append(f)
    return tuple(out)


def parse_detail(text: str) -> dict:
    """"far,oak=hero" -> {"detail": "far", "detail_trees": (("oak", "hero"),)}
    (levels checked by check_options)."""
    level, trees = "default", []
    for item in (x.strip() for x in str(text).split(",")):
        if "=" in item:
            tree, _, lvl = item.partition("=")
            trees.append((tree.strip(), lvl.strip().lower()))
        elif item:
            level = item.lower()
    return {"detail": level, "detail_trees": tuple(trees)}


def check_options(opts: ExportOptions) -> None:
    m, r = opts.mesh, opts.reduce
    if not 3 <= m.radial <= 64:
        raise InputError(f"--radial must be in 3..64, got {m.radial}")
    if not 1 <= m.rings <= 16:
        raise InputError(f"--rings must be in 1..16, got {m.rings}")
    if opts.obj_stride < 1:
        raise InputError(f"--stride must be >= 1, got {opts.obj_stride}")
    if not (r.position_tolerance > 0 and math.isfinite(r.position_tolerance)):
        raise InputError(f"--position-tolerance must be > 0 m, got {r.position_tolerance}")
    if not (0 < r.angle_tolerance < math.pi):
        raise InputError(f"--angle-tolerance must be in (0, 180) degrees, got "
                         f"{math.degrees(r.angle_tolerance)}")
    if not 64 <= opts.preview_size <= 2048:
        raise InputError(f"--size must be in 64..2048 px, got {opts.preview_size}")
    if opts.trees_per_file is not None and opts.trees_per_file < 1:
        raise InputError(f"--trees-per-file must be >= 1, got {opts.trees_per_file}")
    if opts.usd_layers not in ("auto", "one", "tree"):
        raise InputError(f"--usd-layers must be auto, one or tree, got {opts.usd_layers!r}")
    if opts.workers is not None and not 1 <= opts.workers <= 256:
        raise InputError(f"--workers must be in 1..256, got {opts.workers}")
    for tree, level in (("", opts.detail), *opts.detail_trees):
        if level not in DETAIL:
            raise InputError(f"--detail {tree + '=' if tree else ''}{level!r}: the level must "
                             f"be one of {', '.join(DETAIL)}")
    if opts.frame_start is not None and not 0 <= opts.frame_start <= MAX_FRAME_START:
        raise InputError(f"--frame-start must be in 0..{MAX_FRAME_START}, got "
                         f"{opts.frame_start}")
    check_extras(opts.formats)


def check_extras(formats: tuple[str, ...]) -> None:
    """InputError (exit 2) naming the extra to install when a format needs
    an optional package that is missing: checked with the options, before
    any simulation."""
    if "abc" in formats:
        from .exchange.abc import require

        require()
    if "usd" in formats or "usda" in formats:
        from .exchange.usd import require as require_usd

        require_usd()


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# the manifest's first keys, in this order; the writers' own follow
_MANIFEST_ORDER = ("tool", "job", "inputs", "settings", "frames", "sizes")


def _inputs(bake: Bake, bake_path: Path | None, facts: list[TreeFacts]) -> dict:
    meta = bake.meta
    out = {"bake": None, "scene": meta.get("scene"), "scene_hash": meta.get("scene_hash"),
           "baked_by": meta.get("tool"), "solver": meta.get("solver"), "seed": meta.get("seed"),
           "trees": [f.inputs for f in facts]}
    if bake_path is not None:
        out["bake"] = {"file": bake_path.name, "sha256": sha256(bake_path),
                       "bytes": bake_path.stat().st_size}
    return out


def frame_start(bake: Bake, opts: ExportOptions) -> int:
    """The number the bake's first frame gets in the files."""
    return int(bake.meta.get("frame_start", 1)) if opts.frame_start is None else opts.frame_start


def _settings(opts: ExportOptions) -> dict:
    m, r = opts.mesh, opts.reduce
    return {"formats": list(opts.formats), "radial": m.radial, "rings_per_segment": m.rings,
            "leaves": m.leaves, "min_radius_m": m.min_radius, "bark_tile_m": m.bark_tile,
            "keyframe_reduction": r.enabled, "position_tolerance_m": r.position_tolerance,
            "angle_tolerance_deg": round(math.degrees(r.angle_tolerance), 9),
            "split": opts.split, "trees_per_file": opts.trees_per_file,
            "usd_layers": opts.usd_layers, "obj_stride": opts.obj_stride,
            "frame_start": opts.frame_start, "textures": opts.textures,
            "detail": opts.detail, "detail_trees": dict(opts.detail_trees),
            "preview_size_px": opts.preview_size, "up_axis": "Y", "units": "m"}


def _rounded(report: dict) -> dict:
    out = dict(report)
    for k in ("max_position_error_m", "max_angle_error_rad"):
        if k in out:
            out[k] = float(f"{out[k]:.4g}")
    if "max_angle_error_rad" in out:
        out["max_angle_error_deg"] = float(f"{math.degrees(out['max_angle_error_rad']):.4g}")
    if out.get("keys_full"):
        out["keys_kept_fraction"] = round(out["keys_written"] / out["keys_full"], 4)
    return out


def _textures(bake: Bake, opts: ExportOptions) -> dict:
    """Material name -> its generated Texture (None: a plain colour), for
    the materials of every tree's parts (read from the trees' leaf types
    alone: no mesh is built)."""
    if not opts.textures:
        return {}
    from .exchange.materials import texture_for

    names = set()
    meshes = TreeMeshes(bake, opts.mesh, opts.detail, opts.detail_trees, species=True)
    for i in range(len(bake.trees)):
        names.update(part_materials_of(*tree_leaf_fields(bake.trees, i),
                                       meshes.tree_options(i)))
    return {n: texture_for(n, opts.detail) for n in sorted(names)}


@dataclass(frozen=True)
class _Job:
    """What the format writers share: the bake and its meshes, the output
    folder and job name, the options, the first frame's number, material ->
    texture (None: plain colour), material -> texture file, and progress."""

    bake: Bake
    meshes: list[TreeMesh]
    folder: Path
    name: str
    opts: ExportOptions
    first: int
    textures: dict
    maps: dict
    tick: Progress


def export_bake(bake: Bake, out: str | Path = "out", name: str | None = None,
                opts: ExportOptions | None = None, bake_path: str | Path | None = None,
                progress: Progress | None = None) -> ExportReport:
    """Write the formats of `opts` into `out/<name>/` (name: the bake's
    scene) and its manifest.json. Same bake and options -> same bytes."""
    opts = opts or ExportOptions()
    check_options(opts)
    if not opts.formats:
        raise InputError("no export format given")
    keep_heap_top()  # fewer page faults (heap.py)
    if not bake.trees:
        raise InputError("the bake has no trees")
    if not isinstance(bake.trees, StoredTrees):  # a stored tree is checked as it is read
        check_finite(bake)  # never a file full of NaN
    name = name or str(bake.meta.get("scene") or "bake")
    if not name or any(c in name for c in "/\\") or name in (".", ".."):
        raise InputError(f"job name {name!r} cannot be a folder name")
    folder = Path(out) / name
    names = {str(tree_info(bake.trees, i).get("name")) for i in range(len(bake.trees))}
    for tree, _ in opts.detail_trees:
        if tree not in names:
            raise InputError(f"--detail {tree}=...: the bake has no tree named {tree!r}")
    bake_path = Path(bake_path) if bake_path is not None else None
    tick = progress or (lambda stage, done, total: None)
    # species' barks with the textures; --no-textures keeps the one plain "bark"
    meshes = TreeMeshes(bake, opts.mesh, opts.detail, opts.detail_trees, species=opts.textures)
    manifest: dict = {"tool": f"treebake {__version__}", "job": name,
                      "settings": _settings(opts), "frames": {}}
    n = len(bake.times)
    first = frame_start(bake, opts)
    textures = _textures(bake, opts)
    maps = {m: TextureMap(f"textures/{t.name}", t.cutout,
                          None if t.normal is None else f"textures/{t.normal.name}")
            for m, t in textures.items() if t is not None}
    job = _Job(bake, meshes, folder, name, opts, first, textures, maps, tick)
    files = _write_texture_pngs(job)
    files += _write_gltf(job, manifest)
    files += _write_obj(job, manifest)
    files += _write_usd(job, manifest)
    files += _write_abc(job, manifest)
    if "preview" in opts.formats:
        files += write_previews(bake, folder, name, opts.preview_size,
                                progress=lambda d, t: tick("preview", d, t))
    facts = meshes.all_facts()
    manifest["inputs"] = _inputs(bake, bake_path, facts)
    manifest["frames"] = {"count": n, "fps": bake.fps, "first": first, "last": first + n - 1,
                          "start_s": float(bake.times[0]), "end_s": float(bake.times[-1]),
                          "gltf_start_s": first / bake.fps,
                          "extra_samples": sum(f.extra_samples for f in facts),
                          **manifest["frames"]}
    manifest["sizes"] = {
        "trees": len(facts), "animated_trees": sum(not f.static for f in facts),
        "segments": sum(f.segments for f in facts),
        "joints": sum(f.segments for f in facts if not f.static),
        "broken_joints": sum(f.broken_joints for f in facts),
        "vertices": sum(f.vertices for f in facts),
        "triangles": sum(f.triangles for f in facts),
        "leaf_quads": sum(f.leaf_quads for f in facts),
        "projectiles": 0 if bake.objects is None else len(bake.objects.sizes)}
    manifest = {k: manifest[k] for k in _MANIFEST_ORDER if k in manifest} | manifest
    root = folder.resolve()
    manifest["files"] = sorted(
        ({"path": p.resolve().relative_to(root).as_posix(), "bytes": p.stat().st_size,
          "sha256": sha256(p)} for p in files), key=lambda e: e["path"])
    manifest["total_bytes"] = sum(e["bytes"] for e in manifest["files"])
    man = write_text(folder / "manifest.json", json.dumps(manifest, indent=2) + "\n")
    return ExportReport(folder, manifest, [*files, man])


def remove_exports(folder: Path, bake_file: str) -> int:
    """Remove what an export of the bake `bake_file` (its file name) wrote
    into `folder`: every file its manifest.json lists (inside the folder;
    never a bake), the manifest, and the subfolders left empty. For a new
    bake written over that file: its exports would pass for the new one's.
    An export of another bake is left alone. Returns the files removed."""
    manifest = folder / "manifest.json"
    try:
        record = json.loads(manifest.read_text())
        listed = [str(f["path"]) for f in record["files"]]
        source = (record.get("inputs") or {}).get("bake") or {}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return 0
    if source.get("file") not in (None, bake_file):
        return 0
    root, removed, parents = folder.resolve(), 0, set()
    for rel in listed:
        path = (folder / rel).resolve()
        if root not in path.parents or path.suffix == ".npz" or not path.is_file():
            continue
        path.unlink()
        removed += 1
        parents.update(p for p in path.parents if root in p.parents)
    manifest.unlink(missing_ok=True)
    for sub in sorted(parents, key=lambda p: len(p.parts), reverse=True):
        with contextlib.suppress(OSError):  # not empty: something else lives there
            sub.rmdir()
    return removed


def _write_texture_pngs(job: _Job) -> list[Path]:
    """The texture PNGs the OBJ and USD files reference."""
    # PNGs beside the files that reference them (obj/textures/, textures/): a
    # reader need not follow paths out of its file's folder (trimesh refuses)
    pngs = {t.name: t.png for t in job.textures.values() if t is not None}
    pngs |= {t.normal.name: t.normal.png for t in job.textures.values()
             if t is not None and t.normal is not None}
    files: list[Path] = []
    for sub, fmts in (("obj", ("obj",)), ("", ("usd", "usda"))):
        if any(f in job.opts.formats for f in fmts):
            files += [write_bytes(job.folder / sub / "textures" / n, png)
                      for n, png in pngs.items()]
    return files


def _trees_per_file(job: _Job) -> int | None:
    """Trees a glTF file or OBJ sequence holds: --trees-per-file, else
    GLTF_TREES_PER_FILE past that many trees, else all (None)."""
    per_file = job.opts.trees_per_file
    if per_file is None and len(job.bake.trees) > GLTF_TREES_PER_FILE:
        per_file = GLTF_TREES_PER_FILE
    return per_file


def _write_gltf(job: _Job, manifest: dict) -> list[Path]:
    """.glb and .gltf files; their keyframe reduction goes into the manifest."""
    opts, files = job.opts, []
    for fmt in ("glb", "gltf"):
        if fmt in opts.formats:
            from .exchange.gltf import export_gltf

            job.tick(fmt, 0, len(job.bake.trees))
            per_file = _trees_per_file(job)
            files_of = -(-len(job.bake.trees) // per_file) if per_file else 1
            res = export_gltf(job.bake, job.meshes, job.folder, job.name, binary=fmt == "glb",
                              split=opts.split, opts=opts.reduce, frame_start=job.first,
                              textures=job.textures, trees_per_file=per_file,
                              write_files=_pool(job, "gltf", len(job.bake.trees) if opts.split
                                                else files_of),
                              progress=lambda d, t, f=fmt: job.tick(f, d, t))
            files += res.files
            manifest["animation"] = _rounded(res.animation)
            manifest["animation"]["tolerances"] = {
                "position_m": opts.reduce.position_tolerance,
                "angle_deg": round(math.degrees(opts.reduce.angle_tolerance), 9)}
    return files


def _write_obj(job: _Job, manifest: dict) -> list[Path]:
    """The OBJ sequences in obj/ (one, or one per `trees_per_file` trees as
    glTF's files); their frame numbers go into the manifest."""
    if "obj" not in job.opts.formats:
        return []
    from .exchange.obj import export_obj

    res = export_obj(job.bake, job.meshes, job.folder / "obj", job.name, job.opts.obj_stride,
                     progress=lambda d, t: job.tick("obj", d, t), frame_start=job.first,
                     maps=job.maps, trees_per_file=_trees_per_file(job))
    manifest["frames"]["obj"] = {"stride": job.opts.obj_stride,
                                 "files": len(res.frames) * res.parts,
                                 "first": res.frames[0] + job.first,
                                 "last": res.frames[-1] + job.first}
    if res.parts > 1:
        manifest["frames"]["obj"]["sequences"] = res.parts
    return res.files


def _write_usd(job: _Job, manifest: dict) -> list[Path]:
    """.usd and .usda files, validated; their time codes go into the manifest."""
    files = []
    for fmt in ("usd", "usda"):
        if fmt in job.opts.formats:
            from .exchange.usd import export_usd

            layers = job.opts.usd_layers
            if layers == "auto":
                layers = "tree" if len(job.bake.trees) > USD_LAYER_TREES else "one"
            res = export_usd(job.bake, job.meshes, job.folder, job.name, ascii=fmt == "usda",
                             progress=lambda d, t, f=fmt: job.tick(f, d, t),
                             frame_start=job.first, maps=job.maps, layers=layers,
                             write_layers=_pool(job, "usd", len(job.bake.trees))
                             if layers == "tree" else None)
            if res.validation_errors:
                raise TreebakeError("USD validation failed:\n  " +
                                    "\n  ".join(res.validation_errors[:20]))
            files += res.files
            manifest["usd"] = {"time_codes": list(res.time_codes), "joints": res.joints,
                               "subframe_codes": res.subframe_codes,
                               "subframe_turn_deg": FAST_TURN_DEG,
                               "validation_errors": 0, "up_axis": "Y", "meters_per_unit": 1.0,
                               "layers": layers, "tree_layers_validated": res.layers_checked}
    return files


def _pool(job: _Job, kind: str, files: int):
    """Worker processes (export_pool.py) for USD tree layers (`kind`
    "usd") or glTF files ("gltf") when the bake is stored (each worker
    opens it) and there is work for more than one: `files` files of the
    shot's trees; else None (this process writes them)."""
    from .export_pool import MeshSource, file_writer, layer_writer, workers_for

    trees = job.bake.trees
    workers = min(workers_for(len(trees), job.opts.workers), files)
    if not isinstance(trees, StoredTrees) or workers < 2:
        return None
    m = job.meshes
    source = MeshSource(trees.path, m.opts, m.detail, tuple(m.detail_trees.items()), m.species)
    return (layer_writer if kind == "usd" else file_writer)(source, workers, m.facts)


def _write_abc(job: _Job, manifest: dict) -> list[Path]:
    """The Alembic archive; its time sampling and contents go into the manifest."""
    if "abc" not in job.opts.formats:
        return []
    from .exchange.abc import export_abc, library_version

    res = export_abc(job.bake, job.meshes, job.folder, job.name, frame_start=job.first,
                     progress=lambda d, t: job.tick("abc", d, t))
    n = len(job.bake.times)
    manifest["alembic"] = {"frames": [job.first, job.first + n - 1], "start_s": res.start_s,
                           "frame_s": res.step_s, "end_s": (job.first + n - 1) / job.bake.fps,
                           "xforms": res.xforms, "meshes": res.meshes,
                           "point_caches": res.point_caches, "up_axis": "Y",
                           "units": "m", "winding": "clockwise", "library": library_version()}
    return res.files


def write_previews(bake: Bake, folder: Path, name: str, size: int = 256,
                   progress: Callable[[int, int], None] | None = None) -> list[Path]:
    """`name.contact.png` (12 frames) and `name.gif` (the whole bake)."""
    from .preview import animated_gif, contact_sheet

    sheet = contact_sheet(bake, size=size)
    png = folder / f"{name}.contact.png"
    with atomic_path(png) as tmp:
        sheet.save(tmp, format="PNG")
    gif = write_bytes(folder / f"{name}.gif", animated_gif(bake, size=size, progress=progress))
    return [png, gif]
