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
glTF has no segment tips: our exporter writes a terminal joint's tip in its
node's `extras.tip`; a file without them comes back with those segments'
ends at their bases, listed in the tree's info["tipless"] (diff then
compares their bases). The file's structure is checked on the way (chunk
and buffer lengths, accessor ranges, declared min/max, finite values, unit
quaternions), so a truncated or overwritten file is an error.
The keyframe reduction's declared tolerances come back in meta["reduction"].
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..bake import Bake, TreeBake

from ..bake_file import check_finite
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
    """The JSON document and the binary buffer, every length checked: a
    truncated or overwritten file is an error here, not a silent result."""
    data = path.read_bytes()
    if not data:
        raise InputError(f"{path}: the file is empty (0 bytes)")
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise InputError(f"{path}: not a binary glTF file (no 'glTF' header)")
        version, total = struct.unpack_from("<II", data, 4)
        if version != 2:
            raise InputError(f"{path}: glTF version {version}, expected 2")
        if total != len(data):
            raise InputError(f"{path}: the header says {total} bytes, the file has {len(data)} "
                             "(truncated or appended to)")
        length, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A or 20 + length > len(data):
            raise InputError(f"{path}: the JSON chunk is damaged (type {kind:#x}, "
                             f"{length} bytes)")
        doc = json.loads(data[20:20 + length])
        blob = b""
        at = 20 + length
        if at + 8 <= len(data):
            blen, kind = struct.unpack_from("<II", data, at)
            if kind != 0x004E4942 or at + 8 + blen != len(data):
                raise InputError(f"{path}: the binary chunk is damaged (type {kind:#x}, "
                                 f"{blen} bytes at {at + 8} of {len(data)})")
            blob = data[at + 8:at + 8 + blen]
        elif at != len(data):
            raise InputError(f"{path}: {len(data) - at} stray bytes after the JSON chunk")
    else:
        doc = json.loads(data)
        buffers = doc.get("buffers", [])
        blob = (path.parent / buffers[0]["uri"]).read_bytes() if buffers and \
            "uri" in buffers[0] else b""
    if not isinstance(doc, dict) or str(doc.get("asset", {}).get("version")) != "2.0":
        raise InputError(f"{path}: not a glTF 2.0 document")
    buffers = doc.get("buffers", [])
    if buffers and buffers[0].get("byteLength") != len(blob):
        raise InputError(f"{path}: buffer 0 should hold {buffers[0].get('byteLength')} bytes, "
                         f"found {len(blob)} (truncated?)")
    for i, view in enumerate(doc.get("bufferViews", [])):
        if view.get("byteOffset", 0) + view["byteLength"] > len(blob):
            raise InputError(f"{path}: bufferView {i} runs past the end of the buffer")
    return doc, blob


