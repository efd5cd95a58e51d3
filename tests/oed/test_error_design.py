"""Designs that learn the model error (issue 29 item 3, :mod:`oed.error_design`).

The posterior prediction variance after new runs is checked against a brute-force computation written here from
the model error's public numbers only (its hyperparameters, sigma, the data and the model's sensitivities, which are
constant for the linear-in-p model used): the universal-kriging variance on the old and new data stacked in one
system, and the plain Gaussian conditioning with a wide normal prior on p.  The design is checked exhaustively
(every set of candidates scored by that brute force), enumeration and branch-and-bound agree on random instances,
and every bad argument gets a clear error naming it.  The Monte Carlo check that the predicted variance is the
variance of the prediction error is in bench/bench_error_design.py.
"""
from __future__ import annotations

import itertools
import json

import casadi as ca
import numpy as np
import pytest

from identification import Measurements, model_error
from models import Model
from oed.error_design import ErrorDesignResult, error_design_problem, select_error_design
from oed.error_design_search import VarianceProblem, search

X = np.linspace(0.0, 2.0, 9)
SIGMA = np.array([0.05, 0.08])
CAND = np.array([0.1, 0.6, 1.1, 1.7, 2.3, 2.8])
REGION = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
RW = np.array([1.0, 1.0, 2.0, 2.0, 1.0, 3.0, 3.0])


def _g(x):
    """dh/dp (n, 2 sensors, 2 parameters) of y1 = a + b x, y2 = a - b x^2 (linear in p: exact, constant)."""
    x = np.asarray(x, float).ravel()
    return np.stack([np.stack([np.ones_like(x), x], 1), np.stack([np.ones_like(x), -x ** 2], 1)], axis=1)


@pytest.fixture(scope="module")
def case():
    model = Model.explicit(["a", "b"], ["x"], ["y1", "y2"], h=lambda p, q: ca.vertcat(p[0] + p[1] * q[0],
                                                                                     p[0] - p[1] * q[0] ** 2),
                           name="lines")
    rng = np.random.default_rng(11)
    truth = np.stack([1.0 + 0.5 * X + 0.1 * np.sin(3 * X), 1.0 - 0.5 * X ** 2 + 0.1 * X ** 3], axis=1)
    z = truth[None] + SIGMA * rng.standard_normal((2, X.size, 2))
    data = Measurements(X[:, None], z, SIGMA, sensors=["y1", "y2"], input_names=["x"])
    return model_error(model, data, [1.0, 0.5], kind="discrepancy"), data


def _pinned(xa, xb, ell, pin):
    """The squared-exponential correlation conditioned on f(pin) = f'(pin) = 0 (identification.studies.discrepancy_gp's
    docstring), and the rough part's factor at xa (None: no pin)."""
    e = np.exp(-(xa[:, None] - xb[None]) ** 2 / (2 * ell ** 2))
    if pin is None:
        return e, np.ones(len(xa))
    a, b = (xa[:, None] - pin) / ell, (xb[None] - pin) / ell
    a2 = ((xa - pin) / ell) ** 2
    return e - np.exp(-(a ** 2 + b ** 2) / 2) * (1 + a * b), 1 - np.exp(-a2) * (1 + a2)


