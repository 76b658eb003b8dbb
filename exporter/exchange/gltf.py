"""glTF 2.0 writer (.glb, or .gltf + .bin): trees as skinned meshes whose
joints are the segments, LINEAR animation channels, projectiles as animated
rigid nodes. Units metres, Y up ((x, y, z) -> (x, z, -y), see axes.py).

Layout per animated tree: a root node named after the tree (identity
transform, the skin's `skeleton`) whose descendants are the joint nodes
(one per segment, parented like the segments, named `<tree>_<limb>_s<k>`
as names.py makes them, the segment path in `extras.segment_path`, a
terminal joint's segment tip, rest offset Y up, in `extras.tip`); a
separate root node `<tree>_mesh` holds the mesh and the skin (glTF ignores
a skinned mesh node's own transform, so it has none). Every node name is
unique in the file and kept unchanged by three.js, Blender, Maya, Houdini.
A joint's node transform is its frame-0 local transform; channels exist
only where it changes. Static trees are plain meshes with no joints and no
animation. Key times: frame f at (frame_start + f) / fps s.
`asset.extras.treebake` holds the frame grid (fps, frames, frame_start) and
the keyframe reduction's world tolerances (`reduction`), for treebake diff.
glTF has no scene frame range: the scene's `extras.treebake` holds it
(frame_start, frame_end, fps) for a DCC to set (Blender makes it the
scene's custom property `treebake`; docs/formats.md says what each needs).
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .. import __version__
from ..bake import Bake
from ..bake_file import tree_info
from ..fileio import write_bytes
from ..names import joint_names
from ..sampling import FAST_TURN_DEG
from .anim import Animation, ReduceOptions, animate, subtree_reach
from .axes import points_y_up, quats_y_up
from .mesh import TreeMesh, object_mesh
from .textures import Texture

FLOAT, USHORT, UINT = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
LINEAR, LINEAR_MIPMAP_LINEAR, REPEAT, CLAMP_TO_EDGE = 9729, 9987, 10497, 33071
_IDENTITY_Q = (0.0, 0.0, 0.0, 1.0)


class _Buffer:
    """One binary buffer; every accessor gets its own 4-byte aligned view."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.length = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []
        self._times: dict[bytes, int] = {}

    def add(self, array: np.ndarray, ctype: int, atype: str, target: int | None = None,
            bounds: bool = False) -> int:
        dtype = {FLOAT: np.float32, USHORT: np.uint16, UINT: np.uint32}[ctype]
        data = np.ascontiguousarray(array, dtype=dtype)
        raw = data.tobytes()
        view = {"buffer": 0, "byteOffset": self.length, "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self.parts.append(raw + b"\0" * (-len(raw) % 4))
        self.length += len(raw) + (-len(raw) % 4)
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": ctype,
               "count": int(data.shape[0]), "type": atype}
        if bounds:
            flat = data.reshape(data.shape[0], -1)
            acc["min"] = [_num(v) for v in flat.min(axis=0)]
            acc["max"] = [_num(v) for v in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def raw(self, data: bytes) -> int:
        """A buffer view of raw bytes (an embedded image); returns its index."""
        self.views.append({"buffer": 0, "byteOffset": self.length, "byteLength": len(data)})
        self.parts.append(data + b"\0" * (-len(data) % 4))
        self.length += len(data) + (-len(data) % 4)
        return len(self.views) - 1

    def times(self, seconds: np.ndarray) -> int:
        """A keyframe-time accessor (min/max set, as animation inputs need),
        shared by every channel with the same keys."""
        data = np.asarray(seconds, dtype=np.float32)
        key = data.tobytes()
        if key not in self._times:
            self._times[key] = self.add(data, FLOAT, "SCALAR", bounds=True)
        return self._times[key]

    def blob(self) -> bytes:
        return b"".join(self.parts)


def _num(v) -> float | int:
    """A JSON number that reads back as exactly the stored float32/int."""
    if isinstance(v, np.integer):
        return int(v)
    f = float(v)
    return int(f) if f.is_integer() and abs(f) < 2**53 else f


def _floats(values) -> list[float]:
    return [_num(np.float32(v)) for v in values]


@dataclass
class GltfResult:
    """What was written: files and the keyframe-reduction report."""

    files: list[Path] = field(default_factory=list)
    animation: dict = field(default_factory=dict)


class _Document:
    def __init__(self, name: str, extras: dict | None = None,
                 scene_extras: dict | None = None,
                 textures: dict[str, Texture | None] | None = None) -> None:
        self.extras = extras or {}
        self.scene_extras = scene_extras or {}
        self.texture_of = textures or {}  # material -> Texture (None: plain colour)
        self.images: list[dict] = []
        self.samplers_tex: list[dict] = []
        self.textures: list[dict] = []
        self.buf = _Buffer()
        self.nodes: list[dict] = []
        self.meshes: list[dict] = []
        self.skins: list[dict] = []
        self.materials: list[dict] = []
        self.material_ids: dict[str, int] = {}
        self.roots: list[int] = []
        self.samplers: list[dict] = []
        self.channels: list[dict] = []
        self.name = name

    def node(self, spec: dict, root: bool = False) -> int:
        self.nodes.append(spec)
        if root:
            self.roots.append(len(self.nodes) - 1)
        return len(self.nodes) - 1

    def texture(self, tex: Texture) -> int:
        """Embed a PNG (image in the buffer, its sampler, the texture)."""
        self.images.append({"name": tex.name.removesuffix(".png"), "mimeType": "image/png",
                            "bufferView": self.buf.raw(tex.png)})
        wrap = REPEAT if tex.repeat else CLAMP_TO_EDGE
        self.samplers_tex.append({"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR,
                                  "wrapS": wrap, "wrapT": wrap})
        self.textures.append({"sampler": len(self.samplers_tex) - 1,
                              "source": len(self.images) - 1})
        return len(self.textures) - 1

    def material(self, name: str, colour, double_sided: bool) -> int:
        if name not in self.material_ids:
            tex = self.texture_of.get(name)
            pbr = {"baseColorFactor": _floats([*colour, 1.0]), "metallicFactor": 0,
                   "roughnessFactor": 0.9}
            if tex is not None:  # the colour is in the texture (sRGB), the factor is white
                pbr["baseColorFactor"] = [1, 1, 1, 1]
                pbr["baseColorTexture"] = {"index": self.texture(tex)}
            mat = {"name": name, "pbrMetallicRoughness": pbr}
            if tex is not None and tex.normal is not None:
                # tangent space: the mesh's TANGENT attribute (the validator
                # warns where a viewer would have to generate it)
                mat["normalTexture"] = {"index": self.texture(tex.normal)}
            if tex is not None and tex.cutout:
                mat["alphaMode"] = "MASK"
                mat["alphaCutoff"] = 0.5
            if double_sided:
                mat["doubleSided"] = True
            self.materials.append(mat)
            self.material_ids[name] = len(self.materials) - 1
        return self.material_ids[name]

    def has_normal_map(self, material: str) -> bool:
        tex = self.texture_of.get(material)
        return tex is not None and tex.normal is not None

    def mesh(self, mesh: TreeMesh, name: str, skinned: bool, offset: np.ndarray | None = None):
        """Add `mesh` (world, Z up; minus `offset` for rigid objects)."""
        b = self.buf
        pos = points_y_up(mesh.positions)
        attrs = {"POSITION": b.add(pos, FLOAT, "VEC3", ARRAY_BUFFER, bounds=True),
                 "NORMAL": b.add(points_y_up(mesh.normals), FLOAT, "VEC3", ARRAY_BUFFER),
                 "TEXCOORD_0": b.add(np.stack([mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]], 1), FLOAT,
                                     "VEC2", ARRAY_BUFFER)}
        if mesh.tangents is not None and any(self.has_normal_map(p.shader) for p in mesh.parts):
            tangents = np.concatenate([points_y_up(mesh.tangents[:, :3]), mesh.tangents[:, 3:]], 1)
            attrs["TANGENT"] = b.add(tangents, FLOAT, "VEC4", ARRAY_BUFFER)
        if skinned:
            joints = np.zeros((mesh.n_vertices, 4), np.uint16)
            weights = np.zeros((mesh.n_vertices, 4), np.float32)
            joints[:, :2] = mesh.joints
            w1 = mesh.weights[:, 1].astype(np.float32)
            weights[:, 1] = w1
            weights[:, 0] = np.float32(1.0) - w1
            joints[:, 1] = np.where(w1 > 0, joints[:, 1], 0)
            attrs["JOINTS_0"] = b.add(joints, USHORT, "VEC4", ARRAY_BUFFER)
            attrs["WEIGHTS_0"] = b.add(weights, FLOAT, "VEC4", ARRAY_BUFFER)
        prims = []
        big = mesh.n_vertices >= 65535
        for part in mesh.parts:
            if len(part.faces) == 0:
                continue
            idx = b.add(part.faces.reshape(-1), UINT if big else USHORT, "SCALAR",
                        ELEMENT_ARRAY_BUFFER)
            # TANGENT only where the material reads it (else validator infos)
            own = attrs if self.has_normal_map(part.shader) else \
                {k: a for k, a in attrs.items() if k != "TANGENT"}
            prims.append({"attributes": own, "indices": idx,
                          "material": self.material(part.shader, part.colour,
                                                    part.double_sided)})
        self.meshes.append({"name": name, "primitives": prims})
        return len(self.meshes) - 1

    def channel(self, node: int, path: str, seconds: np.ndarray, values: np.ndarray) -> None:
        b = self.buf
        out = b.add(values, FLOAT, "VEC3" if path == "translation" else "VEC4")
        self.samplers.append({"input": b.times(seconds), "output": out,
                              "interpolation": "LINEAR"})
        self.channels.append({"sampler": len(self.samplers) - 1,
                              "target": {"node": node, "path": path}})

    def encode(self, bin_uri: str | None) -> tuple[bytes, bytes]:
        blob = self.buf.blob()
        buffer = {"byteLength": len(blob)}
        if bin_uri is not None:
            buffer["uri"] = bin_uri
        asset = {"version": "2.0", "generator": f"treebake {__version__}"}
        if self.extras:
            asset["extras"] = {"treebake": self.extras}
        scene = {"name": self.name, "nodes": self.roots}
        if self.scene_extras:  # Blender makes them the scene's custom properties
            scene["extras"] = {"treebake": self.scene_extras}
        doc = {"asset": asset, "scene": 0, "scenes": [scene],
               "nodes": self.nodes, "meshes": self.meshes, "materials": self.materials}
        if self.textures:
            doc.update(textures=self.textures, images=self.images, samplers=self.samplers_tex)
        if self.skins:
            doc["skins"] = self.skins
        if self.channels:
            doc["animations"] = [{"name": self.name, "samplers": self.samplers,
                                  "channels": self.channels}]
        doc["accessors"] = self.buf.accessors
        doc["bufferViews"] = self.buf.views
        doc["buffers"] = [buffer]
        if not blob:
            for key in ("accessors", "bufferViews", "buffers"):
                doc.pop(key)
        text = json.dumps(doc, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
        return text, blob


def _trs(translation, rotation) -> dict:
    spec = {}
    t = _floats(translation)
    if any(t):
        spec["translation"] = t
    q = _floats(rotation)
    if tuple(q) != _IDENTITY_Q:
        spec["rotation"] = q
    return spec


def _add_tree(doc: _Document, bake: Bake, i: int, mesh: TreeMesh, anim: Animation | None,
              first: int) -> None:
    """Tree i; its joints are rows first..first+S-1 of `anim`."""
    tree = bake.trees[i]
    # mesh names differ from node names: three.js names a mesh's objects by
    # both, and would suffix the second one it met
    if anim is None:
        doc.node({"name": tree.name, "mesh": doc.mesh(mesh, f"{tree.name}_geo", skinned=False)},
                 root=True)
        return
    S = tree.n_segments
    root = doc.node({"name": tree.name}, root=True)
    base = len(doc.nodes)
    children: dict[int, list[int]] = {}
    for s in range(S):
        children.setdefault(int(tree.seg_parent[s]), []).append(base + s)
    # glTF has no bone length: a terminal joint carries its segment's tip
    # (rest offset from its base, Y up) so a reader (treebake diff) can pose it;
    # every joint carries its segment path (node names are made tool-safe)
    tips = points_y_up(tree.points[tree.seg_end] - tree.points[tree.seg_start])
    for s, name in enumerate(joint_names(tree.name, tree.paths)):
        extras = {"segment_path": tree.paths[s]}
        if s not in children:
            extras["tip"] = _floats(tips[s])
        doc.node({"name": name, **_trs(anim.translation[first + s], anim.rotation[first + s]),
                  "extras": extras})
    doc.nodes[root]["children"] = children.get(-1, [])
    for s, kids in children.items():
        if s >= 0:
            doc.nodes[base + s]["children"] = kids
    rest = points_y_up(tree.points[tree.seg_start])
    ibm = np.tile(np.eye(4, dtype=np.float64), (S, 1, 1))
    ibm[:, 3, :3] = -rest  # column-major: the translation is the 4th column
    ibm_acc = doc.buf.add(ibm.reshape(S, 16), FLOAT, "MAT4")
    doc.skins.append({"name": tree.name, "inverseBindMatrices": ibm_acc,
                      "skeleton": root, "joints": list(range(base, base + S))})
    doc.node({"name": f"{tree.name}_mesh", "mesh": doc.mesh(mesh, f"{tree.name}_geo",
                                                             skinned=True),
              "skin": len(doc.skins) - 1}, root=True)


@dataclass
class AnimationPart:
    """Channels of trees sharing one time grid: `times` (N,) s of the bake
    (its frames, plus a tree's extra sub-frame samples), each tree's first
    joint row (`first`) and the projectiles' first row (or None)."""

    anim: Animation
    times: np.ndarray
    first: dict[int, int]
    obj_first: int | None = None


def _group_animation(bake: Bake, trees: list[int], times: np.ndarray, objects: bool,
                     opts: ReduceOptions) -> AnimationPart | None:
    first: dict[int, int] = {}
    parents, pos, rot, vec, reach, group, allowed = [], [], [], [], [], [], []
    n = 0
    for g, i in enumerate(trees):
        t = bake.trees[i]
        first[i] = n
        _, p, q = t.samples(bake.times)
        allowed.append(t.fast_samples(bake.times))  # sub-frame samples where a part turns fast
        parents.append(np.where(t.seg_parent >= 0, t.seg_parent + n, -1))
        pos.append(points_y_up(p))
        rot.append(quats_y_up(q))
        b, e = points_y_up(t.points[t.seg_start]), points_y_up(t.points[t.seg_end])
        vec.append(e - b)
        margin = float(t.leaf_size.max(initial=0.0)) + float(t.width.max(initial=0.0))
        reach.append(subtree_reach(t.seg_parent, b, e) + margin)
        group.append(np.full(t.n_segments, g))
        n += t.n_segments
    obj_first = None
    if objects and bake.objects is not None and len(bake.objects.sizes):
        o = bake.objects
        k = len(o.sizes)
        obj_first = n
        parents.append(np.full(k, -1))
        pos.append(points_y_up(o.positions))
        rot.append(quats_y_up(o.rotations))
        vec.append(np.zeros((k, 3)))
        reach.append(np.asarray(o.sizes, np.float64))
        group.append(len(trees) + np.arange(k))
        allowed.append(np.ones((len(times), k), bool))
    if not parents:
        return None
    anim = animate(np.concatenate(parents), np.concatenate(pos, axis=1),
                   np.concatenate(rot, axis=1), np.concatenate(vec), np.concatenate(reach),
                   opts, np.concatenate(group), times=times,
                   frames=np.searchsorted(times, bake.times), allowed=np.concatenate(allowed, 1))
    return AnimationPart(anim, times, first, obj_first)


def scene_animation(bake: Bake, trees: list[int], objects: bool,
                    opts: ReduceOptions) -> list[AnimationPart]:
    """Channels for the animated trees in `trees` (and the projectiles),
    reduced together (vectorised), each tree with its own error check.
    Trees on the frame grid share one part; a tree with extra sub-frame
    samples gets a part of its own on its merged grid, where a joint keeps
    them only inside the frame intervals where it turns fast
    (TreeBake.fast_samples)."""
    moving = [i for i in trees if not bake.trees[i].static]
    plain = [i for i in moving if not len(bake.trees[i].extra_times)]
    parts = [_group_animation(bake, plain, np.asarray(bake.times, np.float64), objects, opts)]
    for i in moving:
        if i not in plain:
            parts.append(_group_animation(bake, [i], bake.trees[i].samples(bake.times)[0],
                                          False, opts))
    return [p for p in parts if p is not None]


def build(bake: Bake, name: str, meshes: list[TreeMesh], trees: list[int], objects: bool,
          opts: ReduceOptions, frame_start: int = 1,
          textures: dict[str, Texture | None] | None = None
          ) -> tuple[_Document, list[AnimationPart]]:
    """The glTF document. Key times are (frame_start + frame index) / fps s
    (bake time + frame_start / fps), so an importer's frame = time x fps
    (Blender, three.js's AnimationUtils) is the bake's frame number."""
    n = len(bake.times)
    fps = bake.fps
    # the frame range, which glTF cannot say: frame_start..frame_end at fps
    # key every frame of the bake (keys at frame / fps s)
    hint = {"frame_start": frame_start, "frame_end": frame_start + n - 1, "fps": fps}
    # the frame grid, so a reader (treebake diff) can sample reduced channels,
    # and the reduction's world tolerances: how far the file may be from its bake
    reduction = {"position_m": opts.position_tolerance if opts.enabled else 0.0,
                 "angle_deg": round(math.degrees(opts.angle_tolerance), 9) if opts.enabled
                 else 0.0}
    doc = _Document(name, {"fps": fps, "frames": n, "frame_start": frame_start,
                           "reduction": reduction}, hint, textures)
    parts = scene_animation(bake, trees, objects, opts)
    part_of = {i: p for p in parts for i in p.first}
    joint_node: dict[tuple[int, int], int] = {}  # (part, joint row) -> node
    for i in trees:
        part = part_of.get(i)
        if part is not None:
            joint_node[(id(part), part.first[i])] = len(doc.nodes) + 1  # the root, then joints
        _add_tree(doc, bake, i, meshes[i], None if part is None else part.anim,
                  0 if part is None else part.first[i])
    obj = next((p for p in parts if p.obj_first is not None), None)
    if obj is not None:
        o = bake.objects
        shared: dict[tuple, int] = {}
        for k, (shape, size) in enumerate(zip(o.shapes, o.sizes)):
            key = (shape, float(size))
            if key not in shared:
                shared[key] = doc.mesh(object_mesh(shape, float(size)),
                                       f"{shape}_{round(float(size) * 1000)}mm", skinned=False)
            row = obj.obj_first + k
            joint_node[(id(obj), row)] = doc.node({
                "name": f"projectile_{k}", "mesh": shared[key],
                **_trs(obj.anim.translation[row], obj.anim.rotation[row])}, root=True)
    offset = frame_start / fps
    for part in parts:
        rows = np.array(sorted(r for (pid, r) in joint_node if pid == id(part)))
        seconds = part.times + offset
        for ch in part.anim.channels:
            r = int(rows[np.searchsorted(rows, ch.joint, side="right") - 1])
            doc.channel(int(joint_node[(id(part), r)] + ch.joint - r), ch.path,
                        seconds[ch.frames], ch.values)
    return doc, parts


def write(path: str | Path, doc: _Document) -> list[Path]:
    """.glb (one file) or .gltf (+ .bin beside it), atomically."""
    path = Path(path)
    if path.suffix == ".gltf":
        bin_path = path.with_suffix(".bin")
        text, blob = doc.encode(bin_path.name if doc.buf.length else None)
        files = [write_bytes(path, text)]
        if blob:
            files.append(write_bytes(bin_path, blob))
        return files
    text, blob = doc.encode(None)
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if blob:
        chunks += struct.pack("<II", len(blob), 0x004E4942) + blob
    header = struct.pack("<4sII", b"glTF", 2, 12 + len(chunks))
    return [write_bytes(path, header + chunks)]


@dataclass(frozen=True)
class GltfFile:
    """One glTF file of an export: its name without extension, the trees in
    it (indices into the bake), whether it holds the projectiles."""

    stem: str
    trees: range
    objects: bool


@dataclass(frozen=True)
class GltfSettings:
    """How every file of an export is written: where, .glb or .gltf, the
    keyframe reduction, the first frame's number, the textures to embed."""

    out: Path
    binary: bool
    opts: ReduceOptions
    frame_start: int
    textures: dict | None


@dataclass
class GltfWritten:
    """A file as written: its paths (.gltf and .bin, or .glb), its trees'
    keyframe reports and sub-frame samples."""

    files: list[Path]
    reports: list[dict]
    extra_samples: int


def write_gltf_file(bake: Bake, meshes: Sequence[TreeMesh], job: GltfFile,
                    settings: GltfSettings) -> GltfWritten:
    """Write one file of an export (its trees read into memory while it is
    written, no more). Depends only on its trees: any process writes the
    same bytes."""
    trees, tree_meshes = [], []
    for i in job.trees:  # each tree read once: its mesh is built from the tree just read
        trees.append(bake.trees[i])  # (a stored bake keeps the last tree it read)
        tree_meshes.append(meshes[i])
    part = replace(bake, trees=trees)  # this file's trees
    doc, parts = build(part, job.stem, tree_meshes,
                       list(range(len(job.trees))), job.objects, settings.opts,
                       settings.frame_start, settings.textures)
    ext = ".glb" if settings.binary else ".gltf"
    files = write(settings.out / f"{job.stem}{ext}", doc)
    return GltfWritten(files, [p.anim.report for p in parts],
                       sum(len(t.extra_times) for t in part.trees if not t.static))


FileWriter = Callable[[list[GltfFile], GltfSettings], Iterable[GltfWritten]]


def export_gltf(bake: Bake, meshes: Sequence[TreeMesh], out: str | Path, name: str,
                binary: bool = True, split: bool = False,
                opts: ReduceOptions | None = None, frame_start: int = 1,
                textures: dict[str, Texture | None] | None = None,
                trees_per_file: int | None = None,
                write_files: FileWriter | None = None,
                progress: Callable[[int, int], None] | None = None) -> GltfResult:
    """Write `out/name.glb` (or .gltf + .bin); split: one file per tree,
    `name.<tree>.glb`, and the projectiles in `name.objects.glb`;
    `trees_per_file` N: files of at most N trees, `name.part0001.glb`, ...
    (the projectiles in the first). A file's trees are read into memory
    while it is written, no more. Bake frame f (0-based) is keyed at
    (frame_start + f) / fps s. `textures`: material name -> Texture to
    embed (textures.py); others stay plain. The files are written here or
    by `write_files(jobs, settings)`, which yields them in the jobs' order
    (worker processes: export_pool.py): the same bytes. `progress(done,
    total)` hears the trees written as each file is."""
    settings = GltfSettings(Path(out), binary, opts or ReduceOptions(), frame_start, textures)
    jobs = gltf_files(bake, name, split, trees_per_file)
    if write_files is None:
        written = (write_gltf_file(bake, meshes, job, settings) for job in jobs)
    else:
        written = write_files(jobs, settings)
    result = GltfResult()
    reports = []
    extra = done = 0
    for job, w in zip(jobs, written, strict=True):
        done += len(job.trees)
        if progress is not None:
            progress(done, len(bake.trees))
        result.files += w.files
        reports += w.reports
        extra += w.extra_samples
    result.animation = merge_reports(reports)
    if result.animation:
        result.animation["frames"] = len(bake.times)
        result.animation["extra_samples"] = extra
        result.animation["subframe_turn_deg"] = FAST_TURN_DEG
        result.animation["errors_at"] = "frames"
    return result


def gltf_files(bake: Bake, name: str, split: bool, trees_per_file: int | None) -> list[GltfFile]:
    """The files an export writes: one per tree (`split`; the projectiles
    in their own), files of `trees_per_file` trees, or one."""
    count = len(bake.trees)
    if split:
        jobs = [GltfFile(f"{name}.{tree_info(bake.trees, i)['name']}", range(i, i + 1), False)
                for i in range(count)]
        if bake.objects is not None and len(bake.objects.sizes):
            jobs.append(GltfFile(f"{name}.objects", range(0), True))
        return jobs
    if trees_per_file and count > trees_per_file:
        starts = range(0, count, trees_per_file)
        digits = max(4, len(str(len(starts))))
        return [GltfFile(f"{name}.part{k + 1:0{digits}d}",
                         range(a, min(a + trees_per_file, count)), k == 0)
                for k, a in enumerate(starts)]
    return [GltfFile(name, range(count), True)]


def merge_reports(reports: list[dict]) -> dict:
    if not reports:
        return {}
    out = {k: sum(r[k] for r in reports) for k in ("nodes", "channels", "channels_written",
                                                   "keys_full", "keys_written", "subframe_keys",
                                                   "subframe_channels", "trees_reduced",
                                                   "trees_unreduced")}
    out["frames"] = reports[0]["frames"]
    out["max_position_error_m"] = max(r["max_position_error_m"] for r in reports)
    out["max_angle_error_rad"] = max(r["max_angle_error_rad"] for r in reports)
    return out
