"""Benchmark (issue 22, item 5): design over time and experiments, mudoe against the live Pyomo.DoE.

One run measures, on Pyomo.DoE's reactor example (pyomo/contrib/doe/examples: A -> B -> C,
k_i = A_i exp(-1000 E_i / (R T)), CA0 and a piecewise-constant T at 9 grid points, CA, CB, CC
measured at the grid points with sigma 0.01, parameters scaled by their nominal values):

* the FIM at the nominal design: mudoe's ``information_contributions(model, None, p, inputs=q,
  times=t, sigma=0.01)`` (default settings: Radau IIA degree 3 on a mesh with output error
  within 1 % of sigma) against Pyomo.DoE's warm ``compute_FIM``;
* the continuous D-optimal design of (CA0, T profile) in [1, 5] x [300, 700]^9: mudoe's
  ``select_inputs(model, p, times=t, candidates=[nominal], n_points=1, refine=True, bounds=...)``
  (exact design, then the continuous refinement, 4 starts: the reduced-space Newton of oed.input_newton for D
  since session 13, the full-space NLP by Ipopt before) against ``run_doe``;
* the 9 x 9 factorial of (CA0, T0) (T = 300 after t = 0.125): mudoe's
  ``oed.information(..., axis="inputs")`` over the 81 rows against
  ``compute_FIM_full_factorial``;

every log det also evaluated in the ODE itself (bench.dynamic_reference, exact sensitivities).
The peer runs through :func:`bench.bench_pyomo_doe.run_peer` (its own venv, in a subprocess;
``MUDOE_PEER_PYTHON`` / ``MUDOE_PEER_IPOPT`` / ``MUDOE_PEER_DATA``).  Ratios are peer / mudoe
of the median CPU and wall seconds, measured in this one run.

Run: ``python -m bench dynamic_doe [--rep=10] [--doe-rep=3] [--factorial-rep=2]`` (``--factorial-rep=0``: no
factorial); ``python -m bench dynamic_doe --scale [--step=0.02]``: the large designs of :func:`scale_part` alone.
"""
from __future__ import annotations

import json
import sys

import casadi as ca
import numpy as np

from bench import dynamic_reference as dr
from bench.bench_pyomo_doe import _clock, _machine, _since, _stats, run_peer

P = np.array(dr.PYOMO_DOE_REACTOR["p"])
GRID = np.array(dr.PYOMO_DOE_REACTOR["times"])
NOMINAL = np.r_[dr.PYOMO_DOE_REACTOR["CA0"], dr.PYOMO_DOE_REACTOR["T"]]
LOWER, UPPER = np.r_[1.0, [300.0] * 9], np.r_[5.0, [700.0] * 9]


def reactor():
    """Pyomo.DoE's reactor example as a mudoe dynamic model (CA, CB states; CC = CA0 - CA - CB)."""
    from models import Model

    R = dr.PYOMO_DOE_REACTOR["R"]

    def rhs(x, p, u):
        k1 = p[0] * ca.exp(-p[2] * 1000 / (R * u[1]))
        k2 = p[1] * ca.exp(-p[3] * 1000 / (R * u[1]))
        return ca.vertcat(-k1 * x[0], k1 * x[0] - k2 * x[1])

    return Model.ode(["A1", "A2", "E1", "E2"], ["CA", "CB"], ["CA0"], ["CA", "CB", "CC"], rhs=rhs,
                     x0=lambda p, u: ca.vertcat(u[0], 0), h=lambda x, p, u: ca.vertcat(x[0], x[1], u[0] - x[0] - x[1]),
                     controls={"T": {"grid": GRID, "kind": "constant"}}, horizon=1.0, name="Pyomo.DoE reactor")


def scaled_log10_det(F) -> float:
    """log10 det of D F D, D = diag(p): Pyomo.DoE's ``scale_nominal_param_value=True`` convention."""
    D = np.diag(P)
    return dr.log10_det(D @ np.asarray(F) @ D)


def _timed(fn, rep):
    """(first (wall, CPU), stats of ``rep`` further calls, last result)."""
    t0 = _clock()
    out = fn()
    first = _since(t0)
    times = []
    for _ in range(rep):
        t0 = _clock()
        out = fn()
        times.append(_since(t0))
    return first, _stats(times), out


