r"""Design constraints shared by all solvers (paper eq. 9, :math:`g(w)\le 0`).

.. math::  \sum_k w_k \ge 1,\quad \sum_k w_k = m \text{ or } \le m_{\max},\quad
           c^T w \le B,\quad w_k = 1\ (k\in\text{include}),\quad w_k = 0\ (k\in\text{exclude}).

The sensor count is not compared with the number of parameters: one sensor measured at
several inputs can identify every parameter.  Whether a design is admissible is decided by
its own information matrix (a singular design has criterion ``inf`` and is skipped by every
solver).
"""
from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

__all__ = ["DesignConstraints", "make_constraints"]


@dataclass(frozen=True)
class DesignConstraints:
    """Validated constraints on binary sensor weights.

    Attributes
    ----------
    n_candidates, n_params : int
    n_sensors : int or None
        Exact number of sensors (``sum w == n_sensors``).
    max_sensors : int or None
        Upper bound ``sum w <= max_sensors`` (ignored when ``n_sensors`` is given).
    costs : tuple of float or None
    budget : float or None
    include, exclude : tuple of int
        Forced-in / forced-out sensor indices.
    min_sensors : int
        Smallest design size considered when ``n_sensors`` is not given (default 1).
    """

    n_candidates: int
    n_params: int
    n_sensors: int | None = None
    max_sensors: int | None = None
    costs: tuple | None = None
    budget: float | None = None
    include: tuple = ()
    exclude: tuple = ()
    min_sensors: int = 1

    @property
    def min_size(self) -> int:
        """Smallest admissible design size."""
        if self.n_sensors is not None:
            return self.n_sensors
        return max(self.min_sensors, len(self.include), 1)

    @property
    def max_size(self) -> int:
        """Largest admissible design size."""
        if self.n_sensors is not None:
            return self.n_sensors
        hi = self.n_candidates - len(self.exclude)
        return hi if self.max_sensors is None else min(hi, self.max_sensors)

    @property
    def free(self) -> np.ndarray:
        """Indices that are neither forced in nor out."""
        fixed = set(self.include) | set(self.exclude)
        return np.array([k for k in range(self.n_candidates) if k not in fixed], dtype=int)

    def count_designs(self) -> int:
        """Number of designs meeting the cardinality constraints (budget not applied)."""
        nf = len(self.free)
        ni = len(self.include)
        return sum(comb(nf, s - ni) for s in range(self.min_size, self.max_size + 1) if 0 <= s - ni <= nf)

    def is_admissible(self, w) -> bool:
        """True when binary ``w`` satisfies every constraint."""
        w = np.asarray(w)
        s = int(np.sum(w))
        if s < self.min_size or s > self.max_size:
            return False
        if any(w[k] != 1 for k in self.include) or any(w[k] != 0 for k in self.exclude):
            return False
        if self.costs is not None and self.budget is not None:
            if float(np.dot(self.costs, w)) > self.budget * (1 + 1e-12) + 1e-12:
                return False
        return True


def _index_list(name, values, n):
    out = []
    for v in values:
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"{name}: sensor indices must be integers, got {v!r}")
        if not 0 <= int(v) < n:
            raise ValueError(f"{name}: sensor index {v} out of range 0..{n - 1}")
        out.append(int(v))
    if len(set(out)) != len(out):
        raise ValueError(f"{name}: duplicate sensor indices {out}")
    return tuple(sorted(out))


def make_constraints(n_candidates, n_params, *, n_sensors=None, max_sensors=None, costs=None,
                     budget=None, include=(), exclude=(), sensor_names=None) -> DesignConstraints:
    r"""Build :math:`g(w)\le0`: :math:`\sum w\ge1`, :math:`\sum w=m` or :math:`\le m_{\max}`, :math:`c^Tw\le B`, fixings.

    Ensures :math:`1 \le m \le n_S`, consistency of forced sensors, and that at least one
    design meets the budget (:math:`\min_{|w| \ge m_{\min}} c^T w \le B`).  Fewer sensors than
    parameters are allowed: whether a design is regular is decided by its information.

    ``include``/``exclude`` may contain indices or names from ``sensor_names``.

    Raises
    ------
    ValueError
        Naming the offending argument.
    """
    def resolve(name, seq):
        seq = list(seq) if seq is not None else []
        out = []
        for v in seq:
            if isinstance(v, str):
                if sensor_names is None or v not in sensor_names:
                    raise ValueError(f"{name}: unknown sensor name {v!r}")
                out.append(list(sensor_names).index(v))
            else:
                out.append(v)
        return _index_list(name, out, n_candidates)

    inc = resolve("include", include)
    exc = resolve("exclude", exclude)
    both = set(inc) & set(exc)
    if both:
        raise ValueError(f"include/exclude: sensors {sorted(both)} are both forced in and forced out")
    avail = n_candidates - len(exc)
    if n_sensors is not None:
        if isinstance(n_sensors, bool) or not isinstance(n_sensors, (int, np.integer)):
            raise ValueError(f"n_sensors: must be an integer, got {n_sensors!r}")
        n_sensors = int(n_sensors)
        if n_sensors < 1:
            raise ValueError(f"n_sensors: must be at least 1, got {n_sensors}")
        if n_sensors > avail:
            raise ValueError(f"n_sensors: {n_sensors} exceeds the {avail} candidate sensors not excluded")
        if len(inc) > n_sensors:
            raise ValueError(f"include: {len(inc)} forced sensors exceed n_sensors = {n_sensors}")
    if max_sensors is not None:
        if isinstance(max_sensors, bool) or not isinstance(max_sensors, (int, np.integer)):
            raise ValueError(f"max_sensors: must be an integer, got {max_sensors!r}")
        max_sensors = int(max_sensors)
        if max_sensors < 1:
            raise ValueError(f"max_sensors: must be at least 1, got {max_sensors}")
        if len(inc) > max_sensors:
            raise ValueError(f"include: {len(inc)} forced sensors exceed max_sensors = {max_sensors}")
        if n_sensors is not None and n_sensors > max_sensors:
            raise ValueError(f"n_sensors: {n_sensors} > max_sensors = {max_sensors}")
    if avail < 1:
        raise ValueError("exclude: every candidate is excluded; no design remains")
    if (costs is None) != (budget is None):
        raise ValueError("costs/budget: give both costs and budget, or neither")
    if costs is not None:
        c = np.asarray(costs, dtype=float)
        if c.shape != (n_candidates,):
            raise ValueError(f"costs: expected shape ({n_candidates},), got {c.shape}")
        if not np.all(np.isfinite(c)) or np.any(c < 0):
            raise ValueError("costs: must be finite and non-negative")
        budget = float(budget)
        if not np.isfinite(budget):
            raise ValueError(f"budget: must be finite, got {budget}")
        lo = n_sensors if n_sensors is not None else max(1, len(inc))
        fixed_cost = float(c[list(inc)].sum()) if inc else 0.0
        free = [k for k in range(n_candidates) if k not in inc and k not in exc]
        cheapest = fixed_cost + float(np.sort(c[free])[: max(lo - len(inc), 0)].sum())
        if cheapest > budget * (1 + 1e-12) + 1e-12:
            raise ValueError(
                f"budget: {budget:g} is below the cheapest admissible design cost {cheapest:g} "
                f"(at least {lo} sensors); no design meets the budget")
        costs = tuple(float(x) for x in c)
    return DesignConstraints(n_candidates=n_candidates, n_params=n_params, n_sensors=n_sensors,
                             max_sensors=max_sensors, costs=costs, budget=budget, include=inc, exclude=exc)
