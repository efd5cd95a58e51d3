"""Validation, start point and scalings of one weighted least-squares fit (step 1 of
:func:`identification.fit.estimator.fit_static`).

The start: the validated data and weights, the sigmas of the objective (a common spread when
sigma is unknown), the states at p0 (cached per p0 and inputs), the scalings of parameters s_p,
states s_y and equations e, the Gauss-Newton predictor of Ipopt's start point and the
reduced-space problem (:class:`identification.fit.refinement.ReducedProblem`) shared by all steps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps

from models.blow_up import blow_up_of
from models.contract import Model
from models.sensitivity import sensitivities
from models.state import BATCH_START_MIN, numerics, solve_states
from identification.errors import BadStartError, DataError, IdentificationError, StateSolveError
from identification.fit import newton as newton_core
from identification.fit.implicit_start import START_CACHE_SIZE, solve_states_from
from identification.fit.measurements import Measurements, common_spread
from identification.fit.refinement import ReducedProblem

__all__ = ["Start", "make_start", "scalings", "predictor", "as_start_vector", "checked_start", "param_scale",
           "decrement_unit", "initial_states"]


# ---------------------------------------------------------------------------- validation
def checked_start(model, p0) -> np.ndarray:
    """p0 as a float vector (n_p,) (:func:`as_start_vector`), finite and within every parameter's bounds
    [lower, upper] (model units); a DataError names the parameter otherwise."""
    p0 = as_start_vector(model, p0)
    for i, par in enumerate(model.params):
        if not math.isfinite(p0[i]):
            raise DataError(f"p0: start value of {par.name!r} is not finite ({p0[i]})")
        if p0[i] < par.lower or p0[i] > par.upper:
            raise DataError(f"p0: start value {p0[i]:g} of {par.name!r} lies outside its bounds "
                            f"[{par.lower:g}, {par.upper:g}]")
    return p0


def _validate(model, data, p0, weights):
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    if not isinstance(data, Measurements):
        raise TypeError(f"data: expected an identification.Measurements, got {type(data).__name__}")
    if data.d_q != model.n_q_dim:
        raise DataError(f"data.inputs: has {data.d_q} columns but model {model.name!r} has inputs "
                        f"({', '.join(model.inputs)})")
    if data.n_S != model.n_S:
        raise DataError(f"data.z: has {data.n_S} sensors but model {model.name!r} has {model.n_S} "
                        f"({', '.join(model.sensors)}); use data.select([...]) to match")
    default_names = tuple(f"s{k + 1}" for k in range(data.n_S))
    if data.sensors != default_names and data.sensors != model.sensors:
        raise DataError(f"data.sensors {list(data.sensors)} do not match the model's sensors "
                        f"{list(model.sensors)}; use data.select(model.sensors)")
    p0 = checked_start(model, p0)
    w = data.sensor_weights(weights)
    if not np.any(w > 0):
        raise DataError("weights: no sensor is selected (all weights are zero)")
    n = data.n_data(w)
    if n < model.n_p:
        raise DataError(f"data: only {n} usable values in the selected sensors for {model.n_p} parameters; "
                        "need at least as many values as parameters")
    if data.sigma is None and n <= model.n_p:
        raise DataError(f"data: sigma is unknown and n = {n} values leave no degree of freedom to estimate it "
                        f"for {model.n_p} parameters; give sigma or more data")
    return p0, w, n


#: entries kept per model of each start-point cache in ``model.cache`` (repeated fits of new data)
_START_CACHE_SIZE = START_CACHE_SIZE


def initial_states(model, p0, inputs, Y0=None) -> np.ndarray:
    """States y_j solving E(y_j, p0, q_j) = 0 at the start values, shape (n_q, n_y) (kept in ``model.cache`` per
    p0 and inputs: repeated fits of new data).  A model solved in the reduced space (a collocated ODE) marches
    its trajectories (:meth:`models.trajectory.TrajectoryNumerics.states`): the same states, bit for bit, as
    the reduced-space iteration's own solve at p0, which then reuses them.  ``Y0``: a guess (not cached)."""
    if Y0 is not None:
        return solve_states(model, p0, inputs, Y0=Y0)
    key = (p0.tobytes(), inputs.tobytes())
    Y = model.cache.get("identify.initial_states", key)
    if Y is not None:
        return Y
    if (numerics(model).dense and inputs.shape[0] >= BATCH_START_MIN
            and not model.state_numerics.reduced_space):
        # all inputs at once from the model's guesses (faster than solve_states' batched start;
        # the same damped Newton); solve_states is the fallback
        guess = (np.array([model.y_guess(p0, q) for q in inputs]) if model.has_y_guess
                 else np.zeros((inputs.shape[0], model.n_y)))
        try:
            Y = solve_states_from(model, p0, inputs, guess)
        except StateSolveError:
            Y = None
    if Y is None:
        Y = solve_states(model, p0, inputs)
    Y.setflags(write=False)
    model.cache.put("identify.initial_states", key, Y, maxsize=_START_CACHE_SIZE)
    return Y


