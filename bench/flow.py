"""How hard is it to follow the data through treebake? (issue #38)

Bakes a scene under a call tracer (sys.settrace), records every call into a
function of the installed `treebake` package from the moment the entry
function is called until it returns (every call of it, e.g. each chunk),
collapses the repetition into a walk over modules, and counts:

- re-entries: steps of the walk into a module it had already been in and
  left (total, and per module);
- climbs back up the import layers: those re-entries that go to a module
  on a higher import layer than the one the walk leaves (every step up a
  layer is printed beside it).

The definition (defaults; calibrated on base eb8e296, see below):

- recorded: calls into functions and methods whose code lives in the
  package's files (lambdas, nested functions, properties included);
  comprehensions and generator expressions count as the function they are
  in; module and class bodies (imports under way) and everything they run
  are left out; a call's caller is the innermost treebake frame on the
  stack (so a callback through numpy or a dataclass __init__ counts);
- walk (`--variant first-call`): each distinct function (module +
  qualified name) once, in the order of its first call, as its module,
  runs of the same module merged;
- depth (`--depth 5`): only functions at most 5 calls below the entry
  (the fewest calls on any recorded path from it); `--depth all` for none.
  The figure for all depths is printed too;
- layers (`--layers facade:height`): a module's layer is the longest chain
  of package imports below it (module-level and function-level imports;
  none into the package root or its lazy API facade, `api.py`, which would
  tie pipeline, export and the root into one cycle); a cycle's modules
  share one layer.

On base, preset:demo with --duration 2 (workers 1) gives 25 re-entries
and 13 climbs through pipeline:bake_scene (issue: 28 and 10) and 36
re-entries, sim/linear.py 10, through sim.lod:_simulate_chunk (issue: 35,
linear.py 14). No definition tried reproduces all four figures; the others
(`--variant`, `--fold`, `--depth`, `--static`) stay selectable and
`--all-variants` prints them all.

    python flow.py --entry treebake.pipeline:bake_scene --scene preset:demo --duration 2
    python flow.py --entry treebake.sim.lod:_simulate_chunk --scene preset:demo --duration 2

Only the installed `treebake` package is used (its public `load_scene` and
`bake_scene`, and the module:function given), so the same script measures
a refactored checkout through that checkout's interpreter. Keep
--workers 1 (the default): chunks baked in worker processes are not seen.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import json
import os
import sys
from collections import Counter
from pathlib import Path

PACKAGE = "treebake"
TRANSPARENT = ("<listcomp>", "<dictcomp>", "<setcomp>", "<genexpr>")
CO_OPTIMIZED = 0x1  # set on function code, not on module and class bodies


# --------------------------------------------------------------------------
# the package's modules and its static import graph


def package_modules(pkg) -> dict[str, Path]:
    """module name -> file, for every .py file of the installed package."""
    root = Path(pkg.__file__).resolve().parent
    out = {}
    for p in sorted(root.rglob("*.py")):
        parts = list(p.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(not x.isidentifier() for x in parts):
            continue
        out[".".join([PACKAGE] + parts)] = p
    return out


def _resolve_from(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph(mods: dict[str, Path], scope: str = "module") -> dict[str, set[str]]:
    """module -> the package modules it imports. scope "module": imports run
    at import time (module body, also under if/try, not in functions);
    "all": every import statement, function-level (lazy) ones too;
    "facade" (the default layering): "all" without the imports of the
    package root (`from . import __version__`) and of its lazy facade (the
    modules the root imports that import the rest only inside functions,
    `api.py`), which would tie every module they name into one cycle with
    the root."""
    if scope == "facade":
        every = import_graph(mods, "all")
        top = import_graph(mods, "module")
        lazy = {m for m in top.get(PACKAGE, set())
                if not top[m] - {PACKAGE} and every[m] - {PACKAGE}}
        drop = {PACKAGE} | lazy
        return {m: ts - drop for m, ts in every.items()}
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        is_pkg = path.name == "__init__.py"

        def visit(node, top: bool):
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                    if scope == "all":
                        visit(child, False)
                    continue
                if isinstance(child, ast.ImportFrom):
                    target = _resolve_from(mod, is_pkg, child)
                    found = False
                    for a in child.names:
                        sub = f"{target}.{a.name}"
                        if sub in mods:  # `from . import chains`: the submodule
                            graph[mod].add(sub)
                            found = True
                    if target in mods and (not found or any(
                            f"{target}.{a.name}" not in mods for a in child.names)):
                        graph[mod].add(target)
                elif isinstance(child, ast.Import):
                    for a in child.names:
                        if a.name in mods:
                            graph[mod].add(a.name)
                else:
                    visit(child, top)

        visit(tree, True)
        graph[mod].discard(mod)
    return graph


def sccs(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan, iterative; components in reverse topological order."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = 0
    for v0 in graph:
        if v0 in index:
            continue
        work = [(v0, iter(sorted(graph[v0])))]
        index[v0] = low[v0] = counter
        counter += 1
        stack.append(v0)
        on.add(v0)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    advanced = True
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                out.append(sorted(comp))
    return out


def layers(graph: dict[str, set[str]], kind: str = "height") -> dict[str, int]:
    """Each module's import layer, cycles condensed. "height": the longest
    chain of imports below it (a module importing nothing of the package
    is 0); "depth": minus the longest chain of imports above it (so that,
    as for "height", a larger number is a higher layer)."""
    comps = sccs(graph)
    comp_of = {m: k for k, c in enumerate(comps) for m in c}
    dag = {k: set() for k in range(len(comps))}
    for v, ws in graph.items():
        for w in ws:
            if comp_of[v] != comp_of[w]:
                dag[comp_of[v]].add(comp_of[w])
    # Tarjan yields components with every successor before its predecessors
    h = {}
    for k in range(len(comps)):
        h[k] = 1 + max((h[j] for j in dag[k]), default=-1)
    if kind == "height":
        return {m: h[comp_of[m]] for m in graph}
    d = {k: 0 for k in dag}
    for k in reversed(range(len(comps))):
        for j in dag[k]:
            d[j] = max(d[j], d[k] + 1)
    return {m: -d[comp_of[m]] for m in graph}


# --------------------------------------------------------------------------
# the dynamic trace


def resolve_entry(spec: str):
    mod_name, _, qual = spec.partition(":")
    if not qual:
        raise SystemExit(f"--entry {spec!r}: expected module:function")
    obj = importlib.import_module(mod_name)
    for part in qual.split("."):
        obj = getattr(obj, part)
    obj = getattr(obj, "__func__", obj)
    while hasattr(obj, "__wrapped__"):
        obj = obj.__wrapped__
    return obj.__code__


class Tracer:
    """sys.settrace hook: while the entry function runs, every call into a
    `treebake` function, with its caller (the innermost treebake function
    on the stack), in call order; only first occurrences are kept."""

    def __init__(self, entry_code, file_module: dict[str, str], opaque=()):
        self.entry = entry_code
        self.opaque = set(opaque)  # functions recorded, but not followed into
        self.file_module = file_module
        self.codes: dict = {}  # code -> fid, or None for code outside the package
        self.funcs: list[dict] = []
        # [fid, first invocation?, callees not followed?] of live treebake frames
        self.stack: list[list] = []
        self.seq = 0  # order of first occurrences (functions and edges share it)
        self.edges: dict[tuple[int, int], dict] = {}
        self.sites: dict[tuple[int, int, int], int] = {}
        self.first_children: dict[int, list[int]] = {}
        self.entries = 0  # calls of the entry function (chunks)
        self.events = 0

    def _fid(self, code):
        fid = self.codes.get(code, -1)
        if fid != -1:
            return fid
        mod = self.file_module.get(code.co_filename)
        if mod is None:
            self.codes[code] = None
            return None
        if code.co_name in TRANSPARENT:
            self.codes[code] = -2
            return -2
        if not code.co_flags & CO_OPTIMIZED:  # a module or class body: import time
            self.codes[code] = -3
            return -3
        fid = len(self.funcs)
        self.funcs.append({"module": mod, "name": getattr(code, "co_qualname", code.co_name),
                           "line": code.co_firstlineno, "first": None, "calls": 0})
        self.codes[code] = fid
        return fid

    def global_trace(self, frame, event, arg):
        code = frame.f_code
        if not self.stack:
            if code is not self.entry:
                return None
            self.entries += 1
        fid = self._fid(code)
        if fid is None or fid == -2:
            return None
        if fid == -3 or (self.stack and self.stack[-1][2]):
            # an import under way, or inside an opaque function: not followed
            self.stack.append([-3, False, True])
            frame.f_trace_lines = False
            return self.local_trace
        self.events += 1
        f = self.funcs[fid]
        first = f["calls"] == 0
        f["calls"] += 1
        if first:
            f["first"] = self.seq
            self.seq += 1
        d = len(self.stack)
        if f.get("depth") is None or d < f["depth"]:
            f["depth"] = d
        if self.stack:
            caller, caller_first, _ = self.stack[-1]
            key = (caller, fid)
            e = self.edges.get(key)
            if e is None:
                self.edges[key] = e = {"first": self.seq, "calls": 0,
                                       "in_first": caller_first}
                self.seq += 1
                if caller_first:
                    self.first_children.setdefault(caller, []).append(fid)
            e["calls"] += 1
            back = frame.f_back
            line = back.f_lineno if back is not None else 0
            skey = (caller, line, fid)
            if skey not in self.sites:
                self.sites[skey] = self.seq
                self.seq += 1
        self.stack.append([fid, first, code in self.opaque])
        frame.f_trace_lines = False
        return self.local_trace

    def local_trace(self, frame, event, arg):
        if event == "return":
            self.stack.pop()
        return self.local_trace

    def raw(self) -> dict:
        return {
            "functions": self.funcs,
            "edges": [[a, b, e["first"], e["calls"], e["in_first"]]
                      for (a, b), e in self.edges.items()],
            "sites": [[a, line, b, s] for (a, line, b), s in self.sites.items()],
            "first_children": {str(k): v for k, v in self.first_children.items()},
            "entry_calls": self.entries,
            "events": self.events,
        }


def run_trace(entry: str, scene: str, duration: float | None, solver: str,
              quality: str | None, workers: int = 1, opaque=()) -> dict:
    import treebake

    mods = package_modules(treebake)
    file_module = {str(p): m for m, p in mods.items()}
    file_module.update({os.path.realpath(p): m for m, p in mods.items()})
    code = resolve_entry(entry)
    overrides = {}
    if duration is not None:
        overrides["duration"] = duration
    if quality is not None:
        overrides["quality"] = quality
    sc = treebake.load_scene(scene, **overrides)
    tracer = Tracer(code, file_module, [resolve_entry(o) for o in opaque])
    old = sys.gettrace()
    sys.settrace(tracer.global_trace)
    try:
        treebake.bake_scene(sc, solver=solver, workers=workers)
    finally:
        sys.settrace(old)
    if tracer.entries == 0:
        raise SystemExit(f"{entry} was never called while baking {scene}")
    raw = tracer.raw()
    for f in raw["functions"]:
        f["kind"] = function_kind(f["module"], f["name"])
    root = tracer.codes[code]
    raw.update({"entry": entry, "root": root, "scene": scene, "duration": duration,
                "solver": solver, "quality": quality, "workers": workers,
                "opaque": list(opaque)})
    return raw


# --------------------------------------------------------------------------
# the static alternative: the entry's source, calls in source order


class Static:
    """Calls in each function's body in source order (arguments before the
    call they are passed to), resolved through imports, definitions (nested
    functions too), classes (a call of a class is a call of its __init__ and
    __post_init__, looked up along its bases) and light type inference:
    `self`, annotated parameters, class fields and `self.x = ...`, locals
    assigned from a class or an annotated function's result, container
    annotations (`list[SimTree]`) for subscripts and for-loops. Method calls
    on an object of unknown type: `attr` "typed" skips them, "unique"
    resolves a method name defined in one class of the package only, "all"
    takes every method of that name."""

    def __init__(self, mods: dict[str, Path], attr: str = "typed"):
        self.mods = mods
        self.attr = attr
        self.cache: dict[str, dict] = {}
        self._methods = None
        self._fields: dict = {}
        self._mro: dict = {}

    # --- per module
    def info(self, mod: str) -> dict:
        if mod in self.cache:
            return self.cache[mod]
        path = self.mods[mod]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        is_pkg = path.name == "__init__.py"
        defs, imports = {}, {}

        def collect(body, prefix):
            for n in body:
                if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    defs[prefix + n.name] = n
                    collect(n.body, prefix + n.name + ".<locals>.")
                elif isinstance(n, ast.ClassDef):
                    defs[prefix + n.name] = n
                    collect(n.body, prefix + n.name + ".")
                elif isinstance(n, (ast.If, ast.Try, ast.With, ast.For, ast.While)):
                    for field in ("body", "orelse", "finalbody", "handlers"):
                        sub = getattr(n, field, None)
                        if sub:
                            collect([x for h in sub for x in (h.body if isinstance(
                                h, ast.ExceptHandler) else [h])], prefix)
        collect(tree.body, "")
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom):
                target = _resolve_from(mod, is_pkg, n)
                for a in n.names:
                    imports.setdefault(a.asname or a.name, (target, a.name))
            elif isinstance(n, ast.Import):
                for a in n.names:
                    if a.asname:
                        imports.setdefault(a.asname, (a.name, None))
        out = {"defs": defs, "imports": imports}
        self.cache[mod] = out
        return out

    def methods_named(self, name: str) -> list[tuple]:
        if self._methods is None:
            self._methods = {}
            for mod in self.mods:
                for q, n in self.info(mod)["defs"].items():
                    if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                            "." in q and ".<locals>." not in q.rsplit(".", 1)[0] + "." and \
                            isinstance(self.info(mod)["defs"].get(q.rsplit(".", 1)[0]),
                                       ast.ClassDef):
                        self._methods.setdefault(n.name, []).append(("func", mod, q))
        return self._methods.get(name, [])

    # --- names
    def lookup(self, mod: str, name: str, scope: str = "", depth: int = 0):
        """What `name` is in `mod` seen from function `scope` (qualname):
        ("func"|"class", mod, qual), ("module", mod) or None."""
        if depth > 10 or mod not in self.mods:
            return None
        info = self.info(mod)
        defs = info["defs"]
        q = scope
        while q:  # enclosing functions' own definitions, innermost first
            cand = f"{q}.<locals>.{name}"
            if cand in defs:
                return ("class" if isinstance(defs[cand], ast.ClassDef) else "func", mod, cand)
            q = q.rsplit(".<locals>.", 1)[0] if ".<locals>." in q else ""
        if name in defs:
            return ("class" if isinstance(defs[name], ast.ClassDef) else "func", mod, name)
        if name in info["imports"]:
            target, attr = info["imports"][name]
            if attr is None:
                return ("module", target) if target in self.mods else None
            if f"{target}.{attr}" in self.mods:
                return ("module", f"{target}.{attr}")
            return self.lookup(target, attr, "", depth + 1)
        return None

    def expr_target(self, mod: str, e, scope: str):
        """A name or dotted name as a module, class or function."""
        if isinstance(e, ast.Name):
            return self.lookup(mod, e.id, scope)
        if isinstance(e, ast.Attribute):
            base = self.expr_target(mod, e.value, scope)
            if base and base[0] == "module":
                if f"{base[1]}.{e.attr}" in self.mods:
                    return ("module", f"{base[1]}.{e.attr}")
                return self.lookup(base[1], e.attr)
            if base and base[0] == "class":
                return self.find_method(base, e.attr)
        if isinstance(e, ast.Constant) and isinstance(e.value, str):
            try:
                return self.expr_target(mod, ast.parse(e.value, mode="eval").body, scope)
            except SyntaxError:
                return None
        return None

    # --- classes
    def bases(self, cls) -> list[tuple]:
        _, mod, q = cls
        node = self.info(mod)["defs"][q]
        out = []
        for b in node.bases:
            t = self.expr_target(mod, b, "")
            if t and t[0] == "class":
                out.append(t)
        return out

    def mro(self, cls) -> list[tuple]:
        if cls not in self._mro:
            self._mro[cls] = []
            self._mro[cls] = self._mro_of(cls)
        return self._mro[cls]

    def _mro_of(self, cls) -> list[tuple]:
        out, todo = [], [cls]
        while todo:
            c = todo.pop(0)
            if c not in out:
                out.append(c)
                todo += self.bases(c)
        return out

    def find_method(self, cls, name: str, after=None):
        chain = self.mro(cls)
        if after is not None and after in chain:
            chain = chain[chain.index(after) + 1:]
        for c in chain:
            _, mod, q = c
            n = self.info(mod)["defs"].get(f"{q}.{name}")
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
                return ("func", mod, f"{q}.{name}")
        return None

    def field_types(self, cls, name: str) -> set:
        """Types of attribute `name` of instances of cls: class-level
        annotations, `self.name = ...` in its methods, a property's return."""
        key = (cls, name)
        if key in self._fields:
            return self._fields[key]
        self._fields[key] = set()  # while it is worked out (cycles)
        out = self._field_types(cls, name)
        self._fields[key] = out
        return out

    def _field_types(self, cls, name: str) -> set:
        out = set()
        for c in self.mro(cls):
            _, mod, q = c
            node = self.info(mod)["defs"][q]
            for st in node.body:
                if isinstance(st, ast.AnnAssign) and isinstance(st.target, ast.Name) and \
                        st.target.id == name:
                    out |= self.ann_types(mod, st.annotation, q)
                if isinstance(st, ast.FunctionDef) and st.name == name and \
                        any(isinstance(d, ast.Name) and d.id in ("property", "cached_property")
                            or isinstance(d, ast.Attribute) and d.attr == "cached_property"
                            for d in st.decorator_list) and st.returns is not None:
                    out |= self.ann_types(mod, st.returns, q)
            for st in node.body:
                if isinstance(st, ast.FunctionDef) and st.args.args:
                    me = st.args.args[0].arg
                    env = None
                    for n in ast.walk(st):
                        if isinstance(n, (ast.Assign, ast.AnnAssign)):
                            targets = n.targets if isinstance(n, ast.Assign) else [n.target]
                            for t in targets:
                                if isinstance(t, ast.Attribute) and t.attr == name and \
                                        isinstance(t.value, ast.Name) and t.value.id == me:
                                    if isinstance(n, ast.AnnAssign):
                                        out |= self.ann_types(mod, n.annotation, q)
                                    if n.value is not None:
                                        if env is None:
                                            env = self.param_env(mod, f"{q}.{st.name}", st)
                                        out |= self.types(mod, n.value, env,
                                                          f"{q}.{st.name}", 1)
        return out

    def ann_types(self, mod: str, ann, scope: str) -> set:
        """Classes an annotation names: X, X | None, Optional[X], list[X]
        and the like (("seq", X): a container of X), quoted or not."""
        if ann is None:
            return set()
        if isinstance(ann, ast.Constant) and isinstance(ann.value, str):
            try:
                ann = ast.parse(ann.value, mode="eval").body
            except SyntaxError:
                return set()
        if isinstance(ann, ast.BinOp) and isinstance(ann.op, ast.BitOr):
            return self.ann_types(mod, ann.left, scope) | self.ann_types(mod, ann.right, scope)
        if isinstance(ann, ast.Subscript):
            outer = ann.value.id if isinstance(ann.value, ast.Name) else \
                ann.value.attr if isinstance(ann.value, ast.Attribute) else ""
            inner = ann.slice.elts if isinstance(ann.slice, ast.Tuple) else [ann.slice]
            if outer in ("Optional", "Union"):
                return set().union(*(self.ann_types(mod, x, scope) for x in inner))
            if outer in ("list", "List", "tuple", "Tuple", "Sequence", "Iterable", "set",
                         "frozenset"):
                return {("seq",) + t[1:] for x in inner for t in self.ann_types(mod, x, scope)
                        if t[0] == "class"}
            return set()
        t = self.expr_target(mod, ann, scope)
        return {t} if t and t[0] == "class" else set()

    # --- expressions
    def param_env(self, mod: str, qual: str, node) -> dict:
        env = {}
        args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
        cls = qual.rsplit(".", 1)[0] if "." in qual else None
        is_method = cls is not None and isinstance(self.info(mod)["defs"].get(cls), ast.ClassDef)
        static = any(isinstance(d, ast.Name) and d.id == "staticmethod"
                     for d in node.decorator_list)
        for k, a in enumerate(args):
            if k == 0 and is_method and not static:
                env[a.arg] = {("class", mod, cls)}
                continue
            env[a.arg] = self.ann_types(mod, a.annotation, qual)
        return env

    def types(self, mod: str, e, env: dict, scope: str, depth: int = 0) -> set:
        if depth > 4:
            return set()
        if isinstance(e, ast.Name):
            return env.get(e.id, set())
        if isinstance(e, ast.Attribute):
            out = set()
            for t in self.types(mod, e.value, env, scope, depth + 1):
                if t[0] == "class":
                    out |= self.field_types(t, e.attr)
            return out
        if isinstance(e, ast.Subscript):
            return {("class",) + t[1:] for t in self.types(mod, e.value, env, scope, depth + 1)
                    if t[0] == "seq"}
        if isinstance(e, ast.Call):
            out = set()
            for t in self.call_targets(mod, e.func, env, scope, depth + 1):
                if t[0] == "class":
                    out.add(t)
                elif t[0] == "func":
                    node = self.info(t[1])["defs"].get(t[2])
                    if node is not None and getattr(node, "returns", None) is not None:
                        out |= self.ann_types(t[1], node.returns, t[2])
            return out
        if isinstance(e, ast.IfExp):
            return self.types(mod, e.body, env, scope, depth + 1) | \
                self.types(mod, e.orelse, env, scope, depth + 1)
        if isinstance(e, ast.BoolOp):
            return set().union(*(self.types(mod, v, env, scope, depth + 1) for v in e.values))
        if isinstance(e, (ast.List, ast.Tuple)) and e.elts:
            return {("seq",) + t[1:] for t in self.types(mod, e.elts[0], env, scope, depth + 1)
                    if t[0] == "class"}
        if isinstance(e, ast.ListComp):
            return {("seq",) + t[1:] for t in self.types(mod, e.elt, env, scope, depth + 1)
                    if t[0] == "class"}
        return set()

    def call_targets(self, mod: str, f, env: dict, scope: str, depth: int = 0) -> list:
        """What a call's function expression calls: ("func", ...) entries,
        and ("class", ...) for a class (its __init__ is added by the caller)."""
        if isinstance(f, ast.Name):
            if f.id in env:
                return []  # a callable held in a variable
            t = self.lookup(mod, f.id, scope)
            return [t] if t and t[0] in ("func", "class") else []
        if isinstance(f, ast.Attribute):
            # super().m()
            if isinstance(f.value, ast.Call) and isinstance(f.value.func, ast.Name) and \
                    f.value.func.id == "super":
                cls = scope.rsplit(".", 1)[0] if "." in scope else None
                if cls and isinstance(self.info(mod)["defs"].get(cls), ast.ClassDef):
                    m = self.find_method(("class", mod, cls), f.attr, ("class", mod, cls))
                    return [m] if m else []
                return []
            t = None
            if isinstance(f.value, (ast.Name, ast.Attribute)) and not (
                    isinstance(f.value, ast.Name) and f.value.id in env):
                t = self.expr_target(mod, f, scope)
                if t and t[0] in ("func", "class"):
                    return [t]
                base = self.expr_target(mod, f.value, scope)
                if base and base[0] in ("module", "class"):
                    return []
            out = []
            for ty in sorted(self.types(mod, f.value, env, scope, depth + 1)):
                if ty[0] == "class":
                    m = self.find_method(ty, f.attr)
                    if m and m not in out:
                        out.append(m)
            if out:
                return out
            if self.attr == "unique":
                c = self.methods_named(f.attr)
                return c if len(c) == 1 else []
            if self.attr == "all":
                return list(self.methods_named(f.attr))
        return []

    def calls(self, key) -> list[tuple]:
        """The functions `key` = ("func", mod, qual) calls, in source order."""
        _, mod, qual = key
        node = self.info(mod)["defs"].get(qual)
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            return []
        env = self.param_env(mod, qual, node)
        me = self
        out: list[tuple] = []

        def add(ts):
            for t in ts:
                if t[0] == "class":
                    for name in ("__init__", "__post_init__"):
                        m = me.find_method(t, name)
                        if m:
                            out.append(m)
                else:
                    out.append(t)

        class V(ast.NodeVisitor):
            def visit_FunctionDef(self, n):
                if n is node:
                    for st in n.body:
                        self.visit(st)

            visit_AsyncFunctionDef = visit_FunctionDef

            def visit_ClassDef(self, n):
                pass

            def visit_Lambda(self, n):
                pass

            def visit_Assign(self, n):
                self.visit(n.value)
                ts = me.types(mod, n.value, env, qual)
                for t in n.targets:
                    self.visit(t)
                    if isinstance(t, ast.Name) and ts:
                        env[t.id] = env.get(t.id, set()) | ts

            def visit_AnnAssign(self, n):
                if n.value is not None:
                    self.visit(n.value)
                if isinstance(n.target, ast.Name):
                    env[n.target.id] = env.get(n.target.id, set()) | \
                        me.ann_types(mod, n.annotation, qual) | \
                        (me.types(mod, n.value, env, qual) if n.value is not None else set())

            def visit_For(self, n):
                self.visit(n.iter)
                if isinstance(n.target, ast.Name):
                    ts = {("class",) + t[1:] for t in me.types(mod, n.iter, env, qual)
                          if t[0] == "seq"}
                    if ts:
                        env[n.target.id] = env.get(n.target.id, set()) | ts
                for st in n.body + n.orelse:
                    self.visit(st)

            def visit_Call(self, n):
                for a in n.args:
                    self.visit(a)
                for k in n.keywords:
                    self.visit(k.value)
                self.visit(n.func)
                add(me.call_targets(mod, n.func, env, qual))

        V().visit(node)
        return out


