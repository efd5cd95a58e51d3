"""method='auto' for second-order criteria routes by the measured cost of enumeration (issue 13 item 4)."""
import numpy as np
import pytest

from oed import DesignSettings, select_sensors_from_information
from oed.scip_solver import scip_available


def _instance(seed, n, p):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, 2, p))
    F = np.einsum("kri,krj->kij", a, a)
    B = rng.standard_normal((n, p, p))
    S = 0.05 * (B + B.transpose(0, 2, 1))
    return F, S


@pytest.mark.parametrize("crit", ["A", "D", "E"])
def test_auto_enumerates_second_order_problems_whose_measured_cost_fits(crit):
    F, S = _instance(1, 14, 4)                         # C(14, 6) = 3003 designs > the limit set below
    settings = DesignSettings(enumeration_limit=100)
    # the rate is measured (a wall-clock reading): a time limit no machine's rate misses keeps the route fixed
    r = select_sensors_from_information(F, S, criterion=crit, kind="second_order", n_sensors=6, settings=settings,
                                        time_limit=1e9)
    ref = select_sensors_from_information(F, S, criterion=crit, kind="second_order", n_sensors=6,
                                          method="enumerate")
    assert r.method == "enumerate" and r.proven_optimal and r.gap <= 1e-12     # re-evaluation rounding
    assert r.indices == ref.indices
    assert any("designs/s measured" in n and "<= time_limit" in n for n in r.notes)


@pytest.mark.skipif(not scip_available(), reason="SCIP not available")
def test_auto_goes_to_scip_when_enumeration_would_exceed_the_time_limit():
    F, S = _instance(2, 8, 2)
    settings = DesignSettings(enumeration_limit=10, enumeration_rate=1.0)     # 1 design/s: 28 designs > 5 s
    r = select_sensors_from_information(F, S, criterion="D", kind="second_order", n_sensors=2, time_limit=5.0,
                                        settings=settings)
    assert r.method == "scip" and any("> time_limit" in n for n in r.notes)


def test_enumeration_rate_setting_is_checked():
    with pytest.raises(ValueError, match="enumeration_rate"):
        DesignSettings(enumeration_rate=0.0)


@pytest.mark.skipif(not scip_available(), reason="SCIP not available")
def test_unproven_a_and_e_designs_report_a_finite_gap():
    """A and E criteria are >= 0, so a design found without proof has gap <= value, never inf."""
    F, S = _instance(3, 8, 2)
    settings = DesignSettings(enumeration_limit=10, enumeration_rate=1.0)
    for crit in "AE":
        r = select_sensors_from_information(F, S, criterion=crit, kind="second_order", n_sensors=2,
                                            time_limit=5.0, settings=settings)
        assert r.method == "scip" and np.isfinite(r.value)
        assert r.lower_bound >= 0.0 and np.isfinite(r.gap) and r.gap <= r.value
