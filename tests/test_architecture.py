"""The shape of the code (issue 21): no import circle, no file over 800 lines, no function over 80 lines of
code in the packages.  The layer contracts themselves are checked by ``lint-imports`` (``make test``)."""
from __future__ import annotations

import ast
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("models", "identification", "oed", "reports", "mudoe")
MAX_FILE_LINES = 800
MAX_FUNCTION_CODE_LINES = 80


def _sources():
    for pkg in PACKAGES:
        yield from sorted((ROOT / pkg).rglob("*.py"))


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


def test_no_file_over_800_lines():
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
