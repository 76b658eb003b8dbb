"""The scene file's keys, table by table: meaning, unit, default and allowed
range in one place. scene.py parses and checks by these tables (its error
messages quote the range and unit), docs/scenes.md shows them
(settings.py renders and checks the docs)."""

from __future__ import annotations

import math

from .names import MAX_TREE_NAME
from .quality import QUALITIES
from .settings import Key, markdown, table

BEAUFORT = {  # m/s, lower bounds (WMO)
    "calm": 0.0, "light air": 0.3, "light breeze": 1.6, "gentle breeze": 3.4,
    "moderate breeze": 5.5, "fresh breeze": 8.0, "strong breeze": 10.8, "near gale": 13.9,
    "gale": 17.2, "strong gale": 20.8, "storm": 24.5, "violent storm": 28.5, "hurricane": 32.7,
}
FORMATS = ("glb", "gltf", "obj", "usd", "usda", "abc", "preview", "npz")
LEVELS = tuple(QUALITIES)
SEED_MAX = 2**63 - 1
MAX_TREES = 100_000  # a shot; its memory and disk are checked before the work (resources.py)
NEVER = "never"

TOP = table(
    Key("name", "job name: output goes to `out/<name>/`", kind="string",
        doc_default="file name"),
    Key("duration", "simulated time (with `loop`: the loop's length)", "s", 10.0, 0.0, 3600.0),
    Key("loop", "bake a seamless loop of `duration` (docs/scenes.md, \"Loops\")", kind="bool",
        default=False),
    Key("fps", "frames per second of the bake", "1/s", 24.0, 1.0, 1000.0),
    Key("frame_start", "number of the first frame in every exported format (glTF key "
        "times, USD time codes, OBJ file numbers; docs/formats.md)", "", 1, 0, 1_000_000,
        "integer"),
    Key("seed", "seed for gusts and forest scatter", "", 0, 0, SEED_MAX, "integer",
        doc_range="0 – 2⁶³ − 1"),
    Key("gravity", "gravitational acceleration", "m/s²", 9.81, 0.0, 100.0),
    Key("prestress", "the grown shape is the equilibrium under gravity (no sag at t = 0)",
        kind="bool", default=True),
    Key("ground", "the ground plane z = 0 stops falling parts", kind="bool", default=True),
    Key("quality", "a level name or a table (Quality, below)", kind="choice",
        default="default", choices=LEVELS, doc_range="`draft`, `default`, `final`, a table"),
    Key("formats", "formats `treebake bake` exports (its `--format` overrides)", kind="list",
        default=(), choices=FORMATS, doc_default="none (the bake only)"),
    Key("tree", "trees placed one by one (Trees, below)", kind="table", doc_default="none"),
    Key("forest", "many trees scattered (below)", kind="table", doc_default="none"),
    *(Key(k, f"{what} (Forces and Events, below)", kind="table", doc_default="none")
      for k, what in (("wind", "mean wind with gusts"), ("explosion", "free-air blasts"),
                      ("vortex", "tornadoes"), ("gust", "moving pulses of air"),
                      ("downwash", "rotors' downwash"), ("attractor", "acceleration fields"),
                      ("projectile", "thrown boxes and spheres"), ("cut", "felling"),
                      ("pull", "rope pulls"))),
    Key("camera", "the shot's camera (Camera, below)", kind="table", doc_default="none"),
)

TREE = table(
    Key("grammar", "grammar file (docs/grammar.md), relative to the scene file, or a "
        "bundled grammar's name (`oak`, `grammar:forest/birch`; `treebake list`)", "path",
        kind="string"),
    Key("name", "tree name in files and messages (letters, digits and `_`, starting with a "
        "letter or `_`: names every tool keeps)", kind="string",
        doc_default="the grammar file's name: `oak`; `oak_1`, `oak_2`, … when several share it",
        doc_range=f"≤ {MAX_TREE_NAME} characters, unique"),
    Key("position", "where its base stands", "m (x, y)", (0.0, 0.0), -1e6, 1e6, "vector", n=2),
    Key("rotation", "turn about the vertical", "degrees", 0.0, -360.0, 360.0),
    Key("seed", "overrides the grammar's seed (stochastic grammars)", "", None, 0, SEED_MAX,
        "integer", doc_default="grammar's", doc_range="0 – 2⁶³ − 1"),
    Key("iterations", "overrides the grammar's derivation length", "", None, 0, 1000,
        "integer", doc_default="grammar's"),
    Key("quality", "this tree's quality level", kind="choice", choices=LEVELS,
        doc_default="scene's"),
    Key("phase", "with `loop`: how far ahead in its loop this tree is", "s", 0.0, 0.0, 3600.0,
        doc_range="0 – < `duration`"),
)

