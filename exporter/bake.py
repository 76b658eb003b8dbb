"""Bake: baked per-segment world transforms, the one input of every exporter
and of `diff`.

For each tree: rest geometry (enough to build meshes without the grammar),
and per frame and segment the world position of the segment's base point
(m, float32) and its rotation relative to the rest pose (unit quaternion
x y z w, float32). A vertex at rest position v on segment s is posed at
    position[f, s] + R(rotation[f, s]) (v - rest_base[s]).
A tree that nothing moved has one frame. Projectiles are `objects`.

Fast motion: a tree may also carry extra sub-frame samples (`extra_times`,
s, strictly between frame times, sorted; `extra_positions`,
`extra_rotations` with the same meaning as `positions`, `rotations`) where
its segments turn fast (more than 45 degrees between frames). glTF and USD
merge them into the animation keys, but only inside a frame interval where
the part turns more than FAST_TURN_DEG (`TreeBake.fast_samples`): the
simulation records them for the whole tree; OBJ sequences, previews and
`diff` use the frames alone. Empty (K = 0) by default.

Saved as `.npz` written with fixed zip timestamps, so the same bake gives
the same bytes.
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from .errors import InputError
from .fileio import atomic_path
from .rotations import angle_between, qrotate
from .versions import runtime_versions

FORMAT_VERSION = 1
_EXTRAS = ("extra_times", "extra_positions", "extra_rotations")
# degrees: a segment turning more than this between two frames is fast there;
# the simulation records sub-frame samples for it, the exporters keep them
FAST_TURN_DEG = 45.0


@dataclass
class TreeBake:
    name: str
    points: np.ndarray  # (P, 3) rest, world
    seg_start: np.ndarray  # (S,)
    seg_end: np.ndarray  # (S,)
    seg_parent: np.ndarray  # (S,) -1 = ground
    seg_limb: np.ndarray  # (S,)
    width: np.ndarray  # (S,) m
    leaf: np.ndarray  # (S,)
    leaf_size: np.ndarray  # (S,) m
    limb_parent: np.ndarray  # (L,)
    limb_attach: np.ndarray  # (L,) point index in the parent limb where it starts
    limb_points: list[np.ndarray]  # per limb: global point indices, base first
    paths: list[str]  # (S,) "trunk/2/1:3"
    positions: np.ndarray  # (F, S, 3) float32, segment base
    rotations: np.ndarray  # (F, S, 4) float32, x y z w
    info: dict = field(default_factory=dict)  # grammar, hash, seed, events, ...
    extra_times: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (K,) s
    extra_positions: np.ndarray | None = None  # (K, S, 3) float32; None -> (0, S, 3)
    extra_rotations: np.ndarray | None = None  # (K, S, 4) float32, x y z w

    def __post_init__(self):
        S = self.seg_start.shape[0]
        self.extra_times = np.asarray(self.extra_times, dtype=np.float64).reshape(-1)
        K = len(self.extra_times)
        self.extra_positions = np.asarray(
            np.zeros((K, S, 3)) if self.extra_positions is None else self.extra_positions,
            dtype=np.float32).reshape(K, S, 3)
        self.extra_rotations = np.asarray(
            np.zeros((K, S, 4)) if self.extra_rotations is None else self.extra_rotations,
            dtype=np.float32).reshape(K, S, 4)

    def samples(self, frame_times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every sample in time order: times (N,) s, positions (N, S, 3) and
        rotations (N, S, 4), the frames merged with the extra samples, and
        the index of each frame among them is `np.searchsorted(times,
        frame_times)`. Static trees: their one frame."""
        if self.static or not len(self.extra_times):
            t = frame_times[:1] if self.static else frame_times
            return np.asarray(t, np.float64), self.positions, self.rotations
        times = np.concatenate([frame_times, self.extra_times])
        order = np.argsort(times, kind="stable")
        return (times[order], np.concatenate([self.positions, self.extra_positions])[order],
                np.concatenate([self.rotations, self.extra_rotations])[order])

    def fast_samples(self, frame_times: np.ndarray,
                     turn_deg: float = FAST_TURN_DEG) -> np.ndarray:
        """(N, S) bool over `samples(frame_times)`: True at every frame, and
        at a sub-frame sample for the segments that turn more than
        `turn_deg` between the two frames around it (the angle summed over
        the samples from one frame to the next, so a turn that comes back
        counts too)."""
        times, _, rot = self.samples(frame_times)
        fr = np.searchsorted(times, times[:1] if self.static else frame_times)
        keep = np.zeros((len(times), self.n_segments), bool)
        keep[fr] = True
        if len(times) == len(fr):
            return keep
        q = rot.astype(np.float64)
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        step = angle_between(q[:-1], q[1:])  # (N-1, S) rad
        walked = np.concatenate([np.zeros((1, self.n_segments)), np.cumsum(step, axis=0)])
        turn = walked[fr[1:]] - walked[fr[:-1]]  # (F-1, S) per frame interval
        sub = np.flatnonzero(~keep[:, 0])
        interval = np.searchsorted(fr, sub) - 1  # the frame before each sub-frame sample
        keep[sub] = turn[interval] > np.radians(turn_deg)
        return keep

    def check_extras(self, frame_times: np.ndarray) -> None:
        """Raise InputError unless the extra samples fit the contract above."""
        t = self.extra_times
        if not len(t):
            return
        if self.static:
            raise InputError(f"tree {self.name!r}: a static tree has no extra samples")
        inside = np.searchsorted(frame_times, t)
        between = (inside > 0) & (inside < len(frame_times))
        between &= ~np.isin(t, frame_times)
        if not (np.all(np.diff(t) > 0) and between.all() and np.isfinite(t).all()):
            raise InputError(f"tree {self.name!r}: extra_times must be sorted and strictly "
                             "between frame times")

    @property
    def n_segments(self) -> int:
        return int(self.seg_start.shape[0])

    @property
    def rest_base(self) -> np.ndarray:
        return self.points[self.seg_start]

    @property
    def static(self) -> bool:
        return self.positions.shape[0] == 1

    @property
    def height(self) -> float:
        return float(self.points[:, 2].max() - min(0.0, self.points[:, 2].min()))


