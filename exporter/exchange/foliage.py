"""Foliage cards: the leaves, needles and small twigs of every leafy segment
as textured quads skinned rigidly to that segment, so a crown is dense
without a bone of its own for any of it. Visual only: the physics keeps
its foliage (rig.py: `leaf_mass` kg/m^2 on 2 `leaf_size`^2 of card area
per leafy segment, drag on that area); nothing here reaches the rig, the
simulation or the bake. A "piece" below is a leafy segment, or a leafy
twig (`@twig`: a segment with leafy twigs draws its cards along them,
mesh.py), the cards rigid on the segment either way.

Each leafy segment (length L m, leaf size a m) carries n cards of edge
e = EDGE x a m. A card is a shoot: its stem (texture v = 0) on the
segment's axis at a random point along it, the card reaching out from
there (v = 1 at its tip) at an angle from the segment's axis, turned
about its own length at random, so the cards of a segment fill a sleeve
of radius about e around it. n is what gives that sleeve, seen from the
side, an optical depth of `depth` (an expected cover 1 - exp(-depth)):

    n = depth x 2 e (L + e) / (0.5 x fill x e^2)

with `fill` the fraction of the card's texture that is opaque and 0.5 the
mean |cos| of a randomly turned card, divided by sqrt(k) where k leafy
segments have their midpoints in the same cube of edge 2 e (card_counts);
n is at least 1 and at most MAX_CARDS. Counts, places and turns come from the tree's seed (numpy's
PCG64, unit vectors by rejection in the cube: square roots and divisions
only, no transcendental functions, so the same seed gives the same bytes
on every machine).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_CARDS = 64  # per leafy segment
ATLAS = 2  # a leaf texture is ATLAS x ATLAS cards, one colour variant each (textures.py)


@dataclass(frozen=True)
class FoliageStyle:
    """How a leaf type's cards sit. edge: card edge / leaf_size; depth:
    optical depth of a segment's sleeve of cards, side view; fill: opaque
    fraction of the card's texture; lean: range of the card's tip-ward
    lean, the cotangent of its angle from the segment's axis (0 = square
    to it, 1 = 45 degrees toward its tip)."""

    edge: float = 1.0
    depth: float = 1.0
    fill: float = 0.25
    lean: tuple[float, float] = (0.0, 1.2)


BROADLEAF = FoliageStyle(edge=2.4, depth=1.4, fill=0.40)
STYLES = {1: BROADLEAF, 2: FoliageStyle(edge=2.2, depth=1.2, fill=0.49),
          3: FoliageStyle(edge=1.0, depth=0.5, fill=0.26), 4: BROADLEAF}


def style(kind: int) -> FoliageStyle:
    return STYLES.get(int(kind), STYLES[1])


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.sqrt((v * v).sum(-1, keepdims=True))
    return v / np.where(n > 1e-12, n, 1.0)


def _random_units(rng: np.random.Generator, n: int) -> np.ndarray:
    """n unit vectors, uniform on the sphere: points in the cube kept inside
    the unit ball (and away from its centre), normalised."""
    out = np.zeros((0, 3))
    while len(out) < n:
        p = rng.uniform(-1.0, 1.0, size=(2 * (n - len(out)) + 8, 3))
        r2 = (p * p).sum(1)
        out = np.concatenate([out, p[(r2 <= 1.0) & (r2 > 1e-4)]])
    return _unit(out[:n])


def _across(v: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Unit vectors perpendicular to unit vectors v: r's part across v
    (r random), falling back to a fixed axis where r is nearly along v."""
    out = r - (r * v).sum(1, keepdims=True) * v
    bad = (out * out).sum(1) < 1e-6
    if bad.any():
        ref = np.where(np.abs(v[bad, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        out[bad] = np.cross(v[bad], ref)
    return _unit(out)


def card_counts(p0: np.ndarray, p1: np.ndarray, size: np.ndarray, kind: int,
                scale: float = 1.0) -> np.ndarray:
    """(N,) cards per leafy segment (base p0, tip p1 (N, 3) m, leaf size
    (N,) m): the sleeve's count (module doc) over sqrt(k), k the leafy
    segments whose midpoints fall in the same cube of edge 2 e (e the
    median card edge; cubes from the midpoints' mean, so a tree moved in a
    scene keeps its counts), so crowded twigs (a willow's curtain) do not
    pile up cards where their neighbours' already cover. `scale`: card
    edges x this (an export's detail level: mesh.DETAIL)."""
    st = style(kind)
    e = st.edge * np.asarray(size, np.float64) * scale
    length = np.sqrt(((p1 - p0) ** 2).sum(1))
    sleeve = 2.0 * e * (length + e)
    card = 0.5 * st.fill * e * e
    safe = np.where(card > 0, card, 1.0)
    n = st.depth * sleeve / safe
    cell = 2.0 * float(np.median(e)) if len(e) else 1.0
    if cell > 0:
        mid = 0.5 * (p0 + p1)
        key = np.floor((mid - mid.mean(0)) / cell).astype(np.int64)
        _, inverse, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        n = n / np.sqrt(count[inverse.reshape(-1)])
    return np.clip(np.rint(n), 1, MAX_CARDS).astype(np.int64)


def cards(p0: np.ndarray, p1: np.ndarray, size: np.ndarray, segs: np.ndarray, kind: int,
          seed: int, centre=None, scale: float = 1.0):
    """The cards of leafy segments `segs` (base p0, tip p1 (N, 3) m, leaf
    size (N,) m) of leaf type `kind`: positions (4C, 3), normals, UVs
    (stem at v = 0), joints and weights (rigid on the segment) and
    triangles (2C, 3), and the segment of each card (C,). Each card shows
    one cell of the leaf texture's atlas (its colour variant), by the seed.
    `centre` (m): the crown's, which the cards' fronts and shading normals
    face away from (default: the mean of the segments' midpoints).
    `scale`: card edges x this (card_counts)."""
    st = style(kind)
    n = card_counts(p0, p1, size, kind, scale)
    owner = np.repeat(np.arange(len(segs)), n)
    c = len(owner)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 40, int(kind)])
    t = rng.uniform(0.0, 1.0, c)
    lean = rng.uniform(st.lean[0], st.lean[1], c)
    axis = _unit(p1 - p0)[owner]
    out = _across(axis, _random_units(rng, c))  # away from the segment, at a random azimuth
    d = _unit(out + lean[:, None] * axis)  # the card's length: stem -> tip
    s = _across(d, _random_units(rng, c))  # its width, turned at random about d
    e = (st.edge * size[owner] * scale)[:, None]
    base = p0[owner] + t[:, None] * (p1 - p0)[owner]
    # the card's front (its winding's side) faces out of the crown; its shading
    # normal leans out too, so the crown shades as one mass, not card by card
    away = base + 0.5 * e * d - (np.mean(0.5 * (p0 + p1), axis=0) if centre is None
                                 else np.asarray(centre, np.float64))
    away = _unit(away * [1.0, 1.0, 0.5])
    face = np.cross(s, d)  # the winding's: (corner 1 - 0) x (corner 3 - 0)
    flip = (face * away).sum(1) < 0
    s[flip] *= -1.0
    face[flip] *= -1.0
    half = 0.5 * e * s
    corners = np.stack([base - half, base + half, base + e * d + half, base + e * d - half], 1)
    pos = corners.reshape(-1, 3)
    nrm = np.repeat(_unit(face + 2.0 * away), 4, axis=0)
    # each card one cell of the atlas, by the seed: its colour variant
    cell = rng.integers(0, ATLAS * ATLAS, c)
    corner = np.stack([cell % ATLAS, cell // ATLAS], 1).astype(np.float64) / ATLAS
    uv = (np.repeat(corner, 4, axis=0) +
          np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (c, 1)) / ATLAS)
    quad = (np.arange(c) * 4)[:, None]
    faces = np.concatenate([quad + [0, 1, 2], quad + [0, 2, 3]], axis=1).reshape(-1, 3)
    seg = np.repeat(segs[owner], 4)
    joints = np.stack([seg, seg], 1)
    weights = np.tile([1.0, 0.0], (4 * c, 1))
    return pos, nrm, uv, joints, weights, faces, segs[owner]
