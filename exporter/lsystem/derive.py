"""Parallel rewriting of a grammar's axiom.

All extensions combine: bracketed, parametric, stochastic (seeded
`numpy.random.Generator`), context-sensitive with ABOP's rules (context skips
ignored symbols and whole bracketed side branches), conditions, and the cut
symbol `%` (erases the rest of its branch). Hard caps on module count,
estimated memory and total work make a runaway grammar a clear `LimitError`.
"""

from __future__ import annotations

import math
import time
from bisect import bisect_right
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from itertools import accumulate

import numpy as np

from ..errors import GrammarError, LimitError
from .expr import math_message
from .grammar import Grammar, Module, Production
from .settings import MAX_ITERATIONS

DEFAULT_MAX_MODULES = 2_000_000
DEFAULT_MAX_BYTES = 1 << 30  # 1 GiB, estimated
DEFAULT_MAX_WORK = 50_000_000  # modules visited over all iterations
_BYTES_PER_MODULE = 120  # list slot + tuple + empty params tuple, CPython 3.11
_BYTES_PER_PARAM = 32  # float object + tuple slot


@dataclass
class Derivation:
    """The derived module string and how it was obtained."""

    modules: list[Module]
    grammar: Grammar
    seed: int
    iterations: int
    counts: list[int] = field(default_factory=list)  # module count after each iteration
    seconds: float = 0.0

    @property
    def modules_per_second(self) -> float:
        produced = sum(self.counts)
        return produced / self.seconds if self.seconds > 0 else math.inf


@dataclass(frozen=True)
class Limits:
    """Caps on derivation. `max_bytes` is an estimate of the string's memory."""

    max_modules: int = DEFAULT_MAX_MODULES
    max_bytes: int = DEFAULT_MAX_BYTES
    max_work: int = DEFAULT_MAX_WORK


def derive(grammar: Grammar, seed: int | None = None, iterations: int | None = None,
           limits: Limits = Limits(),
           progress: Callable[[int, int], None] | None = None) -> Derivation:
    """Rewrite the axiom `iterations` times (default: the grammar's)."""
    n = grammar.iterations if iterations is None else int(iterations)
    if not 0 <= n <= MAX_ITERATIONS:
        raise LimitError(f"iterations = {n} is out of range [0, {MAX_ITERATIONS}]")
    seed = grammar.seed if seed is None else int(seed)
    if seed < 0:
        raise LimitError(f"seed must be >= 0, got {seed}")
    rng = np.random.default_rng(seed)
    rewriter = _Rewriter(grammar, rng, limits)
    modules: list[Module] = list(grammar.axiom)
    rewritable = rewriter.rewritable(modules)
    counts: list[int] = []
    start = time.perf_counter()
    for it in range(n):
        modules, rewritable = rewriter.step(modules, rewritable, it + 1)
        counts.append(len(modules))
        if progress is not None:
            progress(it + 1, len(modules))
    return Derivation(modules, grammar, seed, n, counts, time.perf_counter() - start)


def derive_many(grammar: Grammar, seeds: Sequence[int], iterations: int | None = None,
                limits: Limits = Limits()) -> list[Derivation]:
    """One instance per seed: different stochastic choices and random draws."""
    return [derive(grammar, s, iterations, limits) for s in seeds]


def format_modules(modules: Sequence[Module], precision: int = 6) -> str:
    """The module string in grammar syntax, e.g. `F(1.5)[+F]`."""
    parts = []
    for sym, params in modules:
        if params:
            parts.append(sym + "(" + ",".join(f"{p:.{precision}g}" for p in params) + ")")
        else:
            parts.append(sym)
    return "".join(parts)


