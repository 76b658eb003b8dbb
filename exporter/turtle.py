"""3D turtle: a derived module string -> TreeModel.

The turtle's orientation is a unit quaternion (no gimbal lock). Its frame is
ABOP's: heading H, left L, up U with H x L = U. Rotations are the book's
matrices R_U, R_L, R_H applied as [H L U]' = [H L U] R^T, the one reading in
which `+` turns left: `+` moves H toward L, `&` moves H toward -U, `\\`
moves L toward -U (left side down). It starts at the origin with
H = +Z (up), L = -X, U = -Y, so a 2D grammar draws in the XZ plane as seen
from the front (-Y), `+` turning left (counter-clockwise) as in the book.

Commands (angles in degrees, default the grammar's `angle`; lengths in
grammar units times `scale`, default the grammar's `step`):
    F(l) draw a segment     f(l) move without drawing
    +(a) -(a) turn left/right about U     &(a) ^(a) pitch down/up about L
    \\(a) /(a) roll left/right about H      | turn around     $ roll L horizontal
    [ ] push/pop (a bracket starts a child limb)    !(w) set width, ! scale it
    @leaves(type[, size]) @tropism(e | x,y,z,e) and the physics commands of
    `lsystem.symbols` (see docs/grammar.md). @twig: to the end of the
    bracket, F draws twigs (model.Twigs) on the segment under the turtle,
    not segments. Every other symbol is ignored.
Tropism (ABOP eq. 2.4): after each F the frame turns about H x T by
e * |H x T|.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .errors import GrammarError
from .lsystem.grammar import Grammar, Module
from .model import Limb, TreeModel, Twigs

Quat = tuple[float, float, float, float]  # w, x, y, z


def qmul(a: Quat, b: Quat) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def qaxis(x: float, y: float, z: float, angle: float) -> Quat:
    """Rotation by `angle` radians about the unit axis (x, y, z)."""
    s = math.sin(angle / 2)
    return (math.cos(angle / 2), x * s, y * s, z * s)


def qrotate(q: Quat, v: tuple[float, float, float]) -> tuple[float, float, float]:
    w, x, y, z = q
    vx, vy, vz = v
    # v' = v + 2w (q x v) + 2 q x (q x v)
    cx, cy, cz = y * vz - z * vy, z * vx - x * vz, x * vy - y * vx
    cx2, cy2, cz2 = y * cz - z * cy, z * cx - x * cz, x * cy - y * cx
    return (vx + 2 * (w * cx + cx2), vy + 2 * (w * cy + cy2), vz + 2 * (w * cz + cz2))


def qnormalize(q: Quat) -> Quat:
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / n, x / n, y / n, z / n)


def quat_from_frame(h, lft, u) -> Quat:
    """Quaternion whose rotation maps the local frame (H=+Z, L=-X, U=-Y) to the
    given world vectors. Columns of the matrix: -L, -U, H."""
    m00, m10, m20 = -lft[0], -lft[1], -lft[2]
    m01, m11, m21 = -u[0], -u[1], -u[2]
    m02, m12, m22 = h
    tr = m00 + m11 + m22
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = (0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s)
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        q = ((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s)
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        q = ((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s)
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2
        q = ((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s)
    return qnormalize(q)


_H, _L, _U = (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0), (0.0, -1.0, 0.0)
# symbol -> (local axis, sign)
_TURNS = {"+": (_U, 1.0), "-": (_U, -1.0), "&": (_L, 1.0), "^": (_L, -1.0),
          "\\": (_H, -1.0), "/": (_H, 1.0)}
_PHYS = {"@density": 0, "@modulus": 1, "@ei": 2, "@stiffness": 3, "@damping": 4, "@cone": 5,
         "@strength": 6, "@rupture": 7}


@dataclass
class _State:
    pos: tuple[float, float, float]
    q: Quat
    width: float
    limb: int  # current limb, -1 = none yet
    index: int  # index of the turtle's point in the limb's point list, -1 = off the limb
    point: int  # global index of the point under the turtle, -1 = moved without drawing
    new_limb: bool  # the next F starts a child limb
    phys: tuple  # density, modulus, ei, stiffness, damping, cone(deg), strength, rupture
    leaf: int
    leaf_size: float
    tropism: tuple[float, float, float]
    elasticity: float
    twig: int = -1  # `@twig`: F draws twigs on this segment; -1 = F draws segments

    def copy(self) -> _State:
        """The state `[` pushes (every field is immutable: a shallow copy)."""
        new = object.__new__(_State)
        new.__dict__.update(self.__dict__)
        return new


@dataclass
class _Drawing:
    """What the turtle drew: points (m), limbs, segment rows and each limb's
    number of child limbs (key -1: root limbs)."""

    points: list[tuple[float, float, float]]
    limbs: list[Limb] = field(default_factory=list)
    # per segment: (start, end, limb, parent_seg, width, *phys, leaf, leaf_size)
    seg_rows: list[tuple] = field(default_factory=list)
    children: dict[int, int] = field(default_factory=dict)
    # per twig: (start xyz, end xyz, width, leaf, leaf_size, segment)
    twig_rows: list[tuple] = field(default_factory=list)


def count_segments(modules: Sequence[Module]) -> int:
    """The segments a derived string draws at most: its F modules (one of
    zero length draws none), but for the twigs F draws after `@twig` up to
    the end of its bracket (geometry only, no segment: the module caps
    bound them)."""
    count, twig, stack = 0, False, []
    for sym, _ in modules:
        if sym == "F":
            count += not twig
        elif sym == "[":
            stack.append(twig)
        elif sym == "]":
            twig = stack.pop() if stack else False
        elif sym == "@twig":
            twig = True
    return count


def interpret(modules: Sequence[Module], grammar: Grammar, name: str | None = None,
              seed: int | None = None) -> TreeModel:
    """Walk the module string and build the TreeModel (metres, Z up)."""
    g = grammar
    ph = g.physics
    st = _State((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), g.width * g.width_scale, -1, -1, 0, True,
                (ph.density, ph.modulus, math.nan, math.nan, ph.damping, ph.cone,
                 ph.strength, ph.rupture),
                g.leaves, ph.leaf_size, g.tropism, g.elasticity)
    stack: list[_State] = []
    drawing = _Drawing([st.pos])  # point 0: the turtle's start
    turns: dict[tuple, Quat] = {}  # (symbol, parameters) -> its rotation, built once

    def fail(message: str) -> GrammarError:
        return GrammarError(message, g.file, 0, 0)

    for sym, params in modules:
        if sym == "F":
            length = (params[0] if params else g.step) * g.scale
            if length == 0.0:
                continue
            if st.twig >= 0:
                _draw_twig(st, length, drawing)
            else:
                _draw_segment(st, length, drawing)
        elif sym in _TURNS:
            turn = turns.get((sym, params))
            if turn is None:
                turn = turns[(sym, params)] = _turn(sym, params, g)
            st.q = qmul(st.q, turn)
        elif sym == "[":
            stack.append(st)
            if len(stack) > 100_000:
                raise fail("bracket nesting deeper than 100000")
            st = st.copy()
            st.new_limb = True
        elif sym == "]":
            if not stack:
                raise fail("']' without a matching '[' in the derived string")
            st = stack.pop()
        elif sym == "@twig":
            if st.twig < 0:
                st.twig = _segment_under(st, drawing.limbs, fail)
        else:
            _apply_command(st, sym, params, g, fail)
    return _tree_model(drawing, g, name, seed, fail)


def _draw_segment(st: _State, length: float, drawing: _Drawing) -> None:
    """F: a segment `length` m along the heading, on the turtle's limb or a new
    one; the turtle moves to its end and, with tropism, bends."""
    points, limbs = drawing.points, drawing.limbs
    h = qrotate(st.q, _H)
    if st.point < 0:  # moved without drawing: a new point off the limb
        points.append(st.pos)
        st.point = len(points) - 1
        st.new_limb = True
    if st.new_limb:
        _start_limb(st, drawing)
    limb = limbs[st.limb]
    new = (st.pos[0] + h[0] * length, st.pos[1] + h[1] * length,
           st.pos[2] + h[2] * length)
    points.append(new)
    if limb.segments:
        parent_seg = limb.segments[-1]
    else:
        parent_seg = _segment_ending_at(limbs, limb)
    drawing.seg_rows.append((st.point, len(points) - 1, st.limb, parent_seg, st.width,
                             *st.phys, st.leaf, st.leaf_size))
    limb.segments.append(len(drawing.seg_rows) - 1)
    limb.points.append(len(points) - 1)
    st.pos, st.point, st.index = new, len(points) - 1, len(limb.points) - 1
    if st.elasticity != 0.0:
        st.q = _tropism(st.q, h, st.tropism, st.elasticity)


def _draw_twig(st: _State, length: float, drawing: _Drawing) -> None:
    """F after `@twig`: a twig `length` m along the heading, on segment
    `st.twig`; the turtle moves to its end and, with tropism, bends. No
    limb, point or segment: the physics never sees it."""
    h = qrotate(st.q, _H)
    new = (st.pos[0] + h[0] * length, st.pos[1] + h[1] * length,
           st.pos[2] + h[2] * length)
    drawing.twig_rows.append((*st.pos, *new, st.width, st.leaf, st.leaf_size, st.twig))
    st.pos = new
    if st.elasticity != 0.0:
        st.q = _tropism(st.q, h, st.tropism, st.elasticity)


def _segment_under(st: _State, limbs: list[Limb], fail) -> int:
    """The segment `@twig` hangs its twigs on: the one ending at the
    turtle's point on its limb (at a limb's base, the parent's segment
    there, else the limb's first); after `f`, the segment the turtle
    moved away from."""
    if st.limb >= 0:
        limb = limbs[st.limb]
        if st.index > 0:
            return limb.segments[st.index - 1]
        below = _segment_ending_at(limbs, limb)
        if below >= 0:
            return below
        if limb.segments:
            return limb.segments[0]
    raise fail("@twig where the turtle is on no segment (before the first F, or in a bracket "
               "opened at the ground): a twig hangs on the segment under the turtle")


def _start_limb(st: _State, drawing: _Drawing) -> None:
    """A new limb from the turtle's point, the child of the limb it is on
    (none: a root limb, `trunk`, `trunk2`, ...); the turtle moves onto it."""
    limbs, children = drawing.limbs, drawing.children
    parent = st.limb
    attach = st.index if parent >= 0 else -1
    limbs.append(Limb(parent, attach, [st.point]))
    children[parent] = children.get(parent, 0) + 1
    if parent < 0:
        roots = children[-1]
        limbs[-1].path = "trunk" if roots == 1 else f"trunk{roots}"
    else:
        limbs[-1].path = f"{limbs[parent].path}/{children[parent]}"
    st.limb, st.index, st.new_limb = len(limbs) - 1, 0, False


def _apply_command(st: _State, sym: str, params: tuple[float, ...], g: Grammar, fail) -> None:
    """Every command but F, [, ], @twig and the turns (interpret applies
    those): f (moves without drawing), width (m), physics, leaves and
    tropism, applied to `st` in place. Other symbols are ignored;
    `fail(message)` builds the error."""
    if sym == "f":
        length = (params[0] if params else g.step) * g.scale
        h = qrotate(st.q, _H)
        st.pos = (st.pos[0] + h[0] * length, st.pos[1] + h[1] * length,
                  st.pos[2] + h[2] * length)
        st.point = -1
    elif sym == "!" or sym == "@width":
        st.width = params[0] * g.width_scale if params else st.width * g.width_factor
        if st.width < 0:
            raise fail(f"negative width {st.width:g} m")
    elif sym == "|":
        st.q = qmul(st.q, qaxis(*_U, math.pi))
    elif sym == "$" or sym == "@roll":
        st.q = _roll_horizontal(st.q)
    elif sym in _PHYS:
        st.phys = _set_phys(st.phys, _PHYS[sym], params[0], fail)
    elif sym == "@leaves":
        st.leaf = int(params[0])
        if st.leaf < 0:
            raise fail(f"leaf type must be >= 0, got {params[0]:g}")
        if len(params) > 1:
            st.leaf_size = params[1]
    elif sym == "@tropism":
        if len(params) == 4:
            t = params[:3]
            if math.hypot(*t) == 0:
                raise fail("@tropism vector must not be zero")
            st.tropism = (t[0], t[1], t[2])
        st.elasticity = params[-1]


def _turn(sym: str, params: tuple[float, ...], g: Grammar) -> Quat:
    """The rotation of a turn command (`params[0]` degrees, default the
    grammar's angle) in the turtle's frame."""
    axis, sign = _TURNS[sym]
    angle = math.radians(params[0]) if params else math.radians(g.angle)
    return qaxis(*axis, sign * angle)


def _tree_model(drawing: _Drawing, g: Grammar, name: str | None, seed: int | None,
                fail) -> TreeModel:
    """The TreeModel of what the turtle drew: per-segment arrays (SI units;
    cone in radians, strength in N m capped by the rupture modulus)."""
    seg_rows = drawing.seg_rows
    ph = g.physics
    if not seg_rows:
        raise fail("the derived string draws no segments (no F with non-zero length)")
    pts = np.asarray(drawing.points, dtype=float)
    if not np.isfinite(pts).all():
        raise fail("the geometry is not finite (a length or angle parameter is too large)")
    cols = list(zip(*seg_rows))
    cone_deg = np.asarray(cols[10], dtype=float)
    width = np.asarray(cols[4], dtype=float)
    strength = np.asarray(cols[11], dtype=float)
    rupture = np.asarray(cols[12], dtype=float)
    finite = np.isfinite(rupture)
    from_rupture = np.where(finite, np.where(finite, rupture, 0.0) * np.pi * width**3 / 32,
                            np.inf)
    strength = np.minimum(strength, from_rupture)
    ei = np.asarray(cols[7], dtype=float)
    stiff = np.asarray(cols[8], dtype=float)
    twigs = _twigs(drawing.twig_rows)
    leaf, leaf_size = _with_twig_foliage(np.asarray(cols[13], dtype=np.int64),
                                         np.asarray(cols[14], dtype=float), twigs)
    return TreeModel(
        name=name or g.name,
        points=pts,
        seg_start=np.asarray(cols[0], dtype=np.int64),
        seg_end=np.asarray(cols[1], dtype=np.int64),
        seg_limb=np.asarray(cols[2], dtype=np.int64),
        seg_parent=np.asarray(cols[3], dtype=np.int64),
        width=width,
        density=np.asarray(cols[5], dtype=float),
        modulus=np.asarray(cols[6], dtype=float),
        ei=np.where(ei > 0, ei, np.nan),
        stiffness=np.where(stiff > 0, stiff, np.nan),
        damping=np.asarray(cols[9], dtype=float),
        cone=np.radians(cone_deg),
        strength=strength,
        leaf=leaf,
        leaf_size=leaf_size,
        limbs=drawing.limbs,
        anchor=ph.anchor,
        leaf_mass=ph.leaf_mass,
        drag=ph.drag,
        leaf_drag=ph.leaf_drag,
        source={"grammar": g.name, "grammar_file": g.file, "grammar_hash": g.source_hash,
                "seed": g.seed if seed is None else seed},
        twigs=twigs,
    )


def _twigs(rows: list[tuple]) -> Twigs:
    if not rows:
        return Twigs.none()
    a = np.asarray(rows, dtype=float)
    return Twigs(start=a[:, 0:3], end=a[:, 3:6], width=a[:, 6].copy(),
                 leaf=a[:, 7].astype(np.int64), leaf_size=a[:, 8].copy(),
                 segment=a[:, 9].astype(np.int64))


def _with_twig_foliage(leaf: np.ndarray, leaf_size: np.ndarray, twigs: Twigs):
    """Segments' leaf types and sizes with their twigs' foliage: a segment
    whose own `@leaves` is 0 but whose twigs are leafy carries their
    foliage in the physics (the first leafy twig's type and size), so a
    culm with leafy side twigs has their mass and drag."""
    leafy = np.nonzero(twigs.leaf > 0)[0]
    if not len(leafy):
        return leaf, leaf_size
    leaf, leaf_size = leaf.copy(), leaf_size.copy()
    segs, first = np.unique(twigs.segment[leafy], return_index=True)
    bare = leaf[segs] == 0
    leaf[segs[bare]] = twigs.leaf[leafy[first[bare]]]
    leaf_size[segs[bare]] = twigs.leaf_size[leafy[first[bare]]]
    return leaf, leaf_size


def _segment_ending_at(limbs: list[Limb], limb: Limb) -> int:
    """The segment a new limb's first segment hangs on: the parent limb's
    segment ending at the attachment point (recursively at a limb's base)."""
    while limb.parent >= 0:
        parent = limbs[limb.parent]
        if limb.attach > 0:
            return parent.segments[limb.attach - 1]
        limb = parent
    return -1


_PHYS_RANGES = [("@density", 1.0, 5000.0), ("@modulus", 1e3, 1e12), ("@ei", 0.0, np.inf),
                ("@stiffness", 0.0, np.inf), ("@damping", 0.0, 2.0), ("@cone", 0.0, 180.0),
                ("@strength", 0.0, np.inf), ("@rupture", 0.0, np.inf)]


def _set_phys(phys: tuple, k: int, value: float, fail) -> tuple:
    name, lo, hi = _PHYS_RANGES[k]
    if not lo <= value <= hi:
        raise fail(f"{name}({value:g}) is out of range [{lo:g}, {hi:g}]")
    if name in ("@strength", "@rupture") and value == 0:
        value = math.inf  # 0 switches breaking off
    if name == "@cone" and value == 0:
        value = 0.01
    out = list(phys)
    out[k] = value
    return tuple(out)


def _tropism(q: Quat, h, t, e: float) -> Quat:
    ax = h[1] * t[2] - h[2] * t[1]
    ay = h[2] * t[0] - h[0] * t[2]
    az = h[0] * t[1] - h[1] * t[0]
    n = math.sqrt(ax * ax + ay * ay + az * az)
    if n < 1e-12:
        return q
    return qnormalize(qmul(qaxis(ax / n, ay / n, az / n, e * n), q))


def _roll_horizontal(q: Quat) -> Quat:
    h = qrotate(q, _H)
    # L = V x H / |V x H| with V = +Z
    lx, ly = -h[1], h[0]
    n = math.hypot(lx, ly)
    if n < 1e-9:
        return q
    lft = (lx / n, ly / n, 0.0)
    u = (h[1] * lft[2] - h[2] * lft[1], h[2] * lft[0] - h[0] * lft[2],
         h[0] * lft[1] - h[1] * lft[0])
    return quat_from_frame(h, lft, u)
