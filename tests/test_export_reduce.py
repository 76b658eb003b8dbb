"""Keyframe reduction on synthetic channels: every dropped frame is
reproduced within the tolerance (checked by plain interpolation here),
smooth motion keeps few keys, noise keeps them all, quaternion keys stay
in one hemisphere."""

import numpy as np
from treebake.exchange.anim import ReduceOptions, animate, continuous, reduce_keys


def _lerp_rebuild(values, keep):
    frames = np.arange(values.shape[0])
    kept = np.flatnonzero(keep)
    return np.stack([np.interp(frames, kept, values[kept, d]) for d in range(values.shape[1])], 1)


def test_reduced_translation_channels_stay_within_tolerance():
    t = np.linspace(0, 2 * np.pi, 200)
    rng = np.random.default_rng(1)
    smooth = np.stack([np.sin(t), np.cos(0.5 * t), 0.1 * t], 1)
    noisy = smooth + rng.normal(0, 0.01, smooth.shape)
    values = np.stack([smooth, noisy])
    tol = np.array([5e-3, 5e-3])
    keep = reduce_keys(values, tol, rotation=False)
    for c in range(2):
        assert keep[c, 0] and keep[c, -1]
        err = np.linalg.norm(_lerp_rebuild(values[c], keep[c]) - values[c], axis=1)
        assert err.max() <= tol[c]
    assert keep[0].sum() < 60 and keep[1].sum() > 150


def test_rotation_keys_are_continuous_and_constant_channels_dropped():
    frames = 50
    angle = np.linspace(0, 3 * np.pi, frames)  # 1.5 turns: crosses the hemisphere
    q = np.stack([np.zeros(frames), np.zeros(frames), np.sin(angle / 2), np.cos(angle / 2)], 1)
    q[1::2] *= -1  # a sign flip on every other frame, as a solver may give
    pos = np.zeros((frames, 2, 3))
    pos[:, 1] = np.stack([-np.sin(angle), np.cos(angle), np.zeros(frames)], 1)  # R0 (0, 1, 0)
    rot = np.stack([q, q], axis=1)  # joint 1 rides on joint 0: no local motion
    anim = animate(np.array([-1, 0]), pos, rot, np.array([[0.0, 1, 0], [0, 1, 0]]),
                   np.array([2.0, 1.0]), ReduceOptions())
    assert [(c.joint, c.path) for c in anim.channels] == [(0, "rotation")]
    v = anim.channels[0].values.astype(np.float64)
    assert ((v[1:] * v[:-1]).sum(1) >= 0).all()
    assert anim.report["max_angle_error_rad"] <= ReduceOptions().angle_tolerance
    assert (continuous(q) * q).sum(1).min() < 0  # the input really had flips


def test_samples_are_gathered_as_take_along_axis_gathers_them():
    """The reduction reads each channel's kept keys by index: the same
    values as numpy's take_along_axis, on a strided view too (the world
    error interpolates channels swapped out of (F, C, D))."""
    from treebake.exchange.anim import _at_samples

    rng = np.random.default_rng(3)
    values = rng.normal(size=(7, 11, 4))
    for v in (values, np.swapaxes(rng.normal(size=(11, 7, 3)), 0, 1)):
        prev = np.sort(rng.integers(0, v.shape[1], size=(7, 11)), axis=1)
        inner = rng.integers(0, v.shape[1], size=(7, 9))
        got = _at_samples(v, prev, inner)
        for idx, g in zip((prev, inner), got, strict=True):
            assert g.tobytes() == np.take_along_axis(v, idx[..., None], axis=1).tobytes()


