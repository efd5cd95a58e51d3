r"""Batched fits of a collocated ODE model (no state-size ceiling): every member by identify, merged.

The batch engine (:mod:`identification.fit.batch`) advances members of models with small dense states
by its own full-space Newton sweeps.  A collocated dynamic model (:mod:`models.collocation`) has
hundreds of states per experiment, but its state Jacobian is block lower-triangular in the
elements: :mod:`models.trajectory` solves the trajectories and their exact first and second
derivatives element by element for all experiments at once.  Here every member is fitted by
:func:`identification.identify` itself (reduced-space Newton on the trajectories, its checks,
refinement and covariance) in its own thread, and the members' trajectory evaluations are merged
(:func:`models.trajectory.run_merged`): each step evaluates all members' experiments, each at its
own member's p, in one set of mapped CasADi calls and batched LAPACK solves.  The estimates are
identify's (the same computations, to round-off).
"""
from __future__ import annotations

import numpy as np

from models.trajectory import run_merged
from identification.errors import DataError, IdentificationError
from identification.fit.estimator import fit_static

__all__ = ["fit_members"]


def fit_members(model, members, p0, weights, settings, starts=None) -> tuple:
    """identify(model, members[r], p0_r, weights, settings) for every member, merged (see the module
    docstring); p0_r is row r of ``starts`` where it is finite (e.g. the pooled start of a split
    test), else p0.  Returns (results, errors): each member's Estimate or the IdentificationError /
    DataError identify raised (any other exception is raised here, as identify would)."""
    p0 = np.asarray(p0, float)
    starts = None if starts is None else np.asarray(starts, float).reshape(len(members), -1)
    first = [s if starts is not None and np.all(np.isfinite(s)) else p0
             for s in (starts if starts is not None else [None] * len(members))]
    tasks = [lambda d=d, s=s: fit_static(model, d, s, weights=weights, settings=settings) for d, s in zip(members, first)]
    results = run_merged(tasks)
    errors = {}
    for r, res in enumerate(results):
        if isinstance(res, (IdentificationError, DataError)):
            errors[r] = f"{type(res).__name__}: {res}"
        elif isinstance(res, Exception):
            raise res
    return results, errors


def decrements(results) -> np.ndarray:
    """The Newton decrement of every member's estimate (NaN for a failed fit)."""
    return np.array([np.nan if isinstance(r, Exception) else float(r.extra.get("newton_decrement", np.nan))
                     for r in results])
