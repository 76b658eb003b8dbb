"""Read the motion back out of a treebake glTF (.glb or .gltf + .bin), as a
Bake, so `treebake diff` can compare exported files.

Each skin is a tree: its joints are the segments (paths in node extras),
parented like the segments, each joint's rest rotation the identity and its
rest position the inverse bind matrix's translation. Channels are sampled at
every frame (the frame grid is in `asset.extras.treebake`, written by our
exporter: frame f is keyed at (frame_start + f) / fps s; otherwise the
union of the key times) with glTF's LINEAR rule
(slerp for rotations), composed down the hierarchy, and turned back from
Y up to our Z up. Static trees (plain meshes) come back with no segments.
glTF has no segment tips, so a terminal segment's end is taken at its base:
rotations still compare everything.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ..bake import Bake, TreeBake
from ..errors import InputError
from ..rotations import (
    apply,
    compose,
    matrices_from_quaternions,
    quaternions_from_matrices,
    slerp,
)
from .axes import points_z_up, quats_z_up

_DTYPES = {5126: np.float32, 5123: np.uint16, 5125: np.uint32, 5121: np.uint8}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _load(path: Path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise InputError(f"{path}: not a binary glTF file")
        length, _ = struct.unpack_from("<II", data, 12)
        doc = json.loads(data[20:20 + length])
        blob = b""
        at = 20 + length
        if at + 8 <= len(data):
            blen, _ = struct.unpack_from("<II", data, at)
            blob = data[at + 8:at + 8 + blen]
        return doc, blob
    doc = json.loads(data)
    buffers = doc.get("buffers", [])
    blob = (path.parent / buffers[0]["uri"]).read_bytes() if buffers and \
        "uri" in buffers[0] else b""
    return doc, blob


def _accessor(doc: dict, blob: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(_DTYPES[acc["componentType"]])
    width = _WIDTH[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", dtype.itemsize * width)
    count = acc["count"]
    raw = np.frombuffer(blob, dtype=np.uint8, count=view["byteLength"],
                        offset=view.get("byteOffset", 0))
    rows = np.lib.stride_tricks.as_strided(
        raw[start - view.get("byteOffset", 0):], shape=(count, dtype.itemsize * width),
        strides=(stride, 1))
    return np.ascontiguousarray(rows).view(dtype).reshape(count, width).astype(np.float64)


def _sample(times: np.ndarray, keys: np.ndarray, values: np.ndarray,
            rotation: bool) -> np.ndarray:
    """LINEAR sampling of one channel at `times` (clamped at the ends)."""
    i = np.clip(np.searchsorted(keys, times, side="right") - 1, 0, len(keys) - 1)
    j = np.minimum(i + 1, len(keys) - 1)
    span = np.where(j > i, keys[j] - keys[i], 1.0)
    t = np.clip((times - keys[i]) / span, 0.0, 1.0)[:, None]
    if rotation:
        return slerp(values[i], values[j], t[:, 0])
    return values[i] * (1 - t) + values[j] * t


def read_gltf_bake(path: str | Path) -> Bake:
    """The trees' motion in a treebake glTF as a Bake (see the module doc)."""
    p = Path(path)
    try:
        doc, blob = _load(p)
        return _to_bake(doc, blob, p)
    except (OSError, ValueError, KeyError, IndexError, struct.error) as exc:
        raise InputError(f"{p}: not a readable glTF file ({exc})") from None


