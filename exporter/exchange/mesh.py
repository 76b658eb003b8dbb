"""Tree geometry for the exporters: bark as generalized cylinders along each
limb, foliage as cards skinned rigidly to their leafy segment (foliage.py),
skinning weights that make the bark bend smoothly at joints, and
linear-blend posing.

All coordinates are the bake's world frame: metres, Z up. The exporters
convert to their own axes.

Bark: a ring of `radial` vertices (+1 seam column for the UVs) at every
"station" of a limb: `rings` stations per segment, at fractions t = j/rings
of the segment, plus one at the limb's tip. A station at fraction t of
segment s follows s and its neighbour along the limb:

    t < 1/2:  s with weight 1/2 + t, its parent with weight 1/2 - t
    t >= 1/2: s with weight 3/2 - t, the next segment with weight t - 1/2

so the ring at a joint (t = 0) is half parent, half child: posed, it sits
at the joint with the average of the two rotations and the tube bends there
instead of kinking. A joint that breaks in the bake (the child's base leaves
the parent's end) is split instead: two rings, each rigid with its own
segment, capped, so debris carries no stretched skin.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..bake import TreeBake
from ..rotations import apply, cross, matrices_from_quaternions
from .foliage import cards
from .twigs import twig_tubes


BARK_COLOUR = (0.36, 0.25, 0.16)  # linear RGB
# linear RGB, the albedo of leaves in leaf (measured green leaves reflect
# 0.05-0.1 in red and blue, 0.1-0.2 in green; needles darker and bluer)
LEAF_COLOURS = {1: (0.10, 0.22, 0.055), 2: (0.045, 0.10, 0.06), 3: (0.16, 0.24, 0.07),
                4: (0.50, 0.21, 0.05)}
OBJECT_COLOUR = (0.55, 0.45, 0.35)
BREAK_GAP = 0.01  # m: a joint whose child base leaves the parent by more is broken


def leaf_colour(kind: int) -> tuple[float, float, float]:
    return LEAF_COLOURS.get(int(kind), LEAF_COLOURS[1])


@dataclass(frozen=True)
class MeshOptions:
    """radial: vertices around a ring (>= 3); rings: rings per segment (>= 1);
    leaves: emit foliage cards; min_radius: m, thinner twigs are drawn this
    thick; bark_tile: m of limb length per bark texture repeat (V); bark:
    the bark's material (bark.bark_material: `bark_oak`, or `bark`) and
    bark_rgb its plain colour (linear RGB, bark.bark_colour);
    card_scale: foliage card edge x this (fewer, larger cards above 1,
    the same optical depth: foliage.card_counts)."""

    radial: int = 8
    rings: int = 1
    leaves: bool = True
    min_radius: float = 0.002
    bark_tile: float = 1.0
    bark: str = "bark"
    bark_rgb: tuple[float, float, float] = BARK_COLOUR  # its plain colour (linear RGB)
    card_scale: float = 1.0
    twigs: bool = True  # draw the twigs' tubes (their foliage is drawn either way)


@dataclass(frozen=True)
class DetailLevel:
    """An export detail level (ExportOptions.detail): ring sides and rings
    per segment of the bark tubes (None: MeshOptions' own), foliage card
    edge scale. Export-time only: the bake is the same at every level."""

    radial: int | None
    rings: int | None
    card_scale: float
    twigs: bool = True  # the twigs' tubes (`@twig`)


# `default` is today's geometry (MeshOptions as given); `far` about half
# the triangles (square tubes, cards 2x larger and so ~2.5x fewer, no twig
# tubes: a few mm across, too thin to see there), `hero` smoother tubes
# that bend over two rings a segment and smaller, more numerous cards
DETAIL = {"hero": DetailLevel(12, 2, 0.8), "default": DetailLevel(None, None, 1.0),
          "far": DetailLevel(4, 1, 2.0, twigs=False)}


def detail_options(opts: MeshOptions, level: str, bark: str = "bark",
                   bark_rgb: tuple[float, float, float] = BARK_COLOUR) -> MeshOptions:
    """`opts` at detail `level` (DETAIL) with the bark material `bark` of
    plain colour `bark_rgb` (linear RGB)."""
    d = DETAIL[level]
    return replace(opts, radial=opts.radial if d.radial is None else d.radial,
                   rings=opts.rings if d.rings is None else d.rings,
                   card_scale=opts.card_scale * d.card_scale, bark=bark, bark_rgb=bark_rgb,
                   twigs=opts.twigs and d.twigs)


@dataclass
class MeshPart:
    """Triangles (T, 3) of one material, indices into the TreeMesh vertices."""

    material: str
    faces: np.ndarray
    colour: tuple[float, float, float]
    double_sided: bool = False
    look: str | None = None  # the shading material's name when not `material` ("bark_oak")

    @property
    def shader(self) -> str:
        """The material a renderer shades this part with: `look`, else
        `material` (the part's own name: USD prim, Alembic face set)."""
        return self.look or self.material


@dataclass
class TreeMesh:
    """Rest geometry (world, m, Z up) with up to 2 skinning influences per
    vertex: `joints` are segment indices, `weights` sum to 1."""

    positions: np.ndarray  # (V, 3) float64
    normals: np.ndarray  # (V, 3) unit
    uvs: np.ndarray  # (V, 2), v up
    joints: np.ndarray  # (V, 2) int64 segment indices
    weights: np.ndarray  # (V, 2) float64
    parts: list[MeshPart] = field(default_factory=list)
    # (V, 4) glTF TANGENT: unit xyz along +u, w = +1 (bitangent = N x T, along
    # +v); bark: around the limb; other vertices any unit vector across N
    tangents: np.ndarray | None = None

    @property
    def n_vertices(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(sum(len(p.faces) for p in self.parts))

    def faces(self) -> np.ndarray:
        return np.concatenate([p.faces for p in self.parts]) if self.parts else np.zeros((0, 3),
                                                                                        np.int64)


# ---------------------------------------------------------------------------
# topology helpers


def next_in_limb(tree: TreeBake) -> np.ndarray:
    """(S,) the segment continuing each segment along its limb, -1 at tips."""
    order = np.lexsort((np.arange(tree.n_segments), tree.seg_limb))
    nxt = np.full(tree.n_segments, -1, dtype=np.int64)
    a, b = order[:-1], order[1:]
    cont = (tree.seg_limb[a] == tree.seg_limb[b]) & (tree.seg_end[a] == tree.seg_start[b])
    nxt[a[cont]] = b[cont]
    return nxt


def broken_joints(tree: TreeBake, gap: float = BREAK_GAP) -> np.ndarray:
    """(S,) bool: segment s separated from its parent at some frame (its base
    moved more than `gap` m away from where the parent carries it). A tree
    whose bake records no event (info["events"] empty: nothing broke, was
    cut or uprooted) has none, and is not searched frame by frame."""
    out = np.zeros(tree.n_segments, dtype=bool)
    if tree.static or tree.info.get("events", None) == []:
        return out
    return separated_joints(tree, gap)


def separated_joints(tree: TreeBake, gap: float = BREAK_GAP) -> np.ndarray:
    """(S,) bool: segment s's base more than `gap` m from where its parent
    carries it at some frame, searched in every frame of a moved tree."""
    out = np.zeros(tree.n_segments, dtype=bool)
    child = np.nonzero(tree.seg_parent >= 0)[0]
    if len(child) == 0:
        return out
    par = tree.seg_parent[child]
    offset = (tree.points[tree.seg_start[child]] - tree.points[tree.seg_start[par]])[None]
    q = tree.rotations[:, par].astype(np.float64)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * cross(u, np.broadcast_to(offset, u.shape))
    carried = tree.positions[:, par] + offset + w * t + cross(u, t)
    worst = np.linalg.norm(tree.positions[:, child] - carried, axis=-1).max(axis=0)
    out[child] = worst > gap
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def _perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit vector in t (N, 3)."""
    ref = np.where(np.abs(t[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    return _unit(cross(t, ref))


# ---------------------------------------------------------------------------
# bark


@dataclass
class _Stations:
    seg: np.ndarray  # (N,) segment the station lies on
    t: np.ndarray  # (N,) fraction along it
    centre: np.ndarray  # (N, 3)
    tangent: np.ndarray  # (N, 3) unit
    radius: np.ndarray  # (N,)
    joints: np.ndarray  # (N, 2)
    weights: np.ndarray  # (N, 2)
    limb: np.ndarray  # (N,)
    order: np.ndarray  # (N,) rank along the limb


def _point_radius(tree: TreeBake, nxt: np.ndarray, broken: np.ndarray,
                  min_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Ring radius (m) at each segment's start and end: the mean of the two
    segments' radii where a limb continues unbroken, else the segment's."""
    r = np.maximum(0.5 * tree.width.astype(np.float64), min_radius)
    r_start = r.copy()
    r_end = r.copy()
    cont = np.nonzero(nxt >= 0)[0]
    cont = cont[~broken[nxt[cont]]]
    mean = 0.5 * (r[cont] + r[nxt[cont]])
    r_end[cont] = mean
    r_start[nxt[cont]] = mean
    return r_start, r_end


def _stations(tree: TreeBake, opts: MeshOptions, nxt: np.ndarray, broken: np.ndarray):
    """Ring stations of all limbs, and for each segment the station its last
    quad strip ends on."""
    S, m = tree.n_segments, opts.rings
    p0 = tree.points[tree.seg_start].astype(np.float64)
    p1 = tree.points[tree.seg_end].astype(np.float64)
    axis = _unit(p1 - p0)
    r_start, r_end = _point_radius(tree, nxt, broken, opts.min_radius)
    prev = np.where(broken, -1, tree.seg_parent)  # -1: the ground or a broken joint
    # in-limb predecessor (for the joint ring's tangent)
    in_prev = np.full(S, -1, dtype=np.int64)
    ok = nxt >= 0
    in_prev[nxt[ok]] = np.nonzero(ok)[0]
    nxt_ok = np.where((nxt >= 0) & ~broken[np.maximum(nxt, 0)], nxt, -1)

    # regular stations: j = 0..m-1 on every segment
    seg = np.repeat(np.arange(S), m)
    j = np.tile(np.arange(m), S)
    t = j / m
    # end stations: segments with no unbroken continuation
    ends = np.nonzero(nxt_ok < 0)[0]
    seg = np.concatenate([seg, ends])
    t = np.concatenate([t, np.ones(len(ends))])
    centre = p0[seg] + (p1[seg] - p0[seg]) * t[:, None]
    radius = r_start[seg] + (r_end[seg] - r_start[seg]) * t
    tangent = axis[seg].copy()
    joint_ring = (t == 0) & (in_prev[seg] >= 0) & ~broken[seg]
    tangent[joint_ring] = _unit(axis[seg[joint_ring]] + axis[in_prev[seg[joint_ring]]])

    first = t < 0.5
    other = np.where(first, prev[seg], nxt_ok[seg])
    w_other = np.where(first, 0.5 - t, t - 0.5)
    w_other = np.where(other >= 0, w_other, 0.0)
    joints = np.stack([seg, np.maximum(other, 0)], axis=1)
    weights = np.stack([1.0 - w_other, w_other], axis=1)
    # a weight of exactly 0 keeps its joint slot at the segment itself (no duplicates)
    joints[:, 1] = np.where(weights[:, 1] > 0, joints[:, 1], joints[:, 0])

    # rank along the limb: segment order within the limb, then t
    rank_seg = np.empty(S, dtype=np.int64)
    order = np.lexsort((np.arange(S), tree.seg_limb))
    limb_sorted = tree.seg_limb[order]
    starts = np.r_[0, np.nonzero(limb_sorted[1:] != limb_sorted[:-1])[0] + 1]
    run_start = np.repeat(starts, np.diff(np.r_[starts, S]))
    rank_seg[order] = np.arange(S) - run_start
    j_all = np.concatenate([j, np.full(len(ends), m)])
    rank = rank_seg[seg] * (m + 1) + j_all
    n_reg = S * m
    end_station = np.zeros(S, dtype=np.int64)
    has_next = nxt_ok >= 0
    end_station[has_next] = nxt_ok[has_next] * m
    end_station[ends] = n_reg + np.arange(len(ends))
    st = _Stations(seg, t, centre, tangent, radius, joints, weights, tree.seg_limb[seg], rank)
    return st, end_station


def _ring_frames(st: _Stations) -> np.ndarray:
    """Normals N (N, 3) of each station's ring frame, parallel-transported
    along each limb (double reflection) so rings do not twist."""
    n = len(st.seg)
    order = np.lexsort((st.order, st.limb))
    limb = st.limb[order]
    starts = np.r_[0, np.nonzero(limb[1:] != limb[:-1])[0] + 1]
    lengths = np.diff(np.r_[starts, n])
    normal = np.empty((n, 3))
    tan = st.tangent[order]
    pos = st.centre[order]
    first = starts
    normal[first] = _perpendicular(tan[first])
    for k in range(1, int(lengths.max()) if n else 0):
        live = starts[lengths > k]
        a, b = live + k - 1, live + k
        v1 = pos[b] - pos[a]
        c1 = (v1 * v1).sum(1)
        c1s = np.where(c1 > 1e-20, c1, 1.0)
        rl = normal[a] - (2.0 / c1s * (v1 * normal[a]).sum(1))[:, None] * v1
        tl = tan[a] - (2.0 / c1s * (v1 * tan[a]).sum(1))[:, None] * v1
        rl = np.where(c1[:, None] > 1e-20, rl, normal[a])
        tl = np.where(c1[:, None] > 1e-20, tl, tan[a])
        v2 = tan[b] - tl
        c2 = (v2 * v2).sum(1)
        c2s = np.where(c2 > 1e-20, c2, 1.0)
        nb = rl - (2.0 / c2s * (v2 * rl).sum(1))[:, None] * v2
        nb = np.where(c2[:, None] > 1e-20, nb, rl)
        nb = nb - (nb * tan[b]).sum(1)[:, None] * tan[b]  # re-orthogonalise
        bad = np.linalg.norm(nb, axis=1) < 1e-9
        nb[bad] = _perpendicular(tan[b][bad])
        normal[b] = _unit(nb)
    out = np.empty_like(normal)
    out[order] = normal
    return out


def _arc_length(st: _Stations) -> np.ndarray:
    """Distance (m) from the limb's base along its stations."""
    n = len(st.seg)
    order = np.lexsort((st.order, st.limb))
    pos = st.centre[order]
    limb = st.limb[order]
    step = np.r_[0.0, np.linalg.norm(np.diff(pos, axis=0), axis=1)]
    step[np.r_[True, limb[1:] != limb[:-1]]] = 0.0
    total = np.cumsum(step)
    starts = np.r_[0, np.nonzero(limb[1:] != limb[:-1])[0] + 1]
    base = np.repeat(total[starts], np.diff(np.r_[starts, n]))
    out = np.empty(n)
    out[order] = total - base
    return out


def _bark(tree: TreeBake, opts: MeshOptions, broken: np.ndarray):
    nxt = next_in_limb(tree)
    st, end_station = _stations(tree, opts, nxt, broken)
    k = opts.radial
    normal = _ring_frames(st)
    binormal = cross(st.tangent, normal)
    phi = 2 * np.pi * np.arange(k + 1) / k
    cos, sin = np.cos(phi), np.sin(phi)
    cos[k], sin[k] = 1.0, 0.0  # the seam column repeats column 0 exactly
    radial = cos[None, :, None] * normal[:, None, :] + sin[None, :, None] * binormal[:, None, :]
    n_st = len(st.seg)
    positions = (st.centre[:, None, :] + st.radius[:, None, None] * radial).reshape(-1, 3)
    normals = radial.reshape(-1, 3)
    # +u runs around the ring (d radial / d phi = tangent x radial); N x T is
    # then the limb's tangent, +v: the normal map's green
    tangents = cross(np.broadcast_to(st.tangent[:, None, :], radial.shape).reshape(-1, 3),
                     normals)
    v = _arc_length(st) / opts.bark_tile
    uvs = np.stack([np.broadcast_to(np.arange(k + 1) / k, (n_st, k + 1)),
                    np.broadcast_to(v[:, None], (n_st, k + 1))], axis=-1).reshape(-1, 2)
    joints = np.repeat(st.joints, k + 1, axis=0)
    weights = np.repeat(st.weights, k + 1, axis=0)

    # tube strips: station a -> station b for every consecutive pair on a segment
    S, m = tree.n_segments, opts.rings
    a = np.arange(S * m)
    b = np.where(np.tile(np.arange(m), S) < m - 1, a + 1, end_station[np.repeat(np.arange(S), m)])
    i = np.arange(k)
    a0 = (a[:, None] * (k + 1) + i).ravel()
    b0 = (b[:, None] * (k + 1) + i).ravel()
    faces = np.concatenate([np.stack([a0, a0 + 1, b0 + 1], 1), np.stack([a0, b0 + 1, b0], 1)])

    # caps: limb bases on the ground, limb tips, both sides of broken joints
    base_cap = (st.t == 0) & ((tree.seg_parent[st.seg] < 0) | broken[st.seg])
    tip_cap = st.t == 1.0
    extra_pos, extra_nrm, extra_uv, extra_j, extra_w, cap_faces = [], [], [], [], [], []
    extra_tan = []
    n0 = len(positions)
    for sel, sign in ((np.nonzero(base_cap)[0], -1.0), (np.nonzero(tip_cap)[0], 1.0)):
        if len(sel) == 0:
            continue
        centre_ids = n0 + sum(len(p) for p in extra_pos) + np.arange(len(sel))
        extra_pos.append(st.centre[sel])
        extra_nrm.append(sign * st.tangent[sel])
        extra_tan.append(normal[sel])  # across the cap (its UV is a point: any will do)
        extra_uv.append(np.stack([np.full(len(sel), 0.5), v[sel]], 1))
        extra_j.append(st.joints[sel])
        extra_w.append(st.weights[sel])
        ring = sel[:, None] * (k + 1) + i
        c = np.broadcast_to(centre_ids[:, None], ring.shape)
        if sign > 0:
            tri = np.stack([c, ring, ring + 1], -1)
        else:
            tri = np.stack([c, ring + 1, ring], -1)
        cap_faces.append(tri.reshape(-1, 3))
    if extra_pos:
        positions = np.concatenate([positions, *extra_pos])
        normals = np.concatenate([normals, *extra_nrm])
        tangents = np.concatenate([tangents, *extra_tan])
        uvs = np.concatenate([uvs, *extra_uv])
        joints = np.concatenate([joints, *extra_j])
        weights = np.concatenate([weights, *extra_w])
        faces = np.concatenate([faces, *cap_faces])
    return positions, normals, uvs, joints, weights, faces, tangents


def tree_seed(tree: TreeBake) -> int:
    """The seed a tree grew from (its bake's info), 0 if it has none: the
    foliage's placement follows it."""
    seed = tree.info.get("seed")
    return int(seed) if isinstance(seed, (int, np.integer)) else 0


def leaf_material(kind: int) -> str:
    """The material of leaf type `kind` (1, 2, ...): "leaf", "leaf2", ..."""
    return "leaf" if kind == 1 else f"leaf{int(kind)}"


def foliage_on_segments(leaf: np.ndarray, twig_leaf: np.ndarray,
                        twig_segment: np.ndarray) -> np.ndarray:
    """The segments that draw foliage along themselves: leafy ones
    (`leaf` (S,) leaf types) without leafy twigs (`twig_leaf`,
    `twig_segment` (T,)); the others draw it along their twigs."""
    on_twigs = np.zeros(len(leaf), bool)
    on_twigs[twig_segment[twig_leaf > 0]] = True
    return np.nonzero((leaf > 0) & ~on_twigs)[0]


def part_materials_of(leaf: np.ndarray, twig_leaf: np.ndarray, twig_segment: np.ndarray,
                      opts: MeshOptions = MeshOptions()) -> list[str]:
    """The shading materials of the parts tree_mesh(tree, opts) makes for a
    tree whose segments have leaf types `leaf` (TreeBake.leaf) and twigs
    `twig_leaf` on `twig_segment` (Twigs), without building it."""
    drawn = np.concatenate([leaf[foliage_on_segments(leaf, twig_leaf, twig_segment)],
                            twig_leaf])
    leaves = np.unique(drawn[drawn > 0]) if opts.leaves else []
    return [opts.bark] + [leaf_material(k) for k in leaves]


def _foliage_pieces(tree: TreeBake):
    """Where foliage is drawn: base and tip (N, 3) m, leaf size (N,) m, leaf
    type (N,) and the segment each piece rides on (N,). A segment with
    leafy twigs draws its foliage along them, any other leafy segment
    along itself."""
    tw = tree.twigs
    segs = foliage_on_segments(tree.leaf, tw.leaf, tw.segment)
    twigs = np.nonzero(tw.leaf > 0)[0]
    f64 = np.float64
    return (np.concatenate([tree.points[tree.seg_start[segs]].astype(f64), tw.start[twigs]]),
            np.concatenate([tree.points[tree.seg_end[segs]].astype(f64), tw.end[twigs]]),
            np.concatenate([tree.leaf_size[segs].astype(f64), tw.leaf_size[twigs]]),
            np.concatenate([tree.leaf[segs], tw.leaf[twigs]]),
            np.concatenate([segs, tw.segment[twigs]]))


def tree_mesh(tree: TreeBake, opts: MeshOptions = MeshOptions(),
              broken: np.ndarray | None = None) -> TreeMesh:
    """Bark (material "bark", with the twigs' tubes) and leaves (one
    material per leaf type, "leaf", "leaf2", ...) of a tree at rest."""
    if opts.radial < 3 or opts.rings < 1:
        raise ValueError("radial must be >= 3 and rings >= 1")
    if broken is None:
        broken = broken_joints(tree)
    pos, nrm, uv, jnt, wts, faces, tan = _bark(tree, opts, broken)
    if len(tree.twigs) and opts.twigs:
        tp, tn, tu, tj, tw, tf, tt = twig_tubes(tree.twigs, opts.radial, opts.min_radius,
                                                opts.bark_tile)
        faces = np.concatenate([faces, tf + len(pos)])
        pos, nrm, uv = np.concatenate([pos, tp]), np.concatenate([nrm, tn]), \
            np.concatenate([uv, tu])
        jnt, wts, tan = np.concatenate([jnt, tj]), np.concatenate([wts, tw]), \
            np.concatenate([tan, tt])
    look = None if opts.bark == "bark" else opts.bark
    parts = [MeshPart("bark", faces.astype(np.int64), opts.bark_rgb, look=look)]
    arrays = [(pos, nrm, uv, jnt, wts)]
    offset = len(pos)
    if opts.leaves:
        p0, p1, size, kinds, owner = _foliage_pieces(tree)
        centre = 0.5 * (p0 + p1).mean(0) if len(kinds) else None
        for kind in np.unique(kinds):
            sel = kinds == kind
            lp, ln, lu, lj, lw, lf, _ = cards(p0[sel], p1[sel], size[sel], owner[sel],
                                              int(kind), tree_seed(tree), centre,
                                              opts.card_scale)
            parts.append(MeshPart(leaf_material(kind), lf + offset, leaf_colour(kind),
                                  double_sided=True))
            arrays.append((lp, ln, lu, lj, lw))
            offset += len(lp)
    cat = [np.concatenate(x) for x in zip(*arrays)]
    normals = _unit(cat[1])
    across = _perpendicular(normals[len(pos):])  # cards: no normal map, any tangent
    tangents = np.concatenate([_unit(tan), across])
    return TreeMesh(cat[0], normals, cat[2], cat[3].astype(np.int64), cat[4], parts,
                    np.concatenate([tangents, np.ones((len(tangents), 1))], axis=1))


# ---------------------------------------------------------------------------
# projectiles


def box_mesh(edge: float) -> TreeMesh:
    """A cube of edge `edge` m centred on the origin, flat normals, UVs per face."""
    h = 0.5 * edge
    pos, nrm, faces = [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v = cross(n[None], u[None])[0]
            c = n * h
            base = len(pos)
            pos += [c - u * h - v * h, c + u * h - v * h, c + u * h + v * h, c - u * h + v * h]
            nrm += [n] * 4
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    uv = np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (6, 1))
    return _rigid_mesh(np.array(pos), np.array(nrm), uv, np.array(faces))


def sphere_mesh(diameter: float, rows: int = 8, cols: int = 16) -> TreeMesh:
    """A UV sphere of `diameter` m centred on the origin."""
    theta = np.linspace(0, np.pi, rows + 1)  # from the south pole (z = -r)
    phi = np.linspace(0, 2 * np.pi, cols + 1)
    st, ct = np.sin(theta)[:, None], -np.cos(theta)[:, None]
    nrm = np.stack([st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (rows + 1, cols + 1))],
                   -1).reshape(-1, 3)
    nrm[:, :2] = np.where(np.abs(nrm[:, :2]) < 1e-15, 0.0, nrm[:, :2])
    uv = np.stack(np.meshgrid(phi / (2 * np.pi), theta / np.pi), -1).reshape(-1, 2)
    r0 = (np.arange(rows)[:, None] * (cols + 1) + np.arange(cols)).ravel()
    r1 = r0 + cols + 1
    faces = np.concatenate([np.stack([r0, r0 + 1, r1 + 1], 1), np.stack([r0, r1 + 1, r1], 1)])
    # drop the degenerate triangles at the poles
    keep = ((faces[:, 0] // (cols + 1) != 0) | (faces[:, 1] // (cols + 1) != 0)) & \
        ((faces[:, 1] // (cols + 1) != rows) | (faces[:, 2] // (cols + 1) != rows))
    faces = faces[keep]
    faces = faces[(faces[:, 0] // (cols + 1) != rows)]
    return _rigid_mesh(0.5 * diameter * nrm, _unit(nrm), uv, faces)


def _rigid_mesh(pos, nrm, uv, faces) -> TreeMesh:
    n = len(pos)
    return TreeMesh(pos.astype(np.float64), nrm.astype(np.float64), uv.astype(np.float64),
                    np.zeros((n, 2), np.int64), np.tile([1.0, 0.0], (n, 1)),
                    [MeshPart("object", np.asarray(faces, np.int64), OBJECT_COLOUR)])


def object_mesh(shape: str, size: float) -> TreeMesh:
    return sphere_mesh(size) if shape == "sphere" else box_mesh(size)


# ---------------------------------------------------------------------------
# posing


def pose(mesh: TreeMesh, tree: TreeBake, f: int) -> tuple[np.ndarray, np.ndarray]:
    """Posed vertex positions (V, 3) and unit normals at bake frame f (world,
    m): linear blend of each influence's rigid motion."""
    frame = 0 if tree.static else f
    rot = matrices_from_quaternions(tree.rotations[frame].astype(np.float64))
    pos = tree.positions[frame].astype(np.float64)
    base = tree.points[tree.seg_start].astype(np.float64)
    out_p = np.zeros_like(mesh.positions)
    out_n = np.zeros_like(mesh.normals)
    for c in range(mesh.joints.shape[1]):
        j = mesh.joints[:, c]
        w = mesh.weights[:, c:c + 1]
        r = rot[j]
        out_p += w * (pos[j] + apply(r, mesh.positions - base[j]))
        out_n += w * apply(r, mesh.normals)
    return out_p, _unit(out_n)


def pose_rigid(mesh: TreeMesh, position: np.ndarray, quat: np.ndarray):
    """A rigid mesh moved to `position` (m) and rotated by `quat` (x y z w)."""
    r = matrices_from_quaternions(np.asarray(quat, np.float64)[None])[0]
    return mesh.positions @ r.T + position, mesh.normals @ r.T