def static_raw(entry: str, attr: str = "typed") -> dict:
    """The same shape as run_trace's record, from the source alone: each
    function once, depth first, its calls in source order."""
    import treebake

    mods = package_modules(treebake)
    code = resolve_entry(entry)
    file_module = {os.path.realpath(p): m for m, p in mods.items()}
    root_mod = file_module[os.path.realpath(code.co_filename)]
    root = ("func", root_mod, code.co_qualname)
    st = Static(mods, attr)
    fids: dict[tuple, int] = {}
    funcs, edges, first_children = [], [], {}
    seq = 0

    def fid(key):
        nonlocal seq
        if key not in fids:
            fids[key] = len(funcs)
            funcs.append({"module": key[1], "name": key[2], "line": 0, "first": seq,
                          "calls": 1, "kind": function_kind(key[1], key[2])})
            seq += 1
        return fids[key]

    seen_edges = set()
    done = set()

    def expand(key):
        nonlocal seq
        if key in done:
            return
        done.add(key)
        a = fid(key)
        for callee in st.calls(key):
            b = fid(callee)
            if (a, b) not in seen_edges:
                seen_edges.add((a, b))
                edges.append([a, b, seq, 1, True])
                seq += 1
                first_children.setdefault(str(a), []).append(b)
            expand(callee)

    sys.setrecursionlimit(20000)
    fid(root)
    expand(root)
    return {"functions": funcs, "edges": edges, "sites": [], "first_children": first_children,
            "entry": entry, "root": fids[root], "scene": None, "static": True,
            "static_attr": attr, "entry_calls": 1}


