"""Benchmark (issue 30 items 1 and 6): identification speed against scipy in the same run.

* ``reactor``: bench.dynamic_reference's batch reactor, 20 experiments x 30 samples (seed 0), start (0.7,
  0.7, 50, 60): mudoe's warm refit (``identify`` repeated on one model, after a first fit; on CasADi's
  virtual machine, identify's default, and with JIT, ``models.state.jit_scope(True)``) against scipy
  ``least_squares`` with all experiments stacked in one ``solve_ivp`` and the exact sensitivity Jacobian
  (rtol 1e-8; ``bench.dynamic_reference.reference_fit(..., jac="sens", stacked=True)``), alternating.
* ``published``: the four published benchmarks of :mod:`bench.ode_benchmarks` (chain, gas oil, methanol,
  alpha-pinene) from their published starts (COPS: rates 0 on their bound; methanol 1), from every rate 0
  and from every rate 1e-6 (just inside the bound): mudoe's warm refit with the default start
  trajectories (``IdentifySettings(init="data")``) and with ``init="simulate"`` (iterations and CPU), and
  scipy ``least_squares`` over ``solve_ivp`` with RK45, LSODA and BDF (:func:`bench.ode_benchmarks.scipy_fit`);
  the ratio is the fastest scipy method's CPU over mudoe's.  Iterations: the final fit's (reduced-space
  Newton or Ipopt) and every Ipopt pass of every mesh together ("in all").  Both optima are checked: the sum of squares of
  mudoe's estimate (recomputed by solve_ivp, rtol 1e-10) and scipy's.

CPU seconds of this process (the machine is shared: wall times are printed beside them).  Run:
``python -m bench fit_speed [--rep=5] [--scipy-rep=1] [--parts=reactor,published]``; prints a table and a
JSON document.
"""
from __future__ import annotations

import json
import os
import statistics
import sys
import time
import warnings

import numpy as np
from scipy.integrate import solve_ivp

from bench import dynamic_reference as dr
from bench import ode_benchmarks as ob

METHODS = ("RK45", "LSODA", "BDF")


def _cpu(f):
    c0, w0 = time.process_time(), time.perf_counter()
    out = f()
    return out, time.process_time() - c0, time.perf_counter() - w0


def reactor(rep: int = 7) -> dict:
    """mudoe's warm refit of the reactor 20 x 30 and scipy's stacked exact-sensitivity fit, alternating; mudoe
    both on CasADi's virtual machine (identify's default) and with JIT (``models.state.jit_scope(True)``, as
    Monte Carlo, bootstrap and validate fit: compiled element functions and block solves)."""
    from identification import identify
    from models.state import JIT, jit_scope
    from bench.bench_dynamic_fit import _measurements, reactor_model
    ex = dr.batch_reactor()
    d = dr.simulate_data(ex, 20, 30, seed=0)
    data = _measurements(d)
    model = reactor_model()
    est, c_first, w_first = _cpu(lambda: identify(model, data, ex.p_start))
    with jit_scope(True):
        est_jit, c_first_jit, _ = _cpu(lambda: identify(model, data, ex.p_start))
    m_cpu, m_wall, j_cpu, s_cpu, s_wall = [], [], [], [], []
    for _ in range(rep):
        est, c, w = _cpu(lambda: identify(model, data, ex.p_start))
        m_cpu.append(c)
        m_wall.append(w)
        with jit_scope(True):
            est_jit, c, _ = _cpu(lambda: identify(model, data, ex.p_start))
        j_cpu.append(c)
        fit = dr.reference_fit(ex, d, rtol=1e-8, jac="sens", stacked=True)
        s_cpu.append(fit.fit_cpu_seconds)
        s_wall.append(fit.fit_seconds)
    ref = dr.reference_fit(ex, d, rtol=1e-10, jac="sens", stacked=True)
    return {"problem": "reactor 20x30", "start": "(0.7, 0.7, 50, 60)", "solver": est.diagnostics.solver,
            "iterations": est.iterations, "mudoe_cpu": statistics.median(m_cpu), "mudoe_wall": statistics.median(m_wall),
            "mudoe_first_cpu": c_first, "scipy": "stacked exact-sens (DOP853)", "scipy_cpu": statistics.median(s_cpu),
            "scipy_wall": statistics.median(s_wall), "ratio": statistics.median(s_cpu) / statistics.median(m_cpu),
            "mudoe_dev_se": float(np.max(np.abs((est.p - ref.p) / ref.se))), "scipy_nfev": fit.nfev,
            "jit_compiler": not JIT.failed, "mudoe_jit_cpu": statistics.median(j_cpu),
            "mudoe_jit_first_cpu": c_first_jit, "ratio_jit": statistics.median(s_cpu) / statistics.median(j_cpu),
            "jit_minus_vm_se": float(np.max(np.abs((est_jit.p - est.p) / est.stderr))),
            "mudoe_cpu_all": m_cpu, "mudoe_jit_cpu_all": j_cpu, "scipy_cpu_all": s_cpu}


