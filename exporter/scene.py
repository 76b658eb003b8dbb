"""Scene files (TOML): trees, forces, events, camera, quality -> Scene.

Every key is validated against its entry in scene_keys.py (meaning, unit,
default, range: the one source docs/scenes.md is generated from); an error
names the file, the key, the value and the allowed range. Paths (grammars)
are relative to the scene file. Units: m, s, kg, m/s, degrees for angles.
A key the table marks `keyed` takes a value or a list of keys {time, value}
(keys.Keyed; docs/scenes.md, "Keys"), each key checked like a plain value
and its time within the shot.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import library, loop
from .errors import InputError, SceneError
from .keys import Keyed
from .names import MAX_TREE_NAME, is_valid, make_valid
from .quality import QUALITIES, Quality
from .scene_flows import DownwashSpec, GustSpec, read_downwash, read_gust
from .scene_keys import (
    ATTRACTOR,
    BEAUFORT,
    CAMERA,
    CAMERA_KEY,
    CUT,
    EXPLOSION,
    FOREST,
    MAX_TREES,
    PROJECTILE,
    PULL,
    QUALITY,
    TOP,
    TREE,
    VORTEX,
    WIND,
)
from .scene_reader import INTERPOLATION, SceneReader, is_keys

__all__ = ["BEAUFORT", "Scene", "load_job", "load_scene", "parse_scene"]

# Defaults below come from scene_keys.py (the one table of keys, units,
# defaults and ranges); these records are what the parser hands on.


@dataclass
class TreeSpec:
    grammar: Path
    name: str  # unique in the scene, a name every tool keeps (names.py)
    position: tuple[float, float] = TREE["position"].default  # m
    rotation: float = TREE["rotation"].default  # degrees about Z
    seed: int | None = TREE["seed"].default
    iterations: int | None = TREE["iterations"].default
    quality: str | None = TREE["quality"].default  # per-tree override (e.g. far trees)
    phase: float | None = None  # s, a loop's offset (None: a forest's tree, drawn by loop.py)


# A keyed key's field holds a plain value, or a keys.Keyed curve through its keys.
@dataclass
class WindSpec:
    speed: float | Keyed  # m/s at reference height
    direction: float | Keyed = WIND["direction"].default  # degrees, blowing toward, CCW from +X
    reference_height: float = WIND["reference_height"].default  # m
    shear: float = WIND["shear"].default
    turbulence: float | Keyed = WIND["turbulence"].default  # sigma_u / U
    length_scale: float = WIND["length_scale"].default  # m
    start: float = WIND["start"].default  # s
    ramp: float = WIND["ramp"].default  # s
    end: float = WIND["end"].default  # s, the wind dies down over `ramp` s from here


@dataclass
class ExplosionSpec:
    position: tuple[float, float, float]
    time: float
    charge: float  # kg TNT equivalent


@dataclass
class VortexSpec:
    start: tuple[float, float] | None  # m; None: the centre follows `path`
    velocity: tuple[float, float]  # m/s
    max_speed: float | Keyed  # m/s
    core_radius: float | Keyed  # m
    path: Keyed | None = VORTEX["path"].default  # (x, y) m over the shot
    time: float = VORTEX["time"].default
    end: float = VORTEX["end"].default
    inflow: float = VORTEX["inflow"].default
    updraft: float = VORTEX["updraft"].default
    clockwise: bool = VORTEX["clockwise"].default


@dataclass
class AttractorSpec:
    position: tuple[float, float, float] | Keyed  # m
    strength: float | Keyed  # m/s^2
    radius: float = ATTRACTOR["radius"].default
    time: float = ATTRACTOR["time"].default
    end: float = ATTRACTOR["end"].default


@dataclass
class ProjectileSpec:
    shape: str  # "box" or "sphere"
    size: float  # m: edge of a box, diameter of a sphere
    mass: float  # kg
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    time: float = PROJECTILE["time"].default
    restitution: float = PROJECTILE["restitution"].default
    friction: float = PROJECTILE["friction"].default


@dataclass
class CutSpec:
    tree: int
    time: float
    direction: float  # degrees, the direction the tree falls, CCW from +X
    hinge: float = CUT["hinge"].default  # degrees of lean at which the hinge wood snaps


@dataclass
class PullSpec:
    """A rope pull on a tree's trunk (the field pull-and-release test): a
    horizontal or any `force` (N, world) on the trunk bone at `at` x the tree
    height, rising linearly over `ramp` s, held, and released at `release` s."""

    tree: int
    force: tuple[float, float, float]
    release: float
    at: float = PULL["at"].default
    ramp: float = 1.0  # s; parsed: min(1, release)


@dataclass
class CameraSpec:
    """A camera moving through `keys`: (time s, position xyz m, target xyz m),
    with horizontal field of view `fov` degrees; trees outside the view
    widened by `margin` degrees for the whole shot are not simulated, trees
    beyond `far` m for the whole shot use `far_quality`."""

    keys: list[tuple[float, tuple[float, float, float], tuple[float, float, float]]]
    fov: float = CAMERA["fov"].default
    margin: float = CAMERA["margin"].default
    far: float = CAMERA["far"].default
    far_quality: str = CAMERA["far_quality"].default


@dataclass
class Scene:
    name: str
    file: str
    source_hash: str
    duration: float = TOP["duration"].default  # s
    fps: float = TOP["fps"].default
    seed: int = TOP["seed"].default
    gravity: float = TOP["gravity"].default  # m/s^2
    prestress: bool = TOP["prestress"].default  # the grown shape is the equilibrium under gravity
    ground: bool = TOP["ground"].default
    quality: Quality = field(default_factory=Quality)
    trees: list[TreeSpec] = field(default_factory=list)
    wind: WindSpec | None = TOP["wind"].default
    explosions: list[ExplosionSpec] = field(default_factory=list)
    vortices: list[VortexSpec] = field(default_factory=list)
    gusts: list[GustSpec] = field(default_factory=list)
    downwashes: list[DownwashSpec] = field(default_factory=list)
    attractors: list[AttractorSpec] = field(default_factory=list)
    projectiles: list[ProjectileSpec] = field(default_factory=list)
    cuts: list[CutSpec] = field(default_factory=list)
    pulls: list[PullSpec] = field(default_factory=list)
    camera: CameraSpec | None = TOP["camera"].default
    formats: tuple[str, ...] = TOP["formats"].default  # `treebake bake` exports (--format wins)
    frame_start: int = TOP["frame_start"].default  # number of frame 0 in every exported format
    loop: bool = TOP["loop"].default  # a seamless loop of `duration` (loop.py)

    @property
    def frame_count(self) -> int:
        return round(self.duration * self.fps) + 1


def with_wind_speed(wind: Any, speed: Any) -> Any:
    """A `[wind]` table with its speed (m/s at 10 m) replaced by `speed`:
    its `beaufort` and either's keys' interpolation go (the override is
    one value for the whole shot). Anything but a table is left as it is."""
    if not isinstance(wind, dict):
        return wind
    gone = ("beaufort", f"beaufort{INTERPOLATION}", f"speed{INTERPOLATION}")
    return {**{k: v for k, v in wind.items() if k not in gone}, "speed": speed}


def key_horizon(raw: dict, overrides: dict) -> float | None:
    """The shot the keys' times are checked against when `overrides`
    change the duration: the longer of the file's and the override's (a
    shorter --duration bakes the start of the keyed curves, it does not
    make the file wrong); None when the duration is not overridden."""
    if "duration" not in overrides:
        return None
    given = raw.get("duration", TOP["duration"].default)
    if isinstance(given, bool) or not isinstance(given, (int, float)):
        return None
    return min(float(given), TOP["duration"].hi)


def load_scene(path: str | Path, overrides: dict | None = None) -> Scene:
    """Read and validate a scene file. `overrides` replace top-level keys
    (and `wind.speed`) before validation, so they are checked the same way
    (keys' times against the file's own duration: key_horizon)."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder, not a scene file")
    if not p.exists():
        raise InputError(f"{p}: scene file not found")
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
    except RecursionError:  # arrays or tables nested hundreds deep
        raise SceneError("(syntax)", "nested too deep to be a scene", str(p)) from None
    digest = hashlib.sha256(data)
    horizon = None
    if overrides:
        horizon = key_horizon(raw, overrides)
        raw = dict(raw)
        for key, value in overrides.items():
            if key == "wind.speed":  # a scene without [wind] gets one (as a batch job does)
                raw["wind"] = with_wind_speed(raw.get("wind", {}), value)
            else:
                raw[key] = value
        digest.update(repr(sorted(overrides.items())).encode())
    return parse_scene(raw, file=str(p), base=p.parent, source_hash=digest.hexdigest(),
                       horizon=horizon)


