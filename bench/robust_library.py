"""Benchmark parts of issue 31's library leftovers (session 12), run by ``python -m bench robust`` (all) or
``python -m bench robust --library`` (these only):

* sparse grids (``make_prior(rule="sparse")``) against the tensor Gauss rule: the expected log det of a fixed design of
  the compartmental model under priors on 2 and 3 parameters, and of the reactor's exact 4-time design under
  E1, E2 ~ U; points, value, the level l vs l+1 error estimate, and the wall time of the whole evaluation (the
  information at every point by ``oed.information``, CasADi);
* sequential designs under a prior (``sequential_design(prior=, robust=)``) on the press (the paper's case, k5, k7)
  and the exponential-decay sensors of tests/oed/test_sequential_robust.py: chosen sets, estimates, the worst-case
  efficiency of each step's choice against the local choice at the same point, wall time;
* the refinement of exact robust designs (``select_inputs/select_times(prior=, refine=True)``): exact and refined
  criterion, the efficiency of each against the approximate robust design, wall time.
"""
from __future__ import annotations

import time

import numpy as np

P0 = np.array([0.05884, 4.298, 21.80])
T_LOCAL = np.array([0.2288, 1.3886, 18.4168])


def _clock(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _compartmental_eld(model):
    """f(P) = log det of the textbook local D design's information per run at every row of P (oed.information)."""
    from oed import information

    def f(P):
        return np.array([np.linalg.slogdet(information(model, p, axis="inputs", candidates=T_LOCAL[:, None],
                                                       sigma=1.0).F.mean(axis=0))[1] for p in P])
    return f


def _rule_line(label, prior, f):
    """Value, error estimate (level/order + 1) and the time of both evaluations of one rule."""
    (v, e), t = _clock(lambda: (prior.mean(f(prior.points)), prior.error(f)))
    nxt = prior.next_rule().n
    print(f"  {label}: {prior.n} points (+ {nxt} for the error), E log det {v:.10f}, error estimate {e:.1e}, "
          f"{t:.2f} s", flush=True)
    return v, e


def sparse_grids(model):
    """Sparse against tensor rules on the compartmental model (2 and 3 uncertain parameters, a narrow and a wide
    prior) and the reactor (E1, E2)."""
    from oed import make_prior
    f = _compartmental_eld(model)
    names = ("theta1", "theta2", "theta3")
    cases = [("2 parameters, theta2 +- 1", {"theta1": ("uniform", 0.04884, 0.06884),
                                            "theta2": ("uniform", 3.298, 5.298)}),
             ("3 parameters, theta2 +- 1, theta3 +- 2", {"theta1": ("uniform", 0.04884, 0.06884),
                                                         "theta2": ("uniform", 3.298, 5.298),
                                                         "theta3": ("uniform", 19.8, 23.8)}),
             ("3 parameters: lognormal, truncnormal, normal", {"theta1": ("lognormal", 0.05884, 0.1),
                                                              "theta2": ("truncnormal", 4.298, 1.0, 3.0, 6.0),
                                                              "theta3": ("normal", 21.8, 1.0)}),
             ("2 parameters, theta2 +- 4 (wide)", {"theta1": ("uniform", 0.04884, 0.06884),
                                                   "theta2": ("uniform", 0.298, 8.298)})]
    for label, prior in cases:
        print(f"compartmental, {label}: the textbook local D design t = {T_LOCAL.tolist()}", flush=True)
        v_t, e_t = _rule_line("tensor Gauss 20 per parameter", make_prior(prior, names, P0, order=20), f)
        for level in (3, 4, 5, 6, 8, 10):
            v, e = _rule_line(f"sparse level {level}", make_prior(prior, names, P0, rule="sparse", order=level), f)
            print(f"    sparse - tensor = {v - v_t:.1e} (|.| / (estimate + tensor estimate) = "
                  f"{abs(v - v_t) / (e + e_t):.2f})", flush=True)
    _sparse_reactor()


def _sparse_reactor():
    from mudoe.example_reactor import P_TRUE, build
    from oed import information, make_prior
    m = build()
    Q, sigma = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]]), np.array([0.01, 0.008])
    times = np.array([0.2, 0.4, 0.6, 2.0])          # the exact Bayesian 4-time design of configs/reactor.toml's grid

    def f(P):
        return np.array([np.linalg.slogdet(information(m, p, axis="times", times=times, inputs=Q,
                                                       sigma=sigma).F.mean(axis=0))[1] for p in P])
    prior = {"E1": ("uniform", 45.0, 75.0), "E2": ("uniform", 65.0, 95.0)}
    print(f"reactor, E1 ~ U(45, 75), E2 ~ U(65, 95), times {times.tolist()}, 3 experiments", flush=True)
    v_t, e_t = _rule_line("tensor Gauss 8 x 8", make_prior(prior, build(), P_TRUE, order=8), f)
    for level in (3, 4, 5):
        v, e = _rule_line(f"sparse level {level}", make_prior(prior, m, P_TRUE, rule="sparse", order=level), f)
        print(f"    sparse - tensor = {v - v_t:.1e}", flush=True)


