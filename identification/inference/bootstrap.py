r"""Parametric bootstrap intervals of a weighted least-squares estimate.

Replicate r simulates a campaign from the fit,

.. math::

    z^{*(r)}_{ijk} = h_k(\hat y_j, \hat p, q_j) + \sigma_k \varepsilon_{ijk},\qquad
    \varepsilon_{ijk} \sim N(0, 1),

with the missing-value pattern of the original data and sigma_k the sensors' sigma (known), or
the estimate s (sigma estimated; then the replicate's sigma is estimated again), refits it
warm-started at (p_hat, y_hat), and the (1 - alpha) percentile interval of parameter i is
[q_{alpha/2}, q_{1 - alpha/2}] of the refitted p_i.

The replicates of a chunk are refitted together by the batch engine
(:func:`identification.fit.batch.fit_batch`: the estimates of :func:`identification.identify` to
~1e-10, with identify as per-replicate fallback, recorded: which replicate and why);
``refits=ONE_BY_ONE_REFITS`` refits every replicate with identify.  The replicates run on the
replication engine (:mod:`identification.replicate`).

Replicate r draws from ``numpy.random.default_rng(SeedSequence(seed).spawn(n)[r])``: the
numbers do not depend on the backend (serial, local processes, a Dask scheduler), the number
of workers or the chunks of replicates each task runs.  A refit that fails is counted
and named in the notes; the percentiles are over the successful refits only, which the
notes say.
"""
from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from models.contract import Model
from identification import cluster
from identification.replicate import ReplicationTask, replicate
from identification.fit.batch import BatchData, fit_batch
from identification.errors import DataError, IdentificationError, NotBoundedError, StateSolveError
from identification.fit.unbounded import not_bounded_reason
from identification.fit.problem import fit_model
from identification.fit.measurements import Measurements
from identification.inference.intervals import ConfidenceIntervals, resolve_params, validate_alpha
from identification.progress import Progress

__all__ = ["BATCH_REFITS", "ONE_BY_ONE_REFITS", "BatchRefits", "BootstrapError", "BootstrapReplicates",
           "OneByOneRefits", "Refit", "Refits", "bootstrap_intervals", "bootstrap_replicates", "simulated_campaign"]


class BootstrapError(IdentificationError):
    """The bootstrap could not produce intervals (e.g. every refit failed)."""


@dataclass(frozen=True, eq=False)
class Refit:
    """The refit of one bootstrap replicate (the record of :class:`_Task.run_chunk`).

    Attributes
    ----------
    index : int          the replicate
    p : ndarray (n_p,)   refitted parameters (NaN: the refit failed)
    error : str          why the refit failed ("" when it did not)
    fallback : str       why the batch engine left it to identify ("" when it did not)
    """

    index: int
    p: np.ndarray
    error: str = ""
    fallback: str = ""


class Refits(ABC):
    """How the replicates of a chunk are refitted (a strategy chosen once per bootstrap).

    Attributes
    ----------
    max_chunk : int   most replicates per chunk when ``chunk_size`` is not given
    """

    max_chunk: int

    @abstractmethod
    def refit(self, task: "_Task", chunk: list) -> list:
        """Replicates [(index, SeedSequence), ...] -> [Refit, ...]."""


class BatchRefits(Refits):
    """The replicates of a chunk refitted together by :func:`identification.fit.batch.fit_batch`; a replicate
    the batch iteration did not fit is refitted by identify (its reason kept), and when the batch as a whole
    cannot be formed every replicate is refitted by identify and says why."""

    max_chunk = 100

    def refit(self, task: "_Task", chunk: list) -> list:
        seeds = [s for _, s in chunk]
        R = len(chunk)
        try:
            data = BatchData(task.inputs, np.stack([_simulated_values(task, s) for s in seeds]),
                             None if task.sigma_data is None else np.tile(task.sigma_data, (R, 1)),
                             _Campaigns(task, seeds))
            fit = fit_batch(task.model, data, task.p0, task.weights, Y0=task.states)
        except (IdentificationError, StateSolveError, DataError) as exc:
            why = f"the batch engine could not take the chunk ({_error_text(exc)})"
            return [_replicate(task, i, s, why) for i, s in chunk]
        reasons = {f.member: f.reason for f in fit.fallbacks}
        return [_refit_record(i, fit.results[k], task.p0.size, reasons.get(k, "")) for k, (i, _) in enumerate(chunk)]

    def __repr__(self) -> str:
        return "BATCH_REFITS"


