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
computed for all replications of a chunk at once with the same formulas
(:func:`identification.studies.split_fits.batched_split_tests`; run_split_tests itself for a
replication with a failed fit or an invalid covariance, which records the failure;
``MonteCarloSettings.fits=ONE_BY_ONE``: one identify call per fit).

A dynamic model is validated the same way on the collocation of its campaign fit, a static model
over the (sensor, time) outputs (:func:`flat_size_study`; splits by time window become splits of
those columns, :func:`identification.studies.splits.flat_split`).

Replications are independent: replication r uses the random stream
``numpy.random.default_rng(SeedSequence(seed).spawn(n_rep)[r])``, so the numbers do not
depend on the number of workers or on the backend (serial, local processes, Dask: the
replication engine :mod:`identification.replicate`).  The result they give, :class:`MonteCarloResult` with its
rates (:class:`Rate`, :func:`clopper_pearson`), is defined in :mod:`identification.studies.montecarlo_result`.
"""
from __future__ import annotations

import functools
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy import stats

from models.contract import Model
from identification import cluster
from identification.replicate import ReplicationTask, replicate
from identification.studies.detect import DetectSettings
from identification.errors import DataError, IdentificationError
from identification.fit.measurements import Measurements
from identification.fit.problem import COLLOCATED, strategy_for
from identification.inference.results import identify
from identification.progress import Progress
from identification.studies.montecarlo_result import MonteCarloResult, Rate, clopper_pearson
from identification.vocabulary import renamed_arguments
from identification.studies.split_fits import (BATCHED, ONE_BY_ONE, SplitFits, batched_split_tests,
                                               shapiro_pvalues)
from identification.studies.splits import Split, SplitError, flat_split
from models.state import simulate, solve_states

__all__ = ["validate", "size_study", "power_study", "run_monte_carlo", "MonteCarloSettings", "MonteCarloResult",
           "Rate", "clopper_pearson", "ModelCampaign", "linearized_size", "LinearizedSize", "batched_split_tests",
           "shapiro_pvalues", "BATCHED", "ONE_BY_ONE", "Replication", "SplitFailure", "SizeStudyTask", "FlatSizeStudy",
           "flat_size_study"]


# ---------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class MonteCarloSettings:
    """Settings of the Monte Carlo studies.

    Attributes
    ----------
    n_rep : int              replications
    seed : int               root of numpy.random.SeedSequence (replication r uses spawn(n_rep)[r])
    workers : int | None     local processes (None: os.cpu_count(); 1: serial in this process); serial with
                             one cluster.WorkersWarning where spawned processes cannot start (a script
                             without ``if __name__ == "__main__":``, stdin, a task that cannot be sent)
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
    fits : SplitFits         BATCHED: fit the replications of a chunk together with the batch engine
                             (identification.fit.batch.fit_batch: same estimates to ~1e-10, identify as
                             per-member fallback); ONE_BY_ONE: one identify call per fit
                             (:mod:`identification.studies.split_fits`)
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
    fits: SplitFits = BATCHED

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
        if not isinstance(self.fits, SplitFits):
            raise TypeError(f"fits: expected BATCHED or ONE_BY_ONE of identification.studies.split_fits, got "
                            f"{self.fits!r}")
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
@dataclass(frozen=True)
class SplitFailure:
    """A split test of one model that gave no statistic (or no likelihood ratio), and why."""

    model: str
    split: str
    stage: str
    message: str


@dataclass(frozen=True, eq=False)
class Replication:
    """The split tests of every model on one simulated campaign (the record of :meth:`SizeStudyTask.run_chunk`).

    Attributes
    ----------
    index : int
    alpha_paper, alpha_two_sample, alpha_lr : ndarray (n_models, n_splits)   NaN where not computed
    covered : ndarray (n_models, n_splits, 2)   1/0 p* in the cal/val ellipsoid, NaN if n/a
    shapiro : ndarray (n_S,)                    normality-gate p-values of the campaign
    failures : tuple of SplitFailure
    """

    index: int
    alpha_paper: np.ndarray
    alpha_two_sample: np.ndarray
    alpha_lr: np.ndarray
    covered: np.ndarray
    shapiro: np.ndarray
    failures: tuple