def _brute(res, data, targets, new, measured, repeats=1, prior=None, conditioning=False, pin=None, cond=None):
    """Posterior variances (n_targets, 2) of f_k(x*) plus its rough part after the old data and new runs at ``new``
    reading the sensors ``measured``: by one universal-kriging solve on the stacked data with p flat (``prior``
    None) or p ~ N(0, prior I), or (``conditioning``) by plain Gaussian conditioning of the joint normal vector
    (targets, readings) with p ~ N(0, prior I).  ``cond`` = (the condition code of every data row (9,), of the
    targets (one code), of the new runs (len(new),)): the discrepancy of each condition its own draw (None: one)."""
    cd, ct, cn = (np.zeros(X.size), 0, np.zeros(len(new))) if cond is None else cond
    hyp = {d.sensor: (d.amplitude, d.length_scales[0], d.rough) for d in res.discrepancies}
    names = ("y1", "y2")
    counts = data.counts()

    def rough(x, k):
        return hyp[names[k]][2] ** 2 * _pinned(np.array([x]), np.array([x]), hyp[names[k]][1], pin)[1][0]
    obs = [(x, k, rough(x, k) + SIGMA[k] ** 2 / counts[j, k], cd[j]) for k in range(2) for j, x in enumerate(X)]
    obs += [(x, k, rough(x, k) + SIGMA[k] ** 2 / repeats, c) for x, c in zip(new, cn) for k in measured]
    xo, ko, no, co = (np.array(v) for v in zip(*obs))
    lat = [(x, k) for x in targets for k in range(2)]
    xt, kt = (np.array(v) for v in zip(*lat))
    cnt = np.full(len(xt), ct)

    def K(xa, ka, ca, xb, kb, cb):
        out = np.zeros((len(xa), len(xb)))
        for k in range(2):
            s, ell, _ = hyp[names[k]]
            m = np.outer(ka == k, kb == k) & (ca[:, None] == cb[None, :])
            out += m * s ** 2 * _pinned(xa, xb, ell, pin)[0]
        return out

    Go = _g(xo)[np.arange(len(xo)), ko.astype(int)]
    Gt = _g(xt)[np.arange(len(xt)), kt.astype(int)]
    V = K(xo, ko, co, xo, ko, co) + np.diag(no)      # rough part and noise of every reading (a condition each)
    kt_o = K(xt, kt, cnt, xo, ko, co)
    rough_t = np.array([rough(x, int(k)) for x, k in zip(xt, kt)])
    prior_t = np.diag(K(xt, kt, cnt, xt, kt, cnt)) + rough_t
    if not conditioning:
        Vi = np.linalg.inv(V)
        C = np.linalg.inv(Go.T @ Vi @ Go + (0.0 if prior is None else np.eye(2) / prior))
        u = Gt - kt_o @ Vi @ Go
        var = prior_t - np.einsum("ij,jk,ik->i", kt_o, Vi, kt_o) + np.einsum("ip,pq,iq->i", u, C, u)
    else:
        Syy = prior * Go @ Go.T + V
        Sty = prior * Gt @ Go.T + kt_o
        var = prior * np.sum(Gt ** 2, 1) + prior_t - np.sum(Sty * np.linalg.solve(Syy, Sty.T).T, axis=1)
    return var.reshape(len(targets), 2)


def test_variance_after_runs_equals_brute_force_conditioning(case):
    res, data = case
    prob = error_design_problem(res, CAND, region=REGION, region_weights=RW)
    for new in ((), (2,), (0, 4), (1, 3, 5)):
        mine = prob.variances(new)
        uk = _brute(res, data, REGION, CAND[list(new)], (0, 1))
        np.testing.assert_allclose(mine, uk, rtol=1e-9, atol=0)
        for c in (0.1, 3.0):          # the kriging formula is the Gaussian conditioning, for every proper prior
            np.testing.assert_allclose(_brute(res, data, REGION, CAND[list(new)], (0, 1), prior=c),
                                       _brute(res, data, REGION, CAND[list(new)], (0, 1), prior=c, conditioning=True),
                                       rtol=1e-8)
    crit = np.mean(uk / SIGMA ** 2, axis=1) @ (RW / RW.sum())
    assert prob.value((1, 3, 5)) == pytest.approx(crit, rel=1e-9)


def test_exact_at_pins_the_discrepancy_and_its_rough_part(case):
    """exact_at={"x": 0}: the discrepancy and its slope vanish at x = 0 (and the rough part with them): the
    variance after runs against the brute force with the pinned kernel written here."""
    _, data = case
    model = Model.explicit(["a", "b"], ["x"], ["y1", "y2"], h=lambda p, q: ca.vertcat(p[0] + p[1] * q[0],
                                                                                     p[0] - p[1] * q[0] ** 2))
    res = model_error(model, data, [1.0, 0.5], kind="discrepancy", exact_at={"x": 0.0})
    prob = error_design_problem(res, CAND, region=REGION)
    for new in ((), (0, 3)):
        np.testing.assert_allclose(prob.variances(new), _brute(res, data, REGION, CAND[list(new)], (0, 1), pin=0.0),
                                   rtol=1e-9)
    b = res.predict(REGION[:, None], alpha=res.alpha)        # the same float sums in another order: 1e-9 as above
    np.testing.assert_allclose(prob.half_widths((), res.alpha), b.upper - b.mean, rtol=1e-9)


