"""Alembic writer (optional dependency `alembic3d`, `pip install
'treebake[alembic]'`): one Ogawa archive `<job>.abc` holding the segments
as an `OXform` hierarchy with their animation, and the tree meshes as
point caches (`OPolyMesh` whose vertex positions and normals are sampled
every frame). Units metres, Y up ((x, y, z) -> (x, z, -y), like glTF and
USD, axes.py); Alembic has no up-axis field: Y up is its convention, and
Blender's and Houdini's importers read it so.

Layout (the glTF's node hierarchy and names, names.py):

- animated tree `T`: an `OXform` `/T` (identity) whose descendants are the
  joint xforms, one per segment, parented like the segments and named like
  the glTF joint nodes (`/T/T_trunk_s0/T_trunk_s1/...`); a joint's
  transform is its segment's base with the world axes as rest orientation,
  local to its parent joint, as one matrix op (double) per frame;
  `/T_mesh/T_geo`: the tree's mesh as a point cache (`/T_mesh` identity).
- static tree `T`: `/T/T_geo`, a constant mesh in world coordinates.
- projectile k: `/projectile_<k>` (its matrix per frame) with a constant
  box or sphere mesh `box_300mm` under it.

Why point caches and not rigid pieces under the joint xforms: Alembic has
no skinning, so a mesh parented under a joint xform can only move rigidly
with it; the bark would split or kink at every joint (the glTF and USD
skin blend the two segments there, docs/formats.md) and a tree would be
one object per segment (thousands in Blender's outliner). A point cache
stores the skinned mesh itself, frame by frame, the vertices of the OBJ
sequence (the glTF's linear-blend skinning): what SpeedTree's and
Houdini's Alembic exports of deforming vegetation are, and what Blender
(Mesh Sequence Cache modifier), Houdini (Alembic SOP), Maya and Nuke read
natively. The joint xforms come too, for constraining things to branches
and for the transform checks. The cost is size: positions and normals,
12 bytes each per vertex per frame.

Mesh: triangles, one `OPolyMesh` per tree; Alembic winds polygons
clockwise (seen from outside; Blender's and Houdini's importers reverse
them), so each triangle (a, b, c) of the mesh is written (a, c, b).
`uv` and `N` are indexed face-varying geom params (values per vertex,
indices = the face vertices), v up; one face set per material (`bark`,
`leaf`, ...), which Blender turns into material slots of those names.
Alembic has no standard materials: colours and textures are not written.

Time: one uniform time sampling, `1 / fps` s per frame, starting at
`frame_start / fps` s: the bake's frame f is sampled at (frame_start + f)
/ fps s, the glTF's key time, so an importer's frame = time x fps is the
frame number N = frame_start + f of every format; the archive's range is
frame_start / fps ... (frame_start + F - 1) / fps s. Frames only: the
bake's extra sub-frame samples are not written (like the OBJ sequence).

Bytes: the same bake and options give the same bytes with the same
alembic3d build. The archive is written with `OArchive`, not
`CreateArchiveWithInfo` (which stamps the date); Alembic still records its
own version and build date (`_ai_AlembicVersion`), so another build of
the library writes other bytes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..bake import Bake
from ..errors import InputError
from ..fileio import atomic_path
from ..names import joint_names
from ..rotations import matrices_from_quaternions, qnormalize
from .anim import local_transforms
from .axes import points_y_up, quats_y_up
from .mesh import TreeMesh, object_mesh, pose

MISSING = ("--format abc (Alembic) needs the optional dependency alembic3d: "
           "pip install 'treebake[alembic]'")


def _modules():
    """alembic3d's Abc, AbcGeom, AbcCoreAbstract and its bundled imath;
    InputError (exit 2) naming the extra when they are not installed."""
    try:
        import imath
        from alembic3d import Abc, AbcCoreAbstract, AbcGeom
    except ImportError:
        raise InputError(MISSING) from None
    return Abc, AbcGeom, AbcCoreAbstract, imath


def require() -> None:
    """Raise InputError naming `treebake[alembic]` unless alembic3d imports
    (called before any simulation when abc is asked for)."""
    _modules()


def library_version() -> str:
    """The Alembic library's version, as it records it in every archive."""
    Abc = _modules()[0]
    return str(Abc.GetLibraryVersionShort())