# --------------------------------------------------------------------------
# from the record to a walk over modules


FOLDS = ("none", "lambdas", "nested", "accessors")


def function_kind(module: str, qualname: str) -> str:
    """lambda, nested (defined in a function), property (a property's or
    cached_property's getter/setter), dunder (__x__ methods), or function."""
    if qualname.endswith("<lambda>"):
        return "lambda"
    if ".<locals>." in qualname:
        return "nested"
    parts = qualname.split(".")
    if parts[-1].startswith("__") and parts[-1].endswith("__"):
        return "dunder"
    if len(parts) >= 2:
        try:
            import functools
            import inspect
            obj = importlib.import_module(module)
            for p in parts[:-1]:
                obj = getattr(obj, p)
            attr = inspect.getattr_static(obj, parts[-1], None)
            if isinstance(attr, (property, functools.cached_property)):
                return "property"
        except Exception:
            pass
    return "function"


def fold(raw: dict, what: str) -> dict:
    """The record with some functions folded into their callers: "lambdas"
    (`<lambda>`), "nested" (lambdas and functions defined inside functions,
    `<locals>`), "accessors" (those, properties and __dunder__ methods). A
    folded function's callees become its caller's (the caller of its first
    call), in its place."""
    if what == "none":
        return raw
    funcs = raw["functions"]
    kinds = [f.get("kind") or function_kind(f["module"], f["name"]) for f in funcs]
    fold_kinds = {"lambdas": ("lambda",), "nested": ("lambda", "nested"),
                  "accessors": ("lambda", "nested", "property", "dunder")}[what]
    gone = {i for i in range(len(funcs)) if kinds[i] in fold_kinds and i != raw["root"]}
    if not gone:
        return raw
    first_caller = {}
    for a, b, *_ in sorted(raw["edges"], key=lambda e: e[2]):
        first_caller.setdefault(b, a)

    def up(a):
        seen = set()
        while a in gone and a in first_caller and a not in seen:
            seen.add(a)
            a = first_caller[a]
        return a

    edges, keys = [], {}
    for a, b, s, n, inf in sorted(raw["edges"], key=lambda e: e[2]):
        if b in gone:
            continue
        a2 = up(a)
        if a2 in gone or a2 == b:
            continue
        if (a2, b) in keys:
            keys[(a2, b)][3] += n
            continue
        keys[(a2, b)] = e = [a2, b, s, n, inf]
        edges.append(e)
    sites, seen_sites = [], set()
    for a, line, b, s in sorted(raw["sites"], key=lambda x: x[3]):
        if b in gone:
            continue
        a2 = up(a)
        if a2 in gone or a2 == b or (a2, line, b) in seen_sites:
            continue
        seen_sites.add((a2, line, b))
        sites.append([a2, line, b, s])
    kids = {int(k): v for k, v in raw["first_children"].items()}

    def inline(lst, depth=0):
        out = []
        for g in lst:
            if g in gone:
                if depth < 20:
                    out += [x for x in inline(kids.get(g, []), depth + 1) if x not in out]
            elif g not in out:
                out.append(g)
        return out

    fc = {str(k): inline(v) for k, v in kids.items() if k not in gone}
    nf = [dict(f, first=None) if i in gone else f for i, f in enumerate(funcs)]
    return dict(raw, functions=nf, edges=edges, sites=sites, first_children=fc)