class _StartStates:
    """States at p0 per (model name, campaign inputs), solved once per process (the warm start of every fit;
    None when the state solve failed).  Sent empty to a worker."""

    def __init__(self):
        self.cache = {}

    def __reduce__(self):
        return _StartStates, ()                 # sent empty: every process solves its own

    def __call__(self, name: str, model: Model, p0: np.ndarray, inputs: np.ndarray):
        key = (name, inputs.tobytes())
        if key not in self.cache:
            try:
                self.cache[key] = solve_states(model, p0, inputs)
            except IdentificationError:
                self.cache[key] = None
        return self.cache[key]


@dataclass(frozen=True, eq=False)
class SizeStudyTask(ReplicationTask):
    """Everything a replication needs (sent once to every worker; see :mod:`identification.replicate`)."""

    names: tuple
    models: tuple
    p0s: tuple
    weights: tuple
    splits: tuple
    generator: Callable
    truth: tuple          # per model: p* or None
    detect: DetectSettings
    coverage_alpha: float
    fits: SplitFits
    jit: bool
    start_states: _StartStates = field(default_factory=_StartStates)

    def run_chunk(self, chunk: list) -> list:
        """Replications [(index, SeedSequence), ...] -> [Replication, ...]: the data sets of each model are
        grouped by their inputs and every group's split tests run together (``self.fits``)."""
        datas = [self.generator(np.random.default_rng(seed)) for _, seed in chunk]
        outs = [_empty_result(self) for _ in chunk]
        for im, name in enumerate(self.names):
            ds = [d[name] if isinstance(d, Mapping) else d for d in datas]
            todo = [r for r in range(len(ds)) if outs[r]["shapiro"] is None]
            for r, pv in zip(todo, self.fits.shapiro([ds[r] for r in todo])):
                outs[r]["shapiro"] = pv
            groups = {}
            for r, d in enumerate(ds):
                groups.setdefault((d.inputs.tobytes(), d.inputs.shape, d.n_M, d.sigma is None), []).append(r)
            model, p0 = self.models[im], self.p0s[im]
            for rows in groups.values():
                sub = [ds[r] for r in rows]
                st0 = self.start_states(name, model, p0, sub[0].inputs)
                for r, tests in zip(rows, self.fits.split_tests(model, name, sub, self.splits, p0, self.weights[im],
                                                                self.detect, st0)):
                    _record(self, outs[r], im, tests)
        return [Replication(index=i, failures=tuple(out.pop("errors")), **out) for (i, _), out in zip(chunk, outs)]


def _empty_result(task: SizeStudyTask) -> dict:
    """The fields of one replication's record before its tests (NaN everywhere, no failures)."""
    n_m, n_s = len(task.names), len(task.splits)
    return {"alpha_paper": np.full((n_m, n_s), np.nan), "alpha_two_sample": np.full((n_m, n_s), np.nan),
            "alpha_lr": np.full((n_m, n_s), np.nan), "covered": np.full((n_m, n_s, 2), np.nan), "errors": [],
            "shapiro": None}


