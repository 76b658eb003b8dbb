"""Species check: does a grammar's grown tree carry itself and the wind the
way real wood does? Static, from the rig in its rest pose; no simulation.

Three rules (docs/physics-sources.md section 8; units SI):

- **static margin**: at every joint, the bending moment of the grown weight
  of everything the joint carries (gravity, rest pose) over its breaking
  strength (`rig.strength`, N m) is at most STATIC_MARGIN = 0.4 (field
  safety factors of trees against their own weight are 2-4).
- **wind**: a steady wind of speed U at 10 m (power-law shear 0.14, the
  drag law of `forces.drag` with the rig's wood and leaf areas and drag
  coefficients, each bone's force at its centre of mass), its moment times
  the gust load factor GUST = 2 (a gust factor sqrt(2) ~ 1.41 on speed:
  peak gust over the mean wind, drag ~ U^2; docs/physics-sources.md), added
  as a vector to gravity's, against the strength: no joint thicker than
  LIMB = 2 cm breaks below Beaufort 7 (13.9 m/s); something breaks by
  hurricane force (32.7 m/s). Twigs (<= 2 cm) are reported: Beaufort's
  own description has them break from force 8 (17.2 m/s).
- **bend**: the joint angle under the same gust-factored wind load at the
  top of Beaufort 6, moment / k (k the joint's spring, rad), is at most
  BEND_FRACTION = 0.5 of the joint's cone, so a strong breeze keeps trees
  in the solver's linear tier (which they leave at 0.9 of a cone).

The wind blows from every azimuth in AZIMUTHS; a rule takes the worst.
`check(grammar)` gives a SpeciesCheck; `report(grammars)` a list of them as
dicts; `format_table` prints them. bench/species.py runs the library.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .forces import drag
from .rig import GRAVITY, Rig, RigOptions, build_rig
from .scene_keys import BEAUFORT

STATIC_MARGIN = 0.4  # most a joint's own-weight moment may use of its strength
GUST = 2.0  # gust load factor on the mean wind's drag (sqrt(2) ~ 1.41 on speed)
LIMB = 0.02  # m: joints thicker than this are limbs, thinner ones twigs
BEND_FRACTION = 0.5  # most of its cone a joint may bend in a strong breeze (gusts included)
SHEAR = 0.14  # power-law exponent of the mean wind profile
REFERENCE_HEIGHT = 10.0  # m, where the wind speed is given
STRONG_BREEZE = BEAUFORT["near gale"]  # m/s, top of Beaufort 6 (the bend rule's wind)
NEAR_GALE = BEAUFORT["near gale"]  # m/s, Beaufort 7: limbs may not break below it
GALE = BEAUFORT["gale"]  # m/s, Beaufort 8: "twigs break off trees"
HURRICANE = BEAUFORT["hurricane"]  # m/s, Beaufort 12: something must break by then
AZIMUTHS = np.arange(0.0, 360.0, 30.0)  # degrees, wind directions tried
SPEEDS = np.arange(0.0, 60.0 + 1e-9, 0.5)  # m/s, the break-speed scan (linear between: conservative)


@dataclass
class SpeciesCheck:
    """One species' figures (SI). Speeds are the mean wind at 10 m at which
    a joint first breaks (gust factor included; inf: not below 60 m/s)."""

    name: str
    grammar: str
    height: float  # m
    dbh: float  # m
    segments: int
    static_margin: float  # largest own-weight moment / strength
    static_path: str  # segment path of that joint
    static_diameter: float  # m
    limb_break_speed: float  # m/s, first joint > LIMB to break
    limb_break_path: str
    limb_break_diameter: float  # m
    twig_break_speed: float  # m/s, first joint <= LIMB to break
    twig_break_path: str
    first_break_speed: float  # m/s, first joint of any size
    bend: float  # largest angle / cone at STRONG_BREEZE (gusts included)
    bend_path: str
    bend_degrees: float  # that joint's angle, degrees
    bend_first_order: float  # largest moment / (k cone), gravity's stiffness left out
    turn: float  # rad, the most a bone turns from rest at STRONG_BREEZE (gusts included)
    turn_path: str
    gust: float = GUST

    @property
    def passes_static(self) -> bool:
        return self.static_margin <= STATIC_MARGIN

    @property
    def passes_wind(self) -> bool:
        return self.limb_break_speed >= NEAR_GALE and self.first_break_speed <= HURRICANE

    @property
    def passes_bend(self) -> bool:
        return self.bend <= BEND_FRACTION

    @property
    def passes(self) -> bool:
        return self.passes_static and self.passes_wind and self.passes_bend

    def problems(self) -> list[str]:
        """What fails, in words (empty: it passes)."""
        out = []
        if not self.passes_static:
            out.append(f"static margin {self.static_margin:.2f} > {STATIC_MARGIN} at "
                       f"{self.static_path} ({self.static_diameter * 100:.1f} cm)")
        if self.limb_break_speed < NEAR_GALE:
            out.append(f"limb {self.limb_break_path} ({self.limb_break_diameter * 100:.1f} cm) "
                       f"breaks at {self.limb_break_speed:.1f} m/s < {NEAR_GALE} m/s")
        if self.first_break_speed > HURRICANE:
            out.append(f"nothing breaks below hurricane force ({HURRICANE} m/s)")
        if not self.passes_bend:
            out.append(f"{self.bend_path} bends {self.bend:.2f} of its cone at "
                       f"{STRONG_BREEZE} m/s > {BEND_FRACTION}")
        return out

    def as_dict(self) -> dict:
        out = asdict(self)
        out.update(passes_static=self.passes_static, passes_wind=self.passes_wind,
                   passes_bend=self.passes_bend)
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                for k, v in out.items()}


def grown_rig(grammar: str | Path, seed: int | None = None, quality: str = "default") -> Rig:
    """The grammar's tree grown as a scene grows it (pipeline.grow) and
    rigged as pipeline.prepare rigs it at `quality`, standing at the origin."""
    from .pipeline import grow
    from .scene import parse_scene
    from .sim.quality import QUALITIES

    tree = {"grammar": str(Path(grammar).resolve())}
    if seed is not None:
        tree["seed"] = seed
    scene = parse_scene({"name": "species", "tree": [tree], "quality": quality},
                        file="<species>")
    model = grow(scene)[0].model
    q = QUALITIES[quality]
    return build_rig(model, RigOptions(min_bone_length=q.bone_length * max(model.height, 1e-3)))


def _levels(parent: np.ndarray) -> list[np.ndarray]:
    """Bones grouped by depth in the tree, deepest first (roots excluded)."""
    depth = np.zeros(len(parent), dtype=np.int64)
    for b, p in enumerate(parent):  # parents come first
        if p >= 0:
            depth[b] = depth[p] + 1
    return [np.nonzero(depth == d)[0] for d in range(int(depth.max(initial=0)), 0, -1)]


def _subtree_sums(parent: np.ndarray, levels: list[np.ndarray], values: np.ndarray) -> np.ndarray:
    """Sum of `values` (B, ...) over each bone and everything it carries."""
    out = np.array(values, dtype=float, copy=True)
    for idx in levels:
        np.add.at(out, parent[idx], out[idx])
    return out


def joint_moments(rig: Rig, forces: np.ndarray, levels: list[np.ndarray] | None = None
                  ) -> np.ndarray:
    """Bending moment (B, ..., 3) N m at each bone's joint of forces
    (B, ..., 3) N applied at the bones' centres of mass (rest pose)."""
    levels = _levels(rig.bone_parent) if levels is None else levels
    extra = (slice(None),) + (None,) * (forces.ndim - 2) + (slice(None),)
    total = _subtree_sums(rig.bone_parent, levels, forces)
    turning = _subtree_sums(rig.bone_parent, levels, np.cross(rig.com[extra], forces))
    return turning - np.cross(rig.pivot[extra], total)


