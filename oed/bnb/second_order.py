r"""A valid lower bound on the second-order criteria over a branch-and-bound node, and why it is
not used in the search.

Node: fixed-in set :math:`I`, free set :math:`R`, designs :math:`w = I\cup T`, :math:`T\subseteq R`,
:math:`|T| = r`.  For a design, :math:`G = \sum_{k\in w}F_k \succ 0`, :math:`S = \sum_{k\in w}S_k`,
:math:`H = G + S` and :math:`C = H^{-1}GH^{-1}` (:mod:`oed.criteria`).

**Perturbation of one design.**  With :math:`K = G^{-1/2}SG^{-1/2}` (symmetric, eigenvalues
:math:`\mu_i`, :math:`\kappa = \max_i|\mu_i|`): :math:`H = G^{1/2}(I+K)G^{1/2}` and

.. math::  C = G^{-1/2}(I+K)^{-2}G^{-1/2} \succeq (1+\kappa)^{-2}\,G^{-1}

because :math:`|1+\mu_i|\le 1+|\mu_i|\le 1+\kappa` (no condition :math:`\kappa<1` needed).  Trace and
largest eigenvalue are Loewner-monotone, and :math:`\log\det C = -\log\det G - 2\sum_i\log|1+\mu_i|`, so

.. math::  \Psi_A(C)\ge\frac{\Psi_A(G^{-1})}{(1+\kappa)^2},\quad
           \Psi_E(C)\ge\frac{\Psi_E(G^{-1})}{(1+\kappa)^2},\quad
           \Psi_D(C)\ge\Psi_D(G^{-1}) - 2\sum_i\log(1+|\mu_i|).

**Over the node.**  :math:`G(w)\succeq G_I = \sum_{k\in I}F_k`.  The :math:`|\mu_i|` are the absolute
eigenvalues of the pencil :math:`(S, G)`; by Courant-Fischer (and Sylvester's inertia) each of them
decreases when :math:`G` grows in the Loewner order, so with :math:`V = G_I^{-1/2}` (:math:`G_I\succ0`)
and the triangle inequality over the chosen free sensors

.. math::  \kappa \le \|VS_IV\|_2 + \textstyle\sum_{\text{top } r,\,k\in R}\|VS_kV\|_2 =: \bar\kappa,\qquad
           \textstyle\sum_i|\mu_i| \le \|VS_IV\|_* + \sum_{\text{top } r,\,k\in R}\|VS_kV\|_* =: \bar\tau,

and by concavity of :math:`\log(1+x)` under :math:`|\mu_i|\le\bar\kappa`, :math:`\sum|\mu_i|\le\bar\tau`:
:math:`\sum_i\log(1+|\mu_i|)\le p\log(1+\min(\bar\kappa,\bar\tau/p))`.  With :math:`L` any valid lower
bound of the Gauss-Newton criterion over the node (a relaxation bound of :mod:`oed.bnb`, or the
exact node minimum), the node bound is

.. math::  A, E:\ \frac{L}{(1+\bar\kappa)^2},\qquad D:\ L - 2p\log\big(1+\min(\bar\kappa,\bar\tau/p)\big),

and :math:`0` (A, E: :math:`C\succeq0`) or :math:`-\infty` (D) when :math:`G_I` is singular, in
particular at the root.

**Why no better root bound exists.**  A design whose :math:`G` is nearly singular while :math:`H` is
not has :math:`C\approx H^{-1}GH^{-1}` of the size :math:`\lambda(G)/\lambda(H)^2`, i.e. arbitrarily
small: the second-order criterion of a near-singular design can beat every well-conditioned one.
A bound is therefore finite only where the fixed-in sensors already make :math:`G_I` regular.

**Measured usefulness** (``python -m bench frontier --bound-study``, 30 candidates x 4 parameters,
choose 6 (593,775 designs), rank-2 :math:`F_k`, :math:`\|S_k\| = 0.05\|F_k\|`, lexicographic
set-enumeration tree, with :math:`L` the *exact* Gauss-Newton minimum of each node, i.e. better than
any relaxation, and the true optimum as incumbent).  The true :math:`\kappa` of the designs has median
0.095 and 99 % quantile 0.31, but the node radius :math:`\bar\kappa` has median 9.4 at depth 2, 1.3 at
depth 3 and 0.45 at depth 4 (the loss: the triangle inequality over the free sensors and
:math:`G_I\preceq G(w)`).  Nodes pruned (designs they contain):

=====  ======  ===============  ===============  ===============
depth  nodes   A                D                E
=====  ======  ===============  ===============  ===============
2      325     0 (0)            0 (0)            0 (0)
3      2,925   0 (0)            35 (69)          89 (280)
4      20,475  3,349 (15,124)   10,731 (188,161) 8,829 (111,504)
=====  ======  ===============  ===============  ===============

Pruning starts only two levels above the leaves, after some 23,000 nodes whose radii cost about as
much as evaluating the designs, so a branch-and-bound with this bound cannot beat the screened
enumeration (:mod:`oed.enumeration`), which evaluates these 593,775 designs in about 1 s of CPU.
``method="auto"`` therefore proves second-order designs by screened enumeration when its measured
cost fits the time limit and goes to SCIP beyond; this bound is not wired into the search.
"""
from __future__ import annotations

