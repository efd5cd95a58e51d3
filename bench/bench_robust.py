"""Benchmark (issue 31): approximate local, pseudo-Bayesian and maximin designs with their certificates.

One run measures, on the compartmental model eta = theta3 (exp(-theta1 t) - exp(-theta2 t)), t in [0, 24],
theta = (0.05884, 4.298, 21.80) (Atkinson, Donev & Tobias 2007, ch. 17-18), with :func:`oed.approximate_design`:

* the local D design (textbook: t = 0.2288, 1.3886, 18.4168, weights 1/3) and its equivalence maximum;
* pseudo-Bayesian A, D, E designs for theta1 ~ U(0.05884 +- 0.01), theta2 ~ U(4.298 +- 1) and U(4.298 +- 4),
  a 20 x 20 tensor Gauss-Legendre rule: wall time, equivalence gap, the quadrature error estimate (the 21 x 21
  rule), and for D the expected log det against a brute-force multiplicative algorithm on a fine grid
  (spacing 0.001 on [0, 2], 0.01 on [2, 24]; run until its own gap over the grid is below 5e-5 or 20000 steps;
  the grid optimum lies between its value and its value + its gap);
* standardized maximin D and A designs over the 3 x 3 grid of the box theta1 in 0.05884 +- 0.01,
  theta2 in 4.298 +- 2: the certified worst-case efficiency against a brute-force check of the design's
  efficiency on a 21 x 21 parameter grid (each point's own local optimum by the engine, certified);
* the batch reactor (mudoe.example_reactor): Bayesian D sampling times with E1 ~ U(55, 65), E2 ~ U(75, 85)
  (3 x 3 Gauss), three experiments;
* exact robust n-run designs (:func:`oed.robust_exact.select_robust_exact`, complete enumeration and the
  branch-and-bound of :mod:`oed.robust_bnb`, compared on every instance) for the press sensors (the paper's 3 and
  the 20 extended ones) and the reactor's sampling times (the shipped configs/reactor.toml: 6 experiments, 4 of
  10 times; and 4..8 of 40 times), with the efficiency against the approximate design and the local design's
  efficiency across the prior (``--exact-only`` runs just these).

Times are wall seconds, median of ``--rep`` runs (default 3), on the machine and date printed.

Session 12 (bench/robust_library.py): sparse grids against tensor rules, sequential designs under a prior, refined
exact robust designs (``--library`` runs just these; ``--library=sparse,sequential,refined`` some of them).

Run: ``python -m bench robust [--rep=3] [--no-brute] [--exact-only] [--library[=parts]]``
"""
from __future__ import annotations

import math
import platform
import time
from datetime import datetime, timezone

import casadi as ca
import numpy as np

P0 = np.array([0.05884, 4.298, 21.80])


def compartmental():
    from models import Model
    return Model.explicit(["theta1", "theta2", "theta3"], ["t"], ["eta"],
                          h=lambda p, q: p[2] * (ca.exp(-p[0] * q[0]) - ca.exp(-p[1] * q[0])), name="compartmental")


def _timed(fn, rep):
    out, times = None, []
    for _ in range(rep):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


def _fine_information(model, P, T):
    from oed import information
    return np.stack([information(model, p, axis="inputs", candidates=T[:, None], sigma=1.0).F for p in P], axis=1)


def brute_multiplicative(F, prior_w, n_p, tol=5e-5, max_iter=20000):
    """Multiplicative algorithm w <- w g / n_p on the whole grid, dropping points whose weight fell below 1e-10
    at iterations 500, 1000, 2000, 4000, ... (speed only), until its equivalence gap over the whole grid (which
    bounds its distance to the grid's optimum whatever was dropped) is below tol: (expected log det, gap,
    iterations)."""
    w = np.full(F.shape[0], 1.0 / F.shape[0])
    keep = np.arange(F.shape[0])
    gap, Minv = np.inf, None
    for it in range(max_iter):
        if it >= 500 and (it & (it - 1)) == 0 or it == 500:
            sel = w > 1e-10
            keep, w = keep[sel], w[sel] / w[sel].sum()
        Fk = F[keep]
        Minv = np.linalg.inv(np.einsum("x,xsij->sij", w, Fk))
        g = np.einsum("sij,xsji->xs", Minv, Fk) @ prior_w
        if it % 1000 == 999:
            gap = (np.einsum("sij,xsji->xs", Minv, F) @ prior_w).max() - n_p
            if gap < tol:
                return float(prior_w @ -np.linalg.slogdet(Minv)[1]), float(gap), it + 1
        w = w * g / n_p
        w /= w.sum()
    return float(prior_w @ -np.linalg.slogdet(Minv)[1]), float(gap), max_iter


