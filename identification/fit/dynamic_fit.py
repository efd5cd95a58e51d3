r"""Identification of a dynamic model with discretisation error control.

The model is collocated on a mesh (:mod:`models.collocation`) and fitted as any static model
(:func:`identification.fit.estimator.fit_static`).  At the estimate p̂ the outputs at the sampling
times are recomputed on the mesh with every element halved; Radau IIA of degree d converges
with order 2d - 1 at element boundaries, so the difference

.. math::

    e_{jk} = \frac{2^o}{2^o - 1} |h_k^{N/2}(\hat p, q_j) - h_k^{N}(\hat p, q_j)| / \sigma_k,
    \qquad o = 2d - 1,

(Richardson) estimates the discretisation error of the fit's mesh N in units of each sensor's
sigma, and the linearised shift of the estimate were exact outputs used,
dp = (G^T W G)^{-1} G^T W \delta h with \delta h the error so estimated, in standard errors.
While max e > ``tol_sigma`` or max |dp / se| > ``tol_se`` the mesh is refined (each element
split into ceil(1.25 (error / tolerance)^{1/(2d-1)}) parts, 2..``max_factor``) and the fit
repeated from p̂.  The estimate records the mesh and the achieved error (``est.diagnostics.discretisation``, a
:class:`DiscretisationRecord`) and its summary says so, or says that the error could not be
bounded.

The fit on each mesh is the reduced-space iteration on the trajectories (a shooting method: the
trajectories are solved at every p), with Ipopt on the full-space NLP as its fallback, whose trajectories
start through the data (``IdentifySettings.init``, :mod:`identification.fit.data_start`).  A start with a
value on its bound (a rate of 0, moved into the interior) goes to the full-space NLP directly on the first
mesh, and the reduced-space iteration of a collocated ODE gives up at the first trial point where the
trajectories cannot be solved (the full-space NLP needs them consistent only at its solution).
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np

from models.collocation import Mesh, collocate, DEFAULT_ELEMENTS
from models.contract import ModelError
from models.dynamic import DynamicModel
from models.trajectory import interpolate_states, mapped_outputs, outputs_and_sensitivities
from identification.fit.dynamic_data import DynamicMeasurements
from identification.errors import DataError, IdentificationError, StateSolveError
from identification.fit.data_start import linear_outputs
from identification.fit.estimator import IdentifySettings, fit_static, static_information
from identification.fit.implicit_start import start_sensitivities
from identification.fit.start import as_start_vector, initial_states, param_scale

__all__ = ["DiscretisationSettings", "DiscretisationRecord", "identify_dynamic", "collocated_problem",
           "controlled_mesh", "dynamic_information", "predict", "simulate_campaign", "DegenerateStartWarning",
           "START_MARGIN"]

#: a start value on a bound is moved this far into the interior, in units of the parameter's scale
#: (its declared scale, else |p0|, else the bound range: identification.fit.start.param_scale)
START_MARGIN = 1e-3


class DegenerateStartWarning(RuntimeWarning):
    """The outputs do not depend on some parameters at the start values (their sensitivities are exactly
    zero: a degenerate trajectory, e.g. every rate 0); the fit may stall or fail from there."""


@dataclass(frozen=True)
class DiscretisationSettings:
    """Discretisation of a dynamic model in :func:`identify_dynamic`.

    Attributes
    ----------
    degree : int              Radau IIA points per element (order 2 degree - 1)
    elements : int            elements over the horizon of the first mesh (plus the sampling times
                              and control grid points as boundaries)
    tol_sigma : float         largest accepted output error at the sampling times, in sigmas (0.01: 1 %)
    tol_se : float            largest accepted linearised shift of the estimate, in standard errors
    max_refinements : int     refinements before the error counts as not bounded
    max_elements : int        largest mesh tried
    max_factor : int          largest split of an element in one refinement
    """

    degree: int = 3
    elements: int = DEFAULT_ELEMENTS
    tol_sigma: float = 0.01
    tol_se: float = 0.01
    max_refinements: int = 6
    max_elements: int = 4000
    max_factor: int = 8

    def __post_init__(self):
        for name in ("degree", "elements", "max_refinements", "max_elements", "max_factor"):
            v = getattr(self, name)
            least = 0 if name == "max_refinements" else 1
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
                raise ValueError(f"{name}: expected a positive integer, got {v!r}")
        if self.max_factor < 2:
            raise ValueError(f"max_factor: expected an integer >= 2, got {self.max_factor!r}")
        for name in ("tol_sigma", "tol_se"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a positive number, got {v!r}")


@dataclass(frozen=True)
class DiscretisationRecord:
    """The discretisation of a dynamic fit and its estimated error.

    Attributes
    ----------
    degree, n_elements : int
    boundaries : tuple of float       the mesh (time unit of the model)
    error_sigma : float               max over the data of the estimated output error / sigma at the estimate
    error_by_sensor : dict            the same per instrument
    shift_se : ndarray (n_p,)         linearised change of the estimate without discretisation error, in standard errors
    tol_sigma, tol_se : float
    bounded : bool                    both errors are within their tolerances
    history : tuple                   (n_elements, error_sigma, max |shift_se|) of every mesh fitted
    reason : str                      why the error is not bounded ("" when it is)
    """

    degree: int
    n_elements: int
    boundaries: tuple
    error_sigma: float
    error_by_sensor: dict
    shift_se: np.ndarray
    tol_sigma: float
    tol_se: float
    bounded: bool
    history: tuple
    reason: str = ""

    def note(self) -> str:
        """The line printed by ``Estimate.summary()``."""
        h = float(np.max(np.diff(self.boundaries)))
        shift = float(np.max(np.abs(self.shift_se))) if np.all(np.isfinite(self.shift_se)) else float("nan")
        if self.bounded:
            return (f"discretisation: Radau IIA collocation of degree {self.degree} on {self.n_elements} elements "
                    f"(longest {h:.3g}); its error, estimated against every element halved, is at most "
                    f"{100 * self.error_sigma:.2g} % of sigma in the outputs at the sampling times (tolerance "
                    f"{100 * self.tol_sigma:.2g} %) and {shift:.2g} standard errors in the estimate")
        return (f"discretisation error NOT bounded: {self.reason}; on {self.n_elements} elements (degree "
                f"{self.degree}) the error, estimated against every element halved, is {100 * self.error_sigma:.3g} "
                f"% of sigma in the outputs and {shift:.3g} standard errors in the estimate (tolerances "
                f"{100 * self.tol_sigma:.2g} % "
                f"and {self.tol_se:.2g}); the estimate and its verdicts may reflect the discretisation, not the model")


def _dynamic_data(model: DynamicModel, data) -> DynamicMeasurements:
    """The data checked against the model (sensor names set to the model's when left at the default); their
    type is the collocated strategy's (:meth:`identification.fit.problem.CollocatedStrategy.check`, run by
    every :class:`identification.fit.problem.Problem` of a dynamic model)."""
    if data.inputs.shape[1] != model.n_q_dim:
        raise DataError(f"data.inputs: has {data.inputs.shape[1]} columns but model {model.name!r} takes "
                        f"{model.n_q_dim} ({', '.join(model.inputs)}: the constants, then every control's values "
                        "at its grid points)")
    if data.n_S != model.n_S:
        raise DataError(f"data.z: has {data.n_S} sensors but model {model.name!r} has {model.n_S} "
                        f"({', '.join(model.sensors)})")
    if data.sensors != model.sensors:
        if data.sensors != tuple(f"s{k + 1}" for k in range(data.n_S)):
            raise DataError(f"data.sensors {list(data.sensors)} do not match the model's sensors "
                            f"{list(model.sensors)}")
        f = data.flat()
        data = DynamicMeasurements(data.inputs, data.times, data.z, data.sigma, model.sensors, f.input_names, f.series)
    try:
        model.check_times(data.union_times, "data.times")
    except ModelError as exc:
        raise DataError(str(exc)) from None
    return data


def collocated_problem(model: DynamicModel, data: DynamicMeasurements, mesh: Mesh | None = None,
                       degree: int = 3, elements: int = DEFAULT_ELEMENTS, p=None,
                       discretisation: DiscretisationSettings | None = None):
    """(collocated model, flat data) of a dynamic model and its data: the static problem that
    :func:`identification.identify`, ``detect`` and the design functions take.

    The mesh: ``mesh`` if given; else, with ``p`` (and known sigma), the mesh whose output error at p
    is within the discretisation tolerance (:func:`controlled_mesh`); else ``elements`` elements over
    the horizon plus every sampling time and control grid point."""
    data = _dynamic_data(model, data)
    t = data.union_times
    if mesh is None and p is not None:
        if data.sigma is None:
            raise DataError("data.sigma: a mesh controlled at p needs known sigmas; give mesh= or sigma")
        cm, _ = controlled_mesh(model, np.asarray(p, float), data.inputs, t, data.sigma, outputs=data.pairs,
                                discretisation=discretisation)
        return cm, data.flat()
    horizon = model.horizon if model.horizon is not None else float(t[-1])
    cm = collocate(model, t, mesh=mesh, degree=degree, max_step=horizon / elements, outputs=data.pairs)
    return cm, data.flat()


def _weights(data: DynamicMeasurements, weights):
    if weights is None:
        return None
    w = np.asarray(weights, float)
    if w.shape != (data.n_S,):
        raise DataError(f"weights: expected {data.n_S} instrument weights ({', '.join(data.sensors)}), got shape "
                        f"{w.shape}")
    return np.array([w[data.sensors.index(s)] for s, _ in data.pairs])


def _error(model, data, est, mesh, w):
    """(error per flat sensor in sigmas, max, linearised estimate shift in standard errors) of the
    fit ``est`` on ``mesh``: Richardson's estimate 2^o / (2^o - 1) (h^{N/2} - h^N) with the mesh
    halved, o = 2 d - 1 the order at the element boundaries.  h^{N/2} by one Newton step from the fit's trajectories
    interpolated onto the halved mesh (they are within the discretisation error of its solution, and Newton
    converges quadratically), kept when every element's residual is at most 1e-10 (1 + |V|), else Newton to
    convergence (:meth:`models.trajectory.TrajectoryNumerics.refined_outputs`)."""
    # the halved mesh's model, kept with the fit's (collocate validates the times and meshes before its cache)
    fine = est.model.cache.get_or_make("halved_mesh", tuple(data.pairs), lambda: collocate(
        model, data.union_times, mesh=mesh.refined(2), outputs=data.pairs), maxsize=4)
    order = 2 * mesh.degree - 1
    guess = None if est.states is None else interpolate_states(est.model, fine, est.states)
    num = fine.state_numerics
    if guess is not None and hasattr(num, "refined_outputs"):      # one Newton step from the fit's trajectories
        h_fine = num.refined_outputs(est.p, data.inputs, guess)
    else:
        h_fine = num.integrated_outputs(est.p, data.inputs, guess)
    dh = (h_fine - est.fitted) * 2 ** order / (2 ** order - 1)  # (n_q, n_pairs)
    counts = data.flat().counts()
    wt = counts * (np.ones(dh.shape[1]) if w is None else w)[None, :] / est.sigma[None, :] ** 2
    e = np.where(counts > 0, np.abs(dh) / est.sigma[None, :], 0.0)
    A = np.einsum("jkp,jk,jkq->pq", est.G, wt, est.G)
    b = np.einsum("jkp,jk,jk->p", est.G, wt, dh)
    try:
        shift = np.linalg.solve(A, b) / est.stderr_gn  # Gauss-Newton: finite whenever p is identifiable
    except np.linalg.LinAlgError:       # a run-off point (not identifiable): the least-norm shift, in standard
        dp = np.linalg.lstsq(A, b, rcond=None)[0]       # errors where they are finite (0 along the run-off)
        shift = np.where(np.isfinite(est.stderr_gn), dp / np.where(np.isfinite(est.stderr_gn), est.stderr_gn, 1.0),
                         0.0)
    return e.max(axis=0), float(e.max()), shift


def identify_dynamic(model: DynamicModel, data: DynamicMeasurements, p0, weights=None, settings=None,
                     discretisation: DiscretisationSettings | None = None):
    """Weighted least squares of a dynamic model (paper eq. 3 on its collocation) with the
    discretisation error controlled (see the module docstring).

    Parameters
    ----------
    model : DynamicModel
    data : DynamicMeasurements
    p0 : array_like (n_p,)              start values
    weights : array_like (n_S,), optional  instrument weights
    settings : IdentifySettings, optional
    discretisation : DiscretisationSettings, optional

    Returns
    -------
    identification.fit.record.FitRecord
        Of the collocated model (``rec.model``) on the flat data (``rec.data``), with
        ``rec.diagnostics.discretisation`` a :class:`DiscretisationRecord` and a note
        (:func:`identification.identify` returns it as an Estimate).
    """
    ds = discretisation or DiscretisationSettings()
    if not isinstance(ds, DiscretisationSettings):
        raise TypeError(f"discretisation: expected DiscretisationSettings, got {type(ds).__name__}")
    data = _dynamic_data(model, data)
    w = _weights(data, weights)
    cm, flat = collocated_problem(model, data, degree=ds.degree, elements=ds.elements)
    p0, start_notes = _interior_start(model, p0)
    degenerate = _degenerate_start(cm, flat, p0, w)
    if degenerate:
        warnings.warn(degenerate, DegenerateStartWarning, stacklevel=3)
        start_notes += (degenerate,)
    mesh, p_start, history, order = cm.mesh, p0, [], 2 * ds.degree - 1
    first = _first_settings(model, settings, bool(start_notes))
    while True:
        if mesh is not cm.mesh:                     # the first mesh's model is collocated_problem's
            cm = collocate(model, data.union_times, mesh=mesh, outputs=data.pairs)
        try:
            est = fit_static(cm, flat, p_start, weights=w, settings=settings if history else first)
        except IdentificationError as exc:
            if not degenerate:
                raise
            raise IdentificationError(f"{degenerate}; the fit then failed: {exc}", status=exc.status) from exc
        reason = ""
        try:
            by_sensor, err, shift = _error(model, data, est, mesh, w)
        except StateSolveError as exc:
            by_sensor, err, shift = np.full(len(data.pairs), np.nan), float("nan"), np.full(model.n_p, np.nan)
            reason = f"the trajectory on the halved mesh could not be computed ({exc})"
        max_shift = float(np.max(np.abs(shift)))
        history.append((mesh.n_elements, err, max_shift))
        ok = not reason and err <= ds.tol_sigma and max_shift <= ds.tol_se
        if ok or reason:
            break
        need = max(err / ds.tol_sigma, max_shift / ds.tol_se)
        factor = int(min(max(math.ceil(1.25 * need ** (1.0 / order)), 2), ds.max_factor))
        if len(history) > ds.max_refinements:
            reason = f"still above tolerance after {ds.max_refinements} refinements"
            break
        if mesh.n_elements * factor > ds.max_elements:
            reason = f"the next mesh would exceed {ds.max_elements} elements (max_elements)"
            break
        mesh, p_start = mesh.refined(factor), est.p
    per = {s: float(np.nanmax(np.where([ps == s for ps, _ in data.pairs], by_sensor, np.nan)))
           if any(ps == s for ps, _ in data.pairs) else 0.0 for s in data.sensors}
    rec = DiscretisationRecord(ds.degree, mesh.n_elements, mesh.boundaries, err, per, shift, ds.tol_sigma,
                               ds.tol_se, ok, tuple(history), reason)
    return dataclasses.replace(est, notes=start_notes + est.notes + (rec.note(),),
                               extra={**est.extra, "discretisation": rec})


def _first_settings(model: DynamicModel, settings, moved: bool):
    """The settings of the fit on the first mesh: with a start value moved off its bound (a rate of 0: nearly
    constant trajectories, from which the reduced-space iteration, a shooting method, crawls) and start
    trajectories through the data (``init="data"``, outputs linear in the states), the full-space NLP is solved
    from those directly (no reduced-space attempt first); otherwise ``settings``.  Later meshes start from the
    previous estimate with ``settings``."""
    settings = settings or IdentifySettings()
    if not moved or settings.init != "data" or linear_outputs(model) is None:
        return settings
    return dataclasses.replace(settings, reduced_start_inputs=None)


def _interior_start(model: DynamicModel, p0) -> tuple:
    """(p0 with every start value on a finite bound moved ``START_MARGIN`` of its scale into the interior (at
    most half the bound range), the note saying so or ())."""
    p0 = as_start_vector(model, p0).copy()          # the caller's array is never changed
    s = param_scale(model, p0)
    moved = []
    for i, par in enumerate(model.params):
        room = 0.5 * (par.upper - par.lower)
        step = min(START_MARGIN * s[i], room) if room > 0 else 0.0
        if p0[i] == par.lower and math.isfinite(par.lower) and step > 0:
            p0[i] = par.lower + step
        elif p0[i] == par.upper and math.isfinite(par.upper) and step > 0:
            p0[i] = par.upper - step
        else:
            continue
        moved.append(f"{par.name} = {p0[i]:.6g}")
    if not moved:
        return p0, ()
    return p0, (f"start values on a bound moved {START_MARGIN:g} of their scale into the interior: "
                f"{', '.join(moved)} (the sensitivities at a bound such as a rate of 0 may vanish)",)


def _degenerate_start(cm, flat, p0, w) -> str:
    """"" or the one-line message naming the parameters the outputs with data do not depend on at p0 (exact
    AD sensitivities of the collocation, zero in every output: a degenerate start).  An ODE only (a DAE is
    not checked); a start whose trajectory fails is left to the fit, which names it."""
    if cm.dynamic.n_z:
        return ""
    try:       # the fit's own start states and sensitivities (cached: the fit and refits reuse them)
        G = start_sensitivities(cm, p0, flat.inputs, initial_states(cm, p0, flat.inputs)).G
    except StateSolveError:
        return ""
    used = (flat.counts() > 0) & ((np.ones(G.shape[1]) if w is None else np.asarray(w)) > 0)[None, :]
    dead = [n for i, n in enumerate(cm.param_names) if not np.any(G[:, :, i][used])]
    if not dead:
        return ""
    at = ", ".join(f"{n} = {v:.4g}" for n, v in zip(cm.param_names, p0))
    return (f"p0: at the start ({at}) the outputs do not depend on {', '.join(dead)} (their sensitivities are "
            "exactly zero: a degenerate trajectory, e.g. every rate 0); start where they act (nonzero rates, "
            "values of their typical size)")


def _outputs(cm, p, inputs) -> np.ndarray:
    """The collocation solution's outputs (n_q, n_S): one mapped CasADi call for an ODE."""
    if cm.dynamic.n_z:
        return cm.integrated_outputs(p, inputs)
    return mapped_outputs(cm, p, inputs)


