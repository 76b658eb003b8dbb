"""An Alembic archive read back with the Alembic library itself (alembic3d,
PyAlembic): every xform's world matrix at every sample, composed down the
hierarchy the way a DCC does (inheritsXforms honoured), and every
polymesh's samples, in the file's own terms (Y up, Imath row-vector
matrices converted to column-vector 4 x 4 numpy arrays). Nothing of
treebake's writer is used."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Mesh:
    path: str
    positions: list[np.ndarray]  # per sample (V, 3) float32
    normals: list[np.ndarray]  # per sample, face-varying values (V, 3)
    normal_indices: np.ndarray  # (3T,) into the normal values
    faces: np.ndarray  # (T, 3) as written (face counts all 3)
    uvs: np.ndarray  # (V, 2) values
    uv_indices: np.ndarray  # (3T,)
    uv_scope: str
    face_sets: dict[str, np.ndarray]
    times: np.ndarray  # sample times, s


@dataclass
class Archive:
    times: np.ndarray  # the animated xforms' sample times, s
    world: dict[str, np.ndarray] = field(default_factory=dict)  # path -> (F, 4, 4)
    names: dict[str, str] = field(default_factory=dict)  # path -> object name
    parents: dict[str, str] = field(default_factory=dict)  # path -> parent path ('' = top)
    meshes: dict[str, Mesh] = field(default_factory=dict)  # path -> mesh
    start_end: tuple[float, float] = (0.0, 0.0)  # GetArchiveStartAndEndTime
    version: str = ""


def _at(Abc, ts, k: int):
    """The selector of sample k, by its time: PyAlembic's ISampleSelector(k)
    with a Python int picks the float overload (a time in s), not index k."""
    return Abc.ISampleSelector(float(ts.getSampleTime(k)))


def _matrix(m) -> np.ndarray:
    """Imath M44d (row vectors: p' = p M) -> a column-vector 4 x 4 array."""
    return np.array([[m[r][c] for c in range(4)] for r in range(4)]).T


def read(path, frames: int) -> Archive:
    """Read `path`; animated objects must have `frames` samples, constant
    ones 1 (repeated to `frames`)."""
    from alembic3d import Abc, AbcGeom

    wrap = Abc.WrapExistingFlag.kWrapExisting
    archive = Abc.IArchive(str(path))
    out = Archive(times=np.zeros(0), start_end=tuple(Abc.GetArchiveStartAndEndTime(archive)),
                  version=Abc.GetArchiveInfo(archive)["libraryVersionString"])

    def visit(obj, parent_path: str, parent_world: np.ndarray) -> None:
        header = obj.getHeader()
        path = obj.getFullName()
        out.names[path] = obj.getName()
        out.parents[path] = parent_path
        world = parent_world
        if AbcGeom.IXform.matches(header):
            schema = AbcGeom.IXform(obj, wrap).getSchema()
            n = schema.getNumSamples()
            assert n in (1, frames), (path, n)
            ts = schema.getTimeSampling()
            local = []
            for k in range(n):
                sample = schema.getValue(_at(Abc, ts, k))
                local.append(_matrix(sample.getMatrix()))
                inherits = sample.getInheritsXforms()
            local = np.repeat(np.array(local), frames // n, axis=0)
            if n == frames:
                out.times = np.array([ts.getSampleTime(k) for k in range(n)])
            world = local if not inherits else parent_world @ local
            out.world[path] = world
        elif AbcGeom.IPolyMesh.matches(header):
            out.meshes[path] = _mesh(obj, Abc, AbcGeom)
        for i in range(obj.getNumChildren()):
            visit(obj.getChild(i), path, world)

    top = archive.getTop()
    for i in range(top.getNumChildren()):
        visit(top.getChild(i), "", np.tile(np.eye(4), (frames, 1, 1)))
    return out


def _mesh(obj, Abc, AbcGeom) -> Mesh:
    schema = AbcGeom.IPolyMesh(obj, Abc.WrapExistingFlag.kWrapExisting).getSchema()
    n = schema.getNumSamples()
    ts = schema.getTimeSampling()
    pos, nrm = [], []
    normals = schema.getNormalsParam()
    for k in range(n):
        sel = _at(Abc, ts, k)
        pos.append(np.array(schema.getValue(sel).getPositions(), dtype=np.float32))
        ns = normals.getIndexedValue(sel)
        nrm.append(np.array(ns.getVals(), dtype=np.float32))
    first = _at(Abc, ts, 0)
    sample = schema.getValue(first)
    counts = np.array(sample.getFaceCounts())
    assert (counts == 3).all()
    faces = np.array(sample.getFaceIndices()).reshape(-1, 3)
    uvp = schema.getUVsParam()
    uv = uvp.getIndexedValue(first)
    sets = {}
    for name in schema.getFaceSetNames():
        fs = schema.getFaceSet(name).getSchema().getValue(first)
        sets[name] = np.array(fs.getFaces())
    return Mesh(path=obj.getFullName(), positions=pos, normals=nrm,
                normal_indices=np.array(normals.getIndexedValue(first).getIndices()),
                faces=faces, uvs=np.array(uv.getVals()), uv_indices=np.array(uv.getIndices()),
                uv_scope=str(uvp.getScope()), face_sets=sets,
                times=np.array([ts.getSampleTime(k) for k in range(n)]))
