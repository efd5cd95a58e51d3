r"""Optimal sensor selection (optimal design of experiments, paper section 3).

Solves :math:`\min_{w\in\{0,1\}^{n_S}} \Psi(C(w))` subject to design constraints, where
:math:`C` is the second-order or Gauss-Newton covariance and :math:`\Psi` the A-, D- or
E-criterion.  Front doors: :func:`select_sensors_from_information` / :func:`select_sensors`
(sensors; with ``data=None`` planned before measuring) and :func:`select_inputs` (input points, or
input x sensor pairs, through the same engine, with a continuous Ipopt refinement; dynamic models:
experiment inputs with control profiles, :mod:`oed.dynamic_inputs`); see :mod:`oed.design` and
:mod:`oed.inputs`.  Approximate designs (support points and weights on a continuous range, local,
pseudo-Bayesian or maximin over a prior, with the equivalence-theorem certificate):
:func:`approximate_design` (:mod:`oed.approximate`, :mod:`oed.prior`, :mod:`oed.robust`), also as
``approximate=True`` of :func:`select_inputs` and :func:`select_times`.
"""
from .criteria import Criterion, CriteriaSettings, batch_criteria, criterion_value, validate_information
from .design import (DesignResult, DesignRow, DesignSettings, DesignTable, design_table, select_sensors,
                     select_sensors_from_information)
from .discrimination import DiscriminationResult, select_discriminating
from .inputs import InputDesignResult, RefinedInputs, RefineSettings, input_information, refine_inputs, select_inputs
from .times import select_times, time_information
from .dynamic_inputs import dynamic_input_information, select_dynamic_inputs
from .prior import Prior, make_prior
from .approximate import ApproximateDesign, ApproximateSettings, approximate_design, design_efficiencies

__all__ = ["Criterion", "CriteriaSettings", "batch_criteria", "criterion_value", "validate_information",
           "DesignResult", "DesignRow", "DesignSettings", "DesignTable", "design_table", "select_sensors",
           "select_sensors_from_information", "InputDesignResult", "RefinedInputs", "RefineSettings",
           "input_information", "refine_inputs", "select_inputs", "DiscriminationResult", "select_discriminating",
           "select_times", "time_information", "dynamic_input_information", "select_dynamic_inputs", "Prior",
           "make_prior", "ApproximateDesign", "ApproximateSettings", "approximate_design",
           "design_efficiencies"]
