"""Names every tool keeps (issue 15): three.js's own GLTFLoader (under Node)
rewrites none of our node names and finds no duplicates; every joint name is
an identifier of at most 63 bytes, unique in the file, in glTF and USD
alike; trees are named after their grammar, unique per scene."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import preset_bake
from conftest import need
from treebake.errors import SceneError
from treebake.exchange.gltf import export_gltf
from treebake.exchange.mesh import tree_mesh
from treebake.names import is_valid, joint_name, joint_names
from treebake.scene import parse_scene
from validator import three_check

ROOT = Path(__file__).resolve().parent.parent
SAPLING = str(ROOT / "grammars" / "sapling.lsys")
OAK = str(ROOT / "grammars" / "oak.lsys")


def _glb(bake, folder, **kw):
    return export_gltf(bake, [tree_mesh(t) for t in bake.trees], folder, "job", **kw).files


@pytest.mark.parametrize("name", ["demo", "boxes"])
def test_threejs_keeps_every_node_name(name, tmp_path):
    (path,) = _glb(preset_bake(name), tmp_path)
    report = three_check(path)
    assert report["nodes"] > 3
    assert report["rewritten"] == [], report["rewritten"][:5]
    assert report["duplicates"] == []


def test_joint_names_are_identifiers_unique_in_the_file():
    for name in ("demo", "tornado", "explosion"):
        bake = preset_bake(name)
        seen = set()
        for t in bake.trees:
            names = joint_names(t.name, t.paths)
            assert all(is_valid(n) for n in names), names[:3]
            assert not seen & set(names) and len(set(names)) == len(names)
            seen |= {*names, t.name, f"{t.name}_mesh"}
    assert joint_name("oak", "trunk/2/1:3", 7) == "oak_trunk_2_1_s3"
    assert joint_name("oak", "trunk2:0", 0) == "oak_trunk2_s0"
    deep = "trunk" + "/1" * 40 + ":0"  # over Blender's 63 bytes: the index form
    assert joint_name("oak", deep, 12) == "oak_s12"


def test_usd_joints_carry_the_same_names_in_the_tree_hierarchy(tmp_path):
    need("pxr")
    from pxr import Usd, UsdSkel
    from treebake.exchange.usd import export_usd

    bake = preset_bake("boxes")
    res = export_usd(bake, [tree_mesh(t) for t in bake.trees], tmp_path, "job")
    stage = Usd.Stage.Open(str(res.files[0]))
    for t in bake.trees:
        skel = UsdSkel.Skeleton(stage.GetPrimAtPath(f"/job/{t.name}/Skel"))
        tokens = list(skel.GetJointsAttr().Get())
        names = joint_names(t.name, t.paths)
        assert [tok.rsplit("/", 1)[-1] for tok in tokens] == names  # what Blender shows
        assert list(skel.GetJointNamesAttr().Get()) == names
        parent = [tokens.index(tok.rsplit("/", 1)[0]) if "/" in tok else -1 for tok in tokens]
        np.testing.assert_array_equal(parent, t.seg_parent)
        assert list(skel.GetPrim().GetAttribute("treebake:segmentPaths").Get()) == t.paths


def test_trees_are_named_after_their_grammar_unique_in_the_scene():
    scene = parse_scene({"tree": [{"grammar": OAK}, {"grammar": SAPLING},
                                  {"grammar": SAPLING}, {"grammar": OAK, "name": "sapling_2"}]})
    assert [t.name for t in scene.trees] == ["oak", "sapling_1", "sapling_3", "sapling_2"]
    forest = parse_scene({"forest": {"grammars": [OAK, SAPLING], "count": 3,
                                     "area": [50.0, 50.0]}})
    assert [t.name for t in forest.trees] == ["oak_1", "sapling", "oak_2"]
    with pytest.raises(SceneError, match=r"tree\[1\]\.name.*already"):
        parse_scene({"tree": [{"grammar": OAK, "name": "a"}, {"grammar": OAK, "name": "a"}]})
    for bad in ("big oak", "oak:1", "trunk/2", "1oak", "x" * 41, "oak.1", ""):
        with pytest.raises(SceneError, match=r"tree\[0\]\.name.*letters, digits and _"):
            parse_scene({"tree": [{"grammar": OAK, "name": bad}]})