def sequential():
    """Sequential designs under a prior: press (paper, E, 2 of 3 sensors) and the decay sensors (D, 2 of 7)."""
    import casadi as ca
    from identification import Measurements, simulate
    from models import Model
    from models.press import press_model
    from oed.sequential import sequential_design
    press = press_model()
    sig = np.array([15.18e-3, 4.895e-3, 3.904e-3])
    q = np.concatenate([np.linspace(0, 1600, 15), np.linspace(1600, 0, 15)[1:]])[:, None]
    H = simulate(press, [560.0, 430.0], q)
    rng = np.random.default_rng(3)
    exps = [Measurements(q, H[None] + sig * rng.standard_normal((2,) + H.shape), sig, sensors=press.sensors)
            for _ in range(3)]
    _sequential_case("press (3 sensors, E, 2 chosen), k5, k7 ~ U(+-100) around the estimate", press, exps,
                     [500.0, 500.0], {"k5": ("uniform", 400.0, 600.0), "k7": ("uniform", 400.0, 600.0)}, "E", 2)
    T = [0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0]
    m = Model.explicit(["a", "b"], ["q"], [f"y{t:g}" for t in T],
                       h=lambda p, qq: ca.vertcat(*[qq[0] * p[0] * ca.exp(-p[1] * t) for t in T]), name="decay")
    qd, sd = np.array([[1.0], [2.0]]), np.full(len(T), 0.02)
    Hd = simulate(m, [2.0, 1.3], qd)
    rng = np.random.default_rng(0)
    exd = [Measurements(qd, Hd[None] + sd * rng.standard_normal((2,) + Hd.shape), sd, sensors=m.sensors)
           for _ in range(3)]
    _sequential_case("decay (7 sensors, D, 2 chosen), b ~ U(0.2, 2.0) at p0 = (2, 0.6)", m, exd, [2.0, 0.6],
                     {"b": ("uniform", 0.2, 2.0)}, "D", 2)


def _sequential_case(label, model, exps, p0, prior, crit, n):
    from oed.sequential import sequential_design
    print(label, flush=True)
    loc, t = _clock(lambda: sequential_design(model, exps, p0, criterion=crit, n_sensors=n))
    print(f"  local: {[list(c) for c in loc.chosen]}, final estimate {np.round(loc.steps[-1].p, 4).tolist()} "
          f"+- {np.round(loc.steps[-1].stderr, 4).tolist()}, {t:.2f} s", flush=True)
    for robust in ("bayes", "maximin"):
        r, t = _clock(lambda: sequential_design(model, exps, p0, criterion=crit, n_sensors=n, prior=prior,
                                                robust=robust))
        worst = []
        data = exps[0]
        for k, s in enumerate(r.steps):       # the local choice at the same point, against the same prior vectors
            local = sequential_design(model, [exps[k]], s.p_design, initial=data, criterion=crit, n_sensors=n)
            worst.append(_worst_case(model, data, s, local.steps[0].design.indices, crit, n))
            data = exps[k]
        print(f"  {robust}: {[list(c) for c in r.chosen]}, final estimate {np.round(r.steps[-1].p, 4).tolist()} +- "
              f"{np.round(r.steps[-1].stderr, 4).tolist()}; worst-case efficiency per step robust "
              f"{[round(s.robust.worst_case_efficiency, 4) for s in r.steps]} vs local choice "
              f"{[round(w, 4) for w in worst]}; {t:.2f} s", flush=True)


