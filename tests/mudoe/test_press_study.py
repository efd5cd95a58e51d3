"""The press study: friction training (M2 / M3 constants) and the candidate fits on held-out series."""
import numpy as np
import pytest

from models.friction import PreisachNetwork, candidate_models, load_friction, memory_inputs
from models.press import Q_PAPER
from models.prototype import read_campaign
from mudoe.press import fit_candidates, retrain, train_preisach

Q = np.array(Q_PAPER)


@pytest.fixture(scope="module")
def campaign():
    return read_campaign()


@pytest.fixture(scope="module")
def models():
    return candidate_models()


@pytest.fixture(scope="module")
def fits(campaign, models):
    return {sens: fit_candidates(campaign, sensors=sens, models=models)
            for sens in (("D_y", "F_x"), ("D_y", "F_x", "B0_y"))}


# ---------------------------------------------------------------------------- training
def test_train_preisach_reproduces_a_hysteresis_it_can_represent():
    U = memory_inputs(np.r_[Q, Q[1:]])
    truth = PreisachNetwork(np.array([[0.0, -3.0, 0.0, 0.0], [3.0, -3.0, 0.0, 0.0]]) * 4, np.array([0.0, 0.0]),
                            np.array([0.4, 0.4]), 0.0)
    f = truth(U)
    net, info = train_preisach(U, f[None], n_hidden=2, reg=1e-8, n_starts=3, seed=2)
    assert info["status"] == "Solve_Succeeded"
    assert info["rms"] < 0.5                       # N, against a friction of about +-60 N
    assert np.ptp(f) > 50


def test_shipped_friction_constants_are_reproduced_by_retraining(campaign):
    stored = load_friction()
    again = retrain(campaign, write=False, **stored["raw"]["training"])
    assert again["q_c_N"] == pytest.approx(stored["raw"]["q_c_N"], rel=1e-6)
    np.testing.assert_allclose(again["k_M1_N_per_mm"], stored["raw"]["k_M1_N_per_mm"], rtol=1e-6)
    U = memory_inputs(campaign.q_set)
    net = PreisachNetwork.from_dict(again["network"])
    np.testing.assert_allclose(net(U), stored["network"](U), atol=1e-3)
    # the learned friction is a hysteresis: positive on loading, negative on unloading
    mu = stored["network"](U)
    assert np.all(mu[3:15] > 20) and np.all(mu[17:28] < -20)
    assert 30.0 < stored["coulomb"].q_c < 150.0
    assert again["training_result"]["rms_N"] < 0.5 * again["training_result"]["rms_coulomb_N"]


# ---------------------------------------------------------------------------- identification on held-out series
@pytest.mark.parametrize("sensors", [("D_y", "F_x"), ("D_y", "F_x", "B0_y")])
def test_identification_converges_and_only_M3_fits_the_held_out_series(fits, sensors):
    est = fits[sensors]
    for name, e in est.items():
        assert e.status == "Solve_Succeeded", (name, e.status)
        assert np.all(np.isfinite(e.stderr)) and np.all(e.stderr > 0)
        assert np.all((e.p > 300) & (e.p < 800)), (name, e.p)
    chi2 = {n: e.reduced_chi2 for n, e in est.items()}
    assert 0.6 < chi2["M3"] < 1.6, chi2             # near 1 with the paper's composed sigmas
    assert chi2["M1"] > 5.0, chi2                   # frictionless model: reduced chi2 >> 1
    assert chi2["M1"] > chi2["M2"] > chi2["M3"], chi2


# ---------------------------------------------------------------------------- figures take the computed data
def test_press_figures_draw_the_fits_and_samples_they_are_given(campaign, models, fits):
    from mudoe.press import friction_curves, friction_samples, model_curves
    from reports.press_figures import plot_friction, plot_models
    curves = model_curves(campaign, fits[("D_y", "F_x")], models)
    assert all(c.outputs.shape == (campaign.q_set.size, len(models[n].sensors)) for n, c in curves.items())
    fig = plot_models(campaign, curves)
    labels = [ln.get_label() for ln in fig.axes[0].get_lines()]
    assert len(fig.axes) == 3 and sum(lab.startswith(("M1", "M2", "M3")) for lab in labels) == 3
    samples = friction_samples(campaign)
    fig = plot_friction(samples, friction_curves(samples["q_set"], load_friction()))
    assert len(fig.axes[0].get_lines()) == len(samples["series"]) + 3     # samples, M2, M3, zero line
