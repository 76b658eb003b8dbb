"""bench/crown_cover.py: the rasteriser and the cover against shapes whose
cover is known in closed form, and the bundled species against issue 40's
targets (the small ones here, all of them behind `slow`)."""

import sys

import numpy as np
import pytest
from conftest import ROOT

sys.path.insert(0, str(ROOT / "bench"))
import crown_cover as cc

PIXEL = 0.01  # m


def _quad(x0, x1, z0, z1, y=0.0):
    """Two triangles (2, 3, 3) of an axis-aligned rectangle in the x-z plane
    (Z up, m) and their UVs (u along x, v = 0 at the top, as glTF's)."""
    p = np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]])
    uv = np.array([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return p[f], uv[f]


def _cover(prims, view=(0, 2)):
    pts = np.concatenate([c.reshape(-1, 3) for c, *_ in prims])
    lo, hi = pts.min(0), pts.max(0)
    lo[2] = min(lo[2], 0.0)
    mask = cc.silhouette(prims, view, PIXEL, lo, hi)
    return cc.crown_cover(mask, PIXEL, hi[2]), mask


def _opaque(*quads):
    return [(c, uv, None, 0.0, "bark") for c, uv in quads]


def test_a_solid_crown_on_a_pole_covers_its_hull():
    # a 2 m x 2 m opaque crown from 2 to 4 m on a 4 cm pole: the crown above
    # 1.4 m is the square and the pole from 1.4 to 2 m; hull = their union's
    pole, crown = _quad(-0.02, 0.02, 0.0, 2.0), _quad(-1.0, 1.0, 2.0, 4.0)
    r, mask = _cover(_opaque(pole, crown))
    assert mask.sum() == pytest.approx((2.0 * 2.0 + 0.04 * 2.0) / PIXEL**2, rel=0.01)
    assert r["height_m"] == pytest.approx(4.0, abs=PIXEL)
    # hull: the square plus the triangle-ish cone down to the pole at 1.4 m
    hull = 4.0 + 0.6 * (2.0 + 0.04) / 2
    assert r["cover"] == pytest.approx((4.0 + 0.6 * 0.04) / hull, abs=0.01)


def test_two_crowns_side_by_side_cover_two_thirds_of_their_hull():
    a, b = _quad(-1.5, -0.5, 2.0, 3.0), _quad(0.5, 1.5, 2.0, 3.0)
    r, _ = _cover(_opaque(a, b))
    assert r["cover"] == pytest.approx(2.0 / 3.0, abs=0.01)


def test_alpha_counts_not_the_quad():
    # a texture opaque in its left half only, on a 2 m square: half of it covers
    c, uv = _quad(-1.0, 1.0, 2.0, 4.0)
    alpha = np.zeros((64, 64))
    alpha[:, :32] = 1.0
    r, mask = _cover([(c, uv, alpha, 0.5, "leaf")])
    assert mask.sum() == pytest.approx(0.5 * 4.0 / PIXEL**2, rel=0.01)
    assert r["cover"] == pytest.approx(1.0, abs=0.01)  # the hull is the opaque half
    # a checkerboard of 8 x 8 texels: half of the hull
    alpha = (np.add.outer(np.arange(64) // 8, np.arange(64) // 8) % 2).astype(float)
    r, _ = _cover([(c, uv, alpha, 0.5, "leaf")])
    assert r["cover"] == pytest.approx(0.5, abs=0.02)


def test_edge_on_cards_cover_nothing_and_views_differ():
    # a card in the x-z plane seen from the side (along x) is a line
    c, uv = _quad(-1.0, 1.0, 2.0, 4.0)
    pole = _quad(-0.02, 0.02, 0.0, 4.0)
    side = cc.silhouette(_opaque((c, uv), pole), (1, 2), PIXEL, np.array([-1.0, -1, 0]),
                         np.array([1.0, 1, 4]))
    front = cc.silhouette(_opaque((c, uv), pole), (0, 2), PIXEL, np.array([-1.0, -1, 0]),
                          np.array([1.0, 1, 4]))
    assert side.sum() < 0.01 * front.sum()


@pytest.mark.parametrize("species", ["sapling", "forest/broadleaf", "forest/birch",
                                     "forest/conifer"])
def test_small_species_meet_the_crown_cover_target(species, tmp_path):
    r = cc.measure(cc.export_rest_glb(species, tmp_path), 400)
    assert min(r["front"]["cover"], r["side"]["cover"]) >= cc.target(species) + 0.005, r


@pytest.mark.slow
@pytest.mark.parametrize("species", ["oak", "spruce", "willow"])
def test_large_species_meet_the_crown_cover_target(species, tmp_path):
    r = cc.measure(cc.export_rest_glb(species, tmp_path), 600)
    assert min(r["front"]["cover"], r["side"]["cover"]) >= cc.target(species) + 0.005, r
