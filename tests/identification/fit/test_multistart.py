"""Multi-start fits (identification.fit.multistart): identify(..., starts=N) through Problem.fit (issue 30 item 2)."""
import warnings

import casadi as ca
import numpy as np
import pytest

from identification import DataError, Measurements, identify, simulate
from identification.fit.dynamic_fit import simulate_campaign
from identification.fit.multistart import (OBJECTIVE_RTOL, PARAMETER_TOL_SE, VALLEY_CHI2, MultiStartError,
                                           MultiStartRecord, StartFit, distinct_minima, draw_starts, sobol_points,
                                           start_rules, starts_from_unit, static_objective)
from identification.fit.problem import Problem
from models import Model, Parameter
from models.library import two_bar_truss
from mudoe.example_reactor import P_TRUE, TIMES, build

T = np.linspace(0.0, 10.0, 41)
SIGMA = 0.1
P0 = [1.0, 0.5]           # from here the fit ends in a wrong minimum (frequency 2.15 instead of 1.70)


def sinusoid(sigma=SIGMA):
    """y = a sin(w t), a in [-10, 10], w in [0.1, 5]: a local minimum near every frequency that aliases the data."""
    model = Model.explicit(params=[Parameter("a", -10.0, 10.0), Parameter("w", 0.1, 5.0)], inputs=["t"],
                           sensors=["y"], h=lambda p, q: p[0] * ca.sin(p[1] * q[0]), name="sinusoid")
    z = (2.0 * np.sin(1.7 * T))[None, :, None] + SIGMA * np.random.default_rng(1).standard_normal((1, T.size, 1))
    return model, Measurements(T, z, None if sigma is None else [sigma])


def grid_minimum(z):
    """The global minimum of Phi(a, w) = 0.5 sum ((z - a sin(w t)) / sigma)^2 on a dense grid of w (spacing 5e-5)
    with a at its exact optimum for each w (linear least squares, inside [-10, 10]): (Phi, a, w)."""
    w = np.linspace(0.1, 5.0, 98001)
    S = np.sin(np.outer(w, T))
    a = np.clip(S @ z / np.einsum("ij,ij->i", S, S), -10.0, 10.0)
    phi = 0.5 * np.sum(((z[None, :] - a[:, None] * S) / SIGMA) ** 2, axis=1)
    k = int(np.argmin(phi))
    return phi[k], a[k], w[k]


@pytest.fixture(scope="module")
def twenty():
    model, data = sinusoid()
    return model, data, identify(model, data, P0), identify(model, data, P0, starts=20)


def test_twenty_starts_find_the_global_minimum_that_p0_misses(twenty):
    model, data, one, est = twenty
    phi, a, w = grid_minimum(data.z[0, :, 0])
    # p0 alone ends in a local minimum far above the global one
    assert one.objective > phi + 1000.0 and abs(one.p[1] - w) > 0.4
    # the multi-start estimate is the global minimum of the dense grid: within one grid step of its w, and at an
    # objective no higher than the grid's (the grid only approximates the continuous minimum from above)
    assert abs(est.p[1] - w) <= 5e-5 and abs(est.p[0] - a) <= 1e-3
    assert est.objective <= phi and phi - est.objective < 1e-4
    ms = est.diagnostics.starts
    assert isinstance(ms, MultiStartRecord) and ms.n_starts == 20 and ms.best != 0
    assert ms.minima[0].objective == est.objective and np.array_equal(ms.p[ms.best], est.p)
    # the estimate is that of its start, fitted as a single start would be
    single = identify(model, data, ms.starts[ms.best])
    assert np.array_equal(single.p, est.p) and np.array_equal(single.cov, est.cov)


