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


def bending_frame(rig: Rig) -> np.ndarray:
    """(B, 3, 2): two unit vectors perpendicular to each bone's axis, the
    plane its joint bends in (the joint's two hinges; twist is rigid)."""
    axis = rig.axis
    helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(axis, e1)
    return np.stack([e1, e2], axis=2)


def joint_compliance(rig: Rig, levels: list[np.ndarray] | None = None) -> np.ndarray:
    """(B, 2, 2) rad/(N m): each joint's rotation per unit bending moment,
    its spring k plus gravity's geometric stiffness of everything it carries
    turning about it as one body, m g (sym(e_z r^T) - r_z I) with r the
    carried centre of mass from the pivot (a hanging twig's pendulum
    stiffness, an upright stem's P-delta softening). inf where the sum is
    not positive definite (the joint cannot hold its load)."""
    levels = _levels(rig.bone_parent) if levels is None else levels
    msum = _subtree_sums(rig.bone_parent, levels, rig.mass)
    mcsum = _subtree_sums(rig.bone_parent, levels, rig.mass[:, None] * rig.com)
    lever = mcsum - msum[:, None] * rig.pivot  # m r, kg m
    ez = np.array([0.0, 0.0, 1.0])
    kg = GRAVITY * (0.5 * (ez[None, :, None] * lever[:, None, :]
                           + lever[:, :, None] * ez[None, None, :])
                    - lever[:, 2, None, None] * np.eye(3))
    frame = bending_frame(rig)
    a = rig.k[:, None, None] * np.eye(2) + np.einsum("bia,bij,bjc->bac", frame, kg, frame)
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    ok = (a[:, 0, 0] > 0) & (det > 0)
    inv = np.full_like(a, math.inf)
    adj = np.stack([np.stack([a[:, 1, 1], -a[:, 0, 1]], 1),
                    np.stack([-a[:, 1, 0], a[:, 0, 0]], 1)], 1)
    inv[ok] = adj[ok] / det[ok, None, None]
    return inv


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
    frame = bending_frame(rig)
    compliance = joint_compliance(rig, levels)
    # bending moments: the components across each bone (twist is rigid)
    m_grav = np.einsum("bia,bi->ba", frame, joint_moments(rig, gravity_forces(rig), levels))
    finite = np.isfinite(strength)
    safe = np.where(finite, strength, 1.0)
    static = np.where(finite, np.linalg.norm(m_grav, axis=1) / safe, 0.0)
    worst = int(np.argmax(static))
    speeds = np.asarray(speeds, dtype=float)
    breeze_at = len(speeds)
    speeds_b = np.append(speeds, STRONG_BREEZE)
    break_speed = np.full(rig.n_bones, math.inf)
    bend = np.zeros(rig.n_bones)
    bend_plain = np.zeros(rig.n_bones)
    for az in azimuths:
        m_wind = gust * np.einsum("bia,bki->bka", frame,
                                  joint_moments(rig, wind_forces(rig, speeds_b, az), levels))
        with np.errstate(invalid="ignore"):
            turn = np.einsum("bac,bkc->bka", compliance, m_wind)  # rad
        turn = np.where(np.isfinite(turn), turn, math.inf)
        spring = m_grav[:, None, :] + rig.k[:, None, None] * turn  # the spring's moment
        with np.errstate(invalid="ignore"):
            util = np.where(finite[:, None], np.linalg.norm(spring[:, :breeze_at], axis=2)
                            / safe[:, None], 0.0)
        break_speed = np.minimum(break_speed, _first_crossing(np.nan_to_num(util, nan=np.inf),
                                                              speeds))
        bend = np.maximum(bend, np.linalg.norm(turn[:, breeze_at], axis=1) / rig.cone)
        bend_plain = np.maximum(bend_plain,
                                np.linalg.norm(m_wind[:, breeze_at], axis=1) / rig.k / rig.cone)
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
    return SpeciesCheck(
        name=Path(grammar).stem, grammar=str(grammar), height=model.height, dbh=model.dbh(),
        segments=model.n_segments,
        static_margin=float(static[worst]), static_path=paths[seg[worst]],
        static_diameter=float(diameter[worst]),
        limb_break_speed=limb_speed, limb_break_path=limb_path, limb_break_diameter=limb_d,
        twig_break_speed=twig_speed, twig_break_path=twig_path,
        first_break_speed=float(min(limb_speed, twig_speed)),
        bend=float(bend[b_bend]), bend_path=paths[seg[b_bend]],
        bend_degrees=float(math.degrees(bend[b_bend] * rig.cone[b_bend])),
        bend_first_order=float(bend_plain.max()), gust=gust)


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
