"""Tree meshes: generalized cylinders with outward normals and UVs, joint
rings blended half and half, broken joints split (no stretched skin on
debris), leaves as crossed quads or none, fast on a willow."""

import sys
import time
from pathlib import Path

import numpy as np
from treebake.library import grammar_path
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.stress import cases

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import ROOT
from treebake.bake import tree_bake_from_model
from treebake.exchange.mesh import MeshOptions, broken_joints, next_in_limb, pose, tree_mesh
from treebake.lsystem import derive, load_grammar
from treebake.turtle import interpret


def rest_tree(grammar: str):
    g = load_grammar(ROOT / "grammars" / grammar)
    d = derive(g, None, None)
    model = interpret(d.modules, g, seed=d.seed)
    n = model.n_segments
    pos = model.points[model.seg_start][None]
    rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, n, 1))
    return tree_bake_from_model(model, pos, rot, {})


def test_willow_meshes_well_under_a_second():
    tree = rest_tree("willow.lsys")
    assert tree.n_segments > 2500
    start = time.perf_counter()
    mesh = tree_mesh(tree, MeshOptions(radial=8))
    seconds = time.perf_counter() - start
    assert seconds < 0.5, seconds
    assert mesh.n_triangles > 16 * tree.n_segments


def test_bark_is_a_closed_outward_tube_with_uvs():
    tree = rest_tree("oak.lsys")
    mesh = tree_mesh(tree, MeshOptions(radial=6, rings=2, leaves=False))
    assert [p.material for p in mesh.parts] == ["bark"]
    f = mesh.parts[0].faces
    v = mesh.positions[f]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert (np.linalg.norm(n, axis=1) > 0).all()  # no degenerate triangles
    assert ((n * mesh.normals[f].sum(1)).sum(1) > 0).all()  # outward winding
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1)
    assert mesh.uvs[:, 0].min() == 0 and mesh.uvs[:, 0].max() == 1
    # every edge of the tube is shared by two triangles except at open child bases
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert counts.max() == 2


def test_joint_rings_blend_parent_and_child():
    tree = rest_tree("sapling.lsys")
    mesh = tree_mesh(tree, MeshOptions(radial=5, rings=2, leaves=False))
    nxt = next_in_limb(tree)
    s = int(np.nonzero(nxt >= 0)[0][0])
    child = int(nxt[s])
    at_joint = (mesh.joints[:, 0] == child) & (mesh.joints[:, 1] == s)
    assert np.allclose(mesh.weights[at_joint], 0.5)
    ring_mid = (mesh.joints[:, 0] == child) & (mesh.weights[:, 0] == 1.0)
    assert ring_mid.any()  # t = 1/2 of a segment follows it alone
    assert np.allclose(mesh.weights.sum(1), 1)
    assert ((mesh.weights[:, 1] > 0) <= (mesh.joints[:, 0] != mesh.joints[:, 1])).all()


def test_leaves_are_crossed_quads_or_nothing():
    tree = rest_tree("oak.lsys")
    leafy = int((tree.leaf > 0).sum())
    mesh = tree_mesh(tree)
    leaves = [p for p in mesh.parts if p.material.startswith("leaf")]
    assert sum(len(p.faces) for p in leaves) == 4 * leafy and all(p.double_sided for p in leaves)
    for part in leaves:  # normals agree with the winding (renderers shade by both)
        v = mesh.positions[part.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        assert ((n * mesh.normals[part.faces].sum(1)).sum(1) > 0).all()
    bare = tree_mesh(tree, MeshOptions(leaves=False))
    assert len(bare.parts) == 1 and bare.n_vertices == mesh.n_vertices - 8 * leafy


def test_broken_joints_split_the_skin():
    # a blast strips branches off a sapling (the stress suite's case)
    case = next(c for c in cases() if c.name == "blast breaks branches")
    bake = bake_scene(parse_scene({**case.scene, "duration": 3.0, "fps": 24,
                                   "tree": [{"grammar": str(grammar_path("sapling"))}]},
                                  file="<blast>"))
    tree = bake.trees[0]
    broken = broken_joints(tree)
    assert broken.any()
    mesh = tree_mesh(tree, broken=broken)
    f = mesh.parts[0].faces
    rest = np.linalg.norm(mesh.positions[f[:, 0]] - mesh.positions[f[:, 1]], axis=1)
    posed, _ = pose(mesh, tree, len(bake.times) - 1)
    moved = np.linalg.norm(posed[f[:, 0]] - posed[f[:, 1]], axis=1)
    assert (moved <= 1.5 * rest + 0.05).all()  # nothing stretched between tree and debris
    whole = tree_mesh(tree, broken=np.zeros_like(broken))
    pw, _ = pose(whole, tree, len(bake.times) - 1)
    fw = whole.parts[0].faces
    rest_w = np.linalg.norm(whole.positions[fw[:, 0]] - whole.positions[fw[:, 1]], axis=1)
    moved_w = np.linalg.norm(pw[fw[:, 0]] - pw[fw[:, 1]], axis=1)
    # one skin over tree and debris fails the same bound: the split is what keeps it
    assert (moved_w > 1.5 * rest_w + 0.05).any()
    assert moved_w.max() > 0.5  # stretched by metres, not millimetres