class OneByOneRefits(Refits):
    """Every replicate refitted by its own :func:`identification.fit.problem.fit_model` call."""

    max_chunk = 20

    def refit(self, task: "_Task", chunk: list) -> list:
        return [_replicate(task, i, s) for i, s in chunk]

    def __repr__(self) -> str:
        return "ONE_BY_ONE_REFITS"


#: the replicates of a chunk refitted together by the batch engine (the default; identify as fallback)
BATCH_REFITS = BatchRefits()
#: one identify call per replicate
ONE_BY_ONE_REFITS = OneByOneRefits()


@dataclass(frozen=True, eq=False)
class _Task(ReplicationTask):
    """Everything a replicate needs (sent once to every worker process)."""

    model: Model
    inputs: np.ndarray
    fitted: np.ndarray          # (n_q, n_S)
    mask: np.ndarray            # (n_M, n_q, n_S) values present in the data
    sigma_sim: np.ndarray       # (n_S,) sigma of the simulated noise
    sigma_data: object          # the data's sigma (None: estimated)
    sensors: tuple
    input_names: object
    p0: np.ndarray
    weights: np.ndarray
    states: object
    refits: Refits
    jit: bool

    def run_chunk(self, chunk: list) -> list:
        """Replicates [(index, SeedSequence), ...] -> [Refit, ...]."""
        return self.refits.refit(self, chunk)


def simulated_campaign(task, seed: np.random.SeedSequence) -> Measurements:
    """z_ijk = h_jk(p_hat) + sigma_k eps_ijk, eps ~ N(0, 1), where the data had a value (else NaN).

    ``task`` carries ``mask`` (n_M, n_q, n_S), ``fitted`` (n_q, n_S), ``sigma_sim`` (n_S,),
    ``inputs``, ``sigma_data``, ``sensors`` and ``input_names``; ``seed`` fixes the draw.
    """
    return Measurements(task.inputs, _simulated_values(task, seed), task.sigma_data, sensors=task.sensors,
                        input_names=task.input_names)


def _simulated_values(task, seed: np.random.SeedSequence) -> np.ndarray:
    """The values z (n_M, n_q, n_S) of :func:`simulated_campaign` (NaN where the data had none)."""
    eps = np.random.default_rng(seed).standard_normal(task.mask.shape)
    return np.where(task.mask, task.fitted[None] + task.sigma_sim[None, None, :] * eps, np.nan)


def _error_text(exc: Exception) -> str:
    return f"{type(exc).__name__}: {str(exc).splitlines()[0][:200] if str(exc) else ''}"


def _refit_record(index: int, res, n_p: int, fallback: str = "") -> Refit:
    """The Refit of an estimate, or of the exception its fit raised (NaN p and the reason)."""
    if isinstance(res, Exception):
        return Refit(index, np.full(n_p, np.nan), _error_text(res), fallback)
    if not_bounded_reason(res):             # no finite estimate: a failed refit, with its reason
        return Refit(index, np.full(n_p, np.nan), not_bounded_reason(res)[:200], fallback)
    return Refit(index, np.asarray(res.p, float), "", fallback)


def _replicate(task: _Task, index: int, seed: np.random.SeedSequence, fallback: str = "") -> Refit:
    """The Refit of one simulated campaign by identify (:func:`identification.fit.problem.fit_model`)."""
    try:
        data = simulated_campaign(task, seed)
        est = fit_model(task.model, data, task.p0, weights=task.weights, Y0=task.states)
    except (IdentificationError, StateSolveError, DataError) as exc:
        return _refit_record(index, exc, task.p0.size, fallback)
    return _refit_record(index, est, task.p0.size, fallback)


class _Campaigns:
    """Member k of a chunk -> its simulated Measurements (the data of a fallback fit)."""

    def __init__(self, task: _Task, seeds: list):
        self.task, self.seeds = task, seeds

    def __call__(self, k: int) -> Measurements:
        return simulated_campaign(self.task, self.seeds[k])


