"""Joint animation channels from a bake: local transforms, quaternion
hemisphere continuity, constant-channel removal and keyframe reduction with
a world-space error guarantee.

Joints are segments. Joint s sits at its segment's base with the world
axes as its rest orientation, so its world transform at frame f is
T(positions[f, s]) R(rotations[f, s]) and its local transform is taken
relative to its parent segment (roots: relative to the tree's root node,
the identity). Quaternions are x y z w throughout.

Reduction (Douglas-Peucker on every channel at once, vectorised): a
channel keeps its first and last frames; any span whose linear
interpolation misses a dropped frame by more than the channel's tolerance
gets its worst frame as a new key, until none does. Rotation error is the
larger of slerp's (the glTF rule) and normalised component-wise
interpolation's (what Blender does). Local tolerances start from the world
tolerances (rotation: also limited by position_tolerance / reach, the
longest lever the joint swings), then the whole tree is rebuilt by forward
kinematics, the way a viewer does, and compared with the bake; if any joint
misses position_tolerance (at its base or its segment's tip) or
angle_tolerance, the tree's local tolerances are halved and it is reduced
again (after 8 halvings: no reduction for that tree).

Sub-frame samples (a bake's extra samples between frames, merged into the
sample grid): a channel may keep one only where its joint turns fast in
that frame interval (`allowed`, bake.TreeBake.fast_samples); elsewhere the
sample is neither a key nor checked. The world errors (the halvings and
the report) are measured at the frames (`frames`), the frame-rate bake.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..rotations import (
    angle_between,
    continuous,
    dot_last,
    norm_last,
    qconj,
    qmul,
    qnormalize,
    qrotate,
    slerp,
)

# a channel that stays this close to its frame-0 value is not written even
# without reduction: float32 noise of the bake (2 ulp of the joint's distance
# from the origin, at least 1e-7 m) and of unit quaternions
CONSTANT_ULPS = 2 * 2.0**-23
CONSTANT_ANGLE = 1e-6  # rad
MAX_HALVINGS = 8
START_SCALE = 0.125  # local tolerance / world tolerance on the first try
# trees are animated in pieces of about this many joints: a piece's arrays
# (241 frames: 1.5 MB of quaternions) stay in the cache, which halves the
# CPU of a forest's channels against all trees at once (bench/scale.py)
PIECE_JOINTS = 200


@dataclass(frozen=True)
class ReduceOptions:
    """World-space tolerances: position_tolerance in m (joint bases and
    segment tips), angle_tolerance in rad (joint rotations). enabled=False
    keeps every frame of every channel that changes."""

    position_tolerance: float = 2e-3
    angle_tolerance: float = math.radians(0.25)
    enabled: bool = True


@dataclass
class Channel:
    joint: int
    path: str  # "translation" or "rotation"
    frames: np.ndarray  # (K,) kept frame indices, increasing
    values: np.ndarray  # (K, 3) or (K, 4) float32


@dataclass
class Animation:
    """Local rest transforms (frame 0) and the channels that change."""

    translation: np.ndarray  # (J, 3) float32, frame 0
    rotation: np.ndarray  # (J, 4) float32, frame 0
    channels: list[Channel] = field(default_factory=list)
    report: dict = field(default_factory=dict)
    group_errors: tuple = ()  # per tree: worst position error (m), angle error (rad)


# ---------------------------------------------------------------------------
# local transforms


def local_transforms(parent: np.ndarray, pos: np.ndarray, rot: np.ndarray):
    """World (F, J, 3) positions and (F, J, 4) rotations -> local translation
    and rotation relative to each joint's parent (parent -1: identity)."""
    pos = pos.astype(np.float64)
    rot = qnormalize(rot.astype(np.float64))
    has = parent >= 0
    par = np.where(has, parent, 0)
    q_par = np.where(has[None, :, None], rot[:, par], np.array([0.0, 0.0, 0.0, 1.0]))
    p_par = np.where(has[None, :, None], pos[:, par], 0.0)
    inv = qconj(q_par)
    return qrotate(inv, pos - p_par), qmul(inv, rot)


