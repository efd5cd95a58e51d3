r"""How large is the model error, where does it sit, and what prediction error to expect (issue 29).

One path for static and dynamic models: :class:`identification.Problem` gives the static problem of the model
(a dynamic model dx/dt = f(x, z, p, u) collocated on a mesh controlled at p0, its readings flattened to
(instrument, time) columns), and every step below runs on it.  What differs between the kinds is asked of the
problem's strategy, never of the model: :meth:`identification.Problem.columns` says which instrument every
column holds and at which coordinates (a dynamic model: its sampling time t).  The discrepancy is then one
Gaussian process per instrument over the inputs *and* those coordinates (a dynamic model: over the experiment
inputs and time), the pure error is pooled per instrument, a split by time window becomes a split of the
columns (:func:`identification.studies.splits.flat_split`), and ``predict`` returns experiments x sampling
times x instruments for a dynamic model (``band.grid[0]`` the times); ``exact_at`` may name the coordinate
(``{"t": 0.0}``).

For a static model h(y(p, q), p, q) and the means zbar_jk of the readings of sensor k at input row j,

.. math::

    \bar z_{jk} = h_k(q_j, p) + \delta_k(q_j) + \rho_{jk} + \bar\varepsilon_{jk},

with the output discrepancy delta_k a Gaussian process over the model's inputs and rho_jk a rough
part independent between input rows (:mod:`identification.studies.discrepancy_gp`).  Steps:

1. **Test** of 'no model error' on the plain fit's residuals: the REML likelihood ratio for one variance
   component lambda >= 0 (V = D + lambda diag(sigma_k^2)) against the boundary-corrected reference
   0.5 chi2_0 + 0.5 chi2_1 (``detected`` when p < alpha).
2. **Discrepancy** (kind "discrepancy"): per sensor amplitude s_k, length scale l_k and rough part tau_k by
   REML with exact gradients, then p by generalised least squares under the residual covariance, with
   covariance (G^T V^-1 G)^-1 (:mod:`identification.studies.model_error_fit`: REML and GLS alternated to a fixed point, not one joint
   maximisation).
3. **Embedded** (kind "embedded", :mod:`identification.studies.embedded_error`): the parameters vary between
   conditions (input rows or named groups), p + b_g with b_g ~ N(0, diag(omega^2)), omega by REML with exact
   gradients: which parameters carry the error and by how much.
4. **Held-out table**: for every split, each error model fitted on its calibration part predicts its
   validation readings (95 % new-reading bands by default): coverage, median widening, log score.  Readings in
   a condition the calibration part has not seen (:func:`unseen_rows`: a named group without calibration rows,
   or rows that repeat a calibration row's inputs when the calibration rows repeat none, e.g. the press's
   unloading at the loading forces for a model whose one input is the force) are predicted with the
   discrepancy as a new draw of its process (no cross-covariance with the calibration readings: mean h(q*, p),
   its prior band); the embedded error predicts every validation row as a new condition anyway.
   ``kind="auto"``: "none" when the test does not detect model error (so an adequate model gets an error
   model no more often than the test's size), else the error model of the highest total held-out log score
   (without splits: the discrepancy).
5. The chosen error model fitted on all data: p, conf_int, predict, discrepancy.
6. **Stated sigma against the repeats** (sigma given, repeated series; :func:`pure_error_checks`): per selected
   sensor, nu s^2 / sigma^2 against chi2_nu with s the pooled pure error on nu degrees of freedom; a note names
   the sensors where the repeats scatter clearly less (or more) than sigma (one-sided p < alpha).  A stated
   sigma that holds a systematic error (the press's sigma_man, a gauge error that varies smoothly with the
   reading) is held by the discrepancy too, and the new-reading bands, which add sigma^2, are then wider than
   the error requires; ``sigma=None`` takes the pure error.

``identifiable`` is False when, along some direction of p, the model error leaves less than
:data:`~identification.studies.model_error_fit.CONFOUNDED_INFORMATION` (1 %) of the information the noise alone
leaves and its correlation less than :data:`~identification.studies.model_error_fit.CONFOUNDED_CORRELATION` (50 %)
of what uncorrelated errors of the same size would leave: the discrepancy can mimic a change of the parameters
(heuristic thresholds).  A discrepancy that mimics p with a small one (a smooth error absorbed by p) is not
caught by any such check: ``exact_at`` (where the model is known to be exact) is the remedy.

The embedded error's conditions are the input rows, or the ``groups`` the user names; the moment estimate
from the excess spread of the split fits is not implemented.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Sequence

import numpy as np
from scipy import stats

from identification.errors import DataError
from identification.fit.measurements import Measurements
from identification.fit.problem import Problem, strategy_for
from identification.inference.intervals import validate_alpha
from identification.studies.discrepancy_gp import InputScaling
from identification.studies.model_error_fit import ErrorFit, band_logpdf, fit_model_error, pure_error_sigma
from identification.studies.model_error_result import (EmbeddedParameter, ErrorTest, HeldOut, ModelErrorResult,
                                                       PureErrorCheck, SensorDiscrepancy)
from identification.studies.splits import Split, SplitError, flat_split
from models.labels import LabelledModel

__all__ = ["model_error", "ModelErrorResult", "KINDS", "unseen_rows", "SAME_INPUTS", "pure_error_checks",
           "pure_error_notes", "unseen_note", "UNSEEN_COVERAGE_MC", "UNSEEN_COVERAGE_CAMPAIGNS"]

#: the error models model_error chooses from ("auto": by held-out log score)
KINDS = ("auto", "none", "discrepancy", "embedded")
_ERROR_KINDS = ("none", "discrepancy", "embedded")


# ---------------------------------------------------------------------------- validation
def _checked_model_data(model, data) -> None:
    if not isinstance(model, LabelledModel):
        raise TypeError(f"model: expected a models.Model (static or dynamic), got {type(model).__name__}")
    strategy_for(model).check_data(data)


def _checked_inputs(model, data: Measurements) -> None:
    """The static problem's data has as many input columns as its model (DataError)."""
    if data.d_q != model.n_q_dim:
        raise DataError(f"data: the inputs have {data.d_q} columns but the model has {model.n_q_dim} "
                        f"({', '.join(model.inputs)})")


