r"""Monte Carlo validation (size study) of Algorithm 1 on a dynamic model and its time series.

The campaign is fitted once (:func:`identification.fit.dynamic_fit.identify_dynamic`: Radau IIA collocation
with the discretisation error controlled at p̂); the size study then runs on that collocated model
(``est.model``, a static model over the (sensor, time) outputs) with its flat data, as
:func:`identification.studies.dynamic_detect.detect_dynamic` tests on it:

.. math::

    z^{(r)}_{ijk} = h_{k}(y_j(p^*), p^*, q_j) + \sigma_k \varepsilon^{(r)}_{ijk},\qquad k = (l, t),

every experiment simulated at every sampling time of the campaign (the union of the experiments' times).
Splits by experiment (:class:`Split`) apply to the rows; splits by time window or early against late
(:class:`identification.studies.dynamic_detect.DynamicSplit`) become splits of the (sensor, time) columns
(:func:`identification.studies.dynamic_detect.flat_split`); :class:`Split` objects with sensor columns
(:func:`identification.studies.splits.time_window_split`) are used as they are.

The study itself is :func:`identification.studies.montecarlo.validate` (its size study on the flat
campaign this module prepares, :func:`dynamic_size_study`); this module does not import it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.fit.dynamic_data import DynamicMeasurements
from identification.studies.dynamic_detect import flat_split
from identification.fit.dynamic_fit import DiscretisationSettings
from identification.inference.identify import identify
from identification.errors import DataError

__all__ = ["FlatSizeStudy", "dynamic_size_study"]


@dataclass(frozen=True, eq=False)
class FlatSizeStudy:
    """The size study of a dynamic model as a static one: the arguments of
    :func:`identification.studies.montecarlo.size_study`.

    Attributes
    ----------
    model : Model                  the collocated model at the campaign fit (outputs (sensor, time))
    p_true : ndarray (n_p,)        truth of the simulated campaigns
    inputs : ndarray (n_q, d_q)    the experiments' inputs
    sigma : ndarray (n_S,)         sigma per (sensor, time) output
    splits : tuple of Split        the splits on the flat outputs
    p0 : array_like or None        start values of every replication (None: p_true)
    weights : ndarray or None      weight per (sensor, time) output
    name : str                     the model's label in tables
    """

    model: object
    p_true: np.ndarray
    inputs: np.ndarray
    sigma: np.ndarray
    splits: tuple
    p0: object
    weights: object
    name: str


def dynamic_size_study(model, data, splits, p0=None, *, p_true=None, weights=None, identify_settings=None,
                       name: str | None = None, discretisation: DiscretisationSettings | None = None) -> FlatSizeStudy:
    """The size study of a dynamic model on its collocation at the campaign fit (see the module docstring).

    Parameters
    ----------
    model : models.dynamic.DynamicModel
    data : DynamicMeasurements          the campaign (known sigma): inputs, sampling times, mesh
    splits : sequence of Split or DynamicSplit
    p0 : array_like (n_p,), optional     start values of the campaign fit and of every replication
                                         (default ``p_true``)
    p_true : array_like (n_p,), optional truth of the simulated campaigns (default: the campaign fit p̂)
    weights : array_like (n_S,), optional  instrument weights (each instrument at every sampling time)
    identify_settings : IdentifySettings, optional   settings of the campaign fit
    name : str, optional                 the model's label in tables
    discretisation : DiscretisationSettings, optional

    Returns
    -------
    FlatSizeStudy
    """
    if not isinstance(data, DynamicMeasurements):
        raise DataError(f"data: validate on a dynamic model needs the campaign as identification."
                        f"DynamicMeasurements (inputs, sampling times, sigma), got {type(data).__name__}")
    if data.sigma is None:
        raise DataError("data.sigma: a size study simulates noise of known sigma; give sigma with the data")
    start = p0 if p0 is not None else p_true
    if start is None:
        raise DataError("p0, p_true: give start values (p0) or the truth (p_true) of the dynamic model")
    w = None
    if weights is not None:
        w = np.asarray(weights, float).ravel()
        if w.shape != (model.n_S,):
            raise DataError(f"weights: expected {model.n_S} instrument weights ({', '.join(model.sensors)}), got "
                            f"shape {w.shape}")
    est = identify(model, data, start, weights=w, settings=identify_settings, discretisation=discretisation)
    cm, flat = est.model, est.data
    flat_splits = tuple(flat_split(sp, cm.outputs, flat.n_q) for sp in splits)
    w_flat = None if w is None else np.array([w[model.sensors.index(s)] for s, _ in cm.outputs])
    truth = est.p if p_true is None else np.asarray(p_true, float).ravel()
    return FlatSizeStudy(cm, truth, flat.inputs, flat.sigma, flat_splits, p0, w_flat, name or model.name)