def _sse(b, p) -> float:
    """The sum of squares at p by solve_ivp (LSODA, rtol 1e-10): the same yardstick for both optima."""
    sol = solve_ivp(lambda t, x: b.rhs(x, p), (0.0, float(b.times[-1])), b.x0, method="LSODA", t_eval=b.times,
                    rtol=1e-10, atol=1e-12 * float(np.max(np.abs(b.z))))
    return float(np.sum((sol.y.T - b.z) ** 2))


class _IpoptCount:
    """Counts the Ipopt iterations of every pass of every fit (identify reports the last pass's only): wraps
    the estimator's ``solve_nlp`` for the duration of a ``with`` block."""

    def __enter__(self):
        from identification.fit import estimator
        self.module, self.original, self.iterations = estimator, estimator.solve_nlp, 0

        def counted(*args, **kw):
            try:
                res = self.original(*args, **kw)
            except Exception as exc:          # a failed pass: its iterations are in the message
                text = str(exc).split("after ")[-1].split(" ")[0]
                self.iterations += int(text) if text.isdigit() else 0
                raise
            self.iterations += res.iterations
            return res
        estimator.solve_nlp = counted
        return self

    def __exit__(self, *exc):
        self.module.solve_nlp = self.original
        return False


def _mudoe(b, p0, init: str, rep: int) -> dict:
    from identification import IdentifySettings, identify
    model, data, settings = b.model(), b.data(), IdentifySettings(init=init)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # the degenerate-start and bound notes
        try:
            est, c_first, _ = _cpu(lambda: identify(model, data, p0, settings=settings))
        except Exception as exc:                   # a failed fit is a row of the table, not the end of the run
            return {"failed": f"{type(exc).__name__}: {str(exc)[:120]}"}
        cpu, wall = [], []
        for _ in range(rep):
            est, c, w = _cpu(lambda: identify(model, data, p0, settings=settings))
            cpu.append(c)
            wall.append(w)
        with _IpoptCount() as count:
            identify(model, data, p0, settings=settings)
    return {"solver": est.diagnostics.solver, "iterations": est.iterations, "ipopt_total": count.iterations,
            "meshes": len(est.diagnostics.discretisation.history), "cpu": statistics.median(cpu),
            "wall": statistics.median(wall), "first_cpu": c_first, "p": est.p.tolist(), "sse": _sse(b, est.p),
            "stderr": est.stderr.tolist()}