def depth_order(parent: np.ndarray) -> list[np.ndarray]:
    """Joints grouped by depth (roots first), for level-by-level kinematics."""
    if len(parent) and (parent >= np.arange(len(parent))).any():
        raise ValueError("segment parents must come before their children")
    depth = np.zeros(len(parent), dtype=np.int64)
    up = parent.copy()
    while (up >= 0).any():
        live = up >= 0
        depth += live
        up = np.where(live, parent[np.maximum(up, 0)], -1)
    return [np.nonzero(depth == d)[0] for d in range(int(depth.max(initial=-1)) + 1)]


def forward(parent: np.ndarray, levels: list[np.ndarray], t_loc: np.ndarray,
            q_loc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World transforms from local ones, (F, J, 3) and (F, J, 4)."""
    pos = np.empty_like(t_loc)
    rot = np.empty_like(q_loc)
    for lv in levels:
        p = parent[lv]
        root = p < 0
        if root.all():
            pos[:, lv], rot[:, lv] = t_loc[:, lv], q_loc[:, lv]
            continue
        pp = np.where(root, 0, p)
        qp = np.where(root[None, :, None], np.array([0.0, 0.0, 0.0, 1.0]), rot[:, pp])
        tp = np.where(root[None, :, None], 0.0, pos[:, pp])
        rot[:, lv] = qmul(qp, q_loc[:, lv])
        pos[:, lv] = tp + qrotate(qp, t_loc[:, lv])
    return pos, rot


# ---------------------------------------------------------------------------
# reduction


def _spans(keep: np.ndarray, times: np.ndarray | None = None):
    """For every sample: the kept keys around it and the fraction between
    (by time: `times` (F,) s, default evenly spaced)."""
    F = keep.shape[1]
    idx = np.arange(F)
    prev = np.maximum.accumulate(np.where(keep, idx, -1), axis=1)
    nxt = np.minimum.accumulate(np.where(keep, idx, F)[:, ::-1], axis=1)[:, ::-1]
    nxt = np.where(nxt >= F, prev, nxt)  # after the last key: hold it
    at = idx.astype(np.float64) if times is None else np.asarray(times, np.float64)
    span = at[nxt] - at[prev]
    t = np.where(span > 0, (at - at[prev]) / np.where(span > 0, span, 1), 0.0)
    return prev, nxt, t


def _at_samples(values: np.ndarray, *samples: np.ndarray) -> list[np.ndarray]:
    """values (C, F, D) at each channel's samples (C, F') of every index
    array: take_along_axis's values, gathered as rows of one flat array
    (several times faster)."""
    C, F = values.shape[:2]
    rows = values.reshape(C * F, -1)
    base = (np.arange(C) * F)[:, None]
    return [rows.take((base + s).ravel(), axis=0).reshape(s.shape + values.shape[2:])
            for s in samples]


def _interpolate(values: np.ndarray, keep: np.ndarray, rotation: bool,
                 times: np.ndarray | None = None) -> np.ndarray:
    """Every sample (C, F, D) rebuilt from the kept keys as glTF's LINEAR
    interpolation does it (slerp for rotations). A channel with one key
    holds it: taken without the interpolation (most channels of a tree:
    its constant translations), the same values."""
    held = keep.sum(axis=1) == 1
    if not held.any():
        return _interpolate_spans(values, keep, rotation, times)
    first = values[held, keep[held].argmax(axis=1)][:, None]
    out = np.empty_like(values)
    # what the rule gives for a span of one key: slerp(q, q, 0) is q
    # renormalised, a lerp is v + 0 (a -0.0 becomes 0.0)
    out[held] = qnormalize(first) if rotation else first + 0.0
    moving = ~held
    if moving.any():
        out[moving] = _interpolate_spans(values[moving], keep[moving], rotation, times)
    return out


def _interpolate_spans(values: np.ndarray, keep: np.ndarray, rotation: bool,
                       times: np.ndarray | None = None) -> np.ndarray:
    """_interpolate's rule on every channel: each sample from the keys around it."""
    prev, nxt, t = _spans(keep, times)
    va, vb = _at_samples(values, prev, nxt)
    if not rotation:
        return va + (vb - va) * t[..., None]
    return slerp(va, vb, t)