def mudoe_part(rep=10, doe_rep=3, factorial_rep=2):
    """mudoe's three measurements (module docstring) with their ODE log dets."""
    from identification import information_contributions
    from oed import select_inputs
    from oed import information

    model = reactor()
    first, warm, (F, _) = _timed(lambda: information_contributions(model, None, P, inputs=[NOMINAL], times=GRID,
                                                                   sigma=0.01), rep)
    out = {"fim": {"first_s": first, "warm": warm, "log10_det": scaled_log10_det(F.sum(axis=0)),
                   "ode_log10_det": dr.log10_det(dr.pyomo_doe_reactor_fim())}}
    out["fim"]["minus_ode"] = out["fim"]["log10_det"] - out["fim"]["ode_log10_det"]
    first, warm, res = _timed(lambda: select_inputs(model, P, times=GRID, candidates=[NOMINAL], sigma=0.01,
                                                    n_points=1, refine=True, bounds=(LOWER, UPPER), time_limit=60.0),
                              doe_rep)
    x = res.refined.inputs[0]
    out["design"] = {"first_s": first, "warm": warm, "CA0": float(x[0]), "T": x[1:].tolist(),
                     "log10_det": -res.refined.value / np.log(10) + 2 * float(np.sum(np.log10(P))),
                     "ode_log10_det": dr.log10_det(dr.pyomo_doe_reactor_fim(x[0], x[1:])),
                     "start_values": list(res.refined.start_values), "notes": list(res.notes)}
    if factorial_rep < 1:
        return out
    C, T0 = (g.ravel() for g in np.meshgrid(np.linspace(1, 5, 9), np.linspace(300, 700, 9), indexing="ij"))
    Q = np.column_stack([C, T0, np.tile(NOMINAL[2:], (C.size, 1))])
    first, warm, Fq = _timed(lambda: information(model, P, axis="inputs", candidates=Q, times=GRID,
                                                      sigma=0.01).F, factorial_rep)
    ld = np.array([scaled_log10_det(f) for f in Fq])
    _, _, ode = dr.pyomo_doe_reactor_factorial()
    ok = np.isfinite(ode)
    best = int(np.nanargmax(np.where(np.isfinite(ld), ld, -np.inf)))
    out["factorial"] = {"first_s": first, "warm": warm, "points": int(C.size),
                        "singular": int(np.sum(~np.isfinite(ld))), "ode_singular": int(np.sum(~ok)),
                        "max_abs_minus_ode": float(np.max(np.abs(ld[ok] - ode[ok]))),
                        "best": {"CA0": float(C[best]), "T0": float(T0[best]), "log10_det": float(ld[best])}}
    return out


def _design_record(first, res, what):
    """(wall, CPU incl. children) seconds and the refinement's outcome."""
    r = res.refined if hasattr(res, "refined") else res
    out = {"wall_s": first[0], "cpu_s": first[1], "value": r.value, "start_values": list(r.start_values),
           "messages": list(r.messages), "inputs": np.asarray(r.inputs).tolist(), "what": what}
    if hasattr(res, "refined"):
        out.update(exact_value=res.value, notes=list(res.notes))
    return out


