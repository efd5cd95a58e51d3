"""Benchmark (issue 30 item 6, "DAEs on the fast path"): collocated index-1 DAEs marched element by element
(:mod:`models.dae_march`) against the generic whole-trajectory solves they used before (the same run, the
generic path by ``dae_march_scope(False)``, each path on its own fresh model so that no cache is shared).

* ``equilibrium``: A -> S (k1), S = B + C in fast equilibrium C = K B^2, B consumed (k2); states cA, cS,
  algebraic cB, cC; inputs cA0 and a piecewise-constant feed on [0, 1, 2]; sensors cA, cB, cC (sigma 0.01);
  ``--n-exp`` experiments (default 20) x 12 times on [0.25, 3], p = (1.2, 0.7, 2), start 0.8 p.
* ``toy``: x' = -k w, 0 = w - x^2 (x = x0 / (1 + k x0 t)); 10 experiments x0 in [0.5, 2] x 12 times.

Timed (median wall seconds of ``--rep`` repeats, the two paths alternating, after one warm-up each):
``simulate`` (the states of all experiments, :func:`models.state.solve_states`), ``sensitivities``
(:func:`models.sensitivity.sensitivities` at those states), ``identify_first`` (a fit on a fresh model,
function building included), ``identify_warm`` (a refit of new data on the same model) and ``select_times``
(:func:`oed.select_times`, 4 of the 12 times, D).  Checked: states and G relative to the generic path, the
estimates' difference in standard errors.  Run: ``python -m bench dae [--rep=5] [--n-exp=20]``; prints JSON.
"""
from __future__ import annotations

import json
import os
import statistics
import sys
import time

import casadi as ca
import numpy as np

TIMES = np.linspace(0.25, 3.0, 12)


def equilibrium():
    from models.library import equilibrium_dae
    return equilibrium_dae(name="equilibrium DAE (bench)")


def toy():
    from models import Model
    return Model.ode(["k"], ["x"], ["x0"], ["x", "w"], rhs=lambda x, z, p, u: -p[0] * z[0],
                     alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                     h=lambda x, z, p, u: ca.vertcat(x[0], z[0]), horizon=3.0, name="toy DAE (bench)")


def cases(n_exp: int) -> dict:
    rng = np.random.default_rng(0)
    q_eq = np.column_stack([rng.uniform(0.5, 2.0, n_exp), rng.uniform(0.0, 1.0, (n_exp, 3))])
    return {"equilibrium": (equilibrium, np.array([1.2, 0.7, 2.0]), q_eq),
            "toy": (toy, np.array([0.8]), np.linspace(0.5, 2.0, 10)[:, None])}


def _clock(f):
    t0 = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t0


def one_case(make, p, Q, rep: int) -> dict:
    """The five timings of both paths (alternating) and the agreement checks."""
    from identification import identify
    from identification.fit.dynamic_fit import simulate_campaign
    from models.collocation import collocate
    from models.dae_march import dae_march_scope
    from models.sensitivity import sensitivities
    from models.state import solve_states
    from oed import select_times
    sigma = [0.01] * len(make().sensors)
    data = [simulate_campaign(make(), p, Q, TIMES, sigma, seed=s) for s in range(rep + 2)]
    paths = {"march": True, "generic": False}
    models = {k: make() for k in paths}
    cms = {k: collocate(models[k], TIMES) for k in paths}
    times = {k: {op: [] for op in ("simulate", "sensitivities", "identify_first", "identify_warm", "select_times")}
             for k in paths}
    last = {}
    for r in range(rep + 1):                      # r = 0: warm-up (not counted)
        for k, on in paths.items():
            with dae_march_scope(on):
                cm = cms[k]
                Y, t_sim = _clock(lambda: solve_states(cm, p, Q))
                S, t_sens = _clock(lambda: sensitivities(cm, p, Q, Y))
                est0, t_first = _clock(lambda: identify(make(), data[0], 0.8 * p))
                est, t_warm = _clock(lambda: identify(models[k], data[r + 1], 0.8 * p))
                des, t_sel = _clock(lambda: select_times(models[k], p, TIMES, Q, sigma, n_times=4, criterion="D"))
                assert type(cm.state_numerics).__name__ == ("DAETrajectoryNumerics" if on else "GenericDAESolve")
            if r:
                for op, t in zip(times[k], (t_sim, t_sens, t_first, t_warm, t_sel)):
                    times[k][op].append(t)
            last[k] = (Y, S.G, est0, est, des)
    (Ym, Gm, e0m, em, dm), (Yg, Gg, e0g, eg, dg) = last["march"], last["generic"]
    med = {k: {op: statistics.median(v) for op, v in t.items()} for k, t in times.items()}
    return {"n_exp": int(Q.shape[0]), "n_times": int(TIMES.size), "n_y": int(cms["march"].n_y),
            "elements": int(cms["march"].mesh.n_elements), "median_wall_s": med,
            "speedup_generic_over_march": {op: med["generic"][op] / med["march"][op] for op in med["march"]},
            "states_rel_diff": float(np.abs(Ym - Yg).max() / np.abs(Yg).max()),
            "G_rel_diff": float(np.abs(Gm - Gg).max() / np.abs(Gg).max()),
            "estimate_diff_in_se": float(max(np.max(np.abs(e0m.p - e0g.p) / e0g.stderr),
                                             np.max(np.abs(em.p - eg.p) / eg.stderr))),
            "same_times_chosen": list(dm.chosen) == list(dg.chosen), "times_chosen": list(dm.chosen)}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    opts = dict(a[2:].split("=", 1) for a in argv if a.startswith("--") and "=" in a)
    rep, n_exp = int(opts.get("rep", 5)), int(opts.get("n-exp", 20))
    out = {"load_before": os.getloadavg()}
    for name, (make, p, Q) in cases(n_exp).items():
        out[name] = one_case(make, p, Q, rep)
    out["load_after"] = os.getloadavg()
    print(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
