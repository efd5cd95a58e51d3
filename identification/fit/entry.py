"""The fit floor's entry points, for a static model E(y, p, q) = 0 or a dynamic one dx/dt = f(x, p, u).

A static model goes to :mod:`identification.fit.estimator`; a dynamic one (:meth:`models.Model.ode`,
:class:`models.dynamic.DynamicModel`) to :mod:`identification.fit.dynamic_fit` (collocation with the
discretisation error controlled), which fits its collocated static model with the estimator.
"""
from __future__ import annotations

from identification.fit.dynamic_fit import dynamic_information, identify_dynamic
from identification.fit.estimator import IdentifySettings, fit_static, static_information
from identification.fit.record import FitRecord

__all__ = ["fit_model", "information_contributions"]


def fit_model(model, data, p0, weights=None, settings: IdentifySettings | None = None, Y0=None,
              discretisation=None) -> FitRecord:
    """min_p 0.5 sum_ijk w_k ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2 s.t. E(y_j, p, q_j) = 0 (paper eq. 3),
    with the second-order covariance (eq. 7): :func:`identification.fit.estimator.fit_static` for a static
    model, :func:`identification.fit.dynamic_fit.identify_dynamic` for a dynamic one (``Y0`` must then be None;
    ``discretisation`` a :class:`identification.fit.dynamic_fit.DiscretisationSettings`, dynamic models only).
    """
    if getattr(model, "is_dynamic", False):    # an ODE/DAE model: collocation with error control
        if Y0 is not None:
            raise TypeError("Y0: not used for a dynamic model (its trajectories start from an integration at p0)")
        return identify_dynamic(model, data, p0, weights=weights, settings=settings, discretisation=discretisation)
    if discretisation is not None:
        raise TypeError("discretisation: only for a dynamic model")
    return fit_static(model, data, p0, weights=weights, settings=settings, Y0=Y0)


def information_contributions(model, data, p, states=None, *, inputs=None, sigma=None, n_series=1, times=None):
    """Per-sensor information F_k = sum_j c_jk G_jk^T G_jk / sigma_k^2 and second-order terms S_k at p
    (see :func:`identification.fit.estimator.static_information`); a dynamic model takes ``times``
    (sampling times) and returns one matrix per (sensor, time) pair
    (:func:`identification.fit.dynamic_fit.dynamic_information`).

    Returns
    -------
    F, S : ndarray (n_S, n_p, n_p)
    """
    if getattr(model, "is_dynamic", False):
        if states is not None:
            raise TypeError("states: not used for a dynamic model")
        return dynamic_information(model, data, p, inputs=inputs, times=times, sigma=sigma, n_series=n_series)
    if times is not None:
        raise TypeError("times: only for a dynamic model")
    return static_information(model, data, p, states, inputs=inputs, sigma=sigma, n_series=n_series)
