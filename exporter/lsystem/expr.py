"""Safe arithmetic expressions for grammar files.

Our own tokenizer and precedence-climbing parser; expressions compile to
nested Python closures, so user text never reaches `eval`/`exec` and can only
name parameters, constants and the functions in `FUNCTIONS`.

Operators, lowest precedence first: `||` `or`; `&&` `and`; `!` `not`;
comparisons `< <= > >= == !=`; `+ -`; `* / %`; unary `- +`; power `^` `**`
(right associative). Comparisons and logic yield 1.0 or 0.0. Trigonometric
functions take radians (`rad(deg)` converts).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import GrammarError

Values = Sequence[float]
Evaluator = Callable[[Values, np.random.Generator], float]

MAX_DEPTH = 64
MAX_LENGTH = 4000


def _floor(x: float) -> float:
    return float(math.floor(x))


def _ceil(x: float) -> float:
    return float(math.ceil(x))


def _sign(x: float) -> float:
    return 1.0 if x > 0 else (-1.0 if x < 0 else 0.0)


def _clamp(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


def _round(x: float) -> float:
    return float(math.floor(x + 0.5))


# name -> (min args, max args, function). Deterministic math only.
FUNCTIONS: dict[str, tuple[int, int, Callable[..., float]]] = {
    "sin": (1, 1, math.sin),
    "cos": (1, 1, math.cos),
    "tan": (1, 1, math.tan),
    "asin": (1, 1, math.asin),
    "acos": (1, 1, math.acos),
    "atan": (1, 1, math.atan),
    "atan2": (2, 2, math.atan2),
    "sqrt": (1, 1, math.sqrt),
    "exp": (1, 1, math.exp),
    "log": (1, 1, math.log),
    "log10": (1, 1, math.log10),
    "pow": (2, 2, math.pow),
    "min": (1, 16, min),
    "max": (1, 16, max),
    "abs": (1, 1, abs),
    "floor": (1, 1, _floor),
    "ceil": (1, 1, _ceil),
    "round": (1, 1, _round),
    "sign": (1, 1, _sign),
    "clamp": (3, 3, _clamp),
    "rad": (1, 1, math.radians),
    "deg": (1, 1, math.degrees),
}

# Random draws from the derivation's seeded generator.
RANDOM_FUNCTIONS: dict[str, tuple[int, int]] = {
    "rand": (0, 0),  # uniform [0, 1)
    "ran": (1, 1),  # uniform [0, x)   (cpfg)
    "uniform": (2, 2),  # uniform [a, b)
    "normal": (2, 2),  # normal(mean, standard deviation)
}

CONSTANTS = {"pi": math.pi, "true": 1.0, "false": 0.0}

_TOKEN = re.compile(
    r"""
    (?P<ws>\s+)
  | (?P<num>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z_0-9]*)
  | (?P<op>\*\*|&&|\|\||<=|>=|==|!=|[-+*/%^<>!(),])
  | (?P<bad>.)
    """,
    re.VERBOSE | re.DOTALL,
)

_WORD_OPS = {"and": "&&", "or": "||", "not": "!"}
_FORBIDDEN_WORDS = {"lambda", "import", "def", "class", "for", "while", "if", "in", "is",
                    "yield", "await", "async", "with", "del", "global", "exec", "eval"}


@dataclass(frozen=True)
class Token:
    kind: str  # num, name, op, end
    text: str
    col: int  # 0-based column within the line


@dataclass(frozen=True)
class Expr:
    """A compiled expression. `const` is set when it folds to a constant."""

    text: str
    evaluate: Evaluator
    const: float | None = None
    uses_random: bool = False


class _Parser:
    def __init__(self, text: str, file: str, line: int, col0: int,
                 params: dict[str, int], constants: dict[str, float]):
        self.text = text
        self.file = file
        self.line = line
        self.col0 = col0
        self.params = params
        self.constants = constants
        self.tokens = self._tokenize(text)
        self.pos = 0
        self.depth = 0

    def error(self, message: str, col: int) -> GrammarError:
        return GrammarError(message, self.file, self.line, self.col0 + col + 1)

    def _tokenize(self, text: str) -> list[Token]:
        if len(text) > MAX_LENGTH:
            raise self.error(f"expression longer than {MAX_LENGTH} characters", 0)
        tokens = []
        for m in _TOKEN.finditer(text):
            kind = m.lastgroup
            if kind == "ws":
                continue
            t = m.group()
            if kind == "bad":
                if t in "'\"":
                    raise self.error("strings are not allowed in expressions", m.start())
                if t == ".":
                    raise self.error("attribute access ('.') is not allowed in expressions",
                                     m.start())
                if t in "[]{}":
                    raise self.error(f"'{t}' is not allowed in expressions (no indexing)",
                                     m.start())
                raise self.error(f"unexpected character {t!r} in expression", m.start())
            if kind == "name":
                if t.startswith("__"):
                    raise self.error(f"names starting with '__' are not allowed: {t!r}",
                                     m.start())
                if t in _WORD_OPS:
                    kind, t = "op", _WORD_OPS[t]
                elif t in _FORBIDDEN_WORDS:
                    raise self.error(f"{t!r} is not allowed in expressions", m.start())
            tokens.append(Token(kind, t, m.start()))
        tokens.append(Token("end", "", len(text)))
        return tokens

    # -- token helpers -------------------------------------------------
    def peek(self) -> Token:
        return self.tokens[self.pos]

    def take(self) -> Token:
        tok = self.tokens[self.pos]
        self.pos += 1
        return tok

    def expect(self, text: str) -> Token:
        tok = self.take()
        if tok.text != text or tok.kind != "op":
            found = tok.text or "end of expression"
            raise self.error(f"expected {text!r}, found {found!r}", tok.col)
        return tok

    # -- grammar ---------------------------------------------------------
    def parse(self) -> tuple:
        if self.peek().kind == "end":
            raise self.error("empty expression", 0)
        node = self.parse_or()
        tok = self.peek()
        if tok.kind != "end":
            if tok.text == "(":
                raise self.error("only named functions can be called", tok.col)
            raise self.error(f"unexpected {tok.text!r} in expression", tok.col)
        return node

    def _nest(self, col: int) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.error(f"expression nested deeper than {MAX_DEPTH} levels", col)

    def parse_or(self) -> tuple:
        node = self.parse_and()
        while self.peek().text == "||":
            self.take()
            node = ("or", node, self.parse_and())
        return node

    def parse_and(self) -> tuple:
        node = self.parse_not()
        while self.peek().text == "&&":
            self.take()
            node = ("and", node, self.parse_not())
        return node

    def parse_not(self) -> tuple:
        tok = self.peek()
        if tok.text == "!" and tok.kind == "op":
            self.take()
            self._nest(tok.col)
            node = ("not", self.parse_not())
            self.depth -= 1
            return node
        return self.parse_cmp()

    def parse_cmp(self) -> tuple:
        node = self.parse_add()
        tok = self.peek()
        if tok.kind == "op" and tok.text in ("<", "<=", ">", ">=", "==", "!="):
            self.take()
            node = ("cmp", tok.text, node, self.parse_add())
            nxt = self.peek()
            if nxt.kind == "op" and nxt.text in ("<", "<=", ">", ">=", "==", "!="):
                raise self.error("comparisons cannot be chained; use &&", nxt.col)
        return node

    def parse_add(self) -> tuple:
        node = self.parse_mul()
        while self.peek().kind == "op" and self.peek().text in ("+", "-"):
            op = self.take().text
            node = ("bin", op, node, self.parse_mul())
        return node

    def parse_mul(self) -> tuple:
        node = self.parse_unary()
        while self.peek().kind == "op" and self.peek().text in ("*", "/", "%"):
            op = self.take().text
            node = ("bin", op, node, self.parse_unary())
        return node

    def parse_unary(self) -> tuple:
        tok = self.peek()
        if tok.kind == "op" and tok.text in ("-", "+"):
            self.take()
            self._nest(tok.col)
            operand = self.parse_unary()
            self.depth -= 1
            return ("neg", operand) if tok.text == "-" else operand
        return self.parse_pow()

    def parse_pow(self) -> tuple:
        base = self.parse_primary()
        tok = self.peek()
        if tok.kind == "op" and tok.text in ("^", "**"):
            self.take()
            self._nest(tok.col)
            exponent = self.parse_unary()  # right associative, allows 2^-1
            self.depth -= 1
            return ("bin", "^", base, exponent)
        return base

    def parse_primary(self) -> tuple:
        tok = self.take()
        if tok.kind == "num":
            return ("num", float(tok.text))
        if tok.kind == "name":
            if self.peek().text == "(" and self.peek().kind == "op":
                return self.parse_call(tok)
            return self.resolve(tok)
        if tok.text == "(":
            self._nest(tok.col)
            node = self.parse_or()
            self.depth -= 1
            self.expect(")")
            return node
        found = tok.text or "end of expression"
        raise self.error(f"expected a number, name or '(', found {found!r}", tok.col)

    def parse_call(self, name: Token) -> tuple:
        self.expect("(")
        self._nest(name.col)
        args = []
        if self.peek().text != ")":
            args.append(self.parse_or())
            while self.peek().text == ",":
                self.take()
                args.append(self.parse_or())
        self.expect(")")
        self.depth -= 1
        n = name.text
        if n in FUNCTIONS:
            lo, hi, _ = FUNCTIONS[n]
        elif n in RANDOM_FUNCTIONS:
            lo, hi = RANDOM_FUNCTIONS[n]
        else:
            known = ", ".join(sorted(FUNCTIONS) + sorted(RANDOM_FUNCTIONS))
            raise self.error(f"unknown function {n!r} (known: {known})", name.col)
        if not lo <= len(args) <= hi:
            want = str(lo) if lo == hi else f"{lo} to {hi}"
            raise self.error(f"{n}() takes {want} argument(s), got {len(args)}", name.col)
        return ("call", n, tuple(args))

    def resolve(self, tok: Token) -> tuple:
        n = tok.text
        if n in self.params:
            return ("var", self.params[n])
        if n in self.constants:
            return ("num", float(self.constants[n]))
        if n in CONSTANTS:
            return ("num", CONSTANTS[n])
        if n in FUNCTIONS or n in RANDOM_FUNCTIONS:
            raise self.error(f"{n!r} is a function; call it as {n}(...)", tok.col)
        names = sorted(self.params) + sorted(self.constants)
        hint = f" (known here: {', '.join(names)})" if names else ""
        raise self.error(f"unknown name {n!r}{hint}", tok.col)


_BIN = {
    "+": lambda a, b: a + b,
    "-": lambda a, b: a - b,
    "*": lambda a, b: a * b,
    "/": lambda a, b: a / b,
    "%": lambda a, b: math.fmod(a, b) if b != 0 else a / b,
    "^": math.pow,
}
_CMP = {
    "<": lambda a, b: 1.0 if a < b else 0.0,
    "<=": lambda a, b: 1.0 if a <= b else 0.0,
    ">": lambda a, b: 1.0 if a > b else 0.0,
    ">=": lambda a, b: 1.0 if a >= b else 0.0,
    "==": lambda a, b: 1.0 if a == b else 0.0,
    "!=": lambda a, b: 1.0 if a != b else 0.0,
}


def _uses_random(node: tuple) -> bool:
    kind = node[0]
    if kind == "call":
        return node[1] in RANDOM_FUNCTIONS or any(_uses_random(a) for a in node[2])
    if kind in ("num", "var"):
        return False
    return any(_uses_random(c) for c in node[1:] if isinstance(c, tuple))


def _compile(node: tuple) -> Evaluator:
    kind = node[0]
    if kind == "num":
        value = node[1]
        return lambda v, rng: value
    if kind == "var":
        i = node[1]
        return lambda v, rng: v[i]
    if kind == "neg":
        f = _compile(node[1])
        return lambda v, rng: -f(v, rng)
    if kind == "not":
        f = _compile(node[1])
        return lambda v, rng: 0.0 if f(v, rng) else 1.0
    if kind == "and":
        f, g = _compile(node[1]), _compile(node[2])
        return lambda v, rng: 1.0 if (f(v, rng) and g(v, rng)) else 0.0
    if kind == "or":
        f, g = _compile(node[1]), _compile(node[2])
        return lambda v, rng: 1.0 if (f(v, rng) or g(v, rng)) else 0.0
    if kind in ("bin", "cmp"):
        op = (_BIN if kind == "bin" else _CMP)[node[1]]
        a, b = node[2], node[3]
        f, g = _compile(a), _compile(b)
        # Specialise the common "parameter (op) constant" shapes for speed.
        if a[0] == "var" and b[0] == "num":
            i, c = a[1], b[1]
            return lambda v, rng: op(v[i], c)
        if a[0] == "num" and b[0] == "var":
            c, i = a[1], b[1]
            return lambda v, rng: op(c, v[i])
        return lambda v, rng: op(f(v, rng), g(v, rng))
    if kind == "call":
        name, args = node[1], [_compile(a) for a in node[2]]
        if name == "rand":
            return lambda v, rng: float(rng.random())
        if name == "ran":
            (x,) = args
            return lambda v, rng: float(rng.random()) * x(v, rng)
        if name == "uniform":
            a_, b_ = args
            return lambda v, rng: float(rng.uniform(a_(v, rng), b_(v, rng)))
        if name == "normal":
            m_, s_ = args
            return lambda v, rng: float(rng.normal(m_(v, rng), abs(s_(v, rng))))
        fn = FUNCTIONS[name][2]
        if len(args) == 1:
            (x,) = args
            return lambda v, rng: float(fn(x(v, rng)))
        return lambda v, rng: float(fn(*[a(v, rng) for a in args]))
    raise AssertionError(f"unknown node {kind}")  # pragma: no cover - parser invariant


def compile_expr(text: str, params: dict[str, int] | None = None,
                 constants: dict[str, float] | None = None, *, file: str = "<grammar>",
                 line: int = 0, col: int = 0) -> Expr:
    """Parse and compile `text`. `params` maps parameter names to their
    position in the value vector passed at evaluation; `constants` are folded
    in. `col` is the 0-based column of `text` in its line, for messages."""
    parser = _Parser(text, file, line, col, params or {}, constants or {})
    node = parser.parse()
    fn = _compile(node)
    uses_random = _uses_random(node)
    const = None
    if not uses_random and not _has_var(node):
        try:
            const = fn((), None)
        except (ArithmeticError, ValueError) as exc:
            raise parser.error(f"cannot evaluate {text.strip()!r}: {_math_message(exc)}", 0)
        if not math.isfinite(const):
            raise parser.error(f"{text.strip()!r} is not a finite number", 0)
        value = const
        fn = lambda v, rng: value
    return Expr(text.strip(), fn, const, uses_random)


def _has_var(node: tuple) -> bool:
    if node[0] == "var":
        return True
    if node[0] == "num":
        return False
    children = node[2] if node[0] == "call" else node[1:]
    return any(_has_var(c) for c in children if isinstance(c, tuple))


def _math_message(exc: BaseException) -> str:
    if isinstance(exc, ZeroDivisionError):
        return "division by zero"
    if isinstance(exc, OverflowError):
        return "number too large"
    return "math domain error (e.g. sqrt or log of a negative number)"


math_message = _math_message


def evaluate_constant(text: str, constants: dict[str, float], *, file: str = "<grammar>",
                      line: int = 0, col: int = 0) -> float:
    """Evaluate a constant expression (header values, #define, probabilities)."""
    expr = compile_expr(text, {}, constants, file=file, line=line, col=col)
    if expr.const is None:
        raise GrammarError("random draws are not allowed here", file, line, col + 1)
    return expr.const
