"""One result protocol on every public result (issue 28, item 7) and ``import mudoe`` as the front door (item 9).

The result classes are found, not listed: every class in the ``__all__`` of identification, oed and mudoe whose
name ends like a result's (:data:`RESULT_SUFFIXES`) or that derives from
:class:`identification.results_protocol.ResultProtocol`; every other class there must be named in
:data:`NOT_RESULTS`, so that a new class is either a result (and then checked) or said not to be one.  Each result
class is built for real on a small problem (:data:`FACTORIES`), and its ``to_dict()`` must pass strict
``json.dumps``, ``to_frame()`` be a DataFrame, ``summary()`` a non-empty text and ``_repr_html_()`` HTML.
"""
from __future__ import annotations

import importlib
import inspect
import json
import subprocess
import sys
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pandas as pd
import pytest

from identification.results_protocol import RESULT_METHODS, ResultProtocol, is_result, jsonable, notes_lines

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("identification", "oed", "mudoe")
#: a public class whose name ends so is a result
RESULT_SUFFIXES = ("Result", "Estimate", "Design", "Intervals", "Table", "Plan", "Check", "Detection", "Inputs")
#: the public classes that are not results: inputs, settings, data, models, regions, the protocol itself
NOT_RESULTS = {"Measurements", "DynamicMeasurements", "Model", "Parameter", "Split", "Prior", "Criterion", "DesignRow",
               "IdentifySettings", "IpoptSettings", "DetectSettings", "MonteCarloSettings", "CriteriaSettings",
               "DesignSettings", "RefineSettings", "ApproximateSettings", "DiscretisationSettings", "Ellipsoid",
               "ResultProtocol",
               "CandidateInformation",   # the matrices the design verbs read (oed.information), not a result
               "Problem"}                # a model with its data and discretisation: what the verbs read


def public_classes() -> dict:
    """{name: class} of every class (not an exception) in the packages' ``__all__``."""
    out = {}
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isclass(obj) and not issubclass(obj, BaseException):
                out[name] = obj
    return out


def result_classes() -> dict:
    return {n: c for n, c in public_classes().items()
            if c is not ResultProtocol and (n.endswith(RESULT_SUFFIXES) or issubclass(c, ResultProtocol))}


# ------------------------------------------------------------------ small real instances, built once
def _line():
    """y = a + b x at 8 inputs, 2 series (sigma 0.1 known)."""
    from identification import Measurements
    from models import Model
    x = np.linspace(0.0, 2.0, 8)
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] * q[0],
                           name="line")
    z = (1.0 + 2.0 * x)[None, :, None] + 0.1 * np.random.default_rng(3).standard_normal((2, x.size, 1))
    return model, Measurements(x, z, [0.1])


def _two_sensors():
    """Two outputs of (a, b) at 12 inputs, 2 series."""
    from identification import Measurements
    from models import Model
    q = np.linspace(0.1, 2.0, 12)
    model = Model.explicit(["a", "b"], ["x"], ["y1", "y2"],
                           h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * q[0] / (1 + p[1] * q[0])),
                           name="two")
    mean = np.stack([2.0 * (1 - np.exp(-1.5 * q)), 2.0 * q / (1 + 1.5 * q)], axis=1)
    z = mean[None] + 0.05 * np.random.default_rng(4).standard_normal((2, q.size, 2))
    return model, Measurements(q[:, None], z, 0.05, sensors=["y1", "y2"], input_names=["x"])


def _splits():
    from identification import Split
    return (Split("low/high", range(0, 4), range(4, 8)), Split("odd/even", range(0, 8, 2), range(1, 8, 2)))


def _rank_one(seed, n, p):
    a = np.random.default_rng(seed).standard_normal((n, p))
    return np.einsum("ki,kj->kij", a, a)


def _compartmental():
    from models import Model
    return Model.explicit(["theta1", "theta2", "theta3"], ["t"], ["eta"],
                          h=lambda p, q: p[2] * (ca.exp(-p[0] * q[0]) - ca.exp(-p[1] * q[0])), name="compartmental")


def _estimate():
    import mudoe
    model, data = _line()
    return mudoe.identify(model, data, p0=[0.0, 0.0])


def _detection():
    import mudoe
    model, data = _line()
    return mudoe.detect(model, data, _splits(), [0.0, 0.0], normality="override")


def _bootstrap():
    import mudoe
    model, data = _line()
    return mudoe.bootstrap_detect(model, data, _splits(), [0.0, 0.0], n_rep=4, seed=5)


def _monte_carlo():
    import mudoe
    model, data = _line()
    return mudoe.size_study(model, [1.0, 2.0], data.inputs, [0.1], _splits(),
                            settings=mudoe.MonteCarloSettings(n_rep=3, workers=1, progress=False, jit=False))


def _model_error():
    import mudoe
    model, data = _two_sensors()
    return mudoe.model_error(model, data, [1.0, 1.0], splits=(mudoe.Split("low/high", range(0, 6), range(6, 12)),))