class _Rewriter:
    def __init__(self, grammar: Grammar, rng: np.random.Generator, limits: Limits):
        self.grammar = grammar
        self.rng = rng
        self.limits = limits
        self.work = 0
        self.by_symbol: dict[str, list[Production]] = {}
        for p in grammar.productions:
            self.by_symbol.setdefault(p.pred.symbol, []).append(p)
        self.has_context = any(p.left or p.right for p in grammar.productions)
        # Each successor is compiled once: a module whose arguments are all
        # constants is built here; the others keep their evaluators.
        # (module if constant, symbol, evaluators, has productions)
        self.built: dict[tuple[int, int], list[tuple[Module | None, str, tuple, bool]]] = {}
        for p in grammar.productions:
            for k, succ in enumerate(p.successors):
                self.built[(id(p), k)] = [
                    ((m.symbol, tuple(a.const for a in m.args)), m.symbol, (),
                     m.symbol in self.by_symbol)
                    if all(a.const is not None for a in m.args)
                    else (None, m.symbol, tuple(a.evaluate for a in m.args),
                          m.symbol in self.by_symbol)
                    for m in succ]
        # the parameters of a successor's constant modules (each copy counted,
        # though copies share one tuple: the estimate errs high)
        self.const_params = {key: sum(len(m[1]) for m, _, _, _ in mods if m is not None)
                             for key, mods in self.built.items()}
        # each stochastic production's running sums of its probabilities
        self.cumulative = {id(p): list(accumulate(p.probabilities))
                           for p in grammar.productions}
        # parameters the current string holds, carried from step to step: a
        # module copied unchanged keeps its own
        self.params_held = sum(len(params) for _, params in grammar.axiom)
        # `%` can only come from the axiom or a successor: without one, no
        # step needs the cut's scan.
        self.cuts = (any(sym == "%" for sym, _ in grammar.axiom)
                     or any(m.symbol == "%" for p in grammar.productions
                            for succ in p.successors for m in succ))
        ignore = grammar.ignore
        consider = grammar.consider
        if consider is not None:
            self.skip = lambda s: s not in consider and s not in "[]"
        else:
            self.skip = lambda s: s in ignore

    # -- context --------------------------------------------------------
    def _brackets(self, modules: list[Module]) -> list[int]:
        match = [-1] * len(modules)
        stack = []
        for i, (sym, _) in enumerate(modules):
            if sym == "[":
                stack.append(i)
            elif sym == "]" and stack:
                j = stack.pop()
                match[i], match[j] = j, i
        return match

    def _left(self, modules, match, i, patterns, bound: list) -> bool:
        j = i - 1
        for pat in reversed(patterns):
            while j >= 0:
                sym = modules[j][0]
                if sym == "]":
                    j = match[j] - 1
                    if j < -1:
                        return False
                elif sym == "[" or self.skip(sym):
                    j -= 1
                else:
                    break
            if j < 0:
                return False
            sym, params = modules[j]
            if sym != pat.symbol or len(params) != len(pat.params):
                return False
            bound[0:0] = params  # left-context values come first, in order
            j -= 1
        return True

    def _right(self, modules, match, i, patterns, bound: list) -> bool:
        j, n = i + 1, len(modules)
        for pat in patterns:
            while j < n:
                sym = modules[j][0]
                if sym == "[":
                    if match[j] < 0:
                        return False
                    j = match[j] + 1
                elif self.skip(sym):
                    j += 1
                else:
                    break
            if j >= n:
                return False
            sym, params = modules[j]
            if sym == "]" or sym != pat.symbol or len(params) != len(pat.params):
                return False
            bound.extend(params)
            j += 1
        return True

    # -- one parallel step -------------------------------------------------
    def rewritable(self, modules: list[Module]) -> list[int]:
        """The positions of the modules some production may rewrite."""
        by_symbol = self.by_symbol
        return [i for i, (sym, _) in enumerate(modules) if sym in by_symbol]

    def step(self, modules: list[Module], rewritable: list[int],
             iteration: int) -> tuple[list[Module], list[int]]:
        """One parallel rewrite of `modules`, given the positions of those
        with productions (`rewritable`, ascending): the new string and its
        rewritable positions. The runs between them are copied as slices:
        a step costs what it rewrites, not the string's length."""
        limits = self.limits
        self.work += len(modules)
        if self.work > limits.max_work:
            raise LimitError(
                f"{self.grammar.file}: derivation work limit of {limits.max_work} modules "
                f"reached at iteration {iteration}; lower the iteration count")
        match = self._brackets(modules) if self.has_context else None
        out: list[Module] = []
        out_rewritable: list[int] = []
        append, extend, mark = out.append, out.extend, out_rewritable.append
        by_symbol, built, rng = self.by_symbol, self.built, self.rng
        const_params, cumulative = self.const_params, self.cumulative
        isfinite = math.isfinite
        params_total = self.params_held  # rewritten modules' go, their successors' come
        next_check = 4096
        copied = 0  # modules[copied:i] are still to be copied unchanged
        for i in rewritable:
            if i > copied:
                extend(modules[copied:i])
                if len(out) >= next_check:  # a long copied run: the caps first
                    next_check = len(out) + 4096
                    self._check(len(out), params_total, iteration)
            copied = i + 1
            module = modules[i]
            for p in by_symbol[module[0]]:
                if len(module[1]) != len(p.pred.params):
                    continue
                values = list(module[1])
                if p.left and not self._left(modules, match, i, p.left, values):
                    continue
                if p.right and not self._right(modules, match, i, p.right, values):
                    continue
                try:
                    if p.condition is not None and not p.condition.evaluate(values, rng):
                        continue
                    k = 0
                    if len(p.probabilities) > 1:  # the first successor whose running sum passes r
                        k = min(bisect_right(cumulative[id(p)], rng.random()),
                                len(p.probabilities) - 1)
                    params_total += const_params[(id(p), k)] - len(module[1])
                    for const, sym, evaluators, rewrites in built[(id(p), k)]:
                        if rewrites:
                            mark(len(out))
                        if const is not None:
                            append(const)
                            continue
                        args = tuple([f(values, rng) for f in evaluators])
                        # One sum finds a non-finite argument (inf or nan
                        # propagates); overflow of the sum alone is no error.
                        if not isfinite(sum(args)):
                            _check_finite(sym, args, iteration, p)
                        params_total += len(args)
                        append((sym, args))
                except (ArithmeticError, ValueError) as exc:
                    raise GrammarError(
                        f"evaluating the production for {p.pred.symbol!r} at iteration "
                        f"{iteration}: {math_message(exc)}", p.file, p.line, 1) from None
                break
            else:
                mark(len(out))
                append(module)
            if len(out) >= next_check:
                next_check = len(out) + 4096
                self._check(len(out), params_total, iteration)
        extend(modules[copied:])
        self._check(len(out), params_total, iteration)
        if self.cuts and any(sym == "%" for sym, _ in out):
            out = _cut(out)
            out_rewritable = self.rewritable(out)
            params_total = sum(len(params) for _, params in out)
        self.params_held = params_total
        return out, out_rewritable

    def _check(self, count: int, params: int, iteration: int) -> None:
        limits = self.limits
        if count > limits.max_modules:
            raise LimitError(
                f"{self.grammar.file}: the derived string exceeds {limits.max_modules} modules "
                f"at iteration {iteration}; lower the iteration count (the grammar's `iterations:`, "
                f"or the scene tree's `iterations`)")
        estimate = count * _BYTES_PER_MODULE + params * _BYTES_PER_PARAM
        if estimate > limits.max_bytes:
            raise LimitError(
                f"{self.grammar.file}: the derived string would need about "
                f"{estimate / 2**20:.0f} MiB at iteration {iteration} (limit "
                f"{limits.max_bytes / 2**20:.0f} MiB); lower the iteration count")


def _check_finite(symbol: str, args: tuple[float, ...], iteration: int,
                  p: Production) -> None:
    for a in args:
        if not math.isfinite(a):
            raise GrammarError(
                f"module {symbol!r} got a non-finite parameter ({a}) at iteration {iteration}",
                p.file, p.line, 1)


def _cut(modules: list[Module]) -> list[Module]:
    """Apply `%`: drop it and everything after it up to the end of its branch."""
    out: list[Module] = []
    skip_depth = -1  # bracket depth being erased, -1 when not erasing
    depth = 0
    for m in modules:
        sym = m[0]
        if skip_depth >= 0:
            if sym == "[":
                depth += 1
            elif sym == "]":
                if depth == skip_depth:
                    skip_depth = -1
                    depth -= 1
                    out.append(m)
                    continue
                depth -= 1
            continue
        if sym == "%":
            skip_depth = depth
            continue
        if sym == "[":
            depth += 1
        elif sym == "]":
            depth -= 1
        out.append(m)
    return out
