r"""Monte Carlo validation of Algorithm 1: size, power and ellipsoid coverage.

Replication r draws a campaign z^(r) (n_M x n_q x n_S) and runs every split test of
:func:`identification.studies.detect.run_split_tests`.  Estimated quantities (each a binomial
proportion k / n with a Clopper-Pearson interval at level 1 - ci_level, default 95 %):

* **size** (data from the candidate model itself, z = h(y(p*), p*, q) + sigma eps):
  the family-wise rejection rate P(min_s alpha_min,s < TOL / n_tests), for the paper's
  statistic, the two-sample Wald one and the likelihood ratio; a calibrated test has
  size <= TOL;
* **power** (data from another generator, e.g. the virtual prototype): the rejection rate
  of each candidate model;
* **coverage**: the fraction of replications in which the true parameters p* lie in the
  (1 - alpha) confidence ellipsoid {p : (p - p_hat)^T C^{-1} (p - p_hat) <= chi2_{n_p}(1 - alpha)}
  of each calibration and validation fit.

The replications of a chunk are fitted together by the batch engine
(:func:`identification.fit.batch.fit_batch`: one batch per split and fit, same estimates as
:func:`identification.identify` to ~1e-10, identify as recorded per-member fallback), and
the statistics are those of :func:`identification.studies.detect.run_split_tests` on these fits,
computed for all replications of a chunk at once with the same formulas (run_split_tests
itself for a replication with a failed fit or an invalid covariance, which records the
failure; ``MonteCarloSettings.batch=False``: one identify call per fit).  The same batched
split tests serve other loops over many campaigns of one design (the parametric bootstrap of
:mod:`identification.studies.detect_bootstrap`) through :func:`batched_split_tests`.

Replications are independent: replication r uses the random stream
``numpy.random.default_rng(SeedSequence(seed).spawn(n_rep)[r])``, so the numbers do not
depend on the number of workers or on the backend (serial, local processes, Dask).
"""
from __future__ import annotations

import math
import os
import time
import uuid
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy import special, stats

from models.contract import Model
from models.dynamic import DynamicModel
from identification import cluster
from identification.fit.batch import BatchData, BatchFit, fit_batch
from identification.studies.detect import (DEFAULT_STATISTIC, DetectSettings, SplitTest, alpha_field, normality_check,
                     run_split_tests)
from identification.errors import DataError, IdentificationError
from identification.fit.measurements import Measurements
from identification.studies.normality_gate import correction_text, gate_fails
from identification.progress import Progress
from identification.studies.splits import Split, SplitError
from identification.fit.unbounded import not_bounded_reason
from models.state import set_jit, simulate, solve_states

__all__ = ["validate", "size_study", "power_study", "run_monte_carlo", "MonteCarloSettings", "MonteCarloResult",
           "Rate", "clopper_pearson", "ModelCampaign", "linearized_size", "LinearizedSize", "batched_split_tests",
           "shapiro_pvalues"]


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


def clopper_pearson(k: int, n: int, level: float = 0.95) -> Rate:
    """Exact binomial interval: lo = B^{-1}(a/2; k, n-k+1), hi = B^{-1}(1-a/2; k+1, n-k), a = 1 - level."""
    k, n = int(k), int(n)
    if n < 0 or not (0 <= k <= max(n, 0)):
        raise ValueError(f"k, n: need 0 <= k <= n, got k={k}, n={n}")
    if not (0.0 < level < 1.0):
        raise ValueError(f"level: must lie in (0, 1), got {level}")
    if n == 0:
        return Rate(0, 0, math.nan, math.nan, level)
    a = 1.0 - level
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a / 2, k + 1, n - k))
    return Rate(k, n, lo, hi, level)


# ---------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class MonteCarloSettings:
    """Settings of the Monte Carlo studies.

    Attributes
    ----------
    n_rep : int              replications
    seed : int               root of numpy.random.SeedSequence (replication r uses spawn(n_rep)[r])
    workers : int | None     local processes (None: os.cpu_count(); 1: serial in this process)
    scheduler : str | None   Dask scheduler address ("tcp://HOST:8786", ``[validate] scheduler``) or a
                             distributed.Client; None: local (``workers``)
    chunk_size : int | None  replications per task (None: about 8 tasks per worker, at most 50)
    progress : bool          progress bar on stderr (tqdm)
    coverage_alpha : float   the ellipsoid level checked for coverage (0.05: 95 % ellipsoids)
    ci_level : float         level of the Clopper-Pearson intervals
    detect : DetectSettings  tol, covariance kind, identify settings (normality is not gated here)
    jit : bool               compile small models' CasADi functions to C (models.state.set_jit;
                             same numbers, faster per replication); the libraries are compiled
                             once per machine and loaded from models.jit_cache by every worker
    batch : bool             fit the replications of a chunk together with the batch engine
                             (identification.fit.batch.fit_batch: same estimates to ~1e-10, identify as
                             per-member fallback); False: one identify call per fit
    """

    n_rep: int = 2000
    seed: int = 20261121
    workers: int | None = None
    scheduler: str | None = None
    chunk_size: int | None = None
    progress: bool = True
    coverage_alpha: float = 0.05
    ci_level: float = 0.95
    detect: DetectSettings = field(default_factory=lambda: DetectSettings(normality="override"))
    jit: bool = True
    batch: bool = True

    def __post_init__(self):
        if int(self.n_rep) < 1:
            raise ValueError(f"n_rep: need at least one replication, got {self.n_rep}")
        if self.workers is not None and int(self.workers) < 1:
            raise ValueError(f"workers: must be >= 1 or None, got {self.workers}")
        if self.chunk_size is not None and int(self.chunk_size) < 1:
            raise ValueError(f"chunk_size: must be >= 1 or None, got {self.chunk_size}")
        if not (0.0 < float(self.coverage_alpha) < 1.0):
            raise ValueError(f"coverage_alpha: must lie in (0, 1), got {self.coverage_alpha}")
        if not (0.0 < float(self.ci_level) < 1.0):
            raise ValueError(f"ci_level: must lie in (0, 1), got {self.ci_level}")
        if not isinstance(self.detect, DetectSettings):
            raise TypeError(f"detect: expected DetectSettings, got {type(self.detect).__name__}")
        object.__setattr__(self, "scheduler", cluster.check_scheduler(self.scheduler))