def call_depths(raw: dict) -> dict[int, int]:
    """Each function's fewest calls below the entry (breadth first over the
    recorded caller->callee pairs; on the traces of base this is the
    shallowest call stack the function was seen on)."""
    kids: dict[int, list[int]] = {}
    for a, b, *_ in raw["edges"]:
        kids.setdefault(a, []).append(b)
    depth = {raw["root"]: 0}
    todo = [raw["root"]]
    while todo:
        nxt = []
        for a in todo:
            for b in kids.get(a, []):
                if b not in depth:
                    depth[b] = depth[a] + 1
                    nxt.append(b)
        todo = nxt
    return depth


def within(raw: dict, depth: int | None) -> dict:
    """The record without the functions more than `depth` calls below the
    entry (and the calls into them)."""
    if depth is None:
        return raw
    dd = call_depths(raw)
    near = {f for f, d in dd.items() if d <= depth}
    return dict(raw, edges=[e for e in raw["edges"] if e[0] in near and e[1] in near],
                functions=[f if i in near else dict(f, first=None)
                           for i, f in enumerate(raw["functions"])],
                sites=[s for s in raw["sites"] if s[0] in near and s[2] in near],
                first_children={k: [g for g in v if g in near]
                                for k, v in raw["first_children"].items() if int(k) in near})


