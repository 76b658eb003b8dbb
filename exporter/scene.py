"""Scene files (TOML): trees, forces, events, camera, quality -> Scene.

Every key is validated; an error names the file, the key, the value and the
allowed range. Paths (grammars) are relative to the scene file. Units: m, s,
kg, m/s, degrees for angles. The format is documented in docs/scenes.md.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError, SceneError
from .names import MAX_TREE_NAME, is_valid, make_valid
from .sim.quality import QUALITIES, Quality

BEAUFORT = {  # m/s, lower bounds (WMO)
    "calm": 0.0, "light air": 0.3, "light breeze": 1.6, "gentle breeze": 3.4,
    "moderate breeze": 5.5, "fresh breeze": 8.0, "strong breeze": 10.8, "near gale": 13.9,
    "gale": 17.2, "strong gale": 20.8, "storm": 24.5, "violent storm": 28.5, "hurricane": 32.7,
}


@dataclass
class TreeSpec:
    grammar: Path
    name: str  # unique in the scene, a name every tool keeps (names.py)
    position: tuple[float, float] = (0.0, 0.0)  # m
    rotation: float = 0.0  # degrees about Z
    seed: int | None = None
    iterations: int | None = None
    quality: str | None = None  # per-tree override (e.g. far trees)


@dataclass
class WindSpec:
    speed: float  # m/s at reference height
    direction: float = 0.0  # degrees, the direction the wind blows toward, CCW from +X
    reference_height: float = 10.0  # m
    shear: float = 0.14
    turbulence: float = 0.0  # sigma_u / U
    length_scale: float = 50.0  # m
    start: float = 0.0  # s
    ramp: float = 2.0  # s
    end: float = math.inf  # s, the wind dies down over `ramp` s from here


@dataclass
class ExplosionSpec:
    position: tuple[float, float, float]
    time: float
    charge: float  # kg TNT equivalent


@dataclass
class VortexSpec:
    start: tuple[float, float]
    velocity: tuple[float, float]
    max_speed: float
    core_radius: float
    time: float = 0.0
    end: float = math.inf
    inflow: float = 0.5
    updraft: float = 0.5
    clockwise: bool = False


@dataclass
class AttractorSpec:
    position: tuple[float, float, float]
    strength: float
    radius: float = 1.0
    time: float = 0.0
    end: float = math.inf


@dataclass
class ProjectileSpec:
    shape: str  # "box" or "sphere"
    size: float  # m: edge of a box, diameter of a sphere
    mass: float  # kg
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    time: float = 0.0
    restitution: float = 0.2
    friction: float = 0.5


@dataclass
class CutSpec:
    tree: int
    time: float
    direction: float  # degrees, the direction the tree falls, CCW from +X
    hinge: float = 40.0  # degrees of lean at which the hinge wood snaps


@dataclass
class PullSpec:
    """A rope pull on a tree's trunk (the field pull-and-release test): a
    horizontal or any `force` (N, world) on the trunk bone at `at` x the tree
    height, rising linearly over `ramp` s, held, and released at `release` s."""

    tree: int
    force: tuple[float, float, float]
    release: float
    at: float = 0.6
    ramp: float = 1.0


@dataclass
class CameraSpec:
    """A camera moving through `keys`: (time s, position xyz m, target xyz m),
    with horizontal field of view `fov` degrees; trees outside the view
    widened by `margin` degrees for the whole shot are not simulated, trees
    beyond `far` m for the whole shot use `far_quality`."""

    keys: list[tuple[float, tuple[float, float, float], tuple[float, float, float]]]
    fov: float = 60.0
    margin: float = 10.0
    far: float = math.inf
    far_quality: str = "draft"


@dataclass
class Scene:
    name: str
    file: str
    source_hash: str
    duration: float = 10.0  # s
    fps: float = 24.0
    seed: int = 0
    gravity: float = 9.81  # m/s^2
    prestress: bool = True  # the grown shape is the equilibrium under gravity
    ground: bool = True
    quality: Quality = field(default_factory=Quality)
    trees: list[TreeSpec] = field(default_factory=list)
    wind: WindSpec | None = None
    explosions: list[ExplosionSpec] = field(default_factory=list)
    vortices: list[VortexSpec] = field(default_factory=list)
    attractors: list[AttractorSpec] = field(default_factory=list)
    projectiles: list[ProjectileSpec] = field(default_factory=list)
    cuts: list[CutSpec] = field(default_factory=list)
    pulls: list[PullSpec] = field(default_factory=list)
    camera: CameraSpec | None = None
    formats: tuple[str, ...] = ()  # exported by `treebake bake` unless --format says otherwise
    frame_start: int = 1  # the number of the first frame in every exported format

    @property
    def frame_count(self) -> int:
        return round(self.duration * self.fps) + 1


# ---------------------------------------------------------------------------
# validation helpers


class _Reader:
    def __init__(self, file: str):
        self.file = file
        self.tree_names: set[str] = set()

    def fail(self, key: str, message: str) -> SceneError:
        return SceneError(key, message, self.file)

    def table(self, data: Any, key: str) -> dict:
        if not isinstance(data, dict):
            raise self.fail(key, f"must be a table, got {type(data).__name__}")
        return data

    def check_keys(self, data: dict, path: str, allowed: set[str]) -> None:
        for k in data:
            if k not in allowed:
                raise self.fail(f"{path}{k}", f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def number(self, data: dict, key: str, path: str, default: Any = None,
               lo: float = -math.inf, hi: float = math.inf, integer: bool = False) -> Any:
        full = f"{path}{key}"
        if key not in data:
            if default is None:
                raise self.fail(full, "is required")
            return default
        v = data[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(full, f"must be a number, got {v!r}")
        if integer and int(v) != v:
            raise self.fail(full, f"must be a whole number, got {v!r}")
        if not (lo <= v <= hi) or (isinstance(v, float) and math.isnan(v)):
            raise self.fail(full, f"= {v!r} is out of range [{lo:g}, {hi:g}]")
        return int(v) if integer else float(v)

    def boolean(self, data: dict, key: str, path: str, default: bool) -> bool:
        v = data.get(key, default)
        if not isinstance(v, bool):
            raise self.fail(f"{path}{key}", f"must be true or false, got {v!r}")
        return v

    def string(self, data: dict, key: str, path: str, default: str | None = None,
               choices: tuple[str, ...] | None = None) -> str:
        full = f"{path}{key}"
        if key not in data:
            if default is None:
                raise self.fail(full, "is required")
            return default
        v = data[key]
        if not isinstance(v, str):
            raise self.fail(full, f"must be a string, got {v!r}")
        if choices and v not in choices:
            raise self.fail(full, f"= {v!r} is not one of: {', '.join(choices)}")
        return v

    def vector(self, data: dict, key: str, path: str, n: int, default=None,
               lo: float = -1e6, hi: float = 1e6) -> tuple:
        full = f"{path}{key}"
        if key not in data:
            if default is None:
                raise self.fail(full, "is required")
            return tuple(default)
        v = data[key]
        if not isinstance(v, list) or len(v) != n or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            raise self.fail(full, f"must be a list of {n} numbers, got {v!r}")
        for x in v:
            if not lo <= x <= hi:
                raise self.fail(full, f"value {x!r} is out of range [{lo:g}, {hi:g}]")
        return tuple(float(x) for x in v)


def load_scene(path: str | Path, overrides: dict | None = None) -> Scene:
    """Read and validate a scene file. `overrides` replace top-level keys
    (and `wind.speed`) before validation, so they are checked the same way."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise SceneError("(file)", f"cannot read scene: {exc.strerror}", str(p)) from None
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise SceneError("(file)", "not valid UTF-8", str(p)) from None
    except tomllib.TOMLDecodeError as exc:
        raise SceneError("(syntax)", str(exc), str(p)) from None
    digest = hashlib.sha256(data)
    if overrides:
        raw = dict(raw)
        for key, value in overrides.items():
            if key == "wind.speed":
                if isinstance(raw.get("wind"), dict):
                    raw["wind"] = {k: v for k, v in raw["wind"].items() if k != "beaufort"}
                    raw["wind"]["speed"] = value
            else:
                raw[key] = value
        digest.update(repr(sorted(overrides.items())).encode())
    return parse_scene(raw, file=str(p), base=p.parent, source_hash=digest.hexdigest())


