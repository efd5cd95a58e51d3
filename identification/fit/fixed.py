r"""A model with some parameters fixed: the fixed values become input columns.

For a model E(y, p, q) = 0, z ~ h(y, p, q) and a set F of parameter indices, the derived model
has the free parameters p_R (the others, in model order) and the inputs q' = (q, c), c the
values of p_F:

.. math::

    E'(y, p_R, (q, c)) = E(y, P(p_R, c), q),\qquad h'(y, p_R, (q, c)) = h(y, P(p_R, c), q),

with P(p_R, c) the full parameter vector (p_R at the free positions, c at the fixed ones).  E'
and h' are the model's own CasADi expressions with the symbols of p_F replaced by those of c,
so values agree to the last bit and derivatives are exact (CasADi AD of the same graph).

A constrained fit min over p_R of Phi(P(p_R, c)) (a profile point) is then an ordinary fit of
the derived model to data whose input rows carry c; fits with different fixed values are fits
of one model to different inputs: a batch for :func:`identification.fit.batch.fit_batch` with
per-member inputs (:func:`fixed_batch`: K fits cost K n_q row evaluations per sweep; stacking
the rows of all members as common inputs instead cost K^2 n_q and was 4-20x slower than
separate fits, bench/RESULTS.md).
"""
from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from models.contract import Model
from identification.fit.batch_data import BatchData
from identification.errors import DataError

__all__ = ["fixed_model", "full_parameters", "fixed_batch"]


def _fixed_indices(model: Model, fixed) -> tuple:
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    idx = [int(k) for k in np.atleast_1d(np.asarray(fixed, int))]
    if not idx or len(set(idx)) != len(idx) or any(not 0 <= k < model.n_p for k in idx):
        raise ValueError(f"fixed: expected distinct parameter indices in 0..{model.n_p - 1}, got {fixed!r}")
    if len(idx) >= model.n_p:
        raise ValueError(f"fixed: at least one parameter must stay free (the model has {model.n_p}), got {fixed!r}")
    return tuple(idx)


def full_parameters(n_p: int, fixed: Sequence[int], p_free, values):
    """P(p_R, c): the full parameter vector (NumPy arrays, or CasADi column vectors)."""
    fixed = list(fixed)
    free = [k for k in range(n_p) if k not in fixed]
    if isinstance(p_free, (ca.SX, ca.MX)) or isinstance(values, (ca.SX, ca.MX)):
        parts = [None] * n_p
        for a, k in enumerate(free):
            parts[k] = p_free[a]
        for a, k in enumerate(fixed):
            parts[k] = values[a]
        return ca.vertcat(*parts)
    p = np.empty(np.broadcast_shapes(np.shape(p_free)[:-1], np.shape(values)[:-1]) + (n_p,))
    p[..., free] = p_free
    p[..., fixed] = values
    return p


class _Guess:
    """y_guess of the derived model: the model's guess at (P(p_R, c), q) (picklable)."""

    def __init__(self, model: Model, fixed: tuple):
        self.model, self.fixed = model, fixed

    def __call__(self, p_free, qc):
        d = self.model.n_q_dim
        return self.model.y_guess(full_parameters(self.model.n_p, self.fixed, p_free, qc[d:]), qc[:d])


class _Derived:
    """E' or h' of the derived model (picklable: the model's function and the fixed indices)."""

    def __init__(self, fun: ca.Function, n_p: int, d_q: int, fixed: tuple):
        self.fun, self.n_p, self.d_q, self.fixed = fun, n_p, d_q, fixed

    def __call__(self, y, p_free, qc):
        return self.fun(y, full_parameters(self.n_p, self.fixed, p_free, qc[self.d_q:]), qc[:self.d_q])


def fixed_model(model: Model, fixed) -> Model:
    """The derived model with the parameters ``fixed`` (indices) moved to extra input columns.

    Parameters
    ----------
    model : Model
    fixed : int or sequence of int   indices of the fixed parameters (at least one stays free)

    Returns
    -------
    Model
        Parameters: the free ones (names and bounds of ``model``, model order); inputs: the
        model's, then one column per fixed parameter named ``"<name> (fixed)"``; sensors,
        states, symbolic type and state guess as ``model``.  Kept in ``model.cache`` (one per
        set of fixed indices), so repeated calls share the built (and compiled) functions.
    """
    idx = _fixed_indices(model, fixed)
    got = model.cache.get("fixed.model", idx)
    if got is not None:
        return got
    free = [k for k in range(model.n_p) if k not in idx]
    d = model.n_q_dim
    derived = Model([model.params[k] for k in free],
                    tuple(model.inputs) + tuple(f"{model.param_names[k]} (fixed)" for k in idx),
                    model.sensors, model.n_y,
                    _Derived(model.E_fun, model.n_p, d, idx) if model.n_y else None,
                    _Derived(model.h_fun, model.n_p, d, idx),
                    y_guess=_Guess(model, idx) if model.has_y_guess else None, symbolic=model.symbolic,
                    name=f"{model.name} with {', '.join(model.param_names[k] for k in idx)} fixed",
                    sensor_units=model.sensor_units,
                    input_units=tuple(model.input_units) + ("",) * len(idx), description=model.description)
    return model.cache.put("fixed.model", idx, derived)


def _checked(inputs, z, values) -> tuple:
    q = np.asarray(inputs, float)
    z = np.asarray(z, float)
    c = np.atleast_2d(np.asarray(values, float))
    if q.ndim != 2 or z.ndim != 3 or z.shape[1] != q.shape[0]:
        raise DataError(f"z, inputs: expected z (n_M, n_q, n_S) and inputs (n_q, d_q), got {z.shape} and {q.shape}")
    if c.ndim != 2 or not np.all(np.isfinite(c)):
        raise DataError(f"values: expected finite fixed values of shape (R, n_F), got shape {c.shape}")
    return q, z, c


def fixed_batch(inputs, z, sigma, values) -> BatchData:
    """The data of R fits of a derived model (:func:`fixed_model`), one per row of ``values``, as a
    batch with per-member inputs: member r has the rows (q_j, c_r) and the data ``z``.

    Parameters
    ----------
    inputs : ndarray (n_q, d_q)
    z : ndarray (n_M, n_q, n_S)      the data (NaN: missing)
    sigma : ndarray (n_S,)           the sensors' sigmas of the objective
    values : ndarray (R, n_F)        the fixed values of every member
    """
    q, z, c = _checked(inputs, z, values)
    R, n_q = c.shape[0], q.shape[0]
    rows = np.concatenate([np.broadcast_to(q, (R,) + q.shape), np.broadcast_to(c[:, None, :], (R, n_q, c.shape[1]))],
                          axis=2)
    sig = np.tile(np.asarray(sigma, float), (R, 1))
    return BatchData(rows, np.broadcast_to(z, (R,) + z.shape), sig)
