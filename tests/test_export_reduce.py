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
