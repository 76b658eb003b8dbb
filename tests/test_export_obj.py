"""OBJ sequences: frame k equals the skinned glTF mesh at frame k (skinning
computed here from the glTF's joints, weights, inverse bind matrices and
animated nodes), faces reference UVs and normals and name materials, the
files are named for sequence importers and are byte-reproducible."""

import re
import sys
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import preset_bake
from gltfread import Gltf
from treebake.exchange.anim import ReduceOptions
from treebake.exchange.gltf import export_gltf
from treebake.exchange.mesh import MeshOptions, tree_mesh
from treebake.exchange.obj import export_obj


def read_obj_vertices(path: Path) -> dict[str, np.ndarray]:
    """`v` rows of each `o` block."""
    blocks: dict[str, list] = {}
    current = None
    for line in path.read_text().splitlines():
        if line.startswith("o "):
            current = line[2:]
            blocks[current] = []
        elif line.startswith("v "):
            blocks[current].append([float(x) for x in line.split()[1:]])
    return {k: np.array(v) for k, v in blocks.items()}


def _both(bake, tmp_path, stride=1, reduce=None):
    reduce = reduce or ReduceOptions(enabled=False)
    meshes = [tree_mesh(t, MeshOptions()) for t in bake.trees]
    obj = export_obj(bake, meshes, tmp_path / "obj", "job", stride=stride)
    glb = export_gltf(bake, meshes, tmp_path, "job", opts=reduce)
    return obj, Gltf(glb.files[0])


def _compare(bake, obj, g, frames, tol):
    worst = 0.0
    for f in frames:
        blocks = read_obj_vertices(obj.files[0].parent / f"job.{f + 1:04d}.obj")
        for tree in bake.trees:
            if tree.static:
                continue
            t = float(np.float32(bake.times[f] + 1 / bake.fps))  # frame_start 1
            skinned = g.skinned(g.node_index(f"{tree.name}_mesh"), t)
            worst = max(worst, float(np.abs(blocks[tree.name] - skinned).max()))
    assert worst < tol, worst
    return worst


def test_obj_frame_equals_skinned_gltf_frame(tmp_path):
    bake = preset_bake("boxes")  # bending, broken joints, debris, projectiles
    obj, g = _both(bake, tmp_path, stride=4)
    frames = [f for f in range(0, len(bake.times), 4)]
    assert obj.frames == frames
    # OBJ has 6 decimals; glTF float32 far from the origin: 8 ulps of 32 m
    _compare(bake, obj, g, frames, tol=5e-5)


def test_obj_matches_reduced_gltf_within_the_reduction_tolerance(tmp_path):
    bake = preset_bake("breeze")
    opts = ReduceOptions()
    obj, g = _both(bake, tmp_path, stride=3, reduce=opts)
    margin = max(float(t.leaf_size.max()) + float(t.width.max()) for t in bake.trees)
    # a vertex sits at most `margin` beyond its segment: tolerance plus lever * angle
    _compare(bake, obj, g, obj.frames, tol=opts.position_tolerance
             + opts.angle_tolerance * margin + 1e-5)


def test_obj_files_are_what_sequence_importers_expect(tmp_path):
    bake = preset_bake("boxes")
    meshes = [tree_mesh(t) for t in bake.trees]
    res = export_obj(bake, meshes, tmp_path, "job", stride=10)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names[0] == "job.0001.obj" and "job.0011.obj" in names and "job.mtl" in names
    assert len([n for n in names if n.endswith(".obj")]) == len(range(0, len(bake.times), 10))
    text = res.files[1].read_text()
    assert text.splitlines()[1] == "mtllib job.mtl"
    faces = [ln for ln in text.splitlines() if ln.startswith("f ")]
    assert faces and all(re.fullmatch(r"f (\d+)/\1/\1 (\d+)/\2/\2 (\d+)/\3/\3", f) for f in faces)
    mtl = (tmp_path / "job.mtl").read_text()
    used = set(re.findall(r"^usemtl (\S+)$", text, re.MULTILINE))
    assert used == {"bark", "leaf", "object"} and used <= set(re.findall(r"newmtl (\S+)", mtl))
    counts = {k: text.count(f"\n{k} ") for k in ("v", "vt", "vn")}
    assert counts["v"] == counts["vt"] == counts["vn"]
    # an independent reader gets the materials, UVs and normals
    scene = trimesh.load(res.files[1], process=False)
    assert {g.visual.material.name for g in scene.geometry.values()} == used
    bark = scene.geometry["bark"]
    assert bark.visual.uv.shape[0] == len(bark.vertices) and bark.vertex_normals.shape[1] == 3


def test_obj_sequence_is_byte_reproducible(tmp_path):
    bake = preset_bake("explosion")
    meshes = [tree_mesh(t) for t in bake.trees]
    a = export_obj(bake, meshes, tmp_path / "a", "job", stride=9)
    b = export_obj(bake, [tree_mesh(t) for t in bake.trees], tmp_path / "b", "job", stride=9)
    assert [p.name for p in a.files] == [p.name for p in b.files]
    for pa, pb in zip(a.files, b.files):
        assert pa.read_bytes() == pb.read_bytes(), pa.name
    header = a.files[1].read_text().splitlines()[0]
    assert not re.search(r"\d{4}-\d\d-\d\d|\d\d:\d\d", header), header  # no timestamps


def test_a_sequence_the_disk_cannot_hold_is_refused_before_any_file(tmp_path, monkeypatch):
    """A 1,000-tree forest's OBJ sequence is 62 GB: it filled a shared disk
    frame by frame and left every frame it wrote. Now the first frame's
    size times the frames is checked against the free disk first."""
    import pytest
    from treebake.errors import OutputError
    from treebake.exchange import obj

    bake = preset_bake("explosion")
    meshes = [tree_mesh(t) for t in bake.trees]
    full = export_obj(bake, meshes, tmp_path / "full", "job", stride=9)
    frames = [p.stat().st_size for p in full.files if p.suffix == ".obj"]
    # room for the whole sequence but 1 %: refused, naming what it needs
    monkeypatch.setattr(obj, "free_disk", lambda folder: int(0.99 * len(frames) * frames[0]))
    refused = rf"needs about .* \({len(frames)} frames of .*--stride, now 9"
    with pytest.raises(OutputError, match=refused):
        export_obj(bake, meshes, tmp_path / "refused", "job", stride=9)
    assert not (tmp_path / "refused").exists() or not any((tmp_path / "refused").iterdir())
    # the frames are within 1 % of the first frame's size: the estimate holds
    assert max(frames) <= 1.01 * frames[0] and min(frames) >= 0.99 * frames[0]
    monkeypatch.setattr(obj, "free_disk", lambda folder: int(1.02 * len(frames) * frames[0]))
    assert len(export_obj(bake, meshes, tmp_path / "fits", "job", stride=9).frames) == len(frames)