def published(rep: int = 5, scipy_rep: int = 1) -> list:
    """Every benchmark from its published start, from 0 and from 1e-6: mudoe (data and simulated start
    trajectories) and scipy (three integrators)."""
    rows = []
    for name in ob.BENCHMARKS:
        b = ob.benchmark(name)
        starts = {"published": ob.PUBLISHED_START[name], "all 0": (0.0,) * b.n_p, "all 1e-6": (1e-6,) * b.n_p}
        if starts["published"] == starts["all 0"]:
            del starts["all 0"]
        for label, p0 in starts.items():
            row = {"problem": name, "start": label, "p0": list(p0)}
            row["mudoe"] = _mudoe(b, p0, "data", rep)
            row["mudoe_simulate"] = _mudoe(b, p0, "simulate", rep)
            sc = {}
            for method in METHODS:
                fits = [ob.scipy_fit(b, p0, method) for _ in range(scipy_rep)]
                sc[method] = {"cpu": statistics.median(f["cpu_s"] for f in fits),
                              "wall": statistics.median(f["wall_s"] for f in fits), "nfev": fits[0]["nfev"],
                              "sse": _sse(b, fits[0]["p"]), "p": fits[0]["p"].tolist()}
            row["scipy"] = sc
            best = min(sc, key=lambda k: sc[k]["cpu"])
            row["scipy_best"] = best
            if "cpu" in row["mudoe"]:
                row["ratio"] = sc[best]["cpu"] / row["mudoe"]["cpu"]
                se = np.asarray(row["mudoe"]["stderr"])
                row["scipy_minus_mudoe_se"] = float(np.max(np.abs((np.asarray(sc[best]["p"]) -
                                                                   np.asarray(row["mudoe"]["p"])) / se)))
            rows.append(row)
            print(_line(row), flush=True)
    return rows


def _line(r) -> str:
    m, s = r["mudoe"], r.get("mudoe_simulate", {})
    if "failed" in m:
        mud = f"FAILED {m['failed']}"
    else:
        mud = (f"{m['solver']} {m['iterations']} it ({m['meshes']} mesh{'es' if m['meshes'] > 1 else ''}; Ipopt "
               f"{m['ipopt_total']} in all), {1e3 * m['cpu']:.1f} ms")
    sim = (f"{s['solver']} {s['iterations']} it (Ipopt {s['ipopt_total']}), {1e3 * s['cpu']:.1f} ms" if "cpu" in s
           else s.get("failed", ""))
    b = r["scipy_best"]
    sc = r["scipy"][b]
    return (f"| {r['problem']} | {r['start']} | {mud} | {sim} | {b} {1e3 * sc['cpu']:.0f} ms (nfev {sc['nfev']}) | "
            f"{r.get('ratio', float('nan')):.1f}x | {m.get('sse', float('nan')):.6g} / {sc['sse']:.6g} | "
            f"{r.get('scipy_minus_mudoe_se', float('nan')):.1e} |")


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    opts = dict(a[2:].split("=", 1) for a in argv if a.startswith("--") and "=" in a)
    parts = opts.get("parts", "reactor,published").split(",")
    out = {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "load_before": os.getloadavg()}
    if "reactor" in parts:
        r = reactor(int(opts.get("rep", 7)))
        out["reactor"] = r
        print(f"| reactor 20x30 | (0.7, 0.7, 50, 60) | {r['solver']} {r['iterations']} it, {1e3 * r['mudoe_cpu']:.1f} ms "
              f"(first fit {1e3 * r['mudoe_first_cpu']:.0f} ms) | {r['scipy']} {1e3 * r['scipy_cpu']:.1f} ms | "
              f"{r['ratio']:.2f}x | mudoe {r['mudoe_dev_se']:.1e} se from the rtol 1e-10 fit |", flush=True)
        print(f"| reactor 20x30, JIT (jit_scope(True)) | (0.7, 0.7, 50, 60) | {1e3 * r['mudoe_jit_cpu']:.1f} ms (first JIT "
              f"fit {1e3 * r['mudoe_jit_first_cpu']:.0f} ms) | {1e3 * r['scipy_cpu']:.1f} ms | {r['ratio_jit']:.2f}x | "
              f"{r['jit_minus_vm_se']:.1e} se from the VM's estimate |", flush=True)
    if "published" in parts:
        print("| problem | start | mudoe (init=data) CPU | init=simulate | fastest scipy CPU | ratio | SSE mudoe / scipy "
              "| scipy - mudoe (se) |", flush=True)
        out["published"] = published(int(opts.get("rep", 5)), int(opts.get("scipy-rep", 1)))
    out["load_after"] = os.getloadavg()
    print(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
