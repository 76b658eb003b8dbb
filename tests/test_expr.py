"""The safe expression language: values against Python's own arithmetic
(an independent evaluator) and rejection of anything that reaches Python."""

import math

import numpy as np
import pytest
from treebake.errors import GrammarError
from treebake.lsystem.expr import compile_expr, evaluate_constant


@pytest.mark.parametrize("text, expected", [
    ("2+3*4", 14.0),
    ("(2+3)*4", 20.0),
    ("2^3^2", 512.0),
    ("2**3", 8.0),
    ("-2^2", -4.0),
    ("2^-1", 0.5),
    ("7 % 3", 1.0),
    ("10/4", 2.5),
    ("1 < 2 && 3 > 4", 0.0),
    ("1 < 2 || 3 > 4", 1.0),
    ("!(1 == 1)", 0.0),
    ("not 0 and 1", 1.0),
    ("1 <= 1", 1.0),
    ("2 != 2", 0.0),
    ("sqrt(16) + abs(-3) + floor(2.7) + ceil(2.1)", 4 + 3 + 2 + 3),
    ("max(1, 5, 3) - min(4, 2)", 3.0),
    ("pow(2, 10)", 1024.0),
    ("sin(pi/2) + cos(0)", 2.0),
    ("deg(rad(30))", 30.0),
    ("exp(log(5))", 5.0),
    ("1e-3 * 1000", 1.0),
    (".5 + 5.", 5.5),
])
def test_constant_values(text, expected):
    assert evaluate_constant(text, {}) == pytest.approx(expected)


def test_parameters_and_constants():
    e = compile_expr("l*r1 + w/2", {"l": 0, "w": 1}, {"r1": 0.9})
    assert e.evaluate([10.0, 4.0], None) == pytest.approx(11.0)
    # parameters shadow constants of the same name
    e = compile_expr("x", {"x": 0}, {"x": 99.0})
    assert e.evaluate([1.0], None) == 1.0


def test_random_draws_follow_the_seeded_stream():
    e = compile_expr("uniform(10, 20) + rand()", {}, {})
    assert e.const is None and e.uses_random
    a = [e.evaluate([], np.random.default_rng(5)) for _ in range(3)]
    b = [e.evaluate([], np.random.default_rng(5)) for _ in range(3)]
    assert a == b
    rng = np.random.default_rng(5)
    assert a[0] == pytest.approx(rng.uniform(10, 20) + rng.random())
    draws = [compile_expr("normal(3, 2)").evaluate([], np.random.default_rng(s))
             for s in range(4000)]
    assert np.mean(draws) == pytest.approx(3, abs=0.15)
    assert np.std(draws) == pytest.approx(2, abs=0.15)


@pytest.mark.parametrize("text, fragment", [
    ("__import__('os')", "__"),
    ("os.system", "attribute"),
    ("x.__class__", "attribute"),
    ("lambda: 1", "lambda"),
    ("[1, 2]", "indexing"),
    ("a[0]", "indexing"),
    ("'abc'", "strings"),
    ("open(1)", "unknown function"),
    ("eval(1)", "not allowed"),
    ("exec", "not allowed"),
    ("foo + 1", "unknown name"),
    ("sin", "is a function"),
    ("sqrt(1, 2)", "argument"),
    ("1 +", "expected"),
    ("(1", "expected ')'"),
    ("1 2", "unexpected"),
    ("1 < 2 < 3", "chained"),
    ("", "empty"),
    ("1/0", "division by zero"),
    ("sqrt(-1)", "domain"),
    ("10^400", "too large"),
    ("(1)(2)", "only named functions"),
])
def test_rejected_with_location(text, fragment):
    with pytest.raises(GrammarError) as info:
        evaluate_constant(text, {}, file="g.lsys", line=7, col=10)
    err = info.value
    assert fragment in err.message
    assert err.file == "g.lsys" and err.line == 7 and err.col >= 11


def test_deep_nesting_is_a_grammar_error_not_a_crash():
    with pytest.raises(GrammarError, match="nested"):
        evaluate_constant("(" * 500 + "1" + ")" * 500, {})
    with pytest.raises(GrammarError, match="nested"):
        evaluate_constant("-" * 500 + "1", {})


def test_column_points_at_the_problem():
    with pytest.raises(GrammarError) as info:
        evaluate_constant("1 + bogus", {}, line=3, col=4)
    # "bogus" starts at 0-based column 4 of the text; text starts at column 4
    assert info.value.col == 4 + 4 + 1
    assert math.isfinite(evaluate_constant("1", {}))
