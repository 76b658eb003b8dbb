"""Issue 40 items 1-2: `@twig` draws twigs that are geometry only. A twig
rides rigidly on the segment it grows from: no segment, bone, mass or drag
of its own; its leaves count in that segment's foliage; the bake carries
it so exports need no grammar; a grammar without twigs bakes as before."""

import math
import sys
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from treebake.bake_file import load_bake, save_bake
from treebake.cli import main
from treebake.errors import GrammarError, InputError
from treebake.exchange.mesh import MeshOptions, pose, tree_mesh
from treebake.exchange.twigs import twig_sides
from treebake.lsystem import derive, parse_grammar
from treebake.pipeline import bake_scene
from treebake.rig import build_rig
from treebake.scene import parse_scene
from treebake.turtle import interpret

# a trunk of two 1 m segments, a leafy branch with a twig system of two
# orders (0.4 m, then 0.3 m and 0.2 m) and a bare-trunk twig of autumn leaves
TWIGGY = ("name: twiggy\nleaves: 0\n"
          "axiom: !(0.1)F(1)F(1)[&(60)@leaves(1,0.2)F(1)"
          "[@twig!(0.01)+(90)F(0.4)[-(90)F(0.3)]F(0.2)]F(0.5)]"
          "[^(90)@twig@leaves(4,0.25)F(0.4)]F(1)\n")
# the same tree without its twigs (and the trunk's own leaves where its twig's were)
BARE = ("name: twiggy\nleaves: 0\n"
        "axiom: !(0.1)F(1)@leaves(4,0.25)F(1)@leaves(0)[&(60)@leaves(1,0.2)F(1)F(0.5)]F(1)\n")


def model(text):
    g = parse_grammar(text, "t.lsys")
    return interpret(derive(g).modules, g)


def test_twigs_are_drawn_where_the_turtle_goes_and_hang_on_the_segment_under_it():
    m = model(TWIGGY)
    tw = m.twigs
    assert m.n_segments == 5 and len(tw) == 4
    paths = m.segment_paths()
    # branch segment trunk/1:0 (index 2) ends at the branch's first point: its twigs hang on it
    assert [paths[s] for s in tw.segment] == ["trunk/1:0"] * 3 + ["trunk:1"]
    # the branch leaves the trunk at 2 m, pitched down 60 deg (in the YZ plane, up = -Y)
    tip = np.array([0.0, math.sin(math.radians(60)), 2.0 + math.cos(math.radians(60))])
    assert np.allclose(tw.start[0], tip)
    lengths = np.linalg.norm(tw.end - tw.start, axis=1)
    assert np.allclose(lengths, [0.4, 0.3, 0.2, 0.4])
    # the second-order twig starts at the first's end, square to it; the first
    # goes on (0.2 m) from the same point after the bracket
    assert np.allclose(tw.start[1], tw.end[0]) and np.allclose(tw.start[2], tw.end[0])
    d0, d1 = (tw.end[:2] - tw.start[:2]) / lengths[:2, None]
    assert abs(d0 @ d1) < 1e-9
    assert np.allclose(tw.width, [0.01, 0.01, 0.01, 0.1])
    # after the twig bracket F draws segments again, from the branch's tip
    assert np.allclose(m.points[m.seg_end[3]] - m.points[m.seg_start[3]],
                       0.5 * (tip - [0, 0, 2.0]) / np.linalg.norm(tip - [0, 0, 2.0]))


def test_twigs_add_nothing_to_the_physics_but_their_foliage():
    """Twigs on a leafy segment leave the rig exactly as without them; a
    bare segment with leafy twigs carries their foliage (type and size)."""
    m, bare = model(TWIGGY), model(BARE)
    assert list(m.leaf) == [0, 4, 1, 1, 0] and np.allclose(m.leaf_size[1], 0.25)
    leafy = m.leaf > 0
    assert list(bare.leaf) == list(m.leaf)
    assert np.allclose(bare.leaf_size[leafy], m.leaf_size[leafy])
    a, b = build_rig(m), build_rig(bare)
    assert a.n_bones == b.n_bones == 5
    for key in ("mass", "com", "inertia", "wood_area", "leaf_area", "k", "alpha"):
        assert np.array_equal(getattr(a, key), getattr(b, key)), key
    assert a.first_frequency == b.first_frequency


