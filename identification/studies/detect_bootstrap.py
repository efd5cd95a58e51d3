r"""Parametric-bootstrap p-values of the split tests of Algorithm 1 (:mod:`identification.studies.detect`).

The asymptotic p-values alpha_min of :func:`identification.studies.detect.run_split_tests` compare each
statistic T (likelihood ratio, two-sample Wald, paper) with its chi^2 (or F) law, which holds
when the model is linear enough in its parameters.  The bootstrap estimates the law of T under
the null hypothesis "one parameter vector explains the whole campaign" directly:

1. fit the model to the whole campaign (the null fit): p_0, predictions h_jk = h_k(y_j(p_0), p_0, q_j)
   and sigma_k (the data's, or the estimate s when sigma is estimated);
2. for b = 1..B simulate z^{*(b)}_{ijk} = h_jk + sigma_k eps_ijk, eps ~ N(0, 1), with the data's
   missing-value pattern, and run every split test on it, giving T^{*(b)}_s per split s;
3. the bootstrap p-value of split s is

.. math::

    p_s = \frac{1 + \#\{b : T^{*(b)}_s \ge T_s\}}{1 + B_s},

with B_s the bootstrap campaigns whose statistic was computed (a failed fit is counted and
named, never dropped silently).  With the (k + 1) / (B + 1) convention P(p_s <= u) <= u under
the null for u on the grid k / (B + 1) when T is pivotal, so p_s is never 0 and a test at level
a needs B >= 1/a - 1 campaigns to be able to reject.

The family-wise p-value of a statistic compares the smallest asymptotic alpha_min over the
splits with its bootstrap law (min-p; the dependence between splits that share data is
accounted for, where Bonferroni only bounds it).

Campaign b draws from ``numpy.random.default_rng(SeedSequence(seed).spawn(B)[b])``: serial,
local processes and a Dask scheduler (:mod:`identification.cluster`) give identical numbers with
the same chunks, and numbers equal to round-off with other chunks (the batched reductions sum in
another order: estimates a few units in the last place apart).
The campaigns of a chunk share their inputs, so their split tests run together
(:func:`identification.studies.split_fits.batched_split_tests`: every calibration, validation and
pooled fit of a split one batch over the campaigns, the statistics computed together), which
gives the statistics of one run_split_tests per campaign (``fits=ONE_BY_ONE``) to ~1e-8 relative
(measured <= 9.3e-9 on 200 campaigns; the estimates agree to ~1e-10, and a Wald statistic of two
near-equal estimates keeps less of that relative precision the smaller it is).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from models.contract import Model
from identification import cluster
from identification.replicate import replicate, ReplicationTask
from identification.inference.bootstrap import simulated_campaign
from identification.studies.detect import STATISTICS, DetectSettings, run_split_tests
from identification.errors import DataError, IdentificationError, NotBoundedError
from identification.fit.unbounded import not_bounded_reason
from identification.inference.results import identify
from identification.fit.measurements import Measurements
from identification.studies.split_fits import BATCHED, SplitFits
from identification.progress import Progress
from identification.vocabulary import renamed_arguments
from identification.results_protocol import ResultProtocol, jsonable
from identification.studies.splits import Split, SplitError

__all__ = ["BootstrapDetection", "bootstrap_detect"]

#: the statistic of each column (chi^2 or F units), in the order of :data:`identification.studies.detect.STATISTICS`
_STAT_FIELDS = {"likelihood_ratio": "lr", "two_sample": "d2_two_sample", "paper": "d2_paper"}


def _statistics(tests) -> tuple:
    """(T (n_splits, 3), asymptotic alpha (n_splits, 3), errors [(split, text)]) of run_split_tests' output."""
    T = np.full((len(tests), len(STATISTICS)), np.nan)
    A = np.full_like(T, np.nan)
    errors = []
    for s, t in enumerate(tests):
        if not t.ok:
            errors.append((t.split, f"{t.stage}: {t.error.splitlines()[0][:200] if t.error else ''}"))
            continue
        for k, st in enumerate(STATISTICS):
            T[s, k] = getattr(t, _STAT_FIELDS[st])
            A[s, k] = t.alpha(st)
        if t.lr_error:
            errors.append((t.split, f"likelihood ratio: {t.lr_error.splitlines()[0][:200]}"))
    return T, A, errors