def _error_design():
    import mudoe
    return mudoe.select_error_design(_model_error(), np.linspace(0.2, 2.0, 5), 2, region={"x": (0.1, 2.5)})


def _ranking():
    import mudoe
    model, data = _two_sensors()
    sp = (mudoe.Split("low/high", range(0, 6), range(6, 12)),)
    return mudoe.rank_models({"a": mudoe.model_error(model, data, [1.0, 1.0], splits=sp),
                              "a plain": mudoe.model_error(model, data, [1.0, 1.0], splits=sp, kind="none")})


def _inputs(refine=False):
    import mudoe
    model, _ = _two_sensors()
    return mudoe.select_inputs(model, [2.0, 1.5], candidates=np.linspace(0.1, 2.0, 6)[:, None], sigma=0.05,
                               n_points=2, refine=refine, bounds=([0.1], [2.0]) if refine else None)


def _discrimination():
    import mudoe
    from models import Model
    quad = Model.explicit(["c0", "c1", "c2"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0] + p[2] * q[0] ** 2)
    lin = Model.explicit(["d0", "d1"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0])
    return mudoe.select_discriminating(quad, [0.0, 0.0, 1.0], lin, [0.3, 1.0], np.linspace(0, 1, 5)[:, None],
                                       sigma=0.1, n_points=2)


def _approximate():
    import mudoe
    return mudoe.approximate_design(_compartmental(), [0.05884, 4.298, 21.80], sigma=1.0, bounds=(0.0, 24.0),
                                    settings=mudoe.ApproximateSettings(grid=25, rounds=2, polish_rounds=0))


def _sequential():
    import mudoe
    model, data = _two_sensors()
    return mudoe.sequential_design(model, [data, data], [1.5, 1.0], n_sensors=2)


def _robust_exact():
    import mudoe
    F = np.stack([_rank_one(s, 5, 2) + 1e-3 * np.eye(2) for s in (1, 2)], axis=1)      # (5 candidates, 2 samples)
    return mudoe.select_robust_exact(F, [0.5, 0.5], 3, names=[f"c{k}" for k in range(5)])


def _design():
    import mudoe
    return mudoe.select_sensors_from_information(_rank_one(7, 5, 2), n_sensors=3, sensor_names=list("ABCDE"))


def _planned():
    import mudoe
    return mudoe.PlannedDesign(variant="v", mode="sensors", planned=True, p=(1.0, 2.0), candidates=tuple("ABCDE"),
                               result=_design())


def _robust_plan():
    import mudoe
    return mudoe.RobustPlan(variant="v", planned=True, p=(0.05884, 4.298, 21.80), candidates=(0.0, 24.0),
                            design=_approximate(), local=None, local_efficiencies=())


def _robust_exact_plan():
    import mudoe
    r = _robust_exact()
    return mudoe.RobustExactPlan(variant="v", mode="sensors", planned=True, p=(1.0, 2.0),
                                 candidates=tuple(f"c{k}" for k in range(5)), design=r, local=r,
                                 local_efficiencies=(1.0, 1.0), prior_points=((1.0, 2.0), (1.1, 2.0)),
                                 prior_weights=(0.5, 0.5), param_names=("a", "b"))


def _discrimination_plan():
    import mudoe
    r = _discrimination()
    d = np.asarray(r.divergences)
    return mudoe.DiscriminationPlan(variant="quad", rival="lin", planned=True, p=(0.0, 0.0, 1.0), p_rival=(0.3, 1.0),
                                    candidates=tuple(np.linspace(0, 1, 5)), n_series=1, result=r, scores={"T": d},
                                    references={"all readings": tuple((j, "y") for j in range(5))})


def _dynamic_design():
    import mudoe
    from oed.best_designs import best_designs
    F = _rank_one(8, 5, 2)
    res = mudoe.select_sensors_from_information(F, n_sensors=2, sensor_names=[f"t{k}" for k in range(5)])
    table = best_designs(F, None, [f"t{k}" for k in range(5)], 2, "D", chosen=res.indices, top=4)
    return mudoe.DynamicDesign(variant="v", planned=True, p=(1.0, 2.0), candidates=(0.5, 1.0, 2.0, 3.0, 4.0),
                               pairs=False, result=res, table=table)


FACTORIES = {
    "Estimate": _estimate,
    "ConfidenceIntervals": lambda: _estimate().conf_int(0.05),
    "NormalityCheck": lambda: importlib.import_module("mudoe").normality_check(_line()[1]),
    "DetectionResult": _detection,
    "BootstrapDetection": _bootstrap,
    "MonteCarloResult": _monte_carlo,
    "ModelErrorResult": _model_error,
    "ModelRanking": _ranking,
    "ErrorDesignResult": _error_design,
    "DesignResult": _design,
    "DesignTable": lambda: importlib.import_module("mudoe").design_table(_rank_one(7, 4, 2), sensor_names=list("ABCD")),
    "InputDesignResult": _inputs,
    "RefinedInputs": lambda: _inputs(refine=True).refined,
    "DiscriminationResult": _discrimination,
    "ApproximateDesign": _approximate,
    "SequentialResult": _sequential,
    "RobustExactDesign": _robust_exact,
    "PlannedDesign": _planned,
    "RobustPlan": _robust_plan,
    "RobustExactPlan": _robust_exact_plan,
    "DiscriminationPlan": _discrimination_plan,
    "DynamicDesign": _dynamic_design,
}


