"""Benchmark (issue 15): cost and memory of ``identify`` against the number of data points.

Two problems, each fitted once per size in a fresh subprocess (so the time is a cold fit:
building the mapped NLP, Ipopt's solver and the model's evaluators included, and the peak
memory is that fit's alone):

* explicit: y = a (1 - exp(-b x)), 2 parameters, one sensor, sigma known (0.02),
  x uniform in [0.05, 8], truth (a, b) = (2, 0.7), p0 = (1, 1);
* implicit: two springs in series under a load F = q, the second one hardening,
  states (u1, y) = (extension of spring 1, total extension):
  E = (k1 u1 - F, k2 (y - u1) + k3 (y - u1)^3 - F), sensors u1 and y (sigma 0.002, 0.004),
  F uniform in [0.1, 3], truth (k1, k2, k3) = (2, 1.5, 0.8), p0 = (1.5, 1, 0.5).

Peer, in its own subprocess on the same data: scipy.optimize.least_squares (method "trf",
xtol = ftol = gtol = 1e-12) with the exact Jacobian written in NumPy (for the implicit model:
the states by vectorised Newton in NumPy and the Jacobian by the implicit function theorem,
what a careful engineer writes by hand), plus the Gauss-Newton covariance (J^T J)^-1.
Reported: the wall and CPU time of the fit (data generation excluded; on a shared machine the
CPU time is the steadier number), the peak resident memory of the
process (``ru_maxrss``) and its increase during the fit, the time and memory per point, the
ratio mudoe / scipy, and the largest relative difference of the estimates.

Run: ``python -m bench scale`` (sizes 1e2..1e6 explicit, 1e2..1e5 implicit); options
``--quick`` (up to 1e5 explicit, 1e4 implicit), ``--max-explicit=N``, ``--max-implicit=N``,
``--min-implicit=N``, ``--only=implicit`` (or explicit).

``python -m bench scale --phases[=N] [--kind=implicit|explicit]``: where the time of one cold fit of
N points (default 1e5, implicit model) goes, phase by phase (validation and start states, start
point of Ipopt, NLP build, Ipopt set-up, callbacks and linear solves, refinement, covariance).

``python -m bench scale --small [--rep=K] [--rounds=R] [--against=/path/to/other/checkout]``: the
small explicit problems instead (Rooney-Biegler, NIST Eckerle4 and MGH09 from both certified
starts): per-fit wall and CPU time of a warm ``identify`` against scipy least_squares with the
exact Jacobian (timed alternately in the same process), medians of K repetitions (default 30) in
R fresh processes (default 2); with ``--against`` the other checkout's ``identify`` is timed in
alternating processes of the same run (e.g. ``--against=/work/main`` for a before/after table).
"""
from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

SIGMA_EXPLICIT = 0.02
SIGMA_IMPLICIT = np.array([0.002, 0.004])


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _explicit_data(n):
    rng = np.random.default_rng(n)
    x = rng.uniform(0.05, 8.0, n)
    z = 2.0 * (1 - np.exp(-0.7 * x)) + SIGMA_EXPLICIT * rng.standard_normal(n)
    return x, z


def _cubic_u2(F, k2, k3):
    """u2 solving k2 u2 + k3 u2^3 = F (vectorised Newton from F / k2, monotone: converges)."""
    u = F / k2
    for _ in range(100):
        r = k2 * u + k3 * u ** 3 - F
        du = r / (k2 + 3 * k3 * u ** 2)
        u = u - du
        if np.max(np.abs(du)) <= 1e-15 * (1 + np.max(np.abs(u))):
            break
    return u


def _implicit_data(n):
    rng = np.random.default_rng(n + 1)
    F = rng.uniform(0.1, 3.0, n)
    u1 = F / 2.0
    y = u1 + _cubic_u2(F, 1.5, 0.8)
    z = np.column_stack([u1, y]) + SIGMA_IMPLICIT * rng.standard_normal((n, 2))
    return F, z


