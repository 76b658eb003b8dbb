"""One source for settings: each grammar and scene key's meaning, unit,
default and allowed range is a `Key` in one table (lsystem/settings.py for
grammars, scene_keys.py for scenes). The parsers read defaults and ranges
from the tables and build their error messages from them; docs/grammar.md
and docs/scenes.md get their key tables from `markdown` (docs_tables.py
writes them between `<!-- keys:NAME -->` and `<!-- /keys -->` markers,
and a test checks the docs match).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Key:
    """A setting. kind: "number", "integer", "bool", "string", "choice",
    "vector" (n numbers), "list", "table", "text". default: the value used
    when the key is absent (None: required, unless `doc_default` says what
    happens instead); lo, hi: the allowed closed range (None: unbounded);
    doc_default / doc_range: what the docs show when the rule is not a
    plain value (a default from elsewhere, a range that depends on the
    scene). keyed: the key also takes a list of keys {time, value} over
    the shot (keys.Keyed, docs/scenes.md "Keys"), each value checked as a
    plain value is; a key with unit "degrees" is then an angle,
    interpolated the short way round."""

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
    keyed: bool = False

    @property
    def required(self) -> bool:
        return self.default is None and self.doc_default is None

    def range_text(self) -> str:
        """"[0, 3600]" style, as in error messages (inf for unbounded)."""
        lo = -math.inf if self.lo is None else self.lo
        hi = math.inf if self.hi is None else self.hi
        return f"[{_bound(lo)}, {_bound(hi)}]"

    def out_of_range(self, value) -> str:
        """The error message for a value outside the range (without the key)."""
        unit = f" {self.unit}" if self.unit and self.unit not in ("–",) else ""
        shown = f"{value:g}" if isinstance(value, float) else repr(value)
        return f"= {shown} is out of range {self.range_text()}{unit}"


def _bound(x: float) -> str:
    """A range's end as written: an integer whole (2^63 - 1 not as 9.22337e+18)."""
    return str(x) if isinstance(x, int) and not isinstance(x, bool) else f"{x:g}"


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
        meaning = k.meaning
        if k.keyed:
            meaning = f"{meaning}; or [keys](#keys)" if meaning else "a value or [keys](#keys)"
        rows.append(f"| {name} | {meaning} | {k.unit} | {_default(k)} | {_range(k)} |")
    return "\n".join(rows)