def load_job(path: str | Path, overrides: dict | None = None) -> Scene:
    """A scene file, or a grammar (.lsys) baked alone in a default scene: a
    gusty moderate breeze (6.7 m/s at 10 m, turbulence 0.25) unless
    `overrides["wind.speed"]` says otherwise. Overrides are checked like
    the file's own keys."""
    p = Path(path)
    overrides = dict(overrides or {})
    if p.suffix != ".lsys":
        return load_scene(p, overrides)
    if not p.is_file():
        raise InputError(f"{p}: grammar file not found")
    raw = {"name": p.stem, "tree": [{"grammar": str(p.resolve())}],
           "wind": {"speed": overrides.pop("wind.speed", 6.7), "turbulence": 0.25}}
    raw.update(overrides)
    return parse_scene(raw, file=str(p))


def parse_scene(raw: dict, file: str = "<scene>", base: Path = Path("."),
                source_hash: str = "") -> Scene:
    r = _Reader(file)
    top = {"name", "duration", "fps", "seed", "gravity", "prestress", "ground", "quality",
           "tree", "forest", "wind", "explosion", "vortex", "attractor", "projectile", "cut",
           "pull", "camera", "formats", "frame_start"}
    r.check_keys(raw, "", top)
    scene = Scene(
        name=r.string(raw, "name", "", Path(file).stem),
        file=file,
        source_hash=source_hash,
        duration=r.number(raw, "duration", "", 10.0, 0.0, 3600.0),
        fps=r.number(raw, "fps", "", 24.0, 1.0, 1000.0),
        seed=r.number(raw, "seed", "", 0, 0, 2**63 - 1, integer=True),
        gravity=r.number(raw, "gravity", "", 9.81, 0.0, 100.0),
        prestress=r.boolean(raw, "prestress", "", True),
        ground=r.boolean(raw, "ground", "", True),
        frame_start=r.number(raw, "frame_start", "", 1, 0, 1_000_000, integer=True),
    )
    scene.quality = _quality(r, raw.get("quality", "default"))
    formats = raw.get("formats", [])
    allowed_formats = ("glb", "gltf", "obj", "usd", "usda", "preview", "npz")
    if not isinstance(formats, list) or not all(f in allowed_formats for f in formats):
        raise r.fail("formats", f"must be a list of: {', '.join(allowed_formats)}; got {formats!r}")
    scene.formats = tuple(formats)

    for i, t in enumerate(_array(r, raw, "tree")):
        scene.trees.append(_tree(r, t, f"tree[{i}].", base))
    if "forest" in raw:
        scene.trees.extend(_forest(r, r.table(raw["forest"], "forest"), base, scene.seed,
                                   len(scene.trees)))
    if not scene.trees:
        raise r.fail("tree", "the scene has no trees: add [[tree]] tables or a [forest]")
    if len(scene.trees) > 5000:
        raise r.fail("forest.count", f"{len(scene.trees)} trees is more than the limit of 5000")
    _name_trees(scene.trees)

    if "wind" in raw:
        scene.wind = _wind(r, r.table(raw["wind"], "wind"))
    for i, e in enumerate(_array(r, raw, "explosion")):
        p = f"explosion[{i}]."
        r.check_keys(e, p, {"position", "time", "charge"})
        scene.explosions.append(ExplosionSpec(
            r.vector(e, "position", p, 3), r.number(e, "time", p, 0.0, 0.0, 3600.0),
            r.number(e, "charge", p, None, 0.001, 1e6)))
    for i, v in enumerate(_array(r, raw, "vortex")):
        p = f"vortex[{i}]."
        r.check_keys(v, p, {"start", "velocity", "max_speed", "core_radius", "time", "end",
                            "inflow", "updraft", "clockwise"})
        scene.vortices.append(VortexSpec(
            r.vector(v, "start", p, 2), r.vector(v, "velocity", p, 2, (0, 0), -200, 200),
            r.number(v, "max_speed", p, None, 0.0, 150.0),
            r.number(v, "core_radius", p, None, 1.0, 2000.0),
            r.number(v, "time", p, 0.0, 0.0, 3600.0), r.number(v, "end", p, math.inf, 0.0),
            r.number(v, "inflow", p, 0.5, 0.0, 2.0), r.number(v, "updraft", p, 0.5, 0.0, 2.0),
            r.boolean(v, "clockwise", p, False)))
        _check_interval(r, scene.vortices[-1], p)
    for i, a in enumerate(_array(r, raw, "attractor")):
        p = f"attractor[{i}]."
        r.check_keys(a, p, {"position", "strength", "radius", "time", "end"})
        scene.attractors.append(AttractorSpec(
            r.vector(a, "position", p, 3), r.number(a, "strength", p, None, -1000.0, 1000.0),
            r.number(a, "radius", p, 1.0, 0.01, 1000.0), r.number(a, "time", p, 0.0, 0.0),
            r.number(a, "end", p, math.inf, 0.0)))
        _check_interval(r, scene.attractors[-1], p)
    for i, b in enumerate(_array(r, raw, "projectile")):
        p = f"projectile[{i}]."
        r.check_keys(b, p, {"shape", "size", "mass", "position", "velocity", "time",
                            "restitution", "friction"})
        scene.projectiles.append(ProjectileSpec(
            r.string(b, "shape", p, "box", ("box", "sphere")),
            r.number(b, "size", p, None, 0.01, 10.0), r.number(b, "mass", p, None, 0.01, 1e5),
            r.vector(b, "position", p, 3), r.vector(b, "velocity", p, 3, (0, 0, 0), -500, 500),
            r.number(b, "time", p, 0.0, 0.0, 3600.0),
            r.number(b, "restitution", p, 0.2, 0.0, 1.0),
            r.number(b, "friction", p, 0.5, 0.0, 2.0)))
    for i, c in enumerate(_array(r, raw, "cut")):
        p = f"cut[{i}]."
        r.check_keys(c, p, {"tree", "time", "direction", "hinge"})
        scene.cuts.append(CutSpec(
            r.number(c, "tree", p, 0, 0, len(scene.trees) - 1, integer=True),
            r.number(c, "time", p, 0.0, 0.0, 3600.0), r.number(c, "direction", p, 0.0, -360, 360),
            r.number(c, "hinge", p, 40.0, 5.0, 89.0)))
    for i, c in enumerate(_array(r, raw, "pull")):
        p = f"pull[{i}]."
        r.check_keys(c, p, {"tree", "force", "release", "at", "ramp"})
        release = r.number(c, "release", p, None, 0.0, 3600.0)
        scene.pulls.append(PullSpec(
            r.number(c, "tree", p, 0, 0, len(scene.trees) - 1, integer=True),
            r.vector(c, "force", p, 3, None, -1e7, 1e7), release,
            r.number(c, "at", p, 0.6, 0.01, 1.0), r.number(c, "ramp", p, min(1.0, release),
                                                          0.0, release)))
    if "camera" in raw:
        scene.camera = _camera(r, r.table(raw["camera"], "camera"))
    return scene


