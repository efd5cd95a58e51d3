"""The shape of the code (issue 21): no import circle, no file over 1,000 lines (issue 28: modules cut by concept, not to a cap), no function over 80 lines of
code in the packages, at most 4 static/dynamic switches (issue 28).  The layer contracts themselves are checked by
``lint-imports`` (``make test``)."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("models", "identification", "oed", "reports", "mudoe")
MAX_FILE_LINES = 1000
MAX_FUNCTION_CODE_LINES = 80
#: a static/dynamic switch: what ``grep -rn "is_dynamic\|isinstance(.*Dynamic" models identification oed reports mudoe
#: --include=*.py`` finds
SWITCH = re.compile(r"is_dynamic|isinstance\(.*Dynamic")
#: issue 28's target: the kind of a model is asked by its fit strategy (identification.fit.problem.strategy_for), the rest
#: read what differs from the strategy
MAX_SWITCHES = 4


def _sources(root: Path = ROOT):
    for pkg in PACKAGES:
        yield from sorted((root / pkg).rglob("*.py"))


def static_dynamic_switches(root: Path = ROOT) -> list:
    """Every line of the packages under ``root`` that asks whether a model or its data are dynamic, as "path:line: text"."""
    return [f"{p.relative_to(root)}:{k}: {line.strip()}" for p in _sources(root)
            for k, line in enumerate(p.read_text().splitlines(), 1) if SWITCH.search(line)]


def _code_lines(lines: list, node) -> int:
    """Lines of a function that hold code: not blank, not a comment, not its docstring."""
    doc = set()
    body = node.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
            and isinstance(body[0].value.value, str):
        doc = set(range(body[0].lineno, body[0].end_lineno + 1))
    return sum(1 for i in range(node.lineno, node.end_lineno + 1)
               if i not in doc and lines[i - 1].strip() and not lines[i - 1].strip().startswith("#"))


def _strongly_connected(adj: dict) -> list:
    """Tarjan's strongly connected components with more than one module (the import circles)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in adj[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(adj):
        if v not in index:
            visit(v)
    return out


def circles(*packages: str) -> list:
    """The groups of modules that import each other in a circle: strongly connected components of more
    than one module of grimp's import graph (every import counts, deferred ones inside functions too;
    a package's ``__init__`` importing its own modules does not)."""
    graph = grimp.build_graph(*packages, include_external_packages=False)
    mods = set(graph.modules)
    adj = {m: sorted(graph.find_modules_directly_imported_by(m) & mods) for m in mods}
    adj = {m: [w for w in ws if not m.startswith(w + ".") and not w.startswith(m + ".")] for m, ws in adj.items()}
    return _strongly_connected(adj)


def test_no_import_circle():
    assert circles(*PACKAGES) == []


def test_the_circle_finder_sees_a_circle(tmp_path, monkeypatch):
    pkg = tmp_path / "circ_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from . import a\n")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from . import a\n")          # deferred: still a circle
    monkeypatch.syspath_prepend(str(tmp_path))
    assert circles("circ_pkg") == [["circ_pkg.a", "circ_pkg.b"]]


def test_no_file_over_1000_lines():
    long = {str(p.relative_to(ROOT)): n for p in _sources() if (n := len(p.read_text().splitlines())) > MAX_FILE_LINES}
    assert long == {}


def test_no_function_over_80_lines_of_code():
    long = {}
    for p in _sources():
        src = p.read_text()
        lines = src.splitlines()
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = _code_lines(lines, node)
                if n > MAX_FUNCTION_CODE_LINES:
                    long[f"{p.relative_to(ROOT)}:{node.lineno}:{node.name}"] = n
    assert long == {}


def test_the_size_rules_see_a_long_function():
    lines = ["def f():", '    """doc', '    string"""'] + ["    x = 1", "    # a comment", ""] * 81 + ["    return x"]
    node = ast.parse("\n".join(lines)).body[0]
    assert _code_lines(lines, node) == 83            # def, 81 assignments, return


def test_at_most_four_static_dynamic_switches():
    """Issue 28: the static/dynamic question is asked once (identification.fit.problem.strategy_for); the studies, the
    designs and mudoe read what differs from the strategy."""
    found = static_dynamic_switches()
    assert len(found) <= MAX_SWITCHES, f"{len(found)} static/dynamic switches (at most {MAX_SWITCHES}):\n" + "\n".join(found)


def test_the_switch_count_sees_a_switch(tmp_path):
    (tmp_path / "oed").mkdir()
    (tmp_path / "oed" / "a.py").write_text('x = 1\nif getattr(model, "is_dynamic", False):\n    pass\n'
                                           "ok = isinstance(data, DynamicMeasurements)\n")
    assert static_dynamic_switches(tmp_path) == ['oed/a.py:2: if getattr(model, "is_dynamic", False):',
                                                 "oed/a.py:4: ok = isinstance(data, DynamicMeasurements)"]


@pytest.mark.parametrize("name", ["identification.fit", "identification.inference", "identification.studies"])
def test_floors_are_packages(name):
    """The three floors of identification exist as sub-packages (their order is import-linter's contract)."""
    assert (ROOT / name.replace(".", "/") / "__init__.py").is_file()