@dataclass
class ObjectsBake:
    """Projectiles: shape ("box" or "sphere"), size (box edge or sphere
    diameter, m), and per frame world position (m) and rotation (x y z w)."""

    shapes: list[str]
    sizes: np.ndarray  # (P,) m
    positions: np.ndarray  # (F, P, 3) float32
    rotations: np.ndarray  # (F, P, 4) float32, x y z w

    def __post_init__(self):  # the saved precision, in memory too
        self.positions = np.asarray(self.positions, dtype=np.float32)
        self.rotations = np.asarray(self.rotations, dtype=np.float32)


@dataclass
class Bake:
    times: np.ndarray  # (F,) s
    trees: list[TreeBake]
    meta: dict  # saved: deterministic facts about the bake
    objects: ObjectsBake | None = None
    timing: dict = field(default_factory=dict)  # not saved: seconds spent (varies run to run)

    @property
    def fps(self) -> float:
        return float(self.meta.get("fps", 24.0))

    def frame(self, tree: TreeBake, f: int) -> int:
        """Index into a tree's frames (static trees have only frame 0)."""
        return 0 if tree.static else f


def bake_from(scene, solver: str, grown: list, rigged, result, timing: dict) -> Bake:
    """The bake stage: the Bake of a scene (scene.Scene) as `solver` ("planar"
    or "full") simulated it: its grown trees (grow.GrownTree), rigged
    (sim.rigging.RiggedScene), the solver's result (sim.solver.SolveResult:
    motions by tree name, projectile tracks, meta, notes, engines), and the
    timings (s) so far. Its meta holds what made it (the versions that
    decide its motion, versions.py) and the scene's settings."""
    trees = []
    for g, sim_tree in zip(grown, rigged.trees):
        info = {"grammar": g.grammar, "grammar_hash": g.grammar_hash, "seed": g.seed,
                "first_frequency_hz": round(sim_tree.rig.first_frequency, 5),
                "bones": sim_tree.rig.n_bones}
        motion = result.motions.get(g.model.name)
        if motion is None:
            info["static"] = rigged.static.get(g.model.name, "not simulated")
        else:
            info["solver"] = result.tiers.get(g.model.name, str(solver))
            info["events"] = [e.record() for e in motion.events]
        trees.append(tree_bake_from_motion(g.model, sim_tree.rig, motion, info))
    versions = runtime_versions()
    meta = {"tool": f"treebake {versions['treebake']}", "versions": versions,
            "scene": scene.name, "scene_hash": scene.source_hash, "fps": scene.fps,
            "duration": scene.duration, "seed": scene.seed, "solver": str(solver),
            "quality": asdict(scene.quality), "prestress": scene.prestress,
            "gravity": scene.gravity,
            "culling": rigged.culled,  # trees removed or coarsened by each rule
            "frame_start": scene.frame_start,  # the exporters' number of frame 0
            **result.meta}
    if result.motions:
        meta["notes"] = result.notes
    o = result.objects
    objects = None if o is None else ObjectsBake(o.shapes, o.sizes, o.positions, o.rotations)
    return Bake(np.arange(scene.frame_count) / scene.fps, trees, meta, objects, timing)


