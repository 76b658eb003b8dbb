"""An independent glTF 2.0 reader for the export tests: pygltflib parses the
file; accessors, LINEAR animation sampling (lerp / slerp), the node
hierarchy and linear-blend skinning are done here from the spec, sharing
no code with exporter/exchange."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib

_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
           5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = (float(v) for v in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def slerp(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """glTF spec slerp (shortest path)."""
    d = float(np.dot(a, b))
    if d < 0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + t * (b - a)
    else:
        th = np.arccos(d)
        q = (np.sin((1 - t) * th) * a + np.sin(t * th) * b) / np.sin(th)
    return q / np.linalg.norm(q)


class Gltf:
    def __init__(self, path: str | Path) -> None:
        path = Path(path)
        self.g = pygltflib.GLTF2().load(str(path))
        if path.suffix == ".glb":
            self.blob = self.g.binary_blob()
        else:
            self.blob = (path.parent / self.g.buffers[0].uri).read_bytes()
        self.parent = {c: i for i, n in enumerate(self.g.nodes) for c in (n.children or [])}
        self._cache: dict[int, np.ndarray] = {}
        self.channels: dict[tuple[int, str], tuple[np.ndarray, np.ndarray]] = {}
        for anim in self.g.animations or []:
            for ch in anim.channels:
                s = anim.samplers[ch.sampler]
                assert s.interpolation == "LINEAR"
                self.channels[(ch.target.node, ch.target.path)] = (
                    self.accessor(s.input), self.accessor(s.output))

    def accessor(self, i: int) -> np.ndarray:
        if i in self._cache:
            return self._cache[i]
        a = self.g.accessors[i]
        v = self.g.bufferViews[a.bufferView]
        assert v.byteStride in (None, 0)
        n = _WIDTH[a.type]
        dt = np.dtype(_DTYPES[a.componentType])
        start = (v.byteOffset or 0) + (a.byteOffset or 0)
        arr = np.frombuffer(self.blob, dtype=dt, count=a.count * n, offset=start)
        arr = arr.reshape(a.count, n) if n > 1 else arr
        self._cache[i] = arr
        return arr

    def node_index(self, name: str) -> int:
        return next(i for i, n in enumerate(self.g.nodes) if n.name == name)

    def local(self, node: int, t: float) -> np.ndarray:
        """4x4 local transform of `node` at time t (s)."""
        n = self.g.nodes[node]
        tr = np.array(n.translation or [0, 0, 0], np.float64)
        q = np.array(n.rotation or [0, 0, 0, 1], np.float64)
        for path in ("translation", "rotation"):
            ch = self.channels.get((node, path))
            if ch is None:
                continue
            times, vals = ch[0].astype(np.float64), ch[1].astype(np.float64)
            if t <= times[0]:
                v = vals[0]
            elif t >= times[-1]:
                v = vals[-1]
            else:
                k = int(np.searchsorted(times, t, side="right")) - 1
                u = (t - times[k]) / (times[k + 1] - times[k])
                v = (slerp(vals[k], vals[k + 1], u) if path == "rotation"
                     else vals[k] + u * (vals[k + 1] - vals[k]))
            if path == "translation":
                tr = v
            else:
                q = v
        assert n.scale in (None, [1, 1, 1])
        m = np.eye(4)
        m[:3, :3] = quat_to_matrix(q)
        m[:3, 3] = tr
        return m

    def world(self, node: int, t: float) -> np.ndarray:
        m = self.local(node, t)
        p = self.parent.get(node)
        while p is not None:
            m = self.local(p, t) @ m
            p = self.parent.get(p)
        return m

    def worlds(self, nodes: list[int], t: float) -> np.ndarray:
        """World matrices of many nodes at t, each parent evaluated once."""
        memo: dict[int, np.ndarray] = {}

        def w(i: int) -> np.ndarray:
            if i not in memo:
                p = self.parent.get(i)
                memo[i] = self.local(i, t) if p is None else w(p) @ self.local(i, t)
            return memo[i]

        return np.stack([w(i) for i in nodes])

    def skinned(self, mesh_node: int, t: float) -> np.ndarray:
        """Vertex positions (V, 3) of a skinned mesh node at t (primitive 0's
        attributes, shared by all primitives of our meshes)."""
        n = self.g.nodes[mesh_node]
        skin = self.g.skins[n.skin]
        attrs = self.g.meshes[n.mesh].primitives[0].attributes
        pos = self.accessor(attrs.POSITION).astype(np.float64)
        joints = self.accessor(attrs.JOINTS_0).astype(np.int64)
        weights = self.accessor(attrs.WEIGHTS_0).astype(np.float64)
        ibm = self.accessor(skin.inverseBindMatrices).astype(np.float64).reshape(-1, 4, 4)
        ibm = np.transpose(ibm, (0, 2, 1))  # stored column-major
        jm = self.worlds(skin.joints, t) @ ibm
        h = np.concatenate([pos, np.ones((len(pos), 1))], axis=1)
        out = np.zeros((len(pos), 4))
        for c in range(4):
            m = jm[joints[:, c]]
            out += weights[:, c:c + 1] * np.einsum("vij,vj->vi", m, h)
        return out[:, :3]