def test_the_record_counts_the_starts_and_the_distinct_minima(twenty):
    _, _, one, est = twenty
    ms = est.diagnostics.starts
    ok = np.array([o == "minimum" for o in ms.outcome])
    low = np.nanmin(ms.objective)          # the lowest objective; the estimate's is within the tolerance of it
    assert ms.objective_tol == OBJECTIVE_RTOL * max(1.0, low) and ms.minima[0].objective - low <= ms.objective_tol
    assert ms.reached_best == int(np.sum(ok & (ms.objective - low <= ms.objective_tol))) >= 2
    assert sum(m.count for m in ms.minima) == int(ok.sum())
    objs = [m.objective for m in ms.minima]
    assert objs == sorted(objs) and len(ms.minima) >= 3
    # the sinusoid's minima are isolated (different objectives): none is merged into a flat valley
    assert all(not m.is_valley and m.valley == "" and np.array_equal(m.p_low, m.p) for m in ms.minima if m.count == 1)
    assert not any(m.is_valley for m in ms.minima) and "flat valley" not in est.notes[-1]
    assert ms.objective[0] == one.objective                     # start 1 is p0, which ends where identify does
    assert 0 in ms.minima[1].starts or any(0 in m.starts for m in ms.minima[1:])
    note = est.notes[-1]
    assert note.startswith(f"multi-start: {ms.reached_best} of 20 starts reached the best minimum")
    assert f"{len(ms.minima)} distinct local minima, the next best at objective {ms.minima[1].objective:.6g}" in note
    assert "p0 (start 1) ended at objective" in note and note in est.summary()
    frame = ms.to_frame()
    assert list(frame.index) == list(range(1, 21)) and int((frame["minimum"] == 1).sum()) == ms.minima[0].count
    minima = ms.minima_frame()
    assert list(minima["starts"]) == [m.count for m in ms.minima] and minima["starts"].sum() == int(ok.sum())
    assert minima["objective"].iloc[0] == est.objective and minima["w"].iloc[0] == est.p[1]
    assert str(ms.best + 1) in minima["reached from"].iloc[0].split(", ")


def test_the_starts_are_reproducible_with_the_seed():
    model, data = sinusoid()
    a = identify(model, data, P0, starts=6, seed=7).diagnostics.starts
    b = identify(model, data, P0, starts=6, seed=7).diagnostics.starts
    c = identify(model, data, P0, starts=6, seed=8).diagnostics.starts
    assert np.array_equal(a.starts, b.starts) and np.array_equal(a.p, b.p) and a.seed == 7
    assert np.array_equal(a.starts[0], P0) and np.array_equal(c.starts[0], P0)
    assert not np.array_equal(a.starts[1:], c.starts[1:])
    # the starts of a seed do not depend on the fits: drawn alone they are the same
    assert np.array_equal(draw_starts(model, P0, 6, seed=7)[0], a.starts)
    # seed None draws fresh entropy and records it: seed=record.seed draws the same starts again
    X, _, entropy = draw_starts(model, P0, 6, seed=None)
    assert np.array_equal(draw_starts(model, P0, 6, seed=entropy)[0], X)


def rules_model():
    model = Model.explicit(params=[Parameter("k", 1e-4, 1e2), Parameter("f", 0.0, 1.0), Parameter("c", 0.0),
                                   Parameter("d", upper=5.0), Parameter("e")],
                           inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] + p[2] + p[3] + p[4] * q[0])
    return model, np.array([1.0, 0.5, 2.0, 3.0, -4.0])


def test_the_rules_log_scale_for_decades_and_around_p0_for_open_bounds():
    model, p0 = rules_model()
    assert [r[0] for r in start_rules(model, p0)] == ["log", "uniform", "above", "below", "around"]
    X, rules, _ = draw_starts(model, p0, 513, seed=3)
    k, f, c, d, e = X[1:].T
    assert np.all((k >= 1e-4) & (k < 1e2)) and np.all((f >= 0.0) & (f < 1.0))
    assert np.all((c > 0.2) & (c < 20.0)) and np.min(c) < 0.25 and np.max(c) > 18.0     # 0 + 2 x 10^U(-1, 1)
    assert np.all((d < 5.0 - 0.2) & (d > 5.0 - 20.0))                                    # 5 - 2 x 10^U(-1, 1)
    assert np.all(np.abs(e + 4.0) < 12.0) and np.max(np.abs(e + 4.0)) > 11.5             # -4 +- 3 x 4 U(-1, 1)
    assert rules[0] == "k log-uniform in [0.0001, 100]" and rules[4] == "e = -4 +- 3 x 4 U(-1,1)"