def segment_transforms(rig, quats: np.ndarray | None, pivots: np.ndarray | None):
    """Per-segment base positions (F, S, 3) m and rotations (F, S, 4) x y z
    w from per-bone motion (rotations relative to rest (F, B, 4), pivots
    (F, B, 3) m; None: the rest pose, one frame); segments of a merged bone
    move with it."""
    model = rig.model
    sb = rig.seg_bone
    rest_base = model.points[model.seg_start]
    if quats is None:
        rot = np.tile([0.0, 0.0, 0.0, 1.0], (1, model.n_segments, 1))
        return rest_base[None].copy(), rot
    q = quats[:, sb]  # (F, S, 4)
    # each segment's base turned about its bone's pivot (rotating the one
    # vector by the quaternion: no matrices)
    pos = pivots[:, sb] + qrotate(q, rest_base - rig.pivot[sb])
    return pos, q


def tree_bake_from_motion(model, rig, motion, info: dict) -> TreeBake:
    """A tree's bake from its rig's motion (sim.common.TreeMotion; None: it
    stands still), with `info` (grammar, seed, events, ...)."""
    if motion is None:
        pos, rot = segment_transforms(rig, None, None)
        return tree_bake_from_model(model, pos, rot, info)
    pos, rot = segment_transforms(rig, motion.quaternions, motion.pivots)
    tb = tree_bake_from_model(model, pos, rot, info)
    if len(motion.extra_times):  # fast turns: sub-frame samples
        extra_pos, extra_rot = segment_transforms(rig, motion.extra_quaternions,
                                                  motion.extra_pivots)
        tb = replace(tb, extra_times=motion.extra_times,
                     extra_positions=extra_pos.astype(np.float32),
                     extra_rotations=extra_rot.astype(np.float32))
    return tb


def tree_bake_from_model(model, positions: np.ndarray, rotations: np.ndarray,
                         info: dict) -> TreeBake:
    return TreeBake(
        name=model.name, points=model.points.copy(), seg_start=model.seg_start.copy(),
        seg_end=model.seg_end.copy(), seg_parent=model.seg_parent.copy(),
        seg_limb=model.seg_limb.copy(), width=model.width.copy(), leaf=model.leaf.copy(),
        leaf_size=model.leaf_size.copy(),
        limb_parent=np.asarray([limb.parent for limb in model.limbs], dtype=np.int64),
        limb_attach=np.asarray([limb.attach for limb in model.limbs], dtype=np.int64),
        limb_points=[np.asarray(limb.points, dtype=np.int64) for limb in model.limbs],
        paths=model.segment_paths(),
        positions=positions.astype(np.float32), rotations=rotations.astype(np.float32),
        info=info, extra_times=np.zeros(0))


# ---------------------------------------------------------------------------
# files

_FIXED_TIME = (1980, 1, 1, 0, 0, 0)


def _add(zf: zipfile.ZipFile, name: str, array: np.ndarray) -> None:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(array), allow_pickle=False)
    info = zipfile.ZipInfo(name + ".npy", date_time=_FIXED_TIME)
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    # deflate's fastest level: on a spruce's bake it writes 0.14 % more bytes
    # than the default level 6 in 0.65x its CPU time (motion compresses little)
    zf.writestr(info, buf.getvalue(), compresslevel=1)


def _json_array(obj) -> np.ndarray:
    return np.frombuffer(json.dumps(obj, sort_keys=True).encode("utf-8"), dtype=np.uint8)


def save_bake(bake: Bake, path: str | Path) -> Path:
    """Write `bake` atomically; identical bakes give identical bytes."""
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w",
                                                   compression=zipfile.ZIP_DEFLATED) as zf:
        meta = dict(bake.meta, format_version=FORMAT_VERSION, trees=len(bake.trees))
        _add(zf, "meta", _json_array(meta))
        _add(zf, "times", bake.times.astype(np.float64))
        for i, t in enumerate(bake.trees):
            p = f"tree{i}."
            _add(zf, p + "info", _json_array(dict(t.info, name=t.name, paths=t.paths)))
            for key in ("points", "seg_start", "seg_end", "seg_parent", "seg_limb", "width",
                        "leaf", "leaf_size", "limb_parent", "limb_attach", "positions",
                        "rotations"):
                _add(zf, p + key, getattr(t, key))
            if len(t.extra_times):  # only when present: bakes without them keep their bytes
                t.check_extras(bake.times)
                for key in _EXTRAS:
                    _add(zf, p + key, getattr(t, key))
            lengths = np.asarray([len(lp) for lp in t.limb_points], dtype=np.int64)
            flat = np.concatenate(t.limb_points) if t.limb_points else np.zeros(0, np.int64)
            _add(zf, p + "limb_point_counts", lengths)
            _add(zf, p + "limb_points", flat)
        if bake.objects is not None:
            o = bake.objects
            _add(zf, "objects.info", _json_array({"shapes": o.shapes}))
            _add(zf, "objects.sizes", o.sizes)
            _add(zf, "objects.positions", o.positions.astype(np.float32))
            _add(zf, "objects.rotations", o.rotations.astype(np.float32))
    return Path(path)