def test_before_band_is_the_band_of_predict(case):
    res, _ = case
    prob = error_design_problem(res, CAND, region=REGION)
    b = res.predict(REGION[:, None], alpha=0.1)
    np.testing.assert_allclose(prob.half_widths((), alpha=0.1), b.upper - b.mean, rtol=1e-10)


def test_one_sensor_runs_and_repeats_match_brute_force(case):
    res, data = case
    prob = error_design_problem(res, CAND, region=REGION, measure=["y2"], repeats=3)
    np.testing.assert_allclose(prob.variances((0, 5)), _brute(res, data, REGION, CAND[[0, 5]], (1,), repeats=3),
                               rtol=1e-9)
    pairs = error_design_problem(res, CAND, region=REGION, pairs=True)
    assert pairs.n_candidates == 2 * CAND.size and pairs.candidate_sensors[:2] == (("y1",), ("y2",))
    np.testing.assert_allclose(pairs.variances((3,)), _brute(res, data, REGION, CAND[[1]], (1,)), rtol=1e-9)


@pytest.mark.parametrize("criterion", ["integrated", "worst"])
@pytest.mark.parametrize("n", [1, 2])
def test_the_chosen_runs_shrink_the_band_most_among_all_sets(case, criterion, n):
    res, data = case
    d = select_error_design(res, CAND, n, region=REGION, region_weights=RW, criterion=criterion)
    assert d.proven and d.method == "enumerate" and d.gap == 0.0
    scores = {}
    for s in itertools.combinations(range(CAND.size), n):
        v = _brute(res, data, REGION, CAND[list(s)], (0, 1)) / SIGMA ** 2
        scores[s] = v.max() if criterion == "worst" else np.mean(v, axis=1) @ (RW / RW.sum())
    best = min(scores, key=scores.get)
    assert d.chosen == best
    assert d.value_after == pytest.approx(scores[best], rel=1e-9)
    assert d.value_after < d.value_before and d.irreducible <= d.value_after
    assert np.all(d.half_after <= d.half_before * (1 + 1e-12))
    np.testing.assert_allclose(d.chosen_inputs.ravel(), CAND[list(best)])


def _random_problem(seed: int, worst: bool, n_c: int = 9, group: int = 2) -> VarianceProblem:
    """A random GP over [0, 1] with a linear trend, 12 targets and n_c candidates of ``group`` readings each."""
    rng = np.random.default_rng(seed)
    n_T, n_O = 12, n_c * group
    x = rng.uniform(0.0, 1.0, n_T + n_O)
    K = np.exp(-(x[:, None] - x[None]) ** 2 / (2 * 0.25 ** 2)) + 0.5 * np.outer(x, x)
    noise = rng.uniform(0.05, 0.5, n_O)
    w = rng.uniform(0.5, 1.0, n_T)
    return VarianceProblem(np.diag(K)[:n_T].copy(), K[:n_T, n_T:] / np.sqrt(noise), K[n_T:, n_T:] /
                           np.sqrt(np.outer(noise, noise)), tuple(np.arange(c * group, (c + 1) * group)
                                                                  for c in range(n_c)), w / w.sum(), worst)