import numpy as np

from ..criteria import Criterion

__all__ = ["second_order_node_bound", "perturbation_radii"]


def perturbation_radii(F, S, fixed_in, free, r, *, rank_rtol=1e-13):
    r"""Node radii :math:`(\bar\kappa, \bar\tau)` bounding :math:`\max_i|\mu_i|` and :math:`\sum_i|\mu_i|`
    of :math:`G(w)^{-1/2}S(w)G(w)^{-1/2}` over the node (see the module docstring).

    Parameters
    ----------
    F, S : ndarray, shape (n, p, p)
        Validated information and second-order terms.
    fixed_in, free : array_like of int
        The node's fixed-in sensors :math:`I` and free sensors :math:`R`.
    r : int
        Free sensors every design of the node takes (``0 <= r <= len(free)``).

    Returns
    -------
    (float, float)
        ``(inf, inf)`` when :math:`G_I` is singular (scaled smallest eigenvalue ``<= rank_rtol``).
    """
    fixed_in = np.asarray(fixed_in, dtype=int)
    free = np.asarray(free, dtype=int)
    p = F.shape[1]
    if fixed_in.size == 0:
        return np.inf, np.inf
    GI = F[fixed_in].sum(axis=0)
    lam, U = np.linalg.eigh(GI)
    if not lam[0] > rank_rtol * max(lam[-1], np.finfo(float).tiny):
        return np.inf, np.inf
    V = (U / np.sqrt(lam)) @ U.T
    eig_I = np.abs(np.linalg.eigvalsh(V @ S[fixed_in].sum(axis=0) @ V))
    kappa, tau = float(eig_I.max()), float(eig_I.sum())
    if r > 0:
        eig_R = np.abs(np.linalg.eigvalsh(V[None] @ S[free] @ V[None]))
        kappa += float(np.sort(eig_R.max(axis=1))[::-1][:r].sum())
        tau += float(np.sort(eig_R.sum(axis=1))[::-1][:r].sum())
    return kappa, min(tau, p * kappa)


def second_order_node_bound(F, S, fixed_in, free, r, criterion, gn_bound, *, rank_rtol=1e-13) -> float:
    r"""Lower bound on :math:`\Psi(H^{-1}GH^{-1})` over every design :math:`I\cup T` of the node,
    :math:`T\subseteq R`, :math:`|T| = r`, from a lower bound ``gn_bound`` of the Gauss-Newton
    criterion :math:`\Psi(G^{-1})` over the same node (D on log det).

    A, E: ``gn_bound / (1 + kappa)^2``; D: ``gn_bound - 2 p log(1 + min(kappa, tau / p))``;
    0 (A, E) or ``-inf`` (D) when :math:`G_I` is singular.  Derivation in the module docstring.
    """
    crit = Criterion.parse(criterion)
    kappa, tau = perturbation_radii(F, S, fixed_in, free, r, rank_rtol=rank_rtol)
    p = F.shape[1]
    if not np.isfinite(kappa):
        return -np.inf if crit is Criterion.D else 0.0
    if crit is Criterion.D:
        return float(gn_bound - 2.0 * p * np.log1p(min(kappa, tau / p)))
    return float(max(gn_bound, 0.0) / (1.0 + kappa) ** 2)
