"""Run inside Blender's Python (the `bpy` module, tests/tools/blender.py):
import an Alembic archive the way docs/formats.md says (a new scene set to
the bake's frame rate first, then File > Import > Alembic with its
defaults), and record what a Blender user sees: every object's name, type,
parent and world matrix (m, Blender's Z up) at given frame numbers, the
scene's frame range and rate after the import, and for some frames every
mesh object's evaluated vertices (world), its triangles as Blender winds
them and their normals, and its material slots.

    python blender_abc.py FILE.abc OUT.npz FPS FRAME [FRAME ...] [--mesh-frames K,K,...]

Writes OUT.npz (numpy; `info` is JSON text).
"""

import json
import sys

import bpy
import numpy as np


def _args() -> list[str]:
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


def main() -> None:
    args = _args()
    mesh_frames: set[int] = set()
    if "--mesh-frames" in args:
        i = args.index("--mesh-frames")
        mesh_frames = {int(v) for v in args[i + 1].split(",")}
        del args[i:i + 2]
    path, target, fps, *frames = args
    frames = [int(f) for f in frames]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = int(fps), 1.0  # before importing
    options = bpy.ops.wm.alembic_import.get_rna_type().properties.keys()
    kw = {"as_background_job": False} if "as_background_job" in options else {}
    bpy.ops.wm.alembic_import(filepath=path, **kw)
    objects = sorted(scene.objects, key=lambda o: o.name)
    info = {"blender": bpy.app.version_string,
            "scene_range": [scene.frame_start, scene.frame_end], "fps": scene.render.fps,
            "fps_base": scene.render.fps_base,
            "names": [o.name for o in objects], "types": [o.type for o in objects],
            "parents": [o.parent.name if o.parent else "" for o in objects],
            "data": [o.data.name if o.data is not None else "" for o in objects],
            "materials": {o.name: [s.material.name if s.material else "" for s in
                                   o.material_slots] for o in objects if o.type == "MESH"},
            "modifiers": {o.name: [m.type for m in o.modifiers] for o in objects},
            "constraints": {o.name: [c.type for c in o.constraints] for o in objects},
            "frames": frames}
    arrays = {"world": np.zeros((len(frames), len(objects), 4, 4))}
    for i, k in enumerate(frames):
        scene.frame_set(k)
        graph = bpy.context.evaluated_depsgraph_get()
        for j, ob in enumerate(objects):
            arrays["world"][i, j] = np.array(ob.evaluated_get(graph).matrix_world)
        if k not in mesh_frames:
            continue
        for ob in objects:
            if ob.type != "MESH":
                continue
            ev = ob.evaluated_get(graph)
            me = ev.to_mesh()
            co = np.empty(3 * len(me.vertices))
            me.vertices.foreach_get("co", co)
            m = np.array(ev.matrix_world)
            co = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
            loops = np.empty(len(me.loops), np.int64)
            me.loops.foreach_get("vertex_index", loops)
            total = np.empty(len(me.polygons), np.int64)
            me.polygons.foreach_get("loop_total", total)
            normal = np.empty(3 * len(me.polygons))
            me.polygons.foreach_get("normal", normal)
            assert (total == 3).all(), "triangles only"
            arrays[f"co/{k}/{ob.name}"] = co
            arrays[f"tri/{k}/{ob.name}"] = loops.reshape(-1, 3)
            arrays[f"normal/{k}/{ob.name}"] = normal.reshape(-1, 3) @ m[:3, :3].T
            ev.to_mesh_clear()
    np.savez(target, info=np.array(json.dumps(info)), **arrays)


main()