def _forest_motion(trees: int, frames: int, seed: int = 5):
    """World motion of `trees` small random trees (chains with side
    branches) swaying smoothly: parent, pos, rot, seg_vec, reach, group."""
    from treebake.exchange.anim import depth_order, forward, subtree_reach

    rng = np.random.default_rng(seed)
    parents, group, n = [], [], 0
    for g in range(trees):
        size = int(rng.integers(3, 40))
        p = np.array([-1] + [int(rng.integers(0, k)) for k in range(1, size)])
        parents.append(np.where(p >= 0, p + n, -1))
        group.append(np.full(size, g))
        n += size
    parent, group = np.concatenate(parents), np.concatenate(group)
    seg_vec = rng.normal(0, 0.3, (n, 3)) + [0, 1, 0]
    t_loc = np.where(parent[:, None] >= 0, seg_vec[np.maximum(parent, 0)], rng.normal(0, 5, (n, 3)))
    t = np.linspace(0, 4, frames)[:, None, None]
    axis = rng.normal(size=(1, n, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = 0.2 * np.sin(rng.uniform(1, 6, (1, n, 1)) * t + rng.uniform(0, 6, (1, n, 1)))
    angle = angle + rng.normal(0, 1e-3, angle.shape)  # some joints too noisy to reduce much
    q_loc = np.concatenate([axis * np.sin(angle / 2), np.cos(angle / 2)], axis=-1)
    pos, rot = forward(parent, depth_order(parent), np.broadcast_to(t_loc, (frames, n, 3)),
                       q_loc)
    reach = subtree_reach(parent, pos[0], pos[0] + seg_vec)
    return parent, pos, rot, seg_vec, reach, group


def test_a_forest_animated_in_pieces_is_the_forest_animated_at_once(monkeypatch):
    """animate() cuts a forest into pieces of whole trees: every channel
    (joint, frames, values), the rest pose, the report and each tree's
    errors are those of the forest animated at once."""
    import treebake.exchange.anim as anim

    args = _forest_motion(trees=40, frames=60)
    monkeypatch.setattr(anim, "PIECE_JOINTS", 10**9)
    whole = anim.animate(*args[:5], ReduceOptions(), args[5])
    monkeypatch.setattr(anim, "PIECE_JOINTS", 30)
    assert len(anim._pieces(args[0], args[5])) > 10
    cut = anim.animate(*args[:5], ReduceOptions(), args[5])
    assert cut.report == whole.report and whole.report["trees_reduced"] == 40
    assert whole.report["keys_written"] < whole.report["keys_full"] / 2  # reduced, not all kept
    assert [(c.joint, c.path) for c in cut.channels] == [(c.joint, c.path) for c in whole.channels]
    for a, b in zip(cut.channels, whole.channels):
        assert np.array_equal(a.frames, b.frames) and np.array_equal(a.values, b.values)
    assert np.array_equal(cut.translation, whole.translation)
    assert np.array_equal(cut.rotation, whole.rotation)
    for a, b in zip(cut.group_errors, whole.group_errors):
        assert np.array_equal(a, b)


def test_a_channel_with_one_key_holds_what_the_interpolation_rule_gives():
    """_interpolate takes a one-key channel's value without interpolating:
    bit for bit what the rule (lerp, slerp) gives for it, beside channels
    that do interpolate."""
    from treebake.exchange.anim import _interpolate, _interpolate_spans

    rng = np.random.default_rng(2)
    q = rng.normal(size=(6, 9, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q = q.astype(np.float32).astype(np.float64)  # as the file stores them: not quite unit
    keep = np.zeros((6, 9), bool)
    keep[:, 0] = True
    keep[3:, [4, 8]] = True
    v = rng.normal(size=(6, 9, 3))
    v[0, 0, 1] = -0.0
    for values, rotation in ((q, True), (v, False)):
        got = _interpolate(values, keep, rotation)
        want = _interpolate_spans(values, keep, rotation)
        assert got.tobytes() == want.tobytes()


def test_written_rotation_keys_stay_continuous_across_dropped_samples():
    """A joint that turns 170 degrees between kept keys (a sub-frame sample
    between them dropped) has keys whose quaternions would change
    hemisphere: the written keys are flipped back to a non-negative dot,
    each still the same rotation; a joint with no such jump is written as
    it is."""
    from treebake.exchange.anim import _channels

    turn = np.radians([0.0, 170.0, 340.0])
    spin = np.stack([np.zeros(3), np.zeros(3), np.sin(turn / 2), np.cos(turn / 2)], 1)
    still = np.tile([0.0, 0.6, 0.0, 0.8], (3, 1))
    q_loc = np.stack([spin, still], axis=1)  # (F, J, 4); consecutive samples continuous
    assert ((q_loc[1:] * q_loc[:-1]).sum(-1) > 0).all()
    keep = np.array([[True, False, True], [True, True, True]])
    const = np.array([False, False])
    chans = _channels(np.zeros((3, 2, 3)), q_loc, keep, keep, ~const, const)
    assert [(c.joint, c.path) for c in chans] == [(0, "rotation"), (1, "rotation")]
    v = chans[0].values.astype(np.float64)
    assert np.array_equal(chans[0].frames, [0, 2])
    assert (v[1] * v[0]).sum() > 0
    assert np.allclose(v, spin[[0, 2]] * [[1], [-1]], atol=1e-7)
    assert np.array_equal(chans[1].values, still.astype(np.float32))