def scalings(model, p0, inputs, Y_init, cacheable):
    """(s_y, e_scale) at the start; kept in ``model.cache`` per (p0, inputs) when Y_init is the
    cached state solve at p0 (repeated fits of new data, as in Monte Carlo studies and splits)."""
    key = (p0.tobytes(), inputs.tobytes()) if cacheable else None
    hit = model.cache.get("identify.scalings", key) if key is not None else None
    if hit is None:
        s_y = _state_scale(Y_init)
        hit = (s_y, _equation_scale(model, p0, inputs, Y_init, s_y))
        for a in hit:
            a.setflags(write=False)
        if key is not None:
            model.cache.put("identify.scalings", key, hit, maxsize=_START_CACHE_SIZE)
    return hit


def predictor(model, p0, inputs, Y0, zbar, cw, sig, s_p, max_step):
    """Start point of Ipopt: one Gauss-Newton step from p0 on the model linearised at p0.

    p1 = p0 + (G^T W G)^{-1} G^T W (zbar - h(p0)) and y_j(p1) ~ y_j(p0) + y_j'(p0)(p1 - p0),
    with G, h, y' at p0 kept in ``model.cache`` per (p0, inputs) (they do not depend on the
    data, so repeated fits of new data pay one einsum).  The step is taken only when it moves
    every scaled parameter by at most ``max_step`` and stays inside the bounds; otherwise
    Ipopt starts at p0 as before.  It only changes where Ipopt starts, not the problem solved.
    """
    if max_step <= 0 or not model.n_y or not numerics(model).dense:
        return p0, Y0
    key = (p0.tobytes(), inputs.tobytes(), Y0.tobytes())
    hit = model.cache.get("identify.start_sensitivities", key)
    if hit is None:
        sens = sensitivities(model, p0, inputs, Y0)
        hit = (sens.h, sens.G, sens.state_derivatives)
        model.cache.put("identify.start_sensitivities", key, hit, maxsize=_START_CACHE_SIZE)
    h0, G, yp = hit
    wts = cw / sig[None, :] ** 2
    A = np.einsum("jk,jkp,jkr->pr", wts, G, G) * np.outer(s_p, s_p)
    b = np.einsum("jk,jk,jkp->p", wts, zbar - h0, G) * s_p
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return p0, Y0
    d = np.linalg.solve(L.T, np.linalg.solve(L, b))
    if not np.all(np.isfinite(d)) or np.max(np.abs(d)) > max_step:
        return p0, Y0
    p1 = p0 + d * s_p
    if np.any(p1 <= model.lower) or np.any(p1 >= model.upper):
        return p0, Y0
    return p1, Y0 + np.einsum("jyp,p->jy", yp, p1 - p0)


