"""The on-disk JIT cache (models.jit_cache): hits and misses, concurrent compilations, damaged
entries, the fallback without a compiler, and the same numbers as the uncached compilation."""
import json
import os
import shutil
import subprocess
import sys

import casadi as ca
import numpy as np
import pytest

from models.jit_cache import JitCache, JitCompileError, function_key
from models.press import press_model
from models.state import JitConfig, numerics

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="no C compiler (gcc) on the PATH")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _small(tag: float = 1.0) -> ca.Function:
    x = ca.SX.sym("x", 3)
    return ca.Function("small", [x], [ca.sin(x) * x[0] + tag * ca.exp(x[1]), ca.jacobian(ca.sum1(x ** 3), x)])


def _outputs(f, args):
    out = f(*args)
    return [np.asarray(o) for o in (out if isinstance(out, (tuple, list)) else [out])]


def test_miss_then_hit_gives_the_same_function(tmp_path):
    f = _small()
    c1 = JitCache(str(tmp_path))
    g1 = c1.get(f)
    assert (c1.stats.compiled, c1.stats.loaded) == (1, 0)
    c2 = JitCache(str(tmp_path))                        # a new cache object (another process in practice)
    g2 = c2.get(f)
    assert (c2.stats.compiled, c2.stats.loaded) == (0, 1)
    x = [np.array([0.3, -1.2, 2.5])]
    for a, b, c in zip(_outputs(f, x), _outputs(g1, x), _outputs(g2, x)):
        np.testing.assert_array_equal(b, c)
        np.testing.assert_allclose(b, a, rtol=1e-15, atol=0)
    assert len([n for n in os.listdir(tmp_path) if n.endswith(".so")]) == 1
    # loading leaves only an empty source name CasADi reserves (pruned when old, see below)
    assert not [n for n in os.listdir(tmp_path) if n.endswith((".c", ".o", ".tmp")) and (tmp_path / n).stat().st_size]
    # derivatives stay available (an SX function calling compiled code, as jit=True gives)
    np.testing.assert_allclose(np.asarray(g2.jacobian()(x[0], *_outputs(g2, x))[0]),
                               np.asarray(f.jacobian()(x[0], *_outputs(f, x))[0]), rtol=1e-14)


_DERIV_CHILD = """
import sys
import casadi as ca
import numpy as np
from models.jit_cache import JitCache
x = ca.SX.sym("x", 3)
f = ca.Function("small", [x], [ca.sin(x) * x[0] + ca.exp(x[1]), ca.jacobian(ca.sum1(x ** 3), x)])
c = JitCache(sys.argv[1])
g = c.get(f)
assert c.stats.loaded == 1 and c.stats.compiled == 0
v = [0.3, -1.2, 2.5]
r = g.reverse(1)(v, *g(v), np.ones(3), np.ones(3))
e = f.reverse(1)(v, *f(v), np.ones(3), np.ones(3))
print(float(np.max(np.abs(np.asarray(r) - np.asarray(e)))))
"""


def test_a_loaded_function_is_differentiated_in_another_process_and_strays_are_pruned(tmp_path):
    """Ipopt differentiates the loaded NLP functions: CasADi compiles their derivatives with the
    entry's options, so the library names carry a random suffix (a fixed name made dlopen return the
    entry's own library and the derivative failed to load).  Their leftovers are pruned when old."""
    from models.jit_cache import prune_strays
    JitCache(str(tmp_path)).get(_small())
    entry_files = set(os.listdir(tmp_path))
    out = subprocess.run([sys.executable, "-c", _DERIV_CHILD, str(tmp_path)], capture_output=True, text=True,
                         env=_env(), cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert float(out.stdout.strip().splitlines()[-1]) < 1e-12
    strays = set(os.listdir(tmp_path)) - entry_files
    assert any(n.endswith(".so") for n in strays)        # the derivative's own library
    assert prune_strays(str(tmp_path)) == 0               # young: a compilation may be in progress
    for n in strays:
        os.utime(tmp_path / n, (0, 0))
    assert prune_strays(str(tmp_path)) == len(strays)
    assert set(os.listdir(tmp_path)) == entry_files
    c = JitCache(str(tmp_path))
    c.get(_small())
    assert c.stats.loaded == 1                            # the entry and its library survived


def test_the_key_follows_the_function_and_the_flags():
    assert function_key(_small(), ("-O1",)) == function_key(_small(), ("-O1",))
    assert function_key(_small(), ("-O1",)) != function_key(_small(2.0), ("-O1",))
    assert function_key(_small(), ("-O1",)) != function_key(_small(), ("-O2",))


DAMAGES = ("garbage entry", "truncated entry", "library removed", "truncated library")

_FILL = """
import sys
import casadi as ca
from models.jit_cache import JitCache
x = ca.SX.sym("x", 3)
f = ca.Function("small", [x], [ca.sin(x) * x[0] + ca.exp(x[1]), ca.jacobian(ca.sum1(x ** 3), x)])
for d in sys.argv[1:]:
    JitCache(d).get(f)
"""


def _env():
    return dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))


@pytest.fixture(scope="module")
def filled(tmp_path_factory):
    """One cache directory per damage, each holding the entry of :func:`_small` compiled by another
    process (this one never maps the library, so damaging it cannot touch a loaded copy)."""
    dirs = {d: tmp_path_factory.mktemp(d.replace(" ", "_")) for d in DAMAGES}
    subprocess.run([sys.executable, "-c", _FILL, *map(str, dirs.values())], check=True, env=_env(), cwd=ROOT,
                   timeout=120)
    return dirs


