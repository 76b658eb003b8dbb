"""The frame range in the files (issue 42): glTF has none, so the scene's
`extras.treebake` says frame_start, frame_end and fps (Blender makes it
the scene's custom property `treebake`, three.js the scene's
`userData.treebake`), and they span exactly the animation's keys; USD
stages author startTimeCode, endTimeCode, timeCodesPerSecond and
framesPerSecond (Blender's "Set Frame Range", usdview, Maya read them).
Read back with pygltflib and pxr, on the golden sapling-box bake.
Self-contained: runs from any folder against any checkout's treebake."""

from pathlib import Path

import numpy as np
import pygltflib
import pytest
import treebake
from treebake.bake_file import load_bake
from treebake.export import ExportOptions, export_bake

BAKE = Path(treebake.__file__).resolve().parents[1] / "tests" / "golden" / "sapling-box.npz"


def _key_times(g: pygltflib.GLTF2) -> np.ndarray:
    blob = g.binary_blob()
    out = []
    for anim in g.animations:
        for sampler in anim.samplers:
            acc = g.accessors[sampler.input]
            view = g.bufferViews[acc.bufferView]
            start = (view.byteOffset or 0) + (acc.byteOffset or 0)
            out.append(np.frombuffer(blob, np.float32, acc.count, start))
    return np.concatenate(out).astype(np.float64)


@pytest.mark.parametrize("start", [1, 101])
def test_gltf_scene_extras_carry_the_frame_range_of_the_keys(tmp_path, start):
    bake = load_bake(BAKE)
    n, fps = len(bake.times), bake.fps
    report = export_bake(bake, tmp_path, "box",
                         ExportOptions(formats=("glb",), frame_start=start, split=True))
    files = sorted(report.folder.glob("*.glb"))
    assert len(files) == 2  # the sapling and the projectile, each with the range
    for path in files:
        g = pygltflib.GLTF2().load(str(path))
        extras = g.scenes[g.scene].extras
        assert extras["treebake"] == {"frame_start": start, "frame_end": start + n - 1,
                                      "fps": fps}
        t = _key_times(g) * fps  # an importer's frame: key time x fps
        assert t.min() == pytest.approx(start, abs=1e-3)
        assert t.max() == pytest.approx(start + n - 1, abs=1e-3)
    m = report.manifest["frames"]
    assert (m["first"], m["last"], m["count"]) == (start, start + n - 1, n)


def test_usd_stage_authors_the_range_and_rate(tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd

    bake = load_bake(BAKE)
    n = len(bake.times)
    report = export_bake(bake, tmp_path, "box", ExportOptions(formats=("usda",), frame_start=1))
    stage = Usd.Stage.Open(str(report.folder / "box.usda"))
    layer = stage.GetRootLayer()
    assert layer.HasStartTimeCode() and layer.HasEndTimeCode()  # authored, not defaults
    assert layer.HasTimeCodesPerSecond() and layer.HasFramesPerSecond()
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1, n)
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == bake.fps