# ---------------------------------------------------------------------------- data generators
class ModelCampaign:
    """Simulated campaign from a model: z_ijk = h_k(y(p*), p*, q_j) + sigma_k eps_ijk, eps ~ N(0, 1).

    Picklable; the noise-free outputs are computed once at construction.

    Parameters
    ----------
    model : Model
    p_true : array_like (n_p,)     the truth p* (units of the model's parameters)
    inputs : array_like (n_q, d_q)
    sigma : array_like (n_S,)      noise standard deviation per sensor (unit of the outputs)
    n_M : int                      series per campaign
    """

    def __init__(self, model: Model, p_true, inputs, sigma, n_M: int = 2):
        self.p_true = np.asarray(p_true, float).ravel()
        if self.p_true.shape != (model.n_p,):
            raise DataError(f"p_true: expected {model.n_p} values ({', '.join(model.param_names)}), "
                            f"got {self.p_true.size}")
        self.inputs = np.atleast_2d(np.asarray(inputs, float))
        if self.inputs.shape[0] == 1 and model.n_q_dim == 1 and self.inputs.shape[1] > 1:
            self.inputs = self.inputs.T
        self.H = simulate(model, self.p_true, self.inputs)
        s = np.asarray(sigma, float)
        self.sigma = np.full(model.n_S, float(s)) if s.ndim == 0 else s.ravel()
        if self.sigma.shape != (model.n_S,) or not np.all(np.isfinite(self.sigma) & (self.sigma > 0)):
            raise DataError(f"sigma: expected {model.n_S} positive values, got {np.asarray(sigma).tolist()}")
        if int(n_M) < 1:
            raise DataError(f"n_M: need at least one series, got {n_M}")
        self.n_M = int(n_M)
        self.sensors = model.sensors
        self.input_names = model.inputs

    def __call__(self, rng: np.random.Generator) -> Measurements:
        eps = rng.standard_normal((self.n_M,) + self.H.shape)
        return Measurements(self.inputs, self.H[None] + self.sigma * eps, self.sigma, sensors=self.sensors,
                            input_names=self.input_names)


# ---------------------------------------------------------------------------- the replication
@dataclass(frozen=True, eq=False)
class _Task:
    """Everything a replication needs (pickled once per worker; ``token`` identifies it)."""

    token: str
    names: tuple
    models: tuple
    p0s: tuple
    weights: tuple
    splits: tuple
    generator: Callable
    truth: tuple          # per model: p* or None
    detect: DetectSettings
    coverage_alpha: float
    jit: bool = False
    batch: bool = False


@dataclass(eq=False)
class WorkerState:
    """What one Monte Carlo worker process keeps between the replications it runs.

    Attributes
    ----------
    task : _Task or None
        The worker's copy of the task: its models (and their compiled CasADi functions) are
        unpickled once per worker and reused by every replication.
    states : dict {(model name, inputs bytes): ndarray (n_q, n_y) or None}
        States at p0 per model and campaign inputs (warm start of every fit; None when the
        state solve failed).
    """

    task: _Task | None = None
    states: dict = field(default_factory=dict)

    def install(self, task: _Task) -> None:
        """Make ``task`` the worker's task (fresh state cache, JIT as the task asks)."""
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
        self.task = task
        self.states = {}
        set_jit(task.jit)

    def task_for(self, task: _Task | None) -> _Task:
        """The worker's copy of ``task`` (installed on first sight); None: the installed task."""
        if task is not None and (self.task is None or self.task.token != task.token):
            self.install(task)
        return self.task

    def start_states(self, name: str, model: Model, p0: np.ndarray, inputs: np.ndarray):
        """States at p0 for ``inputs`` (n_q, n_y), solved once per model and inputs, or None."""
        key = (name, inputs.tobytes())
        if key not in self.states:
            try:
                self.states[key] = solve_states(model, p0, inputs)
            except IdentificationError:
                self.states[key] = None
        return self.states[key]

    def clear(self) -> None:
        self.task, self.states = None, {}


#: this process's worker state.  Module level because a process pool initializer
#: (:func:`_init_worker`, run once per spawned process) and the chunks it runs can only
#: reach module-level objects; the serial backend installs and clears it around its run.
WORKER = WorkerState()


def _init_worker(task: _Task) -> None:
    """Process pool initializer: install ``task`` in this process's :data:`WORKER`."""
    WORKER.install(task)


def _empty_result(task: _Task) -> dict:
    """The result dict of one replication before its tests (NaN everywhere, no errors)."""
    n_m, n_s = len(task.names), len(task.splits)
    return {"alpha_paper": np.full((n_m, n_s), np.nan), "alpha_two_sample": np.full((n_m, n_s), np.nan),
            "alpha_lr": np.full((n_m, n_s), np.nan), "covered": np.full((n_m, n_s, 2), np.nan), "errors": [],
            "shapiro": None}


def _record(task: _Task, out: dict, im: int, tests) -> None:
    """Enter the split tests of model ``im`` into a replication's result dict ``out``."""
    name, model, truth = task.names[im], task.models[im], task.truth[im]
    g2 = stats.chi2.ppf(1 - task.coverage_alpha, model.n_p) if truth is not None else None
    for js, t in enumerate(tests):
        if t.ok:
            out["alpha_paper"][im, js] = t.alpha_paper
            out["alpha_two_sample"][im, js] = t.alpha_two_sample
            out["alpha_lr"][im, js] = t.alpha_lr
            if t.lr_error:
                out["errors"].append((name, t.split, "pooled fit", t.lr_error.splitlines()[0][:300]))
        else:
            out["errors"].append((name, t.split, t.stage, t.error.splitlines()[0][:300]))
        if truth is not None:
            for kk, (p, C) in enumerate(((t.p_cal, t.C_cal), (t.p_val, t.C_val))):
                if np.all(np.isfinite(p)) and np.all(np.isfinite(C)):
                    try:
                        L = np.linalg.cholesky(C)
                    except np.linalg.LinAlgError:
                        continue
                    v = np.linalg.solve(L, truth - p)
                    out["covered"][im, js, kk] = float(v @ v <= g2)


def _replicate(task: _Task, seed: np.random.SeedSequence) -> dict:
    """One replication, one identify call per fit."""
    data = task.generator(np.random.default_rng(seed))
    out = _empty_result(task)
    for im, name in enumerate(task.names):
        model = task.models[im]
        d = data[name] if isinstance(data, Mapping) else data
        if out["shapiro"] is None:
            out["shapiro"] = normality_check(d).pvalue
        st0 = WORKER.start_states(name, model, task.p0s[im], d.inputs)
        tests = run_split_tests(model, d, task.splits, task.p0s[im], task.weights[im], task.detect, name, st0)
        _record(task, out, im, tests)
    return out


def _given(fit: BatchFit, member: int):
    """A member's estimate for run_split_tests(fits=...): the estimate, or the exception of its fit."""
    try:
        return fit.result(member)
    except (IdentificationError, DataError) as exc:
        return exc


