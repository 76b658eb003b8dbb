"""The docs' generated tables: every grammar and scene key (settings.py's
tables) and the planar LOD's engine table, written between
`<!-- keys:NAME -->` and `<!-- /keys -->` markers. `python -m
treebake.docs_tables [--write] [ROOT]` checks (or rewrites) them; a test
checks that the docs match."""

from __future__ import annotations

import re
import sys
from pathlib import Path

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
    from .quality import QUALITIES
    from .scene_keys import scene_tables
    from .sim.handoff import engine_table

    return {Path("docs/grammar.md"): grammar_tables(), Path("docs/scenes.md"): scene_tables(),
            Path("docs/physics.md"): {"engines": engine_table(QUALITIES)}}


def main(argv: list[str] | None = None) -> int:
    """Check (or with --write rewrite) the docs' tables under ROOT (.)."""
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
        print("out of date: " + ", ".join(stale) + " (python -m treebake.docs_tables --write)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
