"""Settings and result of the sensor-selection branch-and-bound (:func:`oed.bnb.branch_and_bound`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BnBSettings", "BnBResult"]


@dataclass(frozen=True)
class BnBSettings:
    """Settings for :func:`branch_and_bound`.

    Attributes
    ----------
    time_limit : float
        Wall-clock seconds.
    gap_tol : float
        Optimality tolerance: relative for A and E; absolute on log det C for D
        (i.e. relative on det C).  Nodes with bound >= incumbent - tol are pruned.
    root_iters, node_iters : int
        Maximum relaxation iterations at the root / at other nodes.
    node_limit : int or None
    e_betas : tuple of float
        Soft-min sharpness continuation for the E relaxation (``t = beta / lambda_min``).
    nonmonotone : int
        Memory of the non-monotone (Grippo-Lampariello-Lucidi) Armijo line search of the
        projected-gradient relaxation solve (1 = monotone).
    batch_size : int
        Number of best-bound nodes branched together; their children's relaxations are
        solved simultaneously (vectorised over the batch).
    e_refine_iters : int
        E only: exponentiated-subgradient iterations that re-optimise the eigenvalue weights of
        the bound matrix ``Z = U diag(pi) U^T`` (``U``: eigenvectors of the relaxed FIM) at the
        end of a node's relaxation (0 = off).  See :func:`oed.bnb.bounds.e_bound_refine`.
    branch_target : float
        Branch on the free variable whose relaxed value is closest to this (0.5 = most
        fractional; values above 0.5 favour sensors the relaxation nearly selects, which made
        A and E trees smaller on the benchmark instances).
    budget_steering : bool
        With a budget: steer the relaxation towards the budget by minimising
        ``phi(x) + mu c^T x`` with ``mu`` the budget price of the node's Lagrangian bound
        (:func:`oed.bnb.bounds.budget_top`), inherited by the children.  Root bounds get tighter on every
        instance measured, but the trees behave differently: 100 x 10 A with m = 20 gap 3 % ->
        0.4 % in 60 s, 50 x 10 A with m = 20 proven in 2.8 s instead of 20 s, while 50 x 10 A and
        100 x 10 D with m = 10 are no longer proven within 60 s (bench/RESULTS.md).  Off by default.
    early_branch : bool
        At non-root nodes stop the relaxation (after ``early_branch_min_iters`` iterations)
        once the criterion at the relaxed point is below incumbent - tol: the relaxation
        optimum, hence every bound it can give, is then too small to prune.
    """

    time_limit: float = 60.0
    gap_tol: float = 1e-9
    root_iters: int = 400
    node_iters: int = 40
    node_limit: int | None = None
    e_betas: tuple = (30.0, 300.0, 3000.0)
    early_branch: bool = True
    early_branch_min_iters: int = 3
    batch_size: int = 128
    nonmonotone: int = 5
    e_refine_iters: int = 30
    branch_target: float = 0.65
    budget_steering: bool = False

    def __post_init__(self):
        if not (isinstance(self.time_limit, (int, float, np.floating)) and self.time_limit > 0):
            raise ValueError(f"time_limit: expected seconds > 0, got {self.time_limit!r}")
        if not (isinstance(self.gap_tol, (int, float, np.floating)) and 0 <= self.gap_tol < np.inf):
            raise ValueError(f"gap_tol: expected a finite number >= 0, got {self.gap_tol!r}")
        for name, low in (("root_iters", 1), ("node_iters", 1), ("early_branch_min_iters", 0), ("batch_size", 1),
                          ("nonmonotone", 1), ("e_refine_iters", 0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= low):
                raise ValueError(f"{name}: expected an integer >= {low}, got {v!r}")
        if self.node_limit is not None and not (isinstance(self.node_limit, (int, np.integer)) and self.node_limit >= 1):
            raise ValueError(f"node_limit: expected None or an integer >= 1, got {self.node_limit!r}")
        if not (len(self.e_betas) >= 1 and all(float(b) > 0 for b in self.e_betas)):
            raise ValueError(f"e_betas: expected one or more positive sharpness values, got {self.e_betas!r}")
        if not (0.0 <= float(self.branch_target) <= 1.0):
            raise ValueError(f"branch_target: expected a value in [0, 1], got {self.branch_target!r}")


@dataclass(frozen=True)
class BnBResult:
    """Outcome of :func:`branch_and_bound`.

    ``status`` is one of ``"optimal"`` (gap <= tol), ``"time_limit"``, ``"node_limit"``,
    ``"infeasible"`` (no regular design).  ``gap`` = value - lower_bound (for D on log det).
    """

    w: np.ndarray | None
    value: float
    lower_bound: float
    gap: float
    status: str
    nodes: int
    wall_time: float
    root_bound: float
    initial_incumbent: float
