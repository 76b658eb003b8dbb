"""Grammar files (`.lsys`): parsing into a `Grammar`.

The syntax follows *The Algorithmic Beauty of Plants* (ABOP) and cpfg/L-Py
closely enough that grammars can be pasted from the book; `docs/grammar.md`
is the reference. Every problem is a `GrammarError` naming file, line and
column; a module no production can ever rewrite (legal, almost always a
typo) is a `GrammarWarning`, located the same way, on the grammar.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import GrammarError
from .expr import Expr, compile_expr, evaluate_constant
from .settings import PHYSICS, SETTINGS, default, field_name, read_settings
from .scan import RawModule, check_brackets, scan_modules
from .toplevel import find_top, rfind_top

Module = tuple[str, tuple[float, ...]]

MAX_FILE_BYTES = 1_000_000

_NAME = re.compile(r"[A-Za-z_][A-Za-z_0-9]*")
_ARROW = re.compile(r"-\((?P<prob>[^()]*)\)->|-->|→|(?<!<)->")


@dataclass(frozen=True)
class Pattern:
    """A module in a predecessor or context, with formal parameter names."""

    symbol: str
    params: tuple[str, ...]


@dataclass(frozen=True)
class SuccessorModule:
    symbol: str
    args: tuple[Expr, ...]


@dataclass(frozen=True)
class Production:
    left: tuple[Pattern, ...]
    pred: Pattern
    right: tuple[Pattern, ...]
    condition: Expr | None
    successors: tuple[tuple[SuccessorModule, ...], ...]  # stochastic alternatives
    probabilities: tuple[float, ...]
    file: str
    line: int


@dataclass(frozen=True)
class PhysicsDefaults:
    """Tree-wide physics defaults a grammar header may set (SI units; meaning,
    unit, default and range of each: lsystem/settings.py PHYSICS).

    density: green wood density, kg/m^3. modulus: Young's modulus, Pa.
    damping: structural damping ratio of the first mode (dimensionless).
    cone: joint cone half-angle, degrees. strength: bending moment that breaks
    a joint, N*m (inf = unbreakable). rupture: modulus of rupture, Pa; when set,
    joints break at rupture * pi * D^3 / 32. anchor: root-plate anchorage
    moment, N*m (inf = never uprooted). leaf_size: leaf quad edge, m.
    leaf_mass: fresh leaf mass per unit area, kg/m^2. drag: wood drag
    coefficient. leaf_drag: leaf drag coefficient.
    """

    density: float = default("density")
    modulus: float = default("modulus")
    damping: float = default("damping")
    cone: float = default("cone")
    strength: float = default("strength")
    rupture: float = default("rupture")
    anchor: float = default("anchor")
    leaf_size: float = default("leaf size")
    leaf_mass: float = default("leaf mass")
    drag: float = default("drag")
    leaf_drag: float = default("leaf drag")


@dataclass(frozen=True)
class GrammarWarning:
    """Legal text that is almost always a mistake, located like a
    GrammarError (line and column 1-based). The parser records it on the
    Grammar; the CLI prints it (or, with --strict, fails on it)."""

    file: str
    line: int
    col: int
    message: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}: {self.message}"


@dataclass(frozen=True)
class Grammar:
    """A parsed grammar. Lengths are in grammar units; `scale` converts them
    to metres and `width_scale` converts widths (diameters) to metres."""

    name: str
    file: str
    source_hash: str
    axiom: tuple[Module, ...]
    productions: tuple[Production, ...]
    # defaults, units and ranges: lsystem/settings.py (LSYSTEM)
    iterations: int = default("iterations")
    angle: float = default("angle")  # degrees
    step: float = default("step")  # grammar length units
    width: float = default("width")  # initial diameter, width units
    width_factor: float = default("width factor")  # `!` without argument multiplies by this
    seed: int = default("seed")
    ignore: frozenset[str] = frozenset()  # skipped when matching context
    consider: frozenset[str] | None = None  # if set, only these count as context
    tropism: tuple[float, float, float] = default("tropism")  # world, Z up
    elasticity: float = default("elasticity")
    scale: float = default("scale")  # metres per grammar length unit
    width_scale: float = default("width scale")  # metres per grammar width unit
    leaves: int = default("leaves")  # leaf type at the start (0 = none)
    physics: PhysicsDefaults = field(default_factory=PhysicsDefaults)
    constants: tuple[tuple[str, float], ...] = ()
    description: str = ""
    warnings: tuple[GrammarWarning, ...] = ()  # in file order


# ---------------------------------------------------------------------------
# the file


# every spelling of a setting -> its field name (the table's names and aliases;
# "w" is ABOP's omega typed on a keyboard)
_HEADER_KEYS = {**{alias: field_name(k.name) for k in SETTINGS.values()
                   for alias in (k.name, *k.aliases)}, "w": "axiom"}
_PHYSICS_FIELDS = frozenset(field_name(k) for k in PHYSICS)


def _strip_comment(line: str) -> str:
    stripped = line.lstrip()
    if stripped.startswith(("#define", "#include")):
        body_start = len(line) - len(stripped) + 1
        cut = line.find("#", body_start)
    else:
        cut = line.find("#")
    slashes = line.find("//")
    ends = [c for c in (cut, slashes) if c >= 0]
    if ends:
        line = line[: min(ends)]
    return line.rstrip()


# files users pass by mistake (a bake, an export): named, not parsed as text
NOT_GRAMMARS = (
    (b"PK\x03\x04", "a zip archive (a treebake bake is one: `treebake preview` and "
     "`treebake export` read bakes)"),
    (b"glTF", "a binary glTF file (an export)"),
    (b"PXR-USDC", "a USD crate file (an export)"),
    (b"#usda", "a USD text file (an export)"),
    (b"\x89PNG", "a PNG image"),
)


def load_grammar(path: str | Path) -> Grammar:
    """Read and parse a grammar file."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise GrammarError(f"cannot read grammar: {exc.strerror}", str(p), 0, 0) from None
    kind = next((k for magic, k in NOT_GRAMMARS if data.startswith(magic)), None)
    if kind:
        raise GrammarError(f"this is {kind}, not a grammar (.lsys text)", str(p), 0, 0)
    if len(data) > MAX_FILE_BYTES:
        raise GrammarError(f"grammar file larger than {MAX_FILE_BYTES} bytes", str(p), 0, 0)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise GrammarError("file is not valid UTF-8", str(p), line, 1) from None
    return parse_grammar(text, file=str(p), name=p.stem)


