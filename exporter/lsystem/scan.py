"""Module strings of a grammar (`F(1)[+A(x, 2)]B`): split into symbols with
their raw argument texts and columns, brackets checked. Errors are built by
the caller's `err(message, col)`, which knows the file and line."""

from __future__ import annotations

import re
from dataclasses import dataclass

from .symbols import AT_COMMANDS

_NAME = re.compile(r"[A-Za-z_][A-Za-z_0-9]*")



@dataclass
class RawModule:
    symbol: str
    col: int  # 0-based column of the symbol in the line
    args: list[tuple[str, int]]  # (text, 0-based column)


def scan_modules(text: str, col0: int, names: tuple[str, ...], err) -> list[RawModule]:
    """Split a module string into symbols with raw argument texts.

    `names` are declared multi-character module names (longest first);
    `@name` is always one module. `err(message, col)` builds the error.
    """
    out: list[RawModule] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c.isspace():
            i += 1
            continue
        if c in "),":
            raise err(f"unexpected {c!r}", col0 + i)
        if c == "(":
            raise err("'(' must follow a module symbol", col0 + i)
        if c == ":":
            raise err("unexpected ':' (reserved for conditions and probabilities)", col0 + i)
        start = i
        symbol = None
        if c == "@":
            m = _NAME.match(text, i + 1)
            if m:
                symbol = "@" + m.group()
                i = m.end()
        if symbol is None:
            for name in names:
                if text.startswith(name, i):
                    symbol = name
                    i += len(name)
                    break
        if symbol is None:
            symbol = c
            i += 1
        args: list[tuple[str, int]] = []
        if i < n and text[i] == "(":
            depth, j, arg_start = 1, i + 1, i + 1
            while j < n and depth:
                ch = text[j]
                if ch == "(":
                    depth += 1
                elif ch == ")":
                    depth -= 1
                    if depth == 0:
                        break
                elif ch == "," and depth == 1:
                    args.append((text[arg_start:j], col0 + arg_start))
                    arg_start = j + 1
                j += 1
            if depth:
                raise err(f"unclosed '(' after {symbol!r}", col0 + i)
            args.append((text[arg_start:j], col0 + arg_start))
            if len(args) == 1 and not args[0][0].strip():
                args = []  # "A()" has no parameters
            i = j + 1
        if symbol.startswith("@"):
            counts = AT_COMMANDS.get(symbol)
            if counts is None:
                known = ", ".join(sorted(AT_COMMANDS))
                raise err(f"unknown command {symbol!r} (known: {known})", col0 + start)
            if len(args) not in counts:
                want = " or ".join(str(c) for c in counts)
                raise err(f"{symbol} takes {want} argument(s), got {len(args)}", col0 + start)
        out.append(RawModule(symbol, col0 + start, args))
    return out


def check_brackets(mods: list[RawModule], err) -> None:
    """Every '[' closed by a ']' after it, in order."""
    depth = 0
    for m in mods:
        if m.symbol == "[":
            depth += 1
        elif m.symbol == "]":
            depth -= 1
            if depth < 0:
                raise err("']' without a matching '['", m.col)
    if depth:
        opening = [m for m in mods if m.symbol == "["]
        raise err("'[' without a matching ']'", opening[-1].col)
