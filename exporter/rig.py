"""Rig: TreeModel -> bones and joints with masses, stiffness and limits.

A bone is one segment, or several consecutive segments of a limb merged when
`min_bone_length` asks for fewer, longer bones (the planar LOD's cheapest
lever). Each bone has a joint at its base: to the previous bone of its limb,
to the parent limb's bone at the attachment point, or (root limbs) to the
ground.

Physics (SI units):
- mass: green-wood density x solid-cylinder volume of each segment, plus
  leaf mass (`leaf_mass` kg/m^2 x leaf card area, 2 cards of `leaf_size`^2
  per leafy segment);
- joint stiffness from bending compliance: a bone of segments with lengths
  l and stiffness EI = E*pi*D^4/64 has compliance C = sum(l/EI); the joint
  between two bones of a limb carries half of each, k = 1/(C_a/2 + C_b/2);
  the first joint of a limb carries half of its own bone, k = 2/C_b (the
  "root joint 2EI/l" that makes a chain's frequency error fall as 1/N^2);
  `@stiffness` overrides k, `@ei` overrides EI;
- damping: mass-proportional, per limb: every bone of a limb is damped by
  -alpha*m*v (v relative to the limb's parent frame) with alpha =
  2*zeta*omega_limb, where omega_limb is the limb's own first bending
  frequency (Rayleigh quotient of the subtree hanging from its base). So
  each limb's fundamental gets the grammar's structural damping ratio zeta;
  air drag adds aerodynamic damping in the simulator. (Stiffness-
  proportional damping c = beta*k, the usual alternative, locks Chipmunk's
  chains: its per-iteration damping zeroes joint rates when c*h/I >> 1.)
- cone half-angle and breaking moment per joint; a root joint breaks at the
  smaller of the stem's strength and the root-plate `anchor` moment.

Bone capsules (collision and the MuJoCo reference) are `bone_ratio` (0.8-0.95)
of the bone length, centred on the bone, so bones never overlap at joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .model import TreeModel
from .rotations import cross

GRAVITY = 9.81  # m/s^2
AIR_DENSITY = 1.2  # kg/m^3


@dataclass(frozen=True)
class RigOptions:
    """bone_ratio: capsule length / bone length (0.8-0.95). min_bone_length:
    merge a limb's consecutive segments into bones at least this long, m
    (0 = one bone per segment). min_length: shorter segments are always merged
    into a neighbour, m. min_width: diameter floor for zero-width segments, m."""

    bone_ratio: float = 0.9
    min_bone_length: float = 0.0
    min_length: float = 1e-3
    min_width: float = 1e-3

    def __post_init__(self):
        if not 0.8 <= self.bone_ratio <= 0.95:
            raise InputError(f"bone_ratio = {self.bone_ratio} is out of range [0.8, 0.95]")
        if not 0 <= self.min_bone_length <= 100:
            raise InputError(f"min_bone_length = {self.min_bone_length} m is out of range "
                             "[0, 100]")


@dataclass
class RigLimb:
    parent_bone: int  # bone the limb hangs on, -1 = ground
    bones: list[int] = field(default_factory=list)
    path: str = ""


@dataclass
class Rig:
    name: str
    model: TreeModel
    options: RigOptions
    seg_bone: np.ndarray  # (S,) bone of each segment
    bone_limb: np.ndarray  # (B,)
    bone_parent: np.ndarray  # (B,) -1 = ground; parents come first
    bone_depth: np.ndarray  # (B,) joints between a bone and the ground (roots 0)
    pivot: np.ndarray  # (B, 3) m, rest base (joint) point
    tip: np.ndarray  # (B, 3) m, rest end point
    mass: np.ndarray  # (B,) kg
    com: np.ndarray  # (B, 3) m, rest centre of mass
    inertia: np.ndarray  # (B, 3, 3) kg m^2 about the COM, rest orientation
    radius: np.ndarray  # (B,) m, volume-weighted mean radius
    wood_area: np.ndarray  # (B,) m^2, sum of diameter x length (cross-flow area)
    leaf_area: np.ndarray  # (B,) m^2, leaf card area
    k: np.ndarray  # (B,) N m/rad, joint at the bone's base
    zeta: np.ndarray  # (B,) structural damping ratio
    alpha: np.ndarray  # (B,) 1/s, mass-proportional damping coefficient
    cone: np.ndarray  # (B,) rad
    strength: np.ndarray  # (B,) N m, inf = unbreakable
    limbs: list[RigLimb]
    limb_omega: np.ndarray  # (L,) rad/s, each limb's first bending frequency (base fixed)
    first_frequency: float  # Hz, the lowest root limb's (the trunk's) first frequency
    drag: float  # wood drag coefficient
    leaf_drag: float  # foliage drag coefficient

    @property
    def n_bones(self) -> int:
        return int(self.mass.shape[0])

    @property
    def length(self) -> np.ndarray:
        return np.linalg.norm(self.tip - self.pivot, axis=1)

    @property
    def axis(self) -> np.ndarray:
        v = self.tip - self.pivot
        n = np.linalg.norm(v, axis=1, keepdims=True)
        return np.divide(v, n, out=np.tile([0.0, 0.0, 1.0], (len(v), 1)), where=n > 0)

    def main_stem(self) -> np.ndarray:
        """Bones of the main stem (TreeModel.main_stem), ground up."""
        return np.unique(self.seg_bone[self.model.main_stem()])

    def stem_bone_at(self, at: float) -> int:
        """The main-stem bone at `at` x the stem's height above its base."""
        stem = self.main_stem()
        base, top = float(self.pivot[stem[0], 2]), float(self.tip[stem[-1], 2])
        z = base + at * (top - base)
        return int(next((b for b in stem if self.tip[b, 2] >= z), stem[-1]))

    def children(self) -> list[list[int]]:
        out: list[list[int]] = [[] for _ in range(self.n_bones)]
        for b, p in enumerate(self.bone_parent):
            if p >= 0:
                out[p].append(b)
        return out