def test_twig_before_any_segment_is_a_grammar_error():
    with pytest.raises(GrammarError, match="@twig before any segment"):
        model("axiom: @twig F(1)\n")
    with pytest.raises(GrammarError, match="@twig"):
        model("axiom: @twig(2) F(1)\n")  # no parameter


def test_cli_names_the_grammar_of_a_twig_before_any_segment(tmp_path, capsys):
    bad = tmp_path / "bad.lsys"
    bad.write_text("axiom: [@twig F(1)]F(1)\n")
    assert main(["inspect", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.lsys" in err and "@twig before any segment" in err and "Traceback" not in err


def _scene(grammar: Path, seconds=0.5):
    return parse_scene({"name": "tw", "duration": seconds, "fps": 24,
                        "tree": [{"grammar": str(grammar), "position": [3.0, -1.0],
                                  "rotation": 30.0}],
                        "wind": {"speed": 12.0}}, file="<twigs>")


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    d = tmp_path_factory.mktemp("twigs")
    (d / "twiggy.lsys").write_text(TWIGGY)
    (d / "bare.lsys").write_text(BARE)
    return d, bake_scene(_scene(d / "twiggy.lsys")), bake_scene(_scene(d / "bare.lsys"))


def test_the_motion_is_the_same_with_and_without_twigs(baked):
    _, twiggy, bare = baked
    (a,), (b,) = twiggy.trees, bare.trees
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.rotations, b.rotations)


def test_the_bake_file_carries_the_twigs_placed_with_their_tree(baked, tmp_path):
    _, twiggy, bare = baked
    (tree,) = twiggy.trees
    m = model(TWIGGY)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    for key in ("start", "end"):
        assert np.allclose(getattr(tree.twigs, key),
                           getattr(m.twigs, key) @ rot.T + [3.0, -1.0, 0], atol=1e-6), key
    path = save_bake(twiggy, tmp_path / "t.npz")
    back = load_bake(path, lazy=True).trees[0]
    for key in ("start", "end", "width", "leaf", "leaf_size", "segment"):
        assert np.array_equal(getattr(back.twigs, key), getattr(tree.twigs, key)), key
    # a bake without twigs stores no twig arrays: its bytes are as before
    names = zipfile.ZipFile(save_bake(bare, tmp_path / "b.npz")).namelist()
    assert not [n for n in names if "twig" in n]
    assert "tree0.twig_segment.npy" in zipfile.ZipFile(path).namelist()


def test_a_damaged_twig_array_is_reported_as_a_damaged_bake(baked, tmp_path):
    _, twiggy, _ = baked
    (tree,) = twiggy.trees
    bad_twigs = replace(tree.twigs, segment=tree.twigs.segment + 10)
    bad = replace(twiggy, trees=[replace(tree, twigs=bad_twigs)])
    path = save_bake(bad, tmp_path / "bad.npz")
    with pytest.raises(InputError, match="damaged.*twig hangs on a segment"):
        load_bake(path)


def test_twig_tubes_ride_their_segment_and_leaves_move_to_the_twigs(baked):
    _, twiggy, _ = baked
    (tree,) = twiggy.trees
    opts = MeshOptions()
    mesh = tree_mesh(tree, opts)
    plain = tree_mesh(replace(tree, twigs=replace(tree.twigs, leaf=tree.twigs.leaf * 0)), opts)
    bark = mesh.parts[0].faces
    k = twig_sides(opts.radial)
    n_twig_vertices = len(tree.twigs) * 2 * (k + 1)
    first = mesh.n_vertices - sum(len(np.unique(p.faces)) for p in mesh.parts[1:]) \
        - n_twig_vertices
    tube = np.arange(first, first + n_twig_vertices).reshape(len(tree.twigs), 2 * (k + 1))
    tw = tree.twigs
    for i in range(len(tw)):
        v = mesh.positions[tube[i]]
        a, b = tw.start[i].astype(float), tw.end[i].astype(float)
        d = (b - a) / np.linalg.norm(b - a)
        off = v - a
        radial = off - (off @ d)[:, None] * d
        r = max(0.5 * float(tw.width[i]), opts.min_radius)
        assert np.allclose(np.linalg.norm(radial, axis=1), r, rtol=1e-5)
        assert np.allclose(mesh.normals[tube[i]], radial / r, atol=1e-5)  # outward
        assert (mesh.joints[tube[i]] == tw.segment[i]).all()
        assert (mesh.weights[tube[i], 0] == 1.0).all()
    assert np.isin(tube, bark).all()  # drawn in the bark's material
    # wound outward: each tube triangle's face normal agrees with its vertex normals
    tris = bark[np.isin(bark, tube).all(1)]
    assert len(tris) == len(tw) * 2 * k
    p = mesh.positions[tris]
    face = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert ((face * mesh.normals[tris].sum(1)).sum(1) > 0).all()
    # the leafy branch (segment 2) draws its cards along its twigs, not itself
    leaf = next(p for p in mesh.parts if p.material == "leaf")
    corners = mesh.positions[np.unique(leaf.faces)].reshape(-1, 4, 3)
    stems = 0.5 * (corners[:, 0] + corners[:, 1])
    on_twig = np.zeros(len(stems), bool)
    for i in range(3):
        a, b = tw.start[i].astype(float), tw.end[i].astype(float)
        t = np.clip((stems - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        on_twig |= np.linalg.norm(stems - (a + t[:, None] * (b - a)), axis=1) < 1e-5
    segs = mesh.joints[np.unique(leaf.faces), 0].reshape(-1, 4)[:, 0]
    assert on_twig[segs == 2].all() and (segs == 2).sum() > 0
    # without leafy twigs segment 2 draws its cards along itself again
    leaf_plain = next(p for p in plain.parts if p.material == "leaf")
    corners = plain.positions[np.unique(leaf_plain.faces)].reshape(-1, 4, 3)
    stems = 0.5 * (corners[:, 0] + corners[:, 1])
    a = tree.points[tree.seg_start[2]].astype(float)
    b = tree.points[tree.seg_end[2]].astype(float)
    t = (stems - a) @ (b - a) / ((b - a) @ (b - a))
    assert np.allclose(np.linalg.norm(stems - (a + t[:, None] * (b - a)), axis=1), 0, atol=1e-5)
    # posed, a twig keeps its place on its segment: rigid with it
    f = len(twiggy.times) - 1
    posed, _ = pose(mesh, tree, f)
    s = int(tw.segment[0])
    from treebake.rotations import matrices_from_quaternions
    r = matrices_from_quaternions(tree.rotations[f, s:s + 1].astype(float))[0]
    base = tree.points[tree.seg_start[s]]
    want = tree.positions[f, s] + (mesh.positions[tube[0]] - base) @ r.T
    assert np.allclose(posed[tube[0]], want, atol=1e-5)
    assert np.abs(posed[tube[0]] - mesh.positions[tube[0]]).max() > 1e-5  # it did move (a stiff little tree: tens of µm)


def test_glb_with_twigs_validates(baked, tmp_path):
    from validator import validate
    from treebake.export import ExportOptions, export_bake

    _, twiggy, _ = baked
    rep = export_bake(twiggy, tmp_path, "tw", ExportOptions(formats=("glb",)))
    (report,) = validate([rep.folder / "tw.glb"])
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"][:5]