def _local(model, rep):
    from oed.approximate import approximate_design
    r, t = _timed(lambda: approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0)), rep)
    print(f"local D: t = {np.round(r.points[:, 0], 4).tolist()}, weights {np.round(r.weights, 7).tolist()}, "
          f"equivalence max {r.sensitivity_max:.10f} (|max - 3| = {abs(r.sensitivity_max - 3):.1e}), "
          f"{len(r.sensitivity)} points checked, {t:.3f} s")


def _bayes(model, rep, brute):
    from oed.approximate import ApproximateSettings, approximate_design
    for half in (1.0, 4.0):
        prior = {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 4.298 - half, 4.298 + half)}
        for crit in "DAE":
            r, t = _timed(lambda: approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), criterion=crit,
                                                     prior=prior,
                                                     settings=ApproximateSettings(prior_order=20)), rep)
            print(f"bayes {crit}, theta2 +- {half:g}, 20 x 20: {len(r.weights)} points "
                  f"t = {np.round(r.points[:, 0], 4).tolist()} w = {np.round(r.weights, 4).tolist()}; "
                  f"max {r.sensitivity_max:.8g} vs {r.reference:.8g} (gap {r.gap:.1e}), efficiency >= "
                  f"{r.efficiency_bound:.8f}, value {r.value:.8f}, quadrature error ~ {r.quadrature_error:.1e}, "
                  f"{t:.2f} s")
            if crit == "D" and brute:
                T = np.r_[np.linspace(0.0, 2.0, 2001), np.linspace(2.01, 24.0, 2200)]
                t0 = time.perf_counter()
                v, gap, its = brute_multiplicative(_fine_information(model, r.prior.points, T), r.prior.weights, 3)
                print(f"  brute force ({T.size} times, {its} iterations, {time.perf_counter() - t0:.0f} s): "
                      f"E log det {v:.8f} (its gap {gap:.1e}); engine - brute = {r.value - v:.2e}")


def _maximin(model, rep, n_fine):
    from oed.approximate import ApproximateSettings, approximate_design
    box = {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 2.298, 6.298)}
    for crit in "DA":
        r, t = _timed(lambda: approximate_design(model, P0, sigma=1.0, bounds=(0.0, 24.0), criterion=crit,
                                                 prior=box, robust="maximin",
                                                 settings=ApproximateSettings(prior_order=3)), rep)
        t0 = time.perf_counter()
        effs = []
        for t1 in np.linspace(0.04884, 0.06884, n_fine):
            for t2 in np.linspace(2.298, 6.298, n_fine):
                p = np.array([t1, t2, 21.8])
                loc = approximate_design(model, p, sigma=1.0, bounds=(0.0, 24.0), criterion=crit)
                M = np.einsum("x,xij->ij", r.weights, _fine_information(model, [p], r.points[:, 0])[:, 0])
                if crit == "D":
                    effs.append(np.exp((np.linalg.slogdet(M)[1] - loc.value) / 3))
                else:
                    effs.append(-loc.value / np.trace(np.linalg.inv(M)))
        diff = abs(min(effs) - r.worst_case_bound)
        print(f"maximin {crit}, 3 x 3: {len(r.weights)} points t = {np.round(r.points[:, 0], 4).tolist()} "
              f"w = {np.round(r.weights, 4).tolist()}; worst-case efficiency {r.value:.6f}, certified >= "
              f"{r.worst_case_bound:.6f}, maximin ratio >= {r.efficiency_bound:.6f}, {t:.2f} s; brute force over "
              f"{n_fine} x {n_fine}: min efficiency {min(effs):.6f} (|difference| {diff:.1e}), "
              f"{time.perf_counter() - t0:.0f} s")


def _reactor(rep):
    from mudoe.example_reactor import P_TRUE, build
    from oed.approximate import ApproximateSettings, approximate_design
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]])
    for prior in (None, {"E1": ("uniform", 55.0, 65.0), "E2": ("uniform", 75.0, 85.0)}):
        r, t = _timed(lambda: approximate_design(m, P_TRUE, sigma=np.array([0.01, 0.008]), bounds=(0.0, 2.0),
                                                 inputs=Q, prior=prior,
                                                 settings=ApproximateSettings(grid=41, rounds=6, prior_order=3)), rep)
        print(f"reactor {r.robust} D sampling times: t = {np.round(r.points[:, 0], 4).tolist()} "
              f"w = {np.round(r.weights, 4).tolist()}; max {r.sensitivity_max:.8g} (gap {r.gap:.1e}), "
              f"{t:.2f} s")