def _pooled_starts(model: Model, split: Split, fits: list, n_q_u: int) -> tuple:
    """Start values of the pooled fits: the precision-weighted mean (F_c + F_v)^{-1} (F_c p_c + F_v p_v)
    of each member's two estimates with their states (as detect's pooled Newton; moved to p by the
    tangent y' (p - p_est) when the fit is a batch member); NaN (start at p0)
    where it is singular or outside the bounds."""
    qs_c, qs_v = list(split.cal_inputs), list(split.val_inputs)
    qs = sorted(set(qs_c) | set(qs_v))
    P = np.full((len(fits), model.n_p), np.nan)
    Y = np.zeros((len(fits), n_q_u, model.n_y))
    for k, (ec, ev) in enumerate(fits):
        Fc, Fv = ec.information, ev.information
        try:
            p = np.linalg.solve(Fc + Fv, Fc @ ec.p + Fv @ ev.p)
        except np.linalg.LinAlgError:
            continue
        if not (np.all(p > model.lower) and np.all(p < model.upper)):
            continue
        if model.n_y:
            for j_list, est in ((qs_c, ec), (qs_v, ev)):
                rows = [qs.index(j) for j in j_list]
                Y[k, rows] = est.states
                yp = getattr(est, "state_derivatives", None)       # tangent predictor y(p) ~ y + y' (p - p_est)
                if yp is not None:
                    Y[k, rows] += yp @ (p - est.p)
        P[k] = p
    return P, Y


class _Subsets:
    """Picklable member -> Measurements of a split's subset (the data of a fallback fit)."""

    def __init__(self, ds: list, subset: Callable):
        self.ds, self.subset = ds, subset

    def __call__(self, r: int) -> Measurements:
        return self.subset(self.ds[r])


def _split_batch(ds: list, Z: np.ndarray, sig, inputs, series, subset: Callable, sensors=None) -> BatchData:
    """The stacked data of one subset (inputs, series[, sensors]) of every replication (as Split.calibration
    etc.: the values of the other sensors missing)."""
    ser = list(range(Z.shape[1])) if series is None else list(series)
    rows = list(inputs)
    z = Z[:, ser][:, :, rows]
    if sensors is not None:
        z = z.copy()
        z[..., [k for k in range(Z.shape[3]) if k not in set(sensors)]] = np.nan
    return BatchData(ds[0].inputs[rows], z, sig, _Subsets(ds, subset))


def _pooled_batch(ds: list, Z: np.ndarray, sig, split: Split, members: list) -> BatchData:
    """The stacked pooled data of a split for ``members`` (as Split.pooled: NaN outside the pooled values)."""
    pts = split.pooled_points(Z.shape[1])
    qs = sorted({j for j, _ in pts})
    series = sorted({i for _, i in pts})
    mask = split.pooled_mask(Z.shape[1], Z.shape[2], Z.shape[3])[np.ix_(series, qs, range(Z.shape[3]))]
    zp = np.where(mask[None], Z[members][:, series][:, :, qs], np.nan)
    return BatchData(ds[0].inputs[qs], zp, None if sig is None else sig[members],
                     _Subsets([ds[r] for r in members], split.pooled))


def _batched_fits(model: Model, splits: tuple, p0: np.ndarray, weights, det: DetectSettings, ds: list,
                  st0) -> tuple:
    """The fits of run_split_tests for R data sets of one model with the same inputs: every
    calibration, validation and pooled fit of a split is one :func:`identification.fit.batch.fit_batch`
    call over the data sets.  Returns (fits, pooled, ok_split): per data set the (calibration,
    validation) estimates of every split and {pooled points: pooled estimate or failure text} (the
    ``fits`` and ``pooled`` arguments of run_split_tests), and per split whether it fits the data.

    A fit_batch call that raises LinAlgError (a singular system for the batch as a whole, e.g. a
    subset that cannot identify the parameters) leaves its fits out (None): run_split_tests then
    runs identify on each of them, which names the failure as it does without the batch engine."""
    R, n_q, n_M = len(ds), ds[0].n_q, ds[0].n_M
    n_sel = int(np.count_nonzero(ds[0].sensor_weights(weights) > 0))
    fits = [[(None, None)] * len(splits) for _ in range(R)]
    Z = np.stack([d.z for d in ds])
    sig = None if ds[0].sigma is None else np.stack([np.asarray(d.sigma, float) for d in ds])
    ok_split = []
    for js, split in enumerate(splits):
        try:
            split.check(n_q, n_M, model.n_p, n_sel)
        except SplitError:
            ok_split.append(False)
            continue
        ok_split.append(True)
        got = []
        for sub, rows, series, sens in ((split.calibration, split.cal_inputs, split.cal_series, split.cal_sensors),
                                        (split.validation, split.val_inputs, split.val_series, split.val_sensors)):
            try:
                bf = fit_batch(model, _split_batch(ds, Z, sig, rows, series, sub, sens), p0, weights, det.identify,
                               Y0=None if st0 is None else st0[list(rows)])
            except np.linalg.LinAlgError:
                got.append([None] * R)         # singular batch (e.g. rank-deficient subset): identify per member
                continue
            got.append([_given(bf, r) for r in range(R)])
        for r in range(R):
            fits[r][js] = (got[0][r], got[1][r])
    pooled = [{} for _ in range(R)]
    done_keys = {}
    for js, split in enumerate(splits):
        if not ok_split[js]:
            continue
        key = split.pooled_key(n_M)
        have = done_keys.setdefault(key, set())
        members = [r for r in range(R)
                   if r not in have and not any(e is None or isinstance(e, Exception) or not_bounded_reason(e)
                                                for e in fits[r][js])]
        if not members:
            continue
        have.update(members)
        qs = sorted({j for j, _ in split.pooled_points(n_M)})
        P, Y = _pooled_starts(model, split, [fits[r][js] for r in members], len(qs))
        try:
            bf = fit_batch(model, _pooled_batch(ds, Z, sig, split, members), p0, weights, det.identify,
                           Y0=None if st0 is None else st0[qs], starts=P, start_states=Y if model.n_y else None)
        except np.linalg.LinAlgError:
            continue                           # run_split_tests fits these pooled data itself
        for k, r in enumerate(members):
            e = _given(bf, k)
            if isinstance(e, Exception):
                pooled[r][key] = f"pooled fit failed: {type(e).__name__}: {e}"
            else:
                pooled[r][key] = f"pooled fit {not_bounded_reason(e)}" if not_bounded_reason(e) else e
    return fits, pooled, ok_split


