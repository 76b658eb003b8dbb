"""Grammar file parsing: settings, defines, productions and located errors."""

import math

import pytest
from treebake.errors import GrammarError
from treebake.lsystem import load_grammar, parse_grammar


def test_settings_defines_and_productions():
    g = parse_grammar("""
    # a comment
    #define r 0.5     # trailing comment
    #define twice 2*r
    name: demo
    iterations: 3
    angle: 30
    step: 2 * r       // expressions may use defines
    seed: 42
    ignore: + - F
    tropism: 0, 0, -1
    elasticity: 0.2
    scale: 0.1
    density: 600
    axiom: A(1, twice)
    A(x, y) : x > 0 && y < 10 -> F(x*r)A(x+1, y)
    """, file="demo.lsys")
    assert g.name == "demo" and g.iterations == 3 and g.angle == 30 and g.step == 1.0
    assert g.seed == 42 and g.ignore == frozenset("+-F")
    assert g.tropism == (0, 0, -1) and g.elasticity == 0.2
    assert g.scale == 0.1 and g.width_scale == 0.1  # width scale follows scale
    assert g.physics.density == 600 and g.physics.modulus == 8.0e9
    assert g.axiom == (("A", (1.0, 1.0)),)
    (p,) = g.productions
    assert p.pred.symbol == "A" and p.pred.params == ("x", "y")
    assert p.condition is not None and p.line == 16


def test_contexts_and_wildcards():
    g = parse_grammar("axiom: ABC\nA < B > C -> X\n* < + > * -> -\nAB < C -> Y\n")
    p1, p2, p3 = g.productions
    assert [m.symbol for m in p1.left] == ["A"] and [m.symbol for m in p1.right] == ["C"]
    assert p2.left == () and p2.right == () and p2.pred.symbol == "+"
    assert [m.symbol for m in p3.left] == ["A", "B"]


def test_stochastic_forms_are_grouped():
    g = parse_grammar("axiom: F\nF -(0.33)-> F[+F]F\nF -> F[-F]F : 0.33\nF -(0.34)-> FF\n")
    (p,) = g.productions
    assert len(p.successors) == 3 and sum(p.probabilities) == pytest.approx(1)


def test_multi_character_modules_and_at_commands():
    g = parse_grammar("modules: Apex Leaf\naxiom: Apex(1)\n"
                      "Apex(x) -> @density(600)F Leaf [Apex(x)]\n")
    succ = [m.symbol for m in g.productions[0].successors[0]]
    assert succ == ["@density", "F", "Leaf", "[", "Apex", "]"]


def test_abop_arrow_and_unicode():
    g = parse_grammar("ω: F\nF → F+F\n")
    assert len(g.productions) == 1


@pytest.mark.parametrize("text, line, col, fragment", [
    ("axiom: F\nF -> F(\n", 2, 7, "unclosed"),
    ("axiom: F\nF -> F]\n", 2, 7, "without a matching"),
    ("axiom: F[\n", 1, 9, "without a matching"),
    ("axiom: F\nbogus: 3\n", 2, 1, "unknown setting"),
    ("axiom: F\nangle: 1000\n", 2, 8, "out of range"),
    ("axiom: F\niterations: 2.5\n", 2, 13, "whole number"),
    ("axiom: F\niterations: abc\n", 2, 13,
     "iterations takes a whole number in [0, 1000] or an expression of #define constants: "
     "unknown name 'abc'"),
    ("axiom: F\nangle: 2*\n", 2, 10, "angle takes a number in [-360, 360]"),
    ("iterations: 2\n", 1, 1, "missing 'axiom"),
    ("axiom: F\nF -> F(1/0)\n", 2, 8, "division by zero"),
    ("axiom: F\nF(x) -> F(y)\n", 2, 11, "unknown name 'y'"),
    ("axiom: F\nF(x, x) -> F\n", 2, 1, "bound twice"),
    ("axiom: F\nF(2) -> F\n", 2, 3, "must be names"),
    ("axiom: F\nF -(0.5)-> FF\n", 2, 1, "sum to 0.5"),
    ("axiom: F\nF -> F : 1.5\n", 2, 5, "outside [0, 1]"),
    ("axiom: F\nA B -> F\n", 2, 1, "exactly one module"),
    ("axiom: F\n@densty(3)\n", 2, 1, "expected a setting"),
    ("axiom: F\nF -> @densty(3)\n", 2, 6, "unknown command"),
    ("axiom: F\nF -> @leaves(1,2,3)\n", 2, 6, "takes 1 or 2"),
    ("axiom: F\nF -> F(__import__)\n", 2, 8, "__"),
    ("axiom: F\nF -> F(os.getcwd())\n", 2, 10, "attribute"),
    ("#define\naxiom: F\n", 1, 1, "#define NAME VALUE"),
    ("axiom: F\nangle: 3\nangle: 4\n", 3, 1, "given twice"),
    ("axiom: F\n#include other.lsys\n", 2, 1, "not supported"),
    ("axiom: F\nA : -> B\n", 2, 4, "empty condition"),
])
def test_errors_name_line_and_column(text, line, col, fragment):
    with pytest.raises(GrammarError) as info:
        parse_grammar(text, file="bad.lsys")
    err = info.value
    assert fragment in err.message, err
    assert (err.file, err.line, err.col) == ("bad.lsys", line, col), str(err)
    assert str(err).startswith(f"bad.lsys:{line}:{col}: ")


