"""Benchmark (issue 22): identification of dynamic models, mudoe and the scipy peers in one run.

* ``reactor``: bench.dynamic_reference's batch reactor (A -> B -> C, Arrhenius in the
  reference-temperature form, inputs cA0 and T, sensors cA and cB, sigma 0.01), 20 experiments x
  30 samples, seed 0, start (0.7, 0.7, 50, 60).  mudoe: the same model as ``Model.ode``, fitted by
  ``identify`` (collocation with discretisation error control), first fit on a fresh model and
  ``--rep`` repeated fits; scipy ``least_squares`` over ``solve_ivp`` (rtol 1e-8) in its three
  variants (2-point Jacobian, exact sensitivity Jacobian per experiment, all experiments stacked);
  every estimate against the rtol 1e-10 reference in standard errors.
* ``scale``: 200 experiments x 100 samples of the same reactor with a fourth state (the extent
  of reaction, not measured), seed 1: one ``identify`` (wall and CPU seconds).
* ``montecarlo``: the reactor's detection study (mudoe.example_reactor, 6 experiments x 10
  samples, two series, one split by experiment) as ``size_study`` on ``est.model`` with
  ``--n-rep`` replications on ``--workers`` processes.

Run: ``python -m bench dynamic_fit [--rep=5] [--n-rep=1000] [--workers=2] [--parts=reactor,scale,montecarlo]``;
prints one JSON document.
"""
from __future__ import annotations

import json
import os
import platform
import resource
import statistics
import sys
import time

import casadi as ca
import numpy as np

from bench import dynamic_reference as dr

R_KJ = 8.314e-3


def reactor_model(extent: bool = False):
    """bench.dynamic_reference.batch_reactor as a mudoe Model.ode (parameters k1ref, k2ref, E1, E2);
    ``extent``: a fourth state, the extent of both reactions (dxi/dt = k1 cA + k2 cB), not measured."""
    from models import Model
    from models.contract import Parameter

    def k(p, T, i):
        return p[i] * ca.exp(-p[2 + i] / R_KJ * (1.0 / T - 1.0 / 350.0))

    def rhs(x, p, u):
        k1, k2 = k(p, u[1], 0), k(p, u[1], 1)
        f = [-k1 * x[0], k1 * x[0] - k2 * x[1], k2 * x[1]]
        return ca.vertcat(*(f + [k1 * x[0] + k2 * x[1]] if extent else f))

    params = [Parameter("k1ref", 1e-6, 100.0, scale=1.0), Parameter("k2ref", 1e-6, 100.0, scale=1.0),
              Parameter("E1", 0.0, 300.0, scale=50.0), Parameter("E2", 0.0, 300.0, scale=50.0)]
    states = ["cA", "cB", "cC"] + (["xi"] if extent else [])
    return Model.ode(params, states=states, inputs=["cA0", "T"], sensors=["cA", "cB"], rhs=rhs,
                     x0=lambda p, u: ca.vertcat(u[0], *([0.0] * (len(states) - 1))), h=lambda x, p, u: x[:2],
                     horizon=5.0, name="batch reactor (bench)")


def _measurements(d):
    from identification import DynamicMeasurements
    return DynamicMeasurements(d.inputs, d.times, d.z[None], d.sigma, sensors=["cA", "cB"])


def _timed(f):
    t0, c0 = time.perf_counter(), time.process_time()
    out = f()
    return out, time.perf_counter() - t0, time.process_time() - c0


def _stats(v):
    return {"median": statistics.median(v), "min": min(v), "max": max(v)}