def load_job(path: str | Path, overrides: dict | None = None) -> Scene:
    """A scene file, or a grammar (.lsys) baked alone in a default scene: a
    gusty moderate breeze (6.7 m/s at 10 m, turbulence 0.25) unless
    `overrides["wind.speed"]` says otherwise. Overrides are checked like
    the file's own keys."""
    p = Path(path)
    overrides = dict(overrides or {})
    if p.suffix != ".lsys":
        return load_scene(p, overrides)
    if p.is_dir():
        raise InputError(f"{p}: is a folder, not a grammar file")
    if not p.is_file():
        raise InputError(f"{p}: grammar file not found")
    raw = {"name": p.stem, "tree": [{"grammar": str(p.resolve())}],
           "wind": {"speed": overrides.pop("wind.speed", 6.7), "turbulence": 0.25}}
    raw.update(overrides)
    return parse_scene(raw, file=str(p))


def parse_scene(raw: dict, file: str = "<scene>", base: Path = Path("."),
                source_hash: str = "", horizon: float | None = None) -> Scene:
    """A Scene from a scene file's table. Keys' times must lie within the
    shot, 0 to `duration` s (or to `horizon` s where that is longer: the
    file's duration when an override shortened it, key_horizon)."""
    r = SceneReader(file)
    r.check_keys(raw, "", TOP)
    scene = Scene(
        name=r.key(raw, TOP["name"], "", Path(file).stem),
        file=file,
        source_hash=source_hash,
        **{k: r.key(raw, TOP[k], "") for k in ("duration", "fps", "frame_start", "seed",
                                                "gravity", "prestress", "ground", "loop")},
    )
    r.horizon = scene.duration if horizon is None else max(scene.duration, horizon)
    scene.quality = _quality(r, raw.get("quality", TOP["quality"].default))
    formats = raw.get("formats", [])
    allowed_formats = TOP["formats"].choices
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
    if len(scene.trees) > MAX_TREES:
        raise r.fail("forest.count", f"{len(scene.trees)} trees is more than the limit of "
                     f"{MAX_TREES}")
    _name_trees(scene.trees)

    if "wind" in raw:
        scene.wind = _wind(r, r.table(raw["wind"], "wind"))
    for i, e in enumerate(_array(r, raw, "explosion")):
        scene.explosions.append(ExplosionSpec(**r.keys(e, EXPLOSION, f"explosion[{i}].")))
    for i, v in enumerate(_array(r, raw, "vortex")):
        p = f"vortex[{i}]."
        scene.vortices.append(_vortex(r, v, p))
        _check_interval(r, scene.vortices[-1], p)
    for i, g in enumerate(_array(r, raw, "gust")):
        scene.gusts.append(read_gust(r, g, f"gust[{i}]."))
    for i, d in enumerate(_array(r, raw, "downwash")):
        scene.downwashes.append(read_downwash(r, d, f"downwash[{i}]."))
    for i, a in enumerate(_array(r, raw, "attractor")):
        p = f"attractor[{i}]."
        scene.attractors.append(AttractorSpec(**r.keys(a, ATTRACTOR, p)))
        _check_interval(r, scene.attractors[-1], p)
    for i, b in enumerate(_array(r, raw, "projectile")):
        scene.projectiles.append(ProjectileSpec(**r.keys(b, PROJECTILE, f"projectile[{i}].")))
    last_tree = len(scene.trees) - 1
    for i, c in enumerate(_array(r, raw, "cut")):
        p = f"cut[{i}]."
        r.check_keys(c, p, CUT)
        scene.cuts.append(CutSpec(**r.keys(c, CUT, p, tree=r.key(c, CUT["tree"], p,
                                                                    hi=last_tree))))
    for i, c in enumerate(_array(r, raw, "pull")):
        p = f"pull[{i}]."
        r.check_keys(c, p, PULL)
        release = r.key(c, PULL["release"], p)
        scene.pulls.append(PullSpec(**r.keys(
            c, PULL, p, tree=r.key(c, PULL["tree"], p, hi=last_tree),
            ramp=r.key(c, PULL["ramp"], p, min(1.0, release), hi=release))))
    if "camera" in raw:
        scene.camera = _camera(r, r.table(raw["camera"], "camera"))
    loop.validate(scene, raw, r.fail, TOP)
    return scene


