"""One source for settings: each grammar and scene key's meaning, unit,
default and allowed range is a `Key` in one table (lsystem/settings.py for
grammars, scene_keys.py for scenes). The parsers read defaults and ranges
from the tables and build their error messages from them; docs/grammar.md
and docs/scenes.md get their key tables from `markdown` (between
`<!-- keys:NAME -->` and `<!-- /keys -->` markers), and a test checks the
docs match (`python -m treebake.settings --write` regenerates them).
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Key:
    """A setting. kind: "number", "integer", "bool", "string", "choice",
    "vector" (n numbers), "list", "table", "text". default: the value used
    when the key is absent (None: required, unless `doc_default` says what
    happens instead); lo, hi: the allowed closed range (None: unbounded);
    doc_default / doc_range: what the docs show when the rule is not a
    plain value (a default from elsewhere, a range that depends on the
    scene)."""

    name: str
    meaning: str
    unit: str = ""
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    kind: str = "number"
    choices: tuple = ()
    n: int = 0
    doc_default: str | None = None
    doc_range: str | None = None
    aliases: tuple[str, ...] = ()

    @property
    def required(self) -> bool:
        return self.default is None and self.doc_default is None

    def range_text(self) -> str:
        """"[0, 3600]" style, as in error messages (inf for unbounded)."""
        lo = -math.inf if self.lo is None else self.lo
        hi = math.inf if self.hi is None else self.hi
        return f"[{lo:g}, {hi:g}]"

    def out_of_range(self, value) -> str:
        """The error message for a value outside the range (without the key)."""
        unit = f" {self.unit}" if self.unit and self.unit not in ("–",) else ""
        shown = f"{value:g}" if isinstance(value, float) else repr(value)
        return f"= {shown} is out of range {self.range_text()}{unit}"


def table(*keys: Key) -> dict[str, Key]:
    return {k.name: k for k in keys}


# ---------------------------------------------------------------------------
# documentation


def _number(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isinf(v):
            return "∞" if v > 0 else "−∞"
        if v != 0 and (abs(v) >= 1e5 or abs(v) < 1e-3):
            return f"{v:.3g}".replace("e+0", "e").replace("e+", "e").replace("e-0", "e−")
        return f"{v:g}"
    if isinstance(v, str):
        return f'`"{v}"`'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_number(x) for x in v) + "]"
    return str(v)


def _default(k: Key) -> str:
    if k.doc_default is not None:
        return k.doc_default
    if k.default is None:
        return "required"
    return _number(k.default)


def _range(k: Key) -> str:
    if k.doc_range is not None:
        return k.doc_range
    if k.choices:
        return ", ".join(f"`{c}`" for c in k.choices)
    if k.lo is None and k.hi is None:
        return ""
    lo = "" if k.lo is None else _number(float(k.lo) if k.kind != "integer" else int(k.lo))
    hi = "" if k.hi is None or math.isinf(k.hi) else _number(
        float(k.hi) if k.kind != "integer" else int(k.hi))
    if k.lo is not None and k.hi is not None and k.lo == -k.hi:
        return f"±{hi}"
    if not hi:
        return f"≥ {lo}"
    if not lo:
        return f"≤ {hi}"
    return f"{lo} – {hi}"


def markdown(keys: dict[str, Key], quote=lambda k: f"`{k.name}`") -> str:
    """A key table: key (and aliases), meaning, unit, default, range."""
    rows = ["| key | meaning | unit | default | range |", "|---|---|---|---|---|"]
    for k in keys.values():
        name = quote(k)
        if k.aliases:
            name += " (" + ", ".join(f"`{a}`" for a in k.aliases) + ")"
        rows.append(f"| {name} | {k.meaning} | {k.unit} | {_default(k)} | {_range(k)} |")
    return "\n".join(rows)


_BLOCK = re.compile(r"(<!-- keys:(?P<name>[\w.]+) -->\n)(?P<body>.*?)(<!-- /keys -->)", re.S)


def render(text: str, tables: dict[str, str]) -> str:
    """`text` with every marked block replaced by its table."""
    def sub(m):
        name = m.group("name")
        if name not in tables:
            raise KeyError(f"no key table {name!r}")
        return m.group(1) + tables[name] + "\n" + m.group(4)
    return _BLOCK.sub(sub, text)


def doc_tables() -> dict[Path, dict[str, str]]:
    """Every generated table, by docs file (relative to the repository)."""
    from .lsystem.settings import grammar_tables
    from .scene_keys import scene_tables

    return {Path("docs/grammar.md"): grammar_tables(), Path("docs/scenes.md"): scene_tables()}


def main(argv: list[str] | None = None) -> int:
    """python -m treebake.settings [--write] [ROOT]: check (or rewrite) the
    docs' key tables."""
    argv = sys.argv[1:] if argv is None else argv
    write = "--write" in argv
    rest = [a for a in argv if a != "--write"]
    root = Path(rest[0]) if rest else Path(".")
    stale = []
    for rel, tables in doc_tables().items():
        path = root / rel
        old = path.read_text(encoding="utf-8")
        new = render(old, tables)
        if new != old:
            stale.append(str(rel))
            if write:
                path.write_text(new, encoding="utf-8")
    if stale and not write:
        print("out of date: " + ", ".join(stale) + " (python -m treebake.settings --write)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
