r"""Capped-simplex projections and top-r sums over the free sensors of a node.

The node polytope without a budget is :math:`\{x: 0\le x_k\le1\ (k\text{ free}),\ \sum_{\text{free}}x_k=r\}`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["proj_capped_simplex", "proj_capped_simplex_batch", "rowwise_top"]


def proj_capped_simplex(y, r):
    """Euclidean projection of y onto {0 <= x <= 1, sum x = r} (reference for the batched version)."""
    n = y.size
    if r <= 0:
        return np.zeros(n)
    if r >= n:
        return np.ones(n)
    bp = np.sort(np.concatenate([y - 1.0, y]))
    s = np.clip(y[None, :] - bp[:, None], 0.0, 1.0).sum(axis=1)
    i = int(np.searchsorted(-s, -r, side="left"))  # first index with s <= r
    if i <= 0:
        tau = bp[0]
    elif i >= bp.size:
        tau = bp[-1]
    else:
        s0, s1 = s[i - 1], s[i]
        tau = bp[i - 1] if s0 == s1 else bp[i - 1] + (s0 - r) * (bp[i] - bp[i - 1]) / (s0 - s1)
    return np.clip(y - tau, 0.0, 1.0)


def proj_capped_simplex_batch(Y, free, r):
    """Row-wise projection onto ``{0 <= x_k <= 1 (k free), sum_free x = r}``.

    Parameters
    ----------
    Y : ndarray, shape (B, n)
    free : ndarray of bool, shape (B, n)
        Entries outside ``free`` are returned as 0.  Every row needs ``0 < r < free.sum()``.
    r : ndarray of int, shape (B,)

    Returns
    -------
    ndarray, shape (B, n)
        Exact (up to rounding): ``s(tau) = sum_j c_j (b_j - tau)_+`` over the breakpoints
        ``b = (y, y - 1)`` with signs ``c = (+1, -1)`` is evaluated at all sorted breakpoints
        by cumulative sums, and the root of ``s(tau) = r`` is interpolated on its piece.
    """
    B, n = Y.shape
    rf = r.astype(float)
    lo = np.min(np.where(free, Y, np.inf), axis=1)
    Yc = np.where(free, Y, (lo - 2.0)[:, None])  # non-free: below every relevant tau
    bp = np.concatenate([Yc, Yc - 1.0], axis=1)
    sg = np.concatenate([np.ones((B, n)), -np.ones((B, n))], axis=1)
    order = np.argsort(-bp, axis=1, kind="stable")
    b = np.take_along_axis(bp, order, axis=1)
    c = np.take_along_axis(sg, order, axis=1)
    C0 = np.cumsum(c, axis=1) - c  # exclusive sums over breakpoints above b_k
    C1 = np.cumsum(c * b, axis=1) - c * b
    s = C1 - C0 * b  # s at tau = b_k (nondecreasing in k)
    k = np.minimum(np.count_nonzero(s < rf[:, None], axis=1), 2 * n - 1)
    ar = np.arange(B)
    c0, c1 = C0[ar, k], C1[ar, k]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(c0 > 0, (c1 - rf) / np.where(c0 > 0, c0, 1.0), b[ar, k])
    return np.where(free, np.clip(Y - tau[:, None], 0.0, 1.0), 0.0)


def rowwise_top(Q, free, r):
    """For each row: descending order of Q over ``free`` (non-free last), sorted values and top-r sum."""
    Qf = np.where(free, Q, -np.inf)
    order = np.argsort(-Qf, axis=1, kind="stable")
    Qs = np.take_along_axis(Qf, order, axis=1)
    cs = np.cumsum(np.where(np.isfinite(Qs), Qs, 0.0), axis=1)
    ar = np.arange(Q.shape[0])
    return order, Qs, cs[ar, r - 1]
