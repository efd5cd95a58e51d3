r"""Exact branch-and-bound for Gauss-Newton A-, D-, E-optimal sensor selection.

Solves

.. math::  \min_{w\in\{0,1\}^{n_S}} \Psi\Big(\big(\textstyle\sum_k w_kF_k\big)^{-1}\Big)
           \quad\text{s.t.}\quad \sum_k w_k = m,\ w_k=1\ (k\in I),\ w_k=0\ (k\in O),

with :math:`\Psi\in\{\mathrm{tr},\ \log\det,\ \lambda_{\max}\}`, optionally with per-sensor
costs and a budget :math:`c^Tw\le b` (then :math:`lo\le\sum_k w_k\le m`: the budget may stop the
best design short of m sensors).

Bounds are rigorous for *any* relaxation iterate (they need not be optimal): with
:math:`M(v)=\sum_k v_kF_k` and node polytope :math:`P=\{v\in[0,1]^{n_S}: \sum v=m,\ \text{fixings}\}`,

* D: :math:`-\log\det M(v) \ge -\log\det X + p - \mathrm{tr}(X^{-1}M(v))` for any :math:`X\succ0`
  (concavity of log det, tangent at :math:`X=M(x)`);
* A: :math:`\mathrm{tr}\,M(v)^{-1} \ge 2\,\mathrm{tr}X^{-1} - \mathrm{tr}(X^{-2}M(v))` (convexity);
* E: :math:`\lambda_{\min}(M(v)) \le \mathrm{tr}(Z M(v))` for any :math:`Z\succeq0,\ \mathrm{tr}Z=1`,

so each bound is :math:`h(\max_{v\in P} q^Tv)` with :math:`h` decreasing and the inner
maximum a closed-form "top-r" sum.  The same linear form gives reduced-cost variable
fixing.  :math:`X` (resp. :math:`Z`) comes from a few spectral-projected-gradient steps on
the continuous relaxation (for E a soft-min smoothing of :math:`\lambda_{\min}`), warm
started from the parent node; the children of up to ``batch_size`` best-bound parents are
solved together (batched linear algebra), and for E the bound of a node that ends unpruned
is re-optimised over the eigenbasis weights of Z.  Incumbents come from greedy + Fedorov
exchange and from rounding node relaxations.  Branching: the free variable whose relaxed value is closest to
``branch_target`` (0.65); node selection:
best bound first.  Monotonicity (adding a sensor never increases a GN criterion) reduces
``sum w <= m`` to ``sum w = m``.

With a budget the node polytope is :math:`\{v: \sum v\le r,\ c^Tv\le b_{node}\}`.  The relaxation
point still comes from the count-only polytope (any point gives valid bounds); the budget enters
the bound through the linear maximum, bounded by its Lagrangian dual over the budget multiplier
(:func:`oed.bnb.bounds.budget_top`).  Free sensors that no longer fit the node's budget are fixed out, a node
whose free sensors all fit is a leaf (take them all), and the greedy/exchange and rounding
heuristics keep to the budget.  Reduced-cost fixing and the E eigenbasis refinement assume an
exact count and are switched off.

Modules: :mod:`.settings` (settings, result), :mod:`.problem` (criterion data, count/budget limits
and fixings, incumbent), :mod:`.projection` (capped-simplex projections, top-r sums),
:mod:`.bounds` (A/D/E bounds, Lagrangian budget bound, E eigenbasis refinement),
:mod:`.relaxation` (the batched projected-gradient node relaxation), :mod:`.heuristics`
(greedy/exchange, rounding) and :mod:`.tree` (best-bound tree search).
"""

from .heuristics import greedy_exchange
from .problem import SelectionProblem, fixings
from .settings import BnBResult, BnBSettings
from .tree import branch_and_bound

__all__ = ["BnBSettings", "BnBResult", "branch_and_bound", "greedy_exchange", "SelectionProblem", "fixings"]
