r"""Optimal design of experiments (paper section 3).

Solves :math:`\min_{w\in\{0,1\}^{n_c}} \Psi(C(w))` over candidates c on one axis (sensors, sampling
times, (time, sensor) pairs, input rows or (row, sensor) pairs) subject to design constraints, where
:math:`C` is the second-order or Gauss-Newton covariance and :math:`\Psi` the A-, D- or
E-criterion.  One information function, :func:`information` (:mod:`oed.candidate_information`), gives every
candidate's information on any axis, for static and dynamic models alike; one engine,
:func:`select_sensors_from_information` (:mod:`oed.design`), chooses.  Front doors:
:func:`select_sensors` (sensors; with ``data=None`` planned before measuring), :func:`select_times`
(a dynamic model's sampling times, :mod:`oed.times`) and :func:`select_inputs` (input rows, or input x
sensor pairs, with a continuous Ipopt refinement; dynamic models: experiment inputs with control
profiles, :mod:`oed.inputs`).  Every design result names its ``axis`` and its ``chosen`` candidates.
Approximate designs (support points and weights on a continuous range, local, pseudo-Bayesian or
maximin over a prior, with the equivalence-theorem certificate): :func:`approximate_design`
(:mod:`oed.approximate`, :mod:`oed.prior`, :mod:`oed.robust`), also as ``approximate=True`` of
:func:`select_inputs` and :func:`select_times`.  Exact n-run designs under a prior (expected or worst-case
criterion of the chosen set): :func:`oed.robust_exact.select_robust_exact`, by enumeration or the branch-and-bound
with proven gaps of :mod:`oed.robust_bnb`, also as ``select_times(..., prior=, approximate=False)``, refined
continuously with ``refine=True`` (:mod:`oed.robust_refine`).  Sparse-grid priors: :mod:`oed.prior_sparse`;
sequential designs under a prior: :mod:`oed.sequential_robust`.  Designs that
learn the model error (the n runs that most shrink the posterior prediction band of model plus model error over a
region of use, after :func:`identification.model_error`): :func:`select_error_design` (:mod:`oed.error_design`,
imported on first use).
"""
import importlib

from .criteria import DEFAULT_CRITERION, Criterion, CriteriaSettings, batch_criteria, criterion_value, validate_information
from .candidate_information import AXES, CandidateInformation, information
from .design import (DesignResult, DesignRow, DesignSettings, DesignTable, design_table, select_sensors,
                     select_sensors_from_information)
from .discrimination import DiscriminationResult, select_discriminating
from .inputs import (InputDesignResult, RefinedInputs, RefineSettings, dynamic_input_information, input_information,
                     refine_inputs, select_dynamic_inputs, select_inputs)
from .times import select_times, time_information
from .prior import Prior, make_prior
from .approximate import ApproximateDesign, ApproximateSettings, approximate_design, design_efficiencies

#: public names imported on first use (PEP 562): name -> module
_LAZY = {"ErrorDesignResult": "oed.error_design", "select_error_design": "oed.error_design",
         "error_design_problem": "oed.error_design"}

__all__ = ["DEFAULT_CRITERION", "Criterion", "CriteriaSettings", "batch_criteria", "criterion_value", "validate_information",
           "AXES", "CandidateInformation", "information",
           "DesignResult", "DesignRow", "DesignSettings", "DesignTable", "design_table", "select_sensors",
           "select_sensors_from_information", "InputDesignResult", "RefinedInputs", "RefineSettings",
           "input_information", "refine_inputs", "select_inputs", "DiscriminationResult", "select_discriminating",
           "select_times", "time_information", "dynamic_input_information", "select_dynamic_inputs", "Prior",
           "make_prior", "ApproximateDesign", "ApproximateSettings", "approximate_design",
           "design_efficiencies", *_LAZY]


def __getattr__(name: str):
    """``oed.<name>`` of :data:`_LAZY`: import its module on first use."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'oed' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
