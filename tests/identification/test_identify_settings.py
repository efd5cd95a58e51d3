"""Settings dataclasses reject bad values up front, naming the field."""
import pytest

from identification import IdentifySettings
from identification.ipopt_solver import IpoptSettings


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
