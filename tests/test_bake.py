"""Bakes: byte-identical when repeated, round-trip through .npz, leave out
what the scene does not need, and the `treebake bake` command."""

from dataclasses import replace

import numpy as np
import pytest
from treebake.bake_file import load_bake, save_bake
from treebake.cli import main
from treebake.errors import InputError
from treebake.pipeline import bake_scene
from treebake.scene import load_scene, parse_scene


def short(root, preset, **overrides):
    return load_scene(root / "presets" / f"{preset}.toml", {"duration": 1.0, **overrides})


def test_repeated_bake_is_byte_identical(root, tmp_path):
    scene = short(root, "gusty")
    a = save_bake(bake_scene(scene), tmp_path / "a.npz").read_bytes()
    b = save_bake(bake_scene(scene), tmp_path / "b.npz").read_bytes()
    assert a == b
    c = save_bake(bake_scene(short(root, "gusty", seed=9)), tmp_path / "c.npz").read_bytes()
    assert c != a  # the seed reaches the gusts


def test_bake_round_trips_through_npz(root, tmp_path):
    bake = bake_scene(short(root, "boxes"))
    back = load_bake(save_bake(bake, tmp_path / "b.npz"))
    # format 2: the bundled species draw twigs (format 1 is a bake without any)
    assert back.meta["scene"] == "boxes" and back.meta["format_version"] == 2
    np.testing.assert_array_equal(back.times, bake.times)
    for a, b in zip(bake.trees, back.trees):
        assert a.paths == b.paths and a.info == b.info
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.twigs.end, b.twigs.end)
        np.testing.assert_array_equal(a.rotations, b.rotations)
    np.testing.assert_array_equal(back.objects.positions, bake.objects.positions)
    assert "wall_seconds" not in back.meta  # timings vary: not part of the file


def test_rotations_are_stored_and_the_rest_deflated_numpy_reads_both(root, tmp_path):
    """docs/formats.md: a tree's rotations are stored as they are (they
    deflate little, for 2.3 ms of CPU a tree), every other entry is
    deflated; numpy's own reader takes the file as it is."""
    import zipfile

    bake = bake_scene(short(root, "breeze"))
    path = save_bake(bake, tmp_path / "b.npz")
    kinds = {i.filename: i.compress_type for i in zipfile.ZipFile(path).infolist()}
    stored = sorted(n for n, k in kinds.items() if k == zipfile.ZIP_STORED)
    assert stored == [f"tree{i}.rotations.npy" for i in range(len(bake.trees))]
    assert all(k == zipfile.ZIP_DEFLATED for n, k in kinds.items() if n not in stored)
    with np.load(path) as npz:
        for i, tree in enumerate(bake.trees):
            np.testing.assert_array_equal(npz[f"tree{i}.rotations"], tree.rotations)
            np.testing.assert_array_equal(npz[f"tree{i}.positions"], tree.positions)


def test_rotations_are_unit_quaternions_and_positions_follow_the_chain(root):
    """On the pymunk tier, whose pivots are constraints that can open (the
    linear tier and the reference compose every pivot from its parent's, so
    there the gap is zero by construction)."""
    scene = short(root, "breeze")
    bake = bake_scene(scene, quality=replace(scene.quality, tier="pymunk"))
    tree = bake.trees[0]
    assert tree.info["solver"] == "pymunk"
    norms = np.linalg.norm(tree.rotations, axis=-1)
    assert np.abs(norms - 1).max() < 1e-5
    # every child segment starts where its parent segment ends (the rig never tears)
    from treebake.sway import segment_ends

    ends = segment_ends(tree, np.arange(tree.n_segments))
    child = np.nonzero(tree.seg_parent >= 0)[0]
    joined = tree.points[tree.seg_start[child]] == tree.points[tree.seg_end[tree.seg_parent[child]]]
    child = child[joined.all(1)]
    gap = np.linalg.norm(tree.positions[:, child] - ends[:, tree.seg_parent[child]], axis=-1)
    assert gap.max() < 1e-3


def test_calm_scene_simulates_nothing(root):
    bake = bake_scene(load_scene(root / "presets" / "calm.toml"))
    assert all(t.static and t.positions.shape[0] == 1 for t in bake.trees)
    assert all("no force reaches it" in t.info["static"] for t in bake.trees)
    assert "stats" not in bake.meta


def test_trees_out_of_the_blast_stay_static(root):
    sapling = str(root / "grammars" / "sapling.lsys")
    raw = {"duration": 1.0, "tree": [{"grammar": sapling}, {"grammar": sapling,
                                                           "position": [900.0, 0.0]}],
           "explosion": [{"position": [3.0, 0.0, 1.0], "time": 0.2, "charge": 1.0}]}
    bake = bake_scene(parse_scene(raw))
    near, far = bake.trees
    assert not near.static and far.static


def test_not_a_bake_is_a_clear_error(tmp_path):
    junk = tmp_path / "x.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a treebake bake"):
        load_bake(junk)


def test_cli_bake_writes_the_bake_and_reports(root, tmp_path, capsys):
    code = main(["bake", str(root / "grammars" / "sapling.lsys"), "--duration", "0.5",
                 "--out", str(tmp_path), "-q", "--json"])
    assert code == 0
    assert (tmp_path / "sapling" / "sapling.npz").is_file()
    assert '"trees": 1' in capsys.readouterr().out
    assert main(["bake", str(root / "presets" / "calm.toml"), "--fps", "0"]) == 2
    assert main(["bake", str(tmp_path / "missing.lsys")]) == 2


def test_cli_timestep_is_the_full_references_step(root, tmp_path, capsys):
    sapling = str(root / "grammars" / "sapling.lsys")
    assert main(["bake", sapling, "--timestep", "1/480", "-q"]) == 2  # planar: no such step
    assert "--solver full" in capsys.readouterr().err
    assert main(["bake", sapling, "--solver", "full", "--timestep", "1/0", "-q"]) == 2
    assert main(["bake", sapling, "--solver", "full", "--timestep", "0.5", "-q"]) == 2
    code = main(["bake", sapling, "--solver", "full", "--timestep", "1/480", "--duration", "0.25",
                 "--out", str(tmp_path), "-q"])
    assert code == 0
    bake = load_bake(tmp_path / "sapling" / "sapling.npz")
    # rounded so that a load interval is a whole number of steps: within 10 % of 1/480 s
    assert bake.meta["substep"] == pytest.approx(1 / 480, rel=0.1)