def _run_mudoe(kind, n):
    import casadi as ca
    from identification import Measurements, identify
    from models import Model
    if kind == "explicit":
        x, z = _explicit_data(n)
        model = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
        data = Measurements(x, z.reshape(1, -1, 1), [SIGMA_EXPLICIT])
        p0 = [1.0, 1.0]
    else:
        F, z = _implicit_data(n)

        def E(y, p, q):
            u2 = y[1] - y[0]
            return ca.vertcat(p[0] * y[0] - q[0], p[1] * u2 + p[2] * u2 ** 3 - q[0])

        model = Model(["k1", "k2", "k3"], ["F"], ["u1", "y"], n_y=2, E=E, h=lambda y, p, q: y)
        data = Measurements(F, z.reshape(1, n, 2), SIGMA_IMPLICIT)
        p0 = [1.5, 1.0, 0.5]
    base = _rss_mb()
    t, c = time.perf_counter(), _cpu()
    est = identify(model, data, p0=p0)
    wall, cpu = time.perf_counter() - t, _cpu() - c
    return {"time": wall, "cpu": cpu, "rss_base": base, "rss_peak": _rss_mb(), "p": est.p.tolist(),
            "se": est.stderr.tolist(), "status": est.status, "iterations": est.iterations,
            "timing": (est.diagnostics.timing or {}), "ipopt_timing": est.diagnostics.ipopt_timing,
            "ipopt_passes": est.diagnostics.ipopt_passes, "solver": est.diagnostics.solver}


def phases(n: int = 100_000, kind: str = "implicit"):
    """Where the time of one cold fit of ``n`` points goes: the phases of ``identify`` (wall and
    CPU seconds, from ``Estimate.diagnostics.timing``) and, for the Ipopt solve, the NLP build,
    the solver set-up, the time in the derivative callbacks and Ipopt's own work (the linear
    solves of the KKT system, mostly), in a fresh subprocess (as one row of the scale table)."""
    m = _subprocess("mudoe", kind, n)
    print(f"# phases of one cold identify, {kind} model, {n:.0e} points  "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}  nproc {os.cpu_count()}  "
          f"load {os.getloadavg()[0]:.1f}")
    print(f"total {m['time']:.3f} s wall, {m['cpu']:.3f} s CPU, peak {m['rss_peak']:.0f} MB "
          f"(+{m['rss_peak'] - m['rss_base']:.0f}), solver {m['solver']}, Ipopt iterations {m['iterations']}, "
          f"passes {m['ipopt_passes']}")
    print("| phase | wall s | CPU s | share of wall |")
    print("|---|---|---|---|")
    for name, (w, c) in m["timing"].items():
        print(f"| {name} | {w:.3f} | {c:.3f} | {100 * w / m['time']:.0f} % |")
    it = m["ipopt_timing"]
    if it:
        calls = it["callbacks"]
        inside = sum(calls.values())
        print("\n| Ipopt part (wall s) | s |")
        print("|---|---|")
        print(f"| NLP build (mapped stage functions) | {it['build']:.3f} |")
        print(f"| nlpsol set-up | {it['nlpsol']:.3f} |")
        print(f"| solve | {it['solve']:.3f} |")
        for k, v in calls.items():
            print(f"| - callback {k} | {v:.3f} |")
        print(f"| - Ipopt's own work (KKT factorisations and solves) | {it['solve'] - inside:.3f} |")