def controlled_mesh(model: DynamicModel, p, inputs, times, sigma, outputs=None,
                    discretisation: DiscretisationSettings | None = None):
    """The collocated model at ``times`` whose outputs at p are within ``tol_sigma`` sigmas of the
    halved mesh's (Richardson, as in :func:`identify_dynamic`), and its record, for planning
    without data.  Raises :class:`identification.errors.StateSolveError` when no such mesh is
    found within ``max_refinements`` / ``max_elements``."""
    ds = discretisation or DiscretisationSettings()
    t = model.check_times(times)
    horizon = model.horizon if model.horizon is not None else float(t[-1])
    cm = collocate(model, t, degree=ds.degree, max_step=horizon / ds.elements, outputs=outputs)
    sig = np.asarray([dict(zip(model.sensors, np.broadcast_to(np.asarray(sigma, float), (model.n_S,))))[s]
                      for s, _ in cm.outputs])
    order = 2 * ds.degree - 1
    for _ in range(ds.max_refinements + 1):
        fine = collocate(model, t, mesh=cm.mesh.refined(2), outputs=cm.outputs)
        diff = _outputs(fine, p, inputs) - _outputs(cm, p, inputs)
        err = float(np.max(np.abs(diff) / sig)) * 2 ** order / (2 ** order - 1)
        if err <= ds.tol_sigma:
            return cm, err
        factor = int(min(max(math.ceil(1.25 * (err / ds.tol_sigma) ** (1.0 / order)), 2), ds.max_factor))
        if cm.mesh.n_elements * factor > ds.max_elements:
            break
        cm = collocate(model, t, mesh=cm.mesh.refined(factor), outputs=cm.outputs)
    raise StateSolveError(f"discretisation of {model.name!r}: no mesh within {ds.max_elements} elements and "
                          f"{ds.max_refinements} refinements brings the output error below {ds.tol_sigma:g} sigma "
                          f"(last estimate {err:.3g} sigma on {cm.mesh.n_elements} elements)")


