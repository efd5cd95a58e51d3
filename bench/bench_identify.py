"""Benchmark (issue 2): full-space Ipopt identification vs reduced-space scipy least_squares.

Model: the hardening spring chain (models.library.spring_chain) with d_y states, n_q load
cases, 4 or 12 displacement sensors, 2 series, 1 % noise.  All methods start from the same p0
and must reach the same optimum; time includes the covariance (second-order for mudoe,
Gauss-Newton from the final Jacobian for the peers).  The model's own CasADi functions (E and
its derivatives, built by ``simulate`` when the data are generated) exist before any timing, for
mudoe and the peers alike.

Peers: scipy.optimize.least_squares(method="trf", x_scale="jac", tolerances 1e-12) on p, each
residual evaluation solving E(y, p, q_j) = 0 by mudoe's own sparse exact-Jacobian Newton:

* "FD": Jacobian by scipy's default 2-point finite differences, the inner Newton started from
  the model's guess at every evaluation (what a typical residual function does);
* "FD+ws": the same with the inner Newton warm-started from the previous evaluation's states
  (what a careful user does: about half the inner iterations);
* "IFT+ws": the exact Jacobian by the implicit function theorem (mudoe's sensitivities, a peer a
  typical user does not have), warm-started inner Newton.

Sizes: d_y = 30, 300, 3000 with n_p = 2 (k, c) and n_p = 11 (ten stiffness groups and c).
"cold" is the first identification of a problem (building mudoe's NLP stage functions and the
Ipopt solver included; a fresh model each repetition), "warm" a second one with new noise
(cached solver: the Monte Carlo and split use case).  Every time is the median of ``--rep``
repetitions (default 3).
Run: ``python -m bench identify`` (or ``make bench``); options ``--quick`` (skip d_y = 3000),
``--rep=K``.
"""
from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np
from scipy.optimize import least_squares

from identification import Measurements, identify, simulate, solve_states
from models.sensitivity import sensitivities
from models.library import spring_chain


def _problem(n_y, n_q, seed=0, n_groups=1):
    model = spring_chain(n_y, n_sensors=max(4, n_groups + 2), n_groups=n_groups)
    p_true = np.concatenate([2.0 + 0.2 * np.arange(n_groups), [0.5]])
    Q = np.array([[f, 0.3 * f] for f in np.linspace(0.2, 3.0, n_q)])
    H = simulate(model, p_true, Q)
    sig = 0.01 * np.abs(H).max(axis=0)
    z = H[None] + sig * np.random.default_rng(seed).standard_normal((2,) + H.shape)
    return model, Measurements(Q, z, sig, sensors=model.sensors)


def _reduced(model, data, p0, exact_jac, warm_inner):
    mask = data.mask()
    cache = {}

    def states(p):
        key = tuple(p)
        if key not in cache:
            last = cache.get("last") if warm_inner else None
            cache.clear()
            cache[key] = cache["last"] = solve_states(model, p, data.inputs, Y0=last)
        return cache[key]

    def fun(p):
        Y = states(p)
        H = simulate(model, p, data.inputs, Y=Y)
        return ((data.z - H[None]) / data.sigma)[mask]

    def jac(p):
        G = sensitivities(model, p, data.inputs, states(p)).G          # (n_q, n_S, n_p)
        Jfull = -np.broadcast_to(G[None] / data.sigma[None, None, :, None], data.z.shape + (model.n_p,))
        return Jfull[mask]

    t = time.perf_counter()
    res = least_squares(fun, p0, jac=jac if exact_jac else "2-point", method="trf", x_scale="jac",
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    J = res.jac
    cov = np.linalg.inv(J.T @ J)
    return time.perf_counter() - t, res.x, cov, res.nfev


def _median_time(fn, rep):
    times, out = [], None
    for _ in range(rep):
        t, out = fn()
        times.append(t)
    return float(np.median(times)), out


def main(argv=None):
    argv = argv or []
    rep = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--rep=")), 3)
    sizes = [(30, 5, 1), (300, 5, 1), (3000, 5, 1), (300, 10, 1), (300, 20, 1),
             (30, 5, 10), (300, 5, 10), (3000, 5, 10)]
    if "--quick" in argv:
        sizes = [s for s in sizes if s[0] < 3000]
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {sys.version.split()[0]}, median of {rep}")
    print("| d_y | n_q | n_p | full cold s | full warm s | FD s | FD+ws s | IFT+ws s | FD/cold | FD/warm "
          "| FD+ws/cold | FD+ws/warm | IFT+ws/cold | IFT+ws/warm | max rel dp |")
    print("|" + "---|" * 15)
    rows = []
    for n_y, n_q, n_groups in sizes:
        p0 = np.concatenate([np.ones(n_groups), [0.1]])

        def cold():
            model, data = _problem(n_y, n_q, n_groups=n_groups)      # a fresh model: nothing cached
            t = time.perf_counter()
            est = identify(model, data, p0)
            return time.perf_counter() - t, (model, data, est)

        t_cold, (model, data, est) = _median_time(cold, rep)
        seeds = iter(range(1, rep + 1))

        def warm():
            _, data_new = _problem(n_y, n_q, seed=next(seeds), n_groups=n_groups)   # new noise
            t = time.perf_counter()
            identify(model, data_new, p0)
            return time.perf_counter() - t, None

        t_warm, _ = _median_time(warm, rep)
        peers = {}
        for name, exact, ws in (("fd", False, False), ("fdws", False, True), ("iftws", True, True)):
            t_peer, (p_peer, *_rest) = _median_time(
                lambda: (lambda r: (r[0], r[1:]))(_reduced(model, data, p0, exact_jac=exact, warm_inner=ws)), rep)
            peers[name] = (t_peer, p_peer)
        dp = max(np.max(np.abs(pp - est.p) / np.abs(est.p)) for _, pp in peers.values())
        t_fd, t_fdws, t_ift = (peers[k][0] for k in ("fd", "fdws", "iftws"))
        rows.append((n_y, n_q, model.n_p, t_cold, t_warm, t_fd, t_fdws, t_ift))
        print(f"| {n_y} | {n_q} | {model.n_p} | {t_cold:.3f} | {t_warm:.3f} | {t_fd:.3f} | {t_fdws:.3f} | "
              f"{t_ift:.3f} | {t_fd / t_cold:.1f} | {t_fd / t_warm:.1f} | {t_fdws / t_cold:.1f} | "
              f"{t_fdws / t_warm:.1f} | {t_ift / t_cold:.1f} | {t_ift / t_warm:.1f} | {dp:.1e} |", flush=True)
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