FOREST = table(
    Key("grammars", "grammar files (or bundled grammars' names, as `grammar`), used in turn",
        "paths", kind="list"),
    Key("count", "number of trees", "", None, 0, MAX_TREES, "integer"),
    Key("area", "width and depth of the forest", "m", None, 1.0, 1e5, "vector", n=2),
    Key("center", "centre of the area", "m", (0.0, 0.0), -1e6, 1e6, "vector", n=2),
    Key("min_spacing", "smallest distance between two trees", "m", 3.0, 0.0, 1000.0),
    Key("seed", "scatter seed", "", None, 0, SEED_MAX, "integer", doc_default="scene's seed",
        doc_range="0 – 2⁶³ − 1"),
    Key("iterations", "derivation length for all", "", None, 0, 1000, "integer",
        doc_default="grammars'"),
)

WIND = table(
    Key("speed", "mean speed at `reference_height`", "m/s", None, 0.0, 120.0,
        doc_default="— (or `beaufort`)", keyed=True),
    Key("beaufort", "instead of `speed`: the middle of a WMO Beaufort band", kind="choice",
        choices=tuple(BEAUFORT), doc_default="none", doc_range="`calm` … `hurricane`",
        keyed=True),
    Key("direction", "direction the wind blows toward, counter-clockwise from +X", "degrees",
        0.0, -360.0, 360.0, keyed=True),
    Key("reference_height", "height of `speed`", "m", 10.0, 1.0, 500.0),
    Key("shear", "power-law exponent of the profile", "", 0.14, 0.0, 0.6),
    Key("turbulence", "intensity σ_u / U (0 = steady; 0.2 open country, 0.3–0.5 near and in "
        "forests)", "", 0.0, 0.0, 1.0, keyed=True),
    Key("length_scale", "longitudinal integral length scale of the gusts", "m", 50.0, 1.0,
        2000.0),
    Key("start", "the wind rises from here over `ramp`", "s", 0.0, 0.0, 3600.0),
    Key("ramp", "rise (and fall) time", "s", 2.0, 0.0, 600.0),
    Key("end", "the wind dies down from here over `ramp`", "s", math.inf, 0.0,
        doc_default=NEVER, doc_range="≥ `start`"),
)

EXPLOSION = table(
    Key("position", "centre of the charge", "m (x, y, z)", None, -1e6, 1e6, "vector", n=3),
    Key("time", "detonation time", "s", 0.0, 0.0, 3600.0),
    Key("charge", "TNT-equivalent mass", "kg", None, 0.001, 1e6),
)

VORTEX = table(
    Key("start", "centre at `time`", "m (x, y)", None, -1e6, 1e6, "vector", n=2,
        doc_default="— (or `path`)"),
    Key("velocity", "translation", "m/s (x, y)", (0.0, 0.0), -200.0, 200.0, "vector", n=2),
    Key("path", "instead of `start` and `velocity`: the centre over the shot (the air "
        "moves with it)", "m (x, y)", None, -1e6, 1e6, "vector", n=2, doc_default="none",
        keyed=True),
    Key("max_speed", "peak tangential wind, at the core's edge", "m/s", None, 0.0, 150.0,
        keyed=True),
    Key("core_radius", "radius of the solid-body core", "m", None, 1.0, 2000.0, keyed=True),
    Key("time", "start of the active interval", "s", 0.0, 0.0, 3600.0),
    Key("end", "end of the active interval", "s", math.inf, 0.0, doc_default=NEVER,
        doc_range="≥ `time`"),
    Key("inflow", "radial inflow outside the core, × tangential speed", "", 0.5, 0.0, 2.0),
    Key("updraft", "updraft in the core, × `max_speed`", "", 0.5, 0.0, 2.0),
    Key("clockwise", "turning sense seen from above", kind="bool", default=False),
)

