"""treebake diff: identical bakes diff to exactly zero; a single perturbed
segment in one frame is found and named; topology mismatches exit 2."""

import copy

import numpy as np
import pytest
from treebake.bake_file import save_bake
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
    # frames numbered as in the exports (frame_start + index: the number a
    # TD finds in the DCC), the index and frame_start in the report itself
    start = int(bake.meta.get("frame_start", 1))
    assert r.frame_start == start == 1
    assert "DIFFERENT" in text and tree.paths[seg] in text
    assert f"worst at frame {start + frame}\n" in text + "\n"
    assert f"first frame past tolerance: {start + frame} (t = {bake.times[frame]:.3f} s)" in text
    assert f"x {len(bake.times)} frames (1-{len(bake.times)}, as in the exports)" in text
    numbered = copy.copy(bake)  # the module's bake keeps its meta
    numbered.meta = {**bake.meta, "frame_start": 101}
    later = format_report(diff_bakes(numbered, other, position_tolerance=1e-3))
    assert f"first frame past tolerance: {101 + frame} " in later


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


def test_bakes_of_other_lengths_are_named_and_told_apart_by_their_times(bake, tmp_path, capsys):
    """It said 'not the same trees: frame counts differ: 49 vs 73' for the
    same trees baked for 2 and 3 s, and named neither file."""
    shorter = copy.deepcopy(bake)
    shorter.times, shorter.trees = shorter.times[:-2], copy.deepcopy(bake.trees)
    for t in shorter.trees:
        t.positions, t.rotations = t.positions[:-2], t.rotations[:-2]
    a, b = save_bake(bake, tmp_path / "a.npz"), save_bake(shorter, tmp_path / "b.npz")
    assert main(["diff", str(a), str(b)]) == 2
    err = capsys.readouterr().err
    n = len(bake.times)
    assert f"{a} (A) and {b} (B) cannot be compared frame by frame: frame counts differ: " \
           f"{n} vs {n - 2} ({bake.times[-1]:.3f} vs {bake.times[-3]:.3f} s" in err, err
    assert "same trees" not in err


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


MADE_BEFORE = {"treebake": "0.1.0", "numpy": "2.3.0", "mujoco": "3.13.0", "pymunk": "7.3.1"}
MADE_AFTER = {**MADE_BEFORE, "numpy": "2.4.6", "mujoco": "4.0.0"}


@pytest.mark.parametrize("what", ["positions", "rotations"])
def test_a_bake_with_nan_is_refused_by_diff_and_export(bake, tmp_path, capsys, what):
    """A bake whose motion turned NaN from frame 5 on is broken: diff must
    not call it within tolerance (it did: "max nan m", exit 0) and export
    must not write a glb full of NaN; both refuse it, naming tree and frame."""
    ref, broken = tmp_path / "ref.npz", tmp_path / "nan.npz"
    save_bake(bake, ref)
    bad = copy.deepcopy(bake)
    getattr(bad.trees[0], what)[5:] = np.nan
    save_bake(bad, broken)
    assert main(["diff", str(ref), str(broken)]) == 2
    err = capsys.readouterr().err
    assert f"non-finite {what} from frame 5" in err and bake.trees[0].name in err, err
    assert main(["export", str(broken), "--format", "glb", "--out", str(tmp_path)]) == 2
    assert f"non-finite {what} from frame 5" in capsys.readouterr().err
    assert not list(tmp_path.rglob("*.glb"))


def test_version_differences_name_each_change_and_unknown_sides():
    from treebake.versions import runtime_versions, version_differences

    assert version_differences(MADE_BEFORE, MADE_AFTER) == ["numpy 2.3.0 -> 2.4.6",
                                                            "mujoco 3.13.0 -> 4.0.0"]
    assert version_differences(MADE_AFTER, MADE_AFTER) == []
    assert version_differences({}, {}) == [] and version_differences(None, {}) == []
    assert version_differences({}, {"mujoco": "4.0.0"}) == ["mujoco unknown -> 4.0.0"]
    assert version_differences({"numba": "0.60"}, {}) == ["numba 0.60 -> unknown"]
    here = runtime_versions()
    assert list(here) == ["treebake", "numpy", "mujoco", "pymunk"]
    assert all(isinstance(v, str) and v for v in here.values())
    assert here["numpy"] == np.__version__ and here is not runtime_versions()


