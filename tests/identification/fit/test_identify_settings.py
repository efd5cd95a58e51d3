"""Settings dataclasses reject bad values up front, naming the field."""
import numpy as np
import pytest

from identification import IdentificationError, IdentifySettings, Measurements, identify
from models.contract import Model
from identification.fit.ipopt_solver import IpoptSettings


@pytest.mark.parametrize("kw, field", [
    ({"refine_steps": -1}, "refine_steps"),
    ({"refine_steps": 2.5}, "refine_steps"),
    ({"rank_rtol": -1e-9}, "rank_rtol"),
    ({"decrement_tol": float("nan")}, "decrement_tol"),
    ({"refine_decrement": float("inf")}, "refine_decrement"),
    ({"ill_conditioned": 0.5}, "ill_conditioned"),
    ({"predictor_step": -0.1}, "predictor_step"),
])
def test_identify_settings_reject_bad_values(kw, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        IdentifySettings(**kw)


def test_identify_settings_need_ipopt_settings():
    with pytest.raises(TypeError, match="^ipopt:"):
        IdentifySettings(ipopt={"tol": 1e-8})


@pytest.mark.parametrize("kw, field", [
    ({"tol": 0.0}, "tol"),
    ({"acceptable_tol": -1.0}, "acceptable_tol"),
    ({"max_iter": 0}, "max_iter"),
    ({"print_level": 13}, "print_level"),
    ({"linear_solver": ""}, "linear_solver"),
    ({"mumps_pivot_order": 9}, "mumps_pivot_order"),
    ({"extra": (("mu_init",),)}, "extra"),
])
def test_ipopt_settings_reject_bad_values(kw, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        IpoptSettings(**kw)


def test_defaults_are_valid():
    IdentifySettings()
    IpoptSettings()


def test_unbounded_first_pass_is_capped_when_the_optimum_lies_at_infinity(monkeypatch):
    """lazy_bounds: the unbounded pass of a fit whose unconstrained optimum is at infinity (b1 -> inf,
    b2 -> 0 on data linear in x) stops after LAZY_PASS_MAX_ITER Ipopt iterations, not max_iter
    (3000, about 1 s here and 5-7 s on the press), and pass 2 gives the bounded solution."""
    import casadi as ca
    import identification.fit.estimator as est_mod
    from models.contract import Parameter
    model = Model.explicit(params=[Parameter("b1", 0.0, 300.0), Parameter("b2", 0.0, 1.0)], inputs=["x"],
                           sensors=["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    x = np.linspace(50.0, 800.0, 10)
    data = Measurements(x, (0.5 * x + 0.5 * np.random.default_rng(0).standard_normal((2, 10)))[:, :, None], [0.5])
    calls = []
    real = est_mod.solve_nlp

    def spy(build, x0, lbx, ubx, lbg, ubg, par, settings, **kw):
        try:
            r = real(build, x0, lbx, ubx, lbg, ubg, par, settings, **kw)
        except IdentificationError as exc:
            calls.append((settings.max_iter, np.isfinite(lbx[:2]).any(), exc.status))
            raise
        calls.append((settings.max_iter, np.isfinite(lbx[:2]).any(), r.iterations))
        return r

    monkeypatch.setattr(est_mod, "solve_nlp", spy)
    e = identify(model, data, [200.0, 4e-4], settings=IdentifySettings(explicit_newton=False))
    assert calls[0][:2] == (est_mod.LAZY_PASS_MAX_ITER, False)     # pass 1: unbounded, capped
    assert calls[-1][:2] == (IpoptSettings().max_iter, True)        # pass 2: bounded, full budget
    assert e.diagnostics.ipopt_passes == 2 and e.p[0] == pytest.approx(300.0)
    monkeypatch.setattr(est_mod, "solve_nlp", real)
    ref = identify(model, data, [200.0, 4e-4], settings=IdentifySettings(explicit_newton=False, lazy_bounds=False))
    np.testing.assert_allclose(e.p, ref.p, rtol=1e-10)