def _to_bake(doc: dict, blob: bytes, p: Path) -> Bake:
    nodes = doc.get("nodes", [])
    info = doc.get("asset", {}).get("extras", {}).get("treebake", {})
    anims = doc.get("animations", [])
    channels: dict[tuple[int, str], tuple[np.ndarray, np.ndarray]] = {}
    all_keys = []
    for anim in anims:
        for ch in anim["channels"]:
            sampler = anim["samplers"][ch["sampler"]]
            keys = _accessor(doc, blob, sampler["input"])[:, 0]
            channels[(ch["target"]["node"], ch["target"]["path"])] = (
                keys, _accessor(doc, blob, sampler["output"]))
            all_keys.append(keys)
    offset = 0.0  # key time of the bake's first frame (files before frame_start: 0)
    if "fps" in info and "frames" in info:
        fps = float(info["fps"])
        offset = float(info.get("frame_start", 0)) / fps
        times = np.arange(int(info["frames"])) / fps
    elif all_keys:
        times = np.unique(np.round(np.concatenate(all_keys), 6))
        fps = 1.0 / float(np.min(np.diff(times))) if len(times) > 1 else 24.0
    else:
        times, fps = np.zeros(1), 24.0
    frames = len(times)
    parent_of = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    trees = []
    for skin in doc.get("skins", []):
        joints = skin["joints"]
        index = {node: s for s, node in enumerate(joints)}
        seg_parent = np.array([index.get(parent_of.get(j, -1), -1) for j in joints],
                              dtype=np.int64)
        ibm = _accessor(doc, blob, skin["inverseBindMatrices"]).reshape(-1, 4, 4)
        rest = points_z_up(-ibm[:, 3, :3])
        S = len(joints)
        t_loc = np.empty((frames, S, 3))
        q_loc = np.empty((frames, S, 4))
        for s, j in enumerate(joints):
            node = nodes[j]
            t_loc[:, s] = node.get("translation", [0.0, 0.0, 0.0])
            q_loc[:, s] = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
            if (j, "translation") in channels:
                t_loc[:, s] = _sample(times + offset, *channels[(j, "translation")],
                                      rotation=False)
            if (j, "rotation") in channels:
                q_loc[:, s] = _sample(times + offset, *channels[(j, "rotation")], rotation=True)
        pos, rot = _world(seg_parent, t_loc, q_loc)
        end = np.arange(S)
        for s in range(S):  # a segment ends where its first child starts
            kids = np.nonzero(seg_parent == s)[0]
            end[s] = kids[0] if len(kids) else s
        # the segment path rides in extras (node names are made tool-safe)
        paths = [nodes[j].get("extras", {}).get("segment_path", nodes[j].get("name", f"joint{s}"))
                 for s, j in enumerate(joints)]
        trees.append(TreeBake(
            name=skin.get("name", f"tree{len(trees)}"), points=rest,
            seg_start=np.arange(S), seg_end=end, seg_parent=seg_parent,
            seg_limb=np.zeros(S, np.int64), width=np.zeros(S), leaf=np.zeros(S, np.int64),
            leaf_size=np.zeros(S), limb_parent=np.zeros(0, np.int64),
            limb_attach=np.zeros(0, np.int64), limb_points=[], paths=paths,
            positions=points_z_up(pos).astype(np.float32),
            rotations=quats_z_up(rot).astype(np.float32), info={"source": p.name}))
    skinned_names = {t.name for t in trees}
    for i in doc.get("scenes", [{}])[doc.get("scene", 0)].get("nodes", []):
        node = nodes[i]
        if "mesh" in node and "skin" not in node and node.get("name") not in skinned_names \
                and not node.get("name", "").startswith("projectile_"):
            trees.append(TreeBake(node.get("name", f"tree{i}"), np.zeros((0, 3)),
                                  *(np.zeros(0, np.int64) for _ in range(4)),
                                  np.zeros(0), np.zeros(0, np.int64), np.zeros(0),
                                  np.zeros(0, np.int64), np.zeros(0, np.int64), [], [],
                                  np.zeros((1, 0, 3), np.float32),
                                  np.zeros((1, 0, 4), np.float32), {"static": "no joints"}))
    return Bake(times, trees, {"fps": fps, "scene": p.stem, "source": str(p)})


def _world(parent: np.ndarray, t_loc: np.ndarray, q_loc: np.ndarray):
    """World translations and rotations (F, S, ...) from local ones; the
    skeleton root has the identity transform (our exporter's layout)."""
    frames, n = t_loc.shape[:2]
    pos = np.empty_like(t_loc)
    mats = np.empty((frames, n, 3, 3))
    local = matrices_from_quaternions(q_loc.reshape(-1, 4)).reshape(frames, n, 3, 3)
    for s in range(n):  # parents precede children in our files
        p = parent[s]
        if p < 0:
            pos[:, s] = t_loc[:, s]
            mats[:, s] = local[:, s]
        else:
            pos[:, s] = pos[:, p] + apply(mats[:, p], t_loc[:, s])
            mats[:, s] = compose(mats[:, p], local[:, s])
    rot = quaternions_from_matrices(mats.reshape(-1, 3, 3)).reshape(frames, n, 4)
    return pos, rot