def _check_interval(r: _Reader, spec, p: str) -> None:
    if spec.end < spec.time:
        raise r.fail(f"{p}end", f"= {spec.end:g} s is before time ({spec.time:g} s)")


def _array(r: _Reader, raw: dict, key: str) -> list[dict]:
    v = raw.get(key, [])
    if isinstance(v, dict):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise r.fail(key, f"must be an array of tables ([[{key}]])")
    return v


def _quality(r: _Reader, q: Any) -> Quality:
    if isinstance(q, str):
        if q not in QUALITIES:
            raise r.fail("quality", f"= {q!r} is not one of: {', '.join(QUALITIES)}")
        return QUALITIES[q]
    q = r.table(q, "quality")
    p = "quality."
    r.check_keys(q, p, {"base", "substep_rate", "force_rate", "iterations", "planes",
                        "bone_length", "stability", "joint_correction", "coupling"})
    base = QUALITIES[r.string(q, "base", p, "default", tuple(QUALITIES))]
    out = Quality(
        name="custom",
        substep_rate=r.number(q, "substep_rate", p, base.substep_rate, 60.0, 100_000.0),
        force_rate=r.number(q, "force_rate", p, base.force_rate, 1.0, 100_000.0),
        iterations=r.number(q, "iterations", p, base.iterations, 1, 1000, integer=True),
        planes=r.number(q, "planes", p, base.planes, 1, 2, integer=True),
        bone_length=r.number(q, "bone_length", p, base.bone_length, 0.0, 0.5),
        stability=r.number(q, "stability", p, base.stability, 0.1, 2.0),
        joint_correction=r.number(q, "joint_correction", p, base.joint_correction, 0.0, 0.4),
        coupling=r.string(q, "coupling", p, base.coupling, ("apparent", "rigid")),
    )
    if out.force_rate > out.substep_rate:
        raise r.fail("quality.force_rate", f"= {out.force_rate:g} Hz must not exceed "
                     f"substep_rate ({out.substep_rate:g} Hz)")
    return out