def test_the_drawn_starts_are_scrambled_sobol_points():
    """The 512 drawn starts are the first 2^9 points of a scrambled Sobol sequence: one in each of the 512 strata
    of every coordinate (in the rule's scale), and one in each elementary box of area 2^-9 of the first two
    (a (0, 9, 2)-net, which no Latin hypercube gives); fewer starts are the first rows of more."""
    model, p0 = rules_model()
    X, _, _ = draw_starts(model, p0, 513, seed=3)
    u = np.column_stack([np.log(X[1:, 0] / 1e-4) / np.log(1e6), X[1:, 1],
                         np.log10((X[1:, 2] - 0.0) / 2.0) / 2 + 0.5, np.log10((5.0 - X[1:, 3]) / 2.0) / 2 + 0.5,
                         (X[1:, 4] + 4.0) / 24.0 + 0.5])
    strata = np.floor(512 * u + 1e-9).astype(int)          # 1e-9: round-off of the inverse maps at a stratum edge
    for i in range(5):
        assert np.array_equal(np.sort(strata[:, i]), np.arange(512)), model.params[i].name
    for a in range(10):                                     # boxes 2^-a x 2^-(9 - a) of (k, f)
        box = np.floor(u[:, 0] * 2 ** a + 1e-9).astype(int) * 2 ** (9 - a) \
            + np.floor(u[:, 1] * 2 ** (9 - a) + 1e-9).astype(int)
        assert np.array_equal(np.sort(box), np.arange(512)), a
    with warnings.catch_warnings():
        warnings.simplefilter("error")                      # no "balance properties" warning for 7 - 1 = 6 points
        few = draw_starts(model, p0, 7, seed=3)[0]
    assert np.array_equal(few, X[:7])
    assert np.array_equal(starts_from_unit(model, p0, sobol_points(5, 512, 3)), X[1:])
    with pytest.raises(ValueError, match=r"u: expected points in \[0, 1\]\^5"):
        starts_from_unit(model, p0, np.full((2, 5), 1.5))


def test_starts_one_is_the_single_fit_bit_for_bit():
    model, data = sinusoid()
    a, b = identify(model, data, P0), identify(model, data, P0, starts=1, seed=5, workers=2)
    assert np.array_equal(a.p, b.p) and np.array_equal(a.cov, b.cov) and a.notes == b.notes
    assert a.diagnostics.starts is None and b.diagnostics.starts is None


def test_a_failed_start_is_recorded_and_named():
    """y = a exp(b t) with b up to 90 over t <= 10: starts with a large b overflow and fail; p0 fits."""
    model = Model.explicit(params=[Parameter("a", 0.1, 10.0), Parameter("b", -2.0, 90.0)], inputs=["t"],
                           sensors=["y"], h=lambda p, q: p[0] * ca.exp(p[1] * q[0]), name="exponential")
    t = np.linspace(0.0, 10.0, 21)
    z = (2.0 * np.exp(-0.5 * t))[None, :, None] + 0.01 * np.random.default_rng(1).standard_normal((1, t.size, 1))
    data = Measurements(t, z, [0.01])
    est = identify(model, data, [1.0, -0.3], starts=8)
    ms = est.diagnostics.starts
    assert len(ms.failed) >= 1 and ms.best == 0
    assert np.array_equal(est.p, identify(model, data, [1.0, -0.3]).p)
    for i in ms.failed:
        assert ms.outcome[i] == "failed" and ms.errors[i] and np.all(np.isnan(ms.p[i])) and np.isnan(ms.objective[i])
    assert f"{len(ms.failed)} starts failed (start {ms.failed[0] + 1}: " in est.notes[-1]


def test_all_starts_failing_raise_one_error_naming_them():
    """y = a b x: only the product is determined (not identifiable from any start)."""
    model = Model.explicit(params=[Parameter("a", 0.1, 10.0), Parameter("b", 0.1, 10.0)], inputs=["x"],
                           sensors=["y"], h=lambda p, q: p[0] * p[1] * q[0], name="product")
    x = np.linspace(0.1, 1.0, 10)
    data = Measurements(x, (2.0 * x)[None, :, None], [0.01])
    with pytest.raises(MultiStartError, match=r"all 4 starts failed: start 1 \(p0\): IdentifiabilityError") as info:
        identify(model, data, [1.0, 1.0], starts=4)
    assert len(info.value.errors) == 4 and all("not identifiable" in e for e in info.value.errors)
    assert info.value.starts.shape == (4, 2) and "start 2: " in str(info.value)


@pytest.mark.parametrize("bad, match", [(0, "starts: expected a positive integer"), (2.0, "starts:"),
                                        (True, "starts:"), ("3", "starts:")])
def test_starts_not_a_positive_integer_is_refused(bad, match):
    model, data = sinusoid()
    with pytest.raises(ValueError, match=match):
        identify(model, data, P0, starts=bad)