@dataclass
class AbcResult:
    files: list[Path] = field(default_factory=list)
    xforms: int = 0  # joint and projectile xforms that carry animation
    meshes: int = 0
    point_caches: int = 0  # meshes sampled every frame
    samples: int = 0  # time samples of the animated objects
    start_s: float = 0.0  # time of the first sample
    step_s: float = 0.0  # time per frame


def local_matrices(parent: np.ndarray, positions: np.ndarray,
                   rotations: np.ndarray) -> np.ndarray:
    """(F, S, 4, 4) Imath (row-vector) local matrices, Y up, of segments
    with world positions (F, S, 3) m and rotations (F, S, 4) x y z w (Z up):
    rows 0-2 the transposed rotation, row 3 the translation."""
    pos = points_y_up(positions.astype(np.float64))
    rot = qnormalize(quats_y_up(rotations.astype(np.float64)))
    t_loc, q_loc = local_transforms(parent, pos, rot)
    F, S = t_loc.shape[:2]
    r = matrices_from_quaternions(qnormalize(q_loc).reshape(-1, 4)).reshape(F, S, 3, 3)
    m = np.zeros((F, S, 4, 4))
    m[..., :3, :3] = np.swapaxes(r, -1, -2)
    m[..., 3, :3] = t_loc
    m[..., 3, 3] = 1.0
    return m


