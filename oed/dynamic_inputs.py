r"""Experiment design for dynamic models: input rows (constants and control profiles) over time.

A dynamic model's experiment j is its input row q_j (the constants, then every control's values at
its grid points), measured by every instrument k at the sampling times t; its information is

.. math::  F_j = n_\text{series}\sum_{t}\sum_{k} G_{jkt}^T G_{jkt} / \sigma_k^2,\qquad
           G_{jkt} = \partial h_k(x(t; p, q_j), p, u(t)) / \partial p,

computed exactly on the Radau IIA collocation (:mod:`models.collocation`) of a mesh whose output
error at p is within the discretisation tolerance at every candidate
(:func:`identification.fit.dynamic_fit.controlled_mesh`).  The exact design over the candidates and
its continuous refinement are those of :func:`oed.inputs.select_inputs` on the collocated model
(the refinement's NLP holds every trajectory and its sensitivities as variables, sparse, see
:mod:`oed.input_nlp`).  After the refinement the mesh is controlled again at the refined rows;
should it need refining, the refinement is repeated from the refined rows on the finer mesh, so
that the reported design and value are those of a mesh within tolerance.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from identification.fit.dynamic_fit import DiscretisationSettings, controlled_mesh
from models.collocation import collocate, pair_name
from models.trajectory import mapped_outputs, outputs_and_sensitivities
from models.contract import ModelError
from .static_inputs import (InputDesignResult, RefineSettings, input_information, refine_inputs,
                            select_static_inputs)

__all__ = ["dynamic_problem", "dynamic_input_information", "select_dynamic_inputs"]


def _instrument_sigma(model, sigma) -> np.ndarray:
    sig = np.asarray(sigma, dtype=float).ravel()
    if sig.size == 1:
        sig = np.full(model.n_S, float(sig[0]))
    if sig.shape != (model.n_S,) or not np.all(np.isfinite(sig) & (sig > 0)):
        raise ValueError(f"sigma: expected {model.n_S} positive finite values (one per instrument: "
                         f"{', '.join(model.sensors)}), got {sigma!r}")
    return sig


def dynamic_problem(model, p, candidates, times, sigma, discretisation: DiscretisationSettings | None = None):
    """(collocated model, sigma per (sensor, time) pair, discretisation error in sigmas) of a dynamic
    model sampled at ``times``, on a mesh controlled at p over every candidate row."""
    sig = _instrument_sigma(model, sigma)
    try:
        t = model.check_times(times)
    except ModelError as exc:
        raise ValueError(str(exc)) from None
    Q = np.atleast_2d(np.asarray(candidates, dtype=float))
    if Q.shape[1] != model.n_q_dim:
        raise ValueError(f"candidates: expected shape (n_candidates, {model.n_q_dim}) ({', '.join(model.inputs)}: "
                         f"the constants, then every control's values at its grid points), got {Q.shape}")
    cm, err = controlled_mesh(model, np.asarray(p, float).ravel(), Q, t, sig, discretisation=discretisation)
    return cm, np.tile(sig, t.size), err


def _pair_sensors(model, cm, sensors):
    """Instrument names (or None / 'joint') as the collocated model's (sensor, time) pair names."""
    if sensors is None or (isinstance(sensors, str) and sensors == "joint"):
        return sensors
    names = [sensors] if isinstance(sensors, str) else list(sensors)
    unknown = [s for s in names if s not in model.sensors]
    if unknown or not names:
        raise ValueError(f"sensors: expected None, 'joint' or instruments of {list(model.sensors)}, got {sensors!r}")
    return [pair_name(s, t) for t in cm.times for s in model.sensors if s in names]


