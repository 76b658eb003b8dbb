"""Camera culling and parallel simulation: trees the camera never sees are
not simulated, far ones get the far quality, and any number of worker
processes gives the same bake, byte for byte."""

import numpy as np
import pytest
from treebake.bake_file import load_bake, save_bake
from treebake.culling import cull, half_angle
from treebake.pipeline import bake_scene
from treebake.scene import CameraSpec, parse_scene
from treebake.sim import lod as run


def test_cull_sees_in_front_not_behind_and_measures_distance():
    cam = CameraSpec(keys=[(0.0, (0.0, 0.0, 2.0), (10.0, 0.0, 2.0))], fov=60.0, margin=5.0)
    centres = np.array([[20.0, 0.0, 5.0], [-20.0, 0.0, 5.0], [20.0, 30.0, 5.0],
                        [20.0, 14.0, 5.0]])
    radii = np.array([5.0, 5.0, 5.0, 5.0])
    c = cull(cam, 5.0, centres, radii)
    # the view cone covers a 16:9 frame's diagonal plus the 5 deg margin
    diagonal = np.degrees(np.arctan(np.tan(np.radians(30)) * np.hypot(1, 9 / 16)))
    assert np.degrees(half_angle(cam)) == pytest.approx(diagonal + 5.0)
    # 56 deg off with an 8 deg angular radius: out; 35 deg off with 12: in
    assert c.seen.tolist() == [True, False, False, True]
    assert c.nearest[0] == pytest.approx(np.hypot(20.0, 3.0) - 5.0)


def test_a_turning_camera_sees_all_round(tmp_path):
    keys = [(float(t), (0.0, 0.0, 2.0), (np.cos(a) * 10, np.sin(a) * 10, 2.0))
            for t, a in zip(range(9), np.linspace(0, 2 * np.pi, 9))]
    cam = CameraSpec(keys=keys, fov=40.0, margin=0.0)
    ring = np.array([[np.cos(a) * 30, np.sin(a) * 30, 5.0] for a in np.linspace(0, 6, 12)])
    assert cull(cam, 8.0, ring, np.full(12, 3.0)).seen.all()


def test_unseen_trees_are_static_and_far_trees_coarser(root, tmp_path):
    sapling = str(root / "grammars" / "sapling.lsys")
    raw = {"duration": 0.5, "tree": [
        {"grammar": sapling, "position": [10.0, 0.0]},     # in view, near
        {"grammar": sapling, "position": [-30.0, 0.0]},    # behind the camera
        {"grammar": sapling, "position": [200.0, 0.0]}],   # in view, far
        "wind": {"speed": 8.0},
        "camera": {"keys": [{"time": 0.0, "position": [0.0, 0.0, 1.5],
                             "target": [10.0, 0.0, 1.5]}], "far": 100.0}}
    bake = bake_scene(parse_scene(raw))
    near, behind, far = bake.trees
    assert not near.static and not far.static
    assert behind.static and "outside the camera" in behind.info["static"]
    assert near.info["bones"] > far.info["bones"]  # draft merges bones
    # what each rule removed, kept in the bake's metadata
    saved = load_bake(save_bake(bake, tmp_path / "b.npz"))
    assert saved.meta["culling"] == {"unseen": 1, "far": 1, "no_force": 0}


def test_parallel_chunks_give_the_same_bytes(root, tmp_path, monkeypatch):
    monkeypatch.setattr(run, "CHUNK_SEGMENTS", 120)
    raw = {"duration": 0.5, "seed": 2, "wind": {"speed": 12.0, "turbulence": 0.3},
           "forest": {"grammars": [str(root / "grammars" / "forest" / "conifer.lsys"),
                                   str(root / "grammars" / "forest" / "birch.lsys")],
                      "count": 12, "area": [40.0, 40.0]}}
    scene = parse_scene(raw)
    one = bake_scene(scene, workers=1)
    two = bake_scene(scene, workers=2)
    assert one.meta["chunks"] >= 3
    a = save_bake(one, tmp_path / "a.npz").read_bytes()
    b = save_bake(two, tmp_path / "b.npz").read_bytes()
    assert a == b
