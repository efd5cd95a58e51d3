"""No import circle inside models/ or oed/ (issue 21), deferred imports inside functions included."""
import pytest

grimp = pytest.importorskip("grimp")


def circles(package: str) -> list:
    """The groups of modules of ``package`` that import each other in a circle (strongly connected
    components of more than one module of grimp's import graph)."""
    g = grimp.build_graph(package, include_external_packages=False)
    mods = sorted(g.modules)
    adj = {m: sorted(g.find_modules_directly_imported_by(m) & set(mods)) for m in mods}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
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

    for m in mods:
        if m not in index:
            visit(m)
    return out


@pytest.mark.parametrize("package", ["models", "oed"])
def test_no_import_circle(package):
    assert circles(package) == []


def test_the_circle_finder_sees_a_circle(tmp_path, monkeypatch):
    pkg = tmp_path / "circ_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from . import a\n")          # deferred: still a circle
    monkeypatch.syspath_prepend(str(tmp_path))
    assert circles("circ_pkg") == [["circ_pkg.a", "circ_pkg.b"]]
