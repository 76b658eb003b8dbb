"""TreeModel: the hierarchical tree the turtle draws.

World frame: metres, Z up, the tree's base at the origin. A limb (trunk or
branch) is an ordered list of points; segment k of a limb joins its points k
and k+1. A child limb starts at point `attach` of its parent limb. Segments
are stored in flat arrays in creation order, so a segment's parent always
comes before it.

Per-segment attributes (units):
    width      diameter, m
    density    green wood density, kg/m^3
    modulus    Young's modulus, Pa
    ei         bending stiffness override, N*m^2 (NaN = modulus * pi D^4 / 64)
    stiffness  joint stiffness override, N*m/rad (NaN = derived by the rig)
    damping    structural damping ratio of the tree's first mode
    cone       joint cone half-angle, rad
    strength   bending moment that breaks the joint at the segment's base, N*m
               (inf = unbreakable); already includes any modulus of rupture
    leaf       leaf type (0 = none); leaf_size: leaf quad edge, m

Twigs (`Twigs`, the grammar's `@twig`) are drawn geometry, not segments:
each rides rigidly on one segment and adds nothing to the physics but the
foliage its segment already carries.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class Twigs:
    """Twigs drawn by `@twig` (T of them): straight pieces skinned rigidly
    to `segment`, the physics segment they grow from. No bone, joint, mass
    or drag of their own: their wood and leaves count in that segment's
    foliage (rig: `leaf_mass` on two cards of `leaf_size`^2).

    start, end (T, 3) m (world, at rest); width (T,) diameter, m; leaf (T,)
    leaf type (0 = none); leaf_size (T,) m; segment (T,) segment index."""

    start: np.ndarray
    end: np.ndarray
    width: np.ndarray
    leaf: np.ndarray
    leaf_size: np.ndarray
    segment: np.ndarray

    @staticmethod
    def none() -> Twigs:
        return Twigs(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64),
                     np.zeros(0), np.zeros(0, np.int64))

    def __len__(self) -> int:
        return int(self.segment.shape[0])

    def moved(self, rotation: np.ndarray, offset: np.ndarray) -> Twigs:
        """The twigs turned by `rotation` (3, 3) about the origin, then moved
        by `offset` (3,) m."""
        return replace(self, start=self.start @ rotation.T + offset,
                       end=self.end @ rotation.T + offset)


@dataclass
class Limb:
    """A trunk or branch: global point and segment indices, base first."""

    parent: int  # parent limb, -1 for a root limb (attached to the ground)
    attach: int  # index into the parent's `points` where this limb starts; -1 for roots
    points: list[int] = field(default_factory=list)
    segments: list[int] = field(default_factory=list)
    path: str = ""  # e.g. "trunk/2/1": 1-based child numbers from the root


@dataclass
class TreeModel:
    name: str
    points: np.ndarray  # (P, 3) m
    seg_start: np.ndarray  # (S,) point index
    seg_end: np.ndarray  # (S,) point index
    seg_limb: np.ndarray  # (S,) limb index
    seg_parent: np.ndarray  # (S,) parent segment, -1 = ground
    width: np.ndarray  # (S,) m
    density: np.ndarray  # (S,) kg/m^3
    modulus: np.ndarray  # (S,) Pa
    ei: np.ndarray  # (S,) N*m^2 or NaN
    stiffness: np.ndarray  # (S,) N*m/rad or NaN
    damping: np.ndarray  # (S,) ratio
    cone: np.ndarray  # (S,) rad
    strength: np.ndarray  # (S,) N*m, inf = unbreakable
    leaf: np.ndarray  # (S,) int
    leaf_size: np.ndarray  # (S,) m
    limbs: list[Limb]
    anchor: float = float("inf")  # root-plate anchorage moment, N*m
    leaf_mass: float = 0.2  # fresh leaf mass per area, kg/m^2
    drag: float = 1.2  # wood drag coefficient
    leaf_drag: float = 0.3  # leaf drag coefficient
    source: dict = field(default_factory=dict)  # grammar name, hash, seed, iterations
    twigs: Twigs = field(default_factory=Twigs.none)  # drawn only (`@twig`)

    @property
    def n_segments(self) -> int:
        return int(self.seg_start.shape[0])

    @property
    def seg_vector(self) -> np.ndarray:
        return self.points[self.seg_end] - self.points[self.seg_start]

    @property
    def seg_length(self) -> np.ndarray:
        return np.linalg.norm(self.seg_vector, axis=1)

    @property
    def height(self) -> float:
        return float(self.points[:, 2].max() - min(0.0, self.points[:, 2].min()))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The box (lo, hi) (3,) m of the segments: what the physics has."""
        return self.points.min(axis=0), self.points.max(axis=0)

    def drawn_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The box (lo, hi) (3,) m of what is drawn: segments and twigs."""
        pts = np.concatenate([self.points, self.twigs.start, self.twigs.end])
        return pts.min(axis=0), pts.max(axis=0)

    def wood_mass(self) -> float:
        """Total wood mass (solid cylinders), kg."""
        volume = np.pi / 4 * self.width**2 * self.seg_length
        return float(np.sum(self.density * volume))

    def segment_paths(self) -> list[str]:
        """A readable name per segment: limb path and index, e.g. 'trunk/2/1:3'."""
        names = [""] * self.n_segments
        for limb in self.limbs:
            for k, s in enumerate(limb.segments):
                names[s] = f"{limb.path}:{k}"
        return names

    def limb_children(self) -> list[list[int]]:
        """For each limb, the indices of the limbs attached to it."""
        out: list[list[int]] = [[] for _ in self.limbs]
        for i, child in enumerate(self.limbs):
            if child.parent >= 0:
                out[child.parent].append(i)
        return out

    def continuation(self, limb: int, children: list[list[int]]) -> int:
        """The limb that continues `limb`'s axis past its last point: the
        widest limb starting there, if at least half as wide (a leader or a
        sympodial continuation, not a side branch or a frond); -1 if none.
        `children` is `limb_children()`."""
        li = self.limbs[limb]
        last = len(li.points) - 1
        forks = [i for i in children[limb] if self.limbs[i].attach == last
                 and self.limbs[i].segments]
        if not forks:
            return -1
        best = max(forks, key=lambda i: (self.width[self.limbs[i].segments[0]], -i))
        wide = self.width[self.limbs[best].segments[0]] >= 0.5 * self.width[li.segments[-1]]
        return best if wide else -1

    def axes(self) -> list[list[int]]:
        """The limbs grouped into axes: a limb and its continuations, ordered
        by first limb (so an axis's parent axis comes first)."""
        children = self.limb_children()
        taken = np.zeros(len(self.limbs), dtype=bool)
        axes = []
        for li in range(len(self.limbs)):
            if taken[li] or not self.limbs[li].segments:
                continue
            axis = [li]
            nxt = self.continuation(li, children)
            while nxt >= 0 and not taken[nxt]:
                axis.append(nxt)
                nxt = self.continuation(nxt, children)
            taken[axis] = True
            axes.append(axis)
        return axes

    def main_stem(self) -> list[int]:
        """Segments of the main stem from the ground up: the first root limb
        and its continuations."""
        children = self.limb_children()
        limb, stem = 0, []
        while limb >= 0:
            stem.extend(self.limbs[limb].segments)
            limb = self.continuation(limb, children)
        return stem

    def dbh(self) -> float:
        """Stem diameter at breast height (1.3 m) of the first root limb, m;
        the base diameter when the trunk is shorter than 1.3 m."""
        trunk = self.limbs[0]
        for s in trunk.segments:
            z0 = self.points[self.seg_start[s], 2]
            z1 = self.points[self.seg_end[s], 2]
            if min(z0, z1) <= 1.3 <= max(z0, z1):
                return float(self.width[s])
        return float(self.width[trunk.segments[0]])


def placed(model: TreeModel, position: tuple[float, float], rotation_deg: float) -> TreeModel:
    """A copy of `model` rotated about Z by `rotation_deg` degrees and moved
    to `position` (x, y) m on the ground."""
    import dataclasses
    import math

    a = math.radians(rotation_deg)
    c, s = math.cos(a), math.sin(a)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    offset = np.array([position[0], position[1], 0.0])
    return dataclasses.replace(model, points=model.points @ rot.T + offset,
                               twigs=model.twigs.moved(rot, offset))