def _record(task: SizeStudyTask, out: dict, im: int, tests) -> None:
    """Enter the split tests of model ``im`` into a replication's fields ``out``."""
    name, model, truth = task.names[im], task.models[im], task.truth[im]
    g2 = stats.chi2.ppf(1 - task.coverage_alpha, model.n_p) if truth is not None else None
    for js, t in enumerate(tests):
        if t.ok:
            out["alpha_paper"][im, js] = t.alpha_paper
            out["alpha_two_sample"][im, js] = t.alpha_two_sample
            out["alpha_lr"][im, js] = t.alpha_lr
            if t.lr_error:
                out["errors"].append(SplitFailure(name, t.split, "pooled fit", t.lr_error.splitlines()[0][:300]))
        else:
            out["errors"].append(SplitFailure(name, t.split, t.stage, t.error.splitlines()[0][:300]))
        if truth is not None:
            for kk, (p, C) in enumerate(((t.p_cal, t.C_cal), (t.p_val, t.C_val))):
                if np.all(np.isfinite(p)) and np.all(np.isfinite(C)):
                    try:
                        L = np.linalg.cholesky(C)
                    except np.linalg.LinAlgError:
                        continue
                    v = np.linalg.solve(L, truth - p)
                    out["covered"][im, js, kk] = float(v @ v <= g2)


def _first(data, names):
    """The first model's Measurements of a generator's output (a Measurements or a mapping of them)."""
    return data[names[0]] if isinstance(data, Mapping) else data


def _backend_text(backend: cluster.Backend) -> str:
    """The backend as a Monte Carlo result names it."""
    if backend.kind == "serial":
        return "serial (this process)"
    if backend.kind == "local":
        return f"local processes ({backend.workers} workers: this one and {backend.workers - 1} spawned)"
    return str(backend)


def _execute(task: SizeStudyTask, settings: MonteCarloSettings, desc: str) -> tuple:
    """Run every replication on the replication engine; returns (records by index, backend text, workers).

    Chunks of about 8 per worker, at most 50 replications (the numbers do not depend on them)."""
    n_rep = int(settings.n_rep)
    chunks = functools.partial(cluster.seed_chunks, n_rep, settings.seed, chunk_size=settings.chunk_size,
                               per_worker=8, max_size=50)
    bar = Progress(settings.progress).bar(n_rep, desc)
    try:
        reps = replicate(task, n_rep, chunks, workers=settings.workers, scheduler=settings.scheduler, bar=bar)
    finally:
        bar.close()
    return reps.records, _backend_text(reps.backend), reps.backend.workers


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


@renamed_arguments(p_true="p", n_M="n_series", tol="alpha")
def linearized_size(model: Model, p, inputs, sigma, splits: Sequence[Split], n_series: int = 2, weights=None,
                    alpha: float = 0.05, n_draws: int = 200_000, seed: int = 0) -> LinearizedSize:
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
    p = np.asarray(p, float).ravel()
    q = np.atleast_2d(np.asarray(inputs, float))
    sig = np.broadcast_to(np.asarray(sigma, float), (model.n_S,)).copy()
    w = np.ones(model.n_S) if weights is None else np.asarray(weights, float)
    if not (0.0 < float(alpha) < 1.0):
        raise ValueError(f"alpha: must lie in (0, 1), got {alpha}")
    splits = _row_splits(splits)
    for sp in splits:
        sp.check(q.shape[0], n_series, model.n_p, int(np.count_nonzero(w > 0)))
    Y = solve_states(model, p, q)
    G = sensitivities(model, p, q, Y).G                      # (n_q, n_S, n_p)
    n_p = model.n_p
    thr = stats.chi2.ppf(1 - alpha / len(splits), n_p)
    rng = np.random.default_rng(seed)

    n_q, n_S = q.shape[0], model.n_S

    def est_map(qi, si, ki):
        """(M, C): p_hat - p* = vec(eps)^T M for eps (n_series, n_q, n_S); C the covariance of p_hat."""
        ser = list(range(n_series)) if si is None else list(si)
        qi = list(qi)
        Gq = G[qi]
        wk = w if ki is None else w * np.isin(np.arange(n_S), ki)       # a sensor split: the set's sensors only
        F = len(ser) * np.einsum("jkp,jkr,k->pr", Gq, Gq, wk / sig ** 2)
        F2 = len(ser) * np.einsum("jkp,jkr,k->pr", Gq, Gq, wk ** 2 / sig ** 2)
        A = np.linalg.solve(F, np.eye(n_p))
        M = np.zeros((n_series, n_q, n_S, n_p))
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
        eps = (rng.standard_normal((nb, n_series, n_q, n_S)) * sig).reshape(nb, -1)
        for js, (MD, Wp, Wt) in enumerate(Dmaps):
            D = eps @ MD
            rej_p[b0:b0 + nb, js] = np.einsum("bp,pr,br->b", D, Wp, D) > thr
            rej_t[b0:b0 + nb, js] = np.einsum("bp,pr,br->b", D, Wt, D) > thr
    fp, ft = float(rej_p.any(axis=1).mean()), float(rej_t.any(axis=1).mean())
    se = math.sqrt(max(fp * (1 - fp), ft * (1 - ft), 1e-12) / n_draws)
    return LinearizedSize(fp, ft, rej_p.mean(axis=0), rej_t.mean(axis=0), eig, int(n_draws), se)