def test_tests_mirror_the_packages():
    """Every test folder names a package or sub-package (tests/identification/fit tests identification/fit)."""
    folders = [d for d in (ROOT / "tests").rglob("*") if d.is_dir() and d.name != "__pycache__"
               and "data" not in d.relative_to(ROOT / "tests").parts]
    assert folders, "no test folder found"
    strays = [str(d.relative_to(ROOT)) for d in folders
              if not (ROOT / d.relative_to(ROOT / "tests") / "__init__.py").is_file()]
    assert strays == []


# ------------------------------------------------------------------ no test decides on the wall clock (issue 27)
#: the clocks of the ``time`` module: a value computed from one of them is a wall-clock (or CPU-clock) reading
CLOCKS = {"time", "time_ns", "monotonic", "monotonic_ns", "perf_counter", "perf_counter_ns", "process_time",
          "process_time_ns", "thread_time", "thread_time_ns"}
#: names and attributes that hold a duration by this project's conventions (a parameter ``dt``, ``r.wall_time``)
DURATION_WORDS = {"dt", "elapsed", "wall", "wall_time", "duration", "runtime", "seconds", "took", "cpu_time",
                  "elapsed_s", "wall_s", "timings"}


def _name_of(node) -> str:
    return node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""


class _Clocks:
    """Which names and functions of one module hold clock readings (to a fixed point over the module)."""

    def __init__(self, tree):
        self.clock_aliases = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                              and n.module == "time" for a in n.names if a.name in CLOCKS}
        self.timed_functions: set = set()
        self.timed_names: set = set(DURATION_WORDS)
        functions = [n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))]
        while True:
            before = (len(self.timed_functions), len(self.timed_names))
            for n in ast.walk(tree):
                if isinstance(n, (ast.Assign, ast.AnnAssign, ast.AugAssign)) and n.value is not None \
                        and self.timed(n.value):
                    targets = n.targets if isinstance(n, ast.Assign) else [n.target]
                    self.timed_names |= {t.id for tg in targets for t in ast.walk(tg) if isinstance(t, ast.Name)}
            for f in functions:
                if any(isinstance(r, ast.Return) and r.value is not None and self.timed(r.value)
                       for r in ast.walk(f)):
                    self.timed_functions.add(f.name)
            if (len(self.timed_functions), len(self.timed_names)) == before:
                return

    def is_clock_call(self, node) -> bool:
        if not isinstance(node, ast.Call):
            return False
        f = node.func
        if isinstance(f, ast.Attribute) and f.attr in CLOCKS and _name_of(f.value) == "time":
            return True
        return _name_of(f) in self.clock_aliases or _name_of(f) in self.timed_functions

    def timed(self, expr) -> bool:
        for n in ast.walk(expr):
            if self.is_clock_call(n):
                return True
            if isinstance(n, ast.Name) and n.id in self.timed_names:
                return True
            if isinstance(n, ast.Attribute) and n.attr in DURATION_WORDS:
                return True
        return False


def wall_clock_assertions(source: str) -> list:
    """Lines of ``assert`` statements that compare a clock reading (or a duration) with a bound other than
    zero: such a test passes or fails with the load of the machine.  ``assert r.wall_time >= 0`` is fine."""
    tree = ast.parse(source)
    clocks = _Clocks(tree)
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Assert):
            continue
        for cmp in (c for c in ast.walk(node.test) if isinstance(c, ast.Compare)):
            sides = [cmp.left, *cmp.comparators]
            ordered = any(isinstance(op, (ast.Lt, ast.LtE, ast.Gt, ast.GtE)) for op in cmp.ops)
            zero = any(isinstance(s, ast.Constant) and s.value == 0 for s in sides)
            if ordered and not zero and any(clocks.timed(s) for s in sides):
                found.append(node.lineno)
                break
    return found


def test_no_test_asserts_on_the_wall_clock():
    """Speed goals live in bench/ (bench/RESULTS.md); a test that compares a time with a bound is flaky under
    load.  A time limit that decides a result gets a node or iteration limit in tests instead."""
    found = {f"{p.relative_to(ROOT)}:{line}" for p in sorted((ROOT / "tests").rglob("*.py"))
             for line in wall_clock_assertions(p.read_text())}
    assert sorted(found) == []


@pytest.mark.parametrize("source", [
    "import time\nt0 = time.perf_counter()\nwork()\nassert time.perf_counter() - t0 < 1.0\n",
    "import time\ndef f():\n    t = time.monotonic()\n    return time.monotonic() - t\ndef test():\n"
    "    x = f()\n    assert x < 10\n",
    "from time import perf_counter as pc\nstart = pc()\nassert pc() - start <= 2\n",
    "def check(dt):\n    assert dt < 10.0\n",
    "def test(r):\n    assert r.wall_time < 5.0\n",
])
def test_the_wall_clock_guard_sees_a_timed_assertion(source):
    assert wall_clock_assertions(source) != []


@pytest.mark.parametrize("source", [
    "def test(r):\n    assert r.wall_time >= 0\n",
    "import time\nend = time.monotonic() + 60\nwhile time.monotonic() < end:\n    pass\nassert done()\n",
    "def test(r):\n    assert r.value < 10.0\n",
])
def test_the_wall_clock_guard_lets_other_assertions_pass(source):
    assert wall_clock_assertions(source) == []