def _covariances(fits: list, det: DetectSettings, n_p: int) -> tuple:
    """(p (R, 2, n_p), C (R, 2, n_p, n_p), regular (R,)) of the calibration and validation fits of one
    split; regular False where a fit failed."""
    R = len(fits)
    P = np.full((R, 2, n_p), np.nan)
    C = np.full((R, 2, n_p, n_p), np.nan)
    regular = np.ones(R, bool)
    second = det.covariance == "second_order"
    for r, pair in enumerate(fits):
        for i, est in enumerate(pair):
            if isinstance(est, Exception) or est is None:
                regular[r] = False
                continue
            P[r, i] = est.p
            C[r, i] = est.cov if second else est.cov_gn
    return P, C, regular


def _batched_cholesky(C: np.ndarray) -> tuple:
    """(L, ok): the lower Cholesky factors of a stack (m, n, n) (numpy.linalg.cholesky), ok False (L the
    identity) where a matrix is not finite or not positive definite."""
    m, n = C.shape[0], C.shape[-1]
    ok = np.all(np.isfinite(C), axis=(1, 2))
    A = np.where(ok[:, None, None], C, np.eye(n))
    try:
        return np.linalg.cholesky(A), ok
    except np.linalg.LinAlgError:
        L = np.broadcast_to(np.eye(n), A.shape).copy()
        for i in np.flatnonzero(ok):
            try:
                L[i] = np.linalg.cholesky(A[i])
            except np.linalg.LinAlgError:
                ok[i] = False
        return L, ok


def _wald_d2(D: np.ndarray, C: np.ndarray) -> tuple:
    """(d2, ok) with d2 = D^T C^{-1} D for stacks D (m, n), C (m, n, n), as
    :func:`identification.inference.regions.mahalanobis2` (Cholesky of (C + C^T)/2); ok False where it would raise
    CovarianceError (C not finite, not symmetric to rtol 1e-8 / atol 1e-14 max|C|, not positive definite)."""
    Ct = C.swapaxes(1, 2)
    with np.errstate(invalid="ignore"):
        atol = 1e-14 * np.abs(C).max(axis=(1, 2))
        sym = np.all(np.abs(C - Ct) <= atol[:, None, None] + 1e-8 * np.abs(Ct), axis=(1, 2))
    L, ok = _batched_cholesky(0.5 * (C + Ct))
    ok &= sym
    v = np.linalg.solve(L, np.where(ok[:, None], D, 0.0)[:, :, None])[:, :, 0]
    return np.einsum("mi,mi->m", v, v), ok


def _split_statistics(model: Model, name: str, splits: tuple, det: DetectSettings, n_M: int, fits: list,
                      pooled: list, ok_split: list) -> list:
    """The split tests of R data sets from their batched fits, computed together: per data set the
    tuple of :class:`identification.studies.detect.SplitTest` that :func:`run_split_tests` gives with these
    fits (same formulas: Wald distances by Cholesky of the symmetrised covariance, the likelihood
    ratio 2 (Phi_pooled - Phi_cal - Phi_val) or, sigma estimated, the F (Chow) test).

    None for a data set that is not regular (a failed fit or pooled fit, a covariance that is not
    symmetric positive definite, a likelihood ratio that is not computable or clearly negative): the
    caller runs run_split_tests on it, which records the failures with their messages."""
    n_p, R = model.n_p, len(fits)
    regular = np.ones(R, bool)
    res = []
    for js, split in enumerate(splits):
        if not ok_split[js]:
            return [None] * R
        P, C, reg = _covariances([f[js] for f in fits], det, n_p)
        D = P[:, 1] - P[:, 0]
        d2p, okp = _wald_d2(D, C[:, 0])
        d2t, okt = _wald_d2(D, C[:, 0] + C[:, 1])
        reg &= okp & okt
        key = split.pooled_key(n_M)
        stat = np.full(R, np.nan)
        sig_est = np.zeros(R, bool)
        num, scale, dof = np.zeros(R), np.ones(R), np.zeros(R)
        for r in np.flatnonzero(reg):
            est_c, est_v = fits[r][js]
            est_u = pooled[r].get(key)
            if est_u is None or isinstance(est_u, str):
                reg[r] = False
                continue
            sig_est[r] = est_c.sigma_estimated
            if sig_est[r]:
                dof[r] = est_c.n_data + est_v.n_data - 2 * n_p
                rss_sep = est_c.rss + est_v.rss
                if dof[r] <= 0 or not rss_sep > 0:
                    reg[r] = False
                    continue
                num[r], scale[r] = est_u.rss - rss_sep, rss_sep
                stat[r] = (num[r] / n_p) / (rss_sep / dof[r])
            else:
                num[r] = 2.0 * (est_u.objective - est_c.objective - est_v.objective)
                scale[r] = 2.0 * max(est_u.objective, 1.0)
                stat[r] = num[r]
        reg &= ~(num < -1e-7 * scale)
        stat = np.maximum(stat, 0.0)
        a_lr = np.where(sig_est, stats.f.sf(stat, n_p, np.maximum(dof, 1)), special.chdtrc(n_p, stat))
        regular &= reg
        res.append((P, C, d2p, d2t, special.chdtrc(n_p, d2p), special.chdtrc(n_p, d2t), stat, a_lr))
    out = [None] * R
    for r in np.flatnonzero(regular):
        tests = []
        for js, (split, (P, C, d2p, d2t, a_p, a_t, stat, a_lr)) in enumerate(zip(splits, res)):
            est_c, est_v = fits[r][js]
            notes = (tuple(f"calibration fit: {n}" for n in est_c.notes)
                     + tuple(f"validation fit: {n}" for n in est_v.notes))
            c, v = split.label()
            tests.append(SplitTest(name, split.name, c, v, True, "", "", P[r, 0], P[r, 1], C[r, 0], C[r, 1],
                                   float(d2p[r]), float(d2t[r]), float(a_p[r]), float(a_t[r]), est_c.n_data,
                                   est_v.n_data, notes, float(stat[r]), float(a_lr[r]), ""))
        out[r] = tuple(tests)
    return out