def _group_segments(model: TreeModel, opts: RigOptions, chains: list[list[int]],
                    lengths: np.ndarray) -> list[list[list[int]]]:
    """Per chain, the segments of each bone (`lengths` (S,) m per segment)."""
    groups = []
    for chain in chains:
        bones: list[list[int]] = []
        current: list[int] = []
        acc = 0.0
        for s in (s for li in chain for s in model.limbs[li].segments):
            current.append(s)
            acc += lengths[s]
            # a relative tolerance so that n equal segments of L/n make n bones
            if acc >= max(opts.min_bone_length, opts.min_length) * (1 - 1e-9):
                bones.append(current)
                current, acc = [], 0.0
        if current:
            if bones and (acc < opts.min_length or acc < 0.5 * opts.min_bone_length):
                bones[-1].extend(current)
            else:
                bones.append(current)
        groups.append(bones)
    return groups


@dataclass
class _BoneSums:
    """Per bone (B,), from its segments: mass kg, centre of mass (B, 3) m,
    inertia (B, 3, 3) kg m^2 about it, volume-weighted mean radius m, wood
    area m^2 (diameter x length), leaf area m^2, bending compliance rad/(N m)."""

    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray
    radius: np.ndarray
    wood_area: np.ndarray
    leaf_area: np.ndarray
    compliance: np.ndarray


def build_rig(model: TreeModel, options: RigOptions | None = None) -> Rig:
    """Rig a TreeModel. Bones are ordered so that a parent precedes its children."""
    opts = options or RigOptions()
    chains = model.axes()  # an axis that forks sympodially (oak, willow) bends as one chain
    lengths = model.seg_length
    groups = _group_segments(model, opts, chains, lengths)
    seg_bone = np.full(len(lengths), -1, dtype=np.int64)
    bone_segs: list[list[int]] = []
    bone_limb: list[int] = []
    # Limbs are created parent-first by the turtle, so walking limbs in order
    # numbers bones parent-first too.
    for li, bones in enumerate(groups):
        for segs in bones:
            for s in segs:
                seg_bone[s] = len(bone_segs)
            bone_segs.append(segs)
            bone_limb.append(li)
    n = len(bone_segs)
    first = np.array([segs[0] for segs in bone_segs], dtype=np.int64)
    last = np.array([segs[-1] for segs in bone_segs], dtype=np.int64)
    ps = model.seg_parent[first]
    bone_parent = np.where(ps >= 0, seg_bone[np.maximum(ps, 0)], -1)
    pivot = model.points[model.seg_start[first]]
    tip = model.points[model.seg_end[last]]
    sums = _bone_sums(model, opts, seg_bone, bone_segs, lengths)

    limbs = []
    for chain, bones in zip(chains, groups):
        ids = [int(seg_bone[segs[0]]) for segs in bones]
        limbs.append(RigLimb(int(bone_parent[ids[0]]), ids, model.limbs[chain[0]].path))

    first_seg = np.array([segs[0] for segs in bone_segs])
    k = _joint_stiffness(bone_parent, bone_limb, sums.compliance)
    override = model.stiffness[first_seg]
    k = np.where(np.isnan(override), k, override)

    strength = model.strength[first_seg].copy()
    roots = bone_parent < 0
    strength[roots] = np.minimum(strength[roots], model.anchor)
    cone = model.cone[first_seg].copy()

    zeta = model.damping[first_seg]
    rig = Rig(model.name, model, opts, seg_bone, np.asarray(bone_limb, dtype=np.int64),
              bone_parent, bone_depths(bone_parent), pivot, tip, sums.mass, sums.com,
              sums.inertia, sums.radius, sums.wood_area, sums.leaf_area, k, zeta, np.zeros(n),
              cone, strength, limbs, np.zeros(len(limbs)), 0.0, model.drag, model.leaf_drag)
    rig.limb_omega = limb_frequencies(rig)
    roots = [li for li, limb in enumerate(limbs) if limb.parent_bone < 0]
    rig.first_frequency = float(rig.limb_omega[roots].min()) / (2 * math.pi)
    rig.alpha = 2.0 * zeta * rig.limb_omega[rig.bone_limb]
    return rig


