"""Designs before data (issue 13): the second-order frontier of method='auto' and the input-design frontier.

``python -m bench planning`` prints, for seeded random second-order instances (rank-2 F_k, indefinite
S_k of 5 % of ||F_k||), the method auto chose, whether it proved optimality and the wall time (time
limit 60 s); then exact input designs (D, candidates x sensors of an exponential model) by auto,
with and without the joint sensor choice, and their continuous refinement.
"""
from __future__ import annotations

import time
from math import comb

import casadi as ca
import numpy as np

from models import Model
from oed import select_sensors_from_information
from oed.inputs import RefineSettings, select_inputs


def _instance(seed, n, p):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, 2, p))
    F = np.einsum("kri,krj->kij", a, a)
    B = rng.standard_normal((n, p, p))
    B = B + B.transpose(0, 2, 1)
    S = 0.05 * B * (np.linalg.norm(F, axis=(1, 2)) / np.linalg.norm(B, axis=(1, 2)))[:, None, None]
    return F, S


def second_order_frontier(cases=((30, 4, 6, "ADE"), (35, 4, 6, "D"), (40, 4, 6, "D"), (30, 4, 8, "D"))):
    print(f"{'n':>4}{'p':>3}{'m':>3}{'designs':>10} crit {'method':>10}{'proven':>7}{'time s':>9}  note")
    for n, p, m, crits in cases:
        F, S = _instance(n * 100 + m, n, p)
        for crit in crits:
            t = time.perf_counter()
            r = select_sensors_from_information(F, S, criterion=crit, kind="second_order", n_sensors=m,
                                                time_limit=60.0)
            dt = time.perf_counter() - t
            print(f"{n:>4}{p:>3}{m:>3}{comb(n, m):>10}    {crit} {r.method:>10}{str(r.proven_optimal):>7}{dt:>9.2f}  "
                  f"{r.notes[0] if r.notes else ''}", flush=True)


def _exp_model():
    return Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * ca.exp(-p[1] * q[0])))


def input_frontier():
    m = _exp_model()
    p = [240.0, 5e-3]
    print(f"{'cands':>6}{'k':>3} {'sensors':>8}{'designs':>12}{'method':>10}{'proven':>7}{'time s':>9}  refined (s)")
    for n, k in ((50, 4), (100, 4), (200, 4), (100, 8)):
        Q = np.linspace(1, 1000, n)
        for sensors in (None, "joint"):
            t = time.perf_counter()
            refine = sensors is None and n <= 100
            r = select_inputs(m, p, candidates=Q, sigma=[0.5, 0.2], n_points=k, sensors=sensors, criterion="D",
                              time_limit=60.0, refine=refine, refine_settings=RefineSettings(n_starts=4))
            dt = time.perf_counter() - t
            nc = n * (2 if sensors == "joint" else 1)
            ref = (f"{r.refined.value:.6f} vs exact {r.value:.6f} ({r.refined.wall_time:.2f})" if r.refined else "-")
            print(f"{n:>6}{k:>3} {str(sensors):>8}{comb(nc, k):>12}{r.method:>10}{str(r.proven_optimal):>7}"
                  f"{dt:>9.2f}  {ref}", flush=True)


def main(argv=None):
    second_order_frontier()
    input_frontier()


if __name__ == "__main__":
    main()