def _err_at(file: str, lineno: int):
    """`err(message, col)` for one line: a GrammarError at 0-based column col."""
    return lambda message, col: GrammarError(message, file, lineno, col + 1)


@dataclass
class _FileParts:
    """A grammar's lines sorted: the defines' values, the settings' texts
    (key -> (value text, line, 0-based column)) and the production lines."""

    constants: dict[str, float] = field(default_factory=dict)
    headers: dict[str, tuple[str, int, int]] = field(default_factory=dict)
    productions: list[tuple[int, str]] = field(default_factory=list)  # (line, text)


def parse_grammar(text: str, file: str = "<grammar>", name: str = "grammar") -> Grammar:
    """Parse grammar text. Defines are read first (in order), then settings
    and productions, so productions may use defines written below them."""
    if len(text) > MAX_FILE_BYTES:
        raise GrammarError(f"grammar larger than {MAX_FILE_BYTES} characters", file, 0, 0)
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise GrammarError("NUL character in grammar", file, line, 1)
    lines = [_strip_comment(raw) for raw in text.splitlines()]
    parts = _sort_lines(lines, file)
    headers, constants = parts.headers, parts.constants
    declared: tuple[str, ...] = ()
    if "modules" in headers:
        value, lineno, col = headers["modules"]
        names = value.split()
        for nm in names:
            if not _NAME.fullmatch(nm):
                raise _err_at(file, lineno)(f"module name {nm!r} must be a letter followed by "
                                            "letters, digits or '_'", col + value.find(nm))
        declared = tuple(sorted(set(names), key=len, reverse=True))
    settings = read_settings(headers, constants, declared, file)
    if "axiom" not in headers:
        raise GrammarError("missing 'axiom: ...'", file, 1 if lines else 0, 1)
    axiom, written = _axiom(*headers["axiom"], constants, declared, file)
    productions, successors = _parse_productions(parts.productions, constants, declared, file)
    warnings = _arity_warnings([*written, *successors], productions, file)

    physics = PhysicsDefaults(**{k: float(v) for k, v in settings.items() if k in _PHYSICS_FIELDS})
    grammar_keys = {"iterations", "angle", "step", "width", "width_factor", "seed", "ignore",
                    "consider", "tropism", "elasticity", "scale", "width_scale", "leaves",
                    "description"}
    kwargs = {k: v for k, v in settings.items() if k in grammar_keys}
    if "width_scale" not in kwargs and "scale" in kwargs:
        kwargs["width_scale"] = kwargs["scale"]
    return Grammar(
        name=settings.get("name") or name,
        file=file,
        source_hash=hashlib.sha256(text.encode("utf-8")).hexdigest(),
        axiom=axiom,
        productions=productions,
        physics=physics,
        constants=tuple(sorted(constants.items())),
        warnings=warnings,
        **kwargs,
    )