def test_bad_seed_workers_and_start_are_refused():
    model, data = sinusoid()
    with pytest.raises(ValueError, match="seed: expected an integer >= 0"):
        identify(model, data, P0, starts=3, seed=-1)
    with pytest.raises(ValueError, match="workers: must be an integer >= 1"):
        identify(model, data, P0, starts=3, workers=0)
    with pytest.raises(DataError, match="p0: start value 7 of 'w' lies outside its bounds"):
        identify(model, data, [1.0, 7.0], starts=3)


def test_sigma_unknown_starts_are_compared_by_the_residuals():
    """With sigma estimated every fit's objective is (n - n_p) / 2: the starts are ranked by 0.5 RSS / s_best^2."""
    model, data = sinusoid(sigma=None)
    est = identify(model, data, P0, starts=20)
    ms = est.diagnostics.starts
    s_best = est.sigma[0]
    for i in np.flatnonzero([o == "minimum" for o in ms.outcome]):
        rss = np.sum((data.z[0, :, 0] - simulate(model, ms.p[i], T[:, None])[:, 0]) ** 2)
        assert abs(ms.objective[i] - 0.5 * rss / s_best ** 2) <= 1e-8 * ms.objective[i]
    assert ms.minima[0].objective == pytest.approx(est.objective, rel=1e-12)
    assert est.p[1] == pytest.approx(1.70, abs=0.01)


def test_workers_give_the_serial_estimate():
    model, data = sinusoid()
    serial = identify(model, data, P0, starts=8)
    par = identify(model, data, P0, starts=8, workers=2)
    assert par.diagnostics.starts.backend == "2 local processes"
    assert np.array_equal(serial.p, par.p) and np.array_equal(serial.cov, par.cov)
    assert np.array_equal(serial.diagnostics.starts.p, par.diagnostics.starts.p, equal_nan=True)


def test_a_dynamic_model_at_its_global_minimum_gives_the_single_start_estimate():
    """The batch reactor (mudoe.example_reactor) fits to the same minimum from p0 and from two drawn starts."""
    Q = np.array([[1.0, 330.0], [1.0, 340.0], [2.0, 360.0]])
    data = simulate_campaign(build(), P_TRUE, Q, TIMES, np.array([0.01, 0.008]), seed=1)
    p0 = [1.5, 50.0, 1.0, 70.0]
    one = identify(build(), data, p0)
    three = identify(build(), data, p0, starts=3)
    ms = three.diagnostics.starts
    assert np.array_equal(one.p, three.p) and np.array_equal(one.cov, three.cov) and ms.best == 0
    assert ms.reached_best == 3 and len(ms.minima) == 1
    assert np.all(np.abs(ms.p - one.p) <= 1e-6 * one.stderr)
    assert three.diagnostics.discretisation is not None and one.notes == three.notes[:-1]
    # a dynamic model's objective between starts is not evaluated: equal objectives never merge minima there
    assert np.isnan(ms.valley_tol) and all(m.connection == "" for m in ms.minima)


def michaelis_menten(lower=-np.inf):
    """y = Vm x / (K + x), Vm = 10, K = 20 seen at x = 0.5..4 only (seed 3: the fit from the truth runs off along
    Vm / K = const, tests/identification/fit/test_unbounded.py)."""
    model = Model.explicit(params=[Parameter("Vm", lower), Parameter("K", lower)], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="Michaelis-Menten")
    x = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    z = (10.0 * x / (20.0 + x))[None, :, None] + 0.1 * np.random.default_rng(3).standard_normal((2, x.size, 1))
    return model, Measurements(x[:, None], z, [0.1])


def test_a_start_that_runs_off_is_recorded_with_the_limit_of_its_objective():
    """Without bounds a start finds a finite minimum (Vm, K < 0: a pole beyond the data) below the run-off's limit."""
    model, data = michaelis_menten()
    one = identify(model, data, [10.0, 20.0])
    est = identify(model, data, [10.0, 20.0], starts=4)
    ms = est.diagnostics.starts
    assert not one.bounded and est.bounded and ms.outcome[0] == "not bounded" and ms.best != 0
    assert ms.objective[0] == one.unbounded.objective_limit and est.objective < one.unbounded.objective_limit - 0.5
    assert est.p[1] < -4.0                                        # the pole lies beyond the largest input
    assert f"the objective tends to {one.unbounded.objective_limit:.6g} as the parameters run off" in est.notes[-1]


