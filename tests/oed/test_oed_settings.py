"""OED settings reject bad values up front, naming the field."""
import pytest

from oed.bnb import BnBSettings
from oed.design import DesignSettings
from oed.enumeration import EnumerationSettings


@pytest.mark.parametrize("cls, kw, field", [
    (BnBSettings, {"time_limit": 0}, "time_limit"),
    (BnBSettings, {"gap_tol": -1e-9}, "gap_tol"),
    (BnBSettings, {"batch_size": 0}, "batch_size"),
    (BnBSettings, {"node_limit": 0}, "node_limit"),
    (BnBSettings, {"e_betas": ()}, "e_betas"),
    (BnBSettings, {"branch_target": 1.5}, "branch_target"),
    (EnumerationSettings, {"batch_size": 0}, "batch_size"),
    (EnumerationSettings, {"time_limit": -1.0}, "time_limit"),
    (DesignSettings, {"enumeration_limit": -1}, "enumeration_limit"),
    (DesignSettings, {"gap_tol": float("inf")}, "gap_tol"),
    (DesignSettings, {"scip_formulation": "sdp"}, "scip_formulation"),
])
def test_oed_settings_reject_bad_values(cls, kw, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        cls(**kw)


def test_scip_formulation_error_lists_the_choices():
    with pytest.raises(ValueError, match="cuts"):
        DesignSettings(scip_formulation="sdp")


def test_defaults_are_valid():
    BnBSettings()
    DesignSettings()
    EnumerationSettings()
