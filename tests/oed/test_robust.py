"""oed.approximate / oed.robust: approximate local, pseudo-Bayesian and maximin designs and their certificates.

The compartmental model eta = theta3 (exp(-theta1 t) - exp(-theta2 t)), t in [0, 24], at
theta = (0.05884, 4.298, 21.80) (Atkinson, Donev & Tobias 2007, ch. 17: the D-optimal design puts
weight 1/3 at t = 0.2288, 1.3886 and 18.4168).
"""
import casadi as ca
import numpy as np
import pytest

from models import Model, Parameter
from oed.approximate import ApproximateSettings, approximate_design
from oed import information

P0 = np.array([0.05884, 4.298, 21.80])
NARROW = {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 3.298, 5.298)}


@pytest.fixture(scope="module")
def model():
    return Model.explicit(["theta1", "theta2", "theta3"], ["t"], ["eta"],
                          h=lambda p, q: p[2] * (ca.exp(-p[0] * q[0]) - ca.exp(-p[1] * q[0])),
                          name="compartmental")


def _fine_information(model, P, T):
    """(n_t, n_s, 3, 3): the information of one observation at every time and parameter vector."""
    return np.stack([information(model, p, axis="inputs", candidates=T[:, None], sigma=1.0).F for p in P], axis=1)


def _sensitivity(F_design, w, F_fine, prior_w):
    """g(t) = sum_s pi_s tr(M_s^-1 F_s(t)) of the design, recomputed independently of the engine."""
    M = np.einsum("x,xsij->sij", w, F_design)
    return np.einsum("sij,xsji->xs", np.linalg.inv(M), F_fine) @ prior_w


def test_textbook_local_d_design_and_its_certificate(model):
    r = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0))
    assert r.robust == "local" and r.points.shape == (3, 1)
    assert np.all(np.abs(r.points[:, 0] - [0.2288, 1.3886, 18.4168]) < 2e-4)
    assert r.weights == pytest.approx(np.full(3, 1 / 3), abs=1e-6)
    assert abs(r.sensitivity_max - 3.0) < 1e-6 and r.reference == pytest.approx(3.0, abs=1e-12)
    assert r.efficiency_bound > 1 - 1e-6
    # independent check of the certificate on a grid the engine never used (spacing 1e-3)
    T = np.linspace(0.0, 24.0, 24001)
    g = _sensitivity(_fine_information(model, [P0], r.points[:, 0]), r.weights, _fine_information(model, [P0], T),
                     np.ones(1))
    assert g.max() < 3.0 + 1e-6
    assert r.to_frame()["weight"].sum() == pytest.approx(1.0)
    d = r.to_dict()
    assert d["points"] and d["quadrature_error"] is None and "weight 0.333333" in r.summary()
    assert "<table>" in r._repr_html_()


def test_continuous_polish_improves_on_the_grid_refinement(model):
    grid_only = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), settings=ApproximateSettings(
        polish_rounds=0))
    polished = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0))
    assert polished.value >= grid_only.value and polished.gap <= grid_only.gap + 1e-12
    assert abs(polished.sensitivity_max - 3.0) < 1e-10


@pytest.mark.parametrize("criterion", ["A", "E"])
def test_local_a_and_e_designs_satisfy_their_equivalence_theorems(model, criterion):
    r = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), criterion=criterion)
    assert r.gap < 1e-6 * r.reference and r.efficiency_bound > 1 - 1e-6
    assert r.weights.sum() == pytest.approx(1.0) and np.all(r.weights > 0)
    Fd = _fine_information(model, [P0], r.points[:, 0])
    M = np.einsum("x,xij->ij", r.weights, Fd[:, 0])
    lam, V = np.linalg.eigh(M)
    G = np.linalg.matrix_power(np.linalg.inv(M), 2) if criterion == "A" else np.outer(V[:, 0], V[:, 0]) / lam[0] ** 2
    Ff = _fine_information(model, [P0], np.linspace(0.0, 24.0, 4801))[:, 0]
    g = np.einsum("ij,xji->x", G, Ff)
    assert g.max() <= np.trace(G @ M) * (1 + 1e-6)
    assert r.value == pytest.approx(-np.trace(np.linalg.inv(M)) if criterion == "A" else -1 / lam[0], rel=1e-10)


def _brute_multiplicative(F, prior_w, n_p, tol=5e-5, max_iter=200000):
    """The multiplicative algorithm w <- w g / n_p on the whole fine grid (dropping points whose weight fell below
    1e-10 at steps 512, 1024, 2048, ..., for speed) until its equivalence gap over the whole grid (which bounds its
    distance to the grid's optimum whatever was dropped) is below tol; returns (expected log det, gap)."""
    w = np.full(F.shape[0], 1.0 / F.shape[0])
    keep = np.arange(F.shape[0])
    for it in range(max_iter):
        if it >= 512 and it & (it - 1) == 0:
            sel = w > 1e-10
            keep, w = keep[sel], w[sel] / w[sel].sum()
        Fk = F[keep]
        M = np.einsum("x,xsij->sij", w, Fk)
        g = np.einsum("sij,xsji->xs", np.linalg.inv(M), Fk) @ prior_w
        if it % 1000 == 999:
            gap = (np.einsum("sij,xsji->xs", np.linalg.inv(M), F) @ prior_w).max() - n_p
            if gap < tol:
                return float(prior_w @ np.linalg.slogdet(M)[1]), float(gap)
        w = w * g / n_p
        w /= w.sum()
    raise AssertionError("the brute-force multiplicative algorithm did not converge")