def _error_at(model, cm, p, inputs, sig) -> float:
    """Richardson's estimate of the output error of ``cm`` at p and ``inputs``, in sigmas (the mesh
    against every element halved, as :func:`identification.fit.dynamic_fit.controlled_mesh`)."""
    half = collocate(model, cm.times, mesh=cm.mesh.refined(2), outputs=cm.outputs)
    order = 2 * cm.mesh.degree - 1
    if model.n_z:
        diff = half.integrated_outputs(p, inputs) - cm.integrated_outputs(p, inputs)
    else:
        diff = mapped_outputs(half, p, inputs) - mapped_outputs(cm, p, inputs)
    return float(np.max(np.abs(diff) / sig)) * 2 ** order / (2 ** order - 1)


def dynamic_input_information(model, p, candidates, times, sigma, n_series=1,
                              discretisation: DiscretisationSettings | None = None) -> np.ndarray:
    r"""Per-experiment information :math:`F_j` (module docstring) of every candidate row, all
    instruments at all ``times``, shape (n_candidates, n_p, n_p)."""
    cm, sig, _ = dynamic_problem(model, p, candidates, times, sigma, discretisation)
    if model.n_z:
        return input_information(cm, p, candidates, sig, n_series).sum(axis=1)
    if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 1:
        raise ValueError(f"n_series: expected an integer >= 1, got {n_series!r}")
    _, G = outputs_and_sensitivities(cm, p, candidates)        # one mapped call over the candidates
    return float(n_series) * np.einsum("k,jkp,jkr->jpr", 1.0 / sig ** 2, G, G)


def select_dynamic_inputs(model, p, *, times, candidates, sigma, n_points, sensors=None, refine=False, bounds=None,
                          time_limit=60.0, refine_settings: RefineSettings = RefineSettings(),
                          discretisation: DiscretisationSettings | None = None, **kwargs) -> InputDesignResult:
    """:func:`oed.inputs.select_inputs` for a dynamic model (see the module docstring).

    ``times``: the sampling times of every experiment; ``sigma``: one per instrument; ``sensors``:
    None (every instrument), instrument names, or ``"joint"`` ((row, sensor@time) pairs chosen
    together); the other arguments as in :func:`oed.inputs.select_inputs`."""
    t0 = time.perf_counter()
    cm, sig, err = dynamic_problem(model, p, candidates, times, sigma, discretisation)
    pairs = _pair_sensors(model, cm, sensors)
    res = select_static_inputs(cm, p, candidates=candidates, sigma=sig, n_points=n_points, sensors=pairs,
                               refine=refine, bounds=bounds, refine_settings=refine_settings, **kwargs,
                               time_limit=max(time_limit - (time.perf_counter() - t0), 0.05 * time_limit))
    notes = [f"dynamic model: Radau IIA collocation of degree {cm.mesh.degree} on {cm.mesh.n_elements} elements, "
             f"output error at p within {err:.2g} sigma at every candidate"]
    refined = res.refined
    if refined is not None:
        err_r = _error_at(model, cm, p, refined.inputs, sig)
        if err_r > (discretisation or DiscretisationSettings()).tol_sigma:
            fine, err_r = controlled_mesh(model, np.asarray(p, float).ravel(), refined.inputs, cm.times,
                                          _instrument_sigma(model, sigma), discretisation=discretisation)
            left = max(time_limit - (time.perf_counter() - t0), 0.05 * time_limit)
            again = refine_inputs(fine, p, refined.inputs, sig, criterion=res.criterion,
                                  sensors=_pair_sensors(model, fine, sensors), n_series=kwargs.get("n_series", 1),
                                  bounds=(refined.lower, refined.upper), time_limit=left,
                                  settings=dataclasses.replace(refine_settings, n_starts=1))
            refined = dataclasses.replace(again, start_values=refined.start_values + again.start_values,
                                          messages=refined.messages + again.messages,
                                          n_failed=refined.n_failed + again.n_failed,
                                          wall_time=time.perf_counter() - t0)
            notes.append(f"refined design: the mesh was refined to {fine.mesh.n_elements} elements (output error "
                         f"{err_r:.2g} sigma) and the refinement repeated on it")
        else:
            notes.append(f"refined design: output error at p within {err_r:.2g} sigma on the same mesh")
    return dataclasses.replace(res, refined=refined, notes=res.notes + tuple(notes))
