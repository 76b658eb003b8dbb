"""The palm and the bamboo follow their botany (issue 40 item 1,
docs/species.md), measured on the grown trees, and keep their physics
segments within 10 % of what they had before the drawn twigs (149 and
588 at 1edc0e9): the palm a Corner's-model crown of arching pinnate
fronds, older fronds lower and drooping more, leaflets in two ranks; the
bamboo culms alone in the physics, their leafy side branches twigs."""

import functools

import numpy as np
import pytest
from conftest import GRAMMARS
from treebake import species

SEGMENTS_BEFORE = {"palm": 149, "bamboo": 588}  # TreeModel.n_segments at 1edc0e9


@functools.cache
def model(name: str):
    return species.grown_rig(GRAMMARS / f"{name}.lsys").model


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.mark.parametrize("name", sorted(SEGMENTS_BEFORE))
def test_physics_segments_within_a_tenth_of_before(name):
    before = SEGMENTS_BEFORE[name]
    assert 0.9 * before <= model(name).n_segments <= 1.1 * before


def _fronds(m):
    """The palm's fronds (limbs on the stem), oldest first (lowest on the
    stem, then in drawing order), as (limb, tip direction)."""
    out = []
    for i, limb in enumerate(m.limbs):
        if limb.parent == 0:
            last = limb.segments[-1]
            tip = _unit(m.points[m.seg_end[last]] - m.points[m.seg_start[last]])
            out.append((limb.attach, i, tip))
    out.sort(key=lambda f: (f[0], f[1]))
    return [(i, tip) for _, i, tip in out]


def test_palm_is_a_crown_of_fronds_older_ones_drooping_more():
    m = model("palm")
    fronds = _fronds(m)
    assert 12 <= len(fronds) <= 25  # a coconut-like crown
    assert not any(l.parent > 0 and m.limbs[l.parent].parent >= 0 for l in m.limbs), \
        "fronds do not branch: leaflets are twigs"
    tip_z = np.array([tip[2] for _, tip in fronds])
    third = len(fronds) // 3
    # the oldest third's tips point well down, the youngest third's above
    # the horizon, and the tips fall with age along the crown
    assert tip_z[:third].max() < -0.4 and tip_z[-third:].min() > 0.0
    assert np.corrcoef(np.arange(len(tip_z)), tip_z)[0, 1] > 0.9
    # each rachis arches down: its tip points lower than its base, by more
    # than 25 degrees
    for i, tip in fronds:
        first = m.limbs[i].segments[0]
        base = _unit(m.points[m.seg_end[first]] - m.points[m.seg_start[first]])
        assert base[2] > tip[2] and np.degrees(np.arccos(base @ tip)) > 25.0


def test_palm_leaflets_in_two_ranks_on_every_leafy_rachis_segment():
    m = model("palm")
    tw = m.twigs
    leafy = np.nonzero(m.leaf > 0)[0]
    assert len(leafy) and np.all(m.leaf[leafy] == 3)
    for s in leafy:
        mine = tw.segment == s
        assert mine.sum() >= 4 and np.all(tw.leaf[mine] == 3)
        axis = _unit(m.points[m.seg_end[s]] - m.points[m.seg_start[s]])
        d = _unit(tw.end[mine] - tw.start[mine])
        # in pairs from one point of the rachis, one each side: their parts
        # across the axis at least 60 degrees apart (both droop: a V)
        _, pair = np.unique(np.round(tw.start[mine], 6), axis=0, return_inverse=True)
        assert np.all(np.bincount(pair.reshape(-1)) == 2)
        across = _unit(d - (d @ axis)[:, None] * axis)
        for k in range(pair.max() + 1):
            a, b = across[pair.reshape(-1) == k]
            assert a @ b < 0.5
        assert np.all(d @ axis > 0.2)  # leaning to the frond's tip


def test_bamboo_culms_alone_in_the_physics_leafy_branches_as_twigs():
    m = model("bamboo")
    culms = [l for l in m.limbs if l.parent < 0]
    assert len(culms) == len(m.limbs) >= 5  # every limb a culm: no branch segments
    heights = [m.points[c.points[-1], 2] for c in culms]
    assert max(heights) - min(heights) > 3.0  # of different heights
    tw = m.twigs
    assert len(tw) and np.all(tw.leaf > 0)
    for c in culms:
        segs = np.array(c.segments)
        carrying = np.isin(segs, tw.segment)
        # side branches on the upper part of the culm only, from one node on
        k = int(np.argmax(carrying))
        assert carrying[k:].all() and not carrying[:k].any()
        assert 0.3 < k / len(segs) < 0.7
        # those internodes carry the twigs' foliage in the physics
        assert np.all(m.leaf[segs[k:]] == 3) and np.all(m.leaf[segs[:k]] == 0)
        # the tip nods: its last internode leans further than its first
        first = _unit(m.points[m.seg_end[segs[0]]] - m.points[m.seg_start[segs[0]]])
        last = _unit(m.points[m.seg_end[segs[-1]]] - m.points[m.seg_start[segs[-1]]])
        assert np.degrees(np.arccos(np.clip(first @ last, -1, 1))) > 10.0
