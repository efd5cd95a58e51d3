"""Identification: measurements, the full-space estimator, covariances, confidence regions."""
from identification.errors import (ConvergenceError, DataError, IdentifiabilityError, IdentificationError, NotBoundedError,
                     StateSolveError)
from identification.fit.measurements import Measurements
from identification.fit.dynamic_data import DynamicMeasurements
from identification.fit.dynamic_fit import DiscretisationSettings
from identification.fit.problem import Problem, information_contributions
from identification.fit.estimator import IdentifySettings, covariance_from_terms
from identification.inference.results import identify
from identification.fit.ipopt_solver import IpoptSettings
from identification.inference.regions import Ellipsoid, alpha_min, alpha_min_two_sample, in_region, mahalanobis2, CovarianceError
from identification.inference.results import Estimate
from models.state import simulate, solve_state, solve_states
from identification.studies.splits import Split, SplitError, input_range_split, random_splits, series_split, splits_from_scenarios
from identification.studies.detect import DetectionResult, DetectSettings, NormalityError, detect, normality_check
from identification.studies.model_error import ModelErrorResult, model_error
from identification.studies.model_ranking import ModelRanking, rank_models
from identification.studies.montecarlo import (MonteCarloResult, MonteCarloSettings, clopper_pearson, linearized_size, power_study,
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
    "ModelErrorResult", "model_error", "ModelRanking", "rank_models",
    "DynamicMeasurements", "DiscretisationSettings", "Problem",
]
