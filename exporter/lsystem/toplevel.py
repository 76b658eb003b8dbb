"""Searching grammar text outside parentheses: the commas, colons and
context markers that structure a line, not those inside a module's
arguments or an expression's calls."""

from __future__ import annotations

import re


def split_top(text: str, col0: int) -> list[tuple[str, int]]:
    """Split on commas (or whitespace when there are none) outside parentheses."""
    parts, depth, start = [], 0, 0
    if "," not in text:
        return [(m.group(), col0 + m.start()) for m in re.finditer(r"\S+", text)]
    for i, ch in enumerate(text):
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append((text[start:i], col0 + start))
            start = i + 1
    parts.append((text[start:], col0 + start))
    return parts


def find_top(text: str, chars: str, start: int = 0) -> int:
    """Index of the first of `chars` outside parentheses from `start`, -1 if none."""
    depth = 0
    for i in range(start, len(text)):
        ch = text[i]
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif depth == 0 and ch in chars:
            return i
    return -1


def rfind_top(text: str, ch: str) -> int:
    """Index of the last `ch` outside parentheses, -1 if none."""
    depth = 0
    for i in range(len(text) - 1, -1, -1):
        c = text[i]
        if c == ")":
            depth += 1
        elif c == "(":
            depth -= 1
        elif depth == 0 and c == ch:
            return i
    return -1
