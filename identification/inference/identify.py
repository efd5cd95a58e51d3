"""identify: the fit of the problem (:meth:`identification.fit.problem.Problem.fit`) returned as the Estimate users get."""
from __future__ import annotations

from identification.fit.estimator import IdentifySettings
from identification.fit.problem import Problem
from identification.inference.results import Estimate

__all__ = ["identify"]


def identify(model, data, p0, weights=None, settings: IdentifySettings | None = None, Y0=None,
             discretisation=None) -> Estimate:
    """Weighted nonlinear least squares in full space (paper eq. 3), with covariance (eq. 7):
    min_p 0.5 sum_ijk w_k ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2 subject to E(y_j, p, q_j) = 0.

    The numbers are those of :meth:`identification.fit.problem.Problem.fit` on
    ``Problem(model, data, discretisation)`` (see :func:`identification.fit.estimator.fit_static` for
    the parameters, the pipeline and the errors raised; a dynamic model is collocated with its
    discretisation error controlled, :func:`identification.fit.dynamic_fit.identify_dynamic`); the
    result is an :class:`Estimate`, which adds the intervals (:meth:`Estimate.conf_int`), the
    ellipsoid, the curvature and :meth:`Estimate.summary`.

    Parameters
    ----------
    model : models.Model (static, or dynamic with DynamicMeasurements)
    data : Measurements or DynamicMeasurements
    p0 : array_like (n_p,)       start values (inside the bounds), in the parameters' units
    weights : array_like (n_S,), optional   sensor weights (0/1 selects sensors)
    settings : IdentifySettings, optional
    Y0 : array (n_q, n_y), optional         initial guess of the states (static models)
    discretisation : DiscretisationSettings, optional   collocation settings (dynamic models)

    Returns
    -------
    Estimate
    """
    problem = Problem(model, data, discretisation)
    return Estimate.from_record(problem.fit(p0, weights=weights, settings=settings, Y0=Y0))