@pytest.mark.parametrize("damage", DAMAGES)
def test_a_damaged_entry_is_recompiled_not_an_error(filled, damage):
    f, tmp_path = _small(), filled[damage]
    key = function_key(ca.Function("small_jit", f.sx_in(), f.call(f.sx_in()), f.name_in(), f.name_out()), ("-O1",))
    entry = tmp_path / f"{key}.casadi"
    lib = next(p for p in tmp_path.iterdir() if p.suffix == ".so")
    if damage == "garbage entry":
        entry.write_text("not a casadi serialisation")
    elif damage == "truncated entry":
        entry.write_text(entry.read_text()[: len(entry.read_text()) // 2])
    elif damage == "library removed":
        lib.unlink()
    else:
        lib.write_bytes(lib.read_bytes()[:1000])
    c = JitCache(str(tmp_path))
    g = c.get(f)
    assert (c.stats.compiled, c.stats.recovered) == (1, 1)
    x = [np.array([0.1, 0.2, 0.3])]
    for a, b in zip(_outputs(f, x), _outputs(g, x)):
        np.testing.assert_allclose(b, a, rtol=1e-15, atol=0)
    c2 = JitCache(str(tmp_path))
    c2.get(f)
    assert (c2.stats.compiled, c2.stats.loaded) == (0, 1)      # the repaired entry loads
    assert len([p for p in tmp_path.iterdir() if p.suffix == ".so"]) == 1


_CHILD = """
import json, os, sys, time
import casadi as ca
from models.jit_cache import JitCache
x = ca.SX.sym("x", 8)
e = x
for k in range(60):                       # a body that takes gcc a noticeable time
    e = ca.sin(e * (k + 1)) + ca.cos(e[::-1]) * x[k % 8]
f = ca.Function("busy", [x], [e])
open(sys.argv[2] + "." + sys.argv[3], "w").close()       # ready
while not all(os.path.exists(sys.argv[2] + "." + k) for k in ("0", "1")):   # both start together (a barrier)
    time.sleep(0.005)
c = JitCache(sys.argv[1])
g = c.get(f)
print(json.dumps({"compiled": c.stats.compiled, "loaded": c.stats.loaded,
                  "y": [float(v) for v in g([0.1 * k for k in range(8)]).full().ravel()]}))
"""


def test_two_processes_compiling_the_same_key_compile_it_once(tmp_path):
    cache, barrier = tmp_path / "cache", tmp_path / "ready"
    cache.mkdir()
    procs = [subprocess.Popen([sys.executable, "-c", _CHILD, str(cache), str(barrier), str(k)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=_env(), cwd=ROOT) for k in range(2)]
    outs = []
    for p in procs:
        out, err = p.communicate(timeout=600)       # a hang guard only
        assert p.returncode == 0, err
        outs.append(json.loads(out.strip().splitlines()[-1]))
    assert sorted((o["compiled"], o["loaded"]) for o in outs) == [(0, 1), (1, 0)]
    assert outs[0]["y"] == outs[1]["y"]
    assert len([p for p in cache.iterdir() if p.suffix == ".so"]) == 1
    assert len([p for p in cache.iterdir() if p.suffix == ".casadi"]) == 1


def test_a_missing_compiler_raises_a_clear_error(tmp_path):
    with pytest.raises(JitCompileError, match="mudoe-no-such-compiler"):
        JitCache(str(tmp_path), compiler="mudoe-no-such-compiler").get(_small())


def test_without_a_compiler_the_virtual_machine_stays_in_use(tmp_path, monkeypatch):
    cfg = JitConfig(enabled=True, directory=str(tmp_path))
    monkeypatch.setenv("PATH", str(tmp_path))          # no gcc
    assert cfg.compile(_small()) is None
    assert cfg.failed and not cfg.active()


def test_press_functions_identical_with_and_without_the_cache(tmp_path):
    """The cached compilation and the per-process one (cache off) of the press model's E_y give
    the same numbers to the bit, and both equal the virtual machine's to round-off."""
    num = numerics(press_model())
    rng = np.random.default_rng(3)
    args = [rng.random(num.E_y.size1_in(i)) for i in range(num.E_y.n_in())]
    cached = JitConfig(enabled=True, directory=str(tmp_path)).compile(num.E_y)
    plain = JitConfig(enabled=True, cache=False).compile(num.E_y)
    assert cached is not None and plain is not None
    for vm, a, b in zip(_outputs(num.E_y, args), _outputs(cached, args), _outputs(plain, args)):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(a, vm, rtol=1e-14, atol=1e-300)


def test_an_unusable_cache_directory_falls_back_to_compiling_per_process(tmp_path):
    blocker = tmp_path / "a file"
    blocker.write_text("not a directory")
    cfg = JitConfig(enabled=True, directory=str(blocker / "jit"))
    with pytest.warns(RuntimeWarning, match="not usable"):
        g = cfg.compile(_small())
    assert g is not None and not cfg.failed and not cfg.cache
    x = [np.array([0.1, 0.2, 0.3])]
    for a, b in zip(_outputs(_small(), x), _outputs(g, x)):
        np.testing.assert_allclose(b, a, rtol=1e-15, atol=0)