def dynamic_information(model: DynamicModel, data, p, *, inputs=None, times=None, sigma=None, n_series=1,
                        discretisation: DiscretisationSettings | None = None):
    """Per-(sensor, time) information F_k and second-order terms S_k (n_pairs, n_p, n_p) of a dynamic
    model at p (see :func:`identification.information_contributions`), on a mesh whose output error is
    within the discretisation tolerance.

    With ``data=None`` (planning): ``inputs`` (n_q, d_q), common sampling ``times`` and one ``sigma``
    per instrument; the pairs are time-major (every sensor at the first time, then the next).  With
    DynamicMeasurements: the pairs of ``data.pairs``.
    """
    p = np.asarray(p, float).ravel()
    if data is None:
        if inputs is None or times is None or sigma is None:
            raise DataError("data: None needs inputs= (experiment input rows), times= (sampling times) and "
                            "sigma= (one per instrument)")
        q = np.atleast_2d(np.asarray(inputs, float))
        if q.shape[1] != model.n_q_dim:
            raise DataError(f"inputs: has {q.shape[1]} columns but model {model.name!r} takes {model.n_q_dim} "
                            f"({', '.join(model.inputs)})")
        try:
            cm, _ = controlled_mesh(model, p, q, times, sigma, discretisation=discretisation)
        except ModelError as exc:
            raise DataError(str(exc)) from None
        sig = np.tile(np.broadcast_to(np.asarray(sigma, float), (model.n_S,)), cm.times.size)
        if model.n_z:
            return static_information(cm, None, p, inputs=q, sigma=sig, n_series=n_series)
        if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 1:
            raise DataError(f"n_series: expected an integer >= 1, got {n_series!r}")
        _, G = outputs_and_sensitivities(cm, p, q)          # exact, one mapped call (models.trajectory)
        F = float(n_series) * np.einsum("k,jkp,jkr->kpr", 1.0 / sig ** 2, G, G)
        return F, np.zeros_like(F)
    if times is not None or inputs is not None or sigma is not None:
        raise DataError("inputs/times/sigma: give them only when data is None (the data carry their own)")
    data = _dynamic_data(model, data)
    if data.sigma is None:
        raise DataError("data.sigma: information contributions need known sensor sigmas")
    cm, _ = controlled_mesh(model, p, data.inputs, data.union_times, data.sigma, outputs=data.pairs,
                            discretisation=discretisation)
    return static_information(cm, data.flat(), p)