def _json(data: np.ndarray):
    return json.loads(bytes(data).decode("utf-8"))


def load_bake(path: str | Path) -> Bake:
    """Read a bake; anything that is not a whole treebake bake (empty,
    truncated, another kind of file, damaged arrays) is an InputError."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: bake file not found")
    if p.stat().st_size == 0:
        raise InputError(f"{p}: the bake file is empty (0 bytes): an interrupted write or a "
                         "damaged copy; bake it again")
    if not zipfile.is_zipfile(p):
        raise InputError(f"{p}: not a treebake bake (a bake is a .npz zip archive written by "
                         "`treebake bake`)")
    try:
        with np.load(p, allow_pickle=False) as z:
            if "meta" not in z:
                raise InputError(f"{p}: a .npz archive, but not a treebake bake (no meta)")
            meta = _json(z["meta"])
            if meta.get("format_version") != FORMAT_VERSION:
                raise InputError(f"{p}: bake format {meta.get('format_version')} is not "
                                 f"supported (expected {FORMAT_VERSION})")
            trees = []
            for i in range(meta["trees"]):
                pre = f"tree{i}."
                info = _json(z[pre + "info"])
                counts = z[pre + "limb_point_counts"]
                flat = z[pre + "limb_points"]
                splits = np.cumsum(counts)[:-1]
                trees.append(TreeBake(
                    name=info.pop("name"), paths=info.pop("paths"),
                    limb_points=list(np.split(flat, splits)) if len(counts) else [],
                    info=info,
                    **{k: z[pre + k] for k in ("points", "seg_start", "seg_end", "seg_parent",
                                                "seg_limb", "width", "leaf", "leaf_size",
                                                "limb_parent", "limb_attach", "positions",
                                                "rotations")},
                    **{k: z[pre + k] for k in _EXTRAS if pre + k in z}))
            objects = None
            if "objects.info" in z:
                objects = ObjectsBake(_json(z["objects.info"])["shapes"], z["objects.sizes"],
                                      z["objects.positions"], z["objects.rotations"])
            bake = Bake(z["times"], trees, meta, objects)
            _check_shapes(bake)
    except InputError:
        raise
    except (OSError, EOFError, zipfile.BadZipFile, zlib.error, KeyError, ValueError, TypeError,
            IndexError, AttributeError) as exc:
        raise InputError(f"{p}: not a readable treebake bake: damaged or truncated "
                         f"({type(exc).__name__}: {exc})") from None
    check_finite(bake, str(p))
    return bake


def check_finite(bake: Bake, where: str = "the bake") -> None:
    """Raise InputError if any tree's positions or rotations (frames and
    sub-frame samples) hold NaN or infinity: junk to diff or export, named
    with the tree and the first frame."""
    for t in bake.trees:
        for what, frames in (("positions", t.positions), ("rotations", t.rotations),
                             ("sub-frame positions", t.extra_positions),
                             ("sub-frame rotations", t.extra_rotations)):
            if not len(frames):
                continue
            bad = ~np.isfinite(frames).reshape(len(frames), -1).all(axis=1)
            if bad.any():
                raise InputError(f"{where}: tree {t.name!r} has non-finite {what} from "
                                 f"{'sample' if 'sub' in what else 'frame'} "
                                 f"{int(np.argmax(bad))} on: a broken bake")


def _check_shapes(bake: Bake) -> None:
    """Arrays that disagree with each other (a damaged file) raise ValueError."""
    frames = len(bake.times)
    for t in bake.trees:
        s = t.n_segments
        if t.positions.shape not in ((frames, s, 3), (1, s, 3)) or \
                t.rotations.shape != t.positions.shape[:2] + (4,):
            raise ValueError(f"tree {t.name!r}: positions {t.positions.shape} and rotations "
                             f"{t.rotations.shape} do not fit {frames} frames x {s} segments")
        for key in ("seg_end", "seg_parent", "seg_limb", "width", "leaf", "leaf_size"):
            if getattr(t, key).shape != (s,):
                raise ValueError(f"tree {t.name!r}: {key} has shape {getattr(t, key).shape}, "
                                 f"expected ({s},)")
        if len(t.paths) != s:
            raise ValueError(f"tree {t.name!r}: {len(t.paths)} paths for {s} segments")
        if s and (t.seg_start.max() >= len(t.points) or t.seg_end.max() >= len(t.points)):
            raise ValueError(f"tree {t.name!r}: a segment points past its {len(t.points)} points")
        try:  # the extra sub-frame samples, when present, keep their contract too
            t.check_extras(bake.times)
        except InputError as exc:
            raise ValueError(str(exc)) from None