def _accessor(doc: dict, blob: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = np.dtype(_DTYPES[acc["componentType"]])
    width = _WIDTH[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", dtype.itemsize * width)
    count = acc["count"]
    if count < 0 or (count and acc.get("byteOffset", 0) + stride * (count - 1)
                     + dtype.itemsize * width > view["byteLength"]):
        raise ValueError(f"accessor {index} runs past its bufferView")
    raw = np.frombuffer(blob, dtype=np.uint8, count=view["byteLength"],
                        offset=view.get("byteOffset", 0))
    rows = np.lib.stride_tricks.as_strided(
        raw[start - view.get("byteOffset", 0):], shape=(count, dtype.itemsize * width),
        strides=(stride, 1))
    out = np.ascontiguousarray(rows).view(dtype).reshape(count, width).astype(np.float64)
    if not np.isfinite(out).all():
        raise ValueError(f"accessor {index} holds NaN or infinite values (damaged data)")
    if "min" in acc and "max" in acc and count:  # the file's own bounds: overwritten data
        lo, hi = np.asarray(acc["min"], float), np.asarray(acc["max"], float)  # falls outside
        slack = 1e-6 * np.maximum(1.0, np.abs(np.concatenate([lo, hi])).max())
        if (out < lo - slack).any() or (out > hi + slack).any():
            raise ValueError(f"accessor {index} holds values outside its declared min/max "
                             "(damaged data)")
    return out


def _check_meshes(doc: dict, blob: bytes) -> None:
    """Read every accessor of every mesh and check what its kind promises:
    positions inside their declared min/max, unit normals, skin weights in
    [0, 1] summing to 1, joint and vertex indices in range, finite values.
    Bytes overwritten in a mesh show up here although diff compares only
    motion. (A manifest.json beside the file catches every change: diff
    checks its sha256 too.)"""
    skins = doc.get("skins", [])
    for n, node in enumerate(doc.get("nodes", [])):
        if "mesh" not in node:
            continue
        joints = len(skins[node["skin"]]["joints"]) if "skin" in node else 0
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            attrs = prim["attributes"]
            count = doc["accessors"][attrs["POSITION"]]["count"]
            for name, index in attrs.items():
                values = _accessor(doc, blob, index)
                if name == "NORMAL" and len(values) and \
                        np.abs(np.linalg.norm(values, axis=1) - 1).max() > 1e-3:
                    raise ValueError(f"node {n}: normals are not unit length (damaged data)")
                if name == "WEIGHTS_0" and len(values) and \
                        ((values < 0).any() or (values > 1).any()
                         or np.abs(values.sum(axis=1) - 1).max() > 1e-3):
                    raise ValueError(f"node {n}: skin weights do not sum to 1 (damaged data)")
                if name == "JOINTS_0" and len(values) and values.max() >= max(joints, 1):
                    raise ValueError(f"node {n}: a vertex names joint {int(values.max())} of "
                                     f"{joints} (damaged data)")
            if "indices" in prim:
                idx = _accessor(doc, blob, prim["indices"])
                if len(idx) and idx.max() >= count:
                    raise ValueError(f"node {n}: a triangle names vertex {int(idx.max())} of "
                                     f"{count} (damaged data)")


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
        _check_meshes(doc, blob)
        return _to_bake(doc, blob, p)
    except InputError:
        raise
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError,
            struct.error) as exc:
        raise InputError(f"{p}: not a readable treebake glTF file ({exc})") from None


@dataclass(frozen=True)
class _FrameGrid:
    """The bake's sample times (F,) s from its first frame, frames per
    second, and the key time (s) of the first frame in the file."""

    times: np.ndarray
    fps: float
    offset: float


def _to_bake(doc: dict, blob: bytes, p: Path) -> Bake:
    nodes = doc.get("nodes", [])
    info = doc.get("asset", {}).get("extras", {}).get("treebake", {})
    channels, all_keys = _channels(doc, blob)
    grid = _frame_grid(info, all_keys)
    parent_of = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
    trees = []
    for skin in doc.get("skins", []):
        trees.append(_skin_tree(doc, blob, skin, channels, grid, parent_of, p,
                                f"tree{len(trees)}"))
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
    meta = {"fps": grid.fps, "scene": p.stem, "source": str(p)}
    if isinstance(info.get("reduction"), dict):
        meta["reduction"] = info["reduction"]
    bake = Bake(grid.times, trees, meta)
    check_finite(bake, str(p))
    return bake


def _channels(doc: dict, blob: bytes) -> tuple[dict, list[np.ndarray]]:
    """(node, "translation" or "rotation") -> key times (K,) s and values
    (K, 3) or (K, 4) of every animation channel, checked (increasing key
    times, unit quaternions); and every channel's key times."""
    channels: dict[tuple[int, str], tuple[np.ndarray, np.ndarray]] = {}
    all_keys = []
    for anim in doc.get("animations", []):
        for ch in anim["channels"]:
            sampler = anim["samplers"][ch["sampler"]]
            keys = _accessor(doc, blob, sampler["input"])[:, 0]
            if len(keys) > 1 and not (np.diff(keys) > 0).all():
                raise ValueError("animation key times do not increase (damaged data)")
            values = _accessor(doc, blob, sampler["output"])
            if ch["target"]["path"] == "rotation" and len(values) and \
                    np.abs(np.linalg.norm(values, axis=1) - 1.0).max() > 1e-3:
                raise ValueError(f"node {ch['target']['node']}: a rotation key is not a unit "
                                 "quaternion (damaged data)")
            channels[(ch["target"]["node"], ch["target"]["path"])] = (keys, values)
            all_keys.append(keys)
    return channels, all_keys


def _frame_grid(info: dict, all_keys: list[np.ndarray]) -> _FrameGrid:
    """The frames our exporter declared in `asset.extras.treebake`; else the
    union of the key times `all_keys` (s), else one frame at 24 fps."""
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
    return _FrameGrid(times, fps, offset)


def _skin_tree(doc: dict, blob: bytes, skin: dict, channels: dict, grid: _FrameGrid,
               parent_of: dict[int, int], p: Path, default_name: str) -> TreeBake:
    """One skin as a tree: its joints are the segments, their rest bases (m)
    from the inverse bind matrices and their motion sampled on the grid,
    turned to Z up."""
    nodes = doc.get("nodes", [])
    joints = skin["joints"]
    index = {node: s for s, node in enumerate(joints)}
    seg_parent = np.array([index.get(parent_of.get(j, -1), -1) for j in joints],
                          dtype=np.int64)
    ibm = _accessor(doc, blob, skin["inverseBindMatrices"]).reshape(-1, 4, 4)
    rest = points_z_up(-ibm[:, 3, :3])
    S = len(joints)
    t_loc, q_loc = _local_motion(nodes, joints, channels, grid)
    norms = np.linalg.norm(q_loc, axis=-1)
    if np.abs(norms - 1.0).max(initial=0.0) > 1e-3:
        raise ValueError(f"skin {skin.get('name')!r}: a joint rotation is not a unit "
                         "quaternion (damaged data)")
    pos, rot = _world(seg_parent, t_loc, q_loc)
    end = np.arange(S)
    tips, tipless = [], []
    for s in range(S):  # a segment ends where its first child starts
        kids = np.nonzero(seg_parent == s)[0]
        if len(kids):
            end[s] = kids[0]
            continue
        tip = nodes[joints[s]].get("extras", {}).get("tip")  # terminal: its own tip
        if tip is None:  # an older file: the tip is unknown, diff compares its base
            tipless.append(s)
            continue
        end[s] = S + len(tips)
        tips.append(rest[s] + points_z_up(np.asarray(tip, float)[None])[0])
    if tips:
        rest = np.concatenate([rest, np.asarray(tips)])
    # the segment path rides in extras (node names are made tool-safe)
    paths = [nodes[j].get("extras", {}).get("segment_path", nodes[j].get("name", f"joint{s}"))
             for s, j in enumerate(joints)]
    tree_info: dict = {"source": p.name}
    if tipless:
        tree_info["tipless"] = tipless
    return TreeBake(
        name=skin.get("name", default_name), points=rest,
        seg_start=np.arange(S), seg_end=end, seg_parent=seg_parent,
        seg_limb=np.zeros(S, np.int64), width=np.zeros(S), leaf=np.zeros(S, np.int64),
        leaf_size=np.zeros(S), limb_parent=np.zeros(0, np.int64),
        limb_attach=np.zeros(0, np.int64), limb_points=[], paths=paths,
        positions=points_z_up(pos).astype(np.float32),
        rotations=quats_z_up(rot).astype(np.float32), info=tree_info)


def _local_motion(nodes: list[dict], joints: list[int], channels: dict,
                  grid: _FrameGrid) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's local translation (F, S, 3) m and rotation (F, S, 4)
    x y z w (glTF's Y up) on the grid: its channels sampled LINEAR, else its
    node's fixed transform."""
    frames, S = len(grid.times), len(joints)
    t_loc = np.empty((frames, S, 3))
    q_loc = np.empty((frames, S, 4))
    for s, j in enumerate(joints):
        node = nodes[j]
        t_loc[:, s] = node.get("translation", [0.0, 0.0, 0.0])
        q_loc[:, s] = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
        if (j, "translation") in channels:
            t_loc[:, s] = _sample(grid.times + grid.offset, *channels[(j, "translation")],
                                  rotation=False)
        if (j, "rotation") in channels:
            q_loc[:, s] = _sample(grid.times + grid.offset, *channels[(j, "rotation")],
                                  rotation=True)
    return t_loc, q_loc


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
