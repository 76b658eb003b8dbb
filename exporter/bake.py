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

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from .errors import InputError
from .model import Twigs
from .rotations import angle_between, qrotate
from .sampling import FAST_TURN_DEG

_EXTRAS = ("extra_times", "extra_positions", "extra_rotations")


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
    twigs: Twigs = field(default_factory=Twigs.none)  # drawn only, on their segments

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
    trees: Sequence[TreeBake]  # a list, or read tree by tree from a file (bake_file.py)
    meta: dict  # saved: deterministic facts about the bake
    objects: ObjectsBake | None = None
    timing: dict = field(default_factory=dict)  # not saved: seconds spent (varies run to run)
    # the order the trees were finished and are stored in (bake_file.py);
    # None: index order. Not motion: kept so a bake saved again keeps its bytes
    order: list[int] | None = None

    @property
    def fps(self) -> float:
        return float(self.meta.get("fps", 24.0))

    def frame(self, tree: TreeBake, f: int) -> int:
        """Index into a tree's frames (static trees have only frame 0)."""
        return 0 if tree.static else f


class TreeStore:
    """The trees of an in-memory bake as they come (bake_file.BakeWriter's
    interface): every tree once, in any order."""

    def __init__(self, trees: int):
        self.order: list[int] = []
        self._trees: dict[int, TreeBake] = {}
        self.count = trees

    def add(self, index: int, tree: TreeBake) -> None:
        self._trees[index] = tree
        self.order.append(index)

    def finish(self, meta: dict, objects) -> None:
        if len(self._trees) != self.count:
            raise ValueError(f"{self.count - len(self._trees)} trees were never simulated")

    @property
    def trees(self) -> list[TreeBake]:
        return [self._trees[i] for i in range(self.count)]


@dataclass
class TreeBaker:
    """Makes a simulated tree's bake as soon as its motion is final
    (sim.solver.TreeSink) and puts it in `store` (TreeStore or
    bake_file.BakeWriter). `grown` and `rigs` are the scene's grown trees
    and their rigs, in scene order; in a looping shot (`looping`, loop.Loop)
    each tree is cut to the loop at its `phases` entry (s)."""

    grown: Sequence
    rigs: Sequence
    store: object
    looping: object = None
    phases: Sequence[float] = ()

    def __call__(self, index: int, motion, engines: str) -> None:
        tree = moved_tree_bake(self.grown[index], self.rigs[index], motion, engines)
        if self.looping is not None:  # the loop's frames, after the run-in
            tree = self.looping.window(tree, self.phases[index])
        self.store.add(index, tree)


def grown_info(grown, rig) -> dict:
    """What made a tree (grammar, its hash, seed) and its rig's first
    frequency (Hz) and bones: every tree's bake info starts with these."""
    return {"grammar": grown.grammar, "grammar_hash": grown.grammar_hash, "seed": grown.seed,
            "first_frequency_hz": round(rig.first_frequency, 5), "bones": rig.n_bones}


def static_tree_bake(grown, rig, reason: str) -> TreeBake:
    """A tree nothing moves (one frame, its rest pose): `reason` says why
    it was not simulated."""
    return tree_bake_from_motion(grown.model, rig, None, dict(grown_info(grown, rig),
                                                              static=reason))


def moved_tree_bake(grown, rig, motion, engines: str) -> TreeBake:
    """A simulated tree's bake from its motion (sim.common.TreeMotion);
    `engines` in words, which engines moved it and from when."""
    info = dict(grown_info(grown, rig), solver=engines,
                events=[e.record() for e in motion.events])
    return tree_bake_from_motion(grown.model, rig, motion, info)


def bake_meta(scene, solver: str, rigged, result, versions: dict) -> dict:
    """A bake's meta: what made it (`versions`, those that decide its
    motion: versions.runtime_versions), the scene's settings, what culling
    left out, and the solver's result's meta and notes
    (sim.solver.SolveResult)."""
    meta = {"tool": f"treebake {versions['treebake']}", "versions": versions,
            "scene": scene.name, "scene_hash": scene.source_hash, "fps": scene.fps,
            "duration": scene.duration, "seed": scene.seed, "solver": str(solver),
            "quality": asdict(scene.quality), "prestress": scene.prestress,
            "gravity": scene.gravity,
            "culling": rigged.culled,  # trees removed or coarsened by each rule
            "frame_start": scene.frame_start,  # the exporters' number of frame 0
            **result.meta}
    if any(t.active for t in rigged.trees):
        meta["notes"] = result.notes
    return meta


def objects_bake(tracks) -> ObjectsBake | None:
    """The projectiles' bake from their tracks (sim.common.ProjectileTracks)."""
    if tracks is None:
        return None
    return ObjectsBake(tracks.shapes, tracks.sizes, tracks.positions, tracks.rotations)


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
        info=info, extra_times=np.zeros(0), twigs=stored_twigs(model.twigs))


def stored_twigs(twigs: Twigs) -> Twigs:
    """`twigs` as a bake holds them (and its file stores them): geometry
    in float32 (m), types and segments int64."""
    f32 = np.float32
    return Twigs(twigs.start.astype(f32), twigs.end.astype(f32), twigs.width.astype(f32),
                 twigs.leaf.astype(np.int64), twigs.leaf_size.astype(f32),
                 twigs.segment.astype(np.int64))
