r"""Parametric bootstrap intervals of a weighted least-squares estimate.

Replicate r simulates a campaign from the fit,

.. math::

    z^{*(r)}_{ijk} = h_k(\hat y_j, \hat p, q_j) + \sigma_k \varepsilon_{ijk},\qquad
    \varepsilon_{ijk} \sim N(0, 1),

with the missing-value pattern of the original data and sigma_k the sensors' sigma (known), or
the estimate s (sigma estimated; then the replicate's sigma is estimated again), refits it
with :func:`identification.identify` warm-started at (p_hat, y_hat), and the (1 - alpha)
percentile interval of parameter i is [q_{alpha/2}, q_{1 - alpha/2}] of the refitted p_i.

Replicate r draws from ``numpy.random.default_rng(SeedSequence(seed).spawn(n)[r])``: the
numbers do not depend on the number of worker processes.  A refit that fails is counted
and named in the notes; the percentiles are over the successful refits only, which the
notes say.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from models.contract import Model
from .errors import DataError, IdentificationError, StateSolveError
from .estimator import identify
from .measurements import Measurements
from .profile import ConfidenceIntervals, resolve_params, validate_alpha
from .progress import Progress

__all__ = ["BootstrapError", "bootstrap_intervals", "bootstrap_replicates"]


class BootstrapError(IdentificationError):
    """The bootstrap could not produce intervals (e.g. every refit failed)."""


@dataclass(frozen=True, eq=False)
class _Task:
    """Everything a replicate needs (pickled once per worker process)."""

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


class _Worker:
    """The task of this process (set once per spawned worker by the pool initializer)."""

    task: _Task | None = None


def _install(task: _Task) -> None:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    _Worker.task = task


def _replicate(task: _Task, seed: np.random.SeedSequence) -> tuple:
    """(p (n_p,) or NaN, error text or "") of one simulated campaign."""
    rng = np.random.default_rng(seed)
    eps = rng.standard_normal(task.mask.shape)
    z = np.where(task.mask, task.fitted[None] + task.sigma_sim[None, None, :] * eps, np.nan)
    try:
        data = Measurements(task.inputs, z, task.sigma_data, sensors=task.sensors, input_names=task.input_names)
        est = identify(task.model, data, task.p0, weights=task.weights, Y0=task.states)
    except (IdentificationError, StateSolveError, DataError) as exc:
        return np.full(task.p0.size, np.nan), f"{type(exc).__name__}: {str(exc).splitlines()[0][:200]}"
    return np.asarray(est.p, float), ""


def _run_chunk(chunk: list) -> list:
    return [(i, *_replicate(_Worker.task, s)) for i, s in chunk]


def bootstrap_replicates(model: Model, data: Measurements, est, n: int = 200, seed=0, workers: int | None = 1,
                         progress: Progress | None = None) -> tuple:
    """Refitted parameters of ``n`` campaigns simulated from ``est`` (see the module docstring).

    Returns
    -------
    P : ndarray (n, n_p)         refitted parameters (NaN rows: failed refits)
    errors : list of (int, str)  replicate index and error of every failed refit
    """
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n: the number of bootstrap replicates must be an integer >= 2, got {n!r}")
    if workers is not None and not (isinstance(workers, (int, np.integer)) and workers >= 1):
        raise ValueError(f"workers: must be an integer >= 1 or None (all cores), got {workers!r}")
    sigma_sim = np.asarray(est.sigma, float)
    task = _Task(model, np.asarray(data.inputs), np.asarray(est.fitted, float), data.mask(), sigma_sim,
                 None if data.sigma is None else np.asarray(data.sigma, float), tuple(data.sensors),
                 None if data.input_names is None else tuple(data.input_names), np.asarray(est.p, float),
                 np.asarray(est.weights, float), None if est.states is None or est.states.size == 0
                 else np.asarray(est.states, float))
    children = np.random.SeedSequence(seed).spawn(int(n))
    n_w = int(workers or os.cpu_count() or 1)
    size = max(1, min(20, math.ceil(n / (4 * n_w))))
    items = list(enumerate(children))
    chunks = [items[k:k + size] for k in range(0, len(items), size)]
    P = np.full((int(n), model.n_p), np.nan)
    errors = []
    bar = (progress or Progress(enabled=False)).bar(int(n), "bootstrap refits")
    try:
        if n_w == 1:
            saved = _Worker.task
            _install(task)
            try:
                for ch in chunks:
                    _collect(_run_chunk(ch), P, errors, bar)
            finally:
                _Worker.task = saved
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed
            with ProcessPoolExecutor(max_workers=n_w, mp_context=mp.get_context("spawn"), initializer=_install,
                                     initargs=(task,)) as pool:
                futures = [pool.submit(_run_chunk, ch) for ch in chunks]
                for fut in as_completed(futures):
                    _collect(fut.result(), P, errors, bar)
    finally:
        bar.close()
    errors.sort()
    return P, errors


def _collect(results: list, P: np.ndarray, errors: list, bar) -> None:
    for i, p, err in results:
        P[i] = p
        if err:
            errors.append((i, err))
    bar.update(len(results))


def bootstrap_intervals(model: Model, data: Measurements, est, alpha: float = 0.05, params=None, n: int = 200,
                        seed=0, workers: int | None = 1, progress: Progress | None = None) -> ConfidenceIntervals:
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

    Returns
    -------
    ConfidenceIntervals (method "bootstrap"; ``replicates`` the successful refits,
    ``n_failed`` the failed ones, named in ``notes``).

    Raises
    ------
    BootstrapError
        Fewer than two refits succeeded.
    """
    alpha = validate_alpha(alpha)
    idx = resolve_params(params, tuple(est.param_names))
    if model is None or data is None:
        raise ValueError("model, data: the bootstrap needs the model and the measurements the estimate was "
                         "fitted to (conf_int(..., model=model, data=data))")
    P, errors = bootstrap_replicates(model, data, est, n, seed, workers, progress)
    ok = np.all(np.isfinite(P), axis=1)
    if ok.sum() < 2:
        raise BootstrapError(f"bootstrap: {len(errors)} of {n} refits failed; first: "
                             f"{errors[0][1] if errors else 'non-finite estimates'}", status="bootstrap failed")
    Q = np.quantile(P[ok][:, idx], [alpha / 2, 1 - alpha / 2], axis=0)
    notes = []
    if errors:
        notes.append(f"{len(errors)} of {n} bootstrap refits failed and are excluded from the percentiles "
                     f"(first, replicate {errors[0][0]}: {errors[0][1]})")
    k = int(ok.sum())
    if min(alpha / 2 * k, k - (1 - alpha / 2) * k) < 5:
        notes.append(f"only {k} successful refits: the {100 * alpha / 2:g} % tails hold fewer than 5 of them; "
                     "the percentile ends are rough (use a larger n)")
    names = tuple(est.param_names[i] for i in idx)
    return ConfidenceIntervals(names, np.asarray(est.p)[idx], Q[0], Q[1], "bootstrap", alpha, tuple(notes),
                               replicates=P[ok], n_failed=len(errors))