def _vortex(r: SceneReader, v: dict, p: str) -> VortexSpec:
    """A vortex: its centre from `start` (and `velocity`) or from `path`."""
    spec = VortexSpec(**r.keys(v, VORTEX, p))
    if spec.path is None and spec.start is None:
        raise r.fail(f"{p}start", "is required (or give path)")
    if spec.path is not None:
        if "start" in v or "velocity" in v:
            raise r.fail(f"{p}path", "give either path or start and velocity, not both")
        if not isinstance(spec.path, Keyed):  # a fixed centre
            spec.path = Keyed.constant(spec.path)
    return spec


def _check_interval(r: SceneReader, spec, p: str) -> None:
    if spec.end < spec.time:
        raise r.fail(f"{p}end", f"= {spec.end:g} s is before time ({spec.time:g} s)")


def _array(r: SceneReader, raw: dict, key: str) -> list[dict]:
    v = raw.get(key, [])
    if isinstance(v, dict):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise r.fail(key, f"must be an array of tables ([[{key}]])")
    return v


REMOVED_QUALITY_KEYS = {  # keys of older scenes, and what became of them
    "cut_engine": "every cut goes to the MuJoCo reference (`nonlinear = \"pymunk\"` for the "
                  "pymunk tier; docs/physics.md, \"Which engine takes a tree\")",
    "articulated_step": "the articulated tier is gone (MuJoCo is a dependency)",
}