class _Writer:
    def __init__(self, path: Path, bake: Bake, frame_start: int) -> None:
        self.Abc, self.AbcGeom, self.Core, self.imath = _modules()
        self.archive = self.Abc.OArchive(str(path))
        fps = float(bake.fps)
        self.start, self.step = frame_start / fps, 1.0 / fps
        self.ts = self.archive.addTimeSampling(self.Core.TimeSampling(self.step, self.start))
        self.top = self.archive.getTop()
        self.bake = bake
        self.objects: list = []  # every OObject, alive until the archive closes
        self.names: set[str] = set()  # names taken at the top
        self.result = AbcResult(start_s=self.start, step_s=self.step)

    def unique(self, name: str) -> str:
        """`name`, or `name_2`, `name_3`, ... if the top already has it."""
        out, k = name, 1
        while out in self.names:
            k += 1
            out = f"{name}_{k}"
        self.names.add(out)
        return out

    def xform(self, parent, name: str, matrices: np.ndarray | None = None):
        """An OXform under `parent`: identity and constant without
        `matrices`, else one matrix op sample per frame (F, 4, 4)."""
        G = self.AbcGeom
        if matrices is None:
            x = G.OXform(parent, name)
            x.getSchema().set(G.XformSample())
        else:
            x = G.OXform(parent, name, self.ts)
            schema, M44d = x.getSchema(), self.imath.M44d
            for m in matrices.reshape(-1, 16).tolist():
                sample = G.XformSample()
                sample.setMatrix(M44d(*m))
                schema.set(sample)
            self.result.xforms += 1
            self.result.samples += len(matrices)
        self.objects.append(x)
        return x

    def mesh(self, parent, name: str, mesh: TreeMesh, frames: Iterable | None = None) -> None:
        """An OPolyMesh under `parent`: `mesh` as it is (constant), or with
        `frames` (posed positions, normals per frame, world, m, Z up) a
        point cache."""
        G, im = self.AbcGeom, self.imath
        if frames is None:
            m = G.OPolyMesh(parent, name)
            frames = [(mesh.positions, mesh.normals)]
        else:
            m = G.OPolyMesh(parent, name, self.ts)
            self.result.point_caches += 1
        self.objects.append(m)
        self.result.meshes += 1
        schema = m.getSchema()
        faces = np.concatenate([np.zeros((0, 3), np.int64), *(p.faces for p in mesh.parts)])
        wound = np.ascontiguousarray(faces[:, [0, 2, 1]], np.int32).ravel()  # clockwise
        indices = im.IntArrayFromBuffer(wound)
        counts = im.IntArrayFromBuffer(np.full(len(faces), 3, np.int32))
        varying = _uints(im, wound)  # uv and N: values per vertex, indexed per face corner
        scope = G.GeometryScope.kFacevaryingScope
        uv = G.OV2fGeomParamSample(
            im.V2fArrayFromBuffer(np.ascontiguousarray(mesh.uvs, np.float32)), varying, scope)
        for positions, normals in frames:
            p = np.ascontiguousarray(points_y_up(positions), np.float32)
            n = np.ascontiguousarray(points_y_up(normals), np.float32)
            nrm = G.ON3fGeomParamSample(im.V3fArrayFromBuffer(n), varying, scope)
            schema.set(G.OPolyMeshSchemaSample(im.V3fArrayFromBuffer(p), indices, counts,
                                               uv, nrm))
        first = 0
        for part in mesh.parts:
            if len(part.faces) == 0:
                continue
            fs = schema.createFaceSet(part.material)
            fs.getSchema().set(G.OFaceSetSchemaSample(
                im.IntArrayFromBuffer(np.arange(first, first + len(part.faces), dtype=np.int32))))
            self.objects.append(fs)
            first += len(part.faces)

    def tree(self, i: int, mesh: TreeMesh) -> None:
        t = self.bake.trees[i]
        if t.static:
            root = self.xform(self.top, self.unique(t.name))
            self.mesh(root, f"{t.name}_geo", mesh)
            return
        root = self.xform(self.top, self.unique(t.name))
        nodes: list = []
        mats = local_matrices(t.seg_parent, t.positions, t.rotations)
        for s, name in enumerate(joint_names(t.name, t.paths)):
            p = int(t.seg_parent[s])
            nodes.append(self.xform(root if p < 0 else nodes[p], name, mats[:, s]))
        holder = self.xform(self.top, self.unique(f"{t.name}_mesh"))
        F = len(self.bake.times)
        self.mesh(holder, f"{t.name}_geo", mesh, (pose(mesh, t, f) for f in range(F)))

    def projectiles(self) -> None:
        o = self.bake.objects
        if o is None or not len(o.sizes):
            return
        mats = local_matrices(np.full(len(o.sizes), -1), o.positions, o.rotations)
        for k, (shape, size) in enumerate(zip(o.shapes, o.sizes)):
            x = self.xform(self.top, self.unique(f"projectile_{k}"), mats[:, k])
            self.mesh(x, f"{shape}_{round(float(size) * 1000)}mm", object_mesh(shape, float(size)))

    def close(self) -> None:
        """Let go of every object, then the archive: Ogawa writes as they go."""
        self.objects.clear()
        self.top = None
        self.archive = None


def _uints(im, values: np.ndarray):
    """An Imath UnsignedIntArray of `values` (indices; PyImath builds it from
    a DoubleArray, exact below 2**53)."""
    return im.UnsignedIntArray(im.DoubleArrayFromBuffer(
        np.ascontiguousarray(values, np.float64)))


def export_abc(bake: Bake, meshes: list[TreeMesh], out: str | Path, name: str,
               frame_start: int = 1,
               progress: Callable[[int, int], None] | None = None) -> AbcResult:
    """Write `out/name.abc` atomically; bake frame f at (frame_start + f) / fps s."""
    path = Path(out) / f"{name}.abc"
    with atomic_path(path) as tmp:
        w = _Writer(tmp, bake, frame_start)
        try:
            for i, mesh in enumerate(meshes):
                w.tree(i, mesh)
                if progress is not None:
                    progress(i + 1, len(meshes))
            w.projectiles()
        finally:
            result = w.result
            w.close()
            del w
    result.files.append(path)
    return result
