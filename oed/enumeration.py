r"""Exact enumeration of all admissible sensor designs.

Solves :math:`\min_{w\in\{0,1\}^{n_S},\, g(w)\le 0} \Psi(C(w))` by evaluating every
admissible design in batches (batched ``eigh``/``slogdet``).

Screening (default): every design first gets a cheap value :math:`\tilde\Psi(w)\le\Psi(C(w))`
(:func:`oed.criteria.screening_values`: one batched inverse or two ``slogdet``, no eigenvalue
problems); only designs with :math:`\tilde\Psi(w)\le v^* + \epsilon` (:math:`v^*` the incumbent,
:math:`\epsilon` a rounding margin) are evaluated exactly with the rank checks.  A discarded design
has :math:`\Psi(C(w))\ge\tilde\Psi(w) > v^*`, so the result is the same design as without
screening (ties still go to the design enumerated first).
"""
from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from .constraints import DesignConstraints
from .criteria import DEFAULT_SETTINGS, Criterion, CriteriaSettings, Kind, batch_criteria, screening_values

__all__ = ["EnumerationSettings", "EnumerationResult", "iter_designs", "enumerate_designs"]


@dataclass(frozen=True)
class EnumerationSettings:
    """Settings for :func:`enumerate_designs`.

    Attributes
    ----------
    batch_size : int
        Designs evaluated per batched eigen-decomposition.
    max_designs : int
        Refuse to enumerate more designs than this (raise ``ValueError``).
    time_limit : float or None
        Seconds; on expiry the result has ``complete=False``.
    screen : bool
        Screen designs by :func:`oed.criteria.screening_values` and evaluate exactly only those
        that may beat the incumbent (same result, several times faster).
    screen_margin : float
        Rounding margin of the screening test: relative for A and E, absolute on log det for D.
    """

    batch_size: int = 20000
    max_designs: int = 20_000_000
    time_limit: float | None = None
    screen: bool = True
    screen_margin: float = 1e-7

    def __post_init__(self):
        for name in ("batch_size", "max_designs"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 1):
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        if self.time_limit is not None and not (isinstance(self.time_limit, (int, float, np.floating))
                                                and self.time_limit > 0):
            raise ValueError(f"time_limit: expected None or seconds > 0, got {self.time_limit!r}")
        if not (isinstance(self.screen_margin, (int, float, np.floating)) and 0 <= self.screen_margin < 1):
            raise ValueError(f"screen_margin: expected a number in [0, 1), got {self.screen_margin!r}")


@dataclass(frozen=True)
class EnumerationResult:
    """Outcome of :func:`enumerate_designs` (``value`` is ``inf`` if no regular design).

    ``n_evaluated``: admissible designs enumerated; ``n_exact``: of these, evaluated exactly (the
    others were screened out); ``n_singular``: singular designs among the exactly evaluated ones.
    """

    w: np.ndarray | None
    value: float
    n_evaluated: int
    n_singular: int
    complete: bool
    wall_time: float
    n_exact: int = 0


def iter_designs(cons: DesignConstraints, batch_size: int = 20000):
    """Yield boolean arrays of shape (b, n_S) of admissible designs (cardinality, forced, budget)."""
    n = cons.n_candidates
    free = cons.free
    inc = list(cons.include)
    costs = None if cons.costs is None else np.asarray(cons.costs)
    for size in range(cons.min_size, cons.max_size + 1):
        r = size - len(inc)
        if r < 0 or r > len(free):
            continue
        it = itertools.combinations(range(len(free)), r)
        while True:
            chunk = list(itertools.islice(it, batch_size))
            if not chunk:
                break
            W = np.zeros((len(chunk), n), dtype=bool)
            if r > 0:
                flat = np.fromiter(itertools.chain.from_iterable(chunk), dtype=np.intp, count=len(chunk) * r)
                idx = free[flat.reshape(len(chunk), r)]
                rows = np.repeat(np.arange(len(chunk)), r)
                W[rows, idx.ravel()] = True
            if inc:
                W[:, inc] = True
            if costs is not None:
                W = W[W @ costs <= cons.budget * (1 + 1e-12) + 1e-12]
            if len(W):
                yield W


def enumerate_designs(F, S, cons: DesignConstraints, criterion, kind="gauss_newton", *,
                      settings: EnumerationSettings = EnumerationSettings(),
                      criteria_settings: CriteriaSettings = DEFAULT_SETTINGS) -> EnumerationResult:
    r"""Exact minimiser of :math:`\Psi(C(w))` over all admissible binary designs.

    Ties are broken towards the design enumerated first (lexicographic order of the
    chosen indices, smallest size first).  ``F``/``S`` must already be validated.
    """
    crit = Criterion.parse(criterion)
    kind = Kind.parse(kind)
    total = cons.count_designs()
    if total > settings.max_designs:
        raise ValueError(f"method: enumeration would evaluate {total} designs > max_designs = {settings.max_designs}")
    t0 = time.perf_counter()
    best_v = np.inf
    best_w = None
    n_eval = n_sing = n_exact = 0
    complete = True
    for W in iter_designs(cons, settings.batch_size):
        idx = _candidates(F, S, W, crit, kind, best_v, settings, criteria_settings)
        res = batch_criteria(F, S, W[idx], kind, settings=criteria_settings, validated=True)
        v = res.value(crit)
        n_eval += len(W)
        n_exact += len(idx)
        n_sing += int(res.singular.sum())
        if len(idx):
            j = int(np.argmin(v))           # idx is increasing: the first minimal design in enumeration order
            if v[j] < best_v:
                best_v = float(v[j])
                best_w = W[idx[j]].copy()
        if settings.time_limit is not None and time.perf_counter() - t0 > settings.time_limit:
            complete = False
            break
    return EnumerationResult(w=best_w, value=best_v, n_evaluated=n_eval, n_singular=n_sing,
                             complete=complete, wall_time=time.perf_counter() - t0, n_exact=n_exact)


def _candidates(F, S, W, crit, kind, best_v, settings, criteria_settings, n_seed=64):
    """Indices (increasing) of the designs of W that may beat ``best_v``: all of them without
    screening; else those whose screening value is within the margin of the incumbent (when there
    is none yet, the ``n_seed`` designs with the smallest screening values set a provisional one)."""
    if not settings.screen:
        return np.arange(len(W))
    sv = screening_values(F, S, W, crit, kind)
    seed = np.array([], dtype=np.intp)
    if not np.isfinite(best_v) and len(W) > n_seed:
        seed = np.argsort(np.where(np.isnan(sv), -np.inf, sv), kind="stable")[:n_seed]
        vs = batch_criteria(F, S, W[seed], kind, settings=criteria_settings, validated=True).value(crit)
        best_v = float(vs.min())
    if not np.isfinite(best_v):
        return np.arange(len(W))
    margin = settings.screen_margin * (1.0 if crit is Criterion.D else max(abs(best_v), np.finfo(float).tiny))
    # the seeds stay candidates: the provisional incumbent is one of them, whatever the rounding
    return np.union1d(np.flatnonzero(~(sv > best_v + margin)), seed)