def test_bayesian_d_design_certificate_and_brute_force_agreement(model):
    r = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), prior=NARROW,
                           settings=ApproximateSettings(prior_order=2))
    assert r.robust == "bayes" and r.prior.n == 4
    assert abs(r.sensitivity_max - 3.0) < 1e-3
    assert 0 < r.quadrature_error < 1e-3       # 2 x 2 Gauss rule against the 3 x 3 one
    T = np.r_[np.linspace(0.0, 2.0, 2001), np.linspace(2.02, 24.0, 1100)]     # spacing 0.001, then 0.02
    brute, brute_gap = _brute_multiplicative(_fine_information(model, r.prior.points, T), r.prior.weights, 3)
    assert brute_gap < 5e-5
    # the brute force's optimum lies in [brute, brute + brute_gap]; the engine's design must reach it to 1e-4
    assert abs(r.value - brute) < 1e-4
    assert brute <= r.value + max(r.gap, 0.0) + 1e-12


def test_wide_prior_spreads_the_bayesian_design_and_the_local_design_loses_across_it(model):
    from oed import design_efficiencies
    wide = {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 0.298, 8.298)}
    r = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), prior=wide,
                           settings=ApproximateSettings(prior_order=5))
    assert len(r.weights) > 3 and abs(r.sensitivity_max - 3.0) < 1e-3
    local = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0))
    eff = design_efficiencies(model, local, r, sigma=1.0)
    assert eff.shape == (25,) and np.allclose(design_efficiencies(model, r, r, sigma=1.0), 1.0)
    # sum_s pi_s n_p log eff_s = Phi(local) - Phi(bayes) <= the Bayesian design's certified gap
    assert 3 * r.prior.mean(np.log(eff)) <= max(r.gap, 0.0) + 1e-12
    assert eff.min() < 0.9


def test_maximin_d_design_against_a_brute_force_parameter_grid(model):
    box = {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 2.298, 6.298)}
    r = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), prior=box, robust="maximin",
                           settings=ApproximateSettings(prior_order=3))
    assert r.robust == "maximin" and r.prior.n == 9 and r.efficiency_bound > 1 - 1e-4
    assert r.worst_case_bound <= r.value + 1e-12 and np.min(r.efficiencies) == pytest.approx(r.value)
    # brute force: the efficiency of the maximin design at every point of a 5 x 5 parameter grid (which contains
    # the 3 x 3 design grid), against each point's own local D-optimum
    effs = []
    for t1 in np.linspace(0.04884, 0.06884, 5):
        for t2 in np.linspace(2.298, 6.298, 5):
            p = np.array([t1, t2, 21.8])
            loc = approximate_design(model, p, sigma=1.0, bounds=(0.0, 24.0))
            M = np.einsum("x,xij->ij", r.weights, _fine_information(model, [p], r.points[:, 0])[:, 0])
            effs.append(np.exp((np.linalg.slogdet(M)[1] - loc.value) / 3))
    assert abs(min(effs) - r.worst_case_bound) < 1e-3


def test_dynamic_sampling_times_under_a_prior():
    from mudoe.example_reactor import P_TRUE, build
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]])
    r = approximate_design(m, P_TRUE, sigma=np.array([0.01, 0.008]), bounds=(0.0, 2.0), inputs=Q,
                           prior={"E1": ("uniform", 55.0, 65.0), "E2": ("uniform", 75.0, 85.0)},
                           settings=ApproximateSettings(grid=41, rounds=5, prior_order=2))
    assert r.names == ("t",) and r.prior.n == 4
    assert np.all((r.points >= 0.0) & (r.points <= 2.0))
    assert abs(r.sensitivity_max - 4.0) < 1e-3 and r.weights.sum() == pytest.approx(1.0)


@pytest.mark.parametrize("kwargs, match", [
    (dict(bounds=(3.0, 3.0)), r"bounds: approximate designs need a continuous range"),
    (dict(bounds=(0.0, np.inf)), r"bounds: expected finite lower <= upper"),
    (dict(bounds=(0.0, 24.0), prior={"k9": ("uniform", 0.0, 1.0)}), r"prior: 'k9' is not a parameter"),
    (dict(bounds=(0.0, 24.0), prior={"theta1": ("gamma", 1.0, 1.0)}), r"prior\['theta1'\]: unknown distribution"),
    (dict(bounds=(0.0, 24.0), prior=(np.tile(P0, (2, 1)), [-1.0, 2.0])), r"prior: weights w must be finite"),
    (dict(bounds=(0.0, 24.0), prior=NARROW, robust="minimax"), r"robust: expected one of"),
    (dict(bounds=(0.0, 24.0), criterion="G"), r"criterion: unknown design criterion"),
    (dict(bounds=(0.0, 24.0), inputs=[[1.0]]), r"inputs: only for a dynamic model"),
    (dict(bounds=(0.0, 24.0), sensors=["nope"]), r"sensors: unknown"),
])
def test_bad_input_names_the_argument(model, kwargs, match):
    with pytest.raises(ValueError, match=match):
        approximate_design(model, P0, sigma=1.0, **kwargs)


