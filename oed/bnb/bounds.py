r"""Rigorous node bounds: :math:`h(\max_{v\in P} q^Tv)` for A, D, E, the Lagrangian bound of the
budgeted linear maximum, and the re-optimised eigenbasis bound for E (see :mod:`oed.bnb`).
"""
from __future__ import annotations

import numpy as np

from ..criteria import Criterion

__all__ = ["bound_from_s", "budget_top", "e_bound_refine"]


def bound_from_s(crit: Criterion, p: int, f, s):
    r"""Lower bound :math:`h(s)` on the criterion over a node from the linear-form maximum ``s``.

    D: :math:`f + p - s`; A: :math:`2f - s` (``f`` the criterion at the relaxed point);
    E: :math:`1/s` (``inf`` for :math:`s\le0`; ``f`` unused).  Scalars or arrays.
    """
    if crit is Criterion.D:
        return f + p - s
    if crit is Criterion.A:
        return 2.0 * f - s
    if np.ndim(s) == 0:
        return 1.0 / s if s > 0 else np.inf
    pos = s > 0
    return np.where(pos, 1.0 / np.where(pos, s, 1.0), np.inf)


def budget_top(Q, free, r, costs, left, iters=40):
    r"""Upper bound on :math:`\max\{q^Tv:\ v\in[0,1]^{free},\ \sum v\le r,\ c^Tv\le b\}` per row.

    Lagrangian relaxation of the budget: for every :math:`\mu\ge0`

    .. math::  \max_{v} q^Tv \le \mu b + \textstyle\sum_{\text{top } r} (q_k - \mu c_k)_+ =: s(\mu),

    a convex piecewise-linear function of :math:`\mu` whose minimum is the LP value.  It is
    minimised by bisection on its slope :math:`b - \sum_{k\in\text{top}} c_k` over
    :math:`[0, \max_k q_k/c_k]`; every evaluated :math:`s(\mu)` is a valid bound and the
    smallest is returned with its multiplier (the relaxation's budget price, used to steer the
    relaxation point towards the budget).

    Parameters
    ----------
    Q : ndarray (B, n)
    free : ndarray of bool (B, n)
    r : ndarray of int (B,)      count still allowed (>= 1)
    costs : ndarray (n,)
    left : ndarray (B,)          budget still available (>= 0)
    """
    B, n = Q.shape
    rr = np.minimum(r, free.sum(axis=1))

    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(free & (costs[None, :] > 0), Q / costs[None, :], 0.0)
    lo = np.zeros(B)
    hi = np.maximum(ratio.max(axis=1), 0.0)
    best, _ = _lagrangian_top(Q, free, rr, costs, left, lo)
    mu_best = lo.copy()
    val, _ = _lagrangian_top(Q, free, rr, costs, left, hi)
    mu_best = np.where(val < best, hi, mu_best)
    best = np.minimum(best, val)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        val, slope = _lagrangian_top(Q, free, rr, costs, left, mid)
        mu_best = np.where(val < best, mid, mu_best)
        best = np.minimum(best, val)
        up = slope < 0                                # s still decreasing: the minimum lies right
        lo = np.where(up, mid, lo)
        hi = np.where(up, hi, mid)
    return best, mu_best


def _lagrangian_top(Q, free, rr, costs, left, mu):
    r""":math:`s(\mu)=\mu b+\sum_{\text{top } r}(q_k-\mu c_k)_+` per row and its slope
    :math:`b-\sum_{\text{top}}c_k` (``rr``: the count, ``left``: the budget ``b``)."""
    B, n = Q.shape
    ar = np.arange(B)[:, None]
    d = np.where(free, np.maximum(Q - mu[:, None] * costs[None, :], 0.0), 0.0)
    ordd = np.argsort(-d, axis=1, kind="stable")
    ds = d[ar, ordd]
    sel = np.arange(n)[None, :] < rr[:, None]
    val = mu * left + np.where(sel, ds, 0.0).sum(axis=1)
    used = np.where(sel & (ds > 0), costs[ordd], 0.0).sum(axis=1)
    return val, left - used


def e_bound_refine(Fflat, X, free, on, r, tE, iters):
    r"""Best E bound over ``Z = U diag(pi) U^T``, ``pi`` in the simplex, for a batch of nodes.

    With ``U`` the eigenvectors of :math:`M(x)` and :math:`c_{ki} = (u_i^Ta_k)^2`, every ``pi``
    gives the rigorous bound :math:`\lambda_{\min}(M(v)) \le s(\pi) = \max_{v\in P}\sum_k v_k
    \sum_i \pi_i c_{ki}` (a fixed-in sum plus a top-r sum over the free sensors).  ``s`` is convex
    and piecewise linear in ``pi``; a subgradient is :math:`\sum_{k\in\text{top}} c_{k\cdot}`.
    Minimised by exponentiated subgradient steps (the minimum equals the eigenvector-cut LP
    :math:`\max t\ \text{s.t.}\ t\le\sum_k v_kc_{ki}\ \forall i,\ v\in P`).

    Parameters
    ----------
    Fflat : ndarray, shape (n, p*p)
        The flattened :math:`F_k`.
    X : ndarray, shape (B, n)
        Relaxed points (only used to build ``U``).
    free, on : ndarray of bool, shape (B, n)
    r : ndarray of int, shape (B,)
        Number of free sensors still to choose (``1 <= r < free.sum()``).
    tE : ndarray, shape (B,)
        Soft-min sharpness: the start is the soft-min weighting ``pi_i ~ exp(-tE (lam_i - lam_1))``.
    iters : int

    Returns
    -------
    ndarray, shape (B,)
        The smallest ``s(pi)`` seen (an upper bound on :math:`\lambda_{\min}` over the node).
    """
    B, n = X.shape
    p = int(round(np.sqrt(Fflat.shape[1])))
    lam, U = np.linalg.eigh((X @ Fflat).reshape(B, p, p))
    UU = np.einsum("bai,bci->biac", U, U).reshape(B, p, p * p)
    C = (UU @ Fflat.T).transpose(0, 2, 1)  # (B, n, p): u_i^T F_k u_i
    Con = np.einsum("bk,bki->bi", on.astype(float), C)
    pi = np.exp(-tE[:, None] * (lam - lam[:, :1]))
    pi = pi / pi.sum(axis=1, keepdims=True)
    pi = 0.9 * pi + 0.1 / p  # keep every direction alive for the multiplicative updates
    best = np.full(B, np.inf)
    ar = np.arange(B)
    rmax = int(r.max())
    for t in range(max(iters, 1)):
        c = np.einsum("bki,bi->bk", C, pi)
        c = np.where(free, c, -np.inf)
        idx = np.argpartition(-c, rmax - 1, axis=1)[:, :rmax] if rmax < n else np.argsort(-c, axis=1)
        cv = np.take_along_axis(c, idx, axis=1)
        o = np.argsort(-cv, axis=1, kind="stable")
        idx = np.take_along_axis(idx, o, axis=1)
        sel = np.arange(idx.shape[1])[None, :] < r[:, None]
        Ct = C[ar[:, None], idx]  # (B, rmax, p)
        g = Con + np.einsum("bk,bki->bi", sel.astype(float), Ct)
        s = np.einsum("bi,bi->b", g, pi)
        best = np.minimum(best, s)
        gs = g / np.maximum(s, 1e-300)[:, None]
        eta = 2.0 / np.sqrt(t + 1.0)
        z = -eta * (gs - gs.min(axis=1, keepdims=True))
        pi = pi * np.exp(z)
        pi /= pi.sum(axis=1, keepdims=True)
    return best