def _name_trees(trees: list[TreeSpec]) -> None:
    """Trees without a `name` are named after their grammar file (`oak`;
    `oak_1`, `oak_2`, ... when several share it), never taking a given name."""
    taken = {t.name for t in trees if t.name}
    stems = [make_valid(t.grammar.stem) for t in trees]
    count: dict[str, int] = {}
    for t, stem in zip(trees, stems):
        if not t.name:
            count[stem] = count.get(stem, 0) + 1
    seen: dict[str, int] = {}
    for t, stem in zip(trees, stems):
        if t.name:
            continue
        name = stem if count[stem] == 1 and stem not in taken else None
        while name is None or name in taken:
            seen[stem] = seen.get(stem, 0) + 1
            name = f"{stem}_{seen[stem]}"
        t.name = name
        taken.add(name)


def _tree_name(r: _Reader, t: dict, p: str, given: set[str]) -> str:
    if "name" not in t:
        return ""
    name = r.string(t, "name", p)
    if not is_valid(name) or len(name) > MAX_TREE_NAME:
        raise r.fail(f"{p}name", f"= {name!r} must be ASCII letters, digits and _, starting "
                     f"with a letter or _, at most {MAX_TREE_NAME} characters (names that "
                     "three.js, Blender, Maya, Houdini and USD keep unchanged)")
    if name in given:
        raise r.fail(f"{p}name", f"= {name!r} is already another tree's name")
    given.add(name)
    return name