def _sort_lines(lines: list[str], file: str) -> _FileParts:
    """Evaluate the defines in order and set the settings and productions
    aside, from comment-free lines (line 1 first)."""
    parts = _FileParts()
    constants, headers = parts.constants, parts.headers
    for lineno, line in enumerate(lines, start=1):
        stripped = line.strip()
        if not stripped:
            continue
        indent = len(line) - len(line.lstrip())
        err = _err_at(file, lineno)
        if stripped.startswith("#define"):
            rest = stripped[len("#define"):]
            m = re.match(r"\s+([A-Za-z_][A-Za-z_0-9]*)\s*(=\s*)?", rest)
            if not m or not rest[m.end():].strip():
                raise err("expected '#define NAME VALUE'", indent)
            cname = m.group(1)
            if cname.startswith("__"):
                raise err(f"names starting with '__' are not allowed: {cname!r}", indent + 8)
            value_col = indent + len("#define") + m.end()
            constants[cname] = evaluate_constant(rest[m.end():], constants, file=file,
                                                 line=lineno, col=value_col)
            continue
        if stripped.startswith("#include"):
            raise err("#include is not supported; put everything in one file", indent)
        if _ARROW.search(line):
            parts.productions.append((lineno, line))
            continue
        m = re.match(r"\s*([^:]+?)\s*:(.*)$", line)
        if not m:
            raise err("expected a setting 'key: value', '#define NAME VALUE' or a production "
                      "'predecessor -> successor'", indent)
        key = re.sub(r"[\s_]+", " ", m.group(1).strip().lower())
        if key not in _HEADER_KEYS:
            known = ", ".join(sorted({k for k in _HEADER_KEYS if len(k) > 1 and k.isascii()}))
            raise err(f"unknown setting {m.group(1).strip()!r} (known: {known})", indent)
        canonical = _HEADER_KEYS[key]
        if canonical in headers:
            raise err(f"setting {canonical!r} given twice (first on line "
                      f"{headers[canonical][1]})", indent)
        value = m.group(2)
        lead = len(value) - len(value.lstrip())
        headers[canonical] = (value.lstrip(), lineno, m.start(2) + lead)
    return parts


def _axiom(value: str, lineno: int, col: int, constants: dict[str, float],
           declared: tuple[str, ...], file: str
           ) -> tuple[tuple[Module, ...], list[tuple[int, RawModule]]]:
    """The `axiom:` setting's modules, parameters evaluated, and as written
    (line, module)."""
    err = _err_at(file, lineno)
    raw = scan_modules(value, col, declared, err)
    if not raw:
        raise err("axiom is empty", col)
    check_brackets(raw, err)
    axiom = []
    for m in raw:
        params = tuple(evaluate_constant(t, constants, file=file, line=lineno, col=c)
                       for t, c in m.args)
        axiom.append((m.symbol, params))
    return tuple(axiom), [(lineno, m) for m in raw]


def _patterns(text: str, col0: int, declared, err, what: str) -> tuple[Pattern, ...]:
    if text.strip() == "*":
        return ()
    out = []
    for m in scan_modules(text, col0, declared, err):
        names = []
        for arg, c in m.args:
            a = arg.strip()
            if not _NAME.fullmatch(a):
                raise err(f"{what} parameters must be names, got {a!r}", c)
            if a.startswith("__"):
                raise err(f"names starting with '__' are not allowed: {a!r}", c)
            names.append(a)
        out.append(Pattern(m.symbol, tuple(names)))
    return tuple(out)