# ---------------------------------------------------------------------------- one bootstrap campaign
@dataclass(frozen=True, eq=False)
class CampaignStatistics:
    """The split tests of one bootstrap campaign (the record of :meth:`_Task.run_chunk`).

    Attributes
    ----------
    index : int                         the campaign b
    T : ndarray (n_splits, 3)           its statistics (NaN: not computed)
    A : ndarray (n_splits, 3)           their asymptotic p-values
    errors : tuple of (split, text)     failed fits or statistics
    """

    index: int
    T: np.ndarray
    A: np.ndarray
    errors: tuple


@dataclass(frozen=True, eq=False)
class _Task(ReplicationTask):
    """Everything a bootstrap campaign needs (sent once to every worker; see :mod:`identification.replicate`)."""

    model: Model
    model_name: str
    splits: tuple
    inputs: np.ndarray
    fitted: np.ndarray          # (n_q, n_S) predictions of the null fit
    mask: np.ndarray            # (n_M, n_q, n_S) values present in the data
    sigma_sim: np.ndarray       # (n_S,) sigma of the simulated noise
    sigma_data: object          # the data's sigma (None: estimated)
    sensors: tuple
    input_names: object
    p0: np.ndarray              # start of every fit: the null estimate
    weights: object
    settings: DetectSettings
    states: object              # (n_q, n_y) states of the null fit, or None
    fits: SplitFits             # the campaigns of a chunk fitted together (BATCHED) or one by one
    jit: bool                   # small models' CasADi functions as compiled C (models.state.set_jit)

    def run_chunk(self, chunk: list) -> list:
        """Campaigns [(index, SeedSequence), ...] -> [CampaignStatistics, ...]: the split tests of the chunk's
        campaigns (same inputs) by ``self.fits``."""
        datas = [simulated_campaign(self, s) for _, s in chunk]
        got = self.fits.split_tests(self.model, self.model_name, datas, self.splits, self.p0, self.weights,
                                    self.settings, self.states)
        out = []
        for (b, _), tests in zip(chunk, got):
            T, A, errors = _statistics(tests)
            out.append(CampaignStatistics(b, T, A, tuple(errors)))
        return out


def _seed_chunks(n: int, seed, chunk_size: int | None, fits: SplitFits, n_workers: int) -> list:
    """The campaigns cut into chunks (:func:`identification.cluster.seed_chunks`): without ``chunk_size``,
    about 4 per worker, min(n, fits.min_chunk) to fits.max_chunk campaigns each (the batch engine pays a
    per-call cost once per chunk, which outweighs one identify per fit below about 4 campaigns)."""
    if chunk_size is None:
        chunk_size = max(min(n, fits.min_chunk), min(fits.max_chunk, math.ceil(n / (4 * max(1, n_workers)))))
    return cluster.seed_chunks(n, seed, n_workers, chunk_size)


# ---------------------------------------------------------------------------- result
def _exceedance_pvalue(boot: np.ndarray, observed: float) -> tuple:
    """((1 + #{boot >= observed}) / (1 + B), B) over the finite bootstrap values; (NaN, B) when observed is NaN."""
    ok = boot[np.isfinite(boot)]
    if not np.isfinite(observed) or ok.size == 0:
        return math.nan, int(ok.size)
    return (1.0 + np.count_nonzero(ok >= observed)) / (1.0 + ok.size), int(ok.size)