def _run_scipy(kind, n):
    from scipy.optimize import least_squares
    if kind == "explicit":
        x, z = _explicit_data(n)

        def fun(p):
            return (p[0] * (1 - np.exp(-p[1] * x)) - z) / SIGMA_EXPLICIT

        def jac(p):
            e = np.exp(-p[1] * x)
            return np.column_stack([1 - e, p[0] * x * e]) / SIGMA_EXPLICIT

        p0 = [1.0, 1.0]
    else:
        F, z = _implicit_data(n)
        cache = {}

        def states(p):
            key = tuple(p)
            if key not in cache:
                cache.clear()
                cache[key] = (F / p[0], _cubic_u2(F, p[1], p[2]))
            return cache[key]

        def fun(p):
            u1, u2 = states(p)
            return ((np.column_stack([u1, u1 + u2]) - z) / SIGMA_IMPLICIT).ravel()

        def jac(p):
            u1, u2 = states(p)
            d = p[1] + 3 * p[2] * u2 ** 2
            J = np.zeros((n, 2, 3))
            J[:, 0, 0] = J[:, 1, 0] = -F / p[0] ** 2
            J[:, 1, 1] = -u2 / d
            J[:, 1, 2] = -u2 ** 3 / d
            return (J / SIGMA_IMPLICIT[None, :, None]).reshape(2 * n, 3)

        p0 = [1.5, 1.0, 0.5]
    base = _rss_mb()
    t, c = time.perf_counter(), _cpu()
    res = least_squares(fun, p0, jac=jac, method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    cov = np.linalg.inv(res.jac.T @ res.jac)
    wall, cpu = time.perf_counter() - t, _cpu() - c
    return {"time": wall, "cpu": cpu, "rss_base": base, "rss_peak": _rss_mb(), "p": res.x.tolist(),
            "se": np.sqrt(np.diag(cov)).tolist(), "status": str(res.status), "iterations": int(res.nfev)}


def _subprocess(who, kind, n):
    cmd = [sys.executable, "-m", "bench.bench_scale", "--one", who, kind, str(n)]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _nist_module():
    import importlib.util
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "tests", "identification", "fit",
                        "nist.py")
    spec = importlib.util.spec_from_file_location("nist_data", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["nist_data"] = mod              # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def _small_problems():
    """(name, casadi h, numpy f, numpy jacobian, x, y, p0) of the small explicit problems."""
    import casadi as ca
    rb_x = np.array([1.0, 2.0, 3.0, 5.0, 7.0, 10.0])
    rb_y = np.array([8.3, 10.3, 19.0, 16.0, 15.6, 19.8])

    def rb_f(b, x):
        return b[0] * (1 - np.exp(-b[1] * x))

    def rb_j(b, x):
        e = np.exp(-b[1] * x)
        return np.column_stack([1 - e, b[0] * x * e])

    def ek_f(b, x):
        return (b[0] / b[1]) * np.exp(-0.5 * ((x - b[2]) / b[1]) ** 2)

    def ek_j(b, x):
        u = (x - b[2]) / b[1]
        e = np.exp(-0.5 * u ** 2)
        return np.column_stack([e / b[1], -(b[0] / b[1] ** 2) * e + (b[0] / b[1]) * e * u ** 2 / b[1],
                                (b[0] / b[1]) * e * u / b[1]])

    def mgh_f(b, x):
        return b[0] * (x ** 2 + x * b[1]) / (x ** 2 + x * b[2] + b[3])

    def mgh_j(b, x):
        num, den = x ** 2 + x * b[1], x ** 2 + x * b[2] + b[3]
        return np.column_stack([num / den, b[0] * x / den, -b[0] * num * x / den ** 2, -b[0] * num / den ** 2])

    nist = _nist_module()
    out = [("Rooney-Biegler", lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])), rb_f, rb_j, rb_x, rb_y,
            np.array([15.0, 0.5]))]
    for name, f, j in (("Eckerle4", ek_f, ek_j), ("MGH09", mgh_f, mgh_j)):
        d = nist.load(name)
        fun = nist.MODELS[name]
        for start in ("start2", "start1"):
            out.append((f"{name} {start}", (lambda fn: lambda p, q: fn(p, q[0]))(fun), f, j, d.x, d.y,
                        getattr(d, start)))
    return out


def _small_one(index: int, rep: int) -> dict:
    """Wall and CPU time per fit (medians of ``rep``) of ``identify`` (warm: the model's functions
    built by a first fit) and of scipy least_squares with the exact NumPy Jacobian (trf,
    tolerances 1e-12, plus the Gauss-Newton covariance) on small problem ``index``, sigma unknown."""
    from scipy.optimize import least_squares
    from identification import IdentificationError, Measurements, identify
    from models import Model
    name, h, f, jac, x, y, p0 = _small_problems()[index]
    model = Model.explicit([f"b{i + 1}" for i in range(p0.size)], ["x"], ["y"], h=h)
    data = Measurements(x, y.reshape(1, -1, 1), sigma=None)
    out = {"name": name, "n": int(x.size)}
    try:
        est = identify(model, data, p0=p0.copy())
    except IdentificationError as exc:
        out["error"] = str(exc)
        return out
    t_m, c_m, t_s, c_s = [], [], [], []
    for _ in range(rep):                       # interleaved: both see the same load
        t, c = time.perf_counter(), time.process_time()
        identify(model, data, p0=p0.copy())
        t_m.append(time.perf_counter() - t)
        c_m.append(time.process_time() - c)
        t, c = time.perf_counter(), time.process_time()
        r = least_squares(lambda b: f(b, x) - y, p0, jac=lambda b: jac(b, x), method="trf",
                          xtol=1e-12, ftol=1e-12, gtol=1e-12)
        np.linalg.inv(r.jac.T @ r.jac) * (2 * r.cost / (x.size - p0.size))
        t_s.append(time.perf_counter() - t)
        c_s.append(time.process_time() - c)
    out.update(mudoe=float(np.median(t_m)), mudoe_cpu=float(np.median(c_m)), scipy=float(np.median(t_s)),
               scipy_cpu=float(np.median(c_s)), solver=est.diagnostics.solver,
               diff=float(np.max(np.abs(est.p - r.x) / np.abs(r.x))), p=est.p.tolist())
    return out