def _quality(r: SceneReader, q: Any) -> Quality:
    if isinstance(q, str):
        if q not in QUALITIES:
            raise r.fail("quality", f"= {q!r} is not one of: {', '.join(QUALITIES)}")
        return QUALITIES[q]
    q = r.table(q, "quality")
    p = "quality."
    for key, why in REMOVED_QUALITY_KEYS.items():
        if key in q:
            raise r.fail(f"{p}{key}", f"removed in treebake 0.2: {why}")
    if q.get("nonlinear") == "articulated":
        raise r.fail(f"{p}nonlinear", "= 'articulated': removed in treebake 0.2 with the "
                     "articulated tier (MuJoCo is a dependency; docs/physics.md, \"Which engine "
                     "takes a tree\")")
    r.check_keys(q, p, QUALITY)
    base = QUALITIES[r.key(q, QUALITY["base"], p)]
    # every key defaults to the base level's value
    values = {k: r.key(q, spec, p, getattr(base, k)) for k, spec in QUALITY.items()
              if k != "base"}
    out = Quality(name="custom", **values)
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


def _tree_name(r: SceneReader, t: dict, p: str, given: set[str]) -> str:
    if "name" not in t:
        return ""
    name = r.key(t, TREE["name"], p)
    if name is None:
        raise r.fail(f"{p}name", "is required")
    if not is_valid(name) or len(name) > MAX_TREE_NAME:
        raise r.fail(f"{p}name", f"= {name!r} must be ASCII letters, digits and _, starting "
                     f"with a letter or _, at most {MAX_TREE_NAME} characters (names that "
                     "three.js, Blender, Maya, Houdini and USD keep unchanged)")
    if name in given:
        raise r.fail(f"{p}name", f"= {name!r} is already another tree's name")
    given.add(name)
    return name