def _worst_case(model, data, step, indices, crit, n):
    """Worst-case efficiency (against each vector's own best n-set) of the set ``indices`` over the step's prior."""
    from oed import information
    from oed.robust_exact import select_robust_exact
    P = np.asarray(step.robust.prior.points)
    F = np.stack([information(model, ps, data=data).F for ps in P], axis=1)
    own = np.array([select_robust_exact(F[:, [s]], [1.0], n, criterion=crit).value for s in range(P.shape[0])])
    u = select_robust_exact(F[list(indices)], np.full(P.shape[0], 1.0 / P.shape[0]), n, criterion=crit).per_sample
    return float(np.min(np.exp((u - own) / F.shape[-1]) if crit == "D" else own / u))


def refined():
    """Refinement of exact robust designs: exponential inputs (3 of 8) and the reactor's sampling times (4 of 10)."""
    import casadi as ca
    from mudoe.example_reactor import P_TRUE, build
    from models import Model
    from oed import select_inputs, select_times
    from oed.approximate import ApproximateSettings
    T = np.array([0.1, 0.3, 0.6, 1.0, 1.5, 2.2, 3.0, 4.5])
    m = Model.explicit(["a", "b"], ["t"], ["y"], h=lambda p, q: p[0] * ca.exp(-p[1] * q[0]))
    for robust in ("bayes", "maximin"):
        for crit in "DAE":
            r, t = _clock(lambda: select_inputs(m, np.array([2.0, 0.8]), candidates=T[:, None], sigma=0.1, n_points=3,
                                                prior={"b": ("uniform", 0.3, 2.5)}, robust=robust, criterion=crit,
                                                refine=True))
            _refined_line(f"y = a exp(-b t), 3 of 8 inputs, b ~ U(0.3, 2.5) (5 Gauss), {robust} {crit}", r, t, 2)
    mr = build()
    Q, sigma = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]]), np.array([0.01, 0.008])
    for robust in ("bayes", "maximin"):
        r, t = _clock(lambda: select_times(mr, P_TRUE, np.linspace(0.2, 2.0, 10), Q, sigma, n_times=4,
                                           prior={"E1": ("uniform", 55.0, 65.0), "E2": ("uniform", 75.0, 85.0)},
                                           robust=robust, refine=True,
                                           approx_settings=ApproximateSettings(grid=41, rounds=6)))
        _refined_line(f"reactor, 4 of 10 times on [0.2, 2], E1, E2 ~ U (5 x 5), {robust} D", r, t, 4)


def _refined_line(label, r, t, n_p):
    """One line: the exact and refined designs, their criteria and efficiencies against the approximate design."""
    f = r.refined
    if r.robust == "maximin":
        exact_eff = r.efficiency / f.approximate_value
    elif r.criterion == "D":
        exact_eff = float(np.exp((f.start_value - f.approximate_value) / n_p))
    else:
        exact_eff = f.approximate_value / f.start_value
    print(f"{label}: exact {list(r.names)} value {f.start_value:.9g} -> refined t = "
          f"{np.round(f.points[:, 0], 5).tolist()} value {f.value:.9g}"
          + (f", worst-case efficiency {r.efficiency:.6f} -> {f.worst_case_efficiency:.6f}" if r.robust == "maximin"
             else "")
          + f"; efficiency against the approximate design: exact {exact_eff:.6f}, refined "
          f"{f.approximate_efficiency:.6f} (its gap {f.approximate_gap:.1e}); refinement {f.wall_time:.2f} s, whole "
          f"verb {t:.2f} s", flush=True)
