"""What every solver takes and returns: trees to simulate and their motion."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, fields

import numpy as np

from ..rig import Rig
from ..rotations import cross
from ..sampling import FAST_TURN_DEG
from .loads import MAX_ACCELERATION, BoneProps

# rad/s: a bone spinning faster is taken to be unstable (a blast whips real
# twigs to a quarter of it; an unstable state passes any bound within steps)
MAX_ANGULAR_SPEED = 2000.0


def locate(trees: list[SimTree], offsets: np.ndarray, bone_tree: np.ndarray,
           bone: int) -> tuple[str, int]:
    """The tree name and a segment index (in that tree) of a global bone."""
    ti = int(bone_tree[bone])
    tree = trees[ti]
    local = bone - int(offsets[ti])
    return tree.name, int(np.nonzero(tree.rig.seg_bone == local)[0][0])


def cap_loads(force: np.ndarray, mass: np.ndarray, t: float, stats,
              locate_row: Callable[[int], tuple[str, int]],
              blast_capped: np.ndarray | None = None) -> np.ndarray:
    """Scale each bone's external load (N, rows of `force`, in place) down
    to MAX_ACCELERATION x its mass (kg). Counted on `stats.limited`, with
    the bones whose blast push SceneLoads.forces held back (`blast_capped`,
    m/s^2 asked, 0 where none); the first cap is kept in `stats.first_limit`
    as (tree, segment, time s, m/s^2). A blast's push is capped at the same
    rate before it gets here and what that holds back follows, so every
    engine passes the pulse's whole impulse (docs/physics.md, "A blast's
    push is capped in rate, not in impulse")."""
    acc = np.linalg.norm(force, axis=1) / np.maximum(mass, 1e-9)
    over = acc > MAX_ACCELERATION
    asked = acc
    if blast_capped is not None and len(blast_capped):
        asked = np.maximum(acc, blast_capped)
        idx = np.nonzero(over | (blast_capped > 0))[0]
    else:
        idx = np.nonzero(over)[0]
    if not len(idx):
        return force
    if not stats.limited:
        tree, seg = locate_row(int(idx[0]))
        stats.first_limit = (tree, seg, round(t, 4), round(float(asked[idx[0]]), 1))
    stats.limited += len(idx)
    held = np.nonzero(over)[0]
    force[held] *= (MAX_ACCELERATION / acc[held])[:, None]
    return force


def external_loads(loads, bones: Bones, t: float, com: np.ndarray, vcom: np.ndarray,
                   axis: np.ndarray, stats, locate_row: Callable[[int], tuple[str, int]],
                   rows: np.ndarray | None = None, dt: float = 0.0,
                   blast_start: float | None = None, gravity: bool = False) -> np.ndarray:
    """The loads every engine applies to `rows` of `bones` (all: None) at
    t s, with their COMs at `com` (m), moving at `vcom` (m/s), along unit
    `axis`: air, blasts (held over `dt` s, SceneLoads.forces), attractors,
    the scene's pulls, and gravity where asked; capped at MAX_ACCELERATION
    x mass (cap_loads, counted on `stats`). World forces (N) at the COMs."""
    props = bones.props if rows is None else bones.props.take(rows)
    force = loads.forces(t, com, vcom, axis, props, include_gravity=gravity, dt=dt,
                         blast_start=blast_start)
    pulls = bones.pull_forces(t)
    if pulls is not None:
        force += pulls if rows is None else pulls[rows]
    mass = bones.mass if rows is None else bones.mass[rows]
    return cap_loads(force, mass, t, stats, locate_row, loads.blast_capped)


def cap_note(limited: int, first_limit: tuple | None) -> str | None:
    """The bake's note on capped loads (`limited` bone updates, the first
    as (tree, segment, time s, m/s^2)); None if none were capped."""
    if not limited:
        return None
    tree, seg, t, acc = first_limit
    return (f"loads capped at {MAX_ACCELERATION:.0f} m/s^2 on {limited} bone updates "
            f"(first: tree {tree!r}, segment {seg}, t = {t:.3f} s, {acc:.0f} m/s^2): the "
            "motion there is milder than the load asks (a blast's impulse is kept: what the "
            "cap holds back follows at the same rate)")


def hinge_axes(axis: np.ndarray, toward: np.ndarray | None = None) -> np.ndarray:
    """The two hinges of each bone's joint (swing without twist): unit axes
    (B, 2, 3) perpendicular to the bones' unit `axis` (B, 3) and to each
    other, the first turning first. Where `toward` (B, 3) is given (a row of
    NaN: not), a positive turn of the first tips the bone toward it (a
    felling hinge); otherwise the first is horizontal when it can be (z x
    axis, else x x axis). Both solvers' joints use these."""
    axis = np.atleast_2d(axis)
    out = np.empty((len(axis), 2, 3))
    todo = np.ones(len(axis), dtype=bool)
    cands = [] if toward is None else [np.atleast_2d(toward)]
    cands += [np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]])]
    for cand in cands:
        e = cross(axis, np.broadcast_to(cand, axis.shape))
        norm = np.linalg.norm(e, axis=1)
        ok = todo & (norm > 0.1)  # NaN rows (no `toward`) fail this
        e1 = e[ok] / norm[ok, None]
        out[ok, 0] = e1
        out[ok, 1] = cross(axis[ok], e1)
        todo &= ~ok
    if todo.any():
        raise AssertionError("no perpendicular found")  # pragma: no cover
    return out


