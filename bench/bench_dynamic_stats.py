r"""Statistics of Algorithm 1 and of the confidence regions on a dynamic model (issue 22, "Statistics").

The batch reactor A -> B -> C (:mod:`mudoe.example_reactor`, isothermal, Arrhenius rates; p* =
(k1_ref, E1, k2_ref, E2) = (2, 60, 0.8, 80)) with 6 experiments (c_A0 = 1, 2 mol/L x T = 330, 350,
370 K), 10 sampling times 0.2..2 h, sensors c_A and c_B (sigma 0.01 mol/L), n_M = 2 series.  The
data of every replication come from the **exact ODE** (scipy ``solve_ivp``, DOP853, rtol 1e-10,
atol 1e-12), never from the collocated model, so the discretisation error of the fits is part of
what is measured.  The model tested is the collocation of :func:`identification.fit.dynamic_fit.identify_dynamic`
at the default discretisation settings (the mesh its error control chose on a nominal campaign).

Studies (``--study``):

* ``size``: data from the first-order model (correct), Algorithm 1 with three splits (experiments
  c_A0 = 1 vs 2, series 1 vs 2, early t <= 1 h vs late t > 1 h on the flat ``sensor@time`` columns);
  family-wise rejection rate at TOL = 5 % (Bonferroni over the splits) of the likelihood ratio,
  two-sample Wald and paper statistics, and the coverage of the 95 % ellipsoids of every
  calibration and validation fit; the replication engine (:func:`identification.studies.montecarlo.run_monte_carlo`,
  batched fits, ``--workers`` local processes).
* ``coarse``, ``deg2``, ``deg3``: the same data tested with a deliberately coarse fixed mesh (one
  element between sampling times, no error control) of Radau IIA degree 1 (implicit Euler; output
  error up to 31 sigma), 2 (2.8 sigma) and 3 (0.05 sigma): evidence that the control matters, and
  how much error the tests tolerate.
* ``power``: data from a second-order A consumption (dc_A/dt = -k1 c_A^2, k1_ref = 1.5 L/(mol h)),
  tested with the first-order model (its collocation controlled at its fit to a nominal
  second-order campaign).
* ``coverage``: full-campaign fits (:func:`identification.identify` on the collocated model):
  coverage of the 95 % ellipsoid (second-order and Gauss-Newton covariances) and of the 95 %
  profile-likelihood intervals of every parameter (:func:`identification.inference.profile.profile_intervals`,
  for the first ``--profile-reps`` replications).

Every study is seeded and resumable: the engine studies run in blocks of ``--block`` replications
(block b uses seed ``--seed`` + b), each saved to ``--out``_<study>_<b>.npz; the coverage study
appends one JSON line per replication to ``--out``_coverage.jsonl.  A rerun skips what is done;
``--tabulate`` prints the table of what is there (binomial standard errors sqrt(p (1 - p) / n)
and Clopper-Pearson 95 % intervals).

Run: ``python -m bench.bench_dynamic_stats --study=size --reps=1000 --workers=2`` (and coarse,
power, coverage), then ``python -m bench.bench_dynamic_stats --tabulate``.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy import stats
from scipy.integrate import solve_ivp

from identification import DynamicMeasurements, Measurements, identify
from identification.fit.dynamic_fit import collocated_problem, identify_dynamic
from identification.errors import IdentificationError
from identification.studies.normality import gate_fails
from identification.studies.montecarlo import MonteCarloSettings, clopper_pearson, linearized_size, run_monte_carlo
from identification.inference.profile import ProfileError, profile_intervals
from identification.inference.regions import mahalanobis2
from identification.studies.splits import Split, early_late_split, series_split
from mudoe import example_reactor as er

SIGMA = np.array([0.01, 0.01])               # mol/L, c_A and c_B
INPUTS = np.array([[c, T] for T in (330.0, 350.0, 370.0) for c in (1.0, 2.0)])
N_M = 2
P_SECOND = np.array([1.5, 60.0, 0.8, 80.0])  # truth of the wrong-rate-law study (k1_ref in L/(mol h))
TOL = 0.05
FIXED_MESH = {"coarse": 1, "deg2": 2, "deg3": 3}      # fixed-mesh studies: Radau degree on the sampling grid
STUDIES = ("size", "power", "coverage") + tuple(FIXED_MESH)


class ExactReactor:
    r"""Campaigns z = h(x(t), p*, q) + sigma eps from the exact ODE (solve_ivp, rtol 1e-10), flat form.

    ``order`` 1: dc_A/dt = -k1 c_A (the model); 2: dc_A/dt = -k1 c_A^2 (a wrong rate law for the model),
    dc_B/dt = r1 - k2 c_B in both.  Picklable; the noise-free outputs are computed once.
    """

    def __init__(self, order: int, p, pairs, n_M: int = N_M):
        self.order, self.p, self.n_M = int(order), np.asarray(p, float), int(n_M)
        self.pairs = tuple(pairs)
        times = np.unique([t for _, t in self.pairs])
        self.H = np.empty((INPUTS.shape[0], len(self.pairs)))
        for j, (c0, T) in enumerate(INPUTS):
            k1, k2 = (self.p[2 * i] * math.exp(-self.p[2 * i + 1] / er.R_KJ * (1 / T - 1 / er.T_REF)) for i in (0, 1))

            def rhs(t, x, k1=k1, k2=k2):
                r1 = k1 * x[0] ** self.order
                return [-r1, r1 - k2 * x[1], k2 * x[1]]
            sol = solve_ivp(rhs, (0.0, float(times[-1])), [c0, 0.0, 0.0], method="DOP853", t_eval=times,
                            rtol=1e-10, atol=1e-12)
            if not sol.success:
                raise RuntimeError(f"solve_ivp failed for experiment {j}: {sol.message}")
            for k, (s, t) in enumerate(self.pairs):
                self.H[j, k] = sol.y[("cA", "cB").index(s), int(np.searchsorted(times, t))]
        self.sigma = np.array([SIGMA[("cA", "cB").index(s)] for s, _ in self.pairs])
        self.sensors = tuple(f"{s}@{t:g}" for s, t in self.pairs)

    def dynamic(self, rng) -> DynamicMeasurements:
        """One campaign in the dynamic form (for identify_dynamic)."""
        z = self.H[None] + self.sigma * rng.standard_normal((self.n_M,) + self.H.shape)
        times = np.unique([t for _, t in self.pairs])
        zz = z.reshape(self.n_M, INPUTS.shape[0], times.size, 2)       # pairs are time-major (cA, cB at each t)
        return DynamicMeasurements(INPUTS, times, zz, SIGMA, sensors=("cA", "cB"), input_names=("cA0", "T"))

    def __call__(self, rng) -> Measurements:
        z = self.H[None] + self.sigma * rng.standard_normal((self.n_M,) + self.H.shape)
        return Measurements(INPUTS, z, self.sigma, sensors=self.sensors, input_names=("cA0", "T"))


def problem(study: str):
    """(collocated model, generator, splits, p0, truth or None, description) of a study."""
    model = er.build("isothermal")
    pairs = [(s, float(t)) for t in er.TIMES for s in ("cA", "cB")]
    order = 2 if study == "power" else 1
    gen = ExactReactor(order, P_SECOND if order == 2 else er.P_TRUE, pairs)
    nominal = gen.dynamic(np.random.default_rng(12345))
    if tuple(nominal.pairs) != tuple(pairs):
        raise RuntimeError(f"flat column order {nominal.pairs[:4]}... differs from the generator's {pairs[:4]}...")
    if study in FIXED_MESH:
        deg = FIXED_MESH[study]
        cm, _ = collocated_problem(model, nominal, degree=deg, elements=1)
        err = np.abs(cm.integrated_outputs(gen.p, INPUTS) - gen.H).max() / SIGMA[0]
        how = (f"fixed mesh: Radau IIA degree {deg}{' (implicit Euler)' if deg == 1 else ''}, elements between "
               f"the sampling times only, no error control; largest output error at p* {err:.3g} sigma")
    else:
        est = identify_dynamic(model, nominal, er.P_TRUE)
        rec = est.diagnostics.discretisation
        cm = est.model
        how = (f"controlled mesh of identify_dynamic at the default settings: degree {rec.degree}, "
               f"{rec.n_elements} elements, error {100 * rec.error_sigma:.2g} % sigma")
    splits = (Split("experiments cA0 = 1 vs 2", [0, 2, 4], [1, 3, 5]), series_split(INPUTS.shape[0], [0], [1]),
              early_late_split(pairs, INPUTS.shape[0]))
    truth = None if study == "power" else er.P_TRUE
    return cm, gen, splits, er.P_TRUE, truth, how


def _engine_block(study: str, b: int, block: int, seed: int, workers: int, out: str) -> str:
    path = f"{out}_{study}_{b}.npz"
    if os.path.exists(path):
        return path
    cm, gen, splits, p0, truth, how = problem(study)
    st = MonteCarloSettings(n_rep=block, seed=seed + b, workers=workers, progress=False)
    t0 = time.time()
    res = run_monte_carlo({"first order": cm}, gen, splits, p0, truth=truth,
                          kind="power" if study == "power" else "size", settings=st, description=how)
    np.savez(path, alpha_lr=res.alpha_lr, alpha_two_sample=res.alpha_two_sample, alpha_paper=res.alpha_paper,
             covered=res.covered, shapiro=res.shapiro, n_errors=len(res.errors), wall=time.time() - t0,
             how=how, split_names=[s.name for s in splits], gated=np.array(res.gated, bool))
    print(f"{study} block {b}: {block} reps in {time.time() - t0:.0f} s, {len(res.errors)} failed split tests; "
          f"LR rejection {res.rejection_rate(statistic='likelihood_ratio')}", flush=True)
    return path


def _coverage_one(args) -> dict:
    r, seed, n_prof = args
    cm, gen = _COV["cm"], _COV["gen"]
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(r + 1)[r])
    data = gen(rng)
    out = {"r": r}
    try:
        est = identify(cm, data, er.P_TRUE)
    except IdentificationError as exc:
        return {**out, "fit_error": str(exc)}
    thr = stats.chi2.ppf(0.95, cm.n_p)
    out["ell_so"] = bool(mahalanobis2(er.P_TRUE, est.p, est.cov) <= thr)
    out["ell_gn"] = bool(mahalanobis2(er.P_TRUE, est.p, est.cov_gn) <= thr)
    out["wald"] = [bool(abs(a - b) <= 1.959963984540054 * s) for a, b, s in zip(est.p, er.P_TRUE, est.stderr)]
    if r < n_prof:
        try:
            ci = profile_intervals(cm, data, est, alpha=0.05)
            out["profile"] = [bool(lo <= t <= hi) for lo, hi, t in zip(ci.lower, ci.upper, er.P_TRUE)]
        except ProfileError as exc:
            out["profile_error"] = str(exc)
    return out


_COV: dict = {}


def _cov_init():
    cm, gen, *_ = problem("coverage")
    _COV.update(cm=cm, gen=gen)


def _coverage(reps: int, n_prof: int, seed: int, workers: int, out: str) -> None:
    path = f"{out}_coverage.jsonl"
    done = set()
    if os.path.exists(path):
        with open(path) as f:
            done = {json.loads(line)["r"] for line in f if line.strip()}
    todo = [(r, seed, n_prof) for r in range(reps) if r not in done]
    t0 = time.time()
    with ProcessPoolExecutor(workers, initializer=_cov_init) as ex, open(path, "a") as f:
        for i, res in enumerate(ex.map(_coverage_one, todo, chunksize=4)):
            f.write(json.dumps(res) + "\n")
            f.flush()
            if (i + 1) % 100 == 0:
                print(f"coverage: {i + 1}/{len(todo)} in {time.time() - t0:.0f} s", flush=True)


def _rate(k: int, n: int) -> str:
    if n == 0:
        return "n/a"
    p = k / n
    ci = clopper_pearson(int(k), int(n))
    return f"{100 * p:.2f} % +- {100 * math.sqrt(p * (1 - p) / n):.2f} ({k}/{n}; CP95 [{100 * ci.lo:.1f}, {100 * ci.hi:.1f}])"


def tabulate(out: str) -> None:
    """Print the results found under the prefix ``out``."""
    for study in ("size",) + tuple(FIXED_MESH) + ("power",):
        blocks = sorted((p for p in os.listdir(os.path.dirname(out) or ".")
                         if p.startswith(os.path.basename(out) + f"_{study}_") and p.endswith(".npz")))
        if not blocks:
            continue
        arr = [np.load(os.path.join(os.path.dirname(out) or ".", p)) for p in blocks]
        names = list(arr[0]["split_names"])
        print(f"\n{study}: {arr[0]['how']}; {len(blocks)} blocks, wall {sum(float(a['wall']) for a in arr):.0f} s")
        for stat in ("alpha_lr", "alpha_two_sample", "alpha_paper"):
            a = np.concatenate([x[stat][:, 0, :] for x in arr])
            rej = np.any(a < TOL / a.shape[1], axis=1)
            ok = rej | np.all(np.isfinite(a), axis=1)
            print(f"  {stat:17s} family-wise rejection at TOL 5 %: {_rate(int(rej[ok].sum()), int(ok.sum()))}"
                  f"; undecided {int((~ok).sum())}")
            for js, nm in enumerate(names):
                col = a[:, js]
                fin = np.isfinite(col)
                print(f"      split {nm!r}: rejected at TOL/{a.shape[1]} {_rate(int((col[fin] < TOL / a.shape[1]).sum()), int(fin.sum()))};"
                      f" at 5 %: {_rate(int((col[fin] < TOL).sum()), int(fin.sum()))}")
        sh = np.concatenate([x["shapiro"] for x in arr])
        fail = gate_fails(sh, 0.05, "holm", tuple(bool(g) for g in arr[0]["gated"]) or None)
        a = np.concatenate([x["alpha_lr"][:, 0, :] for x in arr])
        rej = np.any(a < TOL / a.shape[1], axis=1)
        print(f"  normality gate (Shapiro-Wilk per sensor, Holm over {sh.shape[1]} sensors, 5 %): fails "
              f"{_rate(int(fail.sum()), fail.size)}; LR family-wise rejection of the campaigns passing it: "
              f"{_rate(int(rej[~fail].sum()), int((~fail).sum()))}")
        cov = np.concatenate([x["covered"][:, 0] for x in arr])
        for js, nm in enumerate(names):
            for i, which in enumerate(("cal", "val")):
                c = cov[:, js, i]
                c = c[np.isfinite(c)]
                if c.size:
                    print(f"  ellipsoid 95 % coverage, {nm} {which}: {_rate(int(c.sum()), int(c.size))}")
        print(f"  failed split tests: {sum(int(x['n_errors']) for x in arr)}")
        if study != "power":
            cm, gen, splits, *_ = problem(study)
            lin = linearized_size(cm, er.P_TRUE, INPUTS, gen.sigma, splits, n_series=N_M, alpha=TOL)
            print(f"  linearised model (no fits, {lin.n_draws} draws, se <= {100 * lin.mc_se:.2f} %): family-wise size of "
                  f"the two-sample Wald = LR statistic {100 * lin.family_two_sample:.2f} %, per split at TOL/"
                  f"{len(splits)}: {np.round(100 * lin.split_two_sample, 2).tolist()} %; paper statistic "
                  f"{100 * lin.family_paper:.2f} %")
    path = f"{out}_coverage.jsonl"
    if os.path.exists(path):
        with open(path) as f:
            rows = [json.loads(line) for line in f if line.strip()]
        fits = [r for r in rows if "fit_error" not in r]
        print(f"\ncoverage (full campaign): {len(rows)} replications, {len(rows) - len(fits)} failed fits")
        for key, label in (("ell_so", "ellipsoid 95 % (second-order cov)"), ("ell_gn", "ellipsoid 95 % (Gauss-Newton)")):
            print(f"  {label}: {_rate(sum(r[key] for r in fits), len(fits))}")
        prof = [r for r in fits if "profile" in r]
        perr = sum("profile_error" in r for r in fits)
        for i, nm in enumerate(("k1_ref", "E1", "k2_ref", "E2")):
            print(f"  {nm}: Wald {_rate(sum(r['wald'][i] for r in fits), len(fits))}; profile "
                  f"{_rate(sum(r['profile'][i] for r in prof), len(prof))}")
        print(f"  profile failures: {perr}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="bench dynamic_stats", description=__doc__.split("\n")[0])
    ap.add_argument("--study", default="size", help=f"comma-separated, of {', '.join(STUDIES)}")
    ap.add_argument("--reps", type=int, default=1000)
    ap.add_argument("--block", type=int, default=100, help="replications per saved block (engine studies)")
    ap.add_argument("--profile-reps", type=int, default=300)
    ap.add_argument("--seed", type=int, default=20261125)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="/tmp/dynstats/mc")
    ap.add_argument("--tabulate", action="store_true")
    args = ap.parse_args(argv)
    if args.tabulate:
        print(f"machine: {platform.node()} {os.cpu_count()} cores, load {os.getloadavg()}")
        tabulate(args.out)
        return
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    for study in args.study.split(","):
        if study not in STUDIES:
            raise SystemExit(f"--study: unknown {study!r}; choose from {', '.join(STUDIES)}")
        if study == "coverage":
            _coverage(args.reps, args.profile_reps, args.seed, args.workers, args.out)
            continue
        for b in range(math.ceil(args.reps / args.block)):
            _engine_block(study, b, args.block, args.seed, args.workers, args.out)


if __name__ == "__main__":
    main()
