"""Run inside Blender's Python (the `bpy` module, tests/tools/blender.py):
import a treebake glb (or Alembic .abc) and render one frame headless, the
way a user would look at it: a camera framing the trees from the front (-Y,
slightly above), a sun, a sky-coloured world and a ground plane.

    python blender_render.py FILE.glb|FILE.abc OUT.png FRAME [--engine workbench|eevee|cycles]
        [--size 960x540] [--samples 16] [--distance 1.0] [--target X,Y,Z --from X,Y,Z]
        [--fps 24]

Workbench shows textures (colour type TEXTURE) but not their alpha (leaf
cards draw as squares); EEVEE and Cycles use the imported materials as they
are, cutout cards included. Without a GPU, Cycles (CPU) is the quick one.
An Alembic archive has no materials, only face sets that Blender makes
into empty materials of their names (`bark`, `leaf`, ...): they get the
plain colours of docs/formats.md here, and Workbench shows them (colour
type MATERIAL). `--fps`: the scene's frame rate, set before an Alembic
import (docs/formats.md; default 24).
"""

import math
import sys

import bpy
from mathutils import Vector


def _arg(name, default):
    argv = sys.argv
    return argv[argv.index(name) + 1] if name in argv else default


# docs/formats.md's plain material colours (linear RGB), for Alembic imports
# (exchange/mesh.py's BARK_COLOUR, LEAF_COLOURS and OBJECT_COLOUR: Blender's
# Python cannot import treebake; test_blender checks the two agree)
COLOURS = {"bark": (0.36, 0.25, 0.16), "leaf": (0.10, 0.22, 0.055), "leaf2": (0.045, 0.10, 0.06),
           "leaf3": (0.16, 0.24, 0.07), "leaf4": (0.50, 0.21, 0.05), "object": (0.55, 0.45, 0.35)}


def _import_abc(path: str) -> None:
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = int(_arg("--fps", "24")), 1.0
    options = bpy.ops.wm.alembic_import.get_rna_type().properties.keys()
    kw = {"as_background_job": False} if "as_background_job" in options else {}
    bpy.ops.wm.alembic_import(filepath=path, **kw)
    for mat in bpy.data.materials:
        rgb = COLOURS.get(mat.name.split(".")[0])
        if rgb is not None:
            mat.diffuse_color = (*rgb, 1.0)  # what Workbench shows


def main() -> None:
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    glb, out, frame = args[0], args[1], int(args[2])
    engine = _arg("--engine", "workbench")
    w, h = (int(v) for v in _arg("--size", "960x540").split("x"))
    bpy.ops.wm.read_factory_settings(use_empty=True)
    alembic = glb.lower().endswith(".abc")
    if alembic:
        _import_abc(glb)
    else:
        bpy.ops.import_scene.gltf(filepath=glb)
    scene = bpy.context.scene
    scene.frame_set(frame)
    lo, hi = Vector((1e9, 1e9, 1e9)), Vector((-1e9, -1e9, -1e9))
    for ob in scene.objects:
        if ob.type == "MESH":
            for corner in ob.bound_box:
                p = ob.matrix_world @ Vector(corner)
                lo = Vector(map(min, lo, p))
                hi = Vector(map(max, hi, p))
    lo.z = max(lo.z, 0.0)
    centre = (lo + hi) / 2
    size = max(hi.x - lo.x, hi.z - lo.z, 1.0)
    cam = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    cam.data.lens = 35
    if "--target" in sys.argv:
        target = Vector(float(v) for v in _arg("--target", "").split(","))
        cam.location = Vector(float(v) for v in _arg("--from", "").split(","))
    else:
        target = centre
        dist = 1.25 * size * float(_arg("--distance", "1.0"))
        cam.location = centre + Vector((0.15 * dist, -dist, 0.12 * dist))
    direction = target - cam.location
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    cam.data.clip_end = 2000
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 4.0
    sun.rotation_euler = (math.radians(50), 0, math.radians(-35))
    scene.collection.objects.link(sun)
    bpy.ops.mesh.primitive_plane_add(size=4000, location=(0, 0, 0))
    ground = bpy.context.active_object
    mat = bpy.data.materials.new("ground")
    mat.diffuse_color = (0.20, 0.17, 0.11, 1.0)
    mat.use_nodes = True
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (
        0.20, 0.17, 0.11, 1.0)
    ground.data.materials.append(mat)
    world = bpy.data.worlds.new("sky")
    world.color = (0.55, 0.68, 0.85)
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.55, 0.68, 0.85, 1)
    scene.world = world
    scene.render.resolution_x, scene.render.resolution_y = w, h
    scene.render.filepath = out
    if engine == "workbench":
        scene.render.engine = "BLENDER_WORKBENCH"
        shading = scene.display.shading
        shading.light = "STUDIO"
        shading.color_type = "MATERIAL" if alembic else "TEXTURE"
        shading.show_shadows = True
        shading.background_type = "WORLD"
    elif engine == "eevee":
        scene.render.engine = "BLENDER_EEVEE"
    else:
        scene.render.engine = "CYCLES"
        scene.cycles.samples = int(_arg("--samples", "16"))
    bpy.ops.render.render(write_still=True)


main()
