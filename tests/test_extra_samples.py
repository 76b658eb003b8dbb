"""Sampling that follows fast motion (issue 15): a tree's extra sub-frame
samples (extra_times / extra_positions / extra_rotations) are saved and
loaded byte-reproducibly, merged into the glTF and USD keys (the reduction
keeps the ones interpolation cannot rebuild), left out of OBJ sequences
and `diff`. Synthetic bakes: a segment whose 170 degree turn between two
frames is not uniform, and a 190 degree turn that slerp between the frames
alone would take the wrong way round."""

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from conftest import need
from gltfread import Gltf, quat_to_matrix
from treebake.bake import Bake, TreeBake
from treebake.bake_file import load_bake, save_bake
from treebake.diff import diff_bakes
from treebake.errors import InputError
from treebake.export import ExportOptions, export_bake

FPS = 24.0
C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # Z up -> Y up


def _quat(axis, degrees):
    a = np.radians(degrees) / 2
    return np.array([*(np.sin(a) * np.asarray(axis, float)), np.cos(a)])


def _qmul(a, b):
    x1, y1, z1, w1 = a
    x2, y2, z2, w2 = b
    return np.array([w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2])


def _top_rotation(t: float) -> np.ndarray:
    """The top segment's rotation at time t (s): still until frame 2, then
    170 degrees about X in one frame, easing in (angle ~ s^2, so the
    sub-frame poses are not slerp's), then 190 degrees about Y in the next
    frame (slerp from frame to frame would turn -170 degrees instead)."""
    s = t * FPS
    a = 170.0 * np.clip(s - 2, 0, 1) ** 2
    b = 190.0 * np.clip(s - 3, 0, 1)
    return _qmul(_quat([0, 1, 0], b), _quat([1, 0, 0], a))


def spinning_bake(extras: bool = True) -> Bake:
    """Three vertical 1 m segments; the top one spins (see _top_rotation)."""
    F = 6
    times = np.arange(F) / FPS
    extra = np.array([2.25, 2.5, 2.75, 3 + 1 / 3, 3 + 2 / 3]) / FPS if extras else np.zeros(0)

    def motion(ts):
        pos = np.zeros((len(ts), 3, 3), np.float32)
        pos[:, :, 2] = [0.0, 1.0, 2.0]
        rot = np.zeros((len(ts), 3, 4), np.float32)
        rot[..., 3] = 1.0
        rot[:, 2] = np.reshape([_top_rotation(t) for t in ts], (-1, 4))
        return pos, rot

    pos, rot = motion(times)
    epos, erot = motion(extra)
    tree = TreeBake(
        name="spinner", points=np.array([[0.0, 0, z] for z in range(4)]),
        seg_start=np.arange(3), seg_end=np.arange(1, 4), seg_parent=np.array([-1, 0, 1]),
        seg_limb=np.zeros(3, np.int64), width=np.full(3, 0.1), leaf=np.zeros(3, np.int64),
        leaf_size=np.zeros(3), limb_parent=np.array([-1]), limb_attach=np.array([-1]),
        limb_points=[np.arange(4)], paths=["trunk:0", "trunk:1", "trunk:2"],
        positions=pos, rotations=rot, info={}, extra_times=extra, extra_positions=epos,
        extra_rotations=erot)
    return Bake(times, [tree], {"scene": "spin", "fps": FPS, "frame_start": 1})


def _angle(q_matrix, want_quat) -> float:
    r = C @ quat_to_matrix(want_quat) @ C.T
    d = np.linalg.norm(r - q_matrix) / (2 * np.sqrt(2))
    return float(np.degrees(2 * np.arcsin(min(d, 1.0))))


