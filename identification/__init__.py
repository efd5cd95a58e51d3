"""Identification: measurements, the full-space estimator, covariances, confidence regions."""
from .errors import DataError, IdentifiabilityError, IdentificationError, StateSolveError
from .measurements import Measurements
from .estimator import IdentifySettings, identify, information_contributions, covariance_from_terms
from .ipopt_solver import IpoptSettings
from .regions import Ellipsoid, alpha_min, alpha_min_two_sample, in_region, mahalanobis2, CovarianceError
from .results import Estimate
from .state import simulate, solve_state, solve_states

__all__ = [
    "DataError", "IdentifiabilityError", "IdentificationError", "StateSolveError", "Measurements",
    "IdentifySettings", "IpoptSettings", "identify", "information_contributions", "covariance_from_terms",
    "Ellipsoid", "alpha_min", "alpha_min_two_sample", "in_region", "mahalanobis2", "CovarianceError",
    "Estimate", "simulate", "solve_state", "solve_states",
]