@pytest.mark.parametrize("worst", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_branch_and_bound_and_enumeration_agree_on_random_instances(worst, seed):
    prob = _random_problem(seed, worst)
    for n in (2, 3):
        e = search(prob, n, "enumerate")
        b = search(prob, n, "bnb")
        g = search(prob, n, "greedy")
        assert e.proven and b.proven
        assert b.value == pytest.approx(e.value, rel=1e-9)
        assert b.lower_bound <= e.value * (1 + 1e-9) and b.gap <= 1e-9 * e.value
        assert g.value >= e.value * (1 - 1e-12) and g.lower_bound <= e.value * (1 + 1e-12)
        assert g.status in ("heuristic", "optimal") and g.method == "greedy"


def test_relaxation_is_exact_at_sets_and_its_gradient_is_the_derivative():
    prob = _random_problem(5, False)
    s = np.array([1, 4, 7])
    x = np.zeros(prob.n_candidates)
    x[s] = 1.0
    v, g = prob.relaxed(x)
    np.testing.assert_allclose(v, prob.variances(s[None])[0], rtol=1e-10)
    x = np.random.default_rng(1).uniform(0.2, 0.8, prob.n_candidates)
    v, g = prob.relaxed(x)
    h = 1e-6                                        # a test-side difference quotient of the analytic gradient
    for c in (0, 3, 8):
        e = np.zeros_like(x)
        e[c] = h
        np.testing.assert_allclose((prob.relaxed(x + e)[0] - prob.relaxed(x - e)[0]) / (2 * h), g[:, c], rtol=1e-5,
                                   atol=1e-9)


def test_time_limit_reports_the_proven_gap():
    prob = _random_problem(3, False, n_c=14)
    out = search(prob, 5, "bnb", time_limit=1e-9)
    assert not out.proven and out.status == "time_limit"
    assert out.lower_bound <= out.value and np.isfinite(out.gap)


def test_box_region_and_result_protocol(case):
    res, _ = case
    d = select_error_design(res, CAND, 2, region={"x": (0.0, 3.0)}, region_size=5, criterion="worst", method="bnb")
    assert d.region.shape == (5, 1) and d.region[0, 0] == 0.0 and d.region[-1, 0] == 3.0
    assert isinstance(d, ErrorDesignResult) and d.proven
    json.dumps(d.to_dict(), allow_nan=False)
    df = d.to_frame()
    assert list(df.columns) == ["x", "target", "weight", "half_before", "half_after", "shrink"] and len(df) == 10
    assert "proven optimal" in d.summary() and "<pre>" in d._repr_html_()
    quad = error_design_problem(res, CAND, region={"x": (0.0, 3.0)}, region_size=5)
    assert quad.region_weights.sum() == pytest.approx(1.0) and 0.0 < quad.region[0, 0]   # Gauss-Legendre nodes


@pytest.mark.parametrize("kind", ["none", "embedded"])
def test_other_error_models_give_the_band_of_predict(case, kind):
    _, data = case
    model = Model.explicit(["a", "b"], ["x"], ["y1", "y2"], h=lambda p, q: ca.vertcat(p[0] + p[1] * q[0],
                                                                                     p[0] - p[1] * q[0] ** 2))
    res = model_error(model, data, [1.0, 0.5], kind=kind)
    d = select_error_design(res, CAND, 2, region=REGION)
    b = res.predict(REGION[:, None], alpha=res.alpha)
    np.testing.assert_allclose(d.half_before, b.upper - b.mean, rtol=1e-10)
    assert d.value_after < d.value_before and d.proven


def test_a_dynamic_model_falls_out_experiments_by_times():
    """dx/dt = u - k x observed as x and 2 x, the truth with a missing - q x^2: new experiments (step levels u) read
    every sampling time; the band before is the one of predict (experiments x times x sensors)."""
    from identification.fit.dynamic_fit import simulate_campaign
    from models.contract import Parameter

    def model(missing):
        params = [Parameter("k", 0.01, 100.0, scale=1.0)] + ([] if missing else [Parameter("q", -10.0, 10.0, scale=1.0)])
        return Model.ode(params, states=["x"], inputs=["u"], sensors=["y", "w"],
                         rhs=lambda x, p, u: ca.vertcat(u[0] - p[0] * x[0] - (0.0 if missing else p[1] * x[0] ** 2)),
                         x0=lambda p, u: ca.vertcat(0.0), h=lambda x, p, u: ca.vertcat(x[0], 2 * x[0]), time_unit="s")
    times = np.linspace(0.2, 3.0, 8)
    data = simulate_campaign(model(False), [1.0, 0.3], np.array([[1.0], [2.0], [3.0]]), times, np.array([0.01, 0.02]),
                             n_series=2, seed=4)
    res = model_error(model(True), data, [1.0], kind="discrepancy")
    region = np.array([[1.5], [2.5]])
    d = select_error_design(res, np.linspace(0.5, 4.0, 6), 2, region=region, sensors=["y"])
    assert d.proven and d.half_before.shape == (2, times.size) and d.target_labels[0] == "y at t=0.2"
    b = res.predict(region, alpha=res.alpha)
    np.testing.assert_allclose(d.half_before, (b.upper - b.mean)[:, :, 0], rtol=1e-9)
    assert d.value_after < d.value_before and np.all(d.half_after <= d.half_before * (1 + 1e-12))


@pytest.mark.parametrize("kwargs, match", [
    (dict(candidates=[[0.1, 2.0]]), "candidates"),
    (dict(candidates=[np.nan]), "candidates"),
    (dict(region=np.ones((3, 2))), "region"),
    (dict(region={"y": (0, 1)}), "region"),
    (dict(region={"x": (1, 0)}), "region"),
    (dict(region_weights=[1.0, -1.0, 1.0, 1.0, 1.0, 1.0, 1.0]), "region_weights"),
    (dict(criterion="mean"), "criterion"),
    (dict(sensors=["F_x"]), "sensors"),
    (dict(measure=[]), "measure"),
    (dict(repeats=0), "repeats"),
    (dict(n=7), "n"),
    (dict(n=True), "n"),
    (dict(method="exact"), "method"),
    (dict(time_limit=0), "time_limit"),
    (dict(alpha=1.5), "alpha"),
    (dict(pairs="yes"), "pairs"),
    (dict(region={"x": (0, 1)}, region_size=0), "region_size"),
])
def test_bad_input_names_the_argument(case, kwargs, match):
    res, _ = case
    args = dict(candidates=CAND, n=2, region=REGION) | kwargs
    with pytest.raises(ValueError, match=match):
        select_error_design(res, args.pop("candidates"), args.pop("n"), **args)
    with pytest.raises(ValueError, match="result"):
        select_error_design(object(), CAND, 1, region=REGION)


def test_time_limit_of_the_front_door_warns_and_says_not_proven(case):
    res, _ = case
    many = np.linspace(0.0, 3.0, 14)
    with pytest.warns(RuntimeWarning, match="not proven optimal"):
        d = select_error_design(res, many, 5, region=REGION, method="bnb", time_limit=1e-9)
    assert not d.proven and d.status == "time_limit" and "NOT proven" in d.summary()
    assert d.lower_bound <= d.value_after and d.gap == pytest.approx(d.value_after - d.lower_bound)


def test_embedded_error_after_runs_equals_brute_force(case):
    """Kind "embedded": every condition (old row, new run, target) has its own b ~ N(0, Omega), shared by its sensors;
    generalised least squares on the stacked old and new readings with that covariance, written here."""
    _, data = case
    model = Model.explicit(["a", "b"], ["x"], ["y1", "y2"], h=lambda p, q: ca.vertcat(p[0] + p[1] * q[0],
                                                                                     p[0] - p[1] * q[0] ** 2))
    res = model_error(model, data, [1.0, 0.5], kind="embedded")
    Om = np.diag([e.omega ** 2 for e in res.embedded])
    new = (1, 4)
    rows = [(x, SIGMA ** 2 / data.counts()[j]) for j, x in enumerate(X)] + [(CAND[c], SIGMA ** 2) for c in new]
    G = np.concatenate([_g([x])[0] for x, _ in rows])                      # (2 rows, 2 p) per condition
    V = np.zeros((len(G), len(G)))
    for i, (x, noise) in enumerate(rows):
        g = _g([x])[0]
        V[2 * i:2 * i + 2, 2 * i:2 * i + 2] = g @ Om @ g.T + np.diag(noise)
    C = np.linalg.inv(G.T @ np.linalg.solve(V, G))
    gt = _g(REGION)                                                        # (n_r, 2, 2)
    want = np.einsum("rkp,pq,rkq->rk", gt, C + Om, gt)
    prob = error_design_problem(res, CAND, region=REGION)
    np.testing.assert_allclose(prob.variances(new), want, rtol=1e-9)


DAYS = np.where(X < 1.0, "day 1", "day 2")            # rows 0-3 day 1, 4-8 day 2
CODES = {"day 1": 0, "day 2": 1, "new": -1}
CAND_DAYS = ["day 1", "day 2", "new", "day 2", "new", "day 1"]


@pytest.fixture(scope="module")
def named(case):
    """The discrepancy with the data's two days named as conditions (each day's discrepancy its own draw)."""
    res, data = case
    return model_error(res.fit.model, data, [1.0, 0.5], kind="discrepancy", groups=DAYS), data


def _brute_days(res, data, region, new, days, prior=None, conditioning=False):
    """_brute per region condition, stacked condition-major (the order of the problem's region)."""
    cd = np.array([CODES[d] for d in DAYS])
    cn = np.array([CODES[CAND_DAYS[c]] for c in new])
    return np.vstack([_brute(res, data, region, CAND[list(new)], (0, 1), prior=prior, conditioning=conditioning,
                             cond=(cd, CODES[day], cn)) for day in days])


def test_runs_in_named_conditions_equal_brute_force_conditioning(named):
    """A run in day 1 shrinks day 1's discrepancy, a run in "new" the one of the condition the data do not hold,
    shared with the region's points there; every variance after runs equals the brute force (1e-9), and that
    kriging formula equals plain Gaussian conditioning with a normal prior on p (1e-8)."""
    res, data = named
    assert res.groups == ("day 1", "day 2") and res.kind == "discrepancy"
    days = ("day 1", "day 2", "new")
    prob = error_design_problem(res, CAND, region=REGION, region_weights=RW, candidate_conditions=CAND_DAYS,
                                region_conditions=days)
    assert prob.candidate_conditions == tuple(CAND_DAYS) and prob.region_conditions[::REGION.size] == days
    for new in ((), (0,), (2,), (1, 4), (0, 2, 3, 5)):
        np.testing.assert_allclose(prob.variances(new), _brute_days(res, data, REGION, new, days), rtol=1e-9, atol=0)
        for c in (0.1, 3.0):
            np.testing.assert_allclose(_brute_days(res, data, REGION, new, days, prior=c),
                                       _brute_days(res, data, REGION, new, days, prior=c, conditioning=True),
                                       rtol=1e-8)
    v0, v_new = prob.variances(()), prob.variances((2,))          # a run in "new" at x = 1.1
    n_r = REGION.size
    assert np.all(v_new[2 * n_r:] < v0[2 * n_r:]) and v_new[2 * n_r + 2].sum() < 0.5 * v0[2 * n_r + 2].sum()
    crit = np.mean(_brute_days(res, data, REGION, (1, 4), days) / SIGMA ** 2, axis=1) @ (np.tile(RW, 3) / RW.sum() / 3)
    assert prob.value((1, 4)) == pytest.approx(crit, rel=1e-9)


def test_band_before_runs_in_a_condition_is_the_band_of_predict(named):
    res, _ = named
    for day in ("day 1", "day 2", "new"):
        prob = error_design_problem(res, CAND, region=REGION, region_conditions=day)
        b = res.predict(REGION[:, None], alpha=0.1, condition=day)
        np.testing.assert_allclose(prob.half_widths((), alpha=0.1), b.upper - b.mean, rtol=1e-10)


def test_new_condition_without_groups_is_the_band_of_predict(case):
    res, data = case
    prob = error_design_problem(res, CAND, region=REGION, region_conditions="new",
                                candidate_conditions=["new"] * 3 + [None] * 3)
    b = res.predict(REGION[:, None], alpha=0.1, condition="new")
    np.testing.assert_allclose(prob.half_widths((), alpha=0.1), b.upper - b.mean, rtol=1e-10)
    cd, cn = np.zeros(X.size), np.array([-1, 0])
    np.testing.assert_allclose(prob.variances((1, 4)), _brute(res, data, REGION, CAND[[1, 4]], (0, 1),
                                                              cond=(cd, -1, cn)), rtol=1e-9)


@pytest.mark.parametrize("criterion", ["integrated", "worst"])
@pytest.mark.parametrize("n", [1, 2])
def test_runs_offered_in_every_condition_the_best_set_among_all(named, criterion, n):
    """candidate_conditions None: every row in every condition the data hold (12 candidates); the chosen set is the
    best of every set scored by the brute force; the region in both days (default)."""
    res, data = named
    d = select_error_design(res, CAND, n, region=REGION, region_weights=RW, criterion=criterion)
    assert d.proven and d.method == "enumerate" and d.region_conditions[::REGION.size] == ("day 1", "day 2")
    cd = np.array([CODES[x] for x in DAYS])
    offered = [(j, day) for j in range(CAND.size) for day in ("day 1", "day 2")]
    scores = {}
    for s in itertools.combinations(range(len(offered)), n):
        cn = np.array([CODES[offered[i][1]] for i in s])
        x = CAND[[offered[i][0] for i in s]]
        v = np.vstack([_brute(res, data, REGION, x, (0, 1), cond=(cd, CODES[day], cn))
                       for day in ("day 1", "day 2")]) / SIGMA ** 2
        scores[s] = v.max() if criterion == "worst" else np.mean(v, axis=1) @ (np.tile(RW, 2) / RW.sum() / 2)
    best = min(scores, key=scores.get)
    assert d.chosen == best and d.value_after == pytest.approx(scores[best], rel=1e-9)
    assert d.chosen_conditions == tuple(offered[i][1] for i in best)
    np.testing.assert_allclose(d.chosen_inputs.ravel(), CAND[[offered[i][0] for i in best]])
    assert all(f"in {c}" in d.summary() for c in d.chosen_conditions)
    df = d.to_frame()
    assert list(df.columns[:3]) == ["x", "condition", "target"] and len(df) == 2 * REGION.size * 2
    json.dumps(d.to_dict(), allow_nan=False)


@pytest.mark.parametrize("criterion", ["integrated", "worst"])
def test_branch_and_bound_and_enumeration_agree_with_conditions(named, criterion):
    res, _ = named
    many = np.linspace(0.0, 3.0, 7)
    prob = error_design_problem(res, many, region=REGION, criterion=criterion,
                                region_conditions=("day 1", "day 2", "new"),
                                candidate_conditions=None)
    assert prob.n_candidates == 14
    for n in (2, 3):
        e, b = search(prob.core, n, "enumerate"), search(prob.core, n, "bnb")
        assert e.proven and b.proven and b.value == pytest.approx(e.value, rel=1e-9)


@pytest.mark.parametrize("kwargs, match", [
    (dict(candidate_conditions="day 3"), "candidate_conditions: unknown condition 'day 3'"),
    (dict(candidate_conditions=["day 1"] * 5), "candidate_conditions: expected one condition label or one per"),
    (dict(region_conditions=["day 1", "monday"]), "region_conditions: unknown condition 'monday'"),
    (dict(region_conditions=["day 1", "day 1"]), "region_conditions: a condition is named twice"),
    (dict(region_conditions=[]), "region_conditions: expected a condition label"),
    (dict(region_conditions=None, candidate_conditions=[None] * 6), "candidate_conditions: unknown condition None"),
])
def test_bad_conditions_name_the_argument(named, kwargs, match):
    res, _ = named
    with pytest.raises(ValueError, match=match):
        select_error_design(res, CAND, 1, region=REGION, **kwargs)


def test_conditions_without_groups_or_discrepancy_name_the_argument(case):
    res, data = case
    with pytest.raises(ValueError, match="region_conditions: unknown condition 'day 1'; expected None"):
        select_error_design(res, CAND, 1, region=REGION, region_conditions="day 1")
    emb = model_error(res.fit.model, data, [1.0, 0.5], kind="embedded", groups=DAYS)
    with pytest.raises(ValueError, match="candidate_conditions: runs and regions in named conditions need the "
                                         "discrepancy"):
        select_error_design(emb, CAND, 1, region=REGION, candidate_conditions="day 1")
