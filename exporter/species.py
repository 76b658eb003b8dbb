"""Species check: does a grammar's grown tree carry itself and the wind the
way real wood does? Static, from the rig in its rest pose (statics.py); no
simulation. Rules and their sources: docs/physics-sources.md section 8.

- **static margin**: at every joint, the bending moment of the grown weight
  of everything the joint carries (gravity, rest pose) over its breaking
  strength (`rig.strength`, N m) is at most STATIC_MARGIN = 0.4 (field
  safety factors of trees against their own weight are 2-4).
- **wind**: a steady wind of mean speed U at 10 m (power-law shear 0.14;
  `forces.drag`'s law with the rig's wood and leaf areas and drag
  coefficients, each bone's force at its centre of mass), its moments
  times the gust load factor GUST = 2 (peak gust over the mean: a gust
  factor sqrt(2) ~ 1.41 on speed, drag ~ U^2), deflect the tree (linear
  statics with gravity's geometric stiffness); what a joint's spring then
  carries (gravity's moment held at rest plus k x its turn, both solvers'
  breaking moment) against its strength: no joint thicker than LIMB = 2 cm
  breaks below Beaufort 7 (13.9 m/s), and something breaks by hurricane
  force (32.7 m/s). Twigs (<= 2 cm) are reported (Beaufort 8's "twigs break
  off trees", 17.2 m/s, is their mark).
- **bend**: each joint's angle in the same gust-factored wind at the top of
  Beaufort 6 (13.9 m/s) is at most BEND_FRACTION = 0.5 of its cone, so a
  strong breeze keeps trees in the planar LOD's linear tier (which a tree
  leaves at 0.9 of a cone). How far bones turn from rest (the linear tier
  also leaves past 1 rad) is reported.

The wind blows from every azimuth in AZIMUTHS; a rule takes the worst.
`check(grammar)` gives a SpeciesCheck; `report()` the bundled species as
dicts; `format_table` prints checks. bench/species.py runs the library.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .rig import Rig, RigOptions, build_rig, depth_levels
from .scene_keys import BEAUFORT
from .statics import StaticSolver, joint_moments, wind_forces

STATIC_MARGIN = 0.4  # most a joint's own-weight moment may use of its strength
GUST = 2.0  # gust load factor on the mean wind's drag (sqrt(2) ~ 1.41 on speed)
LIMB = 0.02  # m: joints thicker than this are limbs, thinner ones twigs
BEND_FRACTION = 0.5  # most of its cone a joint may bend in a strong breeze (gusts included)
STRONG_BREEZE = BEAUFORT["near gale"]  # m/s, top of Beaufort 6 (the bend rule's wind)
NEAR_GALE = BEAUFORT["near gale"]  # m/s, Beaufort 7: no limb may break below it
GALE = BEAUFORT["gale"]  # m/s, Beaufort 8: "twigs break off trees"
HURRICANE = BEAUFORT["hurricane"]  # m/s, Beaufort 12: something must break by then
AZIMUTHS = np.arange(0.0, 360.0, 30.0)  # degrees, wind directions tried
SPEEDS = np.arange(0.0, 45.0 + 1e-9, 0.5)  # m/s, the break-speed scan (linear between:
# util grows faster than linearly with speed, so the chord errs on the low, safe side)


@dataclass
class SpeciesCheck:
    """One species' figures (SI). Speeds are the mean wind at 10 m at which
    a joint first breaks (gust factor included; inf: not in the scan)."""

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
    """The grammar's tree grown as a scene grows it (grow.grow) and
    rigged as sim.rigging rigs it at `quality`, standing at the origin."""
    from .grow import grow
    from .quality import QUALITIES
    from .scene import parse_scene

    tree = {"grammar": str(Path(grammar).resolve())}
    if seed is not None:
        tree["seed"] = seed
    scene = parse_scene({"name": "species", "tree": [tree], "quality": quality},
                        file="<species>")
    model = grow(scene)[0].model
    q = QUALITIES[quality]
    return build_rig(model, RigOptions(min_bone_length=q.bone_length * max(model.height, 1e-3)))


def first_segments(rig: Rig) -> np.ndarray:
    """The segment at each bone's base (its joint's segment)."""
    out = np.full(rig.n_bones, -1, dtype=np.int64)
    for s in range(len(rig.seg_bone) - 1, -1, -1):
        out[rig.seg_bone[s]] = s
    return out


def _grammar_path(grammar: str | Path) -> Path:
    path = Path(grammar)
    if path.suffix == ".lsys" or path.is_file():
        return path
    from .library import grammar_path

    return grammar_path(str(grammar))


def _name(path: Path) -> str:
    from .library import grammars_folder

    try:
        return path.resolve().relative_to(grammars_folder().resolve()).with_suffix("").as_posix()
    except ValueError:
        return path.stem


def bundled() -> list[str]:
    """The bundled production species (`oak`, ..., `forest/birch`; not the
    book figures of abop/)."""
    from .library import grammars

    return [e.name for e in grammars() if not e.name.startswith("abop/")]


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


def check(grammar: str | Path, seed: int | None = None, quality: str = "default",
          gust: float = GUST, speeds: np.ndarray = SPEEDS,
          azimuths: np.ndarray = AZIMUTHS, name: str | None = None) -> SpeciesCheck:
    """The species rules for one grammar's grown tree (module doc):
    `grammar` a .lsys file or a bundled name (`oak`, `forest/birch`)."""
    path = _grammar_path(grammar)
    rig = grown_rig(path, seed, quality)
    model = rig.model
    levels = depth_levels(rig.bone_depth)
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
        name=name or _name(path), grammar=str(path), height=model.height, dbh=model.dbh(),
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


def report(grammars=None, **kwargs) -> list[dict]:
    """check() of each grammar (default: every bundled species), as dicts
    ready for JSON (speeds past the scan are None)."""
    return [check(g, **kwargs).as_dict() for g in (bundled() if grammars is None else grammars)]


def format_table(checks: list[SpeciesCheck]) -> str:
    """A plain-text table of checks, one species a line: the largest static
    margin and its joint, the mean wind (m/s at 10 m, gusts included) at
    which the first limb (> 2 cm) and the first twig break, the largest
    bend / cone and turn (rad) at the top of Beaufort 6."""

    def speed(v):
        return f"{'>' + str(int(SPEEDS[-1])):>5}" if not math.isfinite(v) else f"{v:5.1f}"

    head = (f"{'species':<17} {'static':>6}  {'at (own weight)':<24} {'limb m/s':>8}  "
            f"{'first limb':<24} {'twig m/s':>8} {'bend':>5} {'turn':>5} {'ok':>3}")
    lines = [head, "-" * len(head)]
    for c in checks:
        lines.append(f"{c.name:<17} {c.static_margin:>6.2f}  {c.static_path[:24]:<24} "
                     f"{speed(c.limb_break_speed):>8}  {c.limb_break_path[:24]:<24} "
                     f"{speed(c.twig_break_speed):>8} {c.bend:>5.2f} {c.turn:>5.2f} "
                     f"{'yes' if c.passes else 'NO':>3}")
    return "\n".join(lines)