@dataclass(frozen=True, eq=False)
class BootstrapReplicates:
    """The refits of :func:`bootstrap_replicates`.

    Attributes
    ----------
    P : ndarray (n, n_p)             refitted parameters (NaN rows: failed refits)
    errors : tuple of (int, str)     replicate index and error of every failed refit
    fallbacks : tuple of (int, str)  replicates the batch engine did not fit, refitted by
                                     identify (index, why); a failed one is also in ``errors``
    backend : str                    "serial", "2 local processes", "dask (...)"
    """

    P: np.ndarray
    errors: tuple
    fallbacks: tuple
    backend: str

    def __post_init__(self):
        a = np.array(self.P, dtype=float, copy=True)
        a.setflags(write=False)
        object.__setattr__(self, "P", a)


def bootstrap_replicates(model: Model, data: Measurements, est, n: int = 200, seed=0, workers: int | None = 1,
                         progress: Progress | None = None, scheduler=None, chunk_size: int | None = None,
                         refits: Refits = BATCH_REFITS, jit: bool = True) -> BootstrapReplicates:
    """Refitted parameters of ``n`` campaigns simulated from ``est`` (see the module docstring).

    Parameters
    ----------
    model, data, est : the model, the measurements and the estimate fitted to them
    n : int >= 2                 replicates
    seed : int or SeedSequence entropy    root of the per-replicate seeds
    workers : int or None        local processes (1: serial in this process; None: all cores)
    progress : Progress, optional    a tqdm bar over the replicates
    scheduler : str or distributed.Client, optional
        Run the chunks on this Dask scheduler instead (``workers`` is then ignored); see
        :mod:`identification.cluster`.
    chunk_size : int, optional   replicates per task (default: about 4 tasks per worker, at most 20
                                 refitted one by one or 100 refitted as one batch)
    refits : Refits              BATCH_REFITS: the replicates of a chunk refitted together by the batch
                                 engine (identification.fit.batch.fit_batch); ONE_BY_ONE_REFITS: one
                                 identify call per replicate
    jit : bool                   evaluate small models' CasADi functions as compiled C during the refits
                                 (models.state.set_jit, as Monte Carlo does; compiled once per machine
                                 and kept in models.jit_cache; without a C compiler the virtual machine)

    The numbers depend on ``seed`` only, not on the backend, the workers or the chunks (and agree
    between the two ``refits`` to the estimator's tolerance, ~1e-10 relative).

    Returns
    -------
    BootstrapReplicates : the refits, the failed ones, the fallbacks of the batch engine

    Raises
    ------
    identification.cluster.SchedulerError
        Dask is not installed or the scheduler cannot be reached.
    """
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n: the number of bootstrap replicates must be an integer >= 2, got {n!r}")
    if workers is not None and not (isinstance(workers, (int, np.integer)) and workers >= 1):
        raise ValueError(f"workers: must be an integer >= 1 or None (all cores), got {workers!r}")
    if chunk_size is not None and not (isinstance(chunk_size, (int, np.integer)) and chunk_size >= 1):
        raise ValueError(f"chunk_size: must be an integer >= 1 or None (automatic), got {chunk_size!r}")
    if not isinstance(refits, Refits):
        raise TypeError(f"refits: expected BATCH_REFITS (batch engine) or ONE_BY_ONE_REFITS (identify per refit) "
                        f"of identification.inference.bootstrap, got {refits!r}")
    if not isinstance(jit, (bool, np.bool_)):
        raise ValueError(f"jit: expected True (compiled model functions) or False, got {jit!r}")
    scheduler = cluster.check_scheduler(scheduler)
    sigma_sim = np.asarray(est.sigma, float)
    task = _Task(model, np.asarray(data.inputs), np.asarray(est.fitted, float), data.mask(), sigma_sim,
                 None if data.sigma is None else np.asarray(data.sigma, float), tuple(data.sensors),
                 None if data.input_names is None else tuple(data.input_names), np.asarray(est.p, float),
                 np.asarray(est.weights, float), None if est.states is None or est.states.size == 0
                 else np.asarray(est.states, float), refits, bool(jit))
    chunks = functools.partial(cluster.seed_chunks, int(n), seed, chunk_size=chunk_size, max_size=refits.max_chunk)
    bar = (progress or Progress(enabled=False)).bar(int(n), "bootstrap refits")
    try:
        reps = replicate(task, int(n), chunks, workers=workers, scheduler=scheduler, bar=bar)
    finally:
        bar.close()
    return BootstrapReplicates(np.array([r.p for r in reps.records]).reshape(int(n), model.n_p),
                               tuple((r.index, r.error) for r in reps.records if r.error),
                               tuple((r.index, r.fallback) for r in reps.records if r.fallback), str(reps.backend))


