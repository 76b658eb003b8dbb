"""Property tests: random and mutated grammar text gives a parsed grammar or
our own GrammarError with a line and column -- never another exception, never
a hang. Parsed grammars then derive and interpret under tight caps with only
our own error types."""

from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from treebake.errors import GrammarError, LimitError
from treebake.lsystem import Limits, derive, parse_grammar
from treebake.turtle import interpret

LIBRARY = sorted((Path(__file__).resolve().parent.parent / "grammars").rglob("*.lsys"))
TEXTS = [p.read_text() for p in LIBRARY]
ALPHABET = "FfAB01+-&^\\/|$![](),:<>*#@%.;=' \"\n\t" + "0123456789exlwnpi_" + "→ω"
TIGHT = Limits(max_modules=5_000, max_bytes=2_000_000, max_work=50_000)


def check(text: str) -> None:
    try:
        g = parse_grammar(text, file="fuzz.lsys")
    except GrammarError as err:
        assert err.file == "fuzz.lsys"
        assert isinstance(err.line, int) and isinstance(err.col, int)
        assert err.line >= 0 and err.col >= 0 and err.message
        return
    try:
        d = derive(g, iterations=min(g.iterations, 6), limits=TIGHT)
        interpret(d.modules, g)
    except (GrammarError, LimitError):
        pass


FAST = settings(max_examples=300, deadline=2000,
                suppress_health_check=[HealthCheck.too_slow])


@FAST
@given(st.text(alphabet=ALPHABET, max_size=300))
def test_random_text(text):
    check(text)


@FAST
@given(st.lists(st.sampled_from([
    "axiom: ", "F", "A(1,2)", " -> ", "A(x,y)", " : x > 1", "[", "]", "+(30)", "!(w)",
    "#define r 2\n", "iterations: 3\n", "\n", "<", ">", "*", "@density(3)", ": 0.5",
    "-(0.5)->", "x*r", "(", ")", ",", "ignore: +-\n", "1/0", "sqrt(-1)", "__x", "a.b",
]), max_size=40))
def test_token_soup(parts):
    check("".join(parts))


@FAST
@given(st.sampled_from(range(len(TEXTS))), st.data())
def test_mutated_library_grammars(index, data):
    text = TEXTS[index]
    for _ in range(data.draw(st.integers(1, 4))):
        if not text:
            break
        pos = data.draw(st.integers(0, len(text) - 1))
        action = data.draw(st.sampled_from(["delete", "insert", "replace", "duplicate"]))
        char = data.draw(st.sampled_from(ALPHABET))
        if action == "delete":
            text = text[:pos] + text[pos + 1:]
        elif action == "insert":
            text = text[:pos] + char + text[pos:]
        elif action == "replace":
            text = text[:pos] + char + text[pos + 1:]
        else:
            end = min(len(text), pos + data.draw(st.integers(1, 20)))
            text = text[:end] + text[pos:end] + text[end:]
    check(text)
