"""Size of the normality gate (Algorithm 1, line 05) on exactly Gaussian data (issue 20 item 5).

For each number of sensors m in ``--sensors`` (default 3, 20, 60), ``--sets`` data sets
(default 2000) of exactly Gaussian readings are drawn: 4 series x 12 inputs x m sensors,
z ~ N(0, 1) independently.  The gate is :func:`identification.studies.detect.normality_check` (Shapiro-Wilk
on the differences z2 - z1, z4 - z3 of every sensor, 24 differences per sensor) at 5 % with each
multiplicity correction; it fails when some sensor's adjusted p-value is below 5 %.  Reported:
the failure rate with its binomial standard error sqrt(r (1 - r) / N) and Clopper-Pearson 95 %
interval, against 1 - (1 - 0.05 / m)^m (Holm/Bonferroni with uniform p-values) and 1 - 0.95^m
(no correction).  Every data set's gate is also recomputed from the Monte Carlo's batched
p-values (:func:`identification.studies.montecarlo.shapiro_pvalues` + :func:`identification.studies.normality.gate_fails`)
and must give the same decision.

Run ``python -m bench gate`` (``--sets=N --sensors=3,20,60 --seed=S``).
"""
from __future__ import annotations

import math
import time

import numpy as np

from identification import Measurements
from identification.studies.detect import normality_check
from identification.studies.montecarlo import clopper_pearson, shapiro_pvalues
from identification.studies.normality import GATE_CORRECTIONS, gate_fails

LEVEL = 0.05


def _args(argv) -> dict:
    out = {"sets": 2000, "sensors": (3, 20, 60), "seed": 20261125}
    for a in argv or []:
        key, _, val = a.lstrip("-").partition("=")
        if key == "sensors":
            out["sensors"] = tuple(int(v) for v in val.split(","))
        elif key in ("sets", "seed"):
            out[key] = int(val)
        else:
            raise SystemExit(f"bench gate: unknown option {a!r} (--sets=N, --sensors=3,20,60, --seed=S)")
    return out


def _expected(correction: str, m: int) -> float:
    return 1 - 0.95 ** m if correction == "none" else 1 - (1 - LEVEL / m) ** m


def run(n_sets: int, m: int, seed: int) -> list:
    """Rows (m, correction, failures, n, rate, se, ci, expected) for ``n_sets`` Gaussian data sets."""
    rng = np.random.default_rng([seed, m])
    q = np.linspace(0.0, 1.0, 12)[:, None]
    sensors = [f"s{k}" for k in range(m)]
    ds = [Measurements(q, rng.standard_normal((4, 12, m)), None, sensors=sensors) for _ in range(n_sets)]
    batched = np.array(shapiro_pvalues(ds))
    rows = []
    for c in GATE_CORRECTIONS:
        fails = np.array([not normality_check(d, LEVEL, correction=c).passed for d in ds])
        if not np.array_equal(fails, gate_fails(batched, LEVEL, c)):
            raise AssertionError(f"m = {m}, {c}: the batched gate differs from normality_check")
        k = int(fails.sum())
        r = k / n_sets
        rows.append((m, c, k, n_sets, r, math.sqrt(r * (1 - r) / n_sets), clopper_pearson(k, n_sets),
                     _expected(c, m)))
    return rows


def main(argv=None) -> None:
    a = _args(argv)
    print(f"Normality gate at {100 * LEVEL:g} % on Gaussian data: {a['sets']} data sets per row, 4 series x 12 "
          f"inputs, seed {a['seed']}")
    print("| sensors | correction | failed | rate | binomial se | Clopper-Pearson 95 % | expected | in [3, 6] % |")
    print("|---|---|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    for m in a["sensors"]:
        for m_, c, k, n, r, se, ci, exp in run(a["sets"], m, a["seed"]):
            ok = "yes" if 0.03 <= r <= 0.06 else ("-" if c == "none" else "NO")
            print(f"| {m_} | {c} | {k} / {n} | {100 * r:.2f} % | {100 * se:.2f} % | [{100 * ci.lo:.2f}, "
                  f"{100 * ci.hi:.2f}] % | {100 * exp:.2f} % | {ok} |", flush=True)
    print(f"({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