def as_start_vector(model, p0) -> np.ndarray:
    """``p0`` as a float vector of the model's n_p start values; DataError naming ``p0`` otherwise."""
    try:
        p0 = np.asarray(p0, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError(f"p0: not numeric: {p0!r}") from None
    if p0.shape != (model.n_p,):
        raise DataError(f"p0: expected {model.n_p} values ({', '.join(model.param_names)}), got {p0.size}")
    return p0


def param_scale(model, p0) -> np.ndarray:
    """Parameter scales s_p: the declared scale, else |p0|, else the bound range, else 1."""
    s = np.empty(model.n_p)
    for i, par in enumerate(model.params):
        if par.scale is not None:
            s[i] = par.scale
        elif p0[i] != 0:
            s[i] = abs(p0[i])
        elif math.isfinite(par.lower) and math.isfinite(par.upper) and par.upper > par.lower:
            s[i] = par.upper - par.lower
        else:
            s[i] = 1.0
    return s


def _state_scale(Y):
    if Y.size == 0:
        return np.ones(Y.shape[1])
    s = np.abs(Y).max(axis=0)
    top = s.max() if s.size else 0.0
    floor = top * 1e-6 if top > 0 else 1.0
    return np.where(s > floor, s, floor)


def _equation_scale(model, p0, inputs, Y, s_y):
    """1 / max_j max_i |dE_r/dy_i (y_j, p0, q_j)| s_y,i per equation r (1 where a row is zero)."""
    if not model.n_y:
        return np.ones(0)
    num = numerics(model)
    if num.dense:
        Ey = num.batched("E_y", inputs.shape[0])(Y, p0, inputs)[1]
        rowmax = np.abs(Ey * s_y[None, None, :]).max(axis=(0, 2))
    else:
        rowmax = np.zeros(model.n_y)
        for j in range(inputs.shape[0]):
            Ey = num.point("E_y")(Y[j], p0, inputs[j])[1]
            Ey = abs(sps.csr_matrix(Ey) @ sps.diags(s_y))
            rowmax = np.maximum(rowmax, Ey.max(axis=1).toarray().ravel())
    return np.where(rowmax > 0, 1.0 / np.where(rowmax > 0, rowmax, 1.0), 1.0)



@dataclass(frozen=True)
class Start:
    """The validated problem of one identification and its start point.

    ``w`` sensor weights, ``n`` usable values, ``selected`` sensors with w > 0, ``sig`` the
    sigmas used in the objective (a common spread when sigma is unknown), ``Y_init`` the
    states at p0, ``s_p``/``s_y``/``e_scale`` the scalings of parameters, states and
    equations, ``problem`` the reduced-space problem (data terms) shared by all steps.
    """

    model: Model
    data: Measurements
    p0: np.ndarray
    w: np.ndarray
    n: int
    selected: np.ndarray
    sig: np.ndarray
    Y_init: np.ndarray
    s_p: np.ndarray
    s_y: np.ndarray
    e_scale: np.ndarray
    problem: ReducedProblem


def make_start(model, data, p0, weights, Y0) -> Start:
    """Step 1 of :func:`identify`: validate, choose the sigmas, solve the start states, scale."""
    p0, w, n = _validate(model, data, p0, weights)
    selected = np.flatnonzero(w > 0)
    if data.sigma is None:
        sig = np.full(model.n_S, common_spread(data.z[:, :, selected]))
    else:
        sig = np.asarray(data.sigma, float)
    s_p = param_scale(model, p0)
    if not model.n_y:                       # explicit: no states to solve or scale
        Y_init, s_y, e_scale = np.zeros((data.n_q, 0)), np.ones(0), np.ones(0)
    else:
        try:
            Y_init = initial_states(model, p0, data.inputs, Y0)
        except StateSolveError as exc:
            if blow_up_of(exc) is not None:     # bad input, not a failed fit
                raise BadStartError(f"p0: the trajectory blows up at the start values: {exc}",
                                    status="state solve failed") from None
            raise IdentificationError(f"p0: the state equation cannot be solved at the start values: {exc}",
                                      status="state solve failed") from None
        # a collocated ODE is solved in the reduced space (no NLP): its scalings are made when Ipopt needs them
        s_y, e_scale = ((None, None) if model.state_numerics.reduced_space
                        else scalings(model, p0, data.inputs, Y_init, Y0 is None))
    return Start(model, data, p0, w, n, selected, sig, Y_init, s_p, s_y, e_scale,
                  ReducedProblem.of(model, data, w, sig, s_p))



def decrement_unit(st: Start, objective: float) -> float:
    """Objective units per chi^2 unit of the decrement: 1 with sigma known, else 2 Phi / (n - n_p)
    (the objective's sigma is a common spread; the standard errors use s^2 = RSS / (n - n_p))."""
    return newton_core.decrement_unit(objective, None if st.data.sigma is not None else st.n - st.model.n_p)
