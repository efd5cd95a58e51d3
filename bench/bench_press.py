"""Timing of a full 29-load quasi-static solve of the press model (issue 3).

Solves E(y, p, q_j) = 0 (34 states, N / N mm) for the paper's 29 process forces
(15 loading steps 0..1600 N, 14 unloading steps back to 0 N) in sequence, each
Newton solve started from the previous state.  Two solvers are timed:

* ``rootfinder``: CasADi ``rootfinder('newton')`` (exact SX Jacobian, dense LU
  "csparse" linear solver) wrapped in ``mapaccum`` so the whole continuation is one
  CasADi call (setup excluded from the timing);
* ``python``: :func:`models.mechanism.solve_path`, the project's state solver
  (:func:`models.state.solve_state`: damped Newton in Python with a CasADi
  function for (E, dE/dy) and a dense LU) row by row.

Run ``python -m bench press`` (``--repeat=N`` sets the number of timed repetitions).
"""
from __future__ import annotations

import argparse
import time

import casadi as ca
import numpy as np

from models.mechanism import solve_path
from models.press import press_model

Q_PAPER = np.r_[np.linspace(0.0, 1600.0, 15), np.linspace(1600.0, 0.0, 15)[1:]]


def path_solver(model, n_q: int, tol: float = 1e-12):
    """CasADi function (y0, p, Q[1 x n_q]) -> Y[n_y x n_q] by rootfinder 'newton' + mapaccum."""
    y = ca.SX.sym("y", model.n_y)
    pq = ca.SX.sym("pq", model.n_p + model.n_q_dim)
    res = ca.Function("res", [y, pq], [model.E_fun(y, pq[:model.n_p], pq[model.n_p:])])
    rf = ca.rootfinder("rf", "newton", res, {"abstol": tol * 1e3, "abstolStep": tol, "max_iter": 50,
                                             "linear_solver": "csparse", "error_on_fail": True})
    acc = rf.mapaccum("path", n_q)
    p = ca.MX.sym("p", model.n_p)
    Q = ca.MX.sym("Q", model.n_q_dim, n_q)
    y0 = ca.MX.sym("y0", model.n_y)
    Y = acc(y0, ca.vertcat(ca.repmat(p, 1, n_q), Q))
    return ca.Function("press_path", [y0, p, Q], [Y])


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench press")
    ap.add_argument("--repeat", type=int, default=50, help="timed repetitions (write --repeat=N under python -m bench)")
    args = ap.parse_args(argv or [])
    model = press_model()
    p = model.p_nominal
    Q = Q_PAPER[None, :]
    t0 = time.perf_counter()
    f = path_solver(model, Q.shape[1])
    t_setup = time.perf_counter() - t0
    Y = np.array(f(np.zeros(model.n_y), p, Q))
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        Y = np.array(f(np.zeros(model.n_y), p, Q))
        times.append(time.perf_counter() - t0)
    E = np.array([np.array(model.E_fun(Y[:, j], p, Q[:, j])).ravel() for j in range(Q.shape[1])])
    print(f"press model: n_y = {model.n_y}, {Q.shape[1]} loads, setup {t_setup * 1e3:.1f} ms")
    print(f"rootfinder newton + mapaccum: median {np.median(times) * 1e3:.2f} ms, min {min(times) * 1e3:.2f} ms "
          f"(max |E| = {np.abs(E).max():.1e} N)")
    times2 = []
    for _ in range(max(1, args.repeat // 5)):
        t0 = time.perf_counter()
        Y2 = solve_path(model, p, Q.T)
        times2.append(time.perf_counter() - t0)
    print(f"python Newton (solve_path):  median {np.median(times2) * 1e3:.2f} ms, "
          f"max |dy| vs rootfinder {np.abs(Y2 - Y.T).max():.1e} mm")
    h = np.array(model.h_fun(Y[:, 14], p, Q[:, 14])).ravel()
    print("at q_P = 1600 N: " + ", ".join(f"{s} = {v * 1e3:.1f} um" for s, v in zip(model.sensors, h)))


if __name__ == "__main__":
    main()