def test_saved_and_loaded_byte_reproducibly_old_bakes_still_load(tmp_path):
    bake = spinning_bake()
    a = save_bake(bake, tmp_path / "a.npz").read_bytes()
    back = load_bake(tmp_path / "a.npz")
    t = back.trees[0]
    np.testing.assert_array_equal(t.extra_times, bake.trees[0].extra_times)
    np.testing.assert_array_equal(t.extra_rotations, bake.trees[0].extra_rotations)
    assert t.extra_positions.dtype == np.float32 and t.extra_positions.shape == (5, 3, 3)
    assert save_bake(back, tmp_path / "b.npz").read_bytes() == a
    old = load_bake(Path(__file__).resolve().parent / "golden" / "palm-gale.npz")
    assert old.trees[0].extra_times.shape == (0,)
    assert old.trees[0].extra_rotations.shape == (0, old.trees[0].n_segments, 4)
    bad = spinning_bake()
    bad.trees[0].extra_times = bad.trees[0].extra_times[::-1].copy()
    with pytest.raises(InputError, match="extra_times must be sorted"):
        save_bake(bad, tmp_path / "c.npz")
    # a saved bake whose extra samples were overwritten is a damaged file, not a bake
    with np.load(tmp_path / "a.npz") as z:
        arrays = dict(z)
    arrays["tree0.extra_times"] = arrays["tree0.extra_times"][::-1].copy()
    np.savez(tmp_path / "d.npz", **arrays)
    with pytest.raises(InputError, match="damaged or truncated.*extra_times must be sorted"):
        load_bake(tmp_path / "d.npz")


def test_gltf_keys_follow_the_sub_frame_motion(tmp_path):
    bake = spinning_bake()
    export_bake(bake, tmp_path, "spin", ExportOptions(formats=("glb", "obj")))
    g = Gltf(tmp_path / "spin" / "spin.glb")
    node = g.node_index("spinner_trunk_s2")
    keys = g.channels[(node, "rotation")][0].astype(np.float64)
    extra = bake.trees[0].extra_times
    kept = [t for t in extra if np.isclose(keys, t + 1 / FPS, atol=1e-6).any()]
    assert len(kept) >= 4  # the sub-frame samples slerp cannot rebuild are keys
    worst = 0.0
    for t in [*bake.times, *extra]:  # every sample, as a viewer interpolates the file
        w = g.world(node, float(np.float32(t + 1 / FPS)))
        worst = max(worst, _angle(w[:3, :3], _top_rotation(t)))
    assert worst < 0.3, worst  # the reduction's 0.25 degrees
    # without the extra samples, the file misses the true motion by far
    plain = spinning_bake(extras=False)
    export_bake(plain, tmp_path, "plain", ExportOptions(formats=("glb",)))
    g0 = Gltf(tmp_path / "plain" / "plain.glb")
    n0 = g0.node_index("spinner_trunk_s2")
    miss = max(_angle(g0.world(n0, float(np.float32(t + 1 / FPS)))[:3, :3], _top_rotation(t))
               for t in extra)
    assert miss > 60, miss
    # OBJ: one file per frame, no sub-frame files
    assert len(list((tmp_path / "spin" / "obj").glob("*.obj"))) == len(bake.times)


def test_usd_samples_the_sub_frames_at_fractional_time_codes(tmp_path):
    need("pxr")
    from pxr import Usd, UsdSkel

    bake = spinning_bake()
    export_bake(bake, tmp_path, "spin", ExportOptions(formats=("usda",)))
    stage = Usd.Stage.Open(str(tmp_path / "spin" / "spin.usda"))
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/spin/spinner/Skel/Anim"))
    codes = anim.GetRotationsAttr().GetTimeSamples()
    want = sorted([1.0 + f for f in range(6)] + [1 + t * FPS for t in bake.trees[0].extra_times])
    np.testing.assert_allclose(codes, want, atol=1e-9)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, 6.0)
    for code in codes:
        q = anim.GetRotationsAttr().Get(code)[2]  # local = world: the parents do not turn
        got = np.array([*q.GetImaginary(), q.GetReal()])
        mat = quat_to_matrix(got)
        assert _angle(mat, _top_rotation((code - 1) / FPS)) < 1e-3


def test_diff_compares_frames_only():
    with_extras, without = spinning_bake(), spinning_bake(extras=False)
    report = diff_bakes(with_extras, without)
    assert report.max_angle == 0 and report.frames == 6
    moved = spinning_bake()
    moved.trees[0] = replace(moved.trees[0], extra_rotations=np.roll(
        moved.trees[0].extra_rotations, 1, axis=0))
    assert diff_bakes(with_extras, moved).max_angle == 0