def scale_part(step=0.02):
    """Issue 30 item 6 (design speed), each the first call in this process for its model:

    * ~1000 states: the ``profile`` batch reactor of mudoe/example_reactor.py collocated with ``max_step``
      (0.02 h: 939 states per experiment), two experiments refined together, 2 starts, ``time_limit=600``;
    * the DC motor of mudoe/example_motor.py (configs/motor.toml): its 4 experiments as candidates, n_points=4,
      n_series=2, refined within TL in [0, 0.03] N m and u in [-12, 12] V, ``time_limit=60`` (4 starts; the
      Newton route runs in this process, the Ipopt route's 22 808-variable NLP in the child process).
    """
    from mudoe import example_motor as em
    from mudoe import example_reactor as er
    from oed import RefineSettings, refine_inputs, select_inputs

    cm = er.build("profile").collocate(er.TIMES, max_step=step)
    X0 = np.array([np.r_[2.0, [370.0] * 4, [330.0] * 4], np.r_[1.0, [340.0] * 8]])
    lo, hi = np.r_[0.5, [320.0] * 8], np.r_[2.5, [380.0] * 8]
    t0 = _clock()
    r = refine_inputs(cm, er.P_TRUE, X0, np.full(cm.n_S, 0.01), bounds=(lo, hi), settings=RefineSettings(n_starts=2),
                      time_limit=600)
    out = {"reactor_states": _design_record(_since(t0), r, f"{cm.n_y} states per experiment, 2 experiments")}
    Q = np.array([[0.0, 6, 6, 12, 12, 0, 0, -6, -6, 0, 0], [0.02, 12, 12, 12, 6, 6, 3, 3, 0, 0, 0],
                  [0.01, 3, 6, 3, 0, -3, -6, -3, 0, 3, 0], [0.03, 9, -9, 9, -9, 12, 12, -12, -12, 6, 0]], float)
    t0 = _clock()
    res = select_inputs(em.build("coulomb"), em.P_TRUE, times=em.TIMES, candidates=Q, sigma=[0.02, 0.5, 0.01],
                        n_points=4, n_series=2, refine=True, bounds=(np.r_[0.0, [-12.0] * 10], np.r_[0.03, [12.0] * 10]),
                        time_limit=60.0)
    out["motor"] = _design_record(_since(t0), res, "DC motor, 4 experiments x 11 inputs")
    return out


def _ratio(peer, mine, key):
    return peer[key] / mine[key] if mine[key] > 0 else None


def ratios(peer, mine):
    """Peer / mudoe of the median CPU and wall seconds (mudoe's warm calls; its first call apart)."""
    out = {}
    pairs = {"fim": (peer["compute_FIM"]["warm"], mine["fim"]),
             "design": (peer.get("run_doe", {}).get("warm"), mine["design"]),
             "factorial": (peer.get("factorial", {}).get("timing"), mine.get("factorial"))}
    for name, (pw, m) in pairs.items():
        if pw is None or m is None or m["warm"] is None:
            continue
        out[name] = {"cpu_warm": pw["cpu_median_s"] / m["warm"]["cpu_median_s"],
                     "wall_warm": pw["median_s"] / m["warm"]["median_s"],
                     "cpu_vs_mudoe_first": pw["cpu_median_s"] / m["first_s"][1],
                     "wall_vs_mudoe_first": pw["median_s"] / m["first_s"][0]}
    return out


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    opts = dict(a[2:].split("=", 1) for a in argv if a.startswith("--") and "=" in a)
    rep, doe_rep, fact_rep = int(opts.get("rep", 10)), int(opts.get("doe-rep", 3)), int(opts.get("factorial-rep", 2))
    if "--scale" in argv:                 # issue 30 item 6: the large designs, alone (no peer)
        out = {"machine_before": _machine(), "scale": scale_part(float(opts.get("step", 0.02))),
               "machine_after": _machine()}
        print(json.dumps(out, indent=1, default=float))
        return
    out = {"machine_before": _machine(), "mudoe": mudoe_part(rep, doe_rep, fact_rep)}
    try:
        out["peer"] = run_peer(rep, doe_rep, fact_rep)
    except FileNotFoundError as exc:
        print(f"bench dynamic_doe: {exc}", file=sys.stderr)
        out["peer"] = {"missing": str(exc)}
    else:
        peer = out["peer"]
        if "run_doe" in peer:
            d = peer["run_doe"]["design"]
            T = [d[f"T[{t:g}]"] for t in GRID]
            peer["run_doe"]["ode_log10_det_at_design"] = dr.log10_det(dr.pyomo_doe_reactor_fim(d["CA[0]"], T))
        out["ratios"] = ratios(peer, out["mudoe"])
    out["machine_after"] = _machine()
    for part in ("fim", "design", "factorial"):
        if part in out["mudoe"]:
            out["mudoe"][part]["first_s"] = list(out["mudoe"][part]["first_s"])
    print(json.dumps(out, indent=1, default=float))



if __name__ == "__main__":
    main()
