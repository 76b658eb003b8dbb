"""The grammar file's settings (`key: value` lines): meaning, unit, default
and range in one table, and a file's values read and checked by it
(read_settings). Grammar and PhysicsDefaults take their defaults from it,
docs/grammar.md shows it."""

from __future__ import annotations

import math

from ..errors import GrammarError
from ..settings import Key, markdown, table
from .expr import evaluate_constant
from .scan import scan_modules
from .toplevel import split_top

MAX_ITERATIONS = 1000

LSYSTEM = table(
    Key("axiom", "the start string", kind="text", aliases=("ω",)),
    Key("iterations", "rewriting steps", "", 1, 0, MAX_ITERATIONS, "integer",
        aliases=("n", "derivation length")),
    Key("angle", "default turn angle", "degrees", 90.0, -360.0, 360.0, aliases=("delta", "δ")),
    Key("step", "default `F`/`f` length", "grammar units", 1.0, 0.0),
    Key("width", "initial diameter", "width units", 0.1, 0.0),
    Key("width factor", "`!` without argument multiplies the width by this", "", 0.7, 0.0,
        1e3),
    Key("seed", "default random seed (the CLI's `--seed` overrides)", "", 0, 0, 2**63 - 1,
        "integer", doc_range="0 – 2⁶³ − 1"),
    Key("ignore", "symbols skipped when matching context, e.g. `+ - F`", kind="text",
        doc_default="none"),
    Key("consider", "alternatively: only these symbols count as context", kind="text",
        doc_default="all"),
    Key("modules", "multi-character module names, e.g. `Apex Bud`", kind="text",
        doc_default="none", aliases=("module",)),
    Key("tropism", "tropism vector `x, y, z` in the world frame (Z up)", "", (0.0, 0.0, -1.0),
        kind="vector", n=3, doc_range="non-zero"),
    Key("elasticity", "tropism susceptibility *e* (ABOP eq. 2.4; 0: off)", "rad", 0.0, -10.0,
        10.0),
    Key("scale", "metres per grammar length unit", "m", 1.0, 1e-9, 1e9),
    Key("width scale", "metres per width unit", "m", 1.0, 1e-9, 1e9, doc_default="`scale`"),
    Key("leaves", "leaf type at the start (0 = none; 1 broadleaf, 2 conifer needles, "
        "3 palm leaflets, 4 autumn broadleaf)", "", 0, 0, 16, "integer"),
    Key("name", "free text", kind="text", doc_default="file name"),
    Key("description", "free text (`treebake list` shows it)", kind="text", doc_default="none"),
)

PHYSICS = table(
    Key("density", "green (wet) wood density", "kg/m³", 750.0, 1.0, 5000.0),
    Key("modulus", "Young's modulus of green wood", "Pa", 8.0e9, 1e3, 1e12),
    Key("damping", "damping ratio of each limb's first sway mode in still air, apart from "
        "air drag (wood and branch interaction; bare stems 0.01–0.08, intact crowns 0.08–0.3)",
        "–", 0.05, 0.0, 2.0),
    Key("cone", "joint cone half-angle around the rest pose", "degrees", 30.0, 0.01, 180.0),
    Key("strength", "bending moment that breaks a joint", "N·m", math.inf, 0.0, math.inf,
        doc_default="∞ (never)"),
    Key("rupture", "modulus of rupture; joints break at MOR·πD³/32", "Pa", math.inf, 0.0,
        math.inf, doc_default="∞ (never)"),
    Key("anchor", "root-plate anchorage moment (uprooting)", "N·m", math.inf, 0.0, math.inf,
        doc_default="∞ (never)"),
    Key("leaf size", "the foliage of a leafy segment: the physics counts two cards of this "
        "edge (a card stands for a cluster of leaves); the exported foliage draws many cards "
        "of a few times this edge, skinned to the segment (docs/look.md)", "m", 0.15, 0.0,
        10.0),
    Key("leaf mass", "fresh foliage mass per card area (it and the cards' area are the "
        "foliage's mass and drag area)", "kg/m²", 0.2, 0.0, 10.0),
    Key("drag", "drag coefficient of bare wood", "–", 1.2, 0.0, 10.0),
    Key("leaf drag", "drag coefficient of foliage (before streamlining)", "–", 0.3, 0.0, 10.0),
)

SETTINGS = {**LSYSTEM, **PHYSICS}


def field_name(key: str) -> str:
    """A setting's Python field name: "width factor" -> "width_factor"."""
    return key.replace(" ", "_")


def default(key: str):
    return SETTINGS[key].default


def grammar_tables() -> dict[str, str]:
    """The docs' tables (docs/grammar.md)."""
    return {"grammar": markdown(LSYSTEM), "grammar.physics": markdown(PHYSICS)}


_KEYS = {field_name(k.name): k for k in SETTINGS.values()}  # field name -> Key


def read_settings(headers: dict[str, tuple[str, int, int]], constants: dict[str, float],
                  declared: tuple[str, ...], file: str) -> dict:
    """Field name -> value of every setting of a grammar file but axiom and
    modules, checked against its range in the tables above. `headers`: key
    -> (value text, line, 0-based column); `constants`: the defines' values;
    `declared`: the multi-character module names; `file` for the errors
    (GrammarError, naming file, line and column)."""
    def at(lineno: int):  # err(message, col): a GrammarError at 0-based column col
        return lambda message, col: GrammarError(message, file, lineno, col + 1)

    settings: dict = {}
    for key, (value, lineno, col) in headers.items():
        err = at(lineno)
        if key in ("name", "description"):
            settings[key] = value.strip()
        elif key in ("ignore", "consider"):
            mods = scan_modules(value, col, declared, err)
            if any(m.args for m in mods):
                raise err(f"{key} lists symbols without parameters", col)
            settings[key] = frozenset(m.symbol for m in mods)
        elif key == "tropism":
            parts = split_top(value, col)
            if len(parts) != 3:
                raise err("tropism needs three numbers: x, y, z (world frame, Z up)", col)
            vec = tuple(evaluate_constant(t, constants, file=file, line=lineno, col=c)
                        for t, c in parts)
            if math.hypot(*vec) == 0:
                raise err("tropism vector must not be zero", col)
            settings[key] = vec
        elif key in ("axiom", "modules"):
            continue
        else:
            spec = _KEYS[key]
            try:
                v = evaluate_constant(value, constants, file=file, line=lineno, col=col)
            except GrammarError as exc:  # which setting, and what it takes
                what = "a whole number" if spec.kind == "integer" else "a number"
                raise GrammarError(f"{spec.name} takes {what} in {spec.range_text()} or an "
                                   f"expression of #define constants: {exc.message}",
                                   exc.file, exc.line, exc.col) from None
            if (spec.lo is not None and v < spec.lo) or (spec.hi is not None and v > spec.hi):
                raise err(f"{spec.name} {spec.out_of_range(float(v))}", col)
            if spec.kind == "integer":
                if v != int(v):
                    raise err(f"{spec.name} must be a whole number, got {v:g}", col)
                v = int(v)
            settings[key] = v
    if "ignore" in settings and "consider" in settings:
        _, lineno, col = headers["consider"]
        raise at(lineno)("use either 'ignore' or 'consider', not both", col)
    return settings
