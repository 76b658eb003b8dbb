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
from treebake.model import Twigs
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


def test_a_segments_own_leaves_stay_and_a_bare_one_takes_its_first_leafy_twigs():
    m = model("axiom: !(0.1)F(1)@leaves(1,0.2)F(1)[@twig@leaves(4,0.3)F(0.5)]"
              "@leaves(0)F(1)[@twig@leaves(2,0.4)F(0.2)][@twig@leaves(3,0.5)F(0.2)]\n")
    assert list(m.leaf) == [0, 1, 2] and np.allclose(m.leaf_size[1:], [0.2, 0.4])


def test_twig_where_the_turtle_is_on_no_segment_is_a_grammar_error():
    for text in ("axiom: @twig F(1)\n", "axiom: [F(1)F(1)][+(30)@twig F(0.5)]\n"):
        with pytest.raises(GrammarError, match="@twig where the turtle is on no segment") as e:
            model(text)
        assert str(e.value).startswith("t.lsys: @twig")  # no made-up line:column
    with pytest.raises(GrammarError, match="@twig"):
        model("axiom: @twig(2) F(1)\n")  # no parameter


def test_cli_names_the_grammar_of_a_twig_before_any_segment(tmp_path, capsys):
    bad = tmp_path / "bad.lsys"
    bad.write_text("axiom: [@twig F(1)]F(1)\n")
    assert main(["inspect", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.lsys" in err and "@twig where the turtle is on no segment" in err
    assert "Traceback" not in err


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


def test_previews_draw_the_twigs_where_their_segments_carry_them(baked):
    from treebake.preview import model_preview, posed_segments
    from treebake.rotations import matrices_from_quaternions

    _, twiggy, _ = baked
    (tree,) = twiggy.trees
    f = len(twiggy.times) - 1
    starts, ends, widths, leafy = posed_segments(twiggy, f)
    S, tw = tree.n_segments, tree.twigs
    assert len(starts) == S + len(tw)
    r = matrices_from_quaternions(tree.rotations[f].astype(float))
    for i, s in enumerate(tw.segment):
        base = tree.points[tree.seg_start[s]]
        for got, rest in ((starts[S + i], tw.start[i]), (ends[S + i], tw.end[i])):
            assert np.allclose(got, tree.positions[f, s] + r[s] @ (rest - base), atol=1e-5)
    assert np.array_equal(leafy[S:], tw.leaf > 0)
    # at rest, the preview of the tree with twigs has more bark strokes than without
    with_twigs = np.asarray(model_preview(model(TWIGGY), 256))
    without = np.asarray(model_preview(model(BARE), 256))
    assert (with_twigs != without).any()


def test_twigs_do_not_count_against_the_segment_cap(tmp_path):
    from treebake.turtle import count_segments

    g = parse_grammar(TWIGGY, "t.lsys")
    assert count_segments(derive(g).modules) == model(TWIGGY).n_segments == 5
    many = tmp_path / "many.lsys"
    many.write_text("n: 1\naxiom: !(0.05)F(1)@leaves(1)F(1)" + "[+(20)@twig!(0.005)F(0.3)]" * 200
                    + "\n")
    scene = tmp_path / "s.toml"
    scene.write_text(f'name = "s"\nduration = 0.1\n[[tree]]\ngrammar = "{many}"\n')
    assert main(["bake", str(scene), "--max-segments", "100", "--out", str(tmp_path / "o"),
                 "-q"]) == 0
    assert main(["bake", str(scene), "--max-segments", "1", "--out", str(tmp_path / "o"),
                 "-q"]) == 2  # its two segments still count


def test_diff_sees_twigs_that_changed_and_nothing_else(baked, tmp_path, capsys):
    from treebake.diff import diff_bakes, format_report

    d, twiggy, _ = baked
    longer = d / "longer" / "twiggy.lsys"  # the same tree name
    longer.parent.mkdir(exist_ok=True)
    longer.write_text(TWIGGY.replace("F(0.3)]", "F(0.8)]"))
    other = bake_scene(_scene(longer))
    same = diff_bakes(twiggy, twiggy)
    assert same.within and format_report(same).splitlines()[0].endswith("identical")
    r = diff_bakes(twiggy, other)
    assert r.max_position == 0 and not r.within  # the motion is the same; a twig is not
    assert r.twig_differences == ["twiggy: twig 1 moved 0.5 m at rest"]
    assert "DIFFERENT" in format_report(r) and "twig 1 moved 0.5 m" in format_report(r)
    fewer = d / "fewer" / "twiggy.lsys"
    fewer.parent.mkdir(exist_ok=True)
    fewer.write_text(TWIGGY.replace("[-(90)F(0.3)]", ""))
    assert diff_bakes(twiggy, bake_scene(_scene(fewer))).twig_differences == \
        ["twiggy: 4 vs 3 twigs"]
    a, b = save_bake(twiggy, tmp_path / "a.npz"), save_bake(other, tmp_path / "b.npz")
    assert main(["diff", str(a), str(b)]) == 1
    assert "twig 1 moved" in capsys.readouterr().out


def test_the_camera_sees_a_tree_by_its_twigs(tmp_path):
    """A 2 m stem with a 6 m leafy twig out along +X, the camera looking at
    the twig's far end only: the tree is seen (simulated), not culled."""
    g = tmp_path / "reach.lsys"
    g.write_text("axiom: !(0.05)F(1)@leaves(1)F(1)[-(90)@twig!(0.01)F(6)]\n")
    m = model(g.read_text())
    lo, hi = m.drawn_bounds()
    assert np.allclose(hi[0], 6.0) and np.allclose(m.bounds()[1][0], 0.0)
    scene = parse_scene({"name": "cam", "duration": 0.2, "tree": [{"grammar": str(g)}],
                         "wind": {"speed": 10.0},
                         "camera": {"fov": 10, "margin": 0, "keys": [
                             {"time": 0, "position": [6.0, -20.0, 2.0],
                              "target": [6.0, 0.0, 2.0]}]}}, file="<cam>")
    bake = bake_scene(scene)
    assert bake.meta["culling"]["unseen"] == 0 and not bake.trees[0].static


def test_a_damaged_twig_record_is_named_not_a_traceback(baked, tmp_path):
    _, twiggy, _ = baked
    (tree,) = twiggy.trees
    tw = tree.twigs
    for bad_twigs, what in ((replace(tw, segment=tw.segment.astype(float)), "not integers"),
                            (replace(tw, width=tw.width * np.nan), "non-finite"),
                            (replace(tw, leaf_size=-tw.leaf_size), "negative")):
        bad = replace(twiggy, trees=[replace(tree, twigs=bad_twigs)])
        with pytest.raises(InputError, match=what):
            load_bake(save_bake(bad, tmp_path / "bad.npz"))
    path = save_bake(twiggy, tmp_path / "partial.npz")
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    with zipfile.ZipFile(tmp_path / "cut.npz", "w") as z:
        for n, data in members.items():
            if n != "tree0.twig_segment.npy":
                z.writestr(n, data)
    with pytest.raises(InputError, match="twig arrays are missing"):
        load_bake(tmp_path / "cut.npz")


def test_bakes_with_twigs_are_format_2_and_without_format_1(baked, tmp_path):
    import json

    _, twiggy, bare = baked
    for bake, version in ((twiggy, 2), (bare, 1)):
        with zipfile.ZipFile(save_bake(bake, tmp_path / f"{version}.npz")) as z:
            meta = json.loads(np.load(z.open("meta.npy")).tobytes())
        assert meta["format_version"] == version
        assert load_bake(tmp_path / f"{version}.npz").meta["format_version"] == version


def test_materials_follow_where_the_foliage_is_drawn():
    from treebake.exchange.mesh import part_materials_of

    leaf = np.array([0, 1, 2])
    # segment 1's foliage is drawn on its twigs (leaf type 4): no "leaf" part
    assert part_materials_of(leaf, np.array([4]), np.array([1])) == ["bark", "leaf2", "leaf4"]
    assert part_materials_of(leaf, np.zeros(0, int), np.zeros(0, int)) == \
        ["bark", "leaf", "leaf2"]


def test_far_detail_draws_no_twig_tubes_but_keeps_their_foliage(baked):
    from treebake.exchange.mesh import detail_options

    _, twiggy, _ = baked
    (tree,) = twiggy.trees
    no_twigs = replace(tree, twigs=Twigs.none())
    opts = MeshOptions()
    far = tree_mesh(tree, detail_options(opts, "far"))
    bark = len(far.parts[0].faces)
    assert bark == len(tree_mesh(no_twigs, detail_options(opts, "far")).parts[0].faces)
    assert len(tree_mesh(tree, opts).parts[0].faces) > \
        len(tree_mesh(no_twigs, opts).parts[0].faces)  # default draws them
    assert [p.material for p in far.parts] == ["bark", "leaf", "leaf4"]


def test_twig_tangents_run_around_the_tube(baked):
    """glTF TANGENT of a twig's tube: unit, across the normal, along +u
    (around: the step to the next column of its ring turns the same way),
    and N x T along the twig (+v)."""
    _, twiggy, _ = baked
    (tree,) = twiggy.trees
    mesh = tree_mesh(tree, MeshOptions())
    k = twig_sides(MeshOptions().radial)
    n_tube = len(tree.twigs) * 2 * (k + 1)
    first = mesh.n_vertices - sum(len(np.unique(p.faces)) for p in mesh.parts[1:]) - n_tube
    v = np.arange(first, first + n_tube).reshape(len(tree.twigs), 2, k + 1)
    t, n = mesh.tangents[:, :3], mesh.normals
    ring = v[:, :, :k].ravel()
    assert np.allclose(np.linalg.norm(t[ring], axis=1), 1) and np.allclose((t * n)[ring].sum(1), 0)
    step = mesh.positions[ring + 1] - mesh.positions[ring]
    assert ((step * t[ring]).sum(1) > 0).all()  # +u runs the way the ring's columns go
    axis = (tree.twigs.end - tree.twigs.start).astype(float)
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    bitangent = np.cross(n[v], t[v])  # (T, 2, k + 1, 3)
    assert np.allclose(bitangent, axis[:, None, None, :], atol=1e-6)
    assert (np.diff(mesh.uvs[v][..., 1], axis=1) > 0).all()  # +v along the twig
