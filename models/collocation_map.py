"""Deprecated: the mapped outputs and sensitivities of a collocated ODE moved to :mod:`models.trajectory` (the one
element marcher); this module re-exports them with a DeprecationWarning for one release."""
from __future__ import annotations

import warnings

from .trajectory import mapped_outputs, output_sensitivity_function, outputs_and_sensitivities

__all__ = ["output_sensitivity_function", "mapped_outputs", "outputs_and_sensitivities"]

warnings.warn("models.collocation_map is deprecated: import output_sensitivity_function, mapped_outputs and "
              "outputs_and_sensitivities from models.trajectory", DeprecationWarning, stacklevel=2)