def _tree(r: _Reader, t: dict, p: str, base: Path) -> TreeSpec:
    r.check_keys(t, p, {"grammar", "name", "position", "rotation", "seed", "iterations",
                        "quality"})
    grammar = base / r.string(t, "grammar", p)
    if not grammar.is_file():
        raise r.fail(f"{p}grammar", f"file not found: {grammar}")
    q = t.get("quality")
    if q is not None and q not in QUALITIES:
        raise r.fail(f"{p}quality", f"= {q!r} is not one of: {', '.join(QUALITIES)}")
    return TreeSpec(
        grammar=grammar,
        name=_tree_name(r, t, p, r.tree_names),
        position=r.vector(t, "position", p, 2, (0.0, 0.0)),
        rotation=r.number(t, "rotation", p, 0.0, -360.0, 360.0),
        seed=r.number(t, "seed", p, -1, 0, 2**63 - 1, integer=True) if "seed" in t else None,
        iterations=r.number(t, "iterations", p, 0, 0, 1000, integer=True)
        if "iterations" in t else None,
        quality=q,
    )


def _forest(r: _Reader, f: dict, base: Path, scene_seed: int, first: int) -> list[TreeSpec]:
    p = "forest."
    r.check_keys(f, p, {"grammars", "count", "area", "center", "min_spacing", "seed",
                        "iterations"})
    grammars = f.get("grammars")
    if not isinstance(grammars, list) or not grammars or not all(
            isinstance(g, str) for g in grammars):
        raise r.fail(f"{p}grammars", "must be a non-empty list of grammar file paths")
    paths = []
    for g in grammars:
        path = base / g
        if not path.is_file():
            raise r.fail(f"{p}grammars", f"file not found: {path}")
        paths.append(path)
    count = r.number(f, "count", p, None, 0, 5000, integer=True)
    area = r.vector(f, "area", p, 2, None, 1.0, 1e5)
    center = r.vector(f, "center", p, 2, (0.0, 0.0))
    spacing = r.number(f, "min_spacing", p, 3.0, 0.0, 1000.0)
    seed = r.number(f, "seed", p, scene_seed, 0, 2**63 - 1, integer=True)
    iterations = f.get("iterations")
    if iterations is not None:
        iterations = r.number(f, "iterations", p, 0, 0, 1000, integer=True)
    rng = np.random.default_rng(seed)
    points = _scatter(rng, count, area, spacing)
    if len(points) < count:
        raise r.fail(f"{p}count", f"only {len(points)} of {count} trees fit in area {area} m "
                     f"with min_spacing {spacing} m; enlarge the area or lower the spacing")
    out = []
    for i, (x, y) in enumerate(points):
        out.append(TreeSpec(grammar=paths[i % len(paths)], name="",
                            position=(center[0] + x, center[1] + y),
                            rotation=float(rng.uniform(0, 360)), seed=int(rng.integers(2**31)),
                            iterations=iterations))
    return out


