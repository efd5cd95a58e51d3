"""Benchmark (issue 2): full-space Ipopt identification vs reduced-space scipy least_squares.

Model: the hardening spring chain (models.library.spring_chain) with d_y states, n_q load
cases, 4 displacement sensors, 2 series, 1 % noise.  Both methods start from the same p0 and
must reach the same optimum; time includes the covariance (second-order for mudoe, Gauss-Newton
from the final Jacobian for the peer).

Peer ("reduced"): scipy.optimize.least_squares(method="trf", x_scale="jac") on p, each residual
evaluation solving E(y, p, q_j) = 0 by the same sparse exact-Jacobian Newton as mudoe; its
Jacobian by scipy's default 2-point finite differences (what a typical user writes).
A second peer variant ("reduced+IFT") gets the exact Jacobian from the implicit function theorem.

Sizes: d_y = 30, 300, 3000 with n_p = 2 (k, c) and n_p = 11 (ten stiffness groups and c).
"cold" is the first identification of a problem (building and compiling the NLP included),
"warm" a second one with new noise (cached solver: the Monte Carlo / split use case).
Run: ``python -m bench identify`` (or ``make bench``); options ``--quick`` (skip d_y = 3000).
"""
from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np
from scipy.optimize import least_squares

from identification import Measurements, identify, simulate, solve_states
from identification.sensitivity import sensitivities
from models.library import spring_chain


def _problem(n_y, n_q, seed=0, n_groups=1):
    model = spring_chain(n_y, n_sensors=max(4, n_groups + 2), n_groups=n_groups)
    p_true = np.concatenate([2.0 + 0.2 * np.arange(n_groups), [0.5]])
    Q = np.array([[f, 0.3 * f] for f in np.linspace(0.2, 3.0, n_q)])
    H = simulate(model, p_true, Q)
    sig = 0.01 * np.abs(H).max(axis=0)
    z = H[None] + sig * np.random.default_rng(seed).standard_normal((2,) + H.shape)
    return model, Measurements(Q, z, sig, sensors=model.sensors)


def _reduced(model, data, p0, exact_jac):
    mask = data.mask()
    cache = {}

    def states(p):
        key = tuple(p)
        if key not in cache:
            cache.clear()
            cache[key] = solve_states(model, p, data.inputs, Y0=cache.get("last"))
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


def main(argv=None):
    argv = argv or []
    sizes = [(30, 5, 1), (300, 5, 1), (3000, 5, 1), (300, 10, 1), (300, 20, 1),
             (30, 5, 10), (300, 5, 10), (3000, 5, 10)]
    if "--quick" in argv:
        sizes = [s for s in sizes if s[0] < 3000]
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, python {sys.version.split()[0]}")
    print(f"{'d_y':>5} {'n_q':>4} {'n_p':>4} {'full cold s':>11} {'full warm s':>11} {'reduced FD s':>12} "
          f"{'reduced IFT s':>13} {'FD/cold':>8} {'FD/warm':>8} {'IFT/cold':>8} {'IFT/warm':>8} {'max rel dp':>10}")
    rows = []
    for n_y, n_q, n_groups in sizes:
        model, data = _problem(n_y, n_q, n_groups=n_groups)
        p0 = np.concatenate([np.ones(n_groups), [0.1]])
        t = time.perf_counter()
        est = identify(model, data, p0)
        t_cold = time.perf_counter() - t
        _, data_new = _problem(n_y, n_q, seed=1, n_groups=n_groups)   # new noise: the warm case
        t = time.perf_counter()
        identify(model, data_new, p0)
        t_warm = time.perf_counter() - t
        t_fd, p_fd, _, _ = _reduced(model, data, p0, exact_jac=False)
        t_ift, p_ift, _, _ = _reduced(model, data, p0, exact_jac=True)
        dp = max(np.max(np.abs(p_fd - est.p) / np.abs(est.p)), np.max(np.abs(p_ift - est.p) / np.abs(est.p)))
        rows.append((n_y, n_q, model.n_p, t_cold, t_warm, t_fd, t_ift))
        print(f"{n_y:>5} {n_q:>4} {model.n_p:>4} {t_cold:>11.3f} {t_warm:>11.3f} {t_fd:>12.3f} {t_ift:>13.3f} "
              f"{t_fd / t_cold:>8.1f} {t_fd / t_warm:>8.1f} {t_ift / t_cold:>8.1f} {t_ift / t_warm:>8.1f} "
              f"{dp:>10.1e}", flush=True)
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