def _same_design(datasets) -> list:
    """``datasets`` as a list of Measurements with the same inputs, series count and kind of sigma
    (DataError naming the argument otherwise)."""
    if isinstance(datasets, Measurements):
        raise TypeError("datasets: expected a sequence of Measurements, got one Measurements (wrap it in a list)")
    ds = list(datasets)
    if not ds:
        raise DataError("datasets: give at least one data set")
    bad = [type(d).__name__ for d in ds if not isinstance(d, Measurements)]
    if bad:
        raise TypeError(f"datasets: expected identification.Measurements, got {bad[0]}")
    d0 = ds[0]
    for r, d in enumerate(ds[1:], 1):
        if d.inputs.shape != d0.inputs.shape or not np.array_equal(d.inputs, d0.inputs):
            raise DataError(f"datasets: data set {r} has other inputs than data set 0; group the data sets by their "
                            "inputs and call once per group")
        if d.n_M != d0.n_M or d.z.shape != d0.z.shape:
            raise DataError(f"datasets: data set {r} has values of shape {d.z.shape}, data set 0 {d0.z.shape}; "
                            "give data sets of one shape")
        if (d.sigma is None) != (d0.sigma is None):
            raise DataError(f"datasets: data set {r} and data set 0 differ in whether sigma is known; give "
                            "sigma for all or for none")
    return ds


def batched_split_tests(model: Model, name: str | None, datasets, splits: Sequence[Split], p0, weights=None,
                        detect_settings: DetectSettings | None = None, start_states=None) -> list:
    """``run_split_tests(model, d, splits, p0, weights, detect_settings, name, start_states)`` for every
    data set d of ``datasets``, the fits of all data sets done together by the batch engine.

    Every calibration, validation and pooled fit of a split is one
    :func:`identification.fit.batch.fit_batch` call over the data sets (same estimates as
    :func:`identification.identify` to ~1e-10; identify as recorded per-member fallback), and the
    statistics (Wald distances d2 and the likelihood ratio or F statistic, chi^2 / F units, with
    their p-values alpha_min) are computed for all data sets at once with the formulas of
    :func:`identification.studies.detect.run_split_tests`.  A data set with a failed fit, a covariance that
    is not symmetric positive definite or a likelihood ratio that cannot be computed goes through
    run_split_tests itself (with the batch's fits), which records each failure with its stage and
    message, so failures are named exactly as there.

    Parameters
    ----------
    model : Model
    name : str or None               model label in the SplitTest records (None: the model's name)
    datasets : sequence of Measurements
        The R data sets: the same inputs, the same shape of values (n_M, n_q, n_S) and sigma known
        for all or for none (missing values may differ).  Group data sets by their inputs first.
    splits : sequence of Split
    p0 : array_like (n_p,)           start of every fit
    weights : array_like (n_S,), optional   sensor weights (0/1 selects sensors)
    detect_settings : DetectSettings, optional   covariance kind and identify settings
    start_states : array (n_q, n_y), optional   states at p0 for every input (warm start)

    Returns
    -------
    list of tuple of SplitTest
        One tuple (one SplitTest per split) per data set, in the order of ``datasets``.

    Raises
    ------
    TypeError, DataError, SplitError
        A bad argument (the message names it).
    """
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    ds = _same_design(datasets)
    splits = tuple(splits)
    if not splits or not all(isinstance(sp, Split) for sp in splits):
        raise SplitError("splits: give at least one identification.studies.splits.Split")
    det = detect_settings or DetectSettings()
    if not isinstance(det, DetectSettings):
        raise TypeError(f"detect_settings: expected DetectSettings, got {type(det).__name__}")
    p0 = np.asarray(p0, float).ravel()
    if p0.shape != (model.n_p,):
        raise DataError(f"p0: expected {model.n_p} values ({', '.join(model.param_names)}), got {p0.size}")
    if start_states is not None:
        start_states = np.asarray(start_states, float)
        if start_states.shape != (ds[0].n_q, model.n_y):
            raise DataError(f"start_states: expected the states at p0 of shape {(ds[0].n_q, model.n_y)}, got "
                            f"{start_states.shape}")
    name = name or model.name
    fits, pooled, ok_split = _batched_fits(model, splits, p0, weights, det, ds, start_states)
    out = _split_statistics(model, name, splits, det, ds[0].n_M, fits, pooled, ok_split)
    for r, tests in enumerate(out):
        if tests is None:
            out[r] = run_split_tests(model, ds[r], splits, p0, weights, det, name, start_states, fits=fits[r],
                                     pooled=pooled[r])
    return out


def _first(data, names):
    """The first model's Measurements of a generator's output (a Measurements or a mapping of them)."""
    return data[names[0]] if isinstance(data, Mapping) else data


def shapiro_pvalues(ds: list) -> list:
    """``normality_check(d).pvalue`` of every data set: the Shapiro-Wilk p-values per sensor of the
    differences of pairs of series.  Data sets without missing values and of a common shape are
    tested in one ``scipy.stats.shapiro(..., axis=0)`` call (the same test per column); the others
    by :func:`identification.studies.detect.normality_check`."""
    out = [None] * len(ds)
    groups = {}
    for r, d in enumerate(ds):
        if d.n_M >= 2 and np.all(np.isfinite(d.z)):
            groups.setdefault(d.z.shape, []).append(r)
        else:
            out[r] = normality_check(d).pvalue
    for (n_M, n_q, n_S), rows in groups.items():
        n_pairs = n_M // 2
        Z = np.stack([ds[r].z for r in rows])                                   # (m, n_M, n_q, n_S)
        D = (Z[:, 1:2 * n_pairs:2] - Z[:, 0:2 * n_pairs:2]).reshape(len(rows), n_pairs * n_q, n_S)
        cols = D.transpose(1, 0, 2).reshape(n_pairs * n_q, -1)
        pv = np.full(cols.shape[1], np.nan)
        ok = np.ptp(cols, axis=0) > 0 if cols.shape[0] >= 3 else np.zeros(cols.shape[1], bool)
        if np.any(ok):
            pv[ok] = stats.shapiro(cols[:, ok], axis=0).pvalue
        for k, r in enumerate(pv.reshape(len(rows), n_S)):
            out[rows[k]] = r
    return out


def _replicate_chunk(task: _Task, chunk: list) -> list:
    """The replications of a chunk with the batch engine: the data sets of each model are grouped by
    their inputs and every group's split tests run together (:func:`batched_split_tests`)."""
    datas = [task.generator(np.random.default_rng(seed)) for _, seed in chunk]
    outs = [_empty_result(task) for _ in chunk]
    for im, name in enumerate(task.names):
        ds = [d[name] if isinstance(d, Mapping) else d for d in datas]
        todo = [r for r in range(len(ds)) if outs[r]["shapiro"] is None]
        for r, pv in zip(todo, shapiro_pvalues([ds[r] for r in todo])):
            outs[r]["shapiro"] = pv
        groups = {}
        for r, d in enumerate(ds):
            groups.setdefault((d.inputs.tobytes(), d.inputs.shape, d.n_M, d.sigma is None), []).append(r)
        for rows in groups.values():
            sub = [ds[r] for r in rows]
            model = task.models[im]
            st0 = WORKER.start_states(name, model, task.p0s[im], sub[0].inputs)
            for r, tests in zip(rows, batched_split_tests(model, name, sub, task.splits, task.p0s[im],
                                                          task.weights[im], task.detect, st0)):
                _record(task, outs[r], im, tests)
    return [(i, out) for (i, _), out in zip(chunk, outs)]


