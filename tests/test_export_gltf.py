"""glTF export: the Khronos validator passes every preset with zero errors
and warnings, and an independent reader (pygltflib + tests/tools/gltfread)
gets every joint's world transform at every frame back from the file."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import NAMES, preset_bake
from gltfread import Gltf, quat_to_matrix
from treebake.exchange.anim import ReduceOptions
from treebake.exchange.gltf import export_gltf
from treebake.exchange.mesh import MeshOptions, tree_mesh
from treebake.names import joint_names
from validator import validate

C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Z up -> Y up


def _export(bake, folder, **kw):
    meshes = [tree_mesh(t, MeshOptions()) for t in bake.trees]
    return export_gltf(bake, meshes, folder, "job", **kw)


def _clean(report):
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"][:10]


@pytest.mark.parametrize("name", NAMES)
def test_khronos_validator_passes_every_preset(name, tmp_path):
    res = _export(preset_bake(name), tmp_path)
    (report,) = validate(res.files)
    _clean(report)
    assert report["info"]["animationCount"] == (0 if name == "calm" else 1)


def test_khronos_validator_passes_gltf_bin_and_split_files(tmp_path):
    bake = preset_bake("boxes")
    files = _export(bake, tmp_path / "text", binary=False).files
    assert [f.suffix for f in files] == [".gltf", ".bin"]
    files += _export(bake, tmp_path / "split", split=True).files
    assert {f.name for f in files if "split" in str(f)} == {
        "job.sapling.glb", "job.oak.glb", "job.objects.glb"}
    reports = validate([f for f in files if f.suffix in (".glb", ".gltf")])
    assert len(reports) == 4
    for report in reports:
        _clean(report)


def _float32_tol(bake) -> float:
    """8 float32 ulps of the scene's largest coordinate (the hierarchy of
    float32 local transforms cannot do better far from the origin)."""
    big = max(float(np.abs(t.positions).max()) for t in bake.trees)
    return 1e-6 * max(1.0, big)


def _joint_errors(bake, g: Gltf, tree, frames):
    skin = next(s for s in g.g.skins if s.name == tree.name)
    names = [g.g.nodes[j].name for j in skin.joints]
    assert names == joint_names(tree.name, tree.paths)  # one joint per segment
    assert [g.g.nodes[j].extras["segment_path"] for j in skin.joints] == tree.paths
    worst_p = worst_a = 0.0
    for f in frames:
        w = g.worlds(skin.joints, float(np.float32(bake.times[f] + 1 / bake.fps)))
        p = tree.positions[f].astype(np.float64) @ C.T
        worst_p = max(worst_p, float(np.linalg.norm(w[:, :3, 3] - p, axis=1).max()))
        for s in range(tree.n_segments):
            r = C @ quat_to_matrix(tree.rotations[f, s]) @ C.T
            # |R1 - R2|_F = 2 sqrt(2) sin(angle / 2), accurate near zero
            d = np.linalg.norm(r - w[s, :3, :3]) / (2 * np.sqrt(2))
            worst_a = max(worst_a, float(2 * np.arcsin(min(d, 1.0))))
    return worst_p, worst_a


@pytest.mark.parametrize("name", ["boxes", "tornado"])
def test_round_trip_every_joint_every_frame_unreduced(name, tmp_path):
    bake = preset_bake(name)
    res = _export(bake, tmp_path, opts=ReduceOptions(enabled=False))
    g = Gltf(res.files[0])
    tol = _float32_tol(bake)
    for tree in bake.trees:
        ep, ea = _joint_errors(bake, g, tree, range(len(bake.times)))
        assert ep < tol, (tree.name, ep, tol)
        assert ea < 2e-6, (tree.name, ea)


def test_round_trip_reduced_stays_within_the_tolerances(tmp_path):
    bake = preset_bake("boxes")
    opts = ReduceOptions(position_tolerance=0.004, angle_tolerance=np.radians(0.5))
    res = _export(bake, tmp_path, opts=opts)
    a = res.animation
    assert a["keys_written"] < 0.5 * a["keys_full"]  # it does reduce
    assert a["max_position_error_m"] <= opts.position_tolerance
    g = Gltf(res.files[0])
    slack = _float32_tol(bake)
    for tree in bake.trees:
        ep, ea = _joint_errors(bake, g, tree, range(len(bake.times)))
        assert ep <= opts.position_tolerance + slack, (tree.name, ep)
        assert ea <= opts.angle_tolerance + 2e-6, (tree.name, ea)


def test_projectiles_are_animated_nodes(tmp_path):
    bake = preset_bake("boxes")
    g = Gltf(_export(bake, tmp_path, opts=ReduceOptions(enabled=False)).files[0])
    o = bake.objects
    for k in range(len(o.sizes)):
        node = g.node_index(f"projectile_{k}")
        for f in range(0, len(bake.times), 5):
            w = g.world(node, float(np.float32(bake.times[f] + 1 / bake.fps)))
            np.testing.assert_allclose(w[:3, 3], C @ o.positions[f, k], atol=_float32_tol(bake))
            np.testing.assert_allclose(w[:3, :3], C @ quat_to_matrix(o.rotations[f, k]) @ C.T,
                                       atol=2e-6)


def test_static_trees_are_plain_meshes_without_animation(tmp_path):
    bake = preset_bake("calm")
    assert all(t.static for t in bake.trees)
    g = Gltf(_export(bake, tmp_path).files[0])
    assert not g.g.animations and not g.g.skins
    tree = bake.trees[0]
    node = g.g.nodes[g.node_index(tree.name)]
    pos = g.accessor(g.g.meshes[node.mesh].primitives[0].attributes.POSITION)
    mesh = tree_mesh(tree)
    np.testing.assert_allclose(pos, mesh.positions @ C.T, atol=1e-5)


def test_animation_data_follows_the_spec(tmp_path):
    g = Gltf(_export(preset_bake("explosion"), tmp_path).files[0])
    (anim,) = g.g.animations
    for s in anim.samplers:
        inp = g.g.accessors[s.input]
        assert inp.min is not None and inp.max is not None  # required on inputs
        t = g.accessor(s.input)
        assert np.all(np.diff(t) > 0) and inp.min == [float(t[0])] and inp.max == [float(t[-1])]
        for acc in (s.input, s.output):
            view = g.g.bufferViews[g.g.accessors[acc].bufferView]
            assert view.byteStride is None and view.target is None
    for ch in anim.channels:
        if ch.target.path == "rotation":
            q = g.channels[(ch.target.node, "rotation")][1].astype(np.float64)
            assert np.abs(np.linalg.norm(q, axis=1) - 1).max() < 1e-6
            assert ((q[1:] * q[:-1]).sum(1) >= 0).all()  # one hemisphere, key to key
    # the skinned mesh nodes are roots without transforms
    roots = set(g.g.scenes[0].nodes)
    for i, n in enumerate(g.g.nodes):
        if n.skin is not None:
            assert i in roots and n.translation is None and n.rotation is None


def test_unchanging_channels_are_not_written(tmp_path):
    bake = preset_bake("breeze")
    res = _export(bake, tmp_path)
    a = res.animation
    # intact joints never change their local translation: no such channels
    assert a["channels_written"] < 0.6 * a["channels"]
    g = Gltf(res.files[0])
    paths = [ch.target.path for ch in g.g.animations[0].channels]
    assert paths.count("translation") < 0.1 * paths.count("rotation") + 2