def test_load_errors(tmp_path):
    with pytest.raises(GrammarError, match="cannot read"):
        load_grammar(tmp_path / "missing.lsys")
    bad = tmp_path / "latin1.lsys"
    bad.write_bytes(b"axiom: F\n# caf\xe9\n")
    with pytest.raises(GrammarError) as info:
        load_grammar(bad)
    assert info.value.line == 2 and "UTF-8" in info.value.message


@pytest.mark.parametrize("head, says", [(b"PK\x03\x04", "treebake preview"),
                                        (b"glTF\x02\x00\x00\x00", "binary glTF"),
                                        (b"PXR-USDC", "USD crate")])
def test_a_bake_or_an_export_is_named_not_parsed(tmp_path, head, says):
    # 2 MB: without the check this is "larger than 1000000 bytes", which misleads
    f = tmp_path / "thing.bin"
    f.write_bytes(head + bytes(2_000_000))
    with pytest.raises(GrammarError, match="not a grammar") as info:
        load_grammar(f)
    assert says in info.value.message


def test_every_library_grammar_parses(root):
    files = sorted((root / "grammars").rglob("*.lsys"))
    assert len(files) >= 30
    for f in files:
        g = load_grammar(f)
        assert g.productions and g.source_hash and math.isfinite(g.angle)


SAPLING_LINE_17 = "B(w*0.45,5)"
TYPO_MESSAGE = ("B takes 2 parameters in its productions (B(w,n)); B(w*0.45) has 1 and will "
                "never be rewritten")


def test_a_module_no_production_takes_is_a_located_warning(root):
    """Issue 42: `B(w*0.45)` for `B(w*0.45,5)` baked a 12-segment sapling
    instead of 57 without a word."""
    text = (root / "grammars" / "sapling.lsys").read_text()
    assert text.count(SAPLING_LINE_17) == 1
    g = parse_grammar(text.replace(SAPLING_LINE_17, "B(w*0.45)"), file="typo.lsys")
    (w,) = g.warnings
    assert (w.file, w.line, w.col, w.message) == ("typo.lsys", 17, 48, TYPO_MESSAGE)
    assert str(w) == f"typo.lsys:17:48: {TYPO_MESSAGE}"
    assert parse_grammar(text, file="sapling.lsys").warnings == ()


def test_no_bundled_grammar_warns(root):
    files = sorted((root / "grammars").rglob("*.lsys"))
    assert len(files) >= 30 and any(f.parent.name == "abop" for f in files)
    for f in files:
        assert load_grammar(f).warnings == (), f


@pytest.mark.parametrize("text, found", [
    # turtle commands and markers have no productions: never warned about
    ("axiom: F(1)+(30)X(2)\nA -> B\n", []),
    # several counts: one that matches is enough, wherever the module is
    ("axiom: A(1)\nA(x) -> A(x)A(x,1)A\nA(x,y) -> A(x)\nA -> F\n", []),
    ("axiom: A(1)\nA(x) -> A(x)\nA(x,y) -> A(1,2,3)\n",
     [(3, 11, ("A takes 1 or 2 parameters in its productions (A(x), A(x,y)); A(1,2,3) has "
               "3 and will never be rewritten"))]),
    # the axiom, and a module without parameters
    ("#define k 2\naxiom: F A\nA(n) : n > 0 -> F A(n-1)\n",
     [(2, 10, ("A takes 1 parameter in its productions (A(n)); A has none and will never "
               "be rewritten"))]),
    # every stochastic alternative, whichever form it is written in
    ("axiom: A(1)\nA(x) -(0.5)-> F A(x)\nA(x) -> [+ A(x * 2, 1)] : 0.5\n",
     [(3, 12, ("A takes 1 parameter in its productions (A(x)); A(x * 2, 1) has 2 and will "
               "never be rewritten"))]),
    # a count only a context reads is a deliberate shape
    ("axiom: S(1) A\nA -> S(2) A\nS(x) < A -> A\n", []),
    ("axiom: B(1,2) A\nB(x) -> B(x)\nB(x,y) < A -> A\n", []),
    # a symbol only read as context: warned when no context takes its count
    ("axiom: S A\nS(x) < A > T(y, z) -> A T(1)\n",
     [(1, 8, "S takes 1 parameter as context (S(x)); S has none and will never match"),
      (2, 25, "T takes 2 parameters as context (T(y,z)); T(1) has 1 and will never match")]),
    # declared multi-character names
    ("modules: Apex\naxiom: Apex(1, 2)\nApex(w) -> F Apex(w)\n",
     [(2, 8, ("Apex takes 1 parameter in its productions (Apex(w)); Apex(1, 2) has 2 and "
              "will never be rewritten"))]),
])
def test_arity_warnings(text, found):
    g = parse_grammar(text, file="t.lsys")
    assert [(w.line, w.col, w.message) for w in g.warnings] == found
    assert all(w.file == "t.lsys" for w in g.warnings)