# ---------------------------------------------------------------------------- drivers
def _row_splits(splits) -> tuple:
    """The splits as a non-empty tuple of splits of rows (SplitError for none, or for a split by time window:
    the replications simulate static campaigns, a dynamic model's over its (sensor, time) columns)."""
    splits = tuple(splits)
    if not splits:
        raise SplitError("splits: at least one split is needed")
    timed = [sp.name for sp in splits if sp.timed]
    if timed:
        raise SplitError(f"splits {timed} select readings by time window; a Monte Carlo study of a static model "
                         "takes splits of rows and sensor columns (validate(dynamic model, data=...) converts them, "
                         "identification.studies.splits.flat_split)")
    return splits


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
    splits = _row_splits(splits)
    p0s = tuple(np.asarray(v, float).ravel() for v in _per_model("p0", p0, names))
    for n, m, v in zip(names, models.values(), p0s):
        if v.shape != (m.n_p,):
            raise DataError(f"p0[{n!r}]: expected {m.n_p} values, got {v.size}")
    tr = tuple(None if v is None else np.asarray(v, float).ravel() for v in _per_model("truth", truth, names))
    task = SizeStudyTask(names=names, models=tuple(models.values()), p0s=p0s, weights=_per_model("weights", weights, names),
                 splits=splits, generator=generator, truth=tr, detect=settings.detect,
                 coverage_alpha=float(settings.coverage_alpha), fits=settings.fits, jit=bool(settings.jit))
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
    errors = tuple((r.index, f.model, f.split, f.stage, f.message) for r in out for f in r.failures)
    return MonteCarloResult(
        kind=kind, models=names, splits=splits, tol=settings.detect.tol, n_rep=int(settings.n_rep),
        alpha_paper=np.stack([r.alpha_paper for r in out]),
        alpha_two_sample=np.stack([r.alpha_two_sample for r in out]),
        alpha_lr=np.stack([r.alpha_lr for r in out]),
        covered=np.stack([r.covered for r in out]), shapiro=np.stack([r.shapiro for r in out]),
        errors=errors, seed=int(settings.seed), backend=backend, workers=n_w, wall_time=wall,
        coverage_alpha=float(settings.coverage_alpha), ci_level=float(settings.ci_level), description=description,
        gated=tuple(bool(x) for x in _first(probe, names).sensor_weights(task.weights[0]) > 0),
        normality_level=settings.detect.normality_level, normality_correction=settings.detect.normality_correction)


@renamed_arguments(p_true="p", n_M="n_series")
def size_study(model: Model, p, inputs, sigma, splits: Sequence[Split], p0=None, n_series: int = 2,
               weights=None, settings: MonteCarloSettings | None = None, name: str | None = None) -> MonteCarloResult:
    """Size and coverage: campaigns simulated by ``model`` at p* (z = h(p*) + sigma eps), tested with ``model``.

    The family-wise rejection rate estimates the type-I error of Algorithm 1 (target: <= TOL).
    ``p0`` defaults to p*.
    """
    gen = ModelCampaign(model, p, inputs, sigma, n_series)
    nm = name or model.name
    return run_monte_carlo({nm: model}, gen, splits, gen.p_true if p0 is None else p0, weights, gen.p_true,
                           kind="size", settings=settings,
                           description=f"data from {nm} at p* = {gen.p_true.tolist()}, sigma = {gen.sigma.tolist()}, "
                                       f"n_M = {n_series}, n_q = {gen.inputs.shape[0]}")


