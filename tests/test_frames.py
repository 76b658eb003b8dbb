"""One frame convention (issue 15): frame_start (default 1) numbers the
bake's frames in every format; glTF keys bake frame f at (frame_start + f)
/ fps s so an importer's frame = time x fps is the bake's frame number
(three.js's own AnimationMixer checked under Node); USD time codes and OBJ
file numbers use the same numbers; the range is hinted in the files."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import preset_bake
from conftest import need
from gltfread import Gltf
from treebake.export import ExportOptions, export_bake
from treebake.names import joint_names
from treebake.scene import parse_scene
from validator import three_check

ROOT = Path(__file__).resolve().parent.parent
C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Z up -> Y up


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    bake = preset_bake("felling")  # falls fast at the end: frames differ by centimetres
    out = tmp_path_factory.mktemp("frames")
    need("pxr")
    formats = ("glb", "obj", "usda")
    r1 = export_bake(bake, out, "one", ExportOptions(formats=formats))
    r101 = export_bake(bake, out, "late", ExportOptions(formats=formats, frame_start=101))
    return bake, r1, r101


@pytest.mark.parametrize("start", [1, 101])
def test_every_format_numbers_frames_from_frame_start(files, start):
    bake, r1, r101 = files
    report = r1 if start == 1 else r101
    n, fps = len(bake.times), bake.fps
    assert report.manifest["frames"]["first"] == start
    assert report.manifest["frames"]["last"] == start + n - 1
    g = Gltf(report.folder / f"{report.folder.name}.glb")
    scene_extras = g.g.scenes[0].extras
    assert scene_extras == {"treebake": {"frame_start": start, "frame_end": start + n - 1,
                                         "fps": fps}}
    assert g.g.asset.extras["treebake"]["frame_start"] == start
    inputs = {s.input for a in g.g.animations for s in a.samplers}
    assert inputs
    for i in inputs:  # key times: frame numbers / fps
        t = g.accessor(i).astype(np.float64)
        assert t.min() >= start / fps - 1e-6 and t.max() <= (start + n - 1) / fps + 1e-6
        np.testing.assert_allclose(t * fps, np.round(t * fps), atol=1e-3)
    names = sorted(p.name for p in (report.folder / "obj").glob("*.obj"))
    assert names[0] == f"{report.folder.name}.{start:04d}.obj" and len(names) == n
    assert names[-1] == f"{report.folder.name}.{start + n - 1:04d}.obj"
    from pxr import Usd, UsdSkel  # the fixture made sure pxr is there

    stage = Usd.Stage.Open(str(report.folder / f"{report.folder.name}.usda"))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (start, start + n - 1)
    skel = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    codes = UsdSkel.Animation(skel).GetRotationsAttr().GetTimeSamples()
    assert codes == [float(start + f) for f in range(n)]


def test_threejs_frame_k_is_the_bakes_frame_k(files):
    """AnimationMixer at time k / fps (three.js's frame k) poses every joint
    where the bake has frame k (frame number k, frame_start 1)."""
    bake, r1, _ = files
    fps = bake.fps
    n = len(bake.times)
    ks = [1, n // 2, n - 10, n - 5, n - 1, n]  # frame numbers
    report = three_check(r1.folder / "one.glb", [k / fps for k in ks])
    assert report["rewritten"] == []
    worst = 0.0
    for k in ks:
        pose = next(v for key, v in report["poses"].items() if abs(float(key) - k / fps) < 1e-9)
        for tree in bake.trees:
            if tree.static:
                continue
            got = np.array([pose[n] for n in joint_names(tree.name, tree.paths)])
            want = tree.positions[k - 1].astype(np.float64) @ C.T
            worst = max(worst, float(np.abs(got - want).max()))
    assert worst < 2.5e-3, worst  # the keyframe reduction's 2 mm, plus float32


def test_frame_start_comes_from_the_scene_and_is_checked(tmp_path):
    from treebake.errors import SceneError
    from treebake.pipeline import bake_scene

    sapling = str(ROOT / "grammars" / "sapling.lsys")
    scene = parse_scene({"tree": [{"grammar": sapling}], "frame_start": 1001,
                         "duration": 0.1, "wind": {"speed": 5.0}})
    bake = bake_scene(scene)
    assert bake.meta["frame_start"] == 1001
    report = export_bake(bake, tmp_path, "s", ExportOptions(formats=("obj",)))
    assert report.manifest["frames"]["first"] == 1001
    assert (tmp_path / "s" / "obj" / "s.1001.obj").is_file()
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert manifest["frames"]["obj"]["first"] == 1001
    for bad in (-1, 1.5, "1"):
        with pytest.raises(SceneError, match="frame_start"):
            parse_scene({"tree": [{"grammar": sapling}], "frame_start": bad})
