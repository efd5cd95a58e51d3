"""identify: the fit of the problem (:meth:`identification.fit.problem.Problem.fit`) returned as the Estimate users get."""
from __future__ import annotations

from identification.fit.estimator import IdentifySettings
from identification.fit.problem import Problem
from identification.inference.results import Estimate

__all__ = ["identify"]


def identify(model, data, p0, weights=None, settings: IdentifySettings | None = None, Y0=None,
             discretisation=None, *, starts: int = 1, seed=0, workers: int | None = 1, scheduler=None) -> Estimate:
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
    starts : int >= 1                       fits from p0 and ``starts - 1`` further starts drawn in the bounds
                                            (:mod:`identification.fit.multistart`); the best local minimum is
                                            returned, every start in ``est.diagnostics.starts`` and a note of
                                            summary(); 1 (default): the single fit from p0
    seed : int >= 0, numpy SeedSequence or None   draws the further starts (None: fresh entropy, recorded)
    workers : int or None                   local processes for the starts (1: serially here; None: every core)
    scheduler : Dask address or distributed.Client, optional   run the starts there (``workers`` ignored)

    Returns
    -------
    Estimate
    """
    problem = Problem(model, data, discretisation)
    return Estimate.from_record(problem.fit(p0, weights=weights, settings=settings, Y0=Y0, starts=starts, seed=seed,
                                            workers=workers, scheduler=scheduler))