@dataclass
class SimTree:
    """A rigged tree placed in the world, with what the scene does to it."""

    name: str
    rig: Rig  # in world coordinates
    planes: int = 1  # planar LOD only: bending planes per limb
    load_direction: np.ndarray | None = None  # unit horizontal, for plane choice
    cut: object | None = None  # scene CutSpec
    pulls: list = field(default_factory=list)  # scene PullSpecs on this tree
    active: bool = True
    # (2B,) N m: its springs' prestress torques when not its own grown
    # shape's (a tree that lost parts keeps its set: sim/pruning.py)
    hold: np.ndarray | None = None


@dataclass
class TreeMotion:
    """Per-bone world motion at each frame: rotation relative to the rest
    pose as quaternions (F, B, 4) x y z w, and pivot positions (F, B, 3) m."""

    quaternions: np.ndarray
    pivots: np.ndarray
    events: list = field(default_factory=list)  # events.Event records
    energy: np.ndarray | None = None  # (F,) J, the audit's mechanical energy (audit.py)
    work: np.ndarray | None = None  # (F,) J, external work done on the tree up to each frame
    # sub-frame samples where a bone turned more than FAST_TURN between frames:
    # times (K,) s strictly between frames, quaternions (K, B, 4), pivots (K, B, 3)
    extra_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    extra_quaternions: np.ndarray | None = None
    extra_pivots: np.ndarray | None = None


def tree_motion(quats: np.ndarray, pivots: np.ndarray, bones: slice, events: list, ledger,
                tree: int, extra: list) -> TreeMotion:
    """One tree's TreeMotion from an engine's records: its `bones` of the
    frames' rotations (F, B, 4) and pivots (F, B, 3), its events, its row
    `tree` of the audit's `ledger`, and its kept sub-frame samples `extra`
    [(time s, rotations (b, 4), pivots (b, 3))]."""
    nb = bones.stop - bones.start
    return TreeMotion(quats[:, bones], pivots[:, bones], events, ledger.energy[:, tree],
                      ledger.work[:, tree], np.array([e[0] for e in extra]),
                      np.array([e[1] for e in extra]).reshape(-1, nb, 4),
                      np.array([e[2] for e in extra]).reshape(-1, nb, 3))


FAST_TURN = np.radians(FAST_TURN_DEG)  # rad: a bone turning more between frames: sub-frame samples
MAX_EXTRA = 8  # sub-frame samples per frame at most


def sub_frame_samples(prev: np.ndarray, cur: np.ndarray, samples: list, offsets: np.ndarray,
                      store: list[list]) -> None:
    """Keep the buffered sub-frame `samples` (time s, rotations (B, 3, 3),
    pivots (B, 3)) for every tree (bone ranges `offsets`) whose bones turned
    more than FAST_TURN between the frame quaternions `prev` and `cur`
    (B, 4): appended to store[tree] as (time, quaternions, pivots)."""
    from ..rotations import angle_between, quaternions_from_matrices

    if not samples:
        return
    turn = angle_between(prev, cur)
    for ti in range(len(offsets) - 1):
        lo, hi = offsets[ti], offsets[ti + 1]
        if hi > lo and turn[lo:hi].max() > FAST_TURN:
            pick = samples if len(samples) <= MAX_EXTRA else [
                samples[int(k)] for k in np.linspace(0, len(samples) - 1, MAX_EXTRA)]
            for t, rot, piv in pick:
                store[ti].append((t, quaternions_from_matrices(rot[lo:hi]), piv[lo:hi].copy()))



@dataclass
class ProjectileTracks:
    """Thrown objects' flight: shape ("box" or "sphere"), size (box edge or
    sphere diameter, m), and per frame world position (F, P, 3) m and
    rotation (F, P, 4) x y z w."""

    shapes: list[str]
    sizes: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray


@dataclass
class Pull:
    """A rope pull (scene PullSpec) on a global bone."""

    bone: int
    force: np.ndarray  # N, world
    ramp: float  # s
    release: float  # s