def _bone_sums(model: TreeModel, opts: RigOptions, seg_bone: np.ndarray,
               bone_segs: list[list[int]], seg_len: np.ndarray) -> _BoneSums:
    """Mass, inertia, sizes and compliance of each bone from its segments
    (`seg_len` (S,) m): solid cylinders of green wood plus leaf cards (see
    the module doc)."""
    width = np.maximum(model.width, opts.min_width)
    area = np.pi / 4 * width**2
    seg_wood = model.density * area * seg_len
    leaf_area_seg = np.where(model.leaf > 0, 2.0 * model.leaf_size**2, 0.0)
    seg_mass = seg_wood + model.leaf_mass * leaf_area_seg
    ei = np.where(np.isnan(model.ei), model.modulus * np.pi * width**4 / 64, model.ei)
    compliance = seg_len / ei  # rad per N m
    n = len(bone_segs)
    pts = model.points
    # per-segment quantities summed into bones (segments of a bone follow each other)
    order = np.fromiter((s for segs in bone_segs for s in segs), dtype=np.int64,
                        count=sum(len(segs) for segs in bone_segs))
    of = seg_bone[order]

    def per_bone(values: np.ndarray) -> np.ndarray:
        flat = values.reshape(len(values), -1)
        return np.stack([np.bincount(of, flat[:, k], minlength=n)
                         for k in range(flat.shape[1])], 1).reshape((n,) + values.shape[1:])

    m = seg_mass[order]
    start, end = pts[model.seg_start[order]], pts[model.seg_end[order]]
    mids = 0.5 * (start + end)
    mass = per_bone(m)
    count = np.bincount(of, minlength=n)
    heavy = mass > 0
    com = np.where(heavy[:, None], per_bone(m[:, None] * mids) / np.where(heavy, mass, 1.0)[:, None],
                   per_bone(mids) / count[:, None])
    inertia = per_bone(_cylinders_inertia(m, mids, end - start, width[order] / 2, com[of]))
    vol = area[order] * seg_len[order]
    total = per_bone(vol)
    radius = np.where(total > 0, per_bone(width[order] / 2 * vol) / np.where(total > 0, total, 1.0),
                      per_bone(width[order] / 2) / count)
    wood_area = per_bone(width[order] * seg_len[order])
    leaf_area = per_bone(leaf_area_seg[order])
    return _BoneSums(mass, com, inertia, radius, wood_area, leaf_area,
                     per_bone(compliance[order]))


def _joint_stiffness(bone_parent: np.ndarray, bone_limb: list[int],
                     bone_c: np.ndarray) -> np.ndarray:
    """(B,) N m/rad, the joint at each bone's base: 1 / (half the bone's
    compliance + half its parent's on the same limb), bone_c in rad/(N m)."""
    n = len(bone_parent)
    k = np.empty(n)
    for b in range(n):
        p = bone_parent[b]
        same_limb = p >= 0 and bone_limb[p] == bone_limb[b]
        c_half = bone_c[b] / 2 + (bone_c[p] / 2 if same_limb else 0.0)
        k[b] = 1.0 / c_half if c_half > 0 else 1e12
    return k


def _cylinders_inertia(m, mids, vecs, radii, com) -> np.ndarray:
    """Inertia tensors (N, 3, 3) kg m^2 of solid cylinders (mass m, centre
    mids, axis vecs, radius radii) about the points `com` (N, 3)."""
    lengths = np.linalg.norm(vecs, axis=1)
    axes = np.divide(vecs, lengths[:, None], out=np.zeros_like(vecs), where=lengths[:, None] > 0)
    i_axial = m * radii**2 / 2
    i_trans = m * (3 * radii**2 + lengths**2) / 12
    eye = np.eye(3)
    outer = axes[:, :, None] * axes[:, None, :]
    own = i_trans[:, None, None] * (eye - outer) + i_axial[:, None, None] * outer
    d = mids - com
    shift = m[:, None, None] * ((d * d).sum(1)[:, None, None] * eye - d[:, :, None] * d[:, None, :])
    return own + shift