def _errors(values: np.ndarray, keep: np.ndarray, rotation: bool,
            times: np.ndarray | None = None, at: np.ndarray | None = None) -> np.ndarray:
    """(C, F) interpolation error at every sample; with `at` (C, F) bool,
    only at those samples (0 elsewhere). Rotations: an upper bound of both
    slerp's and component-wise (nlerp) interpolation's angle error: nlerp's
    error plus the angle between nlerp and slerp."""
    prev, nxt, t = _spans(keep, times)
    if at is None:
        va, vb = _at_samples(values, prev, nxt)
        return _span_errors(va, vb, values, t, rotation)
    rows, cols = np.nonzero(at)
    F = values.shape[1]
    flat = values.reshape(-1, values.shape[2])
    base = rows * F
    err = np.zeros(at.shape)
    err[rows, cols] = _span_errors(flat[base + prev[rows, cols]], flat[base + nxt[rows, cols]],
                                   flat[base + cols], t[rows, cols], rotation)
    return err


def _span_errors(va: np.ndarray, vb: np.ndarray, values: np.ndarray, t: np.ndarray,
                 rotation: bool) -> np.ndarray:
    """The error of interpolating `values` (..., D) at fraction t (...)
    between keys va and vb (..., D): m, or rad for rotations."""
    if not rotation:
        return norm_last(va + (vb - va) * t[..., None] - values)
    d = dot_last(va, vb)
    vb = np.where(d[..., None] < 0, -vb, vb)
    half = np.arccos(np.clip(np.abs(d), 0.0, 1.0))  # half the rotation between the keys
    gap = 2.0 * np.abs(t * half - np.arctan2(t * np.sin(half), 1.0 - t + t * np.cos(half)))
    return angle_between(qnormalize(va + (vb - va) * t[..., None]), values) + gap


def _midpoint_errors(values: np.ndarray, rotation: bool,
                     times: np.ndarray | None = None,
                     allowed: np.ndarray | None = None) -> np.ndarray:
    """(C, F-2) error of predicting each inner sample from its two neighbours
    (a first guess at the keys; `_errors` has the last word); with
    `allowed` (C, F), from its allowed neighbours, 0 where not allowed."""
    v = values[:, 1:-1]
    if allowed is None:
        a, b = values[:, :-2], values[:, 2:]
        w = np.full(values.shape[1] - 2, 0.5)
        if times is not None:
            w = (times[1:-1] - times[:-2]) / (times[2:] - times[:-2])
        w = np.broadcast_to(w, a.shape[:2])
    else:
        F = values.shape[1]
        idx = np.arange(F)
        before = np.maximum.accumulate(np.where(allowed, idx, -1), axis=1)[:, :-2]
        after = np.minimum.accumulate(np.where(allowed, idx, F)[:, ::-1], axis=1)[:, ::-1][:, 2:]
        a, b = _at_samples(values, before, after)
        at = idx.astype(np.float64) if times is None else np.asarray(times, np.float64)
        w = (at[1:-1] - at[before]) / (at[after] - at[before])
    if not rotation:
        err = norm_last(a + (b - a) * w[..., None] - v)
    else:
        err = angle_between(slerp(a, b, w), v)
    return err if allowed is None else np.where(allowed[:, 1:-1], err, 0.0)


