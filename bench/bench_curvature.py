"""Monte Carlo: how often is a fit flagged "not trustworthy" by the Bates-Watts curvature (issue 12)?

For each model, ``--n-rep`` campaigns are simulated from the model itself at the true
parameters (Gaussian noise with the stated sigma, sigma known), every campaign is fitted by
:func:`identification.identify`, and ``Estimate.curvature.trustworthy`` is recorded together
with the coverage of the 95 % ellipsoid (is the truth inside?).  Shares are given with
Clopper-Pearson 95 % intervals; fits that raise (e.g. IdentifiabilityError) are counted apart.

Weakly identified (target: not trustworthy for >= 90 % of the fits):

* ``truss P_x`` / ``truss P_y``: the README's two-bar truss (k1 = 210, k2 = 290 N/mm), 21 loads
  0..1000..0 N, 4 series, sigma 4 um, measured with one sensor only;
* ``MM low``: Michaelis-Menten y = Vm x / (K + x), Vm = 1, K = 5, observed below saturation at
  x = 0.2, 0.4, .., 1.0 (5 inputs), 2 series, sigma = 0.01.

Well conditioned (target: trustworthy for >= 90 %):

* ``truss both``: the README truss with both sensors (its documented setting);
* ``MM good``: the same Michaelis-Menten model at x = 1, 2.5, 5, 15, 50 (around and above K);
* ``press``: the press model M1 (k5 = k7 = 500 N/mm), the paper's 29 loads, 2 series, sensors
  D_y and F_x, the paper's sigmas.  With ``--splits`` (default) also every calibration and
  validation fit of the paper's four scenarios (what :func:`identification.studies.detect` checks).

Then the summary of one truss-with-one-sensor fit is printed (it must say "NOT trustworthy"
and name the profile intervals).

Run ``python -m bench.bench_curvature --n-rep 200`` (or ``python -m bench curvature``).
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from identification import Measurements, identify  # noqa: E402
from identification.studies.detect import run_split_tests  # noqa: E402
from identification.errors import DataError, IdentificationError  # noqa: E402
from identification.studies.splits import splits_from_scenarios  # noqa: E402
from models import Model  # noqa: E402
from models.library import two_bar_truss  # noqa: E402
from models.press import PRESS_SCENARIOS, Q_PAPER, press_model  # noqa: E402

TRUSS_TRUE = np.array([210.0, 290.0])
TRUSS_Q = np.r_[np.linspace(0, 1000, 11), np.linspace(1000, 0, 11)[1:]][:, None]
MM_TRUE = np.array([1.0, 5.0])
PRESS_SIGMA = np.array([1.518e-02, 4.895e-03, 3.904e-03])      # mm (the paper's, section 5)


def truss_model() -> Model:
    """The README's two-bar truss (mm, N; unknowns k1, k2 in N/mm)."""
    return two_bar_truss()


def mm_model() -> Model:
    return Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                          h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="Michaelis-Menten")


def cases():
    """(label, weakly identified?, model, inputs, p_true, p0, sigma, weights, n_series)."""
    truss, mm, press = truss_model(), mm_model(), press_model()
    sig_t = np.array([0.004, 0.004])
    return [
        ("truss P_x", True, truss, TRUSS_Q, TRUSS_TRUE, [200.0, 300.0], sig_t, np.array([1.0, 0.0]), 4),
        ("truss P_y", True, truss, TRUSS_Q, TRUSS_TRUE, [200.0, 300.0], sig_t, np.array([0.0, 1.0]), 4),
        ("MM low", True, mm, np.linspace(0.2, 1.0, 5)[:, None], MM_TRUE, MM_TRUE, np.array([0.01]), None, 2),
        ("truss both", False, truss, TRUSS_Q, TRUSS_TRUE, [200.0, 300.0], sig_t, None, 4),
        ("MM good", False, mm, np.array([1.0, 2.5, 5.0, 15.0, 50.0])[:, None], MM_TRUE, MM_TRUE,
         np.array([0.01]), None, 2),
        ("press", False, press, np.array(Q_PAPER, float)[:, None], press.p_nominal, [450.0, 550.0], PRESS_SIGMA,
         np.array([1.0, 1.0, 0.0]), 2),
    ]


def clopper_pearson(k: int, n: int) -> tuple:
    if n == 0:
        return float("nan"), float("nan")
    ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
    return ci.low, ci.high