def _checked_exact_at(exact_at, names: tuple) -> dict:
    if exact_at is None:
        return {}
    if not isinstance(exact_at, Mapping):
        raise ValueError(f"exact_at: expected a mapping {{input name: value}}, got {type(exact_at).__name__}")
    out = {}
    for name, value in exact_at.items():
        if name not in names:
            raise ValueError(f"exact_at: unknown input {name!r}; the model's inputs (and coordinates) are "
                             f"{list(names)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"exact_at[{name!r}]: expected a finite number, got {value!r}") from None
        if not math.isfinite(v):
            raise ValueError(f"exact_at[{name!r}]: expected a finite number, got {value!r}")
        out[str(name)] = v
    return out


def _checked_splits(splits, data: Measurements, w: np.ndarray, n_p: int, pairs=None) -> tuple:
    """The splits as a tuple, a split by time window as a split of the columns ``pairs`` (instrument, time) of
    the static problem's data (:func:`identification.studies.splits.flat_split`); every calibration set holds at least n_p + 2 input x sensor means of the
    selected sensors and every validation set at least one reading (SplitError naming the split)."""
    if splits is None:
        return ()
    splits = (splits,) if isinstance(splits, Split) else tuple(splits)
    sel = w > 0
    out = []
    for sp in splits:
        if not isinstance(sp, Split):
            raise TypeError(f"splits: expected identification.Split objects, got {type(sp).__name__}")
        if sp.timed:
            if pairs is None:
                raise SplitError(f"splits: split {sp.name!r} selects readings by time window; the data hold no "
                                 "time series")
            sp = flat_split(sp, pairs, data.n_q)
        sp.check(data.n_q, data.n_M)
        n_cal = int((sp.calibration(data).counts()[:, sel] > 0).sum())
        n_val = int(sp.validation(data).counts()[:, sel].sum())
        if n_cal < n_p + 2 or n_val < 1:
            raise SplitError(f"splits: split {sp.name!r} has {n_cal} calibration means (input x sensor) and "
                             f"{n_val} validation readings; model_error needs at least n_p + 2 = {n_p + 2} and 1")
        out.append(sp)
    return tuple(out)


def _instrument_weights(weights, names: tuple) -> np.ndarray:
    """Validated instrument (sensor) weights (n_inst,), dimensionless: ones for None, else finite and >= 0."""
    if weights is None:
        return np.ones(len(names))
    w = np.asarray(weights, dtype=float)
    if w.shape != (len(names),):
        raise DataError(f"weights: expected {len(names)} sensor weights ({', '.join(names)}), got shape {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise DataError(f"weights: must be finite and non-negative, got {w.tolist()}")
    return w


def _checked_groups(groups, n_q: int) -> tuple:
    """(codes, labels): the condition of every input row as integer codes (n_q,) and the distinct labels in code
    order, or (None, ()) (ValueError naming the argument)."""
    if groups is None:
        return None, ()
    if isinstance(groups, (str, bytes)) or not hasattr(groups, "__len__"):
        raise ValueError(f"groups: expected one condition label per input row ({n_q}), got {groups!r}")
    labels = list(groups)
    if len(labels) != n_q:
        raise ValueError(f"groups: expected one condition label per input row ({n_q}), got {len(labels)}")
    try:
        codes = {lab: i for i, lab in enumerate(dict.fromkeys(labels))}
    except TypeError:
        raise ValueError("groups: the condition labels must be hashable (numbers or strings)") from None
    return np.array([codes[lab] for lab in labels]), tuple(codes)


def _sigma_of(data, w: np.ndarray, flat: Measurements, layout) -> tuple:
    """(data with sigma, source): sigma as given, or the pure error of repeated series per instrument (pooled over
    its columns ``layout.instrument`` of the static data ``flat``; ``w`` the instrument weights; ValueError
    without)."""
    if data.sigma is not None:
        return data, "given"
    s, dof = pure_error_sigma(flat.z, layout.instrument)
    sel = w > 0
    if data.n_M < 2 or not np.all(dof[sel] > 0) or not np.all(s[sel] > 0):
        raise ValueError("data: sigma is None and the data hold no repeated series to estimate the noise from "
                         "(pure error); give sigma (Measurements(..., sigma=...)) or measure a second series")
    return data.with_sigma(np.where(np.isfinite(s) & (s > 0), s, 1.0)), "pure error (repeated series)"


def pure_error_checks(data: Measurements, w: np.ndarray, layout) -> tuple:
    """One :class:`PureErrorCheck` per selected instrument of the static data ``data`` (sigma given, columns'
    instruments ``layout.instrument``, ``w`` the instrument weights) holding repeated readings: dof s^2 / sigma^2
    against chi2_dof (empty without repeats or without sigma)."""
    if data.sigma is None or data.n_M < 2:
        return ()
    s, dof = pure_error_sigma(data.z, layout.instrument)
    sig = np.broadcast_to(np.asarray(data.sigma, float), (data.n_S,))
    out = []
    for g, name in enumerate(layout.names):
        cols = np.flatnonzero(np.asarray(layout.instrument) == g)
        if w[g] <= 0 or dof[g] <= 0 or not cols.size or not sig[cols[0]] > 0:
            continue
        x = dof[g] * s[g] ** 2 / sig[cols[0]] ** 2
        out.append(PureErrorCheck(name, float(sig[cols[0]]), float(s[g]), int(dof[g]),
                                  float(stats.chi2.cdf(x, dof[g])), float(stats.chi2.sf(x, dof[g]))))
    return tuple(out)


def pure_error_notes(checks: tuple, alpha: float) -> list:
    """Notes on the sensors whose pure error is clearly (p < alpha, one-sided) below or above the stated sigma
    (``checks``: :func:`pure_error_checks`); these are among ``ModelErrorResult.notes``."""
    notes = []
    below = [c for c in checks if c.p_below < alpha]
    above = [c for c in checks if c.p_above < alpha]
    if below:
        notes.append("the repeated series scatter clearly less than the stated sigma on " + ", ".join(
            f"{c.sensor} (pure error {c.pure_error:.4g} against sigma {c.sigma:.4g}, ratio {c.ratio:.2f}, "
            f"chi-square test on {c.dof} dof, p = {c.p_below:.2g})" for c in below)
            + ": if the excess is a systematic error (a gauge error that varies with the reading) the discrepancy "
              "holds it too and the new-reading bands, which add sigma^2, are wider than the error requires; "
              "sigma=None takes the pure error")
    if above:
        notes.append("the repeated series scatter clearly more than the stated sigma on " + ", ".join(
            f"{c.sensor} (pure error {c.pure_error:.4g} against sigma {c.sigma:.4g}, ratio {c.ratio:.2f}, "
            f"chi-square test on {c.dof} dof, p = {c.p_above:.2g})" for c in above)
            + ": the test and the bands take too little noise; sigma=None takes the pure error")
    return notes


# ---------------------------------------------------------------------------- held-out table
#: two input rows whose scaled inputs differ by at most this (per column, of the range) hold the same inputs
SAME_INPUTS = 1e-9


def unseen_rows(split: Split, data: Measurements, groups: np.ndarray | None = None) -> np.ndarray:
    """Which validation input rows of ``split`` lie in a condition its calibration part has not seen, bool
    (n_val,) in the order of ``split.val_inputs``.

    With ``groups`` (the condition code of every input row of ``data``): the rows of a condition without
    calibration rows.  Without: when no two calibration rows hold the same inputs, the validation rows that
    are not calibration rows but repeat a calibration row's inputs (within :data:`SAME_INPUTS` of the inputs'
    range): the data hold them apart though the model's inputs do not tell them apart (the direction of
    motion at one force, another day at one set point), and the calibration part, one reading of each input,
    says nothing about how much two rows at one input differ.  When calibration rows repeat inputs, the
    discrepancy's rough part (independent between rows) has measured that and no row is unseen; a split by
    time window or by series (the same rows on both sides) has none.
    """
    cal, val = list(split.cal_inputs), list(split.val_inputs)
    if groups is not None:
        return ~np.isin(np.asarray(groups)[val], np.asarray(groups)[cal])
    q = np.asarray(data.inputs, float)
    span = np.where(np.ptp(q, axis=0) > 0, np.ptp(q, axis=0), 1.0)
    xc, xv = q[cal] / span, q[val] / span
    repeats = np.all(np.abs(xc[:, None, :] - xc[None, :, :]) <= SAME_INPUTS, axis=2).sum() > len(cal)
    same = np.all(np.abs(xv[:, None, :] - xc[None, :, :]) <= SAME_INPUTS, axis=2).any(axis=1)
    return same & ~np.isin(val, cal) & ~repeats


def _held_out(model, data, p0, w, scaling, split: Split, alpha: float, groups, layout) -> HeldOut:
    """Every error model fitted on the calibration part of ``split`` predicts its validation readings (as new
    conditions: the embedded error always, the discrepancy on the rows :func:`unseen_rows` names)."""
    cal, val = split.calibration(data), split.validation(data)
    plain = fit_model_error(model, cal, p0, w, scaling, "none", layout=layout)
    g = None if groups is None else groups[list(split.cal_inputs)]
    fits = [plain] + [fit_model_error(model, cal, p0, w, scaling, k, plain=plain.plain, groups=g, layout=layout)
                      for k in _ERROR_KINDS[1:]]
    new = unseen_rows(split, data, groups)
    conditions = np.where(new, -1, 0) if groups is None else np.where(new, -1, groups[list(split.val_inputs)])
    sel = w > 0
    z = val.z[:, :, sel]
    ok = np.isfinite(z)
    cover, score, width = [], [], []
    for f in fits:
        b = f.predict(val.inputs, alpha, new_reading=True, conditions=conditions)
        lo, hi = b.lower[None, :, sel], b.upper[None, :, sel]
        cover.append(float(np.mean(((z >= lo) & (z <= hi))[ok])))
        score.append(float(np.mean(band_logpdf(b, val.z)[:, :, sel][ok])))
        width.append(np.broadcast_to(hi - lo, z.shape)[ok])
    n_new = int(np.broadcast_to(new[None, :, None], z.shape)[ok].sum())
    return HeldOut(split.name, int(ok.sum()), cover[0], cover[1], cover[2], float(np.median(width[1] / width[0])),
                   float(np.median(width[2] / width[0])), score[0], score[1], score[2], n_new,
                   1 if g is None else int(np.unique(g).size))


def _choose(kind: str, detected: bool, heldout: tuple) -> tuple:
    """(kind, how) of the error model to report."""
    if kind != "auto":
        return kind, "as asked"
    if not detected:
        return "none", "auto: the test does not detect model error"
    if heldout:
        total = {k: sum(h.log_score(k) * h.n_values for h in heldout) for k in _ERROR_KINDS}
        chosen = max(total, key=total.get)
        return chosen, "auto: total held-out log score " + ", ".join(f"{k} {v:.4g}" for k, v in total.items())
    return "discrepancy", "auto: model error detected, no splits to compare the error models on"


def _embedded(fit: ErrorFit, names: tuple) -> tuple:
    if fit.embedded is None:
        return ()
    return tuple(EmbeddedParameter(n, float(o), float(o / abs(p)) if p != 0 else math.inf)
                 for n, o, p in zip(names, fit.embedded.omega, fit.p))


def _discrepancies(fit: ErrorFit, layout, scaling: InputScaling) -> tuple:
    """One SensorDiscrepancy per instrument (length scales in the units of the inputs, then of the coordinates)."""
    if fit.gp is None:
        return ()
    out = []
    for i, b in enumerate(fit.gp.obs.blocks):
        ell = fit.gp.length_scale(i)
        out.append(SensorDiscrepancy(layout.names[layout.instrument[b[0]]], fit.gp.amplitude(i), ell,
                                     tuple(float(v) for v in ell * scaling.scale), fit.gp.rough(i),
                                     float(fit.sigma[b[0]])))
    return tuple(out)


#: Monte Carlo coverage (mean % and its standard error over campaigns) of the discrepancy's 95 % new-reading band
#: at a condition the calibration part has not seen, by the number of conditions the calibration part holds:
#: condition offsets (``python -m bench model_error --n-offset=100``, 100 campaigns, bench/RESULTS.md "Issue 29:
#: press bands (session 12, pressband)") and, with one condition, 60 prototype campaigns of a measured study
#: (bench/RESULTS.md "Issue 29: press coverage over prototype campaigns (session 13, pressmc)")
UNSEEN_COVERAGE_MC = ((1, 75.7, 2.6), (4, 84.0, 2.2), (9, 89.6, 1.9))
UNSEEN_COVERAGE_CAMPAIGNS = (1, 69.0, 2.0)


def unseen_note(heldout: tuple) -> str:
    """The note on the held-out readings in a condition not seen: which splits hold them, how many conditions
    each calibration part holds, and what such bands covered in Monte Carlo (:data:`UNSEEN_COVERAGE_MC`)."""
    parts = [f"{h.split} ({h.n_unseen} of {h.n_values} readings; {h.n_conditions} condition"
             f"{'' if h.n_conditions == 1 else 's'} in its calibration part)" for h in heldout if h.unseen]
    mc = " / ".join(f"{m:.1f} +- {e:.1f}" for _, m, e in UNSEEN_COVERAGE_MC)
    cs = " / ".join(str(c) for c, _, _ in UNSEEN_COVERAGE_MC)
    one = (" With one condition no band there is calibrated without an assumption: it is a plug-in from one "
           "realisation of the error." if any(h.unseen_from_one for h in heldout) else "")
    return ("held-out readings in a condition the calibration part has not seen, predicted as a new draw of the "
            "discrepancy with its amplitude estimated from the conditions the calibration part holds (no share "
            "common to the conditions is assumed): " + ", ".join(parts) + "." + one + " The amplitude is "
            f"underestimated with few conditions: such 95 % bands covered {mc} % of the readings with {cs} "
            "conditions in Monte Carlo (condition offsets, python -m bench model_error --n-offset=100) and "
            f"{UNSEEN_COVERAGE_CAMPAIGNS[1]:.1f} +- {UNSEEN_COVERAGE_CAMPAIGNS[2]:.1f} % with one condition on 60 "
            "prototype campaigns (bench/RESULTS.md, issue 29): read their coverage and width as a lower bound of "
            "the error there.")


def _notes(fit: ErrorFit, kind: str, exact_at: dict, detected: bool, heldout: tuple, sigma_source: str,
           grouped: bool, checks: tuple = (), alpha: float = 0.05) -> tuple:
    notes = list(fit.notes) + pure_error_notes(checks, alpha)
    if grouped and kind == "none":
        notes.append("groups name the conditions of the error models; the 'none' error model does not use them")
    if kind == "discrepancy" and any(h.unseen for h in heldout):
        notes.append(unseen_note(heldout))
    if sigma_source != "given":
        notes.append("sigma is the pure error of the repeated series, taken as known: the test's reference "
                     "distribution is then approximate")
    if kind == "discrepancy" and not fit.identifiable:
        hint = "" if exact_at else "; pin the discrepancy where the model is known to be exact (exact_at={input: value})"
        notes.append(f"not identifiable: the discrepancy can mimic a change of the parameters (along one direction "
                     f"of p it leaves {100 * fit.information_kept:.2g} % of the information the noise alone leaves, "
                     f"{100 * fit.correlation_kept:.2g} % of what uncorrelated errors of its size would leave); p under "
                     f"the model error has lost its meaning{hint}")
    if exact_at and kind != "discrepancy":
        notes.append(f"exact_at pins the output discrepancy only; the {kind} error model does not use it")
    if kind == "none" and detected:
        notes.append("model error detected, but the reported error model is 'none': the bands ignore it")
    bad = [h.split for h in heldout if h.coverage(kind) < h.coverage_plain]
    if bad:
        notes.append(f"the {kind} error model lowered the held-out coverage on split(s) {', '.join(bad)}")
    return tuple(notes)


# ---------------------------------------------------------------------------- entry
def model_error(model, data, p0, splits: Sequence[Split] | Split | None = None, kind: str = "auto",
                exact_at: Mapping | None = None, alpha: float = 0.05, weights=None, groups=None) -> ModelErrorResult:
    r"""zbar_jk = h_k(q_j, p) + delta_k(q_j) + rho_jk + eps_jk, or h_k(q_j, p + b_j) + eps_jk: detect, size and
    locate the model error of a static or dynamic model, and predict with it (a dynamic model: q_j an experiment
    and the discrepancy delta_k(q_j, t) a process over its inputs and time, per instrument k).

    The 'no model error' test (REML likelihood ratio, reference 0.5 chi2_0 + 0.5 chi2_1), the output
    discrepancy per sensor (Gaussian process over the scaled inputs) or the embedded error (b_j ~ N(0,
    diag(omega^2)) per condition), each by REML with exact gradients, p by generalised least squares under
    it, the held-out table of ``splits`` (module docstring); units those of z and of the parameters.

    Parameters
    ----------
    model : models.Model          static, or dynamic (an ODE/DAE, :meth:`models.Model.ode`)
    data : Measurements or DynamicMeasurements   with sigma (unit of z), or sigma None and repeated series (pure
                                  error, pooled per instrument)
    p0 : array_like (n_p,)        start values of the fits
    splits : Split or sequence of Split, optional   the held-out table (and ``kind="auto"``'s choice); for time
                                  series also splits by time window (:func:`identification.studies.splits.
                                  time_window_splits`) and by experiments
    kind : "auto", "none", "discrepancy" or "embedded"
    exact_at : mapping {input name: value}, optional   where the discrepancy and its slope are zero (a dynamic
                                  model also {"t": time})
    alpha : float in (0, 0.5)     the test's level and the bands' miss probability
    weights : array_like (n_S,), optional   sensor (instrument) selection (0/1), as in identify (a positive weight selects the
                                  sensor; its size weights the plain fit only, not the error model)
    groups : sequence of n_q labels, optional   the condition of every input row (a direction of motion, a day):
                                  rows with one label share their embedded parameter deviation b, and the
                                  discrepancy of every condition is its own draw of the process (independent
                                  between conditions); None: the embedded error's conditions are the rows, the
                                  discrepancy's one condition, and a split's validation rows that repeat the
                                  inputs of its calibration rows are a condition not seen (:func:`unseen_rows`)

    Returns
    -------
    ModelErrorResult

    Raises
    ------
    ValueError (DataError, SplitError)
        A bad argument; the message names it.
    """
    _checked_model_data(model, data)
    if kind not in KINDS:
        raise ValueError(f"kind: unknown kind {kind!r}; choose one of {', '.join(repr(k) for k in KINDS)}")
    alpha = validate_alpha(alpha)
    problem = Problem(model, data)
    layout = problem.columns()
    exact = _checked_exact_at(exact_at, tuple(model.inputs) + tuple(layout.coord_names))
    p0 = np.asarray(p0, float).ravel()
    if p0.shape != (model.n_p,) or not np.all(np.isfinite(p0)):
        raise DataError(f"p0: expected {model.n_p} finite start values ({', '.join(model.param_names)}), got "
                        f"{p0.tolist()}")
    w_inst = _instrument_weights(weights, layout.names)
    if not np.any(w_inst > 0):
        raise DataError("weights: select at least one sensor (a positive weight)")
    w = layout.column_weights(w_inst)
    flat = problem.static()[1] if data.sigma is None else None
    data, sigma_source = _sigma_of(data, w_inst, flat, layout)
    problem = Problem(model, data)
    model, data = problem.static(p0)      # a dynamic model: collocated on a mesh controlled at p0
    _checked_inputs(model, data)
    checks = pure_error_checks(data, w_inst, layout) if sigma_source == "given" else ()
    n_means = int((data.counts()[:, w > 0] > 0).sum())
    if n_means < model.n_p + 2:
        raise DataError(f"data: {n_means} input x sensor means on the selected sensors; model_error needs at least "
                        f"n_p + 2 = {model.n_p + 2}")
    splits = _checked_splits(splits, data, w, model.n_p, getattr(problem.data, "pairs", None))
    codes, labels = _checked_groups(groups, data.n_q)
    scaling = InputScaling.of(data.inputs, exact, tuple(model.inputs) + tuple(layout.coord_names),
                              layout.coords if layout.coord_names else None)
    plain = fit_model_error(model, data, p0, w, scaling, "none", layout=layout)
    t = plain.test
    detected = t.p_value < alpha
    heldout = tuple(_held_out(model, data, p0, w, scaling, sp, alpha, codes, layout) for sp in splits)
    chosen, how = _choose(kind, detected, heldout)
    fit = plain if chosen == "none" else fit_model_error(model, data, p0, w, scaling, chosen, plain=plain.plain,
                                                         groups=codes, layout=layout)
    est = plain.plain
    return ModelErrorResult(
        model_name=est.model_name or model.name, kind=chosen, detected=bool(detected),
        test=ErrorTest(t.statistic, t.p_value, t.lam, t.dof), alpha=alpha,
        sensors=tuple(n for g, n in enumerate(layout.names) if np.any(w[layout.instrument == g] > 0)),
        param_names=tuple(model.param_names),
        p=fit.p.copy(), cov=fit.cov.copy(), p_plain=est.p.copy(), cov_plain=np.asarray(est.cov, float).copy(),
        discrepancies=_discrepancies(fit, layout, scaling), embedded=_embedded(fit, tuple(model.param_names)),
        identifiable=fit.identifiable,
        information_kept=fit.information_kept, correlation_kept=fit.correlation_kept, heldout=heldout, exact_at=exact, sigma=fit.sigma.copy(),
        sigma_source=sigma_source, how=how, notes=_notes(fit, chosen, exact, detected, heldout, sigma_source,
                                                                 codes is not None, checks, alpha),
        fit=fit, groups=labels, pure_error=checks)