def _exact_line(label, F, w, n, names, crit="D", robust="bayes", u_star=None, rep=1, enum_max=300_000):
    """Both routes of select_robust_exact on one instance (enumeration only up to enum_max sets): one line."""
    from oed.robust_exact import select_robust_exact
    kw = dict(criterion=crit, robust=robust, u_star=u_star, names=names, time_limit=30.0)
    b, tb = _timed(lambda: select_robust_exact(F, w, n, method="bnb", **kw), rep)
    total = math.comb(F.shape[0], n)
    enum = "enumeration not run"
    if total <= enum_max:
        e, te = _timed(lambda: select_robust_exact(F, w, n, method="enumerate", max_designs=10 ** 9, **kw), rep)
        same = "same value" if abs(e.value - b.value) <= 1e-9 * max(1.0, abs(e.value)) else "DIFFERENT VALUE"
        enum = f"enumeration {te:.3f} s ({same}{', same set' if e.indices == b.indices else ''})"
    print(f"{label}: {robust} {crit}, {n} of {F.shape[0]} ({total} sets), {F.shape[1]} vectors: {list(b.names)}, "
          f"value {b.value:.9g}, {b.status} (gap {b.gap:.1e}), B&B {tb:.3f} s, {b.nodes} nodes, {b.n_designs} sets "
          f"evaluated; {enum}", flush=True)
    return b


def _u_star(F, n, crit):
    from oed.robust_exact import select_robust_exact
    return np.array([select_robust_exact(F[:, [s]], [1.0], n, criterion=crit, time_limit=30.0).value
                     for s in range(F.shape[1])])


def _exact(rep):
    """Exact robust n-run designs (enumeration and branch-and-bound) at the shipped studies' sizes and beyond: press
    sensors (2 of the paper's 3; 2..10 of the 20 extended sensors) with k5, k7 ~ U(400, 600), the reactor's sampling
    times (4 of the shipped 10; 4..8 of 40) with E1 ~ U(55, 65), E2 ~ U(75, 85); efficiency against the approximate
    design and the local design's efficiency across the prior."""
    from identification import information_contributions
    from models.press import K_NOMINAL, press_model
    from oed import make_prior
    from oed.robust_exact import set_efficiencies
    for extra, sizes in ((False, (2,)), (True, (2, 3, 4, 6, 8, 10))):
        m = press_model(extra_sensors=extra)
        p = np.array(K_NOMINAL)
        pr = make_prior({"k5": ("uniform", 400.0, 600.0), "k7": ("uniform", 400.0, 600.0)}, m, p, order=5)
        info = lambda ps: information_contributions(m, None, ps, inputs=np.array([[500.0]]), sigma=0.01)[0]
        F, F0 = np.stack([info(ps) for ps in pr.points], axis=1), info(p)[:, None]
        for n in sizes:
            for crit in ("D", "E"):
                for robust in ("bayes", "maximin"):
                    us = _u_star(F, n, crit) if robust == "maximin" else None
                    b = _exact_line(f"press ({m.n_S} sensors)", F, pr.weights, n, list(m.sensors), crit, robust, us,
                                    rep)
                    if robust == "bayes":
                        loc = _exact_line("  local at p", F0, [1.0], n, list(m.sensors), crit, rep=1)
                        e = set_efficiencies(crit, F, loc.indices, b.indices)
                        print(f"  local design {list(loc.names)} across the prior against the robust one: min "
                              f"{e.min():.6f}, mean {pr.weights @ e:.6f}, max {e.max():.6f}")
    _exact_reactor(rep)
    _exact_synthetic(rep)


def _exact_synthetic(rep):
    """A size far beyond enumeration: random rank-1 information (a common direction per candidate plus 0.3 x a
    per-vector perturbation), 40 candidates, 9 vectors, n_p = 4, choose 10 (848 million sets), seed 1."""
    rng = np.random.default_rng(1)
    C, S, p, n = 40, 9, 4, 10
    A = rng.normal(size=(C, 1, 1, p)) + 0.3 * rng.normal(size=(C, S, 1, p))
    F = np.einsum("csri,csrj->csij", A, A)
    for crit in "DAE":
        _exact_line("synthetic", F, np.full(S, 1.0 / S), n, [f"c{k}" for k in range(C)], crit, rep=rep)


