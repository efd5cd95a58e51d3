"""Model error of the press (issue 29, first slice): held-out coverage, widening, size of the test, runtime.

Three measurements on the shipped press study (``configs/press.toml``: series 4 and 5, the paper's four
split scenarios, the sensors F_x and B0_y of the study's E-optimal design, sigma = sqrt(sigma_rep^2 +
sigma_man^2)):

1. **coverage**: for every variant M1/M2/M3 and every split, the validation readings predicted from a fit
   on the calibration part, by the plain 95 % new-reading delta-method bands (h +- 1.96 sqrt(g^T C g +
   sigma^2), the baseline of issue 29) and by :func:`identification.model_error`'s bands with the output
   discrepancy and with the embedded error; the median widening (ratio of band widths) per variant; the
   runtime of ``model_error`` (kind auto, with the held-out table); once more with the discrepancy pinned to
   zero with zero slope at zero press force (``exact_at={"q_P": 0}``).
2. **size** of the 'no model error' test (alpha 5 %): ``--n`` campaigns simulated from an adequate model
   (the variant ``--size-variant`` at its fit on the shipped data, z = h(p_hat) + sigma eps, 2 series x 29
   inputs), the rejection rate with its binomial (Clopper-Pearson 95 %) interval.
3. **adequate-model coverage** (``--n-coverage`` campaigns of the same kind): the held-out coverage and the
   widening of the model-error bands when there is no model error.

4. **oscillator** (issue 29's dynamic target, ``mudoe/example_oscillator.py`` with the design of
   ``configs/oscillator.toml``: steps F = 2, 4, 6, 8 N, x (sigma 0.02 mm) and a (sigma 0.05 m/s^2) every 40 ms
   over 1 s, 2 series): ``--oscillator-n`` campaigns simulated from the cubic spring at its true parameters,
   the rate at which the cubic model's error is *not* found (alpha 5 %) with its Clopper-Pearson interval; and
   ``--oscillator-n-coverage`` campaigns on which the linear spring (the wrong model) is given to
   ``model_error`` with the time-window splits t < e vs t >= e (e = :data:`OSC_EDGES`): the held-out
   coverage of the 95 % new-reading bands with the chosen model error (kind auto) and without, pooled over
   campaigns and splits, with the standard error over campaigns.

5. **condition offset** (``--n-offset`` campaigns, issue 29's press coverage target): a small static model whose
   readings carry an offset per condition (a direction, a day) that the model lacks, calibrated on 1, 4 or 9
   conditions and validated on one more at the same set points: the held-out coverage of the discrepancy's 95 %
   new-reading bands with the validation condition kriged as a seen one (before) and predicted as a condition
   not seen (after, :func:`identification.studies.model_error.unseen_rows`).

The coverage part prints five tables: as shipped, pinned at zero force, with the press's direction of motion
named as the conditions (``groups``: loading, unloading), and with sigma None (the pure error of the repeated
series instead of the study's sqrt(sigma_rep^2 + sigma_man^2)) unpinned and pinned; per split also the
Clopper-Pearson interval of the discrepancy's coverage, the readings in a condition the calibration part has
not seen, the factor its bands could shrink by and still hold 95 % (need) and their median width (um); per
variant the stated sigma against the pure error (:attr:`ModelErrorResult.pure_error`).  The condition-offset
part compares the plug-in band at a condition not seen with the Student-t band (``variance_aware``) and an
oracle band with the true offset variance.

Run ``python -m bench model_error --n=1000 --n-coverage=50`` (``--quick``: 100 and 10); the oscillator alone:
``python -m bench model_error --skip=coverage,size,adequate --oscillator-n=1000 --oscillator-n-coverage=20``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from identification import Split, model_error
from identification.fit.dynamic_fit import simulate_campaign
from identification.studies.splits import time_window_splits
from identification.studies.discrepancy_gp import InputScaling
from identification.studies.model_error import unseen_rows
from identification.studies.model_error_fit import fit_model_error, pure_error_sigma
from identification.studies.montecarlo import clopper_pearson
from mudoe.config import load_config
from mudoe.study import prepare
from models.press import PRESS_LOADING_ROWS
from models.state import simulate

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"
#: the sensors of the study's E-optimal design ([oed] n_sensors = 2): F_x and B0_y
WEIGHTS = np.array([0.0, 1.0, 1.0])


def _data(study, variant: str, pure: bool):
    """The variant's data with the study's sigma, or (``pure``) with sigma None: model_error takes the pure error
    of the repeated series."""
    d = study.data[variant]
    return d.with_sigma(None) if pure else d


def _needed(study, variant: str, split, exact_at, alpha: float = 0.05, pure: bool = False) -> tuple:
    """(need, width): the factor by which the discrepancy's held-out new-reading bands of ``split`` could shrink
    and still hold (1 - alpha) of its validation readings, the (1 - alpha) quantile of |z - mean| / half-width
    (< 1: wider than the error requires, > 1: too narrow); the median full width of those bands (um)."""
    m, d = study.models[variant], study.data[variant]
    if pure:
        d = d.with_sigma(pure_error_sigma(d.z)[0])
    scaling = InputScaling.of(d.inputs, exact_at or {}, tuple(m.inputs))
    cal, val = split.calibration(d), split.validation(d)
    f = fit_model_error(m, cal, study.p0, WEIGHTS, scaling, "discrepancy")
    b = f.predict(val.inputs, alpha, True, conditions=np.where(unseen_rows(split, d), -1, 0))
    sel = WEIGHTS > 0
    z = val.z[:, :, sel]
    ok = np.isfinite(z)
    e = np.abs(z - b.mean[None][:, :, sel]) / (b.upper - b.mean)[None][:, :, sel]
    width = np.broadcast_to((b.upper - b.lower)[None][:, :, sel], z.shape)[ok]
    return float(np.quantile(e[ok], 1 - alpha)), 1e3 * float(np.median(width))


def _cp(cover: float, n: int) -> str:
    ci = clopper_pearson(int(round(cover * n)), n)
    return f"[{100 * ci.lo:.1f}, {100 * ci.hi:.1f}]"


def coverage_table(study, exact_at=None, groups=None, pure: bool = False) -> dict:
    """{variant: ModelErrorResult (kind auto)} on the study's data and splits (``pure``: sigma None, the pure error
    of the repeated series); prints the held-out table: coverage of the plain, discrepancy and embedded 95 %
    new-reading bands (%) with the Clopper-Pearson 95 % interval of the discrepancy's (the validation readings
    taken as independent), their median widening, the readings in a condition the calibration part has not seen
    (unseen), the factor the discrepancy bands could shrink by (need) and their median full width in um
    (:func:`_needed`); the CPU and wall time of model_error."""
    out = {}
    print(f"exact_at = {exact_at}, groups = {None if groups is None else sorted(set(groups))}, sigma = "
          f"{'None (pure error of the repeated series)' if pure else 'the study' + chr(39) + 's'}")
    print(f"{'variant':<8} {'split':<32} {'n':>4} {'unseen':>6} {'plain':>6} {'discr.':>6} {'CP 95 %':>13} "
          f"{'widen':>6} {'need':>5} {'width':>6} {'embed.':>6} {'widen':>6}")
    for v, m in study.models.items():
        t0, c0 = time.perf_counter(), time.process_time()
        r = model_error(m, _data(study, v, pure), study.p0, splits=study.splits, weights=WEIGHTS, exact_at=exact_at,
                        groups=groups)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        for h, sp in zip(r.heldout, study.splits):
            need, width = _needed(study, v, sp, exact_at, pure=pure) if groups is None else (np.nan, np.nan)
            print(f"{v:<8} {h.split:<32} {h.n_values:>4} {h.n_unseen:>6} {100 * h.coverage_plain:>6.1f} "
                  f"{100 * h.coverage_discrepancy:>6.1f} {_cp(h.coverage_discrepancy, h.n_values):>13} "
                  f"{h.widening_discrepancy:>6.2f} {need:>5.2f} {width:>6.2f} "
                  f"{100 * h.coverage_embedded:>6.1f} {h.widening_embedded:>6.2f}")
        n = sum(h.n_values for h in r.heldout)
        pooled = {k: sum(h.coverage(k) * h.n_values for h in r.heldout) / n for k in ("none", "discrepancy", "embedded")}
        print(f"{v:<8} {'pooled / median widening':<32} {n:>4} {sum(h.n_unseen for h in r.heldout):>6} "
              f"{100 * pooled['none']:>6.1f} {100 * pooled['discrepancy']:>6.1f} {_cp(pooled['discrepancy'], n):>13} "
              f"{np.median([h.widening_discrepancy for h in r.heldout]):>6.2f} {'':>5} {'':>6} "
              f"{100 * pooled['embedded']:>6.1f} {np.median([h.widening_embedded for h in r.heldout]):>6.2f}")
        print(f"         model_error {dc:.2f} s CPU, {dt:.2f} s wall; test LR {r.test.statistic:.4g}, p = "
              f"{r.test.p_value:.3g}; {r.how} -> {r.kind}; identifiable {r.identifiable} (information kept "
              f"{r.information_kept:.3f}); sigma {r.sigma_source} "
              + " ".join(f"{n} {1e3 * s:.2f} um" for n, s, w in zip(r.fit.plain.sensors, r.sigma, WEIGHTS) if w > 0))
        for c in r.pure_error:
            print(f"         {c.sensor}: pure error {1e3 * c.pure_error:.2f} um against sigma {1e3 * c.sigma:.2f} um "
                  f"(ratio {c.ratio:.2f}, {c.dof} dof, chi-square p below {c.p_below:.2g})")
        for block in r.summary().split("\n\n")[1:3]:          # the parameters, the discrepancy / embedded error
            print("         " + block.replace("\n", "\n         "))
        out[v] = r
    return out


def press_branches(study) -> list:
    """The press study's condition of every input row: "loading" (0 .. 1600 N, the peak included) or
    "unloading" (the direction of motion, which M1's input q_P does not hold)."""
    n_q = next(iter(study.data.values())).n_q
    return ["loading" if j in PRESS_LOADING_ROWS else "unloading" for j in range(n_q)]


# ---------------------------------------------------------------------------- a known condition offset
#: the synthetic case of a condition offset the model lacks: set points, noise, offset spread (sd)
OFFSET_Q = np.linspace(0.2, 2.0, 10)
OFFSET_SIGMA = 0.05
OFFSET_KAPPA = 0.15


def _offset_model():
    import casadi as ca
    from models.contract import Model
    return Model.explicit(["a", "b"], ["x"], ["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * q[0] / (1 + p[1] * q[0])))


def _offset_campaign(rng, n_cond: int):
    """Measurements of ``n_cond`` conditions at the set points OFFSET_Q (2 series): the model at a = 2, b = 1.5
    plus an offset b_gk ~ N(0, OFFSET_KAPPA^2) per condition g and sensor k plus noise; the rows' conditions."""
    from identification import Measurements
    q = np.tile(OFFSET_Q, n_cond)
    cond = np.repeat(np.arange(n_cond), OFFSET_Q.size)
    truth = np.stack([2.0 * (1 - np.exp(-1.5 * q)), 2.0 * q / (1 + 1.5 * q)], axis=1)
    mean = truth + OFFSET_KAPPA * rng.standard_normal((n_cond, 2))[cond]
    z = mean[None] + OFFSET_SIGMA * rng.standard_normal((2, q.size, 2))
    return Measurements(q[:, None], z, OFFSET_SIGMA, sensors=["y1", "y2"], input_names=["x"]), cond


def _offset_heldout(m, d, cal: list, val: list, groups=None, unseen=None, aware: tuple = (False,),
                    condition_term: bool = False) -> list:
    """[(coverage, median widening against the plain bands, median full width / (2 * 1.96 sigma))] of the
    discrepancy's 95 % new-reading bands fitted on rows ``cal`` of ``d`` at rows ``val`` (``groups`` the rows'
    condition codes, None: one; ``unseen`` bool per validation row: predicted as a condition not seen), as the
    held-out table of ``model_error`` computes them, one per ``aware`` (ErrorFit.predict's variance_aware: the
    Student-t band at a condition not seen, or the normal plug-in band); ``condition_term`` the discrepancy with an
    offset per condition in place of the rough part (fit_model_error's option), without the oracle."""
    scaling = InputScaling.of(d.inputs, {}, ("x",))
    dc, dv = d.subset(inputs=cal), d.subset(inputs=val)
    w = np.ones(2)
    plain = fit_model_error(m, dc, [1.0, 1.0], w, scaling, "none")
    f = fit_model_error(m, dc, [1.0, 1.0], w, scaling, "discrepancy", plain=plain.plain,
                        groups=None if groups is None else np.asarray(groups)[cal], condition_term=condition_term)
    codes = np.zeros(len(val), int) if groups is None else np.asarray(groups)[val]
    b0 = plain.predict(dv.inputs, 0.05, True)
    out = []
    cc = np.where(unseen, -1, codes) if unseen is not None else codes
    for a in aware:
        b = f.predict(dv.inputs, 0.05, True, conditions=cc, variance_aware=a)
        cover = float(np.mean((dv.z >= b.lower[None]) & (dv.z <= b.upper[None])))
        out.append((cover, float(np.median((b.upper - b.lower) / (b0.upper - b0.lower))),
                    float(np.median((b.upper - b.lower) / (2 * 1.96 * OFFSET_SIGMA)))))
    if unseen is not None and len(aware) > 1 and not condition_term:     # the oracle: the true offset variance for the estimated new draw
        A = np.stack([f.gp.cross(i, scaling(dv.inputs), cc)[1] for i in range(2)], axis=1)
        b = f.predict(dv.inputs, 0.05, True, conditions=cc, variance_aware=False)
        T = ((b.upper - b.mean) / stats.norm.ppf(0.975)) ** 2 - A + OFFSET_KAPPA ** 2
        cover = float(np.mean(np.abs(dv.z - b.mean[None]) <= stats.norm.ppf(0.975) * np.sqrt(T)[None]))
        out.append((cover, float(np.median(np.sqrt(A[unseen]))) / OFFSET_KAPPA, np.nan))
    return out


def _quantile90(a: np.ndarray) -> float:
    """The 90 % quantile of ``a`` (inf when infinite widths reach it: no band)."""
    with np.errstate(invalid="ignore"):
        q = float(np.quantile(a, 0.9))
    return np.inf if q != q and np.isinf(a).any() else q


#: the numbers of conditions in the calibration part of the condition-offset study
OFFSET_CALIBRATION = (1, 4, 9)


def condition_offset_study(n: int, seed: int) -> None:
    """Held-out coverage of the discrepancy's 95 % new-reading bands at a condition the calibration part has not
    seen, on campaigns with a condition offset the model lacks (truth known): calibrated on c conditions
    (:data:`OFFSET_CALIBRATION`; c = 1 as the press's loading vs unloading), validated on one more at the same set
    points; before (the validation rows kriged as the calibration's condition(s): one condition named, or none and
    the rough part), after (a new draw of the error process: rows found by :func:`unseen_rows`, for c > 1 with
    the conditions named; the normal plug-in band) and t (the same with the Student-t band on the effective
    degrees of freedom of the estimated new-draw variance); mean over campaigns with its standard error, against
    the coverage P(|t_c| < 1.96) of a band whose variance is estimated from c draws of the offset (noise and fixed
    effects neglected); oracle: the plug-in band with the true offset variance kappa^2 in place of the estimated
    new-draw variance (is the band's shape right?), with the estimated new-draw sd over kappa; term and term t:
    the discrepancy with an offset per condition in place of the rough part (``condition_term``), plug-in and
    Student-t (Satterthwaite); term c-1: the same with the new-draw variance on c - 1 dof (``variance_aware=
    "conditions"``; c = 1: no band, infinite); widths: median widening against the plain bands (median over campaigns) and the mean of
    the median full width in units of the plain noise band 2 x 1.96 sigma."""
    rng, t0 = np.random.default_rng(seed), time.perf_counter()
    m, nq = _offset_model(), OFFSET_Q.size
    rows = {(c, k): [] for c in OFFSET_CALIBRATION for k in ("before", "after", "t", "oracle", "term", "term t", "term c-1")}
    for _ in range(n):
        for c in OFFSET_CALIBRATION:
            d, cond = _offset_campaign(rng, c + 1)
            cal, val = list(range(c * nq)), list(range(c * nq, (c + 1) * nq))
            sp = Split(f"{c} vs 1", cal, val)
            if c == 1:
                rows[c, "before"] += _offset_heldout(m, d, cal, val)
                after = _offset_heldout(m, d, cal, val, unseen=unseen_rows(sp, d), aware=(False, True))
            else:
                rows[c, "before"] += _offset_heldout(m, d, cal, val, unseen=unseen_rows(sp, d))
                after = _offset_heldout(m, d, cal, val, groups=cond, unseen=unseen_rows(sp, d, cond),
                                        aware=(False, True))
            rows[c, "after"].append(after[0])
            rows[c, "t"].append(after[1])
            rows[c, "oracle"].append(after[2])
            g = None if c == 1 else cond
            term = _offset_heldout(m, d, cal, val, groups=g, unseen=unseen_rows(sp, d, g),
                                   aware=(False, True, "conditions"), condition_term=True)
            rows[c, "term"].append(term[0])
            rows[c, "term t"].append(term[1])
            rows[c, "term c-1"].append(term[2])
    print(f"condition offset the model lacks (kappa {OFFSET_KAPPA} = {OFFSET_KAPPA / OFFSET_SIGMA:g} sigma per "
          f"condition and sensor), {n} campaigns, seed {seed}: held-out coverage of the discrepancy's 95 % "
          f"new-reading bands at a condition not seen ({2 * 2 * nq} readings per campaign; mean over campaigns "
          f"+- standard error; median widening against the plain bands; width in units of 2 x 1.96 sigma: mean, "
          f"90 % quantile over campaigns)")
    for (c, k), a in rows.items():
        a = np.array(a)
        if k == "oracle":
            print(f"  {c} calibration condition(s), oracle (plug-in, the true kappa^2 for the new draw) "
                  f"{100 * a[:, 0].mean():6.1f} +- {100 * a[:, 0].std(ddof=1) / np.sqrt(n):4.1f} %  estimated "
                  f"new-draw sd / kappa: median {np.median(a[:, 1]):.2f}, mean {a[:, 1].mean():.2f}")
            continue
        how = {"before": "one condition named, kriged" if c == 1 else "no groups, kriged + rough part",
               "after": "new draw, normal plug-in" if c == 1 else "groups named, new draw, plug-in",
               "t": "new draw, Student-t" if c == 1 else "groups named, new draw, Student-t",
               "term": "offset term, new draw, plug-in", "term t": "offset term, new draw, Student-t",
               "term c-1": "offset term, Student-t on c - 1 dof"}[k]
        print(f"  {c} calibration condition(s), {k:<6} ({how:<34}) {100 * a[:, 0].mean():6.1f} +- "
              f"{100 * a[:, 0].std(ddof=1) / np.sqrt(n):4.1f} %  widening {np.median(a[:, 1]):.2f}  width "
              f"{a[:, 2].mean():.2f} (90 % {_quantile90(a[:, 2]):.2f})"
              + (f"   [P(|t_{c}| < 1.96) = {100 * (1 - 2 * stats.t.sf(1.96, c)):.1f} %]" if k == "after" else ""))
    print(f"  {time.perf_counter() - t0:.0f} s")


def _campaigns(study, variant: str, n: int, seed: int):
    """Campaigns simulated from ``variant`` at its plain fit on the shipped data (2 series, sigma given)."""
    m, d = study.models[variant], study.data[variant]
    fit = model_error(m, d, study.p0, kind="none", weights=WEIGHTS)
    h = simulate(m, fit.p_plain, d.inputs)
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield m, d.with_z(h[None] + d.sigma * rng.standard_normal(d.z.shape)), fit.p_plain


def size_study(study, variant: str, n: int, seed: int) -> None:
    """The rejection rate of the 'no model error' test at alpha 5 % on campaigns of an adequate model."""
    t0 = time.perf_counter()
    rej, pv = 0, []
    for i, (m, d, p) in enumerate(_campaigns(study, variant, n, seed)):
        r = model_error(m, d, p, kind="none", weights=WEIGHTS)
        rej += r.detected
        pv.append(r.test.p_value)
        if (i + 1) % 100 == 0:
            print(f"  {i + 1} campaigns, {rej} rejections", file=sys.stderr, flush=True)
    rate = clopper_pearson(rej, n)
    pv = np.array(pv)
    print(f"size ({variant} adequate, {n} campaigns, seed {seed}): {100 * rej / n:.2f} % "
          f"[95 % CI {100 * rate.lo:.2f}, {100 * rate.hi:.2f}] at alpha 5 %; P(LR = 0) = {np.mean(pv == 1):.3f}; "
          f"rate at 1 % {100 * np.mean(pv < 0.01):.2f} %, at 10 % {100 * np.mean(pv < 0.1):.2f} %; "
          f"{time.perf_counter() - t0:.0f} s")


def adequate_coverage(study, variant: str, n: int, seed: int) -> None:
    """Held-out coverage and widening of the model-error bands on campaigns without model error."""
    rows, kinds = [], {}
    for m, d, p in _campaigns(study, variant, n, seed):
        r = model_error(m, d, p, splits=study.splits, weights=WEIGHTS)
        rows += [(h.coverage_plain, h.coverage_discrepancy, h.coverage_embedded, h.widening_discrepancy,
                  h.widening_embedded) for h in r.heldout]
        kinds[r.kind] = kinds.get(r.kind, 0) + 1
    a = np.array(rows)
    se = a[:, :3].std(axis=0) / np.sqrt(len(a))
    print(f"adequate {variant}, {n} campaigns x {len(study.splits)} splits: held-out coverage plain "
          f"{100 * a[:, 0].mean():.1f} (+- {100 * se[0]:.1f}) %, discrepancy {100 * a[:, 1].mean():.1f} "
          f"(+- {100 * se[1]:.1f}) %, embedded {100 * a[:, 2].mean():.1f} (+- {100 * se[2]:.1f}) %; median widening "
          f"discrepancy {np.median(a[:, 3]):.2f}, embedded {np.median(a[:, 4]):.2f}; kind auto chose {kinds}")


#: the time-window edges of the oscillator's held-out splits (s): t < e calibrates, t >= e validates
OSC_EDGES = (0.36, 0.52, 0.68)
OSC_TIMES = np.round(np.arange(1, 26) * 0.04, 10)       # s, as configs/oscillator.toml
OSC_STEPS = np.array([[2.0], [4.0], [6.0], [8.0]])      # N
OSC_SIGMA = np.array([0.02, 0.05])                      # mm, m/s^2


def _oscillator_campaign(rng):
    from mudoe.example_oscillator import P_TRUE, build
    return simulate_campaign(build("cubic"), P_TRUE, OSC_STEPS, OSC_TIMES, OSC_SIGMA, n_series=2,
                             seed=int(rng.integers(2 ** 32)))


def oscillator_adequate(n: int, seed: int) -> None:
    """The rate at which model_error finds no error of the cubic spring on its own campaigns (alpha 5 %)."""
    from mudoe.example_oscillator import P_TRUE, build
    model, rng, t0 = build("cubic"), np.random.default_rng(seed), time.perf_counter()
    found = 0
    for i in range(n):
        found += model_error(model, _oscillator_campaign(rng), P_TRUE, kind="none").detected
        if (i + 1) % 100 == 0:
            print(f"  {i + 1} campaigns, {found} with model error found", file=sys.stderr, flush=True)
    ci = clopper_pearson(n - found, n)
    print(f"oscillator cubic (adequate), {n} campaigns, seed {seed}: no model error found in {100 * (n - found) / n:.2f} % "
          f"[Clopper-Pearson 95 % {100 * ci.lo:.2f}, {100 * ci.hi:.2f}] (target >= 95 %); {time.perf_counter() - t0:.0f} s")


def oscillator_wrong(n: int, seed: int) -> None:
    """Held-out coverage of the linear spring's 95 % new-reading bands on cubic-spring campaigns, time windows."""
    from mudoe.example_oscillator import build
    model, rng, t0 = build("linear"), np.random.default_rng(seed), time.perf_counter()
    splits = time_window_splits(OSC_EDGES)
    rows, kinds = [], {}
    for i in range(n):
        r = model_error(model, _oscillator_campaign(rng), [350.0, 3.0], splits=splits)
        kinds[r.kind] = kinds.get(r.kind, 0) + 1
        rows.append([[h.coverage(r.kind), h.coverage_plain, h.coverage_discrepancy, h.coverage_embedded,
                      h.widening(r.kind), h.n_values] for h in r.heldout])
        print(f"  campaign {i + 1}: " + ", ".join(f"{h.split}: {100 * h.coverage(r.kind):.1f} %" for h in r.heldout)
              + f" ({r.kind}, {time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    a = np.array(rows)                                     # (campaign, split, 6)
    w = a[:, :, 5]
    per = (a[:, :, :4] * w[:, :, None]).sum(axis=1) / w.sum(axis=1)[:, None]   # pooled per campaign
    se = per.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.full(4, np.nan)
    print(f"oscillator linear on cubic data, {n} campaigns x {len(splits)} time-window splits (edges {OSC_EDGES} s), "
          f"seed {seed}: held-out coverage of the 95 % new-reading bands with the chosen model error "
          f"{100 * per[:, 0].mean():.1f} (+- {100 * se[0]:.1f}) % (target [90, 99]); plain {100 * per[:, 1].mean():.1f} "
          f"(+- {100 * se[1]:.1f}) %, discrepancy {100 * per[:, 2].mean():.1f} (+- {100 * se[2]:.1f}) %, embedded "
          f"{100 * per[:, 3].mean():.1f} (+- {100 * se[3]:.1f}) %; per split (chosen) "
          + ", ".join(f"{sp.name}: {100 * np.average(a[:, j, 0], weights=w[:, j]):.1f} %" for j, sp in enumerate(splits))
          + f"; median widening {np.median(a[:, :, 4]):.1f}; kind auto chose {kinds}; {time.perf_counter() - t0:.0f} s")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench model_error")
    ap.add_argument("--n", type=int, default=1000, help="campaigns of the size study")
    ap.add_argument("--n-coverage", type=int, default=50, help="campaigns of the adequate-model coverage")
    ap.add_argument("--size-variant", default="M1")
    ap.add_argument("--seed", type=int, default=29)
    ap.add_argument("--quick", action="store_true", help="--n=100 --n-coverage=10")
    ap.add_argument("--oscillator-n", type=int, default=0, help="campaigns of the cubic oscillator (adequate)")
    ap.add_argument("--oscillator-n-coverage", type=int, default=0,
                    help="campaigns of the linear oscillator on cubic data (held-out coverage)")
    ap.add_argument("--n-offset", type=int, default=0,
                    help="campaigns of the synthetic condition offset (held-out coverage at a condition not seen)")
    ap.add_argument("--skip", default="", help="comma list of parts to skip: coverage,size,adequate,offset")
    args = ap.parse_args(argv or [])
    if args.quick:
        args.n, args.n_coverage = 100, 10
    skip = set(filter(None, args.skip.split(",")))
    study = prepare(load_config(CONFIG)) if not {"coverage", "size", "adequate"} <= skip else None
    if "coverage" not in skip:
        coverage_table(study)
        coverage_table(study, {"q_P": 0.0})          # the linkage is exact at zero press force
        coverage_table(study, groups=press_branches(study))     # the direction of motion named
        coverage_table(study, pure=True)             # sigma None: the pure error of the repeated series
        coverage_table(study, {"q_P": 0.0}, pure=True)
    if "offset" not in skip and args.n_offset:
        condition_offset_study(args.n_offset, args.seed + 4)
    if "size" not in skip and args.n:
        size_study(study, args.size_variant, args.n, args.seed)
    if "adequate" not in skip and args.n_coverage:
        adequate_coverage(study, args.size_variant, args.n_coverage, args.seed + 1)
    if args.oscillator_n:
        oscillator_adequate(args.oscillator_n, args.seed + 2)
    if args.oscillator_n_coverage:
        oscillator_wrong(args.oscillator_n_coverage, args.seed + 3)


if __name__ == "__main__":
    main(sys.argv[1:])