def _grammar_file(r: SceneReader, value: str, key: str, base: Path) -> Path:
    """A scene's grammar: a file relative to the scene, else a bundled
    grammar named as on the command line (`oak`, `grammar:forest/birch`)."""
    path = base / value
    if path.is_file():
        return path
    if value.startswith(library.GRAMMAR_PREFIX) or not Path(value).suffix:
        try:
            return library.grammar_path(value.removeprefix(library.GRAMMAR_PREFIX))
        except InputError:
            pass
    raise r.fail(key, f"file not found: {path} (nor a bundled grammar of that name: "
                      "`treebake list` shows them)")


def _tree(r: SceneReader, t: dict, p: str, base: Path) -> TreeSpec:
    r.check_keys(t, p, TREE)
    grammar = _grammar_file(r, r.key(t, TREE["grammar"], p), f"{p}grammar", base)
    return TreeSpec(**r.keys(t, TREE, p, grammar=grammar,
                             name=_tree_name(r, t, p, r.tree_names)))


def _forest(r: SceneReader, f: dict, base: Path, scene_seed: int, first: int) -> list[TreeSpec]:
    p = "forest."
    r.check_keys(f, p, FOREST)
    grammars = f.get("grammars")
    if not isinstance(grammars, list) or not grammars or not all(
            isinstance(g, str) for g in grammars):
        raise r.fail(f"{p}grammars", "must be a non-empty list of grammar file paths")
    paths = [_grammar_file(r, g, f"{p}grammars", base) for g in grammars]
    count = r.key(f, FOREST["count"], p)
    area = r.key(f, FOREST["area"], p)
    center = r.key(f, FOREST["center"], p)
    spacing = r.key(f, FOREST["min_spacing"], p)
    seed = r.key(f, FOREST["seed"], p, scene_seed)
    iterations = r.key(f, FOREST["iterations"], p)
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


def beaufort_speed(name: str) -> float:
    """The middle of a WMO Beaufort band (m/s at 10 m); the top band's is
    5 m/s above its lower bound."""
    names = list(BEAUFORT)
    i = names.index(name)
    hi = BEAUFORT[names[i + 1]] if i + 1 < len(names) else BEAUFORT[name] + 10
    return 0.5 * (BEAUFORT[name] + hi)


def _wind(r: SceneReader, w: dict) -> WindSpec:
    p = "wind."
    r.check_keys(w, p, WIND)
    if "beaufort" in w:
        if "speed" in w:
            raise r.fail(f"{p}beaufort", "give either speed or beaufort, not both")
        if is_keys(w["beaufort"]):  # keys of band names: of their middle speeds
            speed = r.keyed(w, WIND["beaufort"], p, convert=beaufort_speed)
        else:
            speed = beaufort_speed(r.key(w, WIND["beaufort"], p))
    else:
        speed = r.key(w, WIND["speed"], p)
        if speed is None:
            raise r.fail(f"{p}speed", "is required (or give beaufort)")
    values = r.keys(w, WIND, p, speed=speed, beaufort=None)
    values.pop("beaufort")
    spec = WindSpec(**values)
    if spec.end < spec.start:
        raise r.fail(f"{p}end", f"= {spec.end:g} s is before start ({spec.start:g} s)")
    return spec


def _camera(r: SceneReader, c: dict) -> CameraSpec:
    p = "camera."
    r.check_keys(c, p, CAMERA)
    keys_raw = c.get("keys")
    if not isinstance(keys_raw, list) or not keys_raw:
        raise r.fail(f"{p}keys", "must be a non-empty array of {time, position, target} tables")
    keys = []
    last = -math.inf
    for i, k in enumerate(keys_raw):
        kp = f"{p}keys[{i}]."
        if not isinstance(k, dict):
            raise r.fail(f"{p}keys[{i}]", "must be a table {time, position, target}")
        v = r.keys(k, CAMERA_KEY, kp)
        if v["time"] <= last:
            raise r.fail(f"{kp}time", f"= {v['time']:g} must be later than the previous key "
                         f"({last:g})")
        last = v["time"]
        keys.append((v["time"], v["position"], v["target"]))
    return CameraSpec(**r.keys(c, CAMERA, p, keys=keys))
