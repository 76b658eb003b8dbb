"""Grammar warnings on the command line: printed, or errors under --strict."""

from __future__ import annotations

import sys
from pathlib import Path

from .errors import GrammarError


def warn_grammar(grammar, strict: bool = False) -> None:
    """Print the grammar's warnings to stderr (`treebake: warning: FILE:LINE:COL:
    ...`); strict (--strict): the first is a GrammarError instead (exit 2)."""
    for w in grammar.warnings:
        if strict:
            raise GrammarError(w.message, w.file, w.line, w.col)
        print(f"treebake: warning: {w}", file=sys.stderr)


def warn_grammar_files(paths, strict: bool = False) -> None:
    """warn_grammar for each grammar file, once per file however many trees
    share it. Parsing is cheap next to a run, so a scene's grammars are read
    here once more, before any expensive work; a missing file is left to
    the run, which names it in its own words."""
    from .lsystem import load_grammar

    for path in dict.fromkeys(Path(p) for p in paths):
        if path.is_file():
            warn_grammar(load_grammar(path), strict)