def reduce_keys(values: np.ndarray, tol: np.ndarray, rotation: bool,
                times: np.ndarray | None = None,
                allowed: np.ndarray | None = None) -> np.ndarray:
    """(C, F) bool: the samples to keep so that interpolation reproduces every
    sample of every channel within tol (C,); `times` (F,) s when the
    samples are not evenly spaced; `allowed` (C, F): the only samples a
    channel may keep and is checked at (its first and last among them;
    default all)."""
    C, F = values.shape[:2]
    values = values.astype(np.float32)  # twice as fast; far finer than any tolerance
    tol = tol.astype(np.float32)
    keep = np.zeros((C, F), dtype=bool)
    keep[:, 0] = keep[:, -1] = True
    # a frame its two neighbours cannot predict is kept from the start: on
    # noisy channels this settles most keys in one pass instead of many rounds
    if F > 2:
        keep[:, 1:-1] = _midpoint_errors(values, rotation, times, allowed) > tol[:, None]
    active = np.arange(C)
    # a span that met the tolerance keeps its keys and its errors: each
    # round measures only the samples of the spans that missed the last one
    redo = None
    while len(active):
        k = keep[active]
        err = _errors(values[active], k, rotation, times, redo)
        err[k] = 0.0
        if allowed is not None:
            err[~allowed[active]] = 0.0
        rows = (err > tol[active, None]).any(axis=1)
        if not rows.any():
            break
        active, k, err = active[rows], k[rows], err[rows]
        # Douglas-Peucker: the worst frame of every span that misses becomes a key
        flat_keep = k.ravel()
        flat = err.ravel()
        span_max = np.maximum.reduceat(flat, np.flatnonzero(flat_keep))
        span_id = np.cumsum(flat_keep) - 1
        limit = np.repeat(tol[active], F)
        add = (flat == span_max[span_id]) & (flat > limit)
        keep[active] = k | add.reshape(k.shape)
        redo = (span_max[span_id] > limit).reshape(k.shape)
    return keep


def _constant(values: np.ndarray, tol: np.ndarray, rotation: bool,
              allowed: np.ndarray) -> np.ndarray:
    ref = values[:, :1]
    dev = angle_between(values, ref) if rotation else norm_last(values - ref)
    return ((dev <= tol[:, None]) | ~allowed).all(axis=1)


