"""OBJ sequence writer: one posed mesh per frame, `name.0001.obj` (file
number = frame_start + bake frame index, zero-padded to 4 digits or more),
one shared `name.mtl`. Frames only: extra sub-frame samples are not
written. Y up like glTF ((x, y, z) -> (x, z, -y)), metres.

Each file: `mtllib`, then per tree/projectile an `o` block with `v`, `vt`,
`vn` (one of each per vertex, so faces are `f i/i/i j/j/j k/k/k`) and
`usemtl` groups. No timestamps: the same bake gives the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..bake import Bake
from ..errors import OutputError
from ..fileio import write_bytes
from ..resources import free_disk, mib
from .axes import points_y_up
from .mesh import OBJECT_COLOUR, TreeMesh, object_mesh, pose, pose_rigid
from .textures import TextureMap


def _lines(fmt: str, array: np.ndarray) -> str:
    """`fmt` applied to each row of `array` (fast: one C-level % per file)."""
    if len(array) == 0:
        return ""
    return (fmt * len(array)) % tuple(array.ravel().tolist())


def _safe(name: str) -> str:
    return "_".join(str(name).split()) or "unnamed"


def mtl_text(materials: dict[str, tuple[float, float, float]],
             maps: dict[str, TextureMap] | None = None) -> str:
    """The .mtl: per material its colour, or with `maps` (material ->
    TextureMap: relative PNG paths) its texture as map_Kd (Kd white, so
    readers that multiply keep the texture's colour), for cutout cards
    map_d (the PNG's alpha), and a tangent-space normal map as `norm` (the
    PBR extension of MTL) and `map_Bump` (which Blender's and most
    importers read as the normal map)."""
    maps = maps or {}
    out = [f"# treebake {__version__} materials"]
    for name, colour in materials.items():
        r, g, b = (1.0, 1.0, 1.0) if name in maps else colour
        out += ["", f"newmtl {name}", "Ka 0.000000 0.000000 0.000000",
                f"Kd {r:.6f} {g:.6f} {b:.6f}", "Ks 0.000000 0.000000 0.000000",
                "Ns 10.000000", "d 1.000000", "illum 1"]
        if name in maps:
            tex = maps[name]
            out.append(f"map_Kd {tex.path}")
            if tex.cutout:
                out.append(f"map_d {tex.path}")
            if tex.normal is not None:
                out += [f"norm {tex.normal}", f"map_Bump {tex.normal}"]
    return "\n".join(out) + "\n"


@dataclass
class _Block:
    """The frame-independent text of one object: UVs and faces."""

    name: str
    mesh: TreeMesh
    vt: str
    faces: str
    n: int


def _block(name: str, mesh: TreeMesh, offset: int) -> _Block:
    vt = _lines("vt %.6f %.6f\n", mesh.uvs)
    faces = []
    for part in mesh.parts:
        if len(part.faces) == 0:
            continue
        idx = np.repeat(part.faces + offset + 1, 3, axis=1)
        faces.append(f"usemtl {part.shader}\n" + _lines("f %d/%d/%d %d/%d/%d %d/%d/%d\n", idx))
    return _Block(name, mesh, vt, "".join(faces), mesh.n_vertices)


@dataclass
class ObjResult:
    files: list[Path] = field(default_factory=list)
    frames: list[int] = field(default_factory=list)  # bake frame indices written


def frame_digits(frames: int) -> int:
    return max(4, len(str(frames)))


def export_obj(bake: Bake, meshes: list[TreeMesh], out: str | Path, name: str,
               stride: int = 1, progress: Callable[[int, int], None] | None = None,
               frame_start: int = 1, maps: dict[str, TextureMap] | None = None
               ) -> ObjResult:
    """Write `out/name.mtl` and `out/name.NNNN.obj` for every `stride`-th
    frame, NNNN = frame_start + the bake's frame index; `maps`: textures
    for the .mtl (mtl_text)."""
    if stride < 1:
        raise ValueError("stride must be >= 1")
    out = Path(out)
    materials: dict[str, tuple[float, float, float]] = {}
    blocks: list[_Block] = []
    offset = 0
    for tree, mesh in zip(bake.trees, meshes):
        for part in mesh.parts:
            materials.setdefault(part.shader, part.colour)
        blocks.append(_block(_safe(tree.name), mesh, offset))
        offset += mesh.n_vertices
    objects = []
    if bake.objects is not None:
        o = bake.objects
        for k, (shape, size) in enumerate(zip(o.shapes, o.sizes)):
            mesh = object_mesh(shape, float(size))
            materials.setdefault("object", OBJECT_COLOUR)
            objects.append(_block(f"projectile_{k}", mesh, offset))
            offset += mesh.n_vertices
    result = ObjResult()
    mtl = f"{name}.mtl"
    frames = list(range(0, len(bake.times), stride))
    digits = frame_digits(frame_start + len(bake.times) - 1)

    def frame_text(f: int) -> bytes:
        header = (f"# treebake {__version__}: {bake.meta.get('scene', name)}, "
                  f"frame {frame_start + f}, "
                  f"t = {float(bake.times[f]):.6f} s, metres, Y up\n")
        parts = [header, f"mtllib {mtl}\n"]
        for tree, blk in zip(bake.trees, blocks):
            p, n = pose(blk.mesh, tree, f)
            parts.append(_object_text(blk, p, n))
        for k, blk in enumerate(objects):
            p, n = pose_rigid(blk.mesh, bake.objects.positions[f, k].astype(np.float64),
                              bake.objects.rotations[f, k])
            parts.append(_object_text(blk, p, n))
        return "".join(parts).encode("ascii")

    first = frame_text(frames[0])
    check_room(out, len(first), len(frames), stride)
    result.files.append(write_bytes(out / mtl, mtl_text(materials, maps).encode("ascii")))
    for done, f in enumerate(frames):
        path = out / f"{name}.{frame_start + f:0{digits}d}.obj"
        result.files.append(write_bytes(path, first if done == 0 else frame_text(f)))
        result.frames.append(f)
        if progress is not None:
            progress(done + 1, len(frames))
    return result


def check_room(out: Path, frame_bytes: int, frames: int, stride: int) -> None:
    """Refuse (OutputError), before writing any of it, a sequence of
    `frames` files of about `frame_bytes` each (the first frame's size:
    every frame has the same vertices) that the free disk at `out` cannot
    hold: a 1,000-tree forest's 241 frames are 62 GB."""
    need = frame_bytes * frames
    free = free_disk(out)
    if free is not None and need > free:
        raise OutputError(
            f"{out}: the OBJ sequence needs about {mib(need)} ({frames} frames of "
            f"{mib(frame_bytes)}) and the disk has {mib(free)} free; write every n-th "
            f"frame (--stride, now {stride}), fewer trees, or glb/usd, which keep the motion "
            "as animation")


def _object_text(blk: _Block, positions: np.ndarray, normals: np.ndarray) -> str:
    v = _lines("v %.6f %.6f %.6f\n", points_y_up(positions))
    vn = _lines("vn %.5f %.5f %.5f\n", points_y_up(normals))
    return f"o {blk.name}\n{v}{blk.vt}{vn}{blk.faces}"