def _scatter(rng: np.random.Generator, count: int, area, spacing: float) -> list:
    """Seeded dart throwing: uniform positions at least `spacing` apart."""
    w, h = area
    pts: list[tuple[float, float]] = []
    cell = spacing / math.sqrt(2) if spacing > 0 else 1.0
    grid: dict[tuple[int, int], tuple[float, float]] = {}
    attempts = 0
    while len(pts) < count and attempts < 200 * max(count, 1):
        attempts += 1
        x, y = rng.uniform(-w / 2, w / 2), rng.uniform(-h / 2, h / 2)
        if spacing > 0:
            gx, gy = math.floor(x / cell), math.floor(y / cell)
            ok = True
            for dx in range(-2, 3):
                for dy in range(-2, 3):
                    q = grid.get((gx + dx, gy + dy))
                    if q is not None and (q[0] - x) ** 2 + (q[1] - y) ** 2 < spacing**2:
                        ok = False
                        break
                if not ok:
                    break
            if not ok:
                continue
            grid[(gx, gy)] = (x, y)
        pts.append((x, y))
    return pts


def _wind(r: _Reader, w: dict) -> WindSpec:
    p = "wind."
    r.check_keys(w, p, {"speed", "beaufort", "direction", "reference_height", "shear",
                        "turbulence", "length_scale", "start", "ramp", "end"})
    if "beaufort" in w:
        name = r.string(w, "beaufort", p, choices=tuple(BEAUFORT))
        if "speed" in w:
            raise r.fail(f"{p}beaufort", "give either speed or beaufort, not both")
        names = list(BEAUFORT)
        i = names.index(name)
        hi = BEAUFORT[names[i + 1]] if i + 1 < len(names) else BEAUFORT[name] + 10
        speed = 0.5 * (BEAUFORT[name] + hi)
    else:
        speed = r.number(w, "speed", p, None, 0.0, 120.0)
    spec = WindSpec(
        speed=speed,
        direction=r.number(w, "direction", p, 0.0, -360.0, 360.0),
        reference_height=r.number(w, "reference_height", p, 10.0, 1.0, 500.0),
        shear=r.number(w, "shear", p, 0.14, 0.0, 0.6),
        turbulence=r.number(w, "turbulence", p, 0.0, 0.0, 1.0),
        length_scale=r.number(w, "length_scale", p, 50.0, 1.0, 2000.0),
        start=r.number(w, "start", p, 0.0, 0.0, 3600.0),
        ramp=r.number(w, "ramp", p, 2.0, 0.0, 600.0),
        end=r.number(w, "end", p, math.inf, 0.0),
    )
    if spec.end < spec.start:
        raise r.fail(f"{p}end", f"= {spec.end:g} s is before start ({spec.start:g} s)")
    return spec


def _camera(r: _Reader, c: dict) -> CameraSpec:
    p = "camera."
    r.check_keys(c, p, {"keys", "fov", "margin", "far", "far_quality"})
    keys_raw = c.get("keys")
    if not isinstance(keys_raw, list) or not keys_raw:
        raise r.fail(f"{p}keys", "must be a non-empty array of {time, position, target} tables")
    keys = []
    last = -math.inf
    for i, k in enumerate(keys_raw):
        kp = f"{p}keys[{i}]."
        if not isinstance(k, dict):
            raise r.fail(f"{p}keys[{i}]", "must be a table {time, position, target}")
        r.check_keys(k, kp, {"time", "position", "target"})
        t = r.number(k, "time", kp, None, 0.0, 3600.0)
        if t <= last:
            raise r.fail(f"{kp}time", f"= {t:g} must be later than the previous key ({last:g})")
        last = t
        keys.append((t, r.vector(k, "position", kp, 3), r.vector(k, "target", kp, 3)))
    return CameraSpec(
        keys=keys,
        fov=r.number(c, "fov", p, 60.0, 1.0, 179.0),
        margin=r.number(c, "margin", p, 10.0, 0.0, 90.0),
        far=r.number(c, "far", p, math.inf, 1.0),
        far_quality=r.string(c, "far_quality", p, "draft", tuple(QUALITIES)),
    )