def power_study(models, generator: Callable, splits: Sequence[Split], p0, weights=None,
                settings: MonteCarloSettings | None = None, description: str = "") -> MonteCarloResult:
    """Power: campaigns from ``generator`` (e.g. the virtual prototype), each model tested on them."""
    return run_monte_carlo(models, generator, splits, p0, weights, None, kind="power", settings=settings,
                           description=description)


# ---------------------------------------------------------------------------- a dynamic model's size study
@dataclass(frozen=True, eq=False)
class FlatSizeStudy:
    """The size study of a dynamic model as a static one: the arguments of :func:`size_study`.

    Attributes
    ----------
    model : Model                  the collocated model at the campaign fit (outputs (sensor, time))
    p_true : ndarray (n_p,)        truth of the simulated campaigns
    inputs : ndarray (n_q, d_q)    the experiments' inputs
    sigma : ndarray (n_S,)         sigma per (sensor, time) output
    splits : tuple of Split        the splits on the flat outputs
    p0 : array_like or None        start values of every replication (None: p_true)
    weights : ndarray or None      weight per (sensor, time) output
    name : str                     the model's label in tables
    """

    model: object
    p_true: np.ndarray
    inputs: np.ndarray
    sigma: np.ndarray
    splits: tuple
    p0: object
    weights: object
    name: str


def flat_size_study(model, data, splits, p0=None, *, p_true=None, weights=None, identify_settings=None,
                    name: str | None = None, discretisation=None) -> FlatSizeStudy:
    r"""The size study of a dynamic model on its collocation at the campaign fit.

    The campaign is fitted once (:func:`identification.fit.dynamic_fit.identify_dynamic`: Radau IIA
    collocation with the discretisation error controlled at p̂); the size study then runs on that
    collocated model (``est.model``, a static model over the (sensor, time) outputs) with its flat data,

    .. math::

        z^{(r)}_{ijk} = h_{k}(y_j(p^*), p^*, q_j) + \sigma_k \varepsilon^{(r)}_{ijk},\qquad k = (l, t),

    every experiment simulated at every sampling time of the campaign (the union of the experiments'
    times).  Splits of experiments apply to the rows; splits by time window (half-open, e.g.
    :func:`identification.studies.splits.early_late_dynamic_split`) become splits of the (sensor, time)
    columns (:func:`identification.studies.splits.flat_split`); splits with sensor columns
    (:func:`identification.studies.splits.time_window_split`) are used as they are.

    Parameters
    ----------
    model : models.dynamic.DynamicModel
    data : DynamicMeasurements          the campaign (known sigma): inputs, sampling times, mesh
    splits : sequence of Split
    p0 : array_like (n_p,), optional     start values of the campaign fit and of every replication
                                         (default ``p_true``)
    p_true : array_like (n_p,), optional truth of the simulated campaigns (default: the campaign fit p̂)
    weights : array_like (n_S,), optional  instrument weights (each instrument at every sampling time)
    identify_settings : IdentifySettings, optional   settings of the campaign fit
    name : str, optional                 the model's label in tables
    discretisation : DiscretisationSettings, optional

    Returns
    -------
    FlatSizeStudy
    """
    COLLOCATED.check_data(data, need="validate on a dynamic model needs the campaign as identification."
                          "DynamicMeasurements (inputs, sampling times, sigma)", error=DataError)
    if data.sigma is None:
        raise DataError("data.sigma: a size study simulates noise of known sigma; give sigma with the data")
    start = p0 if p0 is not None else p_true
    if start is None:
        raise DataError("p0, p_true: give start values (p0) or the truth (p_true) of the dynamic model")
    w = None
    if weights is not None:
        w = np.asarray(weights, float).ravel()
        if w.shape != (model.n_S,):
            raise DataError(f"weights: expected {model.n_S} instrument weights ({', '.join(model.sensors)}), got "
                            f"shape {w.shape}")
    est = identify(model, data, start, weights=w, settings=identify_settings, discretisation=discretisation)
    cm, flat = est.model, est.data
    flat_splits = tuple(flat_split(sp, cm.outputs, flat.n_q) for sp in splits)
    w_flat = None if w is None else np.array([w[model.sensors.index(s)] for s, _ in cm.outputs])
    truth = est.p if p_true is None else np.asarray(p_true, float).ravel()
    return FlatSizeStudy(cm, truth, flat.inputs, flat.sigma, flat_splits, p0, w_flat, name or model.name)


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


