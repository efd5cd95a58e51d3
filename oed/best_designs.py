r"""The best designs of one size: a short ranked table instead of every combination.

For designs w with \sum_k w_k = m, ranks \Psi(C(w)) (A: trace, D: log det, E: largest eigenvalue of the
Gauss-Newton or second-order covariance, :func:`oed.criteria.batch_criteria`) and keeps the ``top``
best.  Every design of size m is evaluated while they number at most ``max_enumerate``; beyond, the
designs one exchange away from the chosen design (one candidate out, another in) are ranked, and the
table says so.  The chosen design is always listed.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from math import comb

import numpy as np

from .criteria import Kind, batch_criteria, validate_information
from .design import DesignRow, DesignTable

__all__ = ["RankedDesignTable", "best_designs", "design_rows", "FULL_TABLE_ROWS"]

#: sensor combinations listed in full (the paper's table) up to this many; beyond, the ten best designs
FULL_TABLE_ROWS = 25

_BATCH = 4096


@dataclass(frozen=True)
class RankedDesignTable(DesignTable):
    """A :class:`DesignTable` of the best designs of one size, best first; ``note`` says what was ranked."""

    note: str = ""
    ranked = True


def _masks(n: int, size: int, chosen, exhaustive: bool):
    if exhaustive:
        yield from itertools.combinations(range(n), size)
        return
    c = tuple(sorted(chosen))
    yield c
    for out in c:
        for inn in range(n):
            if inn not in c:
                yield tuple(sorted(set(c) - {out} | {inn}))


def best_designs(F, S, sensor_names, size: int, criterion: str, *, kind: str = "gauss_newton", chosen=(),
                 top: int = 10, max_enumerate: int = 200_000) -> RankedDesignTable:
    """The ``top`` designs of ``size`` candidates by ``criterion`` (see the module docstring).

    Parameters
    ----------
    F, S : array_like (n_S, n_p, n_p)   per-candidate information (S may be None)
    sensor_names : sequence of str       candidate names
    size : int                           candidates per design
    criterion : {"A", "D", "E"}
    kind : {"gauss_newton", "second_order"}
    chosen : sequence of int             indices of the chosen design (always listed)
    """
    F, S = validate_information(F, S)
    n = F.shape[0]
    if not 1 <= size <= n:
        raise ValueError(f"size: expected 1..{n}, got {size}")
    if criterion not in ("A", "D", "E"):
        raise ValueError(f"criterion: expected 'A', 'D' or 'E', got {criterion!r}")
    if top < 0:
        raise ValueError(f"top: expected a non-negative number of designs, got {top}")
    total = comb(n, size)
    exhaustive = total <= max_enumerate or not chosen
    if not exhaustive and len(chosen) != size:
        raise ValueError(f"chosen: {len(chosen)} candidates, but the designs have {size}")
    kind_e = Kind.parse(kind)
    c = tuple(sorted(chosen))
    found, n_ranked = {}, 0
    it = _masks(n, size, chosen, exhaustive)
    while True:
        idx = list(itertools.islice(it, _BATCH))
        if not idx:
            break
        W = np.zeros((len(idx), n))
        W[np.arange(len(idx))[:, None], np.array(idx, dtype=np.intp).reshape(len(idx), size)] = 1.0
        res = batch_criteria(F, S, W, kind_e, validated=True)
        val = {"A": res.A, "D": res.logdet, "E": res.E}[criterion]
        v = np.where(~res.singular & np.isfinite(val), val, np.inf)
        # only a batch's `top` best (stable: ties in enumeration order) can be among the `top` best of all
        keep = set(np.argsort(v, kind="stable")[:top].tolist()) | {r for r, m in enumerate(idx) if m == c}
        for r in sorted(keep):
            m = idx[r]
            flag = "singular" if res.singular[r] else ("near-singular" if res.near_singular[r] else "")
            found[m] = (float(v[r]), DesignRow(mask="".join("1" if k in m else "0" for k in range(n)),
                                               sensors=tuple(sensor_names[k] for k in m), A=float(res.A[r]),
                                               det=float(res.det[r]), logdet=float(res.logdet[r]),
                                               E=float(res.E[r]), flag=flag, reason=res.reason[r]))
        n_ranked += len(idx)
    ranked = sorted(found.items(), key=lambda kv: kv[1][0])
    rows = [r for _, (_, r) in ranked[:top]]
    if c and c in found and found[c][1] not in rows:
        rows.append(found[c][1])
    what = (f"the {min(top, total)} best of all {total} designs of {size}" if exhaustive else
            f"the best of the chosen design and its {n_ranked - 1} neighbours (one candidate exchanged); the "
            f"{total:.3g} designs of {size} are too many to rank")
    return RankedDesignTable(kind=kind_e.value, rows=tuple(rows), note=what)


def design_rows(F, S, sensor_names, min_sensors: int, chosen, criterion: str, *, kind: str = "gauss_newton",
                full_rows: int = FULL_TABLE_ROWS) -> DesignTable:
    """Every combination of at least ``min_sensors`` candidates (:func:`oed.design.design_table`) while they
    number at most ``full_rows``, else the ten best designs of the size of ``chosen`` (a DesignResult) and
    the chosen one (:func:`best_designs`)."""
    from .constraints import DesignConstraints
    from .design import design_table
    n_S, n_p = np.shape(F)[0], np.shape(F)[1]
    if DesignConstraints(n_candidates=n_S, n_params=n_p, min_sensors=min_sensors).count_designs() <= full_rows:
        return design_table(F, S, sensor_names, min_sensors, kind=kind)
    return best_designs(F, S, sensor_names, len(chosen.sensors), criterion, kind=kind, chosen=chosen.indices)