def gravity_forces(rig: Rig) -> np.ndarray:
    """Weight (B, 3) N of each bone."""
    out = np.zeros((rig.n_bones, 3))
    out[:, 2] = -GRAVITY * rig.mass
    return out


def wind_forces(rig: Rig, speeds: np.ndarray, azimuth: float, ground: float = 0.0) -> np.ndarray:
    """Drag (B, K, 3) N on each bone at rest in a steady wind of each of
    `speeds` (K,) m/s at REFERENCE_HEIGHT above `ground`, blowing toward
    `azimuth` degrees (from +X toward +Y): forces.drag's law, shear SHEAR."""
    speeds = np.atleast_1d(np.asarray(speeds, dtype=float))
    a = math.radians(azimuth)
    direction = np.array([math.cos(a), math.sin(a), 0.0])
    z = np.maximum(rig.com[:, 2] - ground, 0.5)
    profile = (z / REFERENCE_HEIGHT) ** SHEAR  # (B,)
    n, k = rig.n_bones, len(speeds)
    air = (profile[:, None] * speeds[None, :])[..., None] * direction  # (B, K, 3)
    rep = lambda v: np.repeat(v, k, axis=0)  # noqa: E731
    force = drag(air.reshape(-1, 3), np.zeros((n * k, 3)), rep(rig.axis), rep(rig.wood_area),
                 rep(rig.leaf_area), rig.drag, rig.leaf_drag)
    return force.reshape(n, k, 3)