def _dfs_order(raw, children_of, returns: bool):
    """Depth first from the root over `children_of`, each function expanded
    once; the functions in visiting order (with the caller again after each
    callee when `returns`)."""
    order, seen = [], set()

    def visit(f):
        seen.add(f)
        order.append(f)
        for g in children_of.get(f, []):
            if g not in seen:
                visit(g)
                if returns:
                    order.append(f)

    sys.setrecursionlimit(100000)
    visit(raw["root"])
    return order


VARIANTS = {
    "first-call": "each distinct function once, in the order of its first call (default)",
    "dfs": "depth first from the entry, each function once, its callees (from all its "
           "calls) in the order first seen",
    "dfs-first": "as dfs, following only the callees of each function's first call",
    "dfs-returns": "as dfs, and back to the caller's module after each callee",
    "dfs-first-returns": "as dfs-first, and back to the caller's module after each callee",
    "first-edge": "each distinct caller->callee pair once, in order: caller, then callee",
    "first-edge-callee": "each distinct caller->callee pair once, in order: the callee",
    "first-site": "each distinct call site (caller line->callee) once: caller, then callee",
    "cross-edge": "each distinct caller->callee pair across modules once: the callee",
    "cross-callee": "each function called from another module once: the callee",
    "cross-modpair": "each distinct module->module call once: the callee module",
    "cross-modpair-return": "each distinct module->module call once: caller, callee, caller",
}