def fmt_share(k: int, n: int) -> str:
    lo, hi = clopper_pearson(k, n)
    return f"{k}/{n} = {100 * k / max(n, 1):5.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]"


def run_case(label, weak, model, q, p_true, p0, sigma, weights, n_series, n_rep, seed, splits):
    h = model.simulate(p_true, q)
    flagged = covered = failed = fitted = 0
    split_flag = split_n = 0
    per_split = {}
    gN, gT = [], []
    t0 = time.perf_counter()
    for r in range(n_rep):
        rng = np.random.default_rng([seed, r])
        z = h[None] + sigma[None, None, :] * rng.standard_normal((n_series,) + h.shape)
        data = Measurements(q, z, sigma, sensors=model.sensors)
        try:
            est = identify(model, data, p0, weights=weights)
            c = est.curvature
        except (IdentificationError, DataError, np.linalg.LinAlgError):
            failed += 1
            continue
        fitted += 1
        flagged += not c.trustworthy
        covered += bool(est.ellipsoid(0.05).contains(p_true))
        gN.append(c.intrinsic)
        gT.append(c.parameter_effects)
        if splits:
            for t in run_split_tests(model, data, splits, p0, weights, curvature=True):
                if t.ok and t.trustworthy is not None:
                    split_n += 1
                    split_flag += not t.trustworthy
                    k_s, n_s = per_split.get(t.split, (0, 0))
                    per_split[t.split] = (k_s + (not t.trustworthy), n_s + 1)
    dt = time.perf_counter() - t0
    target = "not trustworthy >= 90 %" if weak else "trustworthy >= 90 %"
    k = flagged if weak else fitted - flagged
    lo, _ = clopper_pearson(k, fitted)
    print(f"{label:<11} ({'weak' if weak else 'good'}) n_rep {n_rep}, fits failed {failed}; "
          f"critical 1/sqrt(F) = {c.critical:.3g}" if fitted else f"{label}: every fit failed")
    print(f"   not trustworthy: {fmt_share(flagged, fitted)}   target {target}: "
          f"{'met' if k / max(fitted, 1) >= 0.9 else 'NOT met'} (CP lower bound {100 * lo:.1f} %)")
    print(f"   95 % ellipsoid covers the truth: {fmt_share(covered, fitted)}")
    if gN:
        print(f"   median curvature: intrinsic {np.median(gN):.3g}, parameter-effects {np.median(gT):.3g}; "
              f"{dt:.1f} s")
    if splits:
        print(f"   detect's split fits (4 scenarios x cal/val pairs, pair flagged if either fit is): "
              f"not trustworthy {fmt_share(split_flag, split_n)}")
        for name, (k_s, n_s) in per_split.items():
            print(f"      {name:<30} {fmt_share(k_s, n_s)}")
    return dict(label=label, weak=weak, fitted=fitted, flagged=flagged, failed=failed, covered=covered)


def truss_summary():
    model = truss_model()
    h = model.simulate(TRUSS_TRUE, TRUSS_Q)
    z = h[None] + 0.004 * np.random.default_rng(1).standard_normal((4,) + h.shape)
    data = Measurements(TRUSS_Q, z, [0.004, 0.004], sensors=model.sensors)
    est = identify(model, data, [200.0, 300.0], weights=[1.0, 0.0])
    print(est.summary())


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="bench_curvature", description=__doc__.splitlines()[0])
    ap.add_argument("--n-rep", type=int, default=200)
    ap.add_argument("--seed", type=int, default=20261123)
    ap.add_argument("--no-splits", action="store_true", help="skip the press split fits")
    args = ap.parse_args(argv)
    if args.n_rep < 1:
        ap.error("--n-rep: must be >= 1")
    print(f"date {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {platform.platform()}; "
          f"python {platform.python_version()}; nproc {os.cpu_count()}")
    try:
        cpu = subprocess.run(["lscpu"], capture_output=True, text=True, check=False).stdout.splitlines()
        print("\n".join(ln for ln in cpu if ln.startswith(("Model name", "CPU(s)"))))
    except OSError:
        pass
    press_splits = None if args.no_splits else splits_from_scenarios(PRESS_SCENARIOS, len(Q_PAPER))
    for case in cases():
        run_case(*case, args.n_rep, args.seed, press_splits if case[0] == "press" else None)
    print("\n--- the README truss measured with P_x only (seed 1): summary() ---")
    truss_summary()


if __name__ == "__main__":
    main()
