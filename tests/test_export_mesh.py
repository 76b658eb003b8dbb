"""Tree meshes: generalized cylinders with outward normals and UVs, joint
rings blended half and half, broken joints split (no stretched skin on
debris), foliage cards rigid on their leafy segments (placed by the tree's
seed) or none, fast on a willow."""

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from treebake.library import grammar_path
from treebake.pipeline import bake_scene
from treebake.scene import parse_scene
from treebake.stress_cases import cases

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import ROOT
from treebake.bake import tree_bake_from_model
from treebake.exchange.foliage import ATLAS, STYLES
from treebake.model import Twigs
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


def _cards(mesh):
    """Leaf parts' quads: vertex indices (C, 4), 4 consecutive vertices each."""
    faces = np.concatenate([p.faces for p in mesh.parts if p.material.startswith("leaf")])
    first = faces[0::2, 0]
    assert (faces[0::2] == first[:, None] + [0, 1, 2]).all()
    assert (faces[1::2] == first[:, None] + [0, 2, 3]).all()
    return first[:, None] + np.arange(4)


def test_foliage_cards_sit_rigidly_on_their_leafy_segment_or_nothing():
    # the oak without its twigs: with them its leaf clusters are drawn on its
    # twigs (@twig), which tests/test_twigs.py checks
    tree = replace(rest_tree("oak.lsys"), twigs=Twigs.none())
    mesh = tree_mesh(tree)
    leaves = [p for p in mesh.parts if p.material.startswith("leaf")]
    assert leaves and all(p.double_sided for p in leaves)
    quads = _cards(mesh)
    seg = mesh.joints[quads[:, 0], 0]
    # rigid (one influence, the segment itself), all four corners on one leafy segment
    assert (mesh.joints[quads] == seg[:, None, None]).all()
    assert (mesh.weights[quads.ravel()] == [1.0, 0.0]).all()
    assert (tree.leaf[seg] > 0).all()
    assert set(np.unique(seg)) == set(np.nonzero(tree.leaf > 0)[0])  # every leafy segment
    p = mesh.positions[quads]  # (C, 4, 3)
    # a square of edge e = EDGE x the segment's leaf size, its stem edge's
    # midpoint on the segment between its base and tip
    e = STYLES[1].edge * tree.leaf_size[seg]
    for a, b in ((0, 1), (1, 2), (2, 3), (3, 0)):
        assert np.allclose(np.linalg.norm(p[:, a] - p[:, b], axis=1), e)
    assert np.allclose(np.linalg.norm(p[:, 0] - p[:, 2], axis=1), e * np.sqrt(2))
    stem = 0.5 * (p[:, 0] + p[:, 1])
    a0, a1 = tree.points[tree.seg_start[seg]], tree.points[tree.seg_end[seg]]
    t = ((stem - a0) * (a1 - a0)).sum(1) / ((a1 - a0) ** 2).sum(1)
    assert (t > -1e-9).all() and (t < 1 + 1e-9).all()
    assert np.allclose(a0 + t[:, None] * (a1 - a0), stem, atol=1e-9)
    # one cell of the atlas each (a colour variant), its stem (the cell's
    # bottom, v0) at the stem edge, its top (v0 + 1 / ATLAS) at the far edge;
    # every variant in use
    uv = mesh.uvs[quads]  # (C, 4, 2)
    u0, v0 = uv[:, 0, 0], uv[:, 0, 1]
    assert np.allclose(uv[:, :, 0] - u0[:, None], np.array([0, 1, 1, 0]) / ATLAS)
    assert np.allclose(uv[:, :, 1] - v0[:, None], np.array([0, 0, 1, 1]) / ATLAS)
    cells = set(zip((u0 * ATLAS).round().astype(int), (v0 * ATLAS).round().astype(int)))
    assert cells == {(i, j) for i in range(ATLAS) for j in range(ATLAS)}
    for part in leaves:  # normals on the winding's side (renderers shade by both)
        v = mesh.positions[part.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        assert ((n * mesh.normals[part.faces].sum(1)).sum(1) > 0).all()
    bare = tree_mesh(tree, MeshOptions(leaves=False))
    assert len(bare.parts) == 1 and bare.n_vertices == mesh.n_vertices - 4 * len(quads)
    assert np.array_equal(bare.positions, mesh.positions[:bare.n_vertices])


def test_foliage_follows_the_trees_seed_and_only_it():
    tree = rest_tree("sapling.lsys")
    one, two = tree_mesh(replace(tree, info={"seed": 7})), tree_mesh(replace(tree, info={"seed": 7}))
    other = tree_mesh(replace(tree, info={"seed": 8}))
    assert np.array_equal(one.positions, two.positions) and np.array_equal(one.uvs, two.uvs)
    bark = one.parts[0].faces.max() + 1
    assert one.positions.shape == other.positions.shape  # as many cards: the counts are geometry's
    assert np.array_equal(one.positions[:bark], other.positions[:bark])  # the same bark
    assert not np.array_equal(one.positions[bark:], other.positions[bark:])
    # where the tree stands does not decide its foliage: moved, the same cards, moved
    shift = np.array([37.25, -12.5, 0.0])
    moved = tree_mesh(replace(tree, points=tree.points + shift, info={"seed": 7},
                              twigs=tree.twigs.moved(np.eye(3), shift)))
    assert moved.n_vertices == one.n_vertices
    assert np.allclose(moved.positions, one.positions + shift, atol=1e-9)


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


@pytest.mark.parametrize("setting", ["default", "pymunk", "full"])
def test_a_tree_without_events_keeps_every_joint(tmp_path, setting):
    """broken_joints trusts a bake that records no event: no engine opens a
    joint by more than BREAK_GAP unless something broke, was cut or
    uprooted. Checked frame by frame (separated_joints) on an unbreakable
    sapling in a gale, on the linear tier with the reference for large
    motion, on the pymunk tier and on the full reference."""
    from treebake.accuracy import PYMUNK, SCENARIOS, unbreakable
    from treebake.exchange.mesh import separated_joints
    from treebake.quality import QUALITIES

    raw = {"duration": 3.0, "fps": 24, **SCENARIOS["gale"],
           "tree": [{"grammar": str(unbreakable("sapling", tmp_path))}]}
    quality = PYMUNK if setting == "pymunk" else QUALITIES["default"]
    bake = bake_scene(parse_scene(raw, file="<gale>"), quality=quality,
                      solver="full" if setting == "full" else "planar")
    tree = bake.trees[0]
    assert tree.info["events"] == [] and not tree.static
    moved = np.linalg.norm(tree.positions[:, -1] - tree.positions[0, -1], axis=-1).max()
    assert moved > 0.05  # the gale bends it: the joints are loaded
    assert not separated_joints(tree).any()
    assert not broken_joints(tree).any()