def test_when_no_start_reaches_a_finite_minimum_the_first_run_off_is_returned():
    model, data = michaelis_menten(lower=0.0)
    one = identify(model, data, [10.0, 20.0])
    est = identify(model, data, [10.0, 20.0], starts=4)
    ms = est.diagnostics.starts
    assert not est.bounded and ms.minima == () and ms.outcome == ("not bounded",) * 4 and ms.best == 0
    assert np.array_equal(est.p, one.p)
    assert est.notes[-1].startswith("multi-start: none of the 4 starts reached a finite minimum")


def test_dask_gives_the_serial_estimate_and_table():
    """identify(..., starts=8) on a local Dask cluster (two worker processes) is the serial multi-start: the same
    estimate, covariance and note, the same per-start table and the same table of distinct minima."""
    distributed = pytest.importorskip("distributed")
    model, data = sinusoid()
    serial = identify(model, data, P0, starts=8)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cl, \
            distributed.Client(cl) as client:
        dk = identify(model, data, P0, starts=8, scheduler=client)
    a, b = serial.diagnostics.starts, dk.diagnostics.starts
    assert a.backend == "serial" and b.backend.startswith("dask (") and b.backend.endswith(", 2 workers)")
    assert a.best != 0 and len(a.minima) >= 2          # p0 misses the best minimum: the estimate is a worker's
    assert np.array_equal(serial.p, dk.p) and np.array_equal(serial.cov, dk.cov)
    assert serial.objective == dk.objective and serial.notes[:-1] == dk.notes[:-1]
    assert dk.notes[-1] == serial.notes[-1].replace("serial", b.backend)
    assert a.to_frame().equals(b.to_frame()) and a.minima_frame().equals(b.minima_frame())
    assert (a.best, a.reached_best, a.outcome, a.status) == (b.best, b.reached_best, b.outcome, b.status)


# ---------------------------------------------------------------------------- flat valleys
TRUSS_DATA = __file__.rsplit("/tests/", 1)[0] + "/data/truss_one_sensor/measurements_P_x.csv"


@pytest.fixture(scope="module")
def truss():
    """The README truss measured by P_x only (configs/truss_one_sensor.toml's data, um -> mm, sigma 4 um): from 8
    starts, 3 reach the best minimum and 5 run along k2 -> its upper bound 1e5, where P_x no longer depends on k2."""
    raw = np.loadtxt(TRUSS_DATA, delimiter=",", skiprows=1)
    data = Measurements(raw[:, :1], (raw[:, 1:].T / 1000.0)[:, :, None], [0.004])
    model = two_bar_truss(sensors=("P_x",))
    return model, data, identify(model, data, [200.0, 300.0]), identify(model, data, [200.0, 300.0], starts=8)


def test_starts_along_a_flat_valley_are_one_entry_with_ranges_and_a_note(truss):
    model, data, one, est = truss
    ms = est.diagnostics.starts
    assert np.array_equal(one.p, est.p) and np.array_equal(one.cov, est.cov) and ms.best == 0
    valley = [i for i in range(8) if ms.p[i, 1] > 9e4]
    assert len(valley) == 5 and len(ms.minima) == 2               # before: 4 "distinct" minima along the valley
    best, flat = ms.minima
    assert best.starts == (0, 4, 7) and not best.is_valley
    assert flat.starts == tuple(valley) and flat.flat == ("k2",) and flat.connection == "segment"
    assert flat.p_low[1] == ms.p[valley, 1].min() < 99500.0 and flat.p_high[1] == ms.p[valley, 1].max() > 99990.0
    assert flat.objective == ms.objective[valley].min() and flat.objective_high == ms.objective[valley].max()
    # the members differ by far more than the point rule allows, at objectives equal within the valley tolerance
    assert flat.p_high[1] - flat.p_low[1] > 1e3 * PARAMETER_TOL_SE * est.stderr[1]
    assert ms.valley_tol == min(ms.objective_tol, VALLEY_CHI2 / 2) and flat.objective_high - flat.objective <= ms.valley_tol
    assert flat.objective - best.objective > 3.0                 # a genuinely worse minimum, kept apart
    assert flat.valley.startswith("k2 is not determined by the data above 9.94e4: 5 starts ended along a flat "
                                  "valley from 9.94e4 to 1e5, which runs on to its upper bound 1e5")
    assert "no barrier at 5 points of the segment" in flat.valley and flat.valley in est.notes[-1]
    frame = ms.minima_frame()
    assert list(frame["flat"]) == ["", "k2"] and frame["k2 low"].iloc[1] == flat.p_low[1]
    assert ms.to_dict()["minima"][1]["flat"] == ["k2"]


