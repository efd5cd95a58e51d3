"""Mapped outputs and sensitivities of a collocated ODE (models.trajectory; formerly models.collocation_map)."""
import numpy as np
import pytest

from models import Model
from models.trajectory import mapped_outputs, outputs_and_sensitivities
from models.errors import StateSolveError
from models.sensitivity import sensitivities
from models.state import solve_states
from mudoe.example_reactor import P_TRUE, TIMES, build


def test_mapped_outputs_and_sensitivities_equal_the_collocated_models():
    cm = build("profile").collocate(TIMES, max_step=0.1)
    Q = np.array([np.r_[1.0, np.linspace(330, 370, 8)], np.r_[2.0, [360.0] * 8], np.r_[1.5, [340.0, 365.0] * 4]])
    h, G = outputs_and_sensitivities(cm, P_TRUE, Q)
    assert np.allclose(h, cm.integrated_outputs(P_TRUE, Q), rtol=0, atol=1e-12)
    assert np.allclose(mapped_outputs(cm, P_TRUE, Q), h, rtol=0, atol=1e-14)
    ref = sensitivities(cm, P_TRUE, Q, solve_states(cm, P_TRUE, Q)).G      # sparse solve of E_y y' = -E_p
    assert G.shape == ref.shape and np.max(np.abs(G - ref)) <= 1e-9 * np.max(np.abs(ref))


def test_blow_up_names_the_experiment_and_element():
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: p[0] * x ** 2, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, horizon=2.0)
    cm = m.collocate([0.5, 2.0], max_step=0.5)
    assert np.isfinite(mapped_outputs(cm, [1.0], [[0.1]])).all()
    with pytest.raises(StateSolveError, match=r"inputs \[1.0\]: no collocation solution on the element \[0.5, 1\] of experiment 2"):
        outputs_and_sensitivities(cm, [1.0], [[0.1], [1.0]])


def test_the_old_module_warns_and_names_the_new_one():
    import importlib
    import sys
    sys.modules.pop("models.collocation_map", None)
    with pytest.warns(DeprecationWarning, match="models.trajectory"):
        old = importlib.import_module("models.collocation_map")
    assert old.mapped_outputs is mapped_outputs