@dataclass
class Bones:
    """The active trees' rigs as global bone arrays (trees in order): what
    every solver starts from."""

    offsets: np.ndarray  # (trees + 1,) first bone of each tree
    pivot0: np.ndarray  # (B, 3) m, rest
    tip0: np.ndarray
    com0: np.ndarray
    mass: np.ndarray  # kg
    inertia: np.ndarray  # (B, 3, 3) kg m^2
    k: np.ndarray  # N m/rad
    alpha: np.ndarray  # 1/s
    cone: np.ndarray  # rad
    strength: np.ndarray  # N m
    radius: np.ndarray  # m
    bone_tree: np.ndarray  # (B,) tree index
    parent: np.ndarray  # (B,) global parent bone, -1 = ground
    depth: np.ndarray  # (B,) joints between each bone and the ground (Rig.bone_depth)
    length: np.ndarray  # m
    props: BoneProps
    pulls: list[Pull]
    hinges: np.ndarray  # (B, 2, 3) each joint's two hinge axes (hinge_axes), world at rest
    n: int  # B, the bones (counted once, where the arrays are made)

    @classmethod
    def of(cls, trees: list[SimTree]) -> Bones:
        def cat(get) -> np.ndarray:
            return np.concatenate([np.asarray(get(t)) for t in trees]) if trees else np.zeros(0)

        offsets = np.cumsum([0] + [t.rig.n_bones for t in trees])
        n = int(offsets[-1])
        pivot0 = cat(lambda t: t.rig.pivot).reshape(n, 3)
        tip0 = cat(lambda t: t.rig.tip).reshape(n, 3)
        mass = cat(lambda t: t.rig.mass)
        radius = cat(lambda t: t.rig.radius)
        parent = np.full(n, -1, dtype=np.int64)
        pulls = []
        for ti, t in enumerate(trees):
            o = int(offsets[ti])
            parent[o:o + t.rig.n_bones] = np.where(t.rig.bone_parent >= 0,
                                                   t.rig.bone_parent + o, -1)
            for pull in t.pulls:
                pulls.append(Pull(t.rig.stem_bone_at(pull.at) + o,
                                  np.asarray(pull.force, dtype=float), pull.ramp, pull.release))
        props = BoneProps(
            mass=mass, wood_area=cat(lambda t: t.rig.wood_area),
            leaf_area=cat(lambda t: t.rig.leaf_area), diameter=2 * radius,
            cd_wood=cat(lambda t: np.full(t.rig.n_bones, t.rig.drag)),
            cd_leaf=cat(lambda t: np.full(t.rig.n_bones, t.rig.leaf_drag)))
        length = np.linalg.norm(tip0 - pivot0, axis=1)
        axis0 = np.divide(tip0 - pivot0, length[:, None], out=np.tile([0.0, 0.0, 1.0], (n, 1)),
                          where=length[:, None] > 0)
        toward = np.full((n, 3), np.nan)
        for ti, t in enumerate(trees):
            if t.cut is not None:  # a felled tree's root joints tip it toward the cut direction
                a = math.radians(t.cut.direction)
                lo, hi = int(offsets[ti]), int(offsets[ti + 1])
                toward[lo:hi][parent[lo:hi] < 0] = [math.cos(a), math.sin(a), 0.0]
        hinges = hinge_axes(axis0, toward)
        return cls(offsets, pivot0, tip0, cat(lambda t: t.rig.com).reshape(n, 3), mass,
                   cat(lambda t: t.rig.inertia).reshape(n, 3, 3), cat(lambda t: t.rig.k),
                   cat(lambda t: t.rig.alpha), cat(lambda t: t.rig.cone),
                   cat(lambda t: t.rig.strength), radius,
                   np.repeat(np.arange(len(trees)), [t.rig.n_bones for t in trees]),
                   parent, cat(lambda t: t.rig.bone_depth), length, props, pulls, hinges, n)

    def tree(self, ti: int) -> Bones:
        """The bones of one tree (numbered from 0)."""
        lo, hi = int(self.offsets[ti]), int(self.offsets[ti + 1])
        part = {f.name: getattr(self, f.name)[lo:hi] for f in fields(self)
                if f.name not in ("offsets", "props", "pulls", "parent", "bone_tree", "n")}
        props = self.props.take(slice(lo, hi))
        pulls = [Pull(p.bone - lo, p.force, p.ramp, p.release) for p in self.pulls
                 if lo <= p.bone < hi]
        return Bones(offsets=np.array([0, hi - lo]), props=props, pulls=pulls,
                     parent=np.where(self.parent[lo:hi] >= 0, self.parent[lo:hi] - lo, -1),
                     bone_tree=np.zeros(hi - lo, dtype=np.int64), n=hi - lo, **part)

    def pull_forces(self, t: float) -> np.ndarray | None:
        """World force (N) of the pulls acting at time t on each bone: rising
        linearly over `ramp`, held, gone at `release`; None if none acts."""
        active = [p for p in self.pulls if t < p.release]
        if not active:
            return None
        out = np.zeros((self.n, 3))
        for p in active:
            out[p.bone] += p.force * (min(1.0, t / p.ramp) if p.ramp > 0 else 1.0)
        return out