def first_segments(rig: Rig) -> np.ndarray:
    """The segment at each bone's base (its joint's segment)."""
    out = np.full(rig.n_bones, -1, dtype=np.int64)
    for s in range(len(rig.seg_bone) - 1, -1, -1):
        out[rig.seg_bone[s]] = s
    return out


def _first_crossing(util: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """Per joint (rows of util (B, K)), the speed at which util first
    reaches 1, linearly interpolated in the scan; inf if never."""
    over = util >= 1.0
    hit = over.any(1)
    i = np.argmax(over, axis=1)
    out = np.full(util.shape[0], math.inf)
    rows = np.nonzero(hit)[0]
    i1 = i[rows]
    at0 = i1 == 0
    out[rows[at0]] = speeds[0]
    r, j = rows[~at0], i1[~at0]
    u0, u1 = util[r, j - 1], util[r, j]
    out[r] = speeds[j - 1] + (1.0 - u0) / np.maximum(u1 - u0, 1e-300) * (speeds[j] - speeds[j - 1])
    return out


def hinge_frame(rig: Rig) -> np.ndarray:
    """(B, 3, 2): each joint's two hinge axes, perpendicular to the bone and
    to each other (swing without twist; the first horizontal when it can
    be: z x axis, else x x axis), the convention of both solvers."""
    axis = rig.axis
    e1 = np.cross(np.array([0.0, 0.0, 1.0]), axis)
    flat = np.linalg.norm(e1, axis=1) <= 0.1
    e1[flat] = np.cross(np.array([1.0, 0.0, 0.0]), axis[flat])
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([e1, np.cross(axis, e1)], axis=2)


class StaticSolver:
    """Small static deflections of a tree from its rest pose under loads at
    the bones' centres of mass: (K_s + K_g) q = J^T F, q (2B,) the hinge
    angles (two per joint), K_s the joint springs (k on both hinges), K_g
    gravity's geometric stiffness at rest (a hanging twig swings back like
    a pendulum, an upright stem is softened, P-delta):

        K_g[i, j] = -((n_j . g)(n_i . R_j) - (R_j . g)(n_i . n_j))

    for hinge i an ancestor of (or equal to) hinge j, n their axes, g the
    gravity vector, R_j the mass moment sum m (c - p_j) of everything hinge
    j carries. The matrix has entries only between a hinge and its
    ancestors, so it factors as L^T D L without fill-in (Featherstone 2005).
    The prestress holds the rest pose against gravity, so loads other than
    gravity are what move it. Linear: a swing is not capped at the
    streaming angle, so pendulous twigs come out on the safe side."""

    def __init__(self, rig: Rig, levels: list[np.ndarray] | None = None):
        self.rig = rig
        levels = _levels(rig.bone_parent) if levels is None else levels
        nb = rig.n_bones
        n = 2 * nb
        self.frame = frame = hinge_frame(rig)
        axes = frame.transpose(0, 2, 1).reshape(n, 3)  # dof 2b + h: bone b's hinge h
        bone = np.repeat(np.arange(nb), 2)
        parent = np.empty(n, dtype=np.int64)
        parent[0::2] = np.where(rig.bone_parent >= 0, 2 * rig.bone_parent + 1, -1)
        parent[1::2] = np.arange(0, n, 2)
        depth = np.zeros(n, dtype=np.int64)
        for j in range(n):
            if parent[j] >= 0:
                depth[j] = depth[parent[j]] + 1
        width = int(depth.max()) + 1
        anc = np.full((n, width), -1, dtype=np.int64)  # root-aligned ancestors, self last
        for j in range(n):
            p = parent[j]
            if p >= 0:
                anc[j, :depth[j]] = anc[p, :depth[j]]
            anc[j, depth[j]] = j
        msum = _subtree_sums(rig.bone_parent, levels, rig.mass)
        mcsum = _subtree_sums(rig.bone_parent, levels, rig.mass[:, None] * rig.com)
        lever = (mcsum - msum[:, None] * rig.pivot)[bone]  # R_j, kg m
        g = np.array([0.0, 0.0, -GRAVITY])
        valid = anc >= 0
        ai = np.where(valid, anc, 0)
        ni = axes[ai]  # (n, width, 3)
        nj = axes[:, None, :]
        rj = lever[:, None, :]
        rows = -((axes @ g)[:, None] * (ni * rj).sum(2) - (lever @ g)[:, None] * (ni * nj).sum(2))
        rows = np.where(valid, rows, 0.0)
        rows[np.arange(n), depth] += np.repeat(rig.k, 2)
        # L^T D L in place, deepest dofs first (a dof's row is final once its
        # descendants are done); rows[k, :depth[k]] become L, the diagonal D
        tri = np.tril(np.ones((width, width)))
        order = np.argsort(-depth, kind="stable")
        self.stable = True
        for k in order:
            d = depth[k]
            pivot = rows[k, d]
            if not pivot > 0:
                self.stable = False
                pivot = math.inf
            if d:
                a = rows[k, :d] / pivot
                up = anc[k, :d]
                rows[up, :d] -= a[:, None] * rows[k, None, :d] * tri[:d, :d]
                rows[k, :d] = a
        self.rows, self.anc, self.depth, self.axes = rows, anc, depth, axes
        self.diag = rows[np.arange(n), depth].copy()
        self.hold = np.einsum("bia,bi->ba", frame,
                              joint_moments(rig, gravity_forces(rig), levels))  # (B, 2) N m

    def solve(self, torque: np.ndarray) -> np.ndarray:
        """Hinge angles (2B, K) rad for hinge torques (2B, K) N m."""
        rows, anc, depth = self.rows, self.anc, self.depth
        x = np.array(torque, dtype=float, copy=True)
        n = len(depth)
        for k in range(n - 1, -1, -1):  # L^T
            d = depth[k]
            if d:
                x[anc[k, :d]] -= rows[k, :d, None] * x[k]
        with np.errstate(invalid="ignore", divide="ignore"):
            x /= self.diag[:, None]
        for k in range(n):  # L
            d = depth[k]
            if d:
                x[k] -= (rows[k, :d, None] * x[anc[k, :d]]).sum(0)
        return x

    def hinge_torques(self, moments: np.ndarray) -> np.ndarray:
        """(2B, K) N m: joint moment vectors (B, K, 3) on each joint's hinges."""
        t = np.einsum("bia,bki->bak", self.frame, moments)
        return t.reshape(-1, t.shape[-1])

    def turns(self, q: np.ndarray, levels: list[np.ndarray]) -> np.ndarray:
        """(B, K) rad: how far each bone turns from its rest pose (the
        rotation vectors of the joints below it added, first order)."""
        nb = self.rig.n_bones
        own = (q.reshape(nb, 2, -1)[:, :, :, None]
               * self.frame.transpose(0, 2, 1)[:, :, None, :]).sum(1)  # (B, K, 3)
        total = own.copy()
        parent = self.rig.bone_parent
        for idx in reversed(levels):  # shallowest first
            total[idx] += total[parent[idx]]
        return np.linalg.norm(total, axis=2)


def check(grammar: str | Path, seed: int | None = None, quality: str = "default",
          gust: float = GUST, speeds: np.ndarray = SPEEDS,
          azimuths: np.ndarray = AZIMUTHS) -> SpeciesCheck:
    """The species rules for one grammar's grown tree (module doc)."""
    rig = grown_rig(grammar, seed, quality)
    model = rig.model
    levels = _levels(rig.bone_parent)
    paths = model.segment_paths()
    seg = first_segments(rig)
    diameter = np.maximum(model.width[seg], rig.options.min_width)
    strength = rig.strength
    solver = StaticSolver(rig, levels)
    hold = solver.hold  # (B, 2): gravity's bending moment, held by the springs at rest
    finite = np.isfinite(strength)
    safe = np.where(finite, strength, 1.0)
    static = np.where(finite, np.linalg.norm(hold, axis=1) / safe, 0.0)
    worst = int(np.argmax(static))
    speeds = np.asarray(speeds, dtype=float)
    grid = np.append(speeds, STRONG_BREEZE)  # the scan, and the bend rule's wind last
    k = len(grid)
    moments = np.concatenate([gust * joint_moments(rig, wind_forces(rig, grid, az), levels)
                              for az in azimuths], axis=1)  # (B, A K, 3)
    q = solver.solve(solver.hinge_torques(moments)) if solver.stable else \
        np.full((2 * rig.n_bones, moments.shape[1]), math.inf)
    q2 = q.reshape(rig.n_bones, 2, len(azimuths), k)
    spring = hold[:, :, None, None] + rig.k[:, None, None, None] * q2  # N m, what breaks
    with np.errstate(invalid="ignore"):
        util = np.where(finite[:, None, None],
                        np.linalg.norm(spring, axis=1) / safe[:, None, None], 0.0)
    util = np.nan_to_num(util, nan=math.inf)
    break_speed = np.min([_first_crossing(util[:, a, :-1], speeds)
                          for a in range(len(azimuths))], axis=0)
    angle = np.linalg.norm(q2[:, :, :, -1], axis=1).max(1)  # rad, in the strong breeze
    bend = angle / rig.cone
    bend_plain = (np.linalg.norm(moments.reshape(rig.n_bones, len(azimuths), k, 3)[:, :, -1],
                                 axis=2).max(1) / rig.k / rig.cone)
    turn = solver.turns(q[:, k - 1::k], levels).max(1)  # rad, in the strong breeze
    limb = diameter > LIMB

    def first(mask):
        if not mask.any():
            return math.inf, "", math.nan
        cand = np.where(mask, break_speed, math.inf)
        b = int(np.argmin(cand))
        return float(cand[b]), paths[seg[b]], float(diameter[b])

    limb_speed, limb_path, limb_d = first(limb)
    twig_speed, twig_path, _ = first(~limb)
    b_bend = int(np.argmax(bend))
    b_turn = int(np.argmax(turn))
    return SpeciesCheck(
        name=Path(grammar).stem, grammar=str(grammar), height=model.height, dbh=model.dbh(),
        segments=model.n_segments,
        static_margin=float(static[worst]), static_path=paths[seg[worst]],
        static_diameter=float(diameter[worst]),
        limb_break_speed=limb_speed, limb_break_path=limb_path, limb_break_diameter=limb_d,
        twig_break_speed=twig_speed, twig_break_path=twig_path,
        first_break_speed=float(min(limb_speed, twig_speed)),
        bend=float(bend[b_bend]), bend_path=paths[seg[b_bend]],
        bend_degrees=float(math.degrees(angle[b_bend])),
        bend_first_order=float(bend_plain.max()),
        turn=float(turn[b_turn]), turn_path=paths[seg[b_turn]], gust=gust)


def report(grammars, **kwargs) -> list[dict]:
    """check() of each grammar, as dicts (JSON-ready: inf speeds are None)."""
    return [check(g, **kwargs).as_dict() for g in grammars]


def format_table(checks: list[SpeciesCheck]) -> str:
    """A plain-text table of checks, one species a line."""

    def speed(v):
        return "  >60" if not math.isfinite(v) else f"{v:5.1f}"

    head = (f"{'species':<18} {'H m':>5} {'segs':>5} {'static':>6} {'worst joint (own weight)':<26} "
            f"{'limb m/s':>8} {'twig m/s':>8} {'bend/cone':>9} {'ok':>3}")
    lines = [head, "-" * len(head)]
    for c in checks:
        lines.append(f"{c.name:<18} {c.height:>5.1f} {c.segments:>5} {c.static_margin:>6.2f} "
                     f"{c.static_path[:26]:<26} {speed(c.limb_break_speed):>8} "
                     f"{speed(c.twig_break_speed):>8} {c.bend:>9.2f} "
                     f"{'yes' if c.passes else 'NO':>3}")
    return "\n".join(lines)