# ------------------------------------------------------------------ the enumeration
def test_every_public_class_is_a_result_or_said_not_to_be_one():
    results = result_classes()
    unclassified = sorted(n for n in public_classes() if n not in results and n not in NOT_RESULTS)
    assert unclassified == [], "add these to a result suffix, derive them from ResultProtocol or list them in NOT_RESULTS"
    assert {"Estimate", "ConfidenceIntervals", "DetectionResult", "MonteCarloResult", "DesignResult",
            "DiscriminationResult", "SequentialResult", "BootstrapDetection", "ModelErrorResult"} <= set(results)


@pytest.mark.parametrize("name", sorted(result_classes()))
def test_each_result_class_has_the_four_methods(name):
    cls = result_classes()[name]
    assert issubclass(cls, ResultProtocol) and is_result(cls)
    missing = [m for m in RESULT_METHODS[:3] if getattr(cls, m) is getattr(ResultProtocol, m)]
    assert missing == [], f"{name} does not override {missing}"
    assert name in FACTORIES, f"add a small real instance of {name} to FACTORIES"


@pytest.mark.parametrize("name", sorted(FACTORIES))
def test_each_result_on_a_real_instance(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")           # the small problems' own warnings (not under test here)
        r = FACTORIES[name]()
    assert type(r).__name__ == name and is_result(r)
    d = r.to_dict()
    assert isinstance(d, dict) and d
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text) == d                  # plain JSON types only: a round trip changes nothing
    assert jsonable(d) == d
    frame = r.to_frame()
    assert isinstance(frame, pd.DataFrame) and frame.shape[0] >= 1
    s = r.summary()
    assert isinstance(s, str) and s.strip()
    html = r._repr_html_()
    assert isinstance(html, str) and "<" in html and html.strip()


def test_summaries_end_with_numbered_notes():
    from identification.inference.intervals import ConfidenceIntervals
    ci = ConfidenceIntervals(("a", "b"), [1.0, 2.0], [0.0, 1.0], [2.0, np.inf], "profile", 0.05,
                             notes=("b: the upper side is unbounded",))
    assert ci.summary().splitlines()[-2:] == ["Notes:", "[1] b: the upper side is unbounded"]
    assert ci.to_dict()["upper"] == [2.0, "inf"]
    assert notes_lines(()) == [] and notes_lines(["x", "y"]) == ["", "Notes:", "[1] x", "[2] y"]


def test_the_mixin_refuses_a_missing_method():
    class Half(ResultProtocol):
        def summary(self):
            return "half"
    with pytest.raises(NotImplementedError, match="Half.to_dict"):
        Half().to_dict()
    with pytest.raises(NotImplementedError, match="Half.to_frame"):
        Half()._repr_html_()


def test_monte_carlo_table_is_a_deprecated_alias_of_summary():
    r = _monte_carlo()
    with pytest.warns(DeprecationWarning, match="summary"):
        assert r.table() == r.summary()
    assert r.to_dict()["table"] == r.summary()


def test_reports_serialize_writes_what_to_dict_gives():
    """reports.serialize's views of these results are their to_dict() (one JSON view per result)."""
    from reports.serialize import detection_dict, dumps, estimate_dict, oed_dict, validation_dict
    est, det = _estimate(), _detection()
    assert estimate_dict(est) == est.to_dict() and detection_dict(det) == det.to_dict()
    mc = _monte_carlo()
    assert validation_dict(mc) == mc.to_dict()
    import mudoe
    F = _rank_one(7, 4, 2)
    res, table = mudoe.select_sensors_from_information(F, n_sensors=2), mudoe.design_table(F)
    d = json.loads(dumps(oed_dict(res, table, "v")))
    assert d["chosen"] == res.to_dict() and d["table"] == table.to_dict()["rows"] and d["kind"] == table.kind


# ------------------------------------------------------------------ the front door
def test_every_name_of_mudoe_resolves():
    import mudoe
    assert len(mudoe.__all__) == len(set(mudoe.__all__))
    for name in mudoe.__all__:
        assert getattr(mudoe, name) is not None, name
    assert set(mudoe.__all__) <= set(dir(mudoe))
    assert mudoe.identify is importlib.import_module("identification").identify
    assert mudoe.select_sensors is importlib.import_module("oed").select_sensors
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        mudoe.no_such_name  # noqa: B018


def test_import_mudoe_imports_nothing_of_the_library():
    """The re-exports are lazy: ``import mudoe`` alone loads none of models, identification, oed, reports."""
    code = ("import sys, mudoe; print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('models', 'identification', 'oed', 'reports', 'numpy', 'casadi')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}).stdout
    assert out.strip() == "[]"
