r"""Optimal sensor selection (optimal design of experiments, paper section 3).

Solves :math:`\min_{w\in\{0,1\}^{n_S}} \Psi(C(w))` subject to design constraints, where
:math:`C` is the second-order or Gauss-Newton covariance and :math:`\Psi` the A-, D- or
E-criterion.  Front door: :func:`select_sensors_from_information`; see :mod:`oed.design`.
"""
from .criteria import Criterion, CriteriaSettings, batch_criteria, criterion_value, validate_information
from .design import (DesignResult, DesignRow, DesignSettings, DesignTable, design_table, select_sensors,
                     select_sensors_from_information)

__all__ = ["Criterion", "CriteriaSettings", "batch_criteria", "criterion_value", "validate_information",
           "DesignResult", "DesignRow", "DesignSettings", "DesignTable", "design_table", "select_sensors",
           "select_sensors_from_information"]
from .discrimination import DiscriminationResult, select_discriminating  # noqa: E402  (issue 13, item 5)
__all__ += ["DiscriminationResult", "select_discriminating"]
