"""oed.robust_refine: the continuous refinement of exact n-run robust designs (input rows and sampling times): the
refined criterion is at least the exact design's, checked independently, beats a 10x finer candidate grid, and its
efficiency against the approximate robust design is reported (at most 1 + the approximate design's gap)."""
import itertools

import casadi as ca
import numpy as np
import pytest

from models import Model
from oed import make_prior, select_inputs, select_times
from oed.approximate import ApproximateSettings
from oed.robust_refine import RobustRefineSettings, refine_robust

T = np.array([0.1, 0.3, 0.6, 1.0, 1.5, 2.2, 3.0, 4.5])     # 8 candidate inputs (as tests/oed/test_robust_inputs.py)
P0 = np.array([2.0, 0.8])                                  # a, b of y = a exp(-b t), sigma 0.1
PRIOR = {"b": ("uniform", 0.3, 2.5)}


@pytest.fixture(scope="module")
def expo():
    return Model.explicit(["a", "b"], ["t"], ["y"], h=lambda p, q: p[0] * ca.exp(-p[1] * q[0]))


def _F(p, t):
    """One run's information at the times t from the closed-form gradient (sigma = 0.1)."""
    t = np.asarray(t, float).ravel()
    g = np.stack([np.exp(-p[1] * t), -p[0] * t * np.exp(-p[1] * t)], axis=1)
    return g[:, :, None] * g[:, None, :] / 0.1 ** 2


def _u(crit, M):
    """Utilities of a stack of information matrices (..., 2, 2)."""
    if crit == "D":
        return np.linalg.slogdet(M)[1]
    if crit == "A":
        return -np.trace(np.linalg.inv(M), axis1=-2, axis2=-1)
    return -1.0 / np.linalg.eigvalsh(M)[..., 0]


def _phis(crit, robust, pr, t, sets, u_star):
    """The robust criterion of every n-run design t[set] (rows of ``sets``), independently (closed form)."""
    u = np.stack([_u(crit, _F(ps, t)[sets].mean(axis=1)) for ps in pr.points], axis=1)
    if robust == "bayes":
        return u @ pr.weights
    c = (u - u_star) / 2 if crit == "D" else u / np.abs(u_star)
    return c.min(axis=1)


@pytest.mark.parametrize("robust", ["bayes", "maximin"])
@pytest.mark.parametrize("crit", ["D", "A", "E"])
def test_refined_inputs_improve_the_exact_design_and_beat_a_finer_grid(expo, robust, crit):
    r = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR, robust=robust,
                      criterion=crit, refine=True)
    ref = r.refined
    pr = make_prior(PRIOR, expo, P0)
    u_star = None
    if robust == "maximin":       # each vector's own exact 3-run optimum over the candidates (the exact standard)
        sets8 = np.array(list(itertools.combinations(range(8), 3)))
        u_star = np.array([_u(crit, _F(ps, T)[sets8].mean(axis=1)).max() for ps in pr.points])
    assert ref.start_value == pytest.approx(r.value, rel=1e-10)
    assert np.allclose(ref.start[:, 0], T[list(r.indices)])
    assert ref.value >= ref.start_value
    assert ref.value == pytest.approx(_phis(crit, robust, pr, ref.points[:, 0], np.array([[0, 1, 2]]), u_star)[0],
                                      rel=1e-10)
    assert np.all((ref.points >= T.min()) & (ref.points <= T.max()))
    # a finer candidate grid (89 equispaced times, spacing 0.05, 113,564 sets): the continuous refinement is at least
    # as good as its best set
    fine = np.linspace(0.1, 4.5, 89)
    best = _phis(crit, robust, pr, fine, np.array(list(itertools.combinations(range(fine.size), 3))), u_star).max()
    assert ref.value >= best - 1e-12
    # against the approximate robust design on the same range: at most 1 + its gap (an n-run design is one)
    assert 0 < ref.approximate_efficiency <= 1.0 + max(ref.approximate_gap, 0.0) + 1e-9
    assert "refined exact" in r.summary() and r.to_dict()["refined"]["value"] == pytest.approx(ref.value)
    if robust == "maximin":
        assert ref.worst_case_efficiency > r.efficiency


def test_an_exact_design_without_refine_is_unchanged(expo):
    r = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR)
    assert r.refined is None and "refined" not in r.to_dict() and "refined" not in r.summary()


def test_refine_robust_never_worsens_and_stays_in_the_box():
    """One vector (a, b) = (1, 1): the D-optimal 2-run design of y = a exp(-b t) on [0, 5] is t = 0 and t = 1/b = 1.
    Started there it is kept; started elsewhere it is found."""
    pr = make_prior((np.array([[1.0, 1.0]]), [1.0]), ("a", "b"), [1.0, 1.0])

    def info(X, P):
        return np.stack([_F(ps, X[:, 0]) for ps in P], axis=1)
    out = refine_robust(info, np.array([[0.0], [1.0]]), pr, (np.array([0.0]), np.array([5.0])), criterion="D",
                        robust="bayes", u_star=None, spacing=np.array([0.5]), names=("t",),
                        settings=RobustRefineSettings(rounds=4))
    assert out.value == out.start_value and np.allclose(out.points[:, 0], [0.0, 1.0])
    out = refine_robust(info, np.array([[0.5], [4.0]]), pr, (np.array([0.0]), np.array([5.0])), criterion="D",
                        robust="bayes", u_star=None, spacing=np.array([0.5]), names=("t",))
    assert out.value > out.start_value and np.allclose(np.sort(out.points[:, 0]), [0.0, 1.0], atol=1e-5)
    with pytest.raises(ValueError, match="rounds: expected an integer >= 1"):
        RobustRefineSettings(rounds=0)


def test_refined_sampling_times_of_the_reactor():
    from mudoe.example_reactor import P_TRUE, TIMES, build
    m = build()
    Q, sigma = np.array([[1.0, 330.0], [2.0, 370.0]]), np.array([0.01, 0.008])
    prior = make_prior({"E1": ("uniform", 55.0, 65.0)}, m, P_TRUE, order=2)
    r = select_times(m, P_TRUE, TIMES, Q, sigma, n_times=4, prior=prior, refine=True,
                     approx_settings=ApproximateSettings(grid=21, rounds=3))
    ref = r.refined
    assert ref.start_value == pytest.approx(r.value, rel=1e-8) and ref.value >= ref.start_value
    assert np.all((ref.points >= TIMES.min()) & (ref.points <= TIMES.max()))
    assert 0 < ref.approximate_efficiency <= 1.0 + max(ref.approximate_gap, 0.0) + 1e-9
    with pytest.raises(ValueError, match="refine: the refinement of sampling times is for exact robust designs"):
        select_times(m, P_TRUE, TIMES, Q, sigma, n_times=4, refine=True)
