r"""mudoe: model uncertainty via optimal design of experiments -- the front door (``import mudoe``).

Fit a model h(y, p, q) with E(y, p, q) = 0 to repeated measurements (weighted least squares,
:math:`\min_p \tfrac12\sum_{ijk} w_k ((z_{ijk} - h_k(y_j, p, q_j)) / \sigma_k)^2`), design
experiments (:math:`\min_w \Psi(C(w))`) and test the model (Algorithm 1), with one import::

    import mudoe
    model = mudoe.Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"], h=...)
    est = mudoe.identify(model, mudoe.Measurements(inputs=x, z=z, sigma=None), p0=[500, 1e-4])
    print(est.summary())

The names below are re-exported from the packages that define them (:mod:`models`, :mod:`identification`,
:mod:`oed` and mudoe's own modules), which stay importable as before; they are resolved lazily on first
use (PEP 562), so that ``import mudoe`` and the command line (``python -m mudoe``) import nothing more
than they need.  Every result class has ``summary()``, ``to_frame()``, ``to_dict()`` and ``_repr_html_``
(:mod:`identification.results_protocol`).
"""
from __future__ import annotations

import importlib

#: public name -> the module it is imported from (a package's facade where it has one)
_EXPORTS = {
    # models
    "Model": "models", "Parameter": "models", "ModelError": "models", "build_model": "models",
    "load_toml": "models", "press_model": "models",
    # data
    "Measurements": "identification", "DynamicMeasurements": "identification",
    "read_long_csv": "mudoe.kind.long_csv", "write_long_csv": "mudoe.kind.long_csv",
    "write_paper_layout": "mudoe.data_io", "read_paper_layout": "mudoe.data_io",
    # identification
    "identify": "identification", "Problem": "identification", "IdentifySettings": "identification",
    "IpoptSettings": "identification", "information": "oed",
    "information_contributions": "identification", "simulate": "identification",
    "solve_states": "identification", "DiscretisationSettings": "identification",
    "predict": "identification.fit.dynamic_fit", "simulate_campaign": "identification.fit.dynamic_fit",
    "lr_region": "identification.inference.likelihood_region",
    # studies: Algorithm 1, Monte Carlo, model error
    "detect": "identification", "DetectSettings": "identification", "normality_check": "identification",
    "bootstrap_detect": "identification.studies.detect_bootstrap",
    "validate": "identification", "size_study": "identification", "power_study": "identification",
    "MonteCarloSettings": "identification", "linearized_size": "identification",
    "model_error": "identification", "rank_models": "identification",
    "Split": "identification", "random_splits": "identification", "series_split": "identification",
    "input_range_split": "identification", "splits_from_scenarios": "identification",
    "time_window_split": "identification.studies.splits", "early_late_split": "identification.studies.splits",
    # design of experiments
    "select_sensors": "oed", "select_sensors_from_information": "oed", "design_table": "oed",
    "select_times": "oed", "select_inputs": "oed", "select_discriminating": "oed",
    "approximate_design": "oed", "design_efficiencies": "oed", "make_prior": "oed",
    "sequential_design": "oed.sequential", "select_robust_exact": "oed.robust_exact",
    "select_error_design": "oed",
    "DesignSettings": "oed", "CriteriaSettings": "oed", "ApproximateSettings": "oed", "RefineSettings": "oed",
    "Prior": "oed",
    # results (the result protocol: summary, to_frame, to_dict, _repr_html_)
    "ResultProtocol": "identification.results_protocol",
    "Estimate": "identification", "ConfidenceIntervals": "identification.inference.intervals",
    "Ellipsoid": "identification", "NormalityCheck": "identification.studies.normality",
    "DetectionResult": "identification", "BootstrapDetection": "identification.studies.detect_bootstrap",
    "MonteCarloResult": "identification", "ModelErrorResult": "identification",
    "ModelRanking": "identification",
    "DesignResult": "oed", "DesignTable": "oed", "InputDesignResult": "oed", "RefinedInputs": "oed",
    "DiscriminationResult": "oed", "ApproximateDesign": "oed", "SequentialResult": "oed.sequential",
    "RobustExactDesign": "oed.robust_exact", "ErrorDesignResult": "oed",
    "PlannedDesign": "oed.plan_records", "RobustPlan": "oed.plan_records", "RobustExactPlan": "oed.plan_records",
    "DiscriminationPlan": "oed.plan_records", "DynamicDesign": "oed.plan_records",
    # errors
    "IdentificationError": "identification", "DataError": "identification", "ConvergenceError": "identification",
    "NotBoundedError": "identification", "IdentifiabilityError": "identification",
    "StateSolveError": "identification",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    """``mudoe.<name>``: import the module that defines a public name on first use (PEP 562)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'mudoe' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value                      # later look-ups skip __getattr__
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(__all__))