@dataclass(frozen=True)
class _ProductionLine:
    """One production line parsed. `key` (contexts, predecessor, condition
    text) is shared by stochastic alternatives; prob None: not stochastic."""

    key: tuple
    left: tuple[Pattern, ...]
    pred: Pattern
    right: tuple[Pattern, ...]
    condition: Expr | None
    successor: tuple[SuccessorModule, ...]
    prob: float | None
    line: int
    written: tuple[RawModule, ...]  # the successor as written, with columns


def _parse_productions(lines: list[tuple[int, str]], constants: dict[str, float],
                       declared: tuple[str, ...], file: str
                       ) -> tuple[tuple[Production, ...], list[tuple[int, RawModule]]]:
    """The productions of the production lines (line number, text), in file
    order; stochastic alternatives become one production, probabilities
    normalised to sum to 1. Also every successor module as written (line,
    module), alternatives included."""
    parsed = [_parse_production_line(lineno, line, constants, declared, file)
              for lineno, line in lines]

    # Group stochastic alternatives (same predecessor, contexts and condition).
    productions: list[Production] = []
    groups: dict[tuple, list[_ProductionLine]] = {}
    order: list[tuple] = []
    for item in parsed:
        if item.prob is None:
            order.append(("single", len(order), item))
        else:
            if item.key not in groups:
                groups[item.key] = []
                order.append(("group", item.key, None))
            groups[item.key].append(item)
    for kind, key, item in order:
        if kind == "single":
            productions.append(Production(item.left, item.pred, item.right, item.condition,
                                          (item.successor,), (1.0,), file, item.line))
            continue
        items = groups[key]
        total = sum(it.prob for it in items)
        if abs(total - 1.0) > 1e-3:
            lines_txt = ", ".join(str(it.line) for it in items)
            raise GrammarError(
                f"probabilities for {key[1].symbol!r} (lines {lines_txt}) sum to {total:g};"
                " they must sum to 1", file, items[0].line, 1)
        first = items[0]
        productions.append(Production(
            first.left, first.pred, first.right, first.condition,
            tuple(it.successor for it in items), tuple(it.prob / total for it in items), file,
            first.line))
    return tuple(productions), [(it.line, m) for it in parsed for m in it.written]


def _parse_production_line(lineno: int, line: str, constants: dict[str, float],
                           declared: tuple[str, ...], file: str) -> _ProductionLine:
    """`left < pred > right : condition -> successor`, with an optional
    probability in [0, 1] (`-(p)->`, or `: p` after the successor)."""
    err = _err_at(file, lineno)
    m = _ARROW.search(line)
    lhs, rhs, rhs_col = line[: m.start()], line[m.end():], m.end()
    prob_text = m.group("prob")
    prob = None
    if prob_text is not None:
        prob = evaluate_constant(prob_text, constants, file=file, line=lineno,
                                 col=m.start("prob"))
    else:
        colon = rfind_top(rhs, ":")
        if colon >= 0:
            prob = evaluate_constant(rhs[colon + 1:], constants, file=file, line=lineno,
                                     col=rhs_col + colon + 1)
            rhs = rhs[:colon]
    if prob is not None and not 0.0 <= prob <= 1.0:
        raise err(f"probability {prob:g} is outside [0, 1]", rhs_col)

    colon = find_top(lhs, ":")
    cond_text, cond_col = None, 0
    if colon >= 0:
        cond_text, cond_col = lhs[colon + 1:], colon + 1
        lhs = lhs[:colon]
    left, pred, right = _predecessor(lhs, declared, err)

    names: dict[str, int] = {}
    for p in (*left, pred, *right):
        for nm in p.params:
            if nm in names:
                raise err(f"parameter {nm!r} is bound twice in the predecessor", 0)
            names[nm] = len(names)

    condition = None
    if cond_text is not None:
        if not cond_text.strip():
            raise err("empty condition after ':'", cond_col)
        condition = compile_expr(cond_text, names, constants, file=file, line=lineno,
                                 col=cond_col)

    mods = scan_modules(rhs, rhs_col, declared, err)
    if len(mods) == 1 and mods[0].symbol == "ε" and not mods[0].args:
        mods = []
    check_brackets(mods, err)
    successor = tuple(
        SuccessorModule(mod.symbol, tuple(
            compile_expr(t, names, constants, file=file, line=lineno, col=c)
            for t, c in mod.args))
        for mod in mods
    )
    key = (left, pred, right, cond_text.strip() if cond_text else None)
    return _ProductionLine(key, left, pred, right, condition, successor, prob, lineno,
                           tuple(mods))


