"""Sub-frame keys only where a part turns fast (issue 42): the simulation
records extra samples between frames for a whole tree when any of its
parts turns fast; the glTF keeps them only on the joints that turn more
than 45 degrees in that frame interval, and the manifest counts them. The
golden sapling-box bake (a box knocks a sapling over: in each frame
interval with samples some segments turn fast, others do not) read back
with pygltflib, the turns worked out here
from the bake's own samples; the world errors the manifest reports are
measured at the frames. Self-contained: runs from any folder against any
checkout's treebake."""

import sys
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import treebake
from treebake.bake_file import load_bake
from treebake.export import ExportOptions, export_bake

ROOT = Path(treebake.__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "tools"))

from gltfread import Gltf, quat_to_matrix

BAKE = ROOT / "tests" / "golden" / "sapling-box.npz"
TURN = np.radians(45.0)
MARGIN = 1e-3  # rad: turns this close to 45 degrees may fall either way
C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Z up -> Y up


def _turns(tree, frame_times: np.ndarray) -> np.ndarray:
    """(F-1, S) rad each segment turns from one frame to the next, summed
    over the bake's samples in between (frames and extra samples)."""
    times = np.concatenate([frame_times, tree.extra_times])
    q = np.concatenate([tree.rotations, tree.extra_rotations]).astype(np.float64)
    order = np.argsort(times, kind="stable")
    times, q = times[order], q[order]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    sign = np.where((q[1:] * q[:-1]).sum(-1) < 0, -1.0, 1.0)[..., None]  # q and -q alike
    chord = np.linalg.norm(q[1:] - sign * q[:-1], axis=-1)
    step = 4 * np.arcsin(np.clip(chord / 2, 0, 1))  # the angle between neighbouring samples
    walked = np.concatenate([np.zeros((1, q.shape[1])), np.cumsum(step, axis=0)])
    at = np.searchsorted(times, frame_times)
    return walked[at[1:]] - walked[at[:-1]]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    bake = load_bake(BAKE)
    out = tmp_path_factory.mktemp("subframe")
    report = export_bake(bake, out, "box", ExportOptions(formats=("glb",)))
    return bake, report


def _channels(path: Path):
    """Every animation channel: (node, path, key times s) via pygltflib."""
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()
    out = []
    for anim in g.animations:
        for ch in anim.channels:
            acc = g.accessors[anim.samplers[ch.sampler].input]
            view = g.bufferViews[acc.bufferView]
            start = (view.byteOffset or 0) + (acc.byteOffset or 0)
            times = np.frombuffer(blob, np.float32, acc.count, start).astype(np.float64)
            out.append((ch.target.node, ch.target.path, times))
    return g, out


def test_sub_frame_keys_only_on_parts_that_turn_more_than_45_degrees(exported):
    bake, report = exported
    tree = bake.trees[0]
    fps, first = bake.fps, report.manifest["frames"]["first"]
    turns = _turns(tree, bake.times)
    # the bake has sub-frame samples, and in their frame intervals some
    # segments turn fast and others do not: the rule has something to sort
    inside = np.searchsorted(bake.times, tree.extra_times) - 1
    with_extras = np.zeros(len(bake.times) - 1, bool)
    with_extras[inside] = True
    assert len(tree.extra_times) > 0
    assert (turns[with_extras] > TURN + MARGIN).sum() > 0
    assert (turns[with_extras] < TURN - MARGIN).sum() > 0
    g, channels = _channels(report.folder / "box.glb")
    segment = {i: tree.paths.index(n.extras["segment_path"]) for i, n in enumerate(g.nodes)
               if n.extras and "segment_path" in n.extras}
    keys = chans = total = 0
    for node, _, times in channels:
        total += len(times)
        u = times * fps - first  # bake frame index, fractional between frames
        off = np.abs(u - np.round(u)) > 1e-3
        if not off.any():
            continue
        assert node in segment, g.nodes[node].name  # projectiles stay on the frame grid
        s = segment[node]
        k = np.floor(u[off]).astype(int)
        assert with_extras[k].all()  # only where the bake has samples
        worst = turns[k, s].min()
        assert worst > TURN - MARGIN, (g.nodes[node].name, np.degrees(worst))
        keys += int(off.sum())
        chans += 1
    assert keys > 0  # the fast parts keep theirs
    anim = report.manifest["animation"]
    assert anim["subframe_keys"] == keys
    assert anim["subframe_channels"] == chans
    assert anim["subframe_turn_deg"] == 45
    assert anim["keys_written"] == total
    assert anim["errors_at"] == "frames"


def test_reported_errors_are_the_frames_errors(exported):
    """The manifest's worst errors are what a viewer shows at the frames
    (within float32), and within the tolerances."""
    bake, report = exported
    tree = bake.trees[0]
    anim = report.manifest["animation"]
    reader = Gltf(report.folder / "box.glb")
    nodes = [next(i for i, n in enumerate(reader.g.nodes)
                  if n.extras and n.extras.get("segment_path") == p) for p in tree.paths]
    first = report.manifest["frames"]["first"]
    e_pos = e_ang = 0.0
    for f in range(len(bake.times)):
        w = reader.worlds(nodes, float(np.float32((first + f) / bake.fps)))
        want_p = tree.positions[f].astype(np.float64) @ C.T
        e_pos = max(e_pos, float(np.linalg.norm(w[:, :3, 3] - want_p, axis=1).max()))
        for s in range(tree.n_segments):
            r = C @ quat_to_matrix(tree.rotations[f, s]) @ C.T
            cos = (np.trace(r.T @ w[s, :3, :3]) - 1) / 2
            e_ang = max(e_ang, float(np.arccos(np.clip(cos, -1, 1))))
    tol = anim["tolerances"]
    assert e_pos <= tol["position_m"] and np.degrees(e_ang) <= tol["angle_deg"] + 0.01
    assert e_pos <= anim["max_position_error_m"] + 2e-5, (e_pos, anim["max_position_error_m"])
    assert e_ang <= anim["max_angle_error_rad"] + 2e-4, (e_ang, anim["max_angle_error_rad"])


def test_usd_sub_frame_codes_only_where_a_joint_turns_fast(exported, tmp_path):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdSkel

    bake, _ = exported
    tree = bake.trees[0]
    report = export_bake(bake, tmp_path, "box", ExportOptions(formats=("usda",)))
    stage = Usd.Stage.Open(str(report.folder / "box.usda"))
    skel = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    codes = np.array(UsdSkel.Animation(skel).GetRotationsAttr().GetTimeSamples())
    first = report.manifest["frames"]["first"]
    u = codes - first
    off = np.abs(u - np.round(u)) > 1e-6
    turns = _turns(tree, bake.times)
    assert off.any()
    assert (turns[np.floor(u[off]).astype(int)].max(axis=1) > TURN - MARGIN).all()
    assert report.manifest["usd"]["subframe_codes"] == int(off.sum())