def walk(raw: dict, variant: str, depth: int | None = None) -> tuple[list[str], list]:
    """The walk over modules for one collapse definition, runs of a module
    merged; and the functions (ids) it steps through (None where a step is
    a module only)."""
    raw = within(raw, depth)
    funcs = raw["functions"]
    mod = lambda i: funcs[i]["module"]  # noqa: E731
    edges = sorted(raw["edges"], key=lambda e: e[2])
    root = raw["root"]
    if variant == "first-call":
        fids = sorted((i for i, f in enumerate(funcs) if f["first"] is not None),
                      key=lambda i: funcs[i]["first"])
    elif variant == "first-edge":
        fids = [root] + [x for a, b, *_ in edges for x in (a, b)]
    elif variant == "first-edge-callee":
        fids = [root] + [b for _, b, *_ in edges]
    elif variant == "first-site":
        fids = [root] + [x for a, _, b, _ in sorted(raw["sites"], key=lambda s: s[3])
                         for x in (a, b)]
    elif variant in ("dfs", "dfs-returns"):
        kids: dict[int, list[int]] = {}
        for a, b, *_ in edges:
            kids.setdefault(a, []).append(b)
        fids = _dfs_order(raw, kids, variant == "dfs-returns")
    elif variant in ("dfs-first", "dfs-first-returns"):
        kids = {int(k): v for k, v in raw["first_children"].items()}
        fids = _dfs_order(raw, kids, variant == "dfs-first-returns")
    elif variant.startswith("cross-"):
        key = {"cross-edge": lambda a, b: (a, b), "cross-callee": lambda a, b: b,
               "cross-modpair": lambda a, b: (mod(a), mod(b)),
               "cross-modpair-return": lambda a, b: (mod(a), mod(b))}[variant]
        fids, seen = [root], set()
        for a, b, *_ in edges:
            if mod(a) == mod(b) or key(a, b) in seen:
                continue
            seen.add(key(a, b))
            fids += [a, b, a] if variant == "cross-modpair-return" else [b]
    else:
        raise ValueError(variant)
    steps, mods = [], []
    for i in fids:
        m = mod(i)
        if not mods or mods[-1] != m:
            mods.append(m)
            steps.append(i)
    return mods, steps


