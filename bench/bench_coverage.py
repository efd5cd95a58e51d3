"""Monte Carlo coverage of 95 % marginal intervals: Wald, profile likelihood, parametric bootstrap (issue 12).

For every case, ``--reps`` campaigns are simulated from the model at the true parameters
(z = h(p*) + sigma eps, sigma known), each is fitted with :func:`identification.identify`,
and the 95 % intervals of every parameter are computed by

* ``wald``: p_i -+ z_0.975 se_i (second-order covariance, the default ``conf_int``);
* ``profile``: {theta : D_i(theta) <= chi2_1(0.95)} (:mod:`identification.inference.profile`);
* ``bootstrap`` (``--boot=N`` > 0): percentile interval of N parametric-bootstrap refits.

Coverage = share of campaigns whose interval holds p*_i, with its Clopper-Pearson 95 %
interval.  A failed fit or a profile that raised is counted (column ``failed``), never
dropped silently; coverage is over the campaigns where that method produced an interval.

Cases:

* ``mm``: Michaelis-Menten y = V x / (K + x) below saturation (x = 0.5..4, V = 10, K = 10,
  sigma 0.25): 2 parameters, 5 inputs, 2 series, sigma known; ``mm_deep`` the same further below
  saturation (K = 20, sigma 0.1);
* ``truss_Px`` / ``truss_Py``: the README's two-bar truss (k1 = 210, k2 = 290 N/mm) measured
  with one sensor only (P_x or P_y), 4 series, 21 loads, sigma 4 um;
* ``press``: the press linkage M1 (k5, k7) at its fit to the shipped campaign, 2 series, the
  29 set points, sensors D_y and F_x with the campaign's composed sigma.

Run ``python -m bench coverage --reps=1000 --workers=2 --cases=mm,mm_deep,truss_Px --jsonl=cov.jsonl``
(every replication is appended to cov.jsonl as it finishes), then
``python -m bench coverage --tabulate=cov.jsonl --check-misses`` for the table of a finished or partial run
and the scipy check of every profile miss of the Michaelis-Menten cases.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from identification import IdentificationError, Measurements, identify
from identification.studies.montecarlo import clopper_pearson
from identification.inference.profile import ProfileError
from models import Model

CASES = ("mm", "mm_deep", "truss_Px", "truss_Py", "press")
METHODS = ("wald", "profile", "bootstrap")


@dataclass(frozen=True, eq=False)
class Case:
    """A coverage case: model, truth, design, noise and start values."""

    name: str
    model: Model
    p_true: np.ndarray
    inputs: np.ndarray
    sigma: np.ndarray
    n_M: int
    weights: np.ndarray
    p0: np.ndarray
    description: str


def _mm(K: float, sigma: float, name: str) -> Case:
    model = Model.explicit(params=["V", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="Michaelis-Menten")
    model = model.with_bounds({"V": (1e-3, 1e6), "K": (1e-3, 1e6)})
    x = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    return Case(name, model, np.array([10.0, K]), x[:, None], np.array([sigma]), 2, np.ones(1),
                np.array([10.0, K]), f"V x / (K + x), V = 10, K = {K:g}, x = 0.5..4, 2 series, sigma {sigma:g}")


def _truss(sensor: str) -> Case:
    from models.library import two_bar_truss
    model = two_bar_truss("truss linear")
    q = np.r_[np.linspace(0, 1000, 11), np.linspace(1000, 0, 11)[1:]]
    w = np.array([1.0 if s == sensor else 0.0 for s in model.sensors])
    return Case(f"truss_{sensor[-2:]}", model, np.array([210.0, 290.0]), q[:, None], np.array([0.004, 0.004]), 4,
                w, np.array([200.0, 300.0]), f"README two-bar truss, sensor {sensor} only, 4 series x 21 loads, "
                "sigma 4 um")


def _press() -> Case:
    from models.friction import candidate_models, model_inputs
    from models.prototype import TEST_SERIES, composed_sigma, read_campaign
    from models.press import K_NOMINAL
    campaign = read_campaign()
    model = candidate_models()["M1"]
    inputs = model_inputs("M1", campaign.q_set)
    sigma = composed_sigma(campaign.z) * 1e-3
    w = np.array([1.0 if s in ("D_y", "F_x") else 0.0 for s in model.sensors])
    data = Measurements(inputs, campaign.z[list(TEST_SERIES)], sigma, sensors=campaign.sensors)
    p_true = identify(model, data, K_NOMINAL, weights=w).p
    return Case("press", model, np.asarray(p_true), inputs, sigma, 2, w, np.asarray(K_NOMINAL, float),
                f"press M1 at its fit ({p_true[0]:.1f}, {p_true[1]:.1f}) N/mm, 29 set points, 2 series, "
                "sensors D_y, F_x, composed sigma")


def build_case(name: str) -> Case:
    if name == "mm":
        return _mm(10.0, 0.25, name)
    if name == "mm_deep":
        return _mm(20.0, 0.1, name)
    if name in ("truss_Px", "truss_Py"):
        return _truss("P_" + name[-1].lower())
    if name == "press":
        return _press()
    raise ValueError(f"cases: unknown case {name!r}; choose from {', '.join(CASES)}")


class _Cache:
    """Cases built once per process."""

    cases: dict = {}
    truth_h: dict = {}


def _case(name: str) -> tuple:
    if name not in _Cache.cases:
        c = build_case(name)
        _Cache.cases[name] = c
        _Cache.truth_h[name] = c.model.simulate(c.p_true, c.inputs)
    return _Cache.cases[name], _Cache.truth_h[name]


def replicate(name: str, seed: np.random.SeedSequence, n_boot: int) -> dict:
    """One campaign of case ``name``: coverage (1/0, NaN if failed) per method and parameter, and errors."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    c, H = _case(name)
    rng = np.random.default_rng(seed)
    z = H[None] + c.sigma * rng.standard_normal((c.n_M,) + H.shape)
    data = Measurements(c.inputs, z, c.sigma, sensors=c.model.sensors)
    out = {m: np.full(c.model.n_p, np.nan) for m in METHODS}
    out["errors"] = []
    out["inf"] = 0
    out["t_profile"] = math.nan
    out["flagged"] = math.nan
    try:
        est = identify(c.model, data, c.p0, weights=c.weights)
    except IdentificationError as exc:
        out["errors"].append(("fit", str(exc).splitlines()[0][:200]))
        return out
    try:
        out["flagged"] = float(not est.curvature.trustworthy)
    except (np.linalg.LinAlgError, ValueError, IdentificationError) as exc:     # NotBoundedError: no curvature
        out["errors"].append(("curvature", str(exc).splitlines()[0][:200]))
    ci = np.asarray(est.conf_int(0.05))
    out["wald"] = ((ci[:, 0] <= c.p_true) & (c.p_true <= ci[:, 1])).astype(float)
    t0 = time.perf_counter()
    try:
        pr = est.conf_int(0.05, method="profile", model=c.model, data=data)
        out["profile"] = ((pr.lower <= c.p_true) & (c.p_true <= pr.upper)).astype(float)
        out["inf"] = int(np.sum(~np.isfinite(pr.lower)) + np.sum(~np.isfinite(pr.upper)))
    except (ProfileError, IdentificationError) as exc:
        out["errors"].append(("profile", str(exc).splitlines()[0][:200]))
    out["t_profile"] = time.perf_counter() - t0
    if n_boot:
        try:
            bs = est.conf_int(0.05, method="bootstrap", model=c.model, data=data, n=n_boot,
                              seed=int(rng.integers(2 ** 31)))
            out["bootstrap"] = ((bs.lower <= c.p_true) & (c.p_true <= bs.upper)).astype(float)
            if bs.n_failed:
                out["errors"].append(("bootstrap", f"{bs.n_failed} of {n_boot} refits failed"))
        except IdentificationError as exc:
            out["errors"].append(("bootstrap", str(exc).splitlines()[0][:200]))
    return out