@pytest.mark.parametrize("kwargs, match", [
    (dict(grid=2), "grid: expected an integer >= 3"), (dict(zoom=1), "zoom: expected an integer >= 2"),
    (dict(rounds=-1), "rounds: expected an integer >= 0"), (dict(merge_tol=1.5), "merge_tol: expected a number"),
])
def test_bad_settings_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        ApproximateSettings(**kwargs)


def test_prior_outside_the_model_bounds_is_refused():
    m = Model.explicit([Parameter("k", 0.0, 10.0)], ["t"], ["y"], h=lambda p, q: ca.exp(-p[0] * q[0]))
    with pytest.raises(ValueError, match=r"prior: k = -1 \(a quadrature point\) lies outside"):
        approximate_design(m, [1.0], sigma=1.0, bounds=(0.0, 5.0), prior=(np.array([[-1.0], [1.0]]), [1, 1]))


def test_design_verbs_route_approximate_designs(model):
    from oed import select_inputs, select_times
    r = select_inputs(model, P0, candidates=np.linspace(0.0, 24.0, 5), sigma=1.0, approximate=True)
    ref = approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0))
    assert np.array_equal(r.points, ref.points) and np.array_equal(r.weights, ref.weights)
    with pytest.raises(ValueError, match="candidates: approximate designs need a continuous range"):
        select_inputs(model, P0, candidates=[[3.0]], sigma=1.0, approximate=True)
    # a prior without approximate=True: the exact robust design of n_points rows (tests/oed/test_robust_inputs.py)
    with pytest.raises(ValueError, match="n_points: no set of 3 candidates gives a non-singular information"):
        select_inputs(model, P0, candidates=np.linspace(0.0, 24.0, 5), sigma=1.0, n_points=3, prior=NARROW)
    ex = select_inputs(model, P0, candidates=np.linspace(0.25, 24.0, 6), sigma=1.0, n_points=3, prior=NARROW)
    assert ex.proven_optimal and len(ex.indices) == 3 and all(n.startswith("q") for n in ex.names)
    with pytest.raises(ValueError, match="n_points: not used by an approximate design"):
        select_inputs(model, P0, candidates=np.linspace(0.0, 24.0, 5), sigma=1.0, n_points=3, approximate=True)
    from mudoe.example_reactor import P_TRUE, TIMES, build
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 350.0]])
    with pytest.raises(ValueError, match="times: approximate designs need a continuous range of times"):
        select_times(m, P_TRUE, [0.5], Q, np.array([0.01, 0.008]), approximate=True)
    with pytest.raises(ValueError, match="pairs: not used by an approximate design"):
        select_times(m, P_TRUE, TIMES, Q, np.array([0.01, 0.008]), approximate=True, pairs=True)
    rt = select_times(m, P_TRUE, TIMES, Q, np.array([0.01, 0.008]), approximate=True, criterion="A",
                      approx_settings=ApproximateSettings(grid=31, rounds=4))
    assert rt.names == ("t",) and TIMES.min() <= rt.points.min() and rt.points.max() <= TIMES.max()
    assert rt.gap < 1e-6 * rt.reference


def test_classical_polynomial_designs_including_a_multiple_smallest_eigenvalue():
    line = Model.explicit(["b0", "b1"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0])
    r = approximate_design(line, [1.0, 1.0], sigma=1.0, bounds=(-1.0, 1.0), criterion="E")
    assert np.allclose(r.points[:, 0], [-1.0, 1.0]) and np.allclose(r.weights, 0.5, atol=1e-7)
    assert r.multiplicity == 2 and r.gap < 1e-9 and any("multiplicity 2" in n for n in r.notes)
    quad = Model.explicit(["b0", "b1", "b2"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0] + p[2] * q[0] ** 2)
    e = approximate_design(quad, np.ones(3), sigma=1.0, bounds=(-1.0, 1.0), criterion="E")
    assert np.allclose(e.points[:, 0], [-1.0, 0.0, 1.0], atol=1e-6)
    assert np.allclose(e.weights, [0.2, 0.6, 0.2], atol=1e-6) and e.value == pytest.approx(-5.0, rel=1e-7)
    d = approximate_design(quad, np.ones(3), sigma=1.0, bounds=(-1.0, 1.0), criterion="D")
    assert np.allclose(d.weights, 1 / 3, atol=1e-7) and d.value == pytest.approx(np.log(4 / 27), rel=1e-9)