@dataclass(frozen=True, eq=False)
class BootstrapDetection(ResultProtocol):
    """Bootstrap and asymptotic p-values of every split test of one model (immutable; the result protocol:
    :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Columns follow :data:`identification.studies.detect.STATISTICS` ("likelihood_ratio", "two_sample", "paper").

    Attributes
    ----------
    model : str
    splits : tuple of str
    statistics : tuple of str
    observed : ndarray (n_splits, 3)      the statistics of the data (chi^2 units; F for the likelihood
                                          ratio when sigma is estimated); NaN where not computed
    asymptotic : ndarray (n_splits, 3)    their chi^2 / F p-values alpha_min
    pvalue : ndarray (n_splits, 3)        bootstrap p-values (1 + #{T* >= T}) / (1 + B_s)
    n_valid : ndarray (n_splits, 3) int   B_s: bootstrap campaigns whose statistic was computed
    family_asymptotic : ndarray (3,)      smallest asymptotic alpha_min over the splits
    family_pvalue : ndarray (3,)          its bootstrap p-value (min-p over the splits)
    boot_statistics : ndarray (n_boot, n_splits, 3)   T* of every campaign (NaN: not computed)
    boot_asymptotic : ndarray (n_boot, n_splits, 3)   the asymptotic p-values of the campaigns
    n_boot : int ; seed : int or None
    p_null : ndarray (n_p,)               the null fit (whole campaign)
    sigma : ndarray (n_S,)                the sigma of the simulated noise
    sigma_estimated : bool
    errors : tuple of (campaign, split, text)   every failed bootstrap fit or statistic
    observed_errors : tuple of (split, text)    failed fits of the data itself
    backend : str ; wall_time : float (s)
    tests : tuple of SplitTest            the split tests of the data
    """

    model: str
    splits: tuple
    statistics: tuple
    observed: np.ndarray
    asymptotic: np.ndarray
    pvalue: np.ndarray
    n_valid: np.ndarray
    family_asymptotic: np.ndarray
    family_pvalue: np.ndarray
    boot_statistics: np.ndarray
    boot_asymptotic: np.ndarray
    n_boot: int
    seed: object
    p_null: np.ndarray
    sigma: np.ndarray
    sigma_estimated: bool
    errors: tuple
    observed_errors: tuple
    backend: str
    wall_time: float
    tests: tuple

    def __post_init__(self):
        for name in ("observed", "asymptotic", "pvalue", "n_valid", "family_asymptotic", "family_pvalue",
                     "boot_statistics", "boot_asymptotic", "p_null", "sigma"):
            a = np.array(getattr(self, name), copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def _col(self, statistic: str) -> int:
        if statistic not in self.statistics:
            raise ValueError(f"statistic: expected one of {self.statistics}, got {statistic!r}")
        return self.statistics.index(statistic)

    def pvalues(self, statistic: str = "likelihood_ratio") -> np.ndarray:
        """Bootstrap p-value of every split for one statistic."""
        return self.pvalue[:, self._col(statistic)]

    def rejected(self, tol: float = 0.05, statistic: str = "likelihood_ratio") -> bool:
        """Family-wise decision from the min-p bootstrap p-value: reject when it is <= ``tol``."""
        if not (0.0 < float(tol) < 1.0):
            raise ValueError(f"tol: must lie in (0, 1), got {tol!r}")
        p = self.family_pvalue[self._col(statistic)]
        return bool(np.isfinite(p) and p <= tol)

    def summary(self) -> str:
        """A table of asymptotic and bootstrap p-values per split and statistic, with the family-wise row."""
        lines = [f"Parametric bootstrap of the split tests of {self.model}: {self.n_boot} campaigns simulated from "
                 f"the null fit (sigma {'estimated' if self.sigma_estimated else 'known'}), seed {self.seed}; "
                 f"{self.backend}, {self.wall_time:.1f} s",
                 "p-values in %: asymptotic (chi^2 / F) | bootstrap (1 + #{T* >= T}) / (1 + B)",
                 "",
                 "| split | " + " | ".join(f"{st} asympt. | {st} bootstrap" for st in self.statistics) + " |",
                 "|---|" + "---|---|" * len(self.statistics)]

        def cell(a, p):
            fa = "n/a" if not np.isfinite(a) else f"{100 * a:.3g}"
            fp = "n/a" if not np.isfinite(p) else f"{100 * p:.3g}"
            return f"{fa} | {fp}"

        for s, name in enumerate(self.splits):
            lines.append(f"| {name} | " + " | ".join(cell(self.asymptotic[s, k], self.pvalue[s, k])
                                                      for k in range(len(self.statistics))) + " |")
        lines.append("| family (min-p) | " + " | ".join(cell(self.family_asymptotic[k], self.family_pvalue[k])
                                                         for k in range(len(self.statistics))) + " |")
        notes = [f"the smallest attainable bootstrap p-value is 1/(B+1) = {100 / (self.n_boot + 1):.3g} %"]
        if self.errors:
            b, sp, text = self.errors[0]
            notes.append(f"{len(self.errors)} failed fits or statistics in the bootstrap campaigns are excluded "
                         f"(first: campaign {b}, split {sp!r}: {text})")
        for sp, text in self.observed_errors:
            notes.append(f"split {sp!r} of the data: {text}")
        return "\n".join(lines + [""] + [f"[{k}] {t}" for k, t in enumerate(notes, 1)])

    def to_frame(self):
        """One row per split and the family-wise (min-p) row, indexed by ``split``: per statistic the observed
        value ``<st>`` (chi^2 or F units), the asymptotic p-value ``<st> asymptotic`` and the bootstrap p-value
        ``<st> bootstrap`` (in [0, 1]; NaN: not computed); ``.attrs``: model, n_boot, seed."""
        import pandas as pd
        rows = []
        for s, name in enumerate(self.splits):
            row = {}
            for k, st in enumerate(self.statistics):
                row.update({st: self.observed[s, k], f"{st} asymptotic": self.asymptotic[s, k],
                            f"{st} bootstrap": self.pvalue[s, k]})
            rows.append(row)
        fam = {}
        for k, st in enumerate(self.statistics):
            fam.update({st: np.nan, f"{st} asymptotic": self.family_asymptotic[k],
                        f"{st} bootstrap": self.family_pvalue[k]})
        df = pd.DataFrame(rows + [fam], index=pd.Index(list(self.splits) + ["family (min-p)"], name="split"))
        df.attrs.update(model=self.model, n_boot=self.n_boot, seed=self.seed)
        return df

    def to_dict(self) -> dict:
        """JSON-safe: model, splits, statistics, observed, asymptotic and bootstrap p-values (n_splits, 3),
        n_valid, the family-wise p-values, n_boot, seed, p_null, sigma, sigma_estimated, errors,
        observed_errors, backend, wall_time (s); the campaigns' statistics and the split tests are left out."""
        return jsonable(dict(model=self.model, splits=self.splits, statistics=self.statistics,
                             observed=self.observed, asymptotic=self.asymptotic, pvalue=self.pvalue,
                             n_valid=self.n_valid, family_asymptotic=self.family_asymptotic,
                             family_pvalue=self.family_pvalue, n_boot=self.n_boot, seed=self.seed, p_null=self.p_null,
                             sigma=self.sigma, sigma_estimated=self.sigma_estimated, errors=self.errors,
                             observed_errors=self.observed_errors, backend=self.backend, wall_time=self.wall_time))


# ---------------------------------------------------------------------------- front door
def _check_arguments(model, data, n_boot, workers, chunk_size, fits, jit, settings, splits, seed) -> tuple:
    """(settings, splits) of :func:`bootstrap_detect` once its arguments are checked (the error names the
    argument)."""
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    if not isinstance(data, Measurements):
        raise TypeError(f"data: expected an identification.Measurements, got {type(data).__name__}")
    if not (isinstance(n_boot, (int, np.integer)) and not isinstance(n_boot, bool) and n_boot >= 1):
        raise ValueError(f"n_rep: the number of bootstrap campaigns must be an integer >= 1, got {n_boot!r}")
    if workers is not None and not (isinstance(workers, (int, np.integer)) and workers >= 1):
        raise ValueError(f"workers: must be an integer >= 1 or None (all cores), got {workers!r}")
    if chunk_size is not None and not (isinstance(chunk_size, (int, np.integer)) and chunk_size >= 1):
        raise ValueError(f"chunk_size: must be an integer >= 1 or None (automatic), got {chunk_size!r}")
    if not isinstance(fits, SplitFits):
        raise TypeError(f"fits: expected BATCHED (batched fits) or ONE_BY_ONE (one identify per fit) of "
                        f"identification.studies.split_fits, got {fits!r}")
    if not isinstance(jit, (bool, np.bool_)):
        raise TypeError(f"jit: expected True (compiled model functions) or False, got {jit!r}")
    settings = settings or DetectSettings()
    if not isinstance(settings, DetectSettings):
        raise TypeError(f"settings: expected DetectSettings, got {type(settings).__name__}")
    splits = tuple(splits)
    if not splits or not all(isinstance(sp, Split) for sp in splits):
        raise SplitError("splits: give at least one identification.studies.splits.Split")
    try:
        np.random.SeedSequence(seed)
    except (TypeError, ValueError):
        raise ValueError(f"seed: expected a non-negative integer (or a sequence of them), got {seed!r}") from None
    return settings, splits


def _null_fit(model: Model, data: Measurements, p0, weights, settings: DetectSettings):
    """The fit of the whole campaign the bootstrap campaigns are simulated from (IdentificationError or
    NotBoundedError when there is none)."""
    try:
        null = identify(model, data, p0, weights=weights, settings=settings.identify)
    except (IdentificationError, DataError) as exc:
        raise IdentificationError(f"bootstrap_detect: the null fit of the whole campaign failed: {exc}",
                                  status="null fit failed") from None
    if not_bounded_reason(null):
        raise NotBoundedError(f"bootstrap_detect: the null fit of the whole campaign is {not_bounded_reason(null)}; "
                              "there is no null model to simulate campaigns from")
    return null


def _pvalues(T_obs: np.ndarray, A_obs: np.ndarray, T: np.ndarray, A: np.ndarray) -> tuple:
    """(p-values (n_s, n_k), B_s (n_s, n_k), family-wise asymptotic (n_k,), family-wise p-values (n_k,))
    of the observed statistics against the bootstrap ones T, A (n_boot, n_s, n_k)."""
    n_s, n_k = T_obs.shape
    pv = np.full((n_s, n_k), np.nan)
    nv = np.zeros((n_s, n_k), int)
    for s in range(n_s):
        for k in range(n_k):
            pv[s, k], nv[s, k] = _exceedance_pvalue(T[:, s, k], T_obs[s, k])
    # family-wise min-p: campaigns with every split computed; a smaller min alpha is more extreme
    fam_obs = np.where(np.all(np.isfinite(A_obs), axis=0), np.min(A_obs, axis=0), np.nan)
    fam_boot = np.where(np.all(np.isfinite(A), axis=1), np.min(A, axis=1), np.nan)    # (n_boot, 3)
    fam_p = np.array([_exceedance_pvalue(-fam_boot[:, k], -fam_obs[k])[0] for k in range(n_k)])
    return pv, nv, fam_obs, fam_p


@renamed_arguments(n_boot="n_rep")
def bootstrap_detect(model: Model, data: Measurements, splits: Sequence[Split], p0, weights=None, *,
                     n_rep: int = 199, seed=0, settings: DetectSettings | None = None,
                     workers: int | None = 1, scheduler=None, progress: Progress | None = None,
                     chunk_size: int | None = None, model_name: str | None = None,
                     fits: SplitFits = BATCHED, jit: bool = True) -> BootstrapDetection:
    """Bootstrap p-values of the split tests of ``model`` on ``data`` (see the module docstring).

    Parameters
    ----------
    model : Model
    data : Measurements             the campaign (sigma known per sensor, or None: estimated)
    splits : sequence of Split
    p0 : array_like (n_p,)          start of the null fit (then every fit starts at the null estimate)
    weights : array_like (n_S,), optional   sensor weights (0/1 selects sensors)
    n_rep : int >= 1               bootstrap campaigns B
    seed : int or SeedSequence entropy      root of the per-campaign seeds
    settings : DetectSettings, optional     covariance kind and identify settings of the fits
    workers : int or None           local processes (1: serial; None: all cores)
    scheduler : str or distributed.Client, optional   run on a Dask cluster instead of ``workers``
    progress : Progress, optional   a tqdm bar over the campaigns
    chunk_size : int, optional      campaigns per task (None: about 4 tasks per worker, with BATCHED
                                    min(n_rep, 16) to 50 campaigns, with ONE_BY_ONE at most 20; the
                                    numbers do not depend on it)
    model_name : str, optional      label (default the model's name)
    fits : SplitFits                BATCHED: fit the campaigns of a chunk together with the batch engine
                                    (:func:`identification.studies.split_fits.batched_split_tests`: the same
                                    statistics to ~1e-8 relative, failures named as run_split_tests
                                    names them); ONE_BY_ONE: one run_split_tests (identify per fit) per
                                    campaign (:mod:`identification.studies.split_fits`)
    jit : bool                      small models' CasADi functions as compiled C during the campaigns'
                                    fits (models.state.set_jit, as Monte Carlo does: the press 6.9 instead
                                    of 57.9 ms CPU per campaign; compiled once per machine, kept in
                                    models.jit_cache; without a C compiler the virtual machine)

    Raises
    ------
    ValueError, TypeError
        A bad argument (the message names it).
    IdentificationError
        The null fit of the whole campaign failed.
    identification.cluster.SchedulerError
        Dask is not installed or the scheduler cannot be reached.
    """
    import time
    settings, splits = _check_arguments(model, data, n_rep, workers, chunk_size, fits, jit, settings, splits, seed)
    scheduler = cluster.check_scheduler(scheduler)
    name = model_name or model.name
    t0 = time.perf_counter()
    tests = run_split_tests(model, data, splits, p0, weights, settings, name)
    T_obs, A_obs, obs_err = _statistics(tests)
    null = _null_fit(model, data, p0, weights, settings)
    task = _Task(model, name, splits, np.asarray(data.inputs), np.asarray(null.fitted, float), data.mask(),
                 np.asarray(null.sigma, float), None if data.sigma is None else np.asarray(data.sigma, float),
                 tuple(data.sensors), None if data.input_names is None else tuple(data.input_names),
                 np.asarray(null.p, float), None if weights is None else np.asarray(weights, float), settings,
                 None if null.states is None or null.states.size == 0 else np.asarray(null.states, float),
                 fits, bool(jit))
    bar = (progress or Progress(enabled=False)).bar(int(n_rep), "bootstrap campaigns")
    try:
        reps = replicate(task, int(n_rep), functools.partial(_seed_chunks, int(n_rep), seed, chunk_size, fits),
                         workers=workers, scheduler=scheduler, bar=bar)
    finally:
        bar.close()
    T = np.stack([r.T for r in reps.records])
    A = np.stack([r.A for r in reps.records])
    pv, nv, fam_obs, fam_p = _pvalues(T_obs, A_obs, T, A)
    errors = [(r.index,) + e for r in reps.records for e in r.errors]
    return BootstrapDetection(
        model=name, splits=tuple(sp.name for sp in splits), statistics=STATISTICS, observed=T_obs,
        asymptotic=A_obs, pvalue=pv, n_valid=nv, family_asymptotic=fam_obs, family_pvalue=fam_p,
        boot_statistics=T, boot_asymptotic=A, n_boot=int(n_rep),
        seed=seed if isinstance(seed, (int, np.integer)) else str(seed), p_null=np.asarray(null.p, float),
        sigma=np.asarray(null.sigma, float), sigma_estimated=data.sigma is None,
        errors=tuple(sorted(errors, key=lambda e: (e[0], str(e[1])))), observed_errors=tuple(obs_err),
        backend=str(reps.backend), wall_time=time.perf_counter() - t0, tests=tests)