def measure(walk_: list[str], layer: dict[str, int]) -> dict:
    """Re-entries (total, per module) and climbs: steps into a module
    already visited on a higher layer ("climbs back up"; `climbs_any`:
    every step to a higher layer)."""
    seen, per, back, anyup, marks = set(), Counter(), [], 0, []
    for k, m in enumerate(walk_):
        re = m in seen
        up = k > 0 and layer.get(m, 0) > layer.get(walk_[k - 1], 0)
        if re:
            per[m] += 1
        if up:
            anyup += 1
            if re:
                back.append((walk_[k - 1], m))
        marks.append((re, up and re, up))
        seen.add(m)
    return {"reentries": sum(per.values()), "per_module": dict(per.most_common()),
            "climbs": len(back), "climbs_any": anyup,
            "climb_steps": [f"{a} -> {b}" for a, b in back],
            "modules": len(seen), "steps": len(walk_), "marks": marks}


def short(mod: str) -> str:
    return mod[len(PACKAGE) + 1:] if mod.startswith(PACKAGE + ".") else mod


def module_file(mod: str, mods: dict[str, Path]) -> str:
    p = mods.get(mod)
    if p is None:
        return short(mod)
    root = Path(importlib.import_module(PACKAGE).__file__).resolve().parent
    return p.resolve().relative_to(root).as_posix()


# --------------------------------------------------------------------------