@renamed_arguments(p_true="p", n_M="n_series", tol="alpha")
def validate(model, splits: Sequence[Split], p0=None, *, p=None, inputs=None, sigma=None, n_series: int = 2,
             generator: Callable | None = None, weights=None, n_rep: int | None = None, alpha: float | None = None,
             seed: int | None = None, workers: int | None = None, scheduler=None, progress: bool | None = None,
             settings: MonteCarloSettings | None = None, name: str | None = None, data=None) -> MonteCarloResult:
    """Front door (``mudoe validate``): a size study without ``generator``, a power study with one.

    ``name`` labels the model in tables (size study; default the model's own name).

    Size: data from ``model`` at ``p`` with noise ``sigma`` at ``inputs`` (n_series series);
    the rejection rate at TOL should not exceed TOL for a calibrated statistic.  Power: data
    from ``generator(rng)``; the rejection rate of each model in ``model`` (a Model or a
    mapping {name: Model}).  Replications run on local processes (``workers``) or on a Dask
    cluster (``scheduler`` address or Client); the numbers do not depend on either.

    ``n_rep``, ``alpha``, ``seed``, ``workers``, ``scheduler`` and ``progress`` (None: the
    defaults of :class:`MonteCarloSettings`, TOL 5 %) or ``settings`` with all of them; giving
    ``settings`` and one of those keywords raises TypeError.

    A dynamic model (:class:`models.dynamic.DynamicModel`) takes its campaign ``data``
    (DynamicMeasurements) instead of ``inputs`` / ``sigma``, instrument ``weights``, and splits by
    experiment, time window or early against late (:class:`Split`); the same size study runs on its
    collocation at the campaign fit (:func:`flat_size_study`; ``p`` defaults to that fit).
    """
    settings = _validate_settings(settings, alpha, n_rep=n_rep, seed=seed, workers=workers, scheduler=scheduler,
                                  progress=progress)
    if strategy_for(model).takes_time_series:       # a dynamic model: sized on the flat data of its campaign
        if generator is not None or inputs is not None or sigma is not None:
            raise DataError("generator/inputs/sigma: a dynamic model is validated by a size study on its campaign: "
                            "give data= (DynamicMeasurements with its inputs, sampling times and sigma)")
        dyn = flat_size_study(model, data, splits, p0, p_true=p, weights=weights,
                              identify_settings=settings.detect.identify, name=name)
        return size_study(dyn.model, dyn.p_true, dyn.inputs, dyn.sigma, dyn.splits, dyn.p0, n_series, dyn.weights,
                          settings, name=dyn.name)
    if generator is None:
        if isinstance(model, Mapping):
            raise DataError("model: a size study takes one model (the data generator itself)")
        if p is None or inputs is None or sigma is None:
            raise DataError("p, inputs, sigma: a size study needs the truth, the inputs and the noise level")
        return size_study(model, p, inputs, sigma, splits, p0, n_series, weights, settings, name=name)
    if p0 is None:
        raise DataError("p0: a power study needs start values for the fits")
    return power_study(model, generator, splits, p0, weights, settings)
