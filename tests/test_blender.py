"""Blender itself (issue 15): the glb and the USD of one bake, each imported
into Blender, put the same pose on the same frame number, and that pose
is the bake's frame of that number (frame_start 1): Blender's frame k is the
bake's frame k in both formats. Fails (instead of skipping) under
TREEBAKE_REQUIRE_TOOLS=1."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import preset_bake
from conftest import need
from treebake.export import ExportOptions, export_bake
from treebake.names import joint_names


def test_blender_frame_k_is_the_bakes_frame_k_for_glb_and_usd(tmp_path):
    import blender

    need("pxr")  # the USD export

    bake = preset_bake("felling")  # the spruce falls fast at the end: frames differ a lot
    n = len(bake.times)
    export_bake(bake, tmp_path, "fell", ExportOptions(formats=("glb", "usd")))
    numbers = [1, n // 2, n - 6, n - 3, n - 1, n]
    got = blender.frames(tmp_path / "fell" / "fell.glb", tmp_path / "fell" / "fell.usd",
                         tmp_path / "blender.json", numbers)
    tree = bake.trees[0]
    names = joint_names(tree.name, tree.paths)
    assert got["glb"]["actions"] == [[1.0, float(n)]]  # the glb's keys span frames 1..n
    assert got["usd"]["actions"] == [[1.0, float(n)]]
    assert got["usd"]["scene_range"] == [1, n]  # USD start/end codes set the scene range
    assert got["glb"]["scene_range"] == [1, 250]  # the glTF importer leaves Blender's default
    assert got["glb"]["scene_props"] == {"frame_start": 1, "frame_end": n, "fps": bake.fps}
    assert got["glb"]["scene_range_set"] == [1, n]  # docs/formats.md's line sets it
    worst = {"glb": 0.0, "usd": 0.0, "glb_vs_usd": 0.0}
    step = 0.0  # how far the bake moves between neighbouring frames: what an offset would cost
    for k in numbers:
        want = tree.positions[k - 1].astype(np.float64)
        if k > 1:
            step = max(step, float(np.abs(want - tree.positions[k - 2]).max()))
        poses = {}
        for fmt in ("glb", "usd"):
            heads = got[fmt]["heads"][str(k)]
            poses[fmt] = np.array([heads[name] for name in names])
            worst[fmt] = max(worst[fmt], float(np.abs(poses[fmt] - want).max()))
        worst["glb_vs_usd"] = max(worst["glb_vs_usd"],
                                  float(np.abs(poses["glb"] - poses["usd"]).max()))
    assert step > 0.02, step  # an off-by-one frame would show (errors below are < 3 mm)
    assert worst["glb"] < 3e-3, worst  # the keyframe reduction's 2 mm, plus float32
    assert worst["usd"] < 1e-3, worst
    assert worst["glb_vs_usd"] < 3e-3, worst
    print(f"Blender {got['blender']}: worst bone head error glb {worst['glb'] * 1e3:.2f} mm, "
          f"usd {worst['usd'] * 1e3:.3f} mm, glb vs usd {worst['glb_vs_usd'] * 1e3:.2f} mm; "
          f"neighbouring frames differ by up to {step * 1e3:.0f} mm")


def test_blender_renders_the_leaf_cards_cut_out_by_their_alpha(tmp_path):
    """Cycles (CPU) renders the glb as a user would: the embedded textures
    load (no missing-texture magenta) and the cards' alpha mask cuts the
    leaves out, so fewer pixels are leaf-green than with plain cards."""
    import blender
    from PIL import Image

    bake = preset_bake("demo")
    green = {}
    for textures in (True, False):
        name = "tex" if textures else "plain"
        export_bake(bake, tmp_path, name, ExportOptions(formats=("glb",), textures=textures))
        png = tmp_path / f"{name}.png"
        blender.run("blender_render.py", str(tmp_path / name / f"{name}.glb"), str(png), "20",
                    "--engine", "cycles", "--size", "320x180", "--samples", "4")
        rgb = np.asarray(Image.open(png).convert("RGB")).astype(int)
        r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
        green[name] = int(((g > r + 12) & (g > b + 12)).sum())
        assert not ((r > 200) & (g < 80) & (b > 200)).any()  # Blender's missing texture
    assert 0.15 * green["plain"] < green["tex"] < 0.75 * green["plain"], green
