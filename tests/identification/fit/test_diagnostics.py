"""The typed diagnostics of a fit (``est.diagnostics``, identification.fit.record) and their ``extra`` source."""
import dataclasses
import pickle
import warnings

import numpy as np
import pytest

from identification import Measurements, identify
from identification.fit.record import EXTRA_KEYS, FitDiagnostics
from models import Model


def _fit():
    x = np.linspace(0.0, 2.0, 8)
    model = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0])
    z = (1.0 + 2.0 * x)[None, :, None] + 0.1 * np.random.default_rng(1).standard_normal((2, x.size, 1))
    return identify(model, Measurements(x, z, [0.1]), p0=[0.0, 0.0])


def test_the_typed_attributes_read_what_extra_holds():
    est = _fit()
    d = est.diagnostics
    with pytest.warns(DeprecationWarning, match="diagnostics"):
        extra = est.extra
    assert d.solver == extra["solver"] and d.refinement_stop == extra["refinement_stop"]
    assert d.newton_decrement == extra["newton_decrement"] and d.ipopt_passes == extra["ipopt_passes"]
    np.testing.assert_array_equal(d.singular_values, extra["singular_values"])
    np.testing.assert_array_equal(d.hessian_eigenvalues, extra["hessian_eigenvalues"])
    sv = np.asarray(extra["singular_values"])
    assert d.condition == sv.max() / sv.min() and d.discretisation is None and d.other == {}
    assert pickle.loads(pickle.dumps(d)).solver == d.solver


def test_unknown_keys_are_kept_and_missing_ones_have_defaults():
    d = FitDiagnostics.from_extra({"solver": "valley walk", "custom": 3})
    assert d.solver == "valley walk" and d.other == {"custom": 3}
    assert np.isnan(d.newton_decrement) and d.singular_values is None and np.isnan(d.condition)
    empty = FitDiagnostics.from_extra(None)
    assert empty.solver == "" and empty.saddle_escapes == () and empty.timing is None and empty.other == {}
    assert set(EXTRA_KEYS) <= set(FitDiagnostics.__dataclass_fields__)


def test_reading_extra_from_outside_warns_and_the_package_reads_it_silently():
    est = _fit()
    with pytest.warns(DeprecationWarning, match="est.diagnostics"):
        assert est.extra["solver"] == est.diagnostics.solver
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        moved = dataclasses.replace(est, notes=("moved",))      # the standard library's copy reads extra
        assert moved.diagnostics.solver == est.diagnostics.solver and pickle.loads(pickle.dumps(est)).n_p == 2
