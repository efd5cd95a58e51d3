r"""Discrimination design M3 against M2 on the press, and its power gain in a Monte Carlo (issue 13, item 5).

1. M2 (Coulomb) and M3 (Preisach) are fitted on the shipped campaign (held-out series,
   sensors D_y and F_x: :func:`mudoe.press.fit_candidates`).  With M3 assumed true,
   :func:`oed.select_discriminating` scores every reading (set point j of the paper's load
   cycle, sensor s) by d_js = ((h_M3 - h_M2) / sigma_s)^2 (local T-optimality) and by the
   Buzzi-Ferraris divergence, and chooses designs with as many readings per series as the
   paper's design (29 set points x D_y, F_x = 58):

   * ``paper``: all 29 set points, D_y and F_x;
   * ``T pair``: 2 sensors read at all 29 set points, chosen by T (exact: top-k of sensor sums);
   * ``T free``: the 58 best (set point, sensor) readings by T (exact top-k);
   * ``divergence free``: the 58 best readings by the divergence criterion;
   * ``paper, 5 points`` against ``T free, 10``: a small budget of 10 readings per series, the
     paper's sensors at 0, 800, 1600, 800, 0 N against the 10 best readings by T.

2. Power: campaigns of the virtual prototype (:func:`models.prototype.generate_campaign`,
   2 series, seeds ``--seed0`` ...); each design keeps its readings (the others are
   missing), M2 (and, for context, M3) is fitted with the paper's known sigmas, and the
   model is rejected when the goodness-of-fit statistic
   chi2 = sum ((z - h(p_hat)) / sigma)^2 exceeds the 95 % quantile of chi2(n - 2).
   That test rejects M3 as well (the prototype is neither model), so the main test is the
   likelihood ratio of M2 against M3, Delta = chi2_M2 - chi2_M3 (a non-nested comparison,
   Cox / Williams style), with its critical value calibrated by parametric bootstrap: the
   95 % quantile of Delta on the first half of ``--null-rep`` campaigns simulated from M2
   itself (at its estimate, independent normal readings with the paper's sigmas), its size
   checked on the second half.  Rejection rates with Clopper-Pearson 95 % intervals.

3. ``--case small`` (the harder case, where the comparison has room): ONE series and a budget
   of 6 or 8 readings, the paper's sensors D_y and F_x at 3 or 4 set points of the load cycle:

   * ``even 3`` / ``even 4``: evenly spread set points (rows round(linspace(0, 28, k)): 0, 1600,
     0 N and 0, 1029 loading, 1029 unloading, 0 N), the paper's style at a small budget;
   * ``T 3`` / ``T 4``: the k set points chosen by :func:`oed.select_discriminating` (T,
     ``n_points=k``, sensors D_y and F_x: exact top-k of the row sums);
   * ``Tr 3`` / ``Tr 4``: the same with criterion ``T_refit`` (M2 refitted on the design,
     linearised; exact by enumeration of the C(29, k) designs).

   ``--friction-scale 0.33`` gives the prototype a third of its guide friction (M2 and M3
   retrained on its own 6-series campaign), so that the paper-style design has power near 50 %.
   Power is measured on the prototype (``--study power``) and, as the design's own premise, on
   campaigns simulated from M3 at its estimate (``--study power-m3``); ``--study report`` with
   ``--merge PREFIX`` collects runs made in parallel processes (or with other ``--seed0``) and adds
   McNemar's exact paired test of every design against the evenly spread one.

   A fit that fails (Ipopt not converged) is recorded as NaN, counted in the table, and the
   campaign is left out of that design's rates (never silently replaced).

Run ``python -m bench.bench_discrimination --n-rep 150 --null-rep 300`` from the project root;
the small case (each a process; ``S = --case small --n-series 1 --friction-scale 0.33``):
``... S --study null --null-rep 400 --out P``, ``... S --study power --n-rep 200 --out P``,
``... S --study power-m3 --n-rep 200 --out P``, then ``... S --study report --out P``.
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import platform
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from identification import Measurements, clopper_pearson, identify  # noqa: E402
from identification.errors import IdentificationError  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402

from models.friction import FRICTION_JSON, candidate_models, model_inputs  # noqa: E402
from models.press import K_NOMINAL, PRESS_SENSORS, Q_PAPER  # noqa: E402
from models.prototype import (CAMPAIGN_SEED, SIGMA_PAPER_UM, PrototypeConfig, VirtualPrototype,  # noqa: E402
                              generate_campaign, read_campaign)
from mudoe.press import fit_candidates, retrain  # noqa: E402
from oed import select_discriminating  # noqa: E402

SIGMA_MM = np.asarray(SIGMA_PAPER_UM) * 1e-3


@dataclass
class Setup:
    """The prototype and the friction constants of M2/M3 used by every function of this bench
    (set once by :func:`main`): the shipped ones, or (``--friction-scale``) a prototype with its
    guide friction scaled and M2/M3 retrained on its own campaign."""

    config: PrototypeConfig = field(default_factory=PrototypeConfig)
    friction_path: object = FRICTION_JSON


SETUP = Setup()


def scaled_friction(scale, out):
    """A prototype whose break-away force (F_0 and mu) is ``scale`` times the default one, a 6-series
    campaign of it (the shipped campaign's seed) and M2/M3 retrained on its training series
    (:func:`mudoe.press.retrain`, written to ``out``_friction.json).  Returns the campaign."""
    base = PrototypeConfig()
    cfg = dataclasses.replace(base, breakaway_base=base.breakaway_base * scale,
                              breakaway_slope=base.breakaway_slope * scale)
    camp = generate_campaign(seed=CAMPAIGN_SEED, config=cfg, n_series=6)
    path = f"{out}_friction.json"
    info = retrain(camp, path=path)
    SETUP.config, SETUP.friction_path = cfg, path
    print(f"friction scale {scale}: F_0 = {cfg.breakaway_base:.2f} N, mu = {cfg.breakaway_slope:.3f}; retrained "
          f"q_c = {info['q_c_N']:.2f} N, network rms {info['training_result']['rms_N']:.2f} N -> {path}")
    return camp
N_PAPER_READINGS = 2 * len(Q_PAPER)
LEVEL = 0.05


def designs(est):
    """{name: (mask (n_q, n_S) bool, DiscriminationResult or None)} and the two score matrices."""
    q = np.asarray(Q_PAPER)
    cand = (model_inputs("M3", q), model_inputs("M2", q))
    models = candidate_models(SETUP.friction_path)
    common = dict(candidates=cand, sensors=PRESS_SENSORS, sigma=SIGMA_MM)
    out = {}
    paper = np.zeros((q.size, len(PRESS_SENSORS)), bool)
    paper[:, :2] = True
    out["paper"] = (paper, None)
    pair = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], n_sensors=2, **common)
    free = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], n_readings=N_PAPER_READINGS,
                                 **common)
    div = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], n_readings=N_PAPER_READINGS,
                                criterion="divergence", **common)
    thin = np.zeros_like(paper)
    thin[::7, :2] = True                            # D_y, F_x at 0, 800, 1600 (peak), 800, 0 N: 10 readings
    out["paper, 5 points"] = (thin, None)
    small = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], n_readings=int(thin.sum()),
                                  **common)
    for name, res in (("T pair", pair), ("T free", free), ("divergence free", div), ("T free, 10", small)):
        mask = np.zeros_like(paper)
        for j, s in res.readings:
            mask[j, PRESS_SENSORS.index(s)] = True
        out[name] = (mask, res)
    return out, free.divergences, div.divergences, free.difference


def small_designs(est):
    """The small-budget designs of ``--case small``: {name: (mask, result or None)} and the T matrix."""
    q = np.asarray(Q_PAPER)
    cand = (model_inputs("M3", q), model_inputs("M2", q))
    models = candidate_models(SETUP.friction_path)
    paper_sensors = ("D_y", "F_x")
    sigma = dict(zip(PRESS_SENSORS, SIGMA_MM))
    out = {}
    d_t = d_div = diff = None
    for k in (3, 4):
        even = np.zeros((q.size, len(PRESS_SENSORS)), bool)
        even[np.unique(np.round(np.linspace(0, q.size - 1, k)).astype(int)), :2] = True
        out[f"even {k}"] = (even, None)
        res = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], candidates=cand,
                                    sensors=paper_sensors, sigma=sigma, n_points=k)
        mask = np.zeros_like(even)
        mask[list(res.indices), :2] = True
        out[f"T {k}"] = (mask, res)
        ref = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], candidates=cand,
                                    sensors=paper_sensors, sigma=sigma, n_points=k, criterion="T_refit")
        mask = np.zeros_like(even)
        mask[list(ref.indices), :2] = True
        out[f"Tr {k}"] = (mask, ref)
    full = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], candidates=cand,
                                 sensors=PRESS_SENSORS, sigma=SIGMA_MM, n_readings=1)
    div = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"], candidates=cand,
                                sensors=PRESS_SENSORS, sigma=SIGMA_MM, n_readings=1, criterion="divergence")
    d_t, d_div, diff = full.divergences, div.divergences, full.difference
    return out, d_t, d_div, diff


def _value(d, mask):
    return float(d[mask].sum())


def print_table(d_t, d_div, diff, des):
    q = np.asarray(Q_PAPER)
    dirs = model_inputs("M2", q)[:, 1]
    head = "  ".join(f"{s:>7}" for s in PRESS_SENSORS)
    print(f"\nper reading (M3 true, M2 rival): h_M3 - h_M2 (um) | T = ((h_M3 - h_M2)/sigma)^2 | divergence; "
          "* = in the 'T free' design ('T 4' in the small case)")
    print(f"{'j':>2} {'q (N)':>7} {'dir':>4}  {head}  |  {head}  |  {head}")
    marked = "T free" if "T free" in des else "T 4"
    free = des[marked][0]
    for j in range(q.size):
        a = "  ".join(f"{1e3 * v:7.2f}" for v in diff[j])
        b = "  ".join(f"{v:6.2f}" + ("*" if free[j, k] else " ") for k, v in enumerate(d_t[j]))
        c = "  ".join(f"{v:7.2f}" for v in d_div[j])
        print(f"{j:>2} {q[j]:7.1f} {dirs[j]:4.0f}  {a}  |  {b}  |  {c}")
    print("\ndesign values per series (sum over the design's readings)")
    print(f"{'design':<16} {'readings':>8} {'T':>9} {'divergence':>11}  sensors used (readings)")
    for name, (mask, res) in des.items():
        used = ", ".join(f"{s} ({int(mask[:, k].sum())})" for k, s in enumerate(PRESS_SENSORS) if mask[:, k].any())
        extra = f"  [{res.method}, proven {res.proven_optimal}]" if res is not None else ""
        print(f"{name:<16} {int(mask.sum()):>8} {_value(d_t, mask):9.2f} {_value(d_div, mask):11.2f}  {used}{extra}")


def _chi2(model, inputs, z, mask):
    """Goodness-of-fit statistic sum ((z - h(p_hat)) / sigma)^2 of ``model`` on the readings in ``mask``, and its dof."""
    used = mask.any(axis=0)
    zz = np.where(mask[None, :, :] | ~used[None, None, :], z, np.nan)   # unused sensors get weight 0 below
    data = Measurements(inputs, zz, SIGMA_MM, sensors=PRESS_SENSORS)
    try:
        est = identify(model, data, K_NOMINAL, weights=used.astype(float))
    except IdentificationError as exc:
        print(f"  fit of {model.name} failed ({type(exc).__name__}: {str(exc).splitlines()[0]}); recorded as NaN",
              flush=True)
        return np.nan, np.nan
    if not est.success:
        print(f"  fit of {model.name} did not converge ({est.message}); recorded as NaN", flush=True)
        return np.nan, np.nan
    return 2.0 * est.objective, est.dof


def statistics(des, z_of_rep, n_rep, label, path):
    """chi2 of M2 and M3 and their dof per design and replication: dict name -> array (n_done, 4).

    The replications done so far are saved to ``path`` (.npz) after every fifth one, so that an
    interrupted study keeps its completed replications."""
    models = {name: candidate_models(SETUP.friction_path) for name in des}     # one model per design: each keeps its compiled fit
    inputs = {n: model_inputs(n, np.asarray(Q_PAPER)) for n in ("M2", "M3")}
    out = {name: np.empty((n_rep, 4)) for name in des}
    t0 = time.perf_counter()
    for r in range(n_rep):
        z = z_of_rep(r)
        for name, (mask, _) in des.items():
            c2, d2 = _chi2(models[name]["M2"], inputs["M2"], z, mask)
            c3, d3 = _chi2(models[name]["M3"], inputs["M3"], z, mask)
            out[name][r] = (c2, d2, c3, d3)
        if r == 0 or (r + 1) % 5 == 0 or r + 1 == n_rep:
            np.savez(path, **{name: v[:r + 1] for name, v in out.items()})
            print(f"  {label} {r + 1}/{n_rep}: {time.perf_counter() - t0:.1f} s", flush=True)
    return out


def null_campaigns(est_m2, seed0, n_series=2, name="M2"):
    """z of replication r: model ``name`` (M2: the null) at its estimate plus N(0, sigma^2) readings,
    ``n_series`` series."""
    h = candidate_models(SETUP.friction_path)[name].simulate(est_m2.p, model_inputs(name, np.asarray(Q_PAPER)))
    return lambda r: h[None] + SIGMA_MM * np.random.default_rng(seed0 + r).standard_normal((n_series,) + h.shape)


def prototype_campaigns(seed0, n_series=2):
    """z of replication r: a prototype campaign (seed seed0 + r); its first ``n_series`` series (the
    prototype simulates at least 2)."""
    proto = VirtualPrototype(SETUP.config)
    return lambda r: generate_campaign(seed=seed0 + r, config=SETUP.config, n_series=max(2, n_series),
                                       prototype=proto).z[:n_series]


def _fmt_rate(k, n):
    r = clopper_pearson(k, n)
    return f"{100 * r.rate:5.1f} % [{100 * r.lo:5.1f}, {100 * r.hi:5.1f}] ({k}/{n})"


REFIT = {}
CRIT = {}


def paired(runs, pairs):
    """McNemar's exact test of two designs on the same campaigns: {label: {design: (n, 4)}}; prints one
    markdown row per (label, pair) with the discordant counts and the two-sided binomial p-value."""
    print("\n| campaigns | design A | design B | both reject | only A | only B | neither | McNemar p (exact) |")
    print("|---|---|---|---|---|---|---|---|")
    for label, run in runs.items():
        for a, b in pairs:
            if a not in run or b not in run or a not in CRIT or b not in CRIT:
                continue
            n = min(run[a].shape[0], run[b].shape[0])
            ok = np.isfinite(run[a][:n]).all(axis=1) & np.isfinite(run[b][:n]).all(axis=1)
            ra = (run[a][:n, 0] - run[a][:n, 2] > CRIT[a])[ok]
            rb = (run[b][:n, 0] - run[b][:n, 2] > CRIT[b])[ok]
            only_a, only_b = int(np.sum(ra & ~rb)), int(np.sum(~ra & rb))
            p = stats.binomtest(only_a, only_a + only_b).pvalue if only_a + only_b else 1.0
            print(f"| {label} ({int(ok.sum())}) | {a} | {b} | {int(np.sum(ra & rb))} | {only_a} | {only_b} | "
                  f"{int(np.sum(~ra & ~rb))} | {p:.3g} |")


def _refit_value(est, mask):
    """T_refit of the readings in ``mask`` (oed.discrimination's linearised refit of M2, M3 true)."""
    q = np.asarray(Q_PAPER)
    models = candidate_models(SETUP.friction_path)
    used = [s for k, s in enumerate(PRESS_SENSORS) if mask[:, k].any()]
    rows = np.flatnonzero(mask.any(axis=1))
    if any(not np.array_equal(mask[rows, PRESS_SENSORS.index(s)], np.ones(rows.size, bool)) for s in used):
        return float("nan")                          # not a rows x sensors design
    res = select_discriminating(models["M3"], est["M3"], models["M2"], est["M2"],
                                candidates=(model_inputs("M3", q)[rows], model_inputs("M2", q)[rows]),
                                sensors=used, sigma=dict(zip(PRESS_SENSORS, SIGMA_MM)), criterion="T_refit")
    return res.value


def _ok(rows):
    """Rows whose M2 and M3 fits both succeeded."""
    return rows[np.isfinite(rows).all(axis=1)]


def report(des, null, power, d_t=None, power_m3=None):
    """Size and power of (a) the chi2 goodness-of-fit test of M2 and (b) the M2-vs-M3 likelihood ratio
    Delta = chi2_M2 - chi2_M3, calibrated on the first half of the null replications, its size checked
    on the second half; failed fits are counted and their campaigns left out.  Prints a markdown table."""
    print("\n| design | readings | set points | T | T_refit | failed fits (null / prototype) | c (95 % of Delta, "
          "null 1st half) | size LR (null 2nd half) | power LR, M3 true (simulated) | power LR: M2 rejected "
          "(prototype) | size GoF | M2 rejected, GoF | M3 rejected, GoF | Delta prototype min / median / max |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, (mask, _) in des.items():
        a_all, b_all = null[name], power[name]
        half = a_all.shape[0] // 2
        cal, chk, b = _ok(a_all[:half]), _ok(a_all[half:]), _ok(b_all)
        a = np.vstack([cal, chk])
        fails = (a_all.shape[0] - a.shape[0], b_all.shape[0] - b.shape[0])
        gof0 = int(np.sum(stats.chi2.sf(a[:, 0], a[:, 1]) < LEVEL))
        gof1 = int(np.sum(stats.chi2.sf(b[:, 0], b[:, 1]) < LEVEL))
        gof3 = int(np.sum(stats.chi2.sf(b[:, 2], b[:, 3]) < LEVEL))
        crit = float(np.quantile(cal[:, 0] - cal[:, 2], 1 - LEVEL, method="higher"))
        lr0 = int(np.sum(chk[:, 0] - chk[:, 2] > crit))
        lr1 = int(np.sum(b[:, 0] - b[:, 2] > crit))
        d1 = b[:, 0] - b[:, 2]
        t = f"{_value(d_t, mask):.2f}" if d_t is not None else "-"
        tr = f"{REFIT[name]:.2f}" if name in REFIT else "-"
        pts = ", ".join(f"{Q_PAPER[j]:.0f}" for j in np.flatnonzero(mask.any(axis=1)))
        m3 = "-"
        if power_m3 is not None and name in power_m3:
            c = _ok(power_m3[name])
            m3 = _fmt_rate(int(np.sum(c[:, 0] - c[:, 2] > crit)), c.shape[0])
        CRIT[name] = crit
        print(f"| {name} | {int(mask.sum())} | {pts} | {t} | {tr} | {fails[0]} / {fails[1]} | {crit:.2f} | "
              f"{_fmt_rate(lr0, chk.shape[0])} | {m3} | {_fmt_rate(lr1, b.shape[0])} | {_fmt_rate(gof0, a.shape[0])} | "
              f"{_fmt_rate(gof1, b.shape[0])} | {_fmt_rate(gof3, b.shape[0])} | "
              f"{d1.min():.1f} / {np.median(d1):.1f} / {d1.max():.1f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench_discrimination", description=__doc__.splitlines()[0])
    ap.add_argument("--n-rep", type=int, default=150, help="prototype campaigns of the power study")
    ap.add_argument("--null-rep", type=int, default=300, help="M2 campaigns of the size study")
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--study", choices=("design", "null", "power", "power-m3", "report", "all"), default="all",
                    help="null and power can run in two processes; report reads their files")
    ap.add_argument("--out", default="/tmp/bench_discrimination", help="prefix of the statistics files (.npz)")
    ap.add_argument("--case", choices=("paper", "small"), default="paper",
                    help="paper: the paper's budget (58 readings) and 10; small: 6 and 8 readings")
    ap.add_argument("--friction-scale", type=float, default=1.0,
                    help="scale of the prototype's guide friction (M2/M3 retrained on its campaign when != 1)")
    ap.add_argument("--n-series", type=int, default=2, help="series per campaign (small case: 1)")
    ap.add_argument("--designs", default="", help="comma-separated design names to simulate (default all)")
    ap.add_argument("--merge", action="append", default=[],
                    help="report: also read the statistics files of this prefix (repeatable; --designs runs); "
                         "a design found in several files gets their campaigns stacked (runs with other --seed0)")
    args = ap.parse_args(argv)
    print(f"{datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M UTC}, {platform.processor() or platform.machine()}, "
          f"nproc {os.cpu_count()}")
    t0 = time.perf_counter()
    camp = read_campaign() if args.friction_scale == 1.0 else scaled_friction(args.friction_scale, args.out)
    est = fit_candidates(camp, models={k: v for k, v in candidate_models(SETUP.friction_path).items() if k != "M1"})
    for name, e in est.items():
        which = "shipped" if args.friction_scale == 1.0 else "scaled-friction"
        print(f"{name} on the {which} campaign (series 5, 6; D_y, F_x): k5, k7 = {e.p.round(2)} N/mm, "
              f"stderr {e.stderr.round(2)}")
    des, d_t, d_div, diff = designs(est) if args.case == "paper" else small_designs(est)
    print(f"design time (fits + scores): {time.perf_counter() - t0:.1f} s")
    print_table(d_t, d_div, diff, des)
    distinct = {}
    for name, (mask, res) in des.items():
        same = [other for other, (m, _) in distinct.items() if np.array_equal(m, mask)]
        if same:
            print(f"design {name!r} has the same readings as {same[0]!r}; simulated once")
        else:
            distinct[name] = (mask, res)
    des = distinct
    for name, (mask, res) in des.items():
        if res is not None and res.criterion == "T_refit":
            REFIT[name] = res.value
        else:
            REFIT[name] = _refit_value(est, mask)
    print("T_refit (M2 refitted, linearised) per series: " + ", ".join(f"{k} {v:.2f}" for k, v in REFIT.items()))
    run = des if not args.designs else {n: des[n] for n in args.designs.split(",")}

    t0 = time.perf_counter()
    if args.study in ("null", "all"):
        statistics(run, null_campaigns(est["M2"], args.seed0 + 100_000, args.n_series), args.null_rep, "null",
                   f"{args.out}_null.npz")
        print(f"null study: {time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    if args.study in ("power", "all"):
        statistics(run, prototype_campaigns(args.seed0, args.n_series), args.n_rep, "prototype",
                   f"{args.out}_power.npz")
        print(f"power study: {time.perf_counter() - t0:.1f} s")
    if args.study == "power-m3":
        statistics(run, null_campaigns(est["M3"], args.seed0 + 200_000, args.n_series, "M3"), args.n_rep, "M3 true",
                   f"{args.out}_powerM3.npz")
    if args.study in ("report", "all"):
        null, power, m3 = {}, {}, {}
        for prefix in [args.out] + args.merge:
            for store, suffix in ((null, "null"), (power, "power"), (m3, "powerM3")):
                if os.path.exists(f"{prefix}_{suffix}.npz"):
                    f = np.load(f"{prefix}_{suffix}.npz")
                    for n in f.files:                # campaigns of several runs (other seeds) are stacked
                        if n in des:
                            store[n] = np.vstack([store[n], f[n]]) if n in store else f[n]
        done = {n: v for n, v in des.items() if n in null and n in power}
        report(done, null, power, d_t, m3)
        runs = {"M3 true": m3}
        for prefix in [args.out] + args.merge:
            if os.path.exists(f"{prefix}_power.npz"):
                f = np.load(f"{prefix}_power.npz")
                runs[f"prototype, {os.path.basename(prefix)}"] = {n: f[n] for n in f.files}
        paired(runs, [(f"even {k}", f"{t} {k}") for k in (3, 4) for t in ("T", "Tr")])


if __name__ == "__main__":
    main()