def _predecessor(lhs: str, declared: tuple[str, ...],
                 err) -> tuple[tuple[Pattern, ...], Pattern, tuple[Pattern, ...]]:
    """`left < pred > right` (contexts optional, without brackets) -> the
    left context, the strict predecessor (one module) and the right context."""
    if not lhs.strip():
        raise err("production has no predecessor", 0)
    lt = find_top(lhs, "<")
    gt = find_top(lhs, ">", lt + 1 if lt >= 0 else 0)
    if lt >= 0 and find_top(lhs, "<", lt + 1) >= 0:
        raise err("more than one '<' in predecessor", find_top(lhs, "<", lt + 1))
    if gt >= 0 and find_top(lhs, ">", gt + 1) >= 0:
        raise err("more than one '>' in predecessor", find_top(lhs, ">", gt + 1))
    pred_start = lt + 1 if lt >= 0 else 0
    pred_end = gt if gt >= 0 else len(lhs)
    left = _patterns(lhs[:lt], 0, declared, err, "context") if lt >= 0 else ()
    right = _patterns(lhs[gt + 1:], gt + 1, declared, err, "context") if gt >= 0 else ()
    pred = _patterns(lhs[pred_start:pred_end], pred_start, declared, err, "predecessor")
    if len(pred) != 1:
        raise err("the strict predecessor must be exactly one module"
                  f" (found {len(pred)})", pred_start)
    for ctx, where in ((left, "left"), (right, "right")):
        if any(p.symbol in "[]" for p in ctx):
            raise err(f"brackets in the {where} context are not supported", 0)
    return left, pred[0], right


# ---------------------------------------------------------------------------
# warnings


def _arity_warnings(written: list[tuple[int, RawModule]], productions: tuple[Production, ...],
                    file: str) -> tuple[GrammarWarning, ...]:
    """A warning for every module (line, module as written) whose symbol has
    productions, or is matched as context, but none with its parameter count:
    derivation copies it unchanged for ever, which is legal and almost always
    a typo (`B(w*0.45)` for `B(w*0.45,5)`). Symbols no production names
    (turtle commands, leaves) are never warned about."""
    preds: dict[str, dict[int, Pattern]] = {}  # symbol -> count -> first pattern
    contexts: dict[str, dict[int, Pattern]] = {}
    for p in productions:
        preds.setdefault(p.pred.symbol, {}).setdefault(len(p.pred.params), p.pred)
        for c in (*p.left, *p.right):
            contexts.setdefault(c.symbol, {}).setdefault(len(c.params), c)
    warnings = []
    for lineno, m in sorted(written, key=lambda w: (w[0], w[1].col)):
        own, ctx = preds.get(m.symbol, {}), contexts.get(m.symbol, {})
        n = len(m.args)
        if (not own and not ctx) or n in own or n in ctx:
            continue
        text = m.symbol + (f"({','.join(t for t, _ in m.args)})" if m.args else "")
        has = f"has {n}" if n else "has none"
        if own:
            where = _takes(own, "in its productions")
            extra = {k: c for k, c in ctx.items() if k not in own}
            if extra:
                where += f" and {_takes(extra, 'as context')}"
            fate = "will never be rewritten"
        else:
            where, fate = _takes(ctx, "as context"), "will never match"
        warnings.append(GrammarWarning(file, lineno, m.col + 1,
                                       f"{m.symbol} takes {where}; {text} {has} and {fate}"))
    return tuple(warnings)


def _takes(shapes: dict[int, Pattern], where: str) -> str:
    """'2 parameters in its productions (B(w,n))', '1 or 2 parameters ...
    (B(x), B(x,y))', 'no parameters ... (F)': the counts patterns take."""
    counts = sorted(shapes)
    noun = "parameter" if counts == [1] else "parameters"
    amount = "no" if counts == [0] else " or ".join(map(str, counts))
    shown = ", ".join(p.symbol + (f"({','.join(p.params)})" if p.params else "")
                      for _, p in sorted(shapes.items()))
    return f"{amount} {noun} {where} ({shown})"
