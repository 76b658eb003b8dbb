"""Issue 38's structure rules, kept: no module in the package over 600
lines, no function over 80 (the CLI parser's tables excepted), and no import
circle (module-level or lazy imports; the package root and its lazy facade
`api.py` excluded, as bench/flow.py layers them)."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import treebake

ROOT = Path(treebake.__file__).resolve().parent
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80


def _flow():
    spec = importlib.util.spec_from_file_location(
        "treebake_bench_flow", Path(__file__).resolve().parents[1] / "bench" / "flow.py")
    flow = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(flow)
    return flow


def _sources() -> list[Path]:
    return sorted(p for p in ROOT.rglob("*.py") if "__pycache__" not in p.parts)


def test_no_module_over_600_lines():
    long = {str(p.relative_to(ROOT)): n for p in _sources()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


def test_no_function_over_80_lines():
    long = {}
    for p in _sources():
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long[f"{p.relative_to(ROOT)}:{node.name}"] = n
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_no_import_circle():
    flow = _flow()
    graph = flow.import_graph(flow.package_modules(treebake), "facade")
    circles = [c for c in flow.sccs(graph) if len(c) > 1]
    assert not circles, f"import circles: {circles}"


def test_following_a_bakes_data_re_enters_modules_at_most_14_times():
    """Issue 38's target for `bench/flow.py --entry treebake.pipeline:bake_scene
    --scene preset:demo --duration 2` (its definition: the first-call walk
    over modules, five calls deep), kept: 25 at 19d713a, 14 since."""
    flow = _flow()
    raw = flow.run_trace("treebake.pipeline:bake_scene", "preset:demo", 2.0, "planar", None, 1,
                         [])
    walk, _ = flow.walk(raw, "first-call", flow.DEFAULT_DEPTH)
    layer = flow.layers(flow.import_graph(flow.package_modules(treebake), "facade"), "height")
    measured = flow.measure(walk, layer)
    assert measured["reentries"] <= 14, measured


OUTPUT_STAGE = ("treebake.bake", "treebake.bake_file", "treebake.export", "treebake.exchange")


def test_the_simulation_does_not_import_the_output_stage():
    """Issue 38: `sim/` does not import the output stage (bake.py imported
    into sim/common.py for one constant: now sampling.py, which both read)."""
    flow = _flow()
    graph = flow.import_graph(flow.package_modules(treebake), "facade")
    wrong = {m: sorted(d for d in deps if d.startswith(OUTPUT_STAGE))
             for m, deps in graph.items() if m.startswith("treebake.sim")}
    assert not any(wrong.values()), {m: d for m, d in wrong.items() if d}
    assert any(m.startswith("treebake.sim.") for m in graph)  # the graph holds sim's modules
