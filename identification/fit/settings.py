"""Settings of the weighted least-squares estimator (:func:`identification.fit.estimator.fit_static`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from identification.fit.ipopt_solver import IpoptSettings

__all__ = ["IdentifySettings", "INIT_CHOICES"]

#: the start trajectories of a collocated ODE's full-space NLP (:attr:`IdentifySettings.init`)
INIT_CHOICES = ("data", "simulate")


@dataclass(frozen=True)
class IdentifySettings:
    """Settings of :func:`identify` (defaults suit most problems).

    Attributes
    ----------
    ipopt : IpoptSettings
    refine_steps : int        maximum exact reduced Newton refinement steps after Ipopt
    rank_rtol : float         relative singular value of the column-normalised sqrt(Omega) J
                              below which the parameters count as not identifiable
    ill_conditioned : float   condition number of the normalised information that triggers a note
    s_ratio_note : float      ||S|| / ||J^T Omega J|| (normalised) that triggers a note
    decrement_tol : float     Newton decrement g^T H^-1 g (chi^2 units) accepted as optimal when
                              Ipopt stalls (1e-10: within 1e-5 standard errors of the optimum)
    predictor_step : float    largest relative parameter change of the linearised Gauss-Newton
                              predictor that sets Ipopt's start point (0 disables it)
    lazy_bounds : bool        first solve without the parameter bounds (at most LAZY_PASS_MAX_ITER
                              Ipopt iterations) and keep that solution
                              when it lies strictly inside them (else solve with the bounds)
    refine_decrement : float  no refinement step is taken once the Newton decrement g^T H^-1 g
                              (chi^2 units) is below this (1e-18: p within 1e-9 standard errors
                              of the optimum; Ipopt's solutions are typically at 1e-20)
    explicit_newton : bool    explicit models (no state) are first solved by exact reduced-space
                              Gauss-Newton/Newton steps (:func:`solve_explicit_newton`); Ipopt is
                              the fallback and solves the problem when a bound is active
    reduced_start_inputs : int or None
                              implicit models with small (dense) states and at least this many
                              inputs start Ipopt at the reduced-space optimum with its
                              multipliers (:func:`reduced_start`; Ipopt verifies it, usually at
                              iteration 0, instead of iterating on the n_q n_y states); None never
    init : str                where the full-space NLP of a collocated ODE starts its trajectories:
                              "data" (default): through the series means where the outputs are linear
                              in the states, the rest from the simulation at p0
                              (:mod:`identification.fit.data_start`); "simulate": the simulation at p0.
                              Only Ipopt's start: the reduced-space iteration (which solves the
                              trajectories at every p) and the optimum are the same either way.  With
                              "data", a start with a value on its bound (moved into the interior) is
                              solved on the first mesh by the full-space NLP directly, its unbounded
                              first pass capped at DATA_LAZY_PASS_MAX_ITER iterations
    """

    ipopt: IpoptSettings = field(default_factory=IpoptSettings)
    refine_steps: int = 5
    rank_rtol: float = 1e-9
    ill_conditioned: float = 1e8
    s_ratio_note: float = 0.1
    decrement_tol: float = 1e-10
    predictor_step: float = 0.25
    lazy_bounds: bool = True
    refine_decrement: float = 1e-18
    explicit_newton: bool = True
    reduced_start_inputs: int | None = 200
    init: str = "data"

    def __post_init__(self):
        if not isinstance(self.ipopt, IpoptSettings):
            raise TypeError(f"ipopt: expected IpoptSettings, got {type(self.ipopt).__name__}")
        if not (isinstance(self.refine_steps, (int, np.integer)) and self.refine_steps >= 0):
            raise ValueError(f"refine_steps: expected an integer >= 0, got {self.refine_steps!r}")
        for name in ("rank_rtol", "decrement_tol", "refine_decrement", "s_ratio_note"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
        if not (isinstance(self.ill_conditioned, (int, float, np.floating)) and self.ill_conditioned > 1):
            raise ValueError(f"ill_conditioned: expected a condition number > 1, got {self.ill_conditioned!r}")
        if self.reduced_start_inputs is not None and not (
                isinstance(self.reduced_start_inputs, (int, np.integer)) and self.reduced_start_inputs >= 1):
            raise ValueError(f"reduced_start_inputs: expected None or an integer >= 1, "
                             f"got {self.reduced_start_inputs!r}")
        if self.init not in INIT_CHOICES:
            raise ValueError(f"init: expected one of {', '.join(map(repr, INIT_CHOICES))}, got {self.init!r}")
        if not (isinstance(self.predictor_step, (int, float, np.floating)) and 0 <= self.predictor_step < np.inf):
            raise ValueError(f"predictor_step: expected a finite number >= 0 (0 disables the predictor), "
                             f"got {self.predictor_step!r}")