def reactor(rep: int = 5, n_exp: int = 20, n_times: int = 30, seed: int = 0):
    """mudoe's identify and the three scipy variants on the reactor, alternating, ``rep`` fits each."""
    from identification import identify
    ex = dr.batch_reactor()
    d = dr.simulate_data(ex, n_exp, n_times, seed=seed)
    ref = dr.reference_fit(ex, d, rtol=1e-10, jac="sens", stacked=True)
    data = _measurements(d)
    est, w, c = _timed(lambda: identify(reactor_model(), data, ex.p_start))
    out = {"n_exp": n_exp, "n_times": n_times, "seed": seed, "reference_p": ref.p.tolist(), "reference_se": ref.se.tolist(),
           "mudoe_first": {"wall_s": w, "cpu_s": c, "dev_se": ((est.p - ref.p) / ref.se).tolist(),
                           "solver": est.diagnostics.solver,
                           "mesh": est.diagnostics.discretisation.history}}
    model = reactor_model()
    identify(model, data, ex.p_start)
    variants = {"2-point": {"jac": "2-point"}, "sens": {"jac": "sens"}, "sens_stacked": {"jac": "sens", "stacked": True}}
    times = {k: ([], []) for k in ["mudoe"] + list(variants)}
    dev = {}
    for _ in range(rep):
        est, w, c = _timed(lambda: identify(model, data, ex.p_start))
        times["mudoe"][0].append(w)
        times["mudoe"][1].append(c)
        dev["mudoe"] = float(np.max(np.abs((est.p - ref.p) / ref.se)))
        for name, kw in variants.items():
            fit = dr.reference_fit(ex, d, rtol=1e-8, **kw)
            times[name][0].append(fit.fit_seconds)
            times[name][1].append(fit.fit_cpu_seconds)
            dev[name] = float(np.max(np.abs((fit.p - ref.p) / ref.se)))
    m_cpu = statistics.median(times["mudoe"][1])
    for name, (w, c) in times.items():
        out[name] = {"wall_s": _stats(w), "cpu_s": _stats(c), "max_abs_dev_from_reference_se": dev[name],
                     "cpu_ratio_to_mudoe": statistics.median(c) / m_cpu}
    return out


def scale(n_exp: int = 200, n_times: int = 100, seed: int = 1):
    """One identify of the four-state reactor on n_exp x n_times samples."""
    from identification import identify
    ex = dr.batch_reactor()
    d = dr.simulate_data(ex, n_exp, n_times, seed=seed)
    est, w, c = _timed(lambda: identify(reactor_model(extent=True), _measurements(d), ex.p_start))
    rec = est.diagnostics.discretisation
    return {"n_exp": n_exp, "n_times": n_times, "n_states": 4, "wall_s": w, "cpu_s": c,
            "n_y_per_experiment": est.model.n_y, "solver": est.diagnostics.solver, "mesh_history": rec.history,
            "bounded": rec.bounded, "truth_minus_p_in_se": ((d.p_true - est.p) / est.stderr).tolist(),
            "timing": {k: v[0] for k, v in (est.diagnostics.timing or {}).items()}}


def montecarlo(n_rep: int = 1000, workers: int = 2, seed: int = 0):
    """size_study of the reactor's detection study on est.model (2 series, split by experiment)."""
    from identification import DynamicMeasurements, Split, identify
    from identification.studies.montecarlo import MonteCarloSettings, size_study
    from mudoe.example_reactor import P_TRUE, TIMES, build
    Q = np.array([[1.0, 330.0], [1.0, 340.0], [1.0, 350.0], [2.0, 350.0], [2.0, 360.0], [2.0, 370.0]])
    sigma = np.array([0.01, 0.008])
    from identification.fit.dynamic_fit import simulate_campaign
    data = simulate_campaign(build(), P_TRUE, Q, TIMES, sigma, n_series=2, seed=seed)
    est = identify(build(), data, P_TRUE)
    split = Split("early vs late experiments", [0, 2, 4], [1, 3, 5])
    settings = MonteCarloSettings(n_rep=n_rep, seed=seed, workers=workers)
    ch0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    res, w, c = _timed(lambda: size_study(est.model, est.p, Q, est.data.sigma, [split], n_series=2, settings=settings))
    ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    children = (ch1.ru_utime + ch1.ru_stime) - (ch0.ru_utime + ch0.ru_stime)
    return {"n_rep": n_rep, "workers": workers, "wall_s": w, "cpu_s_parent": c, "cpu_s_workers": children,
            "n_y": est.model.n_y,
            "rejection_rate": str(res.rejection_rate()), "gate_failure_rate": str(res.gate_failure_rate()),
            "coverage": str(res.coverage()), "table": res.summary()}


def _machine():
    return {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "platform": platform.platform(),
            "nproc": os.cpu_count(), "loadavg": os.getloadavg()}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    opts = dict(a[2:].split("=", 1) for a in argv if a.startswith("--") and "=" in a)
    parts = opts.get("parts", "reactor,scale,montecarlo").split(",")
    out = {"machine_before": _machine()}
    if "reactor" in parts:
        out["reactor_20x30"] = reactor(int(opts.get("rep", 5)))
    if "scale" in parts:
        out["scale_200x100x4"] = scale()
    if "montecarlo" in parts:
        out["montecarlo"] = montecarlo(int(opts.get("n-rep", 1000)), int(opts.get("workers", 2)))
    out["machine_after"] = _machine()
    print(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