GUST = table(
    Key("position", "the pulse's centre: a fixed point or a path (a creature, a vehicle)",
        "m (x, y, z)", None, -1e6, 1e6, "vector", n=3, keyed=True),
    Key("speed", "peak air speed, at the centre", "m/s", None, 0.0, 120.0, keyed=True),
    Key("radius", "size of the pulse: `profile` falls off over it", "m", None, 0.1, 1000.0),
    Key("profile", "how the speed falls with distance d from the centre: `bump` "
        "(1 − (d/`radius`)²)³ inside `radius`, nothing beyond; `gaussian` exp(−(d/`radius`)²)",
        kind="choice", default="bump", choices=("bump", "gaussian")),
    Key("direction", "direction the air blows toward, counter-clockwise from +X", "degrees",
        None, -360.0, 360.0, keyed=True,
        doc_default="the path's direction of travel (needs a keyed `position`)"),
    Key("time", "the gust rises from here over `ramp`", "s", 0.0, 0.0, 3600.0),
    Key("ramp", "rise (and fall) time", "s", 0.5, 0.0, 600.0),
    Key("end", "the gust dies down from here over `ramp`", "s", math.inf, 0.0,
        doc_default=NEVER, doc_range="≥ `time`"),
)

DOWNWASH = table(
    Key("position", "the rotor's hub, z its height above the ground", "m (x, y, z)", None,
        -1e6, 1e6, "vector", n=3, keyed=True, doc_range="±1e6; z > `floor`"),
    Key("thrust", "the rotor's thrust (its aircraft's weight in a hover: 9.81 N per kg)", "N",
        None, 0.0, 1e7, keyed=True),
    Key("radius", "rotor radius", "m", None, 0.2, 50.0),
    Key("time", "the rotor's wash rises from here over `ramp`", "s", 0.0, 0.0, 3600.0),
    Key("ramp", "rise (and fall) time", "s", 1.0, 0.0, 600.0),
    Key("end", "the wash dies down from here over `ramp`", "s", math.inf, 0.0,
        doc_default=NEVER, doc_range="≥ `time`"),
    Key("floor", "height where the wake turns into the outwash: 0 over open ground, the "
        "canopy's top over a dense forest (the air below it is left still)", "m", 0.0, 0.0,
        200.0),
)

ATTRACTOR = table(
    Key("position", "the point", "m (x, y, z)", None, -1e6, 1e6, "vector", n=3, keyed=True),
    Key("strength", "acceleration toward it at `radius` (negative repels); 1/r² outside, "
        "falling linearly to zero inside", "m/s²", None, -1000.0, 1000.0, keyed=True),
    Key("radius", "", "m", 1.0, 0.01, 1000.0),
    Key("time", "start", "s", 0.0, 0.0),
    Key("end", "end", "s", math.inf, 0.0, doc_default=NEVER, doc_range="≥ `time`"),
)

PROJECTILE = table(
    Key("shape", "", kind="choice", default="box", choices=("box", "sphere")),
    Key("size", "box edge or sphere diameter", "m", None, 0.01, 10.0),
    Key("mass", "", "kg", None, 0.01, 1e5),
    Key("position", "launch position", "m (x, y, z)", None, -1e6, 1e6, "vector", n=3),
    Key("velocity", "launch velocity", "m/s (x, y, z)", (0.0, 0.0, 0.0), -500.0, 500.0,
        "vector", n=3),
    Key("time", "launch time", "s", 0.0, 0.0, 3600.0),
    Key("restitution", "contact restitution", "", 0.2, 0.0, 1.0),
    Key("friction", "contact friction coefficient", "", 0.5, 0.0, 2.0),
)

CUT = table(
    Key("tree", "the tree (index in the scene's tree list)", "", 0, 0, None, "integer",
        doc_range="0 – trees − 1"),
    Key("time", "when it is cut at its base", "s", 0.0, 0.0, 3600.0),
    Key("direction", "direction it falls toward, counter-clockwise from +X", "degrees", 0.0,
        -360.0, 360.0),
    Key("hinge", "lean at which the hinge wood snaps and the stem falls free", "degrees",
        40.0, 5.0, 89.0),
)

PULL = table(
    Key("tree", "the tree (index in the scene's tree list)", "", 0, 0, None, "integer",
        doc_range="0 – trees − 1"),
    Key("force", "rope force on the main stem, world vector", "N (x, y, z)", None, -1e7, 1e7,
        "vector", n=3),
    Key("release", "when the rope is released", "s", None, 0.0, 3600.0),
    Key("at", "height of the rope on the stem", "× tree height", 0.6, 0.01, 1.0),
    Key("ramp", "the force rises linearly over this time", "s", None, 0.0, None,
        doc_default="min(1, `release`)", doc_range="0 – `release`"),
)

CAMERA = table(
    Key("keys", "`{time, position, target}` key frames, linearly interpolated (below)",
        kind="list"),
    Key("fov", "horizontal field of view", "degrees", 60.0, 1.0, 179.0),
    Key("margin", "extra angle around the view that still counts as seen", "degrees", 10.0,
        0.0, 90.0),
    Key("far", "beyond this distance for the whole shot a tree uses `far_quality`", "m",
        math.inf, 1.0, doc_default=NEVER),
    Key("far_quality", "quality level for far trees", kind="choice", default="draft",
        choices=LEVELS),
)

