"""Benchmark (issue 31 items 1, 4): exact robust input designs through ``oed.select_inputs(prior=...)``.

Wall time of the whole verb (the information of every candidate at every prior vector and at p, the local exact
design, each vector's own optimum for maximin, the robust design) on: the batch reactor (mudoe.example_reactor)
choosing 2 of 4 candidate experiments over 3 parameter vectors; and y = a exp(-b t), a = 2, b = 0.8, sigma 0.1,
40 candidate t in [0.05, 5], choosing 5 (658,008 sets: branch-and-bound) with b ~ U(0.3, 2.5) (5 Gauss points),
bayes and maximin D.

Run: ``python -m bench.bench_robust_inputs``
"""
from __future__ import annotations

import platform
import time

import casadi as ca
import numpy as np


def main() -> None:
    """Print the machine, then one line per instance: the wall time and the design's summary."""
    from models import Model
    from oed import select_inputs
    from mudoe.example_reactor import P_TRUE, TIMES, build
    print(platform.platform(), platform.python_version(), time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0], [1.5, 340.0]])
    P = np.array([P_TRUE, P_TRUE * [1, 0.95, 1, 1], P_TRUE * [1, 1.05, 1, 1.05]])
    t0 = time.perf_counter()
    r = select_inputs(m, P_TRUE, candidates=Q, sigma=np.array([0.01, 0.008]), n_points=2, times=TIMES,
                      prior=(P, [0.5, 0.25, 0.25]))
    print(f"reactor, 2 of 4 experiments, 3 vectors: {time.perf_counter() - t0:.2f} s; {r.summary()}")
    e = Model.explicit(["a", "b"], ["t"], ["y"], h=lambda p, q: p[0] * ca.exp(-p[1] * q[0]))
    T = np.linspace(0.05, 5.0, 40)[:, None]
    for rb in ("bayes", "maximin"):
        t0 = time.perf_counter()
        r = select_inputs(e, [2.0, 0.8], candidates=T, sigma=0.1, n_points=5, prior={"b": ("uniform", 0.3, 2.5)},
                          robust=rb)
        print(f"exponential, 5 of 40, 5 vectors, {rb}: {time.perf_counter() - t0:.2f} s; {r.summary()}")


if __name__ == "__main__":
    main()
