"""models.shipping: models with local functions reach worker processes (by value or rebuilt from their factory)."""
import os
import pickle
import textwrap
import time

import numpy as np
import pytest

from identification import cluster
from models.shipping import ModelSource, ShippingError, dumps, loads, rebuild

#: a factory whose y_guess closes over a CasADi SX expression (sent by value in a CasADi pickling context)
#: and, with variant "locked", over a lock (no pickler can send it: rebuilt from the factory)
SX_FACTORY = textwrap.dedent('''
    import threading

    import casadi as ca
    from models.contract import Model, Parameter

    def build(variant="quadratic"):
        import multiprocessing
        if variant == "other in workers" and multiprocessing.parent_process() is not None:
            return Model.explicit(["a"], ["q"], ["y"], h=lambda p, q: p[0] * q[0])
        half = ca.SX(0.5)
        lock = threading.Lock() if variant != "quadratic" else None

        def y_guess(p, q):
            if lock is not None:
                with lock:
                    pass
            return [float(ca.evalf(half)) * q[0]]

        def E(y, p, q):
            return ca.vertcat(y[0] + p[1] * y[0] ** 3 - p[0] * q[0])

        def h(y, p, q):
            return ca.vertcat(y[0])

        return Model([Parameter("a", 0.0, 10.0), Parameter("b", 0.0, 1.0)], ["q"], ["y"], n_y=1, E=E, h=h,
                     y_guess=y_guess, name=f"cubic {variant}")
''')


@pytest.fixture()
def sx_factory(tmp_path, monkeypatch):
    pkg = tmp_path / "ship_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "cubic.py").write_text(SX_FACTORY)
    monkeypatch.syspath_prepend(str(tmp_path))
    from ship_pkg.cubic import build
    return build


def test_a_factory_with_local_functions_is_sent_by_value():
    from mudoe.example_cstr import build
    m = build()
    with pytest.raises((pickle.PicklingError, AttributeError), match="local object"):
        pickle.dumps(m)                          # the issue: the standard pickler refuses y_guess
    m2 = loads(dumps(m))
    q = np.array([[300.0], [330.0]])
    p = [0.08, 60.0, 0.04]
    np.testing.assert_array_equal(m2.y_guess(p, q[0]), m.y_guess(p, q[0]))
    np.testing.assert_allclose(m2.simulate(p, q), m.simulate(p, q), rtol=1e-13)


def test_casadi_expressions_in_a_closure_are_sent_by_value(sx_factory):
    m = sx_factory("quadratic")
    m2 = loads(dumps(m))
    assert m2.origin is None and m2.y_guess([2.0, 0.1], [4.0]).tolist() == [2.0]
    q = np.array([[1.0], [2.0]])
    np.testing.assert_allclose(m2.simulate([2.0, 0.1], q), m.simulate([2.0, 0.1], q), rtol=1e-13)


def test_a_model_that_cannot_be_pickled_is_rebuilt_from_its_factory(sx_factory):
    m = sx_factory("locked")
    with pytest.raises(ShippingError, match=r"cannot be sent to worker processes \(TypeError: .*lock.*factory"):
        dumps(m)                                  # no origin: one clear error naming what to do
    m.origin = ModelSource("ship_pkg.cubic:build", "locked")
    m = m.with_bounds({"a": (1.0, 5.0)})          # changed after building: must survive
    m.sensor_units = ("mm",)
    m2 = loads(dumps({"models": (m,)}))["models"][0]
    assert m2.origin == m.origin and m2.name == "cubic locked"
    assert (m2.lower.tolist(), m2.upper.tolist(), m2.sensor_units) == ([1.0, 0.0], [5.0, 1.0], ("mm",))
    q = np.array([[1.0], [2.0]])
    np.testing.assert_allclose(m2.simulate([2.0, 0.1], q), m.simulate([2.0, 0.1], q), rtol=1e-13)
    assert m2.y_guess([2.0, 0.1], [4.0]).tolist() == [2.0]


def test_a_factory_that_builds_another_model_is_refused(sx_factory):
    m = sx_factory()
    meta = {k: m.__dict__[k] for k in ("params", "inputs", "sensors", "n_y", "name", "description", "symbolic",
                                       "sensor_units", "input_units")}
    meta["sensors"] = ("y", "z")
    with pytest.raises(ShippingError, match="built another model"):
        rebuild(ModelSource("ship_pkg.cubic:build", "quadratic"), meta)
    with pytest.raises(ShippingError, match="cannot rebuild the model from its factory 'no_such_mod_x:build'"):
        ModelSource("no_such_mod_x:build").build()


_INSTALLED = {}


def _install(task):
    _INSTALLED["task"] = task


def _simulate_chunk(task, chunk):
    """(index, outputs, pid) of every input in the chunk; this process waits until the spawned one has run one."""
    t = _INSTALLED["task"] if task is None else task
    flag = t["flag"]
    if flag is None:
        pass
    elif task is None:
        open(flag, "w").close()
    else:
        end = time.monotonic() + 600          # a hang guard: the spawned process may start slowly under load
        while not os.path.exists(flag) and time.monotonic() < end:
            time.sleep(0.02)
    m = t["model"]
    return [(i, m.simulate([2.0, 0.1], np.array([[float(i)]])).ravel().tolist(), os.getpid()) for i in chunk]


def test_a_spawned_worker_runs_a_rebuilt_model(sx_factory, tmp_path):
    m = sx_factory("locked")
    m.origin = ModelSource("ship_pkg.cubic:build", "locked")
    got = []
    task = {"model": m, "flag": str(tmp_path / "spawned_ran")}
    cluster.run_local(_simulate_chunk, task, [[i] for i in range(1, 9)], got.extend, 2, _install)
    assert sorted(i for i, _, _ in got) == list(range(1, 9))
    assert len({pid for _, _, pid in got}) == 2            # the spawned process simulated some of them
    for i, y, _ in got:
        np.testing.assert_allclose(y, m.simulate([2.0, 0.1], np.array([[float(i)]])).ravel(), rtol=1e-13)


def test_a_factory_that_builds_another_model_in_the_worker_is_an_error_here(sx_factory):
    m = sx_factory("other in workers")
    m.origin = ModelSource("ship_pkg.cubic:build", "other in workers")
    task = {"model": m, "flag": None}
    with pytest.raises(ShippingError, match=r"built another model in this process"):
        cluster.run_local(_simulate_chunk, task, [[1]], lambda r: None, 2, _install)
