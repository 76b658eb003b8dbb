"""OBJ sequence writer: one posed mesh per frame, `name.0001.obj` (file
number = frame_start + bake frame index, zero-padded to 4 digits or more),
one shared `name.mtl`; past `trees_per_file` trees, a sequence per that
many trees (`name.part0001.0001.obj`, ...), written one after the other.
Frames only: extra sub-frame samples are not written. Y up like glTF
((x, y, z) -> (x, z, -y)), metres.

Each file: `mtllib`, then per tree/projectile an `o` block with `v`, `vt`,
`vn` (one of each per vertex, so faces are `f i/i/i j/j/j k/k/k`) and
`usemtl` groups. No timestamps: the same bake gives the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
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
    parts: int = 1  # sequences of trees_per_file trees each (1: every tree in one)


def frame_digits(frames: int) -> int:
    return max(4, len(str(frames)))


@dataclass
class _Part:
    """One sequence of an export: its file stem, trees and whether it holds
    the projectiles."""

    stem: str
    trees: range
    objects: bool


def _parts(count: int, name: str, trees_per_file: int | None) -> list[_Part]:
    if not trees_per_file or count <= trees_per_file:
        return [_Part(name, range(count), True)]
    starts = range(0, count, trees_per_file)
    digits = max(4, len(str(len(starts))))
    return [_Part(f"{name}.part{k + 1:0{digits}d}", range(a, min(a + trees_per_file, count)),
                  k == 0) for k, a in enumerate(starts)]


def export_obj(bake: Bake, meshes: Sequence[TreeMesh], out: str | Path, name: str,
               stride: int = 1, progress: Callable[[int, int], None] | None = None,
               frame_start: int = 1, maps: dict[str, TextureMap] | None = None,
               trees_per_file: int | None = None) -> ObjResult:
    """Write `out/name.mtl` and `out/name.NNNN.obj` for every `stride`-th
    frame, NNNN = frame_start + the bake's frame index; `maps`: textures
    for the .mtl (mtl_text). `trees_per_file` N, when the bake has more
    trees: a sequence per N trees, `name.part0001.NNNN.obj`, ... (the
    projectiles in the first), written one after the other, each holding
    only its trees in memory; one `name.mtl`. Every sequence's size is
    checked against the free disk before any file is written."""
    if stride < 1:
        raise ValueError("stride must be >= 1")
    out = Path(out)
    parts = _parts(len(bake.trees), name, trees_per_file)
    frames = list(range(0, len(bake.times), stride))
    digits = frame_digits(frame_start + len(bake.times) - 1)
    materials: dict[str, tuple[float, float, float]] = {}
    # every sequence's first frame, measured before any file (the disk check
    # covers the whole export); a part's trees are let go once measured,
    # unless there is one part (then its first frame is kept to be written)
    need, kept, first = 0, None, None
    for part in parts:
        seq = _Sequence(bake, meshes, part, name, frame_start, materials)
        text = seq.text(frames[0])
        need += len(text)
        if len(parts) == 1:
            kept, first = seq, text
        del seq, text
    check_room(out, need, len(frames), stride)
    result = ObjResult(parts=len(parts))
    result.files.append(write_bytes(out / f"{name}.mtl",
                                    mtl_text(materials, maps).encode("ascii")))
    written = 0
    for part in parts:
        seq = kept or _Sequence(bake, meshes, part, name, frame_start, materials)
        for f in frames:
            path = out / f"{part.stem}.{frame_start + f:0{digits}d}.obj"
            text = first if f == frames[0] and first is not None else seq.text(f)
            result.files.append(write_bytes(path, text))
            written += 1
            if progress is not None:
                progress(written, len(frames) * len(parts))
    result.frames = frames
    return result


class _Sequence:
    """The trees of one part (read once) and their frame-independent text;
    `text(f)`: the OBJ file of bake frame f. Notes each material's colour
    in `materials`."""

    def __init__(self, bake: Bake, meshes: Sequence[TreeMesh], part: _Part, name: str,
                 frame_start: int, materials: dict) -> None:
        self.bake, self.name, self.frame_start = bake, name, frame_start
        self.trees, self.blocks = [], []
        offset = 0
        for i in part.trees:  # each tree read once: its mesh is built from the tree just read
            tree = bake.trees[i]
            mesh = meshes[i]
            for p in mesh.parts:
                materials.setdefault(p.shader, p.colour)
            self.trees.append(tree)
            self.blocks.append(_block(_safe(tree.name), mesh, offset))
            offset += mesh.n_vertices
        self.objects = []
        if part.objects and bake.objects is not None:
            o = bake.objects
            for k, (shape, size) in enumerate(zip(o.shapes, o.sizes)):
                mesh = object_mesh(shape, float(size))
                materials.setdefault("object", OBJECT_COLOUR)
                self.objects.append(_block(f"projectile_{k}", mesh, offset))
                offset += mesh.n_vertices

    def text(self, f: int) -> bytes:
        bake = self.bake
        header = (f"# treebake {__version__}: {bake.meta.get('scene', self.name)}, "
                  f"frame {self.frame_start + f}, "
                  f"t = {float(bake.times[f]):.6f} s, metres, Y up\n")
        parts = [header, f"mtllib {self.name}.mtl\n"]
        for tree, blk in zip(self.trees, self.blocks):
            p, n = pose(blk.mesh, tree, f)
            parts.append(_object_text(blk, p, n))
        for k, blk in enumerate(self.objects):
            p, n = pose_rigid(blk.mesh, bake.objects.positions[f, k].astype(np.float64),
                              bake.objects.rotations[f, k])
            parts.append(_object_text(blk, p, n))
        return "".join(parts).encode("ascii")


def check_room(out: Path, frame_bytes: int, frames: int, stride: int) -> None:
    """Refuse (OutputError), before writing any of it, an OBJ export of
    `frames` frames of about `frame_bytes` each (the first frame's size,
    every sequence's together: every frame has the same vertices) that the
    free disk at `out` cannot hold: a 1,000-tree forest's 241 frames are
    62 GB."""
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