def predict(model: DynamicModel, p, inputs, times, sigma, discretisation: DiscretisationSettings | None = None):
    """Outputs h(x(t), p, u(t)) of every experiment at the common sampling ``times``, shape (n_q, n_t, n_S),
    on a mesh whose error is within ``tol_sigma`` of each instrument's ``sigma`` (:func:`controlled_mesh`)."""
    q = np.atleast_2d(np.asarray(inputs, float))
    if q.shape[1] != model.n_q_dim:
        raise DataError(f"inputs: has {q.shape[1]} columns but model {model.name!r} takes {model.n_q_dim} "
                        f"({', '.join(model.inputs)})")
    try:
        cm, _ = controlled_mesh(model, np.asarray(p, float), q, times, sigma, discretisation=discretisation)
    except ModelError as exc:
        raise DataError(str(exc)) from None
    return cm.integrated_outputs(p, q).reshape(q.shape[0], cm.times.size, model.n_S)


def simulate_campaign(model: DynamicModel, p, inputs, times, sigma, n_series: int = 1, seed=None,
                      discretisation: DiscretisationSettings | None = None) -> DynamicMeasurements:
    """A campaign z = h(x(t), p, u(t)) + eps, eps ~ N(0, sigma_k^2) independent, of ``n_series`` series at the
    common sampling ``times`` (predictions by :func:`predict`; ``seed`` for numpy's default generator)."""
    if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 1:
        raise DataError(f"n_series: expected an integer >= 1, got {n_series!r}")
    sig = np.broadcast_to(np.asarray(sigma, float), (model.n_S,))
    h = predict(model, p, inputs, times, sig, discretisation)
    z = h[None] + sig * np.random.default_rng(seed).standard_normal((n_series,) + h.shape)
    return DynamicMeasurements(np.atleast_2d(np.asarray(inputs, float)), np.asarray(times, float), z, sig,
                               sensors=model.sensors, input_names=model.inputs)