DEFAULT_DEPTH = 5


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--entry", required=True, metavar="MODULE:FUNCTION",
                    help="the function whose data to follow, e.g. treebake.pipeline:bake_scene "
                         "(Class.method works too)")
    ap.add_argument("--scene", default="preset:demo",
                    help="what treebake.load_scene takes: preset:NAME, a .toml, a .lsys, a "
                         "bundled grammar (default preset:demo)")
    ap.add_argument("--duration", type=float, default=2.0,
                    help="the scene's duration override, s (default 2)")
    ap.add_argument("--quality", default=None, help="quality override (draft/default/final)")
    ap.add_argument("--solver", default="planar", help="planar (default) or full")
    ap.add_argument("--workers", type=int, default=1,
                    help="bake_scene's worker processes (default 1: every chunk runs in this "
                         "process, where the tracer sees it)")
    ap.add_argument("--opaque", action="append", default=[], metavar="MODULE:FUNCTION",
                    help="a function recorded but not followed into (repeatable)")
    ap.add_argument("--depth", default=str(DEFAULT_DEPTH),
                    help=f"only functions at most this many calls below the entry "
                         f"(default {DEFAULT_DEPTH}; 'all' for no limit)")
    ap.add_argument("--variant", default="first-call", choices=list(VARIANTS),
                    help="how repetition is collapsed into a walk (default first-call)")
    ap.add_argument("--fold", default="none", choices=FOLDS,
                    help="fold lambdas / nested functions / accessors into their callers "
                         "(default none)")
    ap.add_argument("--layers", default="facade:height",
                    help="import layers: SCOPE:KIND, SCOPE facade (every import, lazy ones "
                         "too, but none into the package root or its lazy API facade; default), "
                         "all, or module (module-level imports only); KIND height (longest "
                         "import chain below; default) or depth")
    ap.add_argument("--static", action="store_true",
                    help="no bake: follow the entry's calls in its source instead")
    ap.add_argument("--static-attr", default="typed", choices=("typed", "unique", "all"),
                    help="--static: method calls on objects of unknown type: skip (typed), "
                         "resolve a method name defined once in the package (unique), or all")
    ap.add_argument("--walk", action="store_true",
                    help="print the walk: each step's module, layer, re-entry/climb, function")
    ap.add_argument("--all-variants", action="store_true",
                    help="also print the figures of every other definition")
    ap.add_argument("--json", metavar="PATH", help="write the figures and the walk as JSON")
    ap.add_argument("--save-raw", metavar="PATH", help="keep the trace record (JSON)")
    ap.add_argument("--from-raw", metavar="PATH", help="measure a kept trace record, no bake")
    a = ap.parse_args(argv)
    depth = None if a.depth in ("all", "none", "") else int(a.depth)

    import treebake

    mods = package_modules(treebake)
    if a.from_raw:
        raw = json.loads(Path(a.from_raw).read_text())
    elif a.static:
        raw = static_raw(a.entry, a.static_attr)
    else:
        raw = run_trace(a.entry, a.scene, a.duration, a.solver, a.quality, a.workers, a.opaque)
    if a.save_raw:
        Path(a.save_raw).write_text(json.dumps(raw))

    scope, _, kind = a.layers.partition(":")
    layer_sets = {f"{s}:{k}": None for s in ("facade", "all", "module") for k in ("height", "depth")}

    def layer_of(spec):
        if layer_sets.get(spec) is None:
            s, _, k = spec.partition(":")
            layer_sets[spec] = layers(import_graph(mods, s), k or "height")
        return layer_sets[spec]

    layer = layer_of(f"{scope}:{kind or 'height'}")
    rf = fold(raw, a.fold)
    w, steps = walk(rf, a.variant, depth)
    res = measure(w, layer)
    w_all, _ = walk(rf, a.variant, None)
    res_all = measure(w_all, layer)

    if raw.get("static"):
        src = f"static (source order, --static-attr {raw.get('static_attr')})"
    else:
        src = (f"scene {raw['scene']}, duration {raw['duration']} s, solver {raw['solver']}, "
               f"workers {raw.get('workers', 1)}"
               + (f", opaque {', '.join(raw['opaque'])}" if raw.get("opaque") else ""))
    print(f"entry {raw['entry']}: {src}")
    print(f"definition: walk {a.variant}, fold {a.fold}, depth <= {depth if depth is not None else 'all'}"
          f", layers {a.layers}")
    funcs = rf["functions"]
    called = sum(1 for f in funcs if f["first"] is not None)
    print(f"  {called} distinct functions in {res_all['modules']} modules"
          + (f", entry called {raw.get('entry_calls')} time(s)" if not raw.get("static") else "")
          + f"; within the depth: {res['modules']} modules, {res['steps']} steps")
    print(f"re-entries: {res['reentries']}")
    print(f"climbs back up the import layers: {res['climbs']}  "
          f"(every step up a layer: {res['climbs_any']})")
    print("re-entries per module:")
    for m, n in res["per_module"].items():
        print(f"  {n:4d}  {module_file(m, mods)}")
    if depth is not None:
        print(f"all depths: re-entries {res_all['reentries']}, climbs back up {res_all['climbs']}; "
              + ", ".join(f"{module_file(m, mods)} {n}"
                          for m, n in list(res_all["per_module"].items())[:5]))
    if a.walk:
        print(f"walk ({res['steps']} steps; L = layer):")
        for m, i, (re, climb, up) in zip(w, steps, res["marks"]):
            f = funcs[i]
            print(f"  L{layer.get(m, 0):<3d} {short(m):26s} {'re-enter' if re else '':9s}"
                  f"{'climb' if climb else ('up' if up else ''):6s} {f['name']}")
    table = []
    if a.all_variants:
        print("other definitions (re-entries, climbs back up, every step up; most re-entered):")
        for fd in FOLDS:
            rfx = fold(raw, fd)
            for v in VARIANTS:
                for d in ([depth, None] if depth is not None else [None]):
                    r = measure(walk(rfx, v, d)[0], layer)
                    top = ", ".join(f"{short(m)} {n}" for m, n in list(r["per_module"].items())[:4])
                    table.append({"fold": fd, "variant": v, "depth": d,
                                  "reentries": r["reentries"], "climbs": r["climbs"],
                                  "climbs_any": r["climbs_any"], "per_module": r["per_module"]})
                    print(f"  {fd:9s} {v:21s} d<={str(d if d is not None else 'all'):3s} "
                          f"{r['reentries']:4d} {r['climbs']:4d} {r['climbs_any']:4d}   {top}")
        print("this definition's climbs under other layerings (back up / every step up):")
        for spec in layer_sets:
            r = measure(w, layer_of(spec))
            print(f"  {spec:14s} {r['climbs']:4d} {r['climbs_any']:4d}")
    if a.json:
        out = {"entry": raw["entry"], "scene": raw.get("scene"), "duration": raw.get("duration"),
               "solver": raw.get("solver"), "workers": raw.get("workers"),
               "opaque": raw.get("opaque", []), "static": bool(raw.get("static")),
               "definition": {"variant": a.variant, "fold": a.fold, "depth": depth,
                              "layers": a.layers},
               "reentries": res["reentries"], "climbs": res["climbs"],
               "climbs_any": res["climbs_any"],
               "per_module": {module_file(m, mods): n for m, n in res["per_module"].items()},
               "climb_steps": res["climb_steps"],
               "all_depths": {"reentries": res_all["reentries"], "climbs": res_all["climbs"],
                              "per_module": {module_file(m, mods): n
                                             for m, n in res_all["per_module"].items()}},
               "walk": [{"module": m, "layer": layer.get(m, 0), "reentry": re, "climb": cl,
                         "function": funcs[i]["name"]}
                        for m, i, (re, cl, _) in zip(w, steps, res["marks"])]}
        if table:
            out["other_definitions"] = table
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