CAMERA_KEY = table(
    Key("time", "when (later than the previous key)", "s", None, 0.0, 3600.0),
    Key("position", "camera position", "m (x, y, z)", None, -1e6, 1e6, "vector", n=3),
    Key("target", "the point it looks at", "m (x, y, z)", None, -1e6, 1e6, "vector", n=3),
)


def _levels(name: str) -> str:
    values = [getattr(QUALITIES[q], name) for q in LEVELS]
    return " / ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)


# defaults come from the `base` level (quality.py)
QUALITY = table(
    Key("base", "the level the table starts from", kind="choice", default="default",
        choices=LEVELS),
    Key("tier", "`auto`: every tree in the linear tier, moved to the nonlinear engine when it "
        "leaves the linear range; `pymunk`: every tree in the pymunk tier (0.1.0's LOD)",
        kind="choice", choices=("auto", "pymunk"), doc_default=_levels("tier")),
    Key("linear_rate", "the linear tier's implicit steps (finer for a stiff tree, split "
        "during blasts)", "Hz", None, 1.0, 10_000.0, doc_default=_levels("linear_rate")),
    Key("relinearise", "the linear tier takes its mass matrix, damping, gravity's stiffness "
        "and the rates' lever arms again at the trees' mean pose (over about 0.5 s) once a "
        "bone of it has turned this far from the pose they were taken at", "rad", None, 0.01,
        10.0, doc_default=_levels("relinearise")),
    Key("nonlinear", "the engine for trees that leave the linear range or that a projectile "
        "can reach: `auto` (the engine table of docs/physics.md: the MuJoCo reference), "
        "`reference` (the same) or `pymunk` (the pymunk tier for every reason)",
        kind="choice", choices=("auto", "reference", "pymunk"), doc_default=_levels("nonlinear")),
    Key("hand_back", "a tree a nonlinear engine took for large motion or a joint near "
        "breaking comes back to the linear tier once back in its range (`false`: it stays)",
        kind="bool", doc_default=_levels("hand_back")),
    Key("reference_step", "the reference's step when it takes a tree from the linear tier",
        "s", None, 1e-5, 1 / 60, doc_default=_levels("reference_step")),
    Key("substep_rate", "physics steps per second (split further, automatically, during "
        "blasts, hits and fast spins)", "Hz", None, 60.0, 100_000.0,
        doc_default=_levels("substep_rate")),
    Key("force_rate", "how often loads are re-evaluated (held in between)", "Hz", None, 1.0,
        100_000.0, doc_default=_levels("force_rate"), doc_range="1 – `substep_rate`"),
    Key("iterations", "pymunk solver iterations per step", "", None, 1, 1000, "integer",
        doc_default=_levels("iterations")),
    Key("planes", "bending planes per limb (1: the load's; 2: two perpendicular)", "", None,
        1, 2, "integer", doc_default=_levels("planes")),
    Key("bone_length", "merge a limb's segments into bones at least this fraction of the "
        "tree height (0: one bone per segment)", "", None, 0.0, 0.5,
        doc_default=" / ".join(("1/12", "0", "0"))),
    Key("stability", "largest ω·h of a joint before its rotary inertia is raised "
        "(docs/physics.md)", "", None, 0.1, 2.0, doc_default=_levels("stability")),
    Key("joint_correction", "fraction of a joint's position error corrected per substep", "",
        None, 0.0, 0.4, doc_default=_levels("joint_correction")),
    Key("coupling", "how a parent limb carries its children: `apparent` (rigid, with the "
        "apparent mass of a base-driven oscillator) or `rigid` (their plain mass)",
        kind="choice", choices=("apparent", "rigid"), doc_default=_levels("coupling")),
)


TABLES = {"scene": TOP, "scene.tree": TREE, "scene.forest": FOREST, "scene.wind": WIND,
          "scene.explosion": EXPLOSION, "scene.vortex": VORTEX, "scene.gust": GUST,
          "scene.downwash": DOWNWASH, "scene.attractor": ATTRACTOR,
          "scene.projectile": PROJECTILE, "scene.cut": CUT, "scene.pull": PULL,
          "scene.camera": CAMERA, "scene.camera.keys": CAMERA_KEY, "scene.quality": QUALITY}


def scene_tables() -> dict[str, str]:
    """The docs' tables (docs/scenes.md)."""
    return {name: markdown(keys) for name, keys in TABLES.items()}