def _versioned(bake, versions, push=0.0):
    """A copy of the bake that records `versions` (None: none, as bakes made
    before versions were recorded), one segment pushed `push` m in one frame."""
    other = copy.deepcopy(bake)
    other.meta.pop("versions", None)
    if versions is not None:
        other.meta["versions"] = dict(versions)
    other.trees[0].positions[3, 2] += np.float32(push)
    return other


def test_diff_names_the_versions_that_differ_when_the_motion_does(bake, tmp_path, capsys):
    import json

    a = save_bake(_versioned(bake, MADE_BEFORE), tmp_path / "a.npz")
    b = save_bake(_versioned(bake, MADE_AFTER, push=0.5), tmp_path / "b.npz")
    capsys.readouterr()
    assert main(["diff", str(a), str(b)]) == 1
    text = capsys.readouterr().out
    assert text.endswith(f"  made with other versions ({a} -> {b}):\n"
                         "    numpy 2.3.0 -> 2.4.6\n    mujoco 3.13.0 -> 4.0.0\n")
    assert main(["diff", str(a), str(b), "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert report["version_differences"] == ["numpy 2.3.0 -> 2.4.6", "mujoco 3.13.0 -> 4.0.0"]
    # a bake from before versions were recorded: its side is unknown
    old = save_bake(_versioned(bake, None), tmp_path / "old.npz")
    assert main(["diff", str(old), str(b)]) == 1
    assert "    mujoco unknown -> 4.0.0\n" in capsys.readouterr().out


def test_diff_says_nothing_of_versions_when_they_agree_or_the_motion_does(bake, tmp_path,
                                                                         capsys):
    import json

    a = save_bake(_versioned(bake, MADE_AFTER), tmp_path / "a.npz")
    moved = save_bake(_versioned(bake, MADE_AFTER, push=0.5), tmp_path / "moved.npz")
    capsys.readouterr()
    assert main(["diff", str(a), str(moved)]) == 1  # same versions: nothing extra
    assert "version" not in capsys.readouterr().out
    assert main(["diff", str(a), str(moved), "--json"]) == 1
    assert "version_differences" not in json.loads(capsys.readouterr().out)
    same = save_bake(_versioned(bake, MADE_BEFORE), tmp_path / "same.npz")
    assert main(["diff", str(a), str(same)]) == 0  # versions differ, motion does not
    assert "version" not in capsys.readouterr().out
    assert main(["diff", str(a), str(same), "--json"]) == 0
    assert "version_differences" not in json.loads(capsys.readouterr().out)
    neither = _versioned(bake, None, push=0.5)  # two bakes without versions agree
    assert diff_bakes(_versioned(bake, None), neither).version_differences == []


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


# ---------------------------------------------------------------------------
# a glb against its own bake, and damaged inputs


@pytest.fixture(scope="module")
def sapling_export(root, tmp_path_factory):
    """A short sapling bake and its glb (reduced, default tolerances) and an
    unreduced glb, each in its own export folder with its manifest."""
    from treebake.exchange.anim import ReduceOptions
    from treebake.export import ExportOptions, export_bake

    tmp = tmp_path_factory.mktemp("sapling")
    bake = bake_scene(load_scene(root / "presets" / "breeze.toml", {"duration": 1.0}))
    npz = save_bake(bake, tmp / "b" / "b.npz")
    glb = export_bake(bake, tmp, "b", bake_path=npz).folder / "b.glb"
    full = export_bake(bake, tmp, "full", ExportOptions(reduce=ReduceOptions(enabled=False)),
                       bake_path=npz).folder / "full.glb"
    return bake, npz, glb, full


def test_a_glb_and_its_own_bake_are_the_same_within_the_declared_reduction(sapling_export,
                                                                            capsys):
    from treebake.diff import load_any

    bake, npz, glb, full = sapling_export
    # unreduced: every joint and every tip (terminal segments too) is the bake's own, to
    # float32 round-off of composing local transforms; the old reader put tips at bases
    exact = diff_bakes(load_any(full), bake)
    assert exact.max_position < 2e-5 and exact.max_angle < 1e-2 and exact.allowance_note == ""
    assert main(["diff", str(glb), str(npz)]) == 0
    text = capsys.readouterr().out
    assert "within tolerance" in text and "keyframe reduction declared by b.glb" in text
    r = diff_bakes(load_any(glb), bake)
    assert r.position_allowance == 0.002 and r.angle_allowance == pytest.approx(0.25)
    assert r.max_position <= 0.002 + 2e-5  # the reduction keeps its promise
    # and the allowance does not hide a real change: 5 mm at one tip
    other = copy.deepcopy(bake)
    t = other.trees[0]
    tip = int(np.nonzero(~np.isin(np.arange(t.n_segments), t.seg_parent))[0][-1])
    t.positions[5:, tip] += np.float32([0.0, 0.0, 0.005])
    moved = diff_bakes(load_any(glb), other)
    assert not moved.within and moved.worst[0].segment == tip


def test_a_glb_at_another_frame_start_with_tool_safe_names_diffs_like_its_bake(
        sapling_export, tmp_path):
    """Both branches' glTF additions together: keys at (frame_start + f) / fps,
    joints named <tree>_<path>_s<k> with the path in extras.segment_path, and
    terminal joints' tips in extras.tip; the reader undoes all three."""
    from treebake.diff import load_any
    from treebake.exchange.anim import ReduceOptions
    from treebake.exchange.gltf_read import _load
    from treebake.export import ExportOptions, export_bake

    bake, npz, glb, full = sapling_export
    late = export_bake(bake, tmp_path, "late",
                       ExportOptions(reduce=ReduceOptions(enabled=False), frame_start=1001),
                       bake_path=npz).folder / "late.glb"
    doc, _ = _load(late)
    info = doc["asset"]["extras"]["treebake"]
    assert info["frame_start"] == 1001 and info["reduction"] == {"position_m": 0.0,
                                                                "angle_deg": 0.0}
    tree = bake.trees[0]
    joints = doc["skins"][0]["joints"]
    extras = [doc["nodes"][j]["extras"] for j in joints]
    assert [e["segment_path"] for e in extras] == list(tree.paths)
    assert all(":" not in doc["nodes"][j]["name"] for j in joints)
    terminal = ~np.isin(np.arange(tree.n_segments), tree.seg_parent)
    assert [("tip" in e) for e in extras] == terminal.tolist()
    back = load_any(late)
    assert back.trees[0].paths == list(tree.paths) and "tipless" not in back.trees[0].info
    exact = diff_bakes(back, bake)
    assert exact.max_position < 2e-5 and exact.max_angle < 1e-2 and exact.allowance_note == ""
    assert diff_bakes(back, load_any(full)).max_position < 2e-5


def _rotation_keys_offset(glb: bytes) -> int:
    """Byte offset in the file of the w component of the middle key of the
    first rotation channel's values: w is near 1 in a breeze (small turns),
    so overwriting it leaves no unit quaternion, which the reader must
    catch (x, y and z are near 0: overwriting them with tiny floats
    leaves a near-unit quaternion no reader can tell from a true one)."""
    import json
    import struct

    length = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20:20 + length])
    anim = doc["animations"][0]
    ch = next(c for c in anim["channels"] if c["target"]["path"] == "rotation")
    acc = doc["accessors"][anim["samplers"][ch["sampler"]]["output"]]
    view = doc["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return 20 + length + 8 + start + 16 * (acc["count"] // 2) + 12  # x y z w, float32


def test_damaged_or_foreign_inputs_are_clear_errors_not_tracebacks(sapling_export, tmp_path,
                                                                   capsys):
    import shutil

    bake, npz, glb, full = sapling_export
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    text = tmp_path / "notes.npz"
    text.write_text("hello")
    cut = tmp_path / "cut.glb"  # truncated, no manifest beside it: the lengths tell
    cut.write_bytes(glb.read_bytes()[:1000])
    alone = tmp_path / "alone"  # overwritten, without a manifest beside it
    alone.mkdir()
    data = bytearray(glb.read_bytes())
    at = _rotation_keys_offset(bytes(data))  # in the motion: no sha256 to tell, the data must
    data[at:at + 10] = b"\xab" * 10
    (alone / "b.glb").write_bytes(bytes(data))
    edited = tmp_path / "edited"  # overwritten where a manifest records its sha256
    shutil.copytree(glb.parent, edited)
    data = bytearray(glb.read_bytes())
    data[-2000:-1990] = bytes(10)
    (edited / "b.glb").write_bytes(bytes(data))
    cases = {empty: "empty (0 bytes)", text: "not a treebake bake",
             cut: "truncated", alone / "b.glb": "damaged data",
             edited / "b.glb": "does not match the size and sha256"}
    for path, message in cases.items():
        capsys.readouterr()
        assert main(["diff", str(path), str(npz)]) == 2, path
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err and "allow_pickle" not in err, err


def test_a_closed_pipe_is_not_a_traceback(sapling_export):
    import subprocess
    import sys

    bake, npz, glb, full = sapling_export
    proc = subprocess.Popen([sys.executable, "-m", "treebake.cli", "diff", str(npz), str(glb)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # like `| head` that has already left
    err = proc.stderr.read().decode()
    proc.wait(timeout=60)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert proc.returncode == 141


def _shot(bake, copies: int, push_every: int = 0):
    """`bake`'s trees repeated `copies` times under new names; with
    `push_every`, every so many trees' segment k moved by k x 0.1 mm in
    frame k (distinct errors across trees)."""
    trees = []
    for c in range(copies):
        for t in bake.trees:
            u = copy.deepcopy(t)
            u.name = f"{t.name}_{c}"
            k = (c * 7) % u.n_segments
            if push_every and c % push_every == 0 and not u.static:
                u.positions[k % len(bake.times), k] += np.float32([1e-4 * (k + 1), 0.0, 0.0])
            trees.append(u)
    return type(bake)(bake.times, trees, dict(bake.meta, trees=len(trees)), bake.objects)


def test_a_streamed_diff_equals_the_whole_shot_compared_at_once(bake, tmp_path):
    """The diff reads one tree at a time; its figures are those of the whole
    shot's error arrays computed at once here (max, RMS over every frame
    and segment, the first frame past the tolerance, the worst segments in
    order), on files read lazily as `treebake diff` reads them."""
    from treebake.diff import _tree_errors, load_any

    a, b = _shot(bake, 6), _shot(bake, 6, push_every=2)
    save_bake(a, tmp_path / "a.npz")
    save_bake(b, tmp_path / "b.npz")
    r = diff_bakes(load_any(tmp_path / "a.npz"), load_any(tmp_path / "b.npz"),
                   position_tolerance=2e-4, worst=4)
    pos, ang = zip(*(_tree_errors(ta, tb, len(a.times)) for ta, tb in zip(a.trees, b.trees)))
    pos, ang = np.concatenate(pos, axis=1), np.concatenate(ang, axis=1)
    assert r.max_position == pytest.approx(pos.max(), rel=1e-12)
    assert r.rms_position == pytest.approx(np.sqrt(np.mean(pos**2)), rel=1e-9)
    assert r.max_angle == pytest.approx(ang.max(), rel=1e-12)
    assert r.segments == pos.shape[1]
    over = np.nonzero(((pos > 2e-4) | (ang > 0.1)).any(axis=1))[0]
    assert r.first_frame == over[0]
    score = np.maximum(pos.max(axis=0) / 2e-4, ang.max(axis=0) / 0.1)
    names = [(t.name, s) for t in a.trees for s in range(t.n_segments)]
    expect = [names[i] for i in np.argsort(-score, kind="stable")[:4] if score[i] > 0]
    assert [(w.tree, w.segment) for w in r.worst] == expect and len(expect) == 4
    assert set(r.curves) == {f"{w.tree} {w.path}" for w in r.worst}


def test_diff_memory_follows_the_tree_not_the_shot(bake, tmp_path):
    """Diffing two bakes of 4x the trees needs about the same memory as of
    1x (tracemalloc's peak, numpy's arrays included), not 4x."""
    import tracemalloc

    from treebake.diff import load_any

    peaks = []
    for copies in (3, 12):
        a, b = _shot(bake, copies), _shot(bake, copies, push_every=1)
        save_bake(a, tmp_path / f"a{copies}.npz")
        save_bake(b, tmp_path / f"b{copies}.npz")
        del a, b
        tracemalloc.start()
        diff_bakes(load_any(tmp_path / f"a{copies}.npz"), load_any(tmp_path / f"b{copies}.npz"))
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < 1.5 * peaks[0], peaks


def test_plot_without_matplotlib_is_refused_before_comparing(bake, tmp_path, monkeypatch, capsys):
    """--plot without the extra: the error before the two bakes are read and
    compared (it came after the whole comparison), naming the extra."""
    import sys

    import treebake.diff as diff

    a = save_bake(bake, tmp_path / "a.npz")
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if not installed
    monkeypatch.setattr(diff, "diff_bakes", lambda *a, **k: pytest.fail("compared first"))
    assert main(["diff", str(a), str(a), "--plot", str(tmp_path / "d.png")]) == 2
    assert "--plot needs matplotlib: pip install 'treebake[plots]'" in capsys.readouterr().err
    assert not (tmp_path / "d.png").exists()