def bone_depths(parent: np.ndarray) -> np.ndarray:
    """Each bone's depth (B,): the joints between it and the ground (roots
    0), for bones whose `parent` (-1: the ground) comes first."""
    depth = np.zeros(len(parent), dtype=np.int64)
    for b in range(len(parent)):  # parents first
        if parent[b] >= 0:
            depth[b] = depth[parent[b]] + 1
    return depth


def depth_levels(depth: np.ndarray) -> list[np.ndarray]:
    """The bones at each depth (bone_depths), deepest first, roots left out:
    the order in which sums outboard of each bone build up."""
    return [np.nonzero(depth == d)[0] for d in range(int(depth.max(initial=0)), 0, -1)]


def subtree_sums(parent: np.ndarray, levels: list[np.ndarray], values: np.ndarray) -> np.ndarray:
    """Sum of `values` (B, ...) over each bone and all bones outboard of it
    (`levels`: depth_levels of the bones' depths)."""
    out = np.array(values, dtype=float, copy=True)
    for idx in levels:
        np.add.at(out, parent[idx], out[idx])
    return out


def limb_frequencies(rig: Rig, g: float = GRAVITY) -> np.ndarray:
    """First bending frequency (rad/s) of each limb with everything it
    carries, its base held fixed: the Rayleigh quotient on the static
    deflection under a 1 g load across the limb, averaged over the world
    axes that are not along the limb's chord. Accurate to about 1% for cantilevers; independent of
    any simulator."""
    parent = rig.bone_parent
    n = rig.n_bones
    limb_parent_bone = np.asarray([limb.parent_bone for limb in rig.limbs])
    limb_of_limb = np.where(limb_parent_bone >= 0, rig.bone_limb[np.maximum(limb_parent_bone, 0)],
                            -1)
    # (limb, bone) pairs: a bone belongs to its limb's subtree and every ancestor limb's
    pair_l, pair_b = [], []
    cur = rig.bone_limb.copy()
    bones = np.arange(n)
    while len(bones):
        pair_l.append(cur)
        pair_b.append(bones)
        up = limb_of_limb[cur]
        keep = up >= 0
        cur, bones = up[keep], bones[keep]
    pl = np.concatenate(pair_l)
    pb = np.concatenate(pair_b)
    base = limb_parent_bone[pl]  # the fixed bone above the limb (-1 = ground)
    depth = rig.bone_depth
    levels = depth_levels(depth)
    msum = subtree_sums(parent, levels, rig.mass)
    mcsum = subtree_sums(parent, levels, rig.mass[:, None] * rig.com)
    n_limbs = len(rig.limbs)
    directions = np.eye(3)
    first = np.asarray([limb.bones[0] for limb in rig.limbs])
    last = np.asarray([limb.bones[-1] for limb in rig.limbs])
    chord = rig.tip[last] - rig.pivot[first]
    chord /= np.maximum(np.linalg.norm(chord, axis=1, keepdims=True), 1e-12)
    omega2 = np.zeros((3, n_limbs))
    for di, direction in enumerate(directions):
        load = g * direction
        moment = cross(mcsum - msum[:, None] * rig.pivot, load)  # N m at each joint
        rho = moment / rig.k[:, None]  # joint rotation vectors, rad
        # sums down the tree, root side first: each bone's rotation and its
        # points' offset term, its own plus every bone's below it (rho is not
        # used again: summed in place)
        a, bsum = rho, cross(rho, rig.pivot)
        for idx in reversed(levels):
            a[idx] += a[parent[idx]]
            bsum[idx] += bsum[parent[idx]]
        a_base = np.where(base[:, None] >= 0, a[np.maximum(base, 0)], 0.0)
        b_base = np.where(base[:, None] >= 0, bsum[np.maximum(base, 0)], 0.0)
        rot = a[pb] - a_base  # bone rotation relative to the fixed base
        u = cross(rot, rig.com[pb]) - (bsum[pb] - b_base)  # COM displacement, m
        m = rig.mass[pb]
        work = np.bincount(pl, m * (u @ load), minlength=n_limbs)
        kinetic = np.bincount(pl, m * (u * u).sum(1)
                              + np.einsum("bi,bij,bj->b", rot, rig.inertia[pb], rot),
                              minlength=n_limbs)
        omega2[di] = np.where((kinetic > 0) & (work > 0), work / np.maximum(kinetic, 1e-300), 0)
    omega = np.sqrt(omega2)
    # only loads across the limb bend it (a load along its chord is axial)
    valid = (omega > 0) & (np.abs(chord @ directions.T).T < 0.75)
    count = valid.sum(0)
    return np.where(count > 0, (omega * valid).sum(0) / np.maximum(count, 1), 1.0)
