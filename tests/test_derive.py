"""Derivation: parallel rewriting, all extensions together, and hard caps."""

import pytest
from treebake.errors import GrammarError, LimitError
from treebake.lsystem import Limits, derive, derive_many, format_modules, parse_grammar


def s(grammar_text, **kw):
    return format_modules(derive(parse_grammar(grammar_text), **kw).modules)


def test_parallel_not_sequential():
    # Algae (ABOP 1.1): lengths follow Fibonacci numbers.
    g = parse_grammar("axiom: a\na -> ab\nb -> a\n")
    lengths = [len(derive(g, iterations=n).modules) for n in range(10)]
    assert lengths == [1, 2, 3, 5, 8, 13, 21, 34, 55, 89]
    assert format_modules(derive(g, iterations=4).modules) == "abaababa"


def test_parametric_with_conditions():
    # ABOP eq. 1.8-style: A(x) grows while small, then stops.
    out = s("axiom: A(1)\nA(x) : x < 4 -> F(x)A(x*2)\nA(x) : x >= 4 -> B(x)\n", iterations=5)
    assert out == "F(1)F(2)B(4)"


def test_first_matching_production_wins_and_arity_must_match():
    out = s("axiom: A(1)A\nA(x) -> X(x)\nA -> Y\n", iterations=1)
    assert out == "X(1)Y"


def test_cut_symbol_erases_rest_of_branch():
    out = s("axiom: F[F A F[F]F]F\nA -> %\n", iterations=1)
    assert out == "F[F]F"
    assert s("axiom: FA F\nA -> %\n", iterations=1) == "F"


def test_rewriting_goes_on_after_a_cut_shortens_the_string():
    # Each step cuts the side branch B opens and grows the main axis: the
    # modules after a cut move, and the next step must still find them.
    g = "axiom: A\nA -> [B F F F]F A\nB -> %\n"
    assert s(g, iterations=1) == "[BFFF]FA"
    assert s(g, iterations=2) == "[]F[BFFF]FA"
    assert s(g, iterations=3) == "[]F[]F[BFFF]FA"


def test_context_uses_parameters_from_both_sides():
    out = s("axiom: A(1)B(2)C(3)\nA(a) < B(b) > C(c) -> X(a+b+c)\n", iterations=1)
    assert out == "A(1)X(6)C(3)"


def test_context_skips_ignored_symbols_and_side_branches():
    # Signal propagation (ABOP eq. 1.9 style): b moves right through + and [..]
    g = "ignore: +\naxiom: ba+[a]a\nb < a -> b\nb -> a\n"
    assert s(g, iterations=1) == "ab+[a]a"
    assert s(g, iterations=2) == "aa+[b]b"  # the branch and the axis both get it


def test_stochastic_is_seeded_and_instances_differ():
    g = parse_grammar("axiom: F\nF -(0.5)-> F[+F]\nF -(0.5)-> F[-F]\n")
    a = derive(g, seed=1, iterations=6).modules
    assert a == derive(g, seed=1, iterations=6).modules
    instances = derive_many(g, seeds=range(8), iterations=6)
    assert len({format_modules(d.modules) for d in instances}) > 4


def test_module_cap_is_a_clear_error():
    with pytest.raises(LimitError, match="exceeds 1000 modules at iteration 10"):
        derive(parse_grammar("axiom: F\nF -> FF\n"), iterations=20,
               limits=Limits(max_modules=1000))


def test_memory_cap_is_a_clear_error():
    with pytest.raises(LimitError, match="MiB"):
        derive(parse_grammar("axiom: F(1)\nF(x) -> F(x)F(x)\n"), iterations=20,
               limits=Limits(max_bytes=1 << 20))


def test_memory_estimate_counts_the_parameters_of_modules_carried_over():
    """Modules built in earlier steps and copied since keep their parameters:
    the estimate is the whole string's, not the step's new tuples' (it was
    a third of it here)."""
    from treebake.lsystem.derive import _BYTES_PER_MODULE, _BYTES_PER_PARAM

    g = parse_grammar("axiom: A(0)\nA(x) -> A(x + 1)[B(x, x, x, x, x, x)]A(x + 2)\n")
    out = derive(g, iterations=10).modules
    held = len(out) * _BYTES_PER_MODULE + sum(len(p) for _, p in out) * _BYTES_PER_PARAM
    assert sum(len(p) for sym, p in out if sym == "B") > 0.5 * sum(len(p) for _, p in out)
    derive(g, iterations=10, limits=Limits(max_bytes=held))  # fits exactly
    with pytest.raises(LimitError, match="at iteration 10"):
        derive(g, iterations=10, limits=Limits(max_bytes=held - 1))


def test_work_cap_stops_a_long_non_growing_derivation():
    with pytest.raises(LimitError, match="work limit"):
        derive(parse_grammar("axiom: A\nA -> B\nB -> A\n"), iterations=1000,
               limits=Limits(max_work=500))


def test_runtime_math_errors_name_the_production():
    g = parse_grammar("axiom: A(1)\n\nA(x) -> A(x - 1)B(1/x)\n", file="g.lsys")
    with pytest.raises(GrammarError) as info:
        derive(g, iterations=3)
    assert info.value.line == 3 and "division by zero" in info.value.message
    g = parse_grammar("axiom: A(2)\nA(x) -> A(x*x*x*x*x*x*x*x)\n")
    with pytest.raises(GrammarError, match="non-finite|too large"):
        derive(g, iterations=12)


def test_iteration_bounds():
    g = parse_grammar("axiom: F\nF -> F\n")
    with pytest.raises(LimitError):
        derive(g, iterations=-1)
    assert derive(g, iterations=0).modules == [("F", ())]
