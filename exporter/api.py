"""The public Python API, re-exported at the package root:

    import treebake
    scene = treebake.load_scene("preset:felling", duration=4.0)
    bake = treebake.bake_scene(scene)
    treebake.save_bake(bake, "out/felling/felling.npz")
    treebake.export_bake(bake, "out", formats=("glb", "usd"))
    again = treebake.load_bake("out/felling/felling.npz")

Units are SI (m, s, kg; angles in degrees in scenes); see docs/scenes.md
and docs/formats.md. Errors a user can cause raise `treebake.InputError`
(or a subclass) with a message naming the file and key.
"""

from __future__ import annotations

from pathlib import Path


def load_scene(source: str | Path, **overrides):
    """A validated `Scene` from a scene file (.toml), a grammar file
    (.lsys, baked alone in a gusty breeze), a bundled grammar's name
    (`"oak"`) or a bundled preset (`"preset:felling"`). Keyword overrides
    replace top-level keys before validation: `duration` (s), `fps`
    (frames/s), `seed`, `quality`, `frame_start`, and `wind` (m/s at 10 m)."""
    from .library import resolve
    from .scene import load_job

    if "wind" in overrides:
        overrides["wind.speed"] = overrides.pop("wind")
    return load_job(resolve(str(source)), overrides)


def bake_scene(scene, solver: str = "planar", workers: int = 1, progress=None, quality=None):
    """Grow, rig and simulate `scene` (from `load_scene`); returns the
    `Bake` (per frame and segment: base position, m, and rotation). solver:
    "planar" (the planar LOD: the linear tier, with the pymunk tier and the
    MuJoCo reference for trees that leave its range) or "full" (the MuJoCo
    reference for everything); quality: a `treebake.quality.Quality` that
    overrides the scene's; workers: processes (the result is the same for
    any number); progress(done, total) is called as it goes (growing
    numbers in any unit: done / total is the share done)."""
    from .pipeline import bake_scene as _bake

    return _bake(scene, solver=solver, quality=quality, workers=workers, progress=progress)


def save_bake(bake, path: str | Path) -> Path:
    """Write a bake as `.npz`, atomically; the same bake gives the same bytes."""
    from .bake_file import save_bake as _save

    return _save(bake, path)


def load_bake(path: str | Path):
    """Read a `.npz` bake written by `save_bake` or `treebake bake`."""
    from .bake_file import load_bake as _load

    return _load(path)


def export_bake(bake, out: str | Path = "out", formats=("glb",), name: str | None = None,
                textures: bool = True, **options):
    """Write `bake` into `out/<name>/` (name: the scene's) in `formats`
    (any of glb, gltf, obj, usd, usda, abc, preview; usd needs `treebake[usd]`,
    abc `treebake[alembic]`), with manifest.json. `textures=False` writes plain colour materials.
    Other options are ExportOptions fields (split, obj_stride,
    preview_size). Returns the ExportReport (folder, manifest, files)."""
    from .export import ExportOptions, parse_formats
    from .export import export_bake as _export

    opts = ExportOptions(formats=parse_formats(formats), textures=textures, **options)
    return _export(bake, out, name, opts)


# not `bake` / `export`: those are the names of submodules, and importing a
# submodule rebinds the package attribute of the same name
__all__ = ["bake_scene", "export_bake", "load_bake", "load_scene", "save_bake"]