def test_the_valley_objective_is_the_fits_objective(truss):
    """static_objective at each start's estimate is the objective its fit reported (the same Phi, paper eq. 3)."""
    model, data, _, est = truss
    ms = est.diagnostics.starts
    phi = static_objective(Problem(model, data), est.weights, est.sigma)
    for i in range(8):
        assert abs(phi(ms.p[i]) - ms.objective[i]) <= 1e-9 * ms.objective[i]


def test_equal_objectives_with_a_barrier_between_stay_apart():
    """y = a^2 x: a = +-sqrt(2) fit equally well (objectives equal to round-off), with a barrier at a = 0."""
    model = Model.explicit(params=[Parameter("a", -3.0, 3.0)], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] ** 2 * q[0], name="square")
    x = np.linspace(0.1, 1.0, 10)
    z = (2.0 * x)[None, :, None] + 0.01 * np.random.default_rng(1).standard_normal((1, x.size, 1))
    est = identify(model, Measurements(x[:, None], z, [0.01]), [1.0], starts=6)
    ms = est.diagnostics.starts
    assert len(ms.minima) == 2 and not any(m.is_valley for m in ms.minima)
    assert abs(ms.minima[0].objective - ms.minima[1].objective) <= ms.valley_tol
    assert ms.minima[0].p[0] == pytest.approx(-ms.minima[1].p[0], rel=1e-6)
    assert "the same objective at other parameters: the minimum is not unique" in est.notes[-1]


def _fits(points, objective):
    return [StartFit(index=i, outcome="minimum", p=np.array(p, float), objective=float(o), sigma0=1.0, status="ok",
                     error="", warnings=(), fit_time=0.0) for i, (p, o) in enumerate(zip(points, objective))]


def test_distinct_minima_merges_a_flat_direction_and_keeps_a_barrier():
    """Phi(p) = (p1 - 1)^2 + b(p2): flat in p2 when b = 0; with a bump b between p2 = 0 and 5 the points stay apart;
    without an objective (a dynamic model) the objectives alone merge them and the note says so."""
    points = [(1.0, 0.0), (1.0, 5.0), (1.0, 10.0), (3.0, 2.0)]
    obj = np.array([0.0, 1e-9, 2e-9, 4.0])
    fits, se = _fits(points, obj), np.array([0.1, 0.1])
    flat = distinct_minima(fits, obj, 1e-6, se, 0, vtol=1e-6, phi=lambda p: (p[0] - 1.0) ** 2, names=("p1", "p2"))
    assert [m.starts for m in flat] == [(0, 1, 2), (3,)] and flat[0].flat == ("p2",)
    assert flat[0].p_high[1] == 10.0 and flat[0].p_low[1] == 0.0 and flat[0].objective_high == 2e-9
    assert flat[0].valley.startswith("p2 is not determined by the data between 0 and 10: 3 starts ended along")
    assert "along it p1 stays at 1" in flat[0].valley
    bump = distinct_minima(fits, obj, 1e-6, se, 0, vtol=1e-6, names=("p1", "p2"),
                           phi=lambda p: (p[0] - 1.0) ** 2 + (0.5 if 1.0 < p[1] < 4.0 else 0.0))
    assert [m.starts for m in bump] == [(0,), (1, 2), (3,)] and bump[1].flat == ("p2",)
    blind = distinct_minima(fits, obj, 1e-6, se, 0, vtol=1e-6, phi=None, names=("p1", "p2"))
    assert [m.starts for m in blind] == [(0, 1, 2), (3,)] and blind[0].connection == "objective"
    assert "not evaluated (a dynamic model): merged by the objectives alone" in blind[0].valley
    # objectives that differ by more than the valley tolerance are never merged, flat or not
    far = distinct_minima(fits, np.array([0.0, 1e-5, 2e-5, 4.0]), 1e-4, se, 0, vtol=1e-6,
                          phi=lambda p: (p[0] - 1.0) ** 2, names=("p1", "p2"))
    assert [m.starts for m in far] == [(0,), (1,), (2,), (3,)]