def _exact_reactor(rep):
    from mudoe.config import load_config
    from mudoe.example_reactor import P_TRUE, build
    from oed import information, make_prior
    from oed.approximate import ApproximateSettings, approximate_design
    from oed.robust_exact import set_efficiencies
    from pathlib import Path
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "reactor.toml")
    from mudoe.kind.time_series import experiment_rows
    Q = experiment_rows(cfg, build())
    sigma = np.array([s.sigma for s in cfg.sensors], float)
    m = build()
    narrow = {"E1": ("uniform", 55.0, 65.0), "E2": ("uniform", 75.0, 85.0)}
    wide = {"E1": ("uniform", 45.0, 75.0), "E2": ("uniform", 65.0, 95.0)}
    shipped = np.asarray(cfg.dynamic.times, float)
    for times, sizes, order, prior in ((shipped, (cfg.dynamic.n_times,), 3, narrow),
                                       (shipped, (cfg.dynamic.n_times,), 5, narrow),
                                       (shipped, (cfg.dynamic.n_times,), 5, wide),
                                       (np.linspace(0.05, 2.0, 40), (4, 6, 8), 3, narrow),
                                       (np.linspace(0.05, 2.0, 40), (6,), 5, wide)):
        pr = make_prior(prior, m, P_TRUE, order=order)
        print(f"prior: {prior}", flush=True)
        t0 = time.perf_counter()
        info = lambda ps: information(m, ps, axis="times", times=times, inputs=Q, sigma=sigma).F
        F, F0 = np.stack([info(ps) for ps in pr.points], axis=1), info(P_TRUE)[:, None]
        t_info = time.perf_counter() - t0
        ap, t_ap = _timed(lambda: approximate_design(m, P_TRUE, sigma=sigma, bounds=(times.min(), times.max()),
                                                     inputs=Q, prior=pr, settings=ApproximateSettings(grid=41,
                                                                                                      rounds=6)), 1)
        print(f"reactor ({Q.shape[0]} experiments of configs/reactor.toml, {times.size} times, {pr.n} vectors): "
              f"information {t_info:.2f} s; Bayesian D approximate design t = {np.round(ap.points[:, 0], 4).tolist()} "
              f"w = {np.round(ap.weights, 3).tolist()} (gap {ap.gap:.1e}), {t_ap:.2f} s", flush=True)
        names = [f"{t:g}" for t in times]
        for n in sizes:
            for crit in ("D", "A", "E"):
                b = _exact_line("reactor", F, pr.weights, n, names, crit, rep=rep)
                loc = _exact_line("  local at P_TRUE", F0, [1.0], n, names, crit, rep=1)
                e = set_efficiencies(crit, F, loc.indices, b.indices)
                msg = ""
                if crit == "D":
                    msg = (f"; exact design's efficiency against the approximate one "
                           f"{np.exp((b.value - ap.value) / F.shape[2]):.6f}")
                print(f"  local design across the prior against the robust one: min {e.min():.6f}, mean "
                      f"{pr.weights @ e:.6f}, max {e.max():.6f}{msg}")
            us = _u_star(F, n, "D")
            _exact_line("reactor", F, pr.weights, n, names, "D", "maximin", us, rep)


def _library(argv) -> None:
    """Session 12's parts (bench/robust_library.py): sparse grids, sequential designs under a prior, refined exact
    robust designs; ``--library=sparse,sequential,refined`` picks some."""
    from bench import robust_library as lib
    picked = next((a.split("=", 1)[1].split(",") for a in argv if a.startswith("--library=")),
                  ["sparse", "sequential", "refined"])
    if "sparse" in picked:
        lib.sparse_grids(compartmental())
    if "sequential" in picked:
        lib.sequential()
    if "refined" in picked:
        lib.refined()


def main(argv=None) -> None:
    argv = list(argv or [])
    rep = next((int(a.split("=")[1]) for a in argv if a.startswith("--rep=")), 3)
    brute = "--no-brute" not in argv
    if any(a.startswith("--library") for a in argv):
        print(f"machine: {platform.node()} {platform.machine()}, python {platform.python_version()}; "
              f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
        _library(argv)
        return
    if "--exact-only" in argv:
        print(f"machine: {platform.node()} {platform.machine()}, python {platform.python_version()}; "
              f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
        _exact(rep)
        return
    print(f"machine: {platform.node()} {platform.machine()}, python {platform.python_version()}; "
          f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC")
    model = compartmental()
    _local(model, rep)
    _bayes(model, rep, brute)
    _maximin(model, 1, 21 if brute else 5)
    _reactor(1)
    _exact(rep)
    _library(argv)


if __name__ == "__main__":
    import sys
    main(sys.argv[1:])