def subtree_reach(parent: np.ndarray, base: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """(J,) the largest distance (m) from each joint's base to a tip point of
    any joint in its subtree: the lever its rotation error acts on."""
    reach = np.linalg.norm(tips - base, axis=1)
    anc = parent.copy()
    who = np.arange(len(parent))
    while (anc >= 0).any():
        live = anc >= 0
        a, w = anc[live], who[live]
        np.maximum.at(reach, a, np.linalg.norm(tips[w] - base[a], axis=1))
        anc = np.where(live, parent[np.maximum(anc, 0)], -1)
    return reach


def _subtree(parent: np.ndarray, rows: np.ndarray):
    """The joints `rows` (whole trees, sorted) with parents renumbered."""
    new = np.full(len(parent), -1, dtype=np.int64)
    new[rows] = np.arange(len(rows))
    p = parent[rows]
    return np.where(p >= 0, new[np.maximum(p, 0)], -1)


def _world_error(parent, t_loc, q_loc, keep_t, keep_q, pos, rot, seg_vec, times=None,
                 at=None):
    """Worst world errors per joint over the samples `at` (indices; default
    all): position (m, joint base and segment tip) and angle (rad), as a
    viewer rebuilds them from the kept keys (lerp, slerp, then the joint
    hierarchy)."""
    t_r = np.swapaxes(_interpolate(np.swapaxes(t_loc, 0, 1), keep_t, False, times), 0, 1)
    q_r = np.swapaxes(_interpolate(np.swapaxes(q_loc, 0, 1), keep_q, True, times), 0, 1)
    if at is not None:
        t_r, q_r, pos, rot = t_r[at], q_r[at], pos[at], rot[at]
    wp, wq = forward(parent, depth_order(parent), t_r, q_r)
    e_base = norm_last(wp - pos).max(axis=0)
    e_tip = norm_last(wp + qrotate(wq, seg_vec[None]) - pos
                      - qrotate(rot, seg_vec[None])).max(axis=0)
    return np.maximum(e_base, e_tip), angle_between(wq, rot).max(axis=0)


def _chunks(rows: np.ndarray, group: np.ndarray, size: int = 1500) -> list[np.ndarray]:
    """`rows` in pieces of whole trees, about `size` joints each (bounded memory)."""
    g = group[rows]
    cuts = np.flatnonzero(g[1:] != g[:-1]) + 1
    out, start = [], 0
    for c in [*cuts.tolist(), len(rows)]:
        if c - start >= size or c == len(rows):
            out.append(rows[start:c])
            start = c
    return [c for c in out if len(c)]


def _quantised(t_loc, q_loc):
    """What the file stores: float32 values, quaternions renormalised."""
    t = t_loc.astype(np.float32).astype(np.float64)
    q = qnormalize(q_loc).astype(np.float32).astype(np.float64)
    return t, q


def animate(parent: np.ndarray, pos: np.ndarray, rot: np.ndarray, seg_vec: np.ndarray,
            reach: np.ndarray, opts: ReduceOptions, group: np.ndarray | None = None,
            times: np.ndarray | None = None, frames: np.ndarray | None = None,
            allowed: np.ndarray | None = None) -> Animation:
    """Channels for joints with world motion pos (F, J, 3), rot (F, J, 4)
    (in the output's axes; a joint's rest orientation is the world axes);
    seg_vec (J, 3) rest base-to-tip vectors, m; reach (J,) m (subtree_reach);
    group (J,) tree index of each joint: tolerances are tightened per tree;
    times (F,) s of the samples when they are not evenly spaced (frames
    merged with extra sub-frame samples); frames: the indices of the frames
    among them (default all), where the world errors are measured; allowed
    (F, J) bool: the samples each joint's channels may keep (default all;
    every frame must be). Channel `frames` index the samples.

    Trees are independent: they are animated in pieces of whole trees of
    about PIECE_JOINTS joints, and the pieces' channels and reports merged
    (the same values as one piece)."""
    J = pos.shape[1]
    group = np.zeros(J, np.int64) if group is None else np.asarray(group, np.int64)
    pieces = _pieces(parent, group)
    if len(pieces) == 1:
        return _animate_piece(parent, pos, rot, seg_vec, reach, opts, group, times, frames,
                              allowed)
    parts = []
    for a, b in pieces:
        parts.append(_animate_piece(
            np.where(parent[a:b] >= 0, parent[a:b] - a, -1), pos[:, a:b], rot[:, a:b],
            seg_vec[a:b], reach[a:b], opts, group[a:b] - group[a], times, frames,
            None if allowed is None else allowed[:, a:b]))
    return _merged(parts, [a for a, _ in pieces])


def _pieces(parent: np.ndarray, group: np.ndarray) -> list[tuple[int, int]]:
    """Joint ranges [a, b) of whole trees, about PIECE_JOINTS joints each;
    one range unless the trees are numbered 0, 1, ... in the joints' order
    and every parent lies in its joint's piece."""
    J = len(group)
    step = np.diff(group)
    if J == 0 or group[0] != 0 or ((step != 0) & (step != 1)).any():
        return [(0, J)]
    cuts = _chunks(np.arange(J), group, PIECE_JOINTS)
    ranges = [(int(c[0]), int(c[-1]) + 1) for c in cuts]
    start = np.repeat([a for a, _ in ranges], [b - a for a, b in ranges])
    if ((parent >= 0) & (parent < start)).any():
        return [(0, J)]
    return ranges


def _merged(parts: list[Animation], starts: list[int]) -> Animation:
    """One Animation from pieces whose joints start at `starts`: channels
    renumbered, report counts added, worst errors the worst of the pieces."""
    channels = []
    for part, start in zip(parts, starts):
        for c in part.channels:
            c.joint += start
        channels += part.channels
    report = dict(parts[0].report)
    for part in parts[1:]:
        for key, value in part.report.items():
            if key.startswith("max_"):
                report[key] = max(report[key], value)
            elif key != "frames":  # every piece has the same frames
                report[key] += value
    return Animation(np.concatenate([p.translation for p in parts]),
                     np.concatenate([p.rotation for p in parts]), channels, report,
                     tuple(np.concatenate([p.group_errors[k] for p in parts]) for k in (0, 1)))


def _animate_piece(parent: np.ndarray, pos: np.ndarray, rot: np.ndarray,
                   seg_vec: np.ndarray, reach: np.ndarray, opts: ReduceOptions,
                   group: np.ndarray, times: np.ndarray | None, frames: np.ndarray | None,
                   allowed: np.ndarray | None) -> Animation:
    """animate() for one piece of whole trees (its joints numbered from 0)."""
    F, J = pos.shape[:2]
    at = None if frames is None else np.asarray(frames, np.int64)
    if at is not None and len(at) == F and (at == np.arange(F)).all():
        at = None  # every sample is a frame: no copies of the samples at the frames
    is_frame = np.ones(F, bool)
    if at is not None:
        is_frame[:] = False
        is_frame[at] = True
    ok = None if allowed is None or allowed.all() else np.ascontiguousarray(allowed.T)
    G = int(group.max(initial=-1)) + 1
    pos = pos.astype(np.float64)
    rot = continuous(qnormalize(rot.astype(np.float64)), axis=0)
    t_loc, q_loc = local_transforms(parent, pos, rot)
    q_loc = continuous(q_loc, axis=0)
    t_loc, q_loc = _quantised(t_loc, q_loc)
    const_position = np.maximum(1e-7, CONSTANT_ULPS * np.abs(pos).max(axis=(0, 2)))
    tv = np.swapaxes(t_loc, 0, 1)
    qv = np.swapaxes(q_loc, 0, 1)
    reduce = np.full(G, opts.enabled and F > 2)
    scale = np.full(G, START_SCALE)
    keep_t = np.zeros((J, F), bool)
    keep_q = np.zeros((J, F), bool)
    const_t = np.zeros(J, bool)
    const_q = np.zeros(J, bool)
    e_pos = np.zeros(J)
    e_ang = np.zeros(J)
    lever = opts.position_tolerance / np.maximum(reach, 1e-6)
    rows = np.arange(J)
    for attempt in range(MAX_HALVINGS + 2):
        red = reduce[group[rows]]
        sc = scale[group[rows]]
        tol_t = np.where(red, sc * opts.position_tolerance, 0.0)
        tol_q = np.where(red, sc * np.minimum(opts.angle_tolerance, lever[rows]), 0.0)
        ok_rows = np.ones((len(rows), F), bool) if ok is None else ok[rows]
        const_t[rows] = _constant(tv[rows], np.maximum(tol_t, const_position[rows]), False,
                                  ok_rows)
        const_q[rows] = _constant(qv[rows], np.maximum(tol_q, CONSTANT_ANGLE), True, ok_rows)
        keep_t[rows] = _kept_samples(tv, rows, const_t[rows], red, tol_t, False, times, ok)
        keep_q[rows] = _kept_samples(qv, rows, const_q[rows], red, tol_q, True, times, ok)
        for chunk in _chunks(rows, group):
            e_pos[chunk], e_ang[chunk] = _world_error(
                _subtree(parent, chunk), t_loc[:, chunk], q_loc[:, chunk], keep_t[chunk],
                keep_q[chunk], pos[:, chunk], rot[:, chunk], seg_vec[chunk], times, at)
        g_pos = np.zeros(G)
        g_ang = np.zeros(G)
        np.maximum.at(g_pos, group, e_pos)
        np.maximum.at(g_ang, group, e_ang)
        failing = reduce & ((g_pos > opts.position_tolerance) | (g_ang > opts.angle_tolerance))
        if not failing.any():
            break
        scale[failing] *= 0.5
        if attempt >= MAX_HALVINGS:
            reduce[failing] = False  # give up reducing these trees: keep every frame
        rows = np.flatnonzero(failing[group])
    channels = _channels(t_loc, q_loc, keep_t, keep_q, const_t, const_q)
    written = sum(len(c.frames) for c in channels)
    between = [int((~is_frame[c.frames]).sum()) for c in channels]
    report = {"frames": int(is_frame.sum()), "nodes": J, "channels": 2 * J,
              "channels_written": len(channels),
              "keys_full": 2 * (J * F if ok is None else int(ok.sum())), "keys_written": written,
              "subframe_keys": sum(between), "subframe_channels": sum(b > 0 for b in between),
              "trees_reduced": int(reduce.sum()), "trees_unreduced": int(G - reduce.sum()),
              "max_position_error_m": float(g_pos.max(initial=0.0)),
              "max_angle_error_rad": float(g_ang.max(initial=0.0))}
    return Animation(t_loc[0].astype(np.float32), q_loc[0].astype(np.float32), channels, report,
                     (g_pos, g_ang))


def _kept_samples(vals: np.ndarray, rows: np.ndarray, const: np.ndarray, red: np.ndarray,
                  tol: np.ndarray, is_rot: bool, times: np.ndarray | None,
                  allowed: np.ndarray | None = None) -> np.ndarray:
    """(R, F) bool: the samples written for the channels `rows` of vals
    (J, F, D), given per row whether it is constant, reduced and its
    tolerance (m or rad): a constant channel its first, an unreduced one
    all it may keep (`allowed` (J, F), default every sample), a reduced
    one its keys, or all it may keep when key times would cost more."""
    F = vals.shape[1]
    ok = np.ones((len(rows), F), bool) if allowed is None else allowed[rows]
    k = np.zeros((len(rows), F), bool)
    k[const, 0] = True
    k[~const & ~red] = ok[~const & ~red]
    sel = ~const & red
    if sel.any():
        k[sel] = reduce_keys(vals[rows[sel]], tol[sel], is_rot, times,
                             None if allowed is None else ok[sel])
        # a reduced channel needs its own key times (4 bytes a key); when
        # that costs more than it saves, keep every frame (shared times)
        width = vals.shape[2] * 4
        dense = sel & (k.sum(axis=1) * (width + 4) >= ok.sum(axis=1) * width)
        k[dense] = ok[dense]
    return k


def _channels(t_loc: np.ndarray, q_loc: np.ndarray, keep_t: np.ndarray, keep_q: np.ndarray,
              const_t: np.ndarray, const_q: np.ndarray) -> list[Channel]:
    """Each joint's translation (m) and rotation (x y z w) channel at its kept
    samples, float32; constant channels are left out."""
    t_keys = _keys(t_loc, keep_t & ~const_t[:, None])
    q_keys = _keys(q_loc, keep_q & ~const_q[:, None])
    # kept keys, not just frames, stay continuous: a channel whose keys
    # change hemisphere (rare: q_loc is continuous frame to frame) is flipped
    rows, _, q, _ = q_keys
    same = rows[1:] == rows[:-1]
    flips = set(rows[1:][same & ((q[1:] * q[:-1]).sum(-1) < 0)].tolist())
    channels = []
    for j in range(t_loc.shape[1]):
        if not const_t[j]:
            fr, values = _channel_keys(t_keys, j)
            channels.append(Channel(j, "translation", fr, values.astype(np.float32)))
        if not const_q[j]:
            fr, values = _channel_keys(q_keys, j)
            if j in flips:
                values = continuous(values, axis=0)
            channels.append(Channel(j, "rotation", fr, values.astype(np.float32)))
    return channels


def _keys(values: np.ndarray, keep: np.ndarray):
    """The kept samples of every channel at once: joint and sample indices
    (joint by joint, samples increasing), their values (N, D), and where
    each joint's keys start (J + 1,)."""
    rows, frames = np.nonzero(keep)
    starts = np.searchsorted(rows, np.arange(keep.shape[0] + 1))
    return rows, frames, values[frames, rows], starts


def _channel_keys(keys, j: int) -> tuple[np.ndarray, np.ndarray]:
    """Joint j's kept samples and values from _keys."""
    _, frames, values, starts = keys
    a, b = starts[j], starts[j + 1]
    return frames[a:b], values[a:b]