def _small_subprocess(tree: str | None, index: int, rep: int) -> dict:
    """:func:`_small_one` in a fresh process importing the package from ``tree`` (None: this tree)."""
    here = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ)
    env["PYTHONPATH"] = tree or here
    cmd = [sys.executable, os.path.abspath(__file__), "--small-one", str(index), str(rep)]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env, cwd=tree or here)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def small(rep: int = 30, against: str | None = None, rounds: int = 2):
    """Per-fit time of a warm ``identify`` against scipy least_squares with the exact Jacobian on
    the small explicit problems (:func:`_small_one`), medians of ``rep`` fits each, in one run.

    With ``against`` (the root of another checkout, e.g. main) the same fits are timed with that
    tree's package too, in alternating fresh processes (``rounds`` each; the medians are over
    all of them), so both see the same machine load."""
    print(f"# small explicit problems, median of {rep} x {rounds} fits each  "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}  nproc {os.cpu_count()}")
    head = "| problem | n |" + (" other ms (CPU ms) |" if against else "") + \
        " mudoe ms (CPU ms) (solver) | scipy exact-J ms (CPU ms) | scipy / mudoe wall (CPU) | max rel diff p |"
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for index in range(len(_small_problems())):
        runs = {"this": [], "other": []}
        for _ in range(rounds):
            if against:
                runs["other"].append(_small_subprocess(against, index, rep))
            runs["this"].append(_small_subprocess(None, index, rep))
        this = runs["this"]
        if "error" in this[0]:
            print(f"| {this[0]['name']} | {this[0]['n']} | failed: {this[0]['error']} |")
            continue

        def med(rs, key):
            return float(np.median([r[key] for r in rs]))
        m, mc = med(this, "mudoe"), med(this, "mudoe_cpu")
        s = med(this + runs["other"], "scipy")
        sc = med(this + runs["other"], "scipy_cpu")
        other = ""
        if against:
            o = runs["other"]
            other = (f" failed |" if "error" in o[0] else
                     f" {1e3 * med(o, 'mudoe'):.2f} ({1e3 * med(o, 'mudoe_cpu'):.2f}) |")
        print(f"| {this[0]['name']} | {this[0]['n']} |{other} {1e3 * m:.2f} ({1e3 * mc:.2f}) ({this[0]['solver']}) | "
              f"{1e3 * s:.2f} ({1e3 * sc:.2f}) | {s / m:.2f} ({sc / mc:.2f}) | {this[0]['diff']:.1e} |", flush=True)


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "--one":
        who, kind, n = argv[1], argv[2], int(argv[3])
        print(json.dumps((_run_mudoe if who == "mudoe" else _run_scipy)(kind, n)))
        return
    if argv and argv[0] == "--small-one":
        print(json.dumps(_small_one(int(argv[1]), int(argv[2]))))
        return
    if any(a.startswith("--phases") for a in argv):
        opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
        phases(int(float(opts.get("phases", 1e5))), opts.get("kind", "implicit"))
        return
    if "--small" in argv:
        opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
        small(int(opts.get("rep", 30)), opts.get("against"), int(opts.get("rounds", 2)))
        return
    quick = "--quick" in argv
    opts = dict(a.lstrip("-").split("=", 1) for a in argv if "=" in a)
    max_exp = int(float(opts.get("max-explicit", 1e5 if quick else 1e6)))
    max_imp = int(float(opts.get("max-implicit", 1e4 if quick else 1e5)))
    print(f"# bench scale  {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}  "
          f"{platform.processor() or platform.machine()}  nproc {os.cpu_count()}  "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', '-')}")
    print("| model | points | mudoe s (CPU s) | scipy exact-J s (CPU s) | ratio wall (CPU) | mudoe CPU us/point "
          "| mudoe peak MB (+fit) | bytes/point | scipy peak MB | max rel diff p |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    only = opts.get("only")
    for kind, top in (("explicit", max_exp), ("implicit", max_imp)):
        if only is not None and kind != only:
            continue
        n = int(float(opts.get(f"min-{kind}", 100)))
        while n <= top:
            m = _subprocess("mudoe", kind, n)
            s = _subprocess("scipy", kind, n)
            diff = float(np.max(np.abs(np.subtract(m["p"], s["p"])) / np.abs(s["p"])))
            grow = m["rss_peak"] - m["rss_base"]
            print(f"| {kind} | {n:.0e} | {m['time']:.3f} ({m['cpu']:.3f}) | {s['time']:.3f} ({s['cpu']:.3f}) | "
                  f"{m['time'] / s['time']:.2f} ({m['cpu'] / max(s['cpu'], 1e-3):.2f}) | {1e6 * m['cpu'] / n:.2f} | "
                  f"{m['rss_peak']:.0f} (+{grow:.0f}) | {grow * 2 ** 20 / n:.0f} | {s['rss_peak']:.0f} | {diff:.1e} |",
                  flush=True)
            n *= 10


if __name__ == "__main__":
    main()