def _chunk(name, items, n_boot):
    return [(i, replicate(name, s, n_boot)) for i, s in items]


def _save(path, name: str, items: list) -> None:
    """Append replications (index, result) of case ``name`` to a JSON-lines file (partial runs survive)."""
    if path is None:
        return
    with open(path, "a", encoding="utf-8") as f:
        for i, r in items:
            row = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()}
            f.write(json.dumps(dict(case=name, index=i, **row), allow_nan=True) + "\n")


def load(path) -> dict:
    """Replications saved by ``--jsonl``: {case: [result, ...]} (arrays restored, by index)."""
    out = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            row = json.loads(line)
            name, i = row.pop("case"), row.pop("index")
            for m in METHODS:
                row[m] = np.asarray(row[m], float)
            out.setdefault(name, {})[i] = row
    return {name: [rows[i] for i in sorted(rows)] for name, rows in out.items()}


def run_case(name: str, reps: int, seed: int, n_boot: int, workers: int, jsonl=None) -> list:
    children = np.random.SeedSequence([seed, CASES.index(name)]).spawn(reps)
    items = list(enumerate(children))
    size = max(1, min(10, reps // (4 * workers) or 1))
    chunks = [items[k:k + size] for k in range(0, reps, size)]
    res = [None] * reps
    if workers == 1:
        for ch in chunks:
            done = _chunk(name, ch, n_boot)
            _save(jsonl, name, done)
            for i, r in done:
                res[i] = r
    else:
        import multiprocessing as mp
        with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn")) as pool:
            for fut in as_completed([pool.submit(_chunk, name, ch, n_boot) for ch in chunks]):
                done = fut.result()
                _save(jsonl, name, done)
                for i, r in done:
                    res[i] = r
    return res


def table(name: str, res: list, n_boot: int) -> list:
    c, _ = _case(name)
    rows = []
    for m in METHODS:
        if m == "bootstrap" and not n_boot:
            continue
        A = np.array([r[m] for r in res])
        for i, p in enumerate(c.model.param_names):
            ok = np.isfinite(A[:, i])
            rate = clopper_pearson(int(A[ok, i].sum()), int(ok.sum()))
            rows.append((name, m, p, rate, int((~ok).sum())))
    return rows


def press_timing(repeat: int = 5) -> str:
    """Wall time of both 95 % profile intervals of M1 fitted to the shipped campaign (held-out series)."""
    from models.friction import candidate_models, model_inputs
    from models.prototype import TEST_SERIES, composed_sigma, read_campaign
    from models.press import K_NOMINAL
    campaign = read_campaign()
    model = candidate_models()["M1"]
    data = Measurements(model_inputs("M1", campaign.q_set), campaign.z[list(TEST_SERIES)],
                        composed_sigma(campaign.z) * 1e-3, sensors=campaign.sensors)
    w = [1.0 if s in ("D_y", "F_x") else 0.0 for s in model.sensors]
    est = identify(model, data, K_NOMINAL, weights=w)
    est.conf_int(0.05, method="profile", model=model, data=data)          # warm the caches
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        ci = est.conf_int(0.05, method="profile", model=model, data=data)
        times.append(time.perf_counter() - t0)
    wald = np.asarray(est.conf_int(0.05))
    return (f"press, shipped campaign (series {TEST_SERIES}), M1: both 95 % profile intervals in "
            f"median {np.median(times):.3f} s (min {min(times):.3f}, max {max(times):.3f}, {repeat} runs); "
            f"k5 [{ci.lower[0]:.2f}, {ci.upper[0]:.2f}] (Wald [{wald[0, 0]:.2f}, {wald[0, 1]:.2f}]), "
            f"k7 [{ci.lower[1]:.2f}, {ci.upper[1]:.2f}] (Wald [{wald[1, 0]:.2f}, {wald[1, 1]:.2f}]) N/mm")


def report(name: str, res: list, n_boot: int, wall: float = math.nan) -> None:
    """Print the markdown rows of one case: coverage per method and parameter, the share of fits
    flagged not trustworthy (Bates-Watts curvature), failures and profile timing."""
    c, _ = _case(name)
    fl = np.array([r.get("flagged", math.nan) for r in res], float)
    ok = np.isfinite(fl)
    flagged = clopper_pearson(int(fl[ok].sum()), int(ok.sum()))
    for case, m, p, rate, failed in table(name, res, n_boot):
        print(f"| {case} | {m} | {p} | {rate} | {failed} | {flagged} |")
    errs = [e for r in res for e in r["errors"]]
    n_inf = sum(r["inf"] > 0 for r in res)
    tp = np.array([r["t_profile"] for r in res], float)
    print(f"  {c.description}; {len(res)} campaigns, {n_inf} with an unbounded profile side; "
          f"profile time median {np.nanmedian(tp):.3f} s, max {np.nanmax(tp):.3f} s; case wall {wall:.0f} s")
    for kind in ("fit", "curvature", "profile", "bootstrap"):
        ek = [e[1] for e in errs if e[0] == kind]
        if ek:
            print(f"  {len(ek)} {kind} failures; first: {ek[0]}")


def check_misses(name: str, res: list, seed: int) -> str:
    """Independent check of the profile's misses on the Michaelis-Menten cases: for every campaign whose
    profile interval misses the truth p*_i, D_i(p*_i) = min over the other parameter of S - min S (scipy,
    several starts, S the chi2 sum) must exceed chi2_1(0.95); a miss with D_i(p*_i) below it is a wrong
    profile interval."""
    from scipy import optimize, stats
    if not name.startswith("mm"):
        return f"{name}: the miss check is implemented for the Michaelis-Menten cases only"
    c, H = _case(name)
    children = np.random.SeedSequence([seed, CASES.index(name)]).spawn(len(res))
    x, sig, crit = c.inputs[:, 0], float(c.sigma[0]), float(stats.chi2.ppf(0.95, 1))
    checked, wrong = 0, []
    for i, r in enumerate(res):
        prof = np.asarray(r["profile"], float)
        if not np.any(prof == 0.0):
            continue
        z = (H[None] + c.sigma * np.random.default_rng(children[i]).standard_normal((c.n_M,) + H.shape))[:, :, 0]

        def S(V, K):
            return float(np.sum(((z - V * x / (K + x)) / sig) ** 2))

        best = min(optimize.minimize(lambda q: S(*np.exp(q)), np.log([v0, k0]), method="Nelder-Mead",
                                     options=dict(xatol=1e-10, fatol=1e-12, maxiter=4000)).fun
                   for v0 in (5, 10, 30, 100) for k0 in (3, 10, 30, 100))
        for j in np.flatnonzero(prof == 0.0):
            t = c.p_true[j]
            f = (lambda o: S(t, np.exp(o))) if j == 0 else (lambda o: S(np.exp(o), t))
            m = min(optimize.minimize_scalar(f, bracket=(math.log(b), math.log(b) + 0.1)).fun
                    for b in (1, 5, 10, 20, 50, 200))
            checked += 1
            if m - best <= crit:
                wrong.append(f"campaign {i} {c.model.param_names[j]}: D = {m - best:.4f}")
    return (f"{name}: {checked} profile misses checked with scipy, {len(wrong)} wrong (D_i(truth) <= chi2_1(0.95))"
            + (": " + "; ".join(wrong[:5]) if wrong else ""))


HEADER = ("| case | method | parameter | coverage [CP 95 %] | failed | fits flagged not trustworthy [CP 95 %] |\n"
          "|---|---|---|---|---|---|")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench coverage")
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--boot", type=int, default=0, help="bootstrap refits per campaign (0: no bootstrap)")
    ap.add_argument("--boot-cases", default="mm,mm_deep,truss_Px,truss_Py", help="cases that get the bootstrap")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--jsonl", default=None, help="append every replication to this JSON-lines file as it finishes")
    ap.add_argument("--tabulate", default=None, help="only print the table of a --jsonl file (partial runs too)")
    ap.add_argument("--check-misses", action="store_true",
                    help="with --tabulate: check every profile miss of the Michaelis-Menten cases with scipy")
    args = ap.parse_args(argv or [])
    names = [n for n in args.cases.split(",") if n]
    boot_cases = set(args.boot_cases.split(","))
    if args.tabulate:
        print(HEADER)
        for name, res in load(args.tabulate).items():
            report(name, res, args.boot if name in boot_cases else 0)
            if args.check_misses:
                print("  " + check_misses(name, res, args.seed))
        return
    print(f"machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} cpus; "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"reps {args.reps}, seed {args.seed}, bootstrap n {args.boot} on {sorted(boot_cases)}, "
          f"workers {args.workers}")
    if "press" in names:
        print(press_timing())
    print(HEADER)
    for name in names:
        t0 = time.perf_counter()
        n_boot = args.boot if name in boot_cases else 0
        res = run_case(name, args.reps, args.seed, n_boot, args.workers, args.jsonl)
        report(name, res, n_boot, time.perf_counter() - t0)