def _run_chunk(task, chunk):
    """Replications [(index, SeedSequence), ...] -> [(index, result dict), ...]."""
    t = WORKER.task_for(task)
    if t.batch:
        return _replicate_chunk(t, chunk)
    return [(i, _replicate(t, s)) for i, s in chunk]


# ---------------------------------------------------------------------------- execution backends
def _chunks(n_rep, seed, n_workers, chunk_size):
    children = np.random.SeedSequence(seed).spawn(n_rep)
    size = chunk_size or max(1, min(50, math.ceil(n_rep / (8 * max(1, n_workers)))))
    items = list(enumerate(children))
    return [items[i:i + size] for i in range(0, n_rep, size)]


class _Collector:
    """Replication results by index; every chunk advances the progress bar."""

    def __init__(self, n_rep: int, bar):
        self.out = [None] * n_rep
        self.bar = bar

    def add(self, res: list) -> None:
        for i, r in res:
            self.out[i] = r
        self.bar.update(len(res))


def _run_dask(task: _Task, settings: MonteCarloSettings, got: _Collector) -> tuple:
    """Chunks on a Dask cluster (the task scattered once to every worker); returns (backend text, workers).

    Raises :class:`identification.cluster.SchedulerError` when Dask is missing or the scheduler
    cannot be reached.
    """
    with cluster.connect(settings.scheduler) as client:
        n_w = cluster.n_workers(client)
        chunks = _chunks(len(got.out), settings.seed, n_w, settings.chunk_size)
        cluster.run_chunks(client, _run_chunk, task, chunks, got.add)
        return f"dask ({client.scheduler.address}, {n_w} workers)", n_w


def _run_serial(task: _Task, chunks: list, got: _Collector) -> str:
    """Chunks in this process (worker state installed for the run, JIT restored after)."""
    prev = set_jit(task.jit)
    try:
        WORKER.install(task)
        for ch in chunks:
            got.add(_run_chunk(None, ch))
    finally:
        set_jit(prev)
        WORKER.clear()
    return "serial (this process)"


