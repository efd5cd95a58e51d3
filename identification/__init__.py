"""Identification: measurements, the full-space estimator, covariances, confidence regions."""
from .errors import (ConvergenceError, DataError, IdentifiabilityError, IdentificationError, NotBoundedError,
                     StateSolveError)
from .measurements import Measurements
from .dynamic_data import DynamicMeasurements
from .estimator import IdentifySettings, identify, information_contributions, covariance_from_terms
from .ipopt_solver import IpoptSettings
from .regions import Ellipsoid, alpha_min, alpha_min_two_sample, in_region, mahalanobis2, CovarianceError
from .results import Estimate
from models.state import simulate, solve_state, solve_states
from .splits import Split, SplitError, input_range_split, random_splits, series_split, splits_from_scenarios
from .detect import DetectionResult, DetectSettings, NormalityError, detect, normality_check
from .montecarlo import (MonteCarloResult, MonteCarloSettings, clopper_pearson, linearized_size, power_study,
                         size_study, validate)

__all__ = [
    "ConvergenceError", "DataError", "IdentifiabilityError", "IdentificationError", "NotBoundedError", "StateSolveError",
    "Measurements",
    "IdentifySettings", "IpoptSettings", "identify", "information_contributions", "covariance_from_terms",
    "Ellipsoid", "alpha_min", "alpha_min_two_sample", "in_region", "mahalanobis2", "CovarianceError",
    "Estimate", "simulate", "solve_state", "solve_states",
    "Split", "SplitError", "input_range_split", "random_splits", "series_split", "splits_from_scenarios",
    "DetectionResult", "DetectSettings", "NormalityError", "detect", "normality_check",
    "MonteCarloResult", "MonteCarloSettings", "clopper_pearson", "linearized_size", "power_study", "size_study",
    "validate",
    "DynamicMeasurements",
]
