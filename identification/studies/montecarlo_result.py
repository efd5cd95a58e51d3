"""The outcome of a Monte Carlo study of Algorithm 1: rejection rates and coverages with their exact binomial
intervals (:class:`Rate`, :func:`clopper_pearson`) and the immutable :class:`MonteCarloResult` that
:func:`identification.studies.montecarlo.validate`, ``size_study`` and ``power_study`` return.

A rate k / n is reported with its Clopper-Pearson interval at level 1 - alpha (default 95 %):
lo = B^{-1}(alpha/2; k, n-k+1), hi = B^{-1}(1-alpha/2; k+1, n-k), B the beta distribution (scipy.stats).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import stats

from identification.results_protocol import ResultProtocol, jsonable
from identification.studies.detect import DEFAULT_STATISTIC, alpha_field
from identification.studies.normality import correction_text, gate_fails
from identification.vocabulary import renamed_arguments

__all__ = ["Rate", "clopper_pearson", "MonteCarloResult"]


# ---------------------------------------------------------------------------- statistics helpers
@dataclass(frozen=True)
class Rate:
    """A binomial proportion k / n with its Clopper-Pearson interval [lo, hi] (level ``level``)."""

    k: int
    n: int
    lo: float
    hi: float
    level: float = 0.95

    @property
    def rate(self) -> float:
        return self.k / self.n if self.n else math.nan

    def __str__(self):
        if not self.n:
            return "n/a"
        return f"{100 * self.rate:.2f} % [{100 * self.lo:.2f}, {100 * self.hi:.2f}] ({self.k}/{self.n})"


@renamed_arguments(level=("alpha", lambda c: 1.0 - c))
def clopper_pearson(k: int, n: int, alpha: float = 0.05) -> Rate:
    """Exact binomial interval of confidence level 1 - alpha: lo = B^{-1}(a/2; k, n-k+1), hi = B^{-1}(1-a/2; k+1, n-k),
    a = 1 - level (``level=`` is the old keyword, deprecated)."""
    k, n = int(k), int(n)
    if n < 0 or not (0 <= k <= max(n, 0)):
        raise ValueError(f"k, n: need 0 <= k <= n, got k={k}, n={n}")
    if not (0.0 < alpha < 1.0):
        raise ValueError(f"alpha: must lie in (0, 1), got {alpha}")
    level = 1.0 - alpha
    if n == 0:
        return Rate(0, 0, math.nan, math.nan, level)
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return Rate(k, n, lo, hi, level)



# ---------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class MonteCarloResult(ResultProtocol):
    """Monte Carlo rejection rates and coverages (immutable; the result protocol: :meth:`summary`,
    :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    kind : str                  "size" (data from the candidate model) or "power"
    models, splits : tuple      model names and the Split objects
    tol : float                 family-wise level TOL
    n_rep : int
    alpha_paper, alpha_two_sample, alpha_lr : ndarray (n_rep, n_models, n_splits)   NaN where a split
                                failed (alpha_lr also where the pooled fit failed)
    covered : ndarray (n_rep, n_models, n_splits, 2)   1/0 p* in the cal/val ellipsoid, NaN if n/a
    shapiro : ndarray (n_rep, n_S)   normality-gate p-values of each simulated campaign
    gated : tuple of bool       the sensors of the gate (the first model's selected sensors)
    normality_level, normality_correction   the gate's family-wise level and correction
                                (``detect.normality_level`` / ``normality_correction`` of the settings)
    errors : tuple              (replication, model, split, stage, message) of every failed split
    seed, backend, workers, wall_time, coverage_alpha, ci_level, description
    """

    kind: str
    models: tuple
    splits: tuple
    tol: float
    n_rep: int
    alpha_paper: np.ndarray
    alpha_two_sample: np.ndarray
    alpha_lr: np.ndarray
    covered: np.ndarray
    shapiro: np.ndarray
    errors: tuple
    seed: int
    backend: str
    workers: int
    wall_time: float
    coverage_alpha: float
    ci_level: float
    description: str = ""
    gated: tuple = ()
    normality_level: float = 0.05
    normality_correction: str = "holm"

    def __post_init__(self):
        for name in ("alpha_paper", "alpha_two_sample", "alpha_lr", "covered", "shapiro"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def _im(self, model):
        model = self.models[0] if model is None else model
        if model not in self.models:
            raise KeyError(f"model: {model!r} not in {list(self.models)}")
        return self.models.index(model)

    def _alpha(self, statistic):
        return getattr(self, alpha_field(statistic))

    def decisions(self, model=None, statistic: str = DEFAULT_STATISTIC) -> np.ndarray:
        """Per replication: 1 reject, 0 accept, NaN undecided (Bonferroni at TOL / n_tests).

        (Holm rejects the family exactly when Bonferroni does.)
        """
        a = self._alpha(statistic)[:, self._im(model), :]
        thr = self.tol / a.shape[1]
        rej = np.any(a < thr, axis=1)
        undec = ~rej & np.any(~np.isfinite(a), axis=1)
        return np.where(rej, 1.0, np.where(undec, np.nan, 0.0))

    def gate_failure_rate(self) -> Rate:
        """Fraction of the campaigns failing the normality gate (its correction over the gated sensors;
        :func:`identification.studies.normality.gate_fails`, as :func:`identification.studies.detect.normality_check`)."""
        fail = gate_fails(self.shapiro, self.normality_level, self.normality_correction, self.gated or None)
        return clopper_pearson(int(np.sum(fail)), int(fail.size), alpha=1.0 - self.ci_level)

    def rejection_rate(self, model=None, statistic: str = DEFAULT_STATISTIC) -> Rate:
        """Family-wise rejection rate over the decided replications, with Clopper-Pearson CI."""
        d = self.decisions(model, statistic)
        ok = np.isfinite(d)
        return clopper_pearson(int(np.sum(d[ok])), int(ok.sum()), alpha=1.0 - self.ci_level)

    def n_undecided(self, model=None, statistic: str = DEFAULT_STATISTIC) -> int:
        return int(np.sum(~np.isfinite(self.decisions(model, statistic))))

    def n_not_bounded(self, model=None) -> int:
        """Failed split fits whose data did not bound the parameters (the best fit ran off to infinity;
        recorded in ``errors`` with a message starting "not bounded" or "pooled fit not bounded")."""
        name = self.models[self._im(model)]
        return sum(1 for e in self.errors if e[1] == name and "not bounded:" in e[4][:30])

    def split_rejection_rate(self, split: int, model=None, statistic: str = DEFAULT_STATISTIC,
                             level: float | None = None) -> Rate:
        """Rejection rate of one split's hypothesis at ``level`` (default TOL / n_tests)."""
        a = self._alpha(statistic)[:, self._im(model), split]
        lev = self.tol / len(self.splits) if level is None else level
        ok = np.isfinite(a)
        return clopper_pearson(int(np.sum(a[ok] < lev)), int(ok.sum()), alpha=1.0 - self.ci_level)

    def coverage(self, model=None, split: int | None = None, which: str = "both") -> Rate:
        """Fraction of fits whose (1 - coverage_alpha) ellipsoid contains p* (size studies only).

        Fits of one replication are dependent (shared data); the interval treats all pooled
        fits as independent and is therefore too narrow when pooling splits -- use one split
        and ``which`` = "cal" or "val" for an exact binomial interval.
        """
        c = self.covered[:, self._im(model)]
        if split is not None:
            c = c[:, [split]]
        if which == "cal":
            c = c[..., 0]
        elif which == "val":
            c = c[..., 1]
        elif which != "both":
            raise ValueError(f"which: expected 'cal', 'val' or 'both', got {which!r}")
        c = c[np.isfinite(c)]
        return clopper_pearson(int(c.sum()), int(c.size), alpha=1.0 - self.ci_level)

    def summary(self) -> str:
        """Markdown table of rejection rates (all three statistics) and, for size studies, coverage."""
        lev = 100 * self.tol / len(self.splits)
        lines = [f"{self.kind} study: {self.n_rep} replications, TOL = {100 * self.tol:g} %, "
                 f"{len(self.splits)} splits (per-test level {lev:.4g} %), Clopper-Pearson {100 * self.ci_level:g} % "
                 f"intervals; {self.backend}, {self.wall_time:.1f} s",
                 "",
                 "| model | statistic | family-wise rejection rate | undecided | "
                 + " | ".join(f"split {j + 1} ({sp.name})" for j, sp in enumerate(self.splits)) + " |",
                 "|---|---|---|---|" + "---|" * len(self.splits)]
        for m in self.models:
            for st in ("paper", "two_sample", "likelihood_ratio"):
                cells = [f"{100 * self.split_rejection_rate(j, m, st).rate:.2f} %" for j in range(len(self.splits))]
                lines.append(f"| {m} | {st} | {self.rejection_rate(m, st)} | {self.n_undecided(m, st)} | "
                             + " | ".join(cells) + " |")
        if self.kind == "size" and np.any(np.isfinite(self.covered)):
            lines += ["", f"Coverage of the {100 * (1 - self.coverage_alpha):g} % ellipsoids (p* inside):", "",
                      "| model | split | calibration fit | validation fit |", "|---|---|---|---|"]
            for m in self.models:
                for j, sp in enumerate(self.splits):
                    lines.append(f"| {m} | {sp.name} | {self.coverage(m, j, 'cal')} | {self.coverage(m, j, 'val')} |")
        sw = self.shapiro
        if sw.size and np.any(np.isfinite(sw)):
            rates = [f"{100 * np.mean(sw[:, k][np.isfinite(sw[:, k])] < 0.05):.1f} %" for k in range(sw.shape[1])]
            gate = correction_text(self.normality_correction, self.normality_level,
                                   int(np.sum(self.gated)) if self.gated else sw.shape[1])
            lines += ["", "Normality gate (Shapiro-Wilk 5 %) rejection rate per sensor: " + ", ".join(rates),
                      f"Normality gate (Shapiro-Wilk at {gate}) failure rate: {self.gate_failure_rate()}"]
        if self.errors:
            lines += ["", f"{len(self.errors)} failed split fits, e.g.: {self.errors[0]}"]
            nb = {m: self.n_not_bounded(m) for m in self.models}
            if any(nb.values()):
                lines.append("of them, fits whose data did not bound the parameters (the best fit ran off to infinity; "
                             "counted as undecided): " + ", ".join(f"{m} {k}" for m, k in nb.items()))
        return "\n".join(lines)

    def table(self) -> str:
        """Deprecated alias of :meth:`summary` (the result protocol's name); warns."""
        warnings.warn("MonteCarloResult.table() is deprecated; use MonteCarloResult.summary()", DeprecationWarning,
                      stacklevel=2)
        return self.summary()

    def to_frame(self):
        """One row per (model, statistic), indexed by both: the family-wise rejection rate (a fraction in
        [0, 1]) with its Clopper-Pearson interval ``lo``, ``hi``, the counts ``k`` / ``n``, the undecided
        replications and the rejection rate of each split's hypothesis (columns ``split <name>``); ``.attrs``:
        kind, n_rep, tol, seed."""
        import pandas as pd
        rows = []
        for m in self.models:
            for st in ("paper", "two_sample", "likelihood_ratio"):
                r = self.rejection_rate(m, st)
                rows.append(dict(model=m, statistic=st, rate=r.rate, lo=r.lo, hi=r.hi, k=r.k, n=r.n,
                                 undecided=self.n_undecided(m, st),
                                 **{f"split {sp.name}": self.split_rejection_rate(j, m, st).rate
                                    for j, sp in enumerate(self.splits)}))
        df = pd.DataFrame(rows).set_index(["model", "statistic"])
        df.attrs.update(kind=self.kind, n_rep=self.n_rep, tol=self.tol, seed=self.seed)
        return df

    def to_dict(self) -> dict:
        """Rejection rates (all three statistics), coverage (size studies) and the :meth:`summary` text as
        JSON-safe values (what a report's results.json holds under "validation")."""
        out = dict(kind=self.kind, models=list(self.models), n_rep=self.n_rep, tol=self.tol, seed=self.seed,
                   wall_time=self.wall_time, description=self.description, rates={})
        for m in self.models:
            for st in ("paper", "two_sample", "likelihood_ratio"):
                r = self.rejection_rate(m, st)
                out["rates"][f"{m}/{st}"] = dict(rate=r.rate, lo=r.lo, hi=r.hi, k=r.k, n=r.n)
        if self.kind == "size":
            cov = {}
            for m in self.models:
                for j, sp in enumerate(self.splits):
                    c, v = self.coverage(m, j, "cal"), self.coverage(m, j, "val")
                    cov[f"{m}/{sp.name}"] = dict(cal=c.rate, val=v.rate)
            out["coverage"] = cov
        out["table"] = self.summary()
        return jsonable(out)