def bootstrap_intervals(model: Model, data: Measurements, est, alpha: float = 0.05, params=None, n: int = 200,
                        seed=0, workers: int | None = 1, progress: Progress | None = None, scheduler=None,
                        chunk_size: int | None = None, refits: Refits = BATCH_REFITS,
                        jit: bool = True) -> ConfidenceIntervals:
    """Parametric bootstrap percentile (1 - alpha) intervals (see the module docstring).

    Parameters
    ----------
    model, data : the model and measurements ``est`` was fitted to
    est : Estimate
    alpha : float in (0, 0.5)   miss probability
    params : names or indices, optional (default all)
    n : int >= 2                replicates
    seed : int or SeedSequence entropy    root of the per-replicate seeds
    workers : int or None       local processes (1: serial in this process; None: all cores)
    progress : Progress, optional   a tqdm bar over the replicates
    scheduler : str or distributed.Client, optional   run the refits on a Dask cluster instead
    chunk_size : int, optional  replicates per task (see :func:`bootstrap_replicates`)
    refits : Refits             BATCH_REFITS (the batch engine) or ONE_BY_ONE_REFITS (identify per refit)
    jit : bool                  compiled model functions during the refits (see :func:`bootstrap_replicates`)

    Returns
    -------
    ConfidenceIntervals (method "bootstrap"; ``replicates`` the successful refits,
    ``n_failed`` the failed ones, named in ``notes``; ``fallbacks`` the refits the batch engine
    left to identify, (replicate, why), counted in ``notes``).

    Raises
    ------
    BootstrapError
        Fewer than two refits succeeded.
    NotBoundedError
        The estimate is not bounded (``est.bounded`` False).
    """
    alpha = validate_alpha(alpha)
    idx = resolve_params(params, tuple(est.param_names))
    if model is None or data is None:
        raise ValueError("model, data: the bootstrap needs the model and the measurements the estimate was "
                         "fitted to (conf_int(..., model=model, data=data))")
    if not_bounded_reason(est):
        raise NotBoundedError(f"bootstrap intervals: the estimate is {not_bounded_reason(est)}; there is no finite "
                              "estimate to simulate from and refit around: use conf_int(method=\"profile\")")
    reps = bootstrap_replicates(model, data, est, n, seed, workers, progress, scheduler, chunk_size, refits, jit)
    P, errors = reps.P, reps.errors
    ok = np.all(np.isfinite(P), axis=1)
    if ok.sum() < 2:
        raise BootstrapError(f"bootstrap: {len(errors)} of {n} refits failed; first: "
                             f"{errors[0][1] if errors else 'non-finite estimates'}", status="bootstrap failed")
    Q = np.quantile(P[ok][:, idx], [alpha / 2, 1 - alpha / 2], axis=0)
    notes = []
    if errors:
        notes.append(f"{len(errors)} of {n} bootstrap refits failed and are excluded from the percentiles "
                     f"(first, replicate {errors[0][0]}: {errors[0][1]})")
    if reps.fallbacks:
        i0, why = reps.fallbacks[0]
        notes.append(f"{len(reps.fallbacks)} of {n} bootstrap refits were not converged by the batch engine and "
                     f"were refitted by identify (first, replicate {i0}: {why})")
    k = int(ok.sum())
    if min(alpha / 2 * k, k - (1 - alpha / 2) * k) < 5:
        notes.append(f"only {k} successful refits: the {100 * alpha / 2:g} % tails hold fewer than 5 of them; "
                     "the percentile ends are rough (use a larger n)")
    names = tuple(est.param_names[i] for i in idx)
    return ConfidenceIntervals(names, np.asarray(est.p)[idx], Q[0], Q[1], "bootstrap", alpha, tuple(notes),
                               replicates=P[ok], n_failed=len(errors), fallbacks=reps.fallbacks)
