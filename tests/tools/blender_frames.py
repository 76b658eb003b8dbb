"""Run inside Blender's Python (the `bpy` module, tests/tools/blender.py):
import a glTF binary and a USD file of the same bake, each into a fresh
scene, and record what a Blender user sees at given frame numbers: every
pose bone's head in world coordinates (m, Blender's Z up), the imported
action's frame range and the scene's frame range.

    python blender_frames.py FILE.glb FILE.usd OUT.json FRAME [FRAME ...]
"""

import json
import sys

import bpy


def sample(frames: list[int]) -> dict:
    scene = bpy.context.scene
    out = {"scene_range": [scene.frame_start, scene.frame_end], "fps": scene.render.fps,
           "actions": [], "heads": {}}
    arms = [o for o in scene.objects if o.type == "ARMATURE"]
    for arm in arms:
        ad = arm.animation_data
        if ad and ad.action:
            out["actions"].append(list(ad.action.frame_range))
    for k in frames:
        scene.frame_set(k)
        heads = {}
        for arm in arms:
            for pb in arm.pose.bones:
                heads[pb.name] = list(arm.matrix_world @ pb.head)
        out["heads"][str(k)] = heads
    return out


def main() -> None:
    glb, usd, target, *frames = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv \
        else sys.argv[1:]
    frames = [int(f) for f in frames]
    result = {}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    result["glb"] = sample(frames)
    scene = bpy.context.scene
    if "treebake" in scene:  # the glTF scene's extras.treebake, a custom property
        r = scene["treebake"]
        result["glb"]["scene_props"] = r.to_dict()
        # docs/formats.md's line for Blender: the scene range from that property
        scene.frame_start, scene.frame_end = r["frame_start"], r["frame_end"]
        result["glb"]["scene_range_set"] = [scene.frame_start, scene.frame_end]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=usd)
    result["usd"] = sample(frames)
    result["blender"] = bpy.app.version_string
    with open(target, "w") as fh:
        json.dump(result, fh)


main()
