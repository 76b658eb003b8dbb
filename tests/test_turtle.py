"""The 3D turtle against hand-worked geometry, and the TreeModel hierarchy."""

import math

import numpy as np
import pytest
from treebake.errors import GrammarError
from treebake.lsystem import derive, parse_grammar
from treebake.turtle import interpret


def model(text, **kw):
    g = parse_grammar(text)
    return interpret(derive(g, **kw).modules, g)


def seg_dirs(m):
    v = m.seg_vector
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_turns_follow_abop_conventions():
    d = seg_dirs(model("angle: 90\naxiom: F+F"))
    assert np.allclose(d, [[0, 0, 1], [-1, 0, 0]])  # + turns left (toward L = -X)
    d = seg_dirs(model("angle: 90\naxiom: F-F&F"))
    assert np.allclose(d[1], [1, 0, 0])
    # after "-" heading +X; & pitches the heading toward -U = +Y... check by hand:
    # frame after -(90): H=+X, L=+Z, U=-Y -> & moves H toward +Y
    assert np.allclose(d[2], [0, 1, 0])
    d = seg_dirs(model("angle: 90\naxiom: F^F"))
    assert np.allclose(d[1], [0, -1, 0])  # pitch up: toward U = -Y (the viewer)
    d = seg_dirs(model("angle: 90\naxiom: \\+F"))
    # roll left moves L toward -U: L=-X -> +Y; then + turns H toward it
    assert np.allclose(d[0], [0, 1, 0])
    d = seg_dirs(model("angle: 90\naxiom: F|F"))
    assert np.allclose(d[1], [0, 0, -1])


def test_roll_to_horizontal():
    # an arbitrary orientation; after $ the left vector is horizontal, so a
    # 90-degree turn gives a horizontal segment
    m = model("axiom: &(30)/(47)+(20)&(11)$+(90)F")
    assert seg_dirs(m)[0][2] == pytest.approx(0, abs=1e-12)


def test_tropism_bends_toward_the_vector_by_e_times_sine():
    m = model("tropism: 0, 0, -1\nelasticity: 0.2\nangle: 90\naxiom: &FF")
    d = seg_dirs(m)
    assert np.allclose(d[0], [0, 1, 0])  # horizontal
    # |H x T| = 1 -> the heading turns 0.2 rad toward -Z
    assert np.allclose(d[1], [0, math.cos(0.2), -math.sin(0.2)])


def test_hierarchy_and_attachment():
    m = model("axiom: F[+F[-F]F]F[-F]F")
    assert len(m.limbs) == 4
    trunk, b1, b11, b2 = m.limbs
    assert trunk.parent == -1 and trunk.path == "trunk" and len(trunk.segments) == 3
    assert (b1.parent, b1.attach, b1.path) == (0, 1, "trunk/1")
    assert (b11.parent, b11.attach, b11.path) == (1, 1, "trunk/1/1")
    assert (b2.parent, b2.attach, b2.path) == (0, 2, "trunk/2")
    # a branch's first segment hangs on the parent segment ending at its point
    assert m.seg_parent[b1.segments[0]] == trunk.segments[0]
    assert m.seg_parent[b11.segments[0]] == b1.segments[0]
    assert m.seg_parent[trunk.segments[0]] == -1
    # parents are created before children
    assert all(m.seg_parent[s] < s for s in range(m.n_segments))
    assert m.points[b1.points[0]].tolist() == m.points[trunk.points[1]].tolist()


def test_several_root_limbs_and_moves():
    m = model("angle: 90\naxiom: [&f+F][&f(2)F]")
    assert [limb.parent for limb in m.limbs] == [-1, -1]
    assert [limb.path for limb in m.limbs] == ["trunk", "trunk2"]
    assert m.seg_parent.tolist() == [-1, -1]


def test_widths_and_unknown_symbols_ignored():
    m = model("width: 0.5\nwidth factor: 0.5\naxiom: FXY!F!(0.1)F Q F")
    assert m.width.tolist() == [0.5, 0.25, 0.1, 0.1]


def test_physics_attributes_per_segment_and_defaults():
    m = model("density: 600\nmodulus: 9e9\ncone: 20\nangle: 90\n"
              "axiom: !(0.2)F[@density(450)@cone(5)@strength(300)F]@rupture(40e6)F@ei(100)F")
    assert m.density.tolist() == [600, 450, 600, 600]
    assert m.modulus.tolist() == [9e9] * 4
    assert np.degrees(m.cone).tolist() == pytest.approx([20, 5, 20, 20])
    # strength: set explicitly (300 N m) or from the modulus of rupture
    mor = 40e6 * math.pi * 0.2**3 / 32
    assert m.strength[0] == math.inf and m.strength[1] == 300
    assert m.strength[2] == pytest.approx(mor) and m.strength[3] == pytest.approx(mor)
    assert np.isnan(m.ei[:3]).all() and m.ei[3] == 100


def test_leaves_are_scoped_by_brackets():
    m = model("leaf size: 0.2\naxiom: F[@leaves(2, 0.3)F[F]]F")
    assert m.leaf.tolist() == [0, 2, 2, 0]
    assert m.leaf_size.tolist() == [0.2, 0.3, 0.3, 0.2]


def test_errors():
    with pytest.raises(GrammarError, match="no segments"):
        model("axiom: +f")
    with pytest.raises(GrammarError, match="out of range"):
        model("axiom: @density(-3)F")
    with pytest.raises(GrammarError, match="negative width"):
        model("axiom: !(-1)F")


def test_scale_converts_to_metres():
    m = model("scale: 0.5\nwidth: 4\nwidth scale: 0.01\naxiom: F(3)")
    assert m.height == pytest.approx(1.5) and m.width[0] == pytest.approx(0.04)


def test_zero_width_without_rupture_is_unbreakable_not_nan():
    m = model("axiom: !(0)F")
    assert m.strength[0] == math.inf