def _run_processes(task: _Task, chunks: list, n_w: int, got: _Collector) -> str:
    """Chunks on this process and ``n_w - 1`` spawned ones (:func:`identification.cluster.run_local`; each
    spawned process installs the task once, :func:`_init_worker`; this one's state is restored after)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    prev = set_jit(task.jit)
    try:
        cluster.run_local(_run_chunk, task, chunks, got.add, n_w, _init_worker)
    finally:
        set_jit(prev)
        WORKER.clear()
    return f"local processes ({n_w} workers: this one and {n_w - 1} spawned)"


def _execute(task: _Task, settings: MonteCarloSettings, desc: str) -> tuple:
    """Run every replication; returns (results ordered by index, backend text, workers)."""
    n_rep = int(settings.n_rep)
    bar = Progress(settings.progress).bar(n_rep, desc)
    got = _Collector(n_rep, bar)
    try:
        if settings.scheduler is not None:
            backend, n_w = _run_dask(task, settings, got)
        else:
            n_w = int(settings.workers or os.cpu_count() or 1)
            chunks = _chunks(n_rep, settings.seed, n_w, settings.chunk_size)
            if n_w == 1:
                backend = _run_serial(task, chunks, got)
            else:
                backend = _run_processes(task, chunks, n_w, got)
    finally:
        bar.close()
    return got.out, backend, n_w


# ---------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class MonteCarloResult:
    """Monte Carlo rejection rates and coverages (immutable).

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
        :func:`identification.studies.normality_gate.gate_fails`, as :func:`identification.studies.detect.normality_check`)."""
        fail = gate_fails(self.shapiro, self.normality_level, self.normality_correction, self.gated or None)
        return clopper_pearson(int(np.sum(fail)), int(fail.size), self.ci_level)

    def rejection_rate(self, model=None, statistic: str = DEFAULT_STATISTIC) -> Rate:
        """Family-wise rejection rate over the decided replications, with Clopper-Pearson CI."""
        d = self.decisions(model, statistic)
        ok = np.isfinite(d)
        return clopper_pearson(int(np.sum(d[ok])), int(ok.sum()), self.ci_level)

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
        return clopper_pearson(int(np.sum(a[ok] < lev)), int(ok.sum()), self.ci_level)

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
        return clopper_pearson(int(c.sum()), int(c.size), self.ci_level)

    def table(self) -> str:
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


# ---------------------------------------------------------------------------- linearised prediction
@dataclass(frozen=True)
class LinearizedSize:
    """Rejection probabilities of Algorithm 1 under the linearised model (no fitting).

    Attributes
    ----------
    family_paper, family_two_sample : float   P(some split has alpha_min < TOL / n_tests)
    split_paper, split_two_sample : ndarray   per split P(alpha_min < TOL / n_tests)
    eig_ratio : tuple of ndarray              per split eigenvalues of C_cal^{-1} (C_cal + C_val)
                                              (the paper's statistic is sum_i lambda_i chi2_1)
    n_draws : int ; mc_se : float             draws and the largest binomial standard error
    """

    family_paper: float
    family_two_sample: float
    split_paper: np.ndarray
    split_two_sample: np.ndarray
    eig_ratio: tuple
    n_draws: int
    mc_se: float


def linearized_size(model: Model, p_true, inputs, sigma, splits: Sequence[Split], n_M: int = 2, weights=None,
                    tol: float = 0.05, n_draws: int = 200_000, seed: int = 0) -> LinearizedSize:
    r"""Size of the Wald statistics when the model is linear in p near p* (exact for linear models).

    For a linear model the likelihood ratio equals the two-sample Wald statistic, so
    ``family_two_sample`` is its linearised size too.

    With sensitivities G_jk = dh_k/dp at p*, the Gauss-Newton estimate of a set A is
    p_A - p* = F_A^{-1} sum_{j in A, k} (n_A w_k / sigma_k^2) G_jk^T epsbar_jk (F_A its
    information), so p_val - p_cal is a linear map of the noise.  Gaussian noise is drawn
    directly (``n_draws`` campaigns, no fits) and the statistics are

        d2_paper = D^T F_cal D,   d2_2s = D^T (F_cal^{-1} + F_val^{-1})^{-1} D,   D = p_val - p_cal,

    compared with chi2_{n_p}(1 - TOL / n_tests).  Agreement with :func:`size_study` checks that
    the linearisation (and the chi^2 law) hold for a nonlinear model.
    """
    from models.sensitivity import sensitivities
    p_true = np.asarray(p_true, float).ravel()
    q = np.atleast_2d(np.asarray(inputs, float))
    sig = np.broadcast_to(np.asarray(sigma, float), (model.n_S,)).copy()
    w = np.ones(model.n_S) if weights is None else np.asarray(weights, float)
    if not (0.0 < float(tol) < 1.0):
        raise ValueError(f"tol: must lie in (0, 1), got {tol}")
    splits = tuple(splits)
    for sp in splits:
        sp.check(q.shape[0], n_M, model.n_p, int(np.count_nonzero(w > 0)))
    Y = solve_states(model, p_true, q)
    G = sensitivities(model, p_true, q, Y).G                      # (n_q, n_S, n_p)
    n_p = model.n_p
    thr = stats.chi2.ppf(1 - tol / len(splits), n_p)
    rng = np.random.default_rng(seed)

    n_q, n_S = q.shape[0], model.n_S

    def est_map(qi, si, ki):
        """(M, C): p_hat - p* = vec(eps)^T M for eps (n_M, n_q, n_S); C the covariance of p_hat."""
        ser = list(range(n_M)) if si is None else list(si)
        qi = list(qi)
        Gq = G[qi]
        wk = w if ki is None else w * np.isin(np.arange(n_S), ki)       # a sensor split: the set's sensors only
        F = len(ser) * np.einsum("jkp,jkr,k->pr", Gq, Gq, wk / sig ** 2)
        F2 = len(ser) * np.einsum("jkp,jkr,k->pr", Gq, Gq, wk ** 2 / sig ** 2)
        A = np.linalg.solve(F, np.eye(n_p))
        M = np.zeros((n_M, n_q, n_S, n_p))
        M[np.ix_(ser, qi)] = (Gq * (wk / sig ** 2)[None, :, None]) @ A
        return M.reshape(-1, n_p), A @ F2 @ A

    maps = [(est_map(sp.cal_inputs, sp.cal_series, sp.cal_sensors),
             est_map(sp.val_inputs, sp.val_series, sp.val_sensors)) for sp in splits]
    eig = tuple(np.sort(np.linalg.eigvals(np.linalg.solve(Cc, Cc + Cv)).real) for (_, Cc), (_, Cv) in maps)
    Dmaps = [(Mv - Mc, np.linalg.inv(Cc), np.linalg.inv(Cc + Cv)) for (Mc, Cc), (Mv, Cv) in maps]
    rej_p = np.zeros((n_draws, len(splits)), bool)
    rej_t = np.zeros((n_draws, len(splits)), bool)
    block = 50000
    for b0 in range(0, n_draws, block):
        nb = min(block, n_draws - b0)
        eps = (rng.standard_normal((nb, n_M, n_q, n_S)) * sig).reshape(nb, -1)
        for js, (MD, Wp, Wt) in enumerate(Dmaps):
            D = eps @ MD
            rej_p[b0:b0 + nb, js] = np.einsum("bp,pr,br->b", D, Wp, D) > thr
            rej_t[b0:b0 + nb, js] = np.einsum("bp,pr,br->b", D, Wt, D) > thr
    fp, ft = float(rej_p.any(axis=1).mean()), float(rej_t.any(axis=1).mean())
    se = math.sqrt(max(fp * (1 - fp), ft * (1 - ft), 1e-12) / n_draws)
    return LinearizedSize(fp, ft, rej_p.mean(axis=0), rej_t.mean(axis=0), eig, int(n_draws), se)


# ---------------------------------------------------------------------------- drivers
def _per_model(what: str, value, names: tuple) -> tuple:
    """One value per model name: ``value[name]`` from a mapping (DataError when one is missing), else ``value``."""
    if isinstance(value, Mapping):
        missing = [n for n in names if n not in value]
        if missing:
            raise DataError(f"{what}: no entry for model(s) {missing}")
        return tuple(value[n] for n in names)
    return tuple(value for _ in names)


def run_monte_carlo(models, generator: Callable, splits: Sequence[Split], p0, weights=None, truth=None,
                    kind: str = "power", settings: MonteCarloSettings | None = None,
                    description: str = "") -> MonteCarloResult:
    """Replicate ``generator(rng) -> Measurements`` (or {model: Measurements}) and test every model.

    Parameters
    ----------
    models : Model or mapping {name: Model}
    generator : picklable callable (numpy Generator) -> Measurements or mapping {name: Measurements}
    splits : sequence of Split
    p0 : array_like or mapping {name: array}   start values of the fits
    weights : array_like or mapping, optional  sensor weights per model
    truth : array_like or mapping, optional    p* per model, for the coverage of the ellipsoids
    kind : "size" or "power"                   label of the study
    settings : MonteCarloSettings
    """
    settings = settings or MonteCarloSettings()
    if kind not in ("size", "power"):
        raise ValueError(f"kind: expected 'size' or 'power', got {kind!r}")
    if not callable(generator):
        raise TypeError(f"generator: expected a callable rng -> Measurements, got {type(generator).__name__}")
    if isinstance(models, Model):
        models = {models.name: models}
    if not isinstance(models, Mapping) or not models:
        raise TypeError("models: expected a models.Model or a non-empty mapping {name: Model}")
    names = tuple(models)
    splits = tuple(splits)
    if not splits:
        raise SplitError("splits: at least one split is needed")
    p0s = tuple(np.asarray(v, float).ravel() for v in _per_model("p0", p0, names))
    for n, m, v in zip(names, models.values(), p0s):
        if v.shape != (m.n_p,):
            raise DataError(f"p0[{n!r}]: expected {m.n_p} values, got {v.size}")
    tr = tuple(None if v is None else np.asarray(v, float).ravel() for v in _per_model("truth", truth, names))
    task = _Task(token=uuid.uuid4().hex, names=names, models=tuple(models.values()), p0s=p0s,
                 weights=_per_model("weights", weights, names), splits=splits, generator=generator, truth=tr,
                 detect=settings.detect, coverage_alpha=float(settings.coverage_alpha), jit=bool(settings.jit),
                 batch=bool(settings.batch))
    # fail early (in this process) on a generator or split that does not fit the models
    probe = generator(np.random.default_rng(np.random.SeedSequence(settings.seed).spawn(1)[0]))
    for n, m in zip(names, models.values()):
        d = probe[n] if isinstance(probe, Mapping) else probe
        if not isinstance(d, Measurements):
            raise TypeError(f"generator: must return Measurements (or a mapping of them), got {type(d).__name__}")
        for sp in splits:
            sp.check(d.n_q, d.n_M)
    t0 = time.perf_counter()
    out, backend, n_w = _execute(task, settings, f"{kind} study")
    wall = time.perf_counter() - t0
    errors = tuple((i,) + e for i, r in enumerate(out) for e in r["errors"])
    return MonteCarloResult(
        kind=kind, models=names, splits=splits, tol=settings.detect.tol, n_rep=int(settings.n_rep),
        alpha_paper=np.stack([r["alpha_paper"] for r in out]),
        alpha_two_sample=np.stack([r["alpha_two_sample"] for r in out]),
        alpha_lr=np.stack([r["alpha_lr"] for r in out]),
        covered=np.stack([r["covered"] for r in out]), shapiro=np.stack([r["shapiro"] for r in out]),
        errors=errors, seed=int(settings.seed), backend=backend, workers=n_w, wall_time=wall,
        coverage_alpha=float(settings.coverage_alpha), ci_level=float(settings.ci_level), description=description,
        gated=tuple(bool(x) for x in _first(probe, names).sensor_weights(task.weights[0]) > 0),
        normality_level=settings.detect.normality_level, normality_correction=settings.detect.normality_correction)


def size_study(model: Model, p_true, inputs, sigma, splits: Sequence[Split], p0=None, n_M: int = 2,
               weights=None, settings: MonteCarloSettings | None = None, name: str | None = None) -> MonteCarloResult:
    """Size and coverage: campaigns simulated by ``model`` at p* (z = h(p*) + sigma eps), tested with ``model``.

    The family-wise rejection rate estimates the type-I error of Algorithm 1 (target: <= TOL).
    ``p0`` defaults to p*.
    """
    gen = ModelCampaign(model, p_true, inputs, sigma, n_M)
    nm = name or model.name
    return run_monte_carlo({nm: model}, gen, splits, gen.p_true if p0 is None else p0, weights, gen.p_true,
                           kind="size", settings=settings,
                           description=f"data from {nm} at p* = {gen.p_true.tolist()}, sigma = {gen.sigma.tolist()}, "
                                       f"n_M = {n_M}, n_q = {gen.inputs.shape[0]}")


def power_study(models, generator: Callable, splits: Sequence[Split], p0, weights=None,
                settings: MonteCarloSettings | None = None, description: str = "") -> MonteCarloResult:
    """Power: campaigns from ``generator`` (e.g. the virtual prototype), each model tested on them."""
    return run_monte_carlo(models, generator, splits, p0, weights, None, kind="power", settings=settings,
                           description=description)


def _validate_settings(settings: MonteCarloSettings | None, tol: float | None, **given) -> MonteCarloSettings:
    """The settings of :func:`validate`: ``settings``, or the keywords given (None = the default of
    :class:`MonteCarloSettings`; ``tol`` goes to its :class:`DetectSettings`, normality "override").

    Raises TypeError when ``settings`` and one of the keywords are both given.
    """
    given = {k: v for k, v in given.items() if v is not None}
    if settings is None:
        det = DetectSettings(normality="override") if tol is None else DetectSettings(tol=tol, normality="override")
        return MonteCarloSettings(detect=det, **given)
    if not isinstance(settings, MonteCarloSettings):
        raise TypeError(f"settings: expected MonteCarloSettings, got {type(settings).__name__}")
    clash = list(given) + ([] if tol is None else ["tol"])
    if clash:
        raise TypeError(f"settings and {', '.join(clash)}: give the keyword(s) inside settings (tol as "
                        "settings.detect.tol), not both")
    return settings


def validate(model, splits: Sequence[Split], p0=None, *, p_true=None, inputs=None, sigma=None, n_M: int = 2,
             generator: Callable | None = None, weights=None, n_rep: int | None = None, tol: float | None = None,
             seed: int | None = None, workers: int | None = None, scheduler=None, progress: bool | None = None,
             settings: MonteCarloSettings | None = None, name: str | None = None, data=None) -> MonteCarloResult:
    """Front door (``mudoe validate``): a size study without ``generator``, a power study with one.

    ``name`` labels the model in tables (size study; default the model's own name).

    Size: data from ``model`` at ``p_true`` with noise ``sigma`` at ``inputs`` (n_M series);
    the rejection rate at TOL should not exceed TOL for a calibrated statistic.  Power: data
    from ``generator(rng)``; the rejection rate of each model in ``model`` (a Model or a
    mapping {name: Model}).  Replications run on local processes (``workers``) or on a Dask
    cluster (``scheduler`` address or Client); the numbers do not depend on either.

    ``n_rep``, ``tol``, ``seed``, ``workers``, ``scheduler`` and ``progress`` (None: the
    defaults of :class:`MonteCarloSettings`, TOL 5 %) or ``settings`` with all of them; giving
    ``settings`` and one of those keywords raises TypeError.

    A dynamic model (:class:`models.dynamic.DynamicModel`) takes its campaign ``data``
    (DynamicMeasurements) instead of ``inputs`` / ``sigma``, instrument ``weights``, and splits by
    experiment, time window or early against late; the size study runs on its collocation at the
    campaign fit (:func:`identification.studies.dynamic_validate.validate_dynamic`; ``p_true`` defaults to
    that fit).
    """
    settings = _validate_settings(settings, tol, n_rep=n_rep, seed=seed, workers=workers, scheduler=scheduler,
                                  progress=progress)
    if isinstance(model, DynamicModel):
        if generator is not None or inputs is not None or sigma is not None:
            raise DataError("generator/inputs/sigma: a dynamic model is validated by a size study on its campaign: "
                            "give data= (DynamicMeasurements with its inputs, sampling times and sigma)")
        from identification.studies.dynamic_validate import validate_dynamic
        return validate_dynamic(model, data, splits, p0, p_true=p_true, n_M=n_M, weights=weights, settings=settings,
                                name=name)
    if generator is None:
        if isinstance(model, Mapping):
            raise DataError("model: a size study takes one model (the data generator itself)")
        if p_true is None or inputs is None or sigma is None:
            raise DataError("p_true, inputs, sigma: a size study needs the truth, the inputs and the noise level")
        return size_study(model, p_true, inputs, sigma, splits, p0, n_M, weights, settings, name=name)
    if p0 is None:
        raise DataError("p0: a power study needs start values for the fits")
    return power_study(model, generator, splits, p0, weights, settings)
