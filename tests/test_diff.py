"""treebake diff: identical bakes diff to exactly zero; a single perturbed
segment in one frame is found and named; topology mismatches exit 2."""

import copy

import numpy as np
import pytest

from treebake.bake import save_bake
from treebake.cli import main
from treebake.diff import TopologyError, diff_bakes, format_report
from treebake.pipeline import bake_scene
from treebake.scene import load_scene


@pytest.fixture(scope="module")
def bake(root):
    return bake_scene(load_scene(root / "presets" / "breeze.toml", {"duration": 1.0}))


def test_identical_bakes_diff_to_exactly_zero(bake):
    r = diff_bakes(bake, copy.deepcopy(bake))
    assert r.max_position == 0.0 and r.max_angle == 0.0 and r.rms_position == 0.0
    assert r.within and r.noise and r.first_frame is None
    assert "identical" in format_report(r)


def test_a_single_perturbed_segment_in_one_frame_is_found(bake):
    other = copy.deepcopy(bake)
    tree = other.trees[1]
    seg, frame = 17, 9
    tree.positions[frame, seg] += np.float32([0.0, 0.004, 0.0])  # 4 mm sideways
    r = diff_bakes(bake, other, position_tolerance=1e-3)
    assert not r.within and not r.noise
    assert r.first_frame == frame and r.first_time == pytest.approx(bake.times[frame])
    top = r.worst[0]
    assert (top.tree, top.segment, top.frame) == (tree.name, seg, frame)
    assert top.path == tree.paths[seg] and ":" in top.path
    assert top.max_position == pytest.approx(0.004, rel=1e-3)
    assert len([w for w in r.worst if w.max_position > 1e-9]) == 1  # nothing else moved
    text = format_report(r)
    assert "DIFFERENT" in text and tree.paths[seg] in text and f"frame {frame}" in text


def test_rotation_changes_are_measured_in_degrees(bake):
    other = copy.deepcopy(bake)
    q = other.trees[0].rotations
    half = np.radians(0.5) / 2  # a 0.5 degree turn about z, applied to one segment
    turn = np.array([0.0, 0.0, np.sin(half), np.cos(half)])
    x, y, z, w = q[5, 3].astype(float)
    tx, ty, tz, tw = turn
    q[5, 3] = [tw * x + tx * w + ty * z - tz * y, tw * y - tx * z + ty * w + tz * x,
               tw * z + tx * y - ty * x + tz * w, tw * w - tx * x - ty * y - tz * z]
    r = diff_bakes(bake, other, position_tolerance=10.0, angle_tolerance=0.1)
    assert r.max_angle == pytest.approx(0.5, abs=1e-3)
    assert r.worst[0].segment == 3 and r.first_frame == 5


def test_float32_round_off_is_reported_as_noise(bake):
    other = copy.deepcopy(bake)
    for t in other.trees:
        t.positions = np.nextafter(t.positions, np.float32(np.inf))
    r = diff_bakes(bake, other)
    assert r.noise and r.within and r.max_position > 0


def test_topology_mismatch_says_what_differs(bake, root):
    other = bake_scene(load_scene(root / "presets" / "gusty.toml", {"duration": 1.0}))
    with pytest.raises(TopologyError, match="segments|trees differ"):
        diff_bakes(bake, other)
    shorter = copy.deepcopy(bake)
    shorter.times = shorter.times[:-1]
    with pytest.raises(TopologyError, match="frame counts differ"):
        diff_bakes(bake, shorter)


def test_cli_exit_codes_json_and_plot(bake, root, tmp_path, capsys):
    a = save_bake(bake, tmp_path / "a.npz")
    assert main(["diff", str(a), str(a)]) == 0
    other = copy.deepcopy(bake)
    other.trees[0].positions[3, 2] += np.float32(0.5)
    b = save_bake(other, tmp_path / "b.npz")
    capsys.readouterr()
    assert main(["diff", str(a), str(b), "--json", "--plot", str(tmp_path / "d.png")]) == 1
    import json

    report = json.loads(capsys.readouterr().out)
    assert report["first_frame"] == 3 and report["worst"][0]["segment"] == 2
    assert (tmp_path / "d.png").stat().st_size > 1000
    g = bake_scene(load_scene(root / "presets" / "gusty.toml", {"duration": 1.0}))
    c = save_bake(g, tmp_path / "c.npz")
    assert main(["diff", str(a), str(c)]) == 2


def test_gltf_files_diff_like_their_bakes(bake, tmp_path):
    """Exported glb files read back (our reader samples the channels) and
    compare: the same bake twice is identical; a 5 cm push of one segment
    in one frame shows up there, by name, above the 2 mm export tolerance."""
    from treebake.diff import load_any
    from treebake.export import export_bake

    a = export_bake(bake, tmp_path, "a").folder / "a.glb"
    b = export_bake(copy.deepcopy(bake), tmp_path, "b").folder / "b.glb"
    same = diff_bakes(load_any(a), load_any(b))
    assert same.max_position == 0 and same.max_angle == 0
    other = copy.deepcopy(bake)
    seg, frame = 40, 12
    other.trees[0].positions[frame, seg] += np.float32([0.05, 0.0, 0.0])
    c = export_bake(other, tmp_path, "c").folder / "c.glb"
    r = diff_bakes(load_any(a), load_any(c), position_tolerance=0.01)
    assert not r.within and r.worst[0].segment == seg and r.worst[0].frame == frame
    assert r.worst[0].path == bake.trees[0].paths[seg]
    # and the read-back motion is the bake's own, within the export tolerance
    back = load_any(a).trees[0]
    ref = bake.trees[0]
    assert back.paths == ref.paths
    assert np.abs(back.positions - ref.positions).max() < 2.5e-3
