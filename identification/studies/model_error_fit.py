r"""The fit of a static model with and without a model error (output discrepancy or embedded), and its predictions.

Alternating estimation, not one joint maximisation over (p, theta) (the linear mixed model's REML / GLS
fixed point, applied to the model linearised at the current p as in Lindstrom and Bates):

1. the plain fit p_hat of :func:`identification.identify` (paper eq. 3) on the selected sensors;
2. the error model's hyperparameters theta by restricted maximum likelihood of the residual means
   r = zbar - h(p) with the sensitivities G(p) as fixed effects (:func:`identification.studies.discrepancy_gp.
   fit_discrepancy`, :func:`identification.studies.embedded_error.fit_embedded`, exact gradients);
3. the generalised least-squares refit of p under the residual covariance V(theta),

.. math::

    p^{ME} = \arg\min_p\; (\bar z - h(p))^\top V^{-1} (\bar z - h(p)),\qquad
    C^{ME} = (G^\top V^{-1} G)^{-1},

by Gauss-Newton steps on the model (states re-solved, G = dh/dp exact by AD and the implicit function
theorem), each halved until the objective decreases; steps 2 and 3 repeat at the new p until theta moves by less
than 1e-3 (in log units; at most :data:`OUTER_ITERATIONS` rounds, a note otherwise).

Prediction at new inputs q* (universal kriging: the discrepancy and the parameter error together),
for sensor k with k* = cov(delta_k(q*), r), u = g* - G^T V^{-1} k*:

.. math::

    \hat z_k(q^*) = h_k(q^*, p^{ME}) + k_*^\top V^{-1} r(p^{ME}),\qquad
    \operatorname{var} = s_k^2 c(q^*, q^*) + \tau_k^2 w(q^*) - k_*^\top V^{-1} k_* + u^\top C^{ME} u
    \;[+\,\sigma_k^2 \text{ for a new reading}];

at a condition the data do not hold (``conditions`` of :meth:`ErrorFit.predict`, the discrepancy of every
condition its own draw) k* = 0: mean h_k(q*, p^ME), variance s_k^2 c(q*, q*) + tau_k^2 w(q*) + g*^T C^ME g*;
optionally (``variance_aware``, not the default: :data:`VARIANCE_AWARE`) a Student-t band there on the
Satterthwaite degrees of freedom nu = 2 var^2 / var(A^) of the estimated new-draw variance A = s_k^2 c + tau_k^2 w
(var(A^) by the delta method over the REML expected information,
:meth:`identification.studies.discrepancy_gp.GPFit.prior_variance_spread`); measured in
bench/bench_model_error.py (``--n-offset``) and not adopted: it does not bring 4 calibration conditions to
nominal coverage and makes the bands of one condition absurdly wide in some campaigns;
``variance_aware="conditions"`` takes var(A^) = 2 A^2 / (c - 1) instead, c the conditions the fit's data hold (a
chi-square variance on c - 1 degrees of freedom; one dof goes to the fixed effects), the rest taken as known
(nu = var^2 (c - 1) / A^2; with c = 1 the band is infinite: nothing calibrates it); with the offset per condition
(``condition_term``) measured in bench/RESULTS.md "Issue 29: bands for a condition not seen", not the default;
with the embedded error (kind "embedded", :mod:`identification.studies.embedded_error`: p + b at a new
condition, b ~ N(0, Omega)) mean h(q*, p^ME) and variance g*^T (C^ME + Omega) g* [+ sigma_k^2];
without model error (kind "none") mean h(q*, p_hat) and variance g*^T C g* [+ sigma_k^2] (the
delta-method bands of the plain fit, C its second-order covariance).  Units: those of z.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import linalg, stats

from identification.fit.problem import ColumnLayout
from identification.inference.results import identify
from identification.inference.results import Estimate
from identification.studies.discrepancy_gp import (GPFit, InputScaling, Observations, WhiteTest, fit_discrepancy,
                                                   reml_information, white_lr_test)
from identification.studies.embedded_error import EmbeddedFit, fit_embedded
from models.errors import NumericsError
from models.sensitivity import sensitivities
from models.state import solve_states

__all__ = ["ErrorFit", "Band", "band_quantile", "band_logpdf", "VARIANCE_AWARE", "VARIANCE_AWARE_MODES", "fit_model_error", "outputs_at", "pure_error_sigma", "CONFOUNDED_INFORMATION",
           "CONFOUNDED_CORRELATION"]

#: bands at a condition not seen are Student-t on the effective degrees of freedom of the estimated new-draw
#: variance (ErrorFit.predict's ``variance_aware``: True Satterthwaite from the REML information, "conditions" on
#: c - 1 degrees of freedom for c conditions); False: the normal plug-in band
VARIANCE_AWARE = False
#: the ``variance_aware`` values ErrorFit.predict accepts
VARIANCE_AWARE_MODES = (False, True, "conditions")
#: rounds of (REML hyperparameters at the current linearisation, generalised least squares in p)
OUTER_ITERATIONS = 5
#: identifiable is False when, along some direction of p, the model error leaves less than this share of the
#: information the noise alone leaves (standard error inflated more than 10 times) ...
CONFOUNDED_INFORMATION = 0.01
#: ... and the discrepancy's correlation leaves less than this share of what uncorrelated errors of the same
#: size would leave (the discrepancy mimics a change of p, rather than being merely large); heuristic thresholds
CONFOUNDED_CORRELATION = 0.5


@dataclass(frozen=True)
class Band:
    """Mean and (1 - alpha) band, each ndarray (n*, n_S) in the unit of z (NaN for unselected sensors).

    ``what``: "prediction" (of the output's mean, or of a new reading) or "discrepancy".  ``grid``: the axes
    between the rows and the sensors of a dynamic model's band (its sampling times), else empty.  ``dof``:
    None for normal bands, else the degrees of freedom of a Student-t band per element (inf: normal).
    """

    mean: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    alpha: float
    sensors: tuple
    what: str
    new_reading: bool = False
    grid: tuple = ()
    dof: np.ndarray | None = None


def outputs_at(model, p: np.ndarray, inputs: np.ndarray, Y0=None) -> tuple:
    """(h (n, n_S), G (n, n_S, n_p)) of the model at p for the input rows (n, d_q), exact G."""
    Y = solve_states(model, p, inputs, Y0)
    s = sensitivities(model, p, inputs, Y)
    return np.asarray(s.h, float), np.asarray(s.G, float)


@dataclass(frozen=True, eq=False)
class ErrorFit:
    """A fit of one data set, without (``gp`` None) or with an output discrepancy.

    Attributes
    ----------
    model : Model
    weights : ndarray (n_S,)          sensor selection
    sigma : ndarray (n_S,)            sensor standard deviations used (unit of z)
    scaling : InputScaling
    plain : Estimate                  the fit without model error
    test : WhiteTest                  'no model error' test on the plain residuals
    p, cov : ndarray                  parameters and their covariance under this fit's error model
    gp : GPFit or None                the output discrepancy (kind "discrepancy")
    embedded : EmbeddedFit or None    the parameters' spread between conditions (kind "embedded")
    alpha_r : ndarray (N,)            V^{-1} r(p) (stacked residual means)
    Vinv_G : ndarray (N, n_p)         V^{-1} G
    Vinv : ndarray (N, N)
    information_kept : float          min generalised eigenvalue of (G^T V^-1 G, G^T D^-1 G): the share of the
                                      noise-only information about p the model error leaves
    correlation_kept : float          min generalised eigenvalue of (G^T V^-1 G, G^T diag(V)^-1 G): the share
                                      uncorrelated errors of the same size would leave
    notes : tuple of str
    layout : ColumnLayout or None     the columns' instruments and coordinates (None: one column per sensor)
    """

    model: object
    weights: np.ndarray
    sigma: np.ndarray
    scaling: InputScaling
    plain: Estimate
    test: WhiteTest
    p: np.ndarray
    cov: np.ndarray
    gp: GPFit | None = None
    alpha_r: np.ndarray | None = None
    Vinv_G: np.ndarray | None = None
    Vinv: np.ndarray | None = None
    information_kept: float = 1.0
    correlation_kept: float = 1.0
    notes: tuple = ()
    embedded: EmbeddedFit | None = None
    layout: ColumnLayout | None = None

    @property
    def kind(self) -> str:
        return "discrepancy" if self.gp is not None else "embedded" if self.embedded is not None else "none"

    @property
    def identifiable(self) -> bool:
        """False when the output discrepancy can mimic a change of p (both shares below their thresholds)."""
        if self.gp is None:
            return True
        return self.information_kept >= CONFOUNDED_INFORMATION or self.correlation_kept >= CONFOUNDED_CORRELATION

    def predict(self, inputs: np.ndarray, alpha: float, new_reading: bool, conditions: np.ndarray | None = None,
                variance_aware: bool | str = VARIANCE_AWARE) -> Band:
        """The (1 - alpha) band of the outputs (``new_reading``: of one new reading) at input rows (n*, d_q) in the
        conditions ``conditions`` (n*,) integer codes (None: the data's one condition; a code the fit's data do not
        hold: a condition not seen, whose discrepancy is a new draw of the process; the discrepancy only);
        ``variance_aware``: at a condition not seen, a Student-t band on the effective degrees of freedom of the
        estimated new-draw variance (:meth:`_dof`; True: Satterthwaite from the REML information, "conditions": the
        new-draw variance on c - 1 degrees of freedom, c the conditions of the fit's data), else (False) the normal
        plug-in band."""
        _check_variance_aware(variance_aware)
        h, G = outputs_at(self.model, self.p, inputs)
        sel = self.weights > 0
        spread = None
        if self.gp is None:
            C = self.cov if self.embedded is None else self.cov + self.embedded.Omega
            var = np.einsum("jkp,pq,jkq->jk", G, C, G)
            mean = h
        else:
            mean, var, spread = self._kriging(inputs, h, G, include_g=True, conditions=conditions,
                                              spread=variance_aware)
        var = np.clip(var, 0.0, None) + (self.sigma ** 2 if new_reading else 0.0)
        return self._band(mean, var, sel, alpha, "prediction", new_reading, self._dof(var, spread))

    def discrepancy(self, inputs: np.ndarray, alpha: float, conditions: np.ndarray | None = None,
                    variance_aware: bool | str = VARIANCE_AWARE) -> Band:
        """The (1 - alpha) band of the discrepancy delta(q*) (zero without model error) in the conditions
        ``conditions`` (as :meth:`predict`)."""
        _check_variance_aware(variance_aware)
        n = np.atleast_2d(inputs).shape[0]
        sel = self.weights > 0
        if self.embedded is not None:
            G = outputs_at(self.model, self.p, inputs)[1]
            var = np.einsum("jkp,pq,jkq->jk", G, self.embedded.Omega, G)
            return self._band(np.zeros_like(var), var, sel, alpha, "discrepancy", False)
        if self.gp is None:
            z = np.zeros((n, len(self.sigma)))
            return self._band(z, z, sel, alpha, "discrepancy", False)
        mean, var, spread = self._kriging(inputs, np.zeros((n, len(self.sigma))), None, include_g=False,
                                          conditions=conditions, spread=variance_aware)
        var = np.clip(var, 0.0, None)
        return self._band(mean, var, sel, alpha, "discrepancy", False, self._dof(var, spread))

    @staticmethod
    def _dof(var: np.ndarray, spread: np.ndarray | None) -> np.ndarray | None:
        """The effective degrees of freedom (n*, n_S) of a band variance ``var`` whose new-draw part A has the
        sampling variance ``spread`` (Satterthwaite: the rest taken as known, nu = 2 var^2 / var(A^)); inf where
        nothing is estimated (a condition seen, or no spread); None without ``spread``."""
        if spread is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(spread > 0, 2 * var ** 2 / spread, np.inf)

    def _kriging(self, inputs, h, G, include_g: bool, conditions=None, spread: bool = False) -> tuple:
        """(mean, var, spread) (n*, n_S): the kriging mean and variance and, with ``spread``, the sampling variance
        of the estimated new-draw variance at rows of a condition not seen (0 elsewhere; None without)."""
        xs = self.scaling(inputs)
        coords = None if self.layout is None else self.scaling.coordinates(self.layout.coords)
        mean = np.full(h.shape, np.nan)
        var = np.full(h.shape, np.nan)
        spr = np.zeros(h.shape) if spread else None
        codes = None if conditions is None else np.asarray(conditions, int)
        for k in self.gp.obs.sensors:
            x = xs if coords is None else np.hstack([xs, np.repeat(coords[k][None], xs.shape[0], 0)])
            i = self.gp.obs.block_of(k)
            kx, prior = self.gp.cross(i, x, conditions)
            mean[:, k] = h[:, k] + kx @ self.alpha_r
            u = (G[:, k, :] if include_g else 0.0) - kx @ self.Vinv_G
            var[:, k] = prior - np.einsum("an,nm,am->a", kx, self.Vinv, kx) + np.einsum("ap,pq,aq->a", u, self.cov, u)
            if spread and codes is not None:
                seen = self.gp.obs.condition_codes(i)
                unseen = ~np.isin(codes, seen)
                if unseen.any() and spread == "conditions":      # a chi-square variance on c - 1 dof
                    c = np.unique(seen).size
                    spr[unseen, k] = 2 * prior[unseen] ** 2 / (c - 1) if c > 1 else np.inf
                elif unseen.any():
                    spr[unseen, k] = self.gp.prior_variance_spread(i, x[unseen])
        return mean, var, spr

    def _band(self, mean, var, sel, alpha, what, new_reading, dof: np.ndarray | None = None) -> Band:
        c = band_quantile(alpha, dof)
        mean = np.where(sel, mean, np.nan)
        half = c * np.sqrt(np.where(sel, var, np.nan))
        return Band(mean, mean - half, mean + half, alpha, tuple(self.plain.sensors), what, new_reading,
                    dof=None if dof is None else np.where(sel, dof, np.nan))


def _check_variance_aware(variance_aware) -> None:
    """Raise ValueError naming ``variance_aware`` unless it is one of :data:`VARIANCE_AWARE_MODES` (False and True by
    identity, so that a truthy typo such as "condition" is refused instead of taken as True)."""
    if not any(variance_aware is m or (isinstance(m, str) and variance_aware == m) for m in VARIANCE_AWARE_MODES):
        raise ValueError(f"variance_aware: expected one of {VARIANCE_AWARE_MODES}, got {variance_aware!r}")


def band_quantile(alpha: float, dof: np.ndarray | None = None):
    """The (1 - alpha / 2) quantile of the standard normal (``dof`` None or inf) or of Student's t on ``dof``
    degrees of freedom (elementwise; dimensionless)."""
    z = float(stats.norm.ppf(1 - alpha / 2))
    if dof is None:
        return z
    dof = np.asarray(dof, float)
    fin = np.isfinite(dof) & (dof > 0)
    with np.errstate(invalid="ignore"):
        t = np.where(fin, stats.t.ppf(1 - alpha / 2, np.where(fin, dof, 1.0)), z)
    return np.where(dof == 0, np.inf, t)                 # no degree of freedom: no band


def band_logpdf(band: Band, z: np.ndarray) -> np.ndarray:
    """log density of readings z (broadcast against band.mean) under the band's predictive distribution: normal,
    or Student's t where the band has finite ``dof`` (log of 1 / unit of z)."""
    q = band_quantile(band.alpha, band.dof)
    scale = (band.upper - band.mean) / q
    normal = stats.norm.logpdf(z, band.mean, scale)
    if band.dof is None:
        return normal
    dof = np.broadcast_to(band.dof, np.broadcast(z, band.mean).shape)
    fin = np.isfinite(dof)
    return np.where(fin, stats.t.logpdf(z, np.where(fin, dof, 1.0), band.mean, scale), normal)


def pure_error_sigma(z: np.ndarray, instrument=None) -> tuple:
    """(s (n_inst,), dof (n_inst,)): the pooled standard deviation of the series about their mean at each input
    (pure error), s_g^2 = sum_ijk (z_ijk - zbar_jk)^2 / sum_jk (n_jk - 1) over the columns k of instrument g
    (``instrument`` (n_S,); None: every column its own) (unit of z; NaN where dof = 0)."""
    mask = np.isfinite(z)
    n = mask.sum(axis=0)
    zbar = np.where(n > 0, np.nansum(z, axis=0) / np.maximum(n, 1), 0.0)
    ss = np.sum(np.where(mask, (z - zbar[None]) ** 2, 0.0), axis=(0, 1))
    dof = np.clip(n - 1, 0, None).sum(axis=0)
    if instrument is not None:
        g = np.asarray(instrument, int)
        ss, dof = np.bincount(g, ss), np.bincount(g, dof).astype(int)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(dof > 0, np.sqrt(ss / dof), np.nan), dof


def _gls(model, data, start: tuple, Y, V: np.ndarray, obs: Observations, zbar_s: np.ndarray) -> tuple:
    """(p, h (n_q, n_S), G (n_q, n_S, n_p), notes): Gauss-Newton on the GLS objective r^T V^-1 r from
    ``start`` = (p, h, G) (states Y as the state solves' guess)."""
    L = linalg.cholesky(V, lower=True)
    p, h, G = start
    notes = []
    for _ in range(8):
        r, Gs = zbar_s - obs.stack(h), obs.stack(G)
        wr, wG = linalg.solve_triangular(L, r, lower=True), linalg.solve_triangular(L, Gs, lower=True)
        step = linalg.cho_solve(linalg.cho_factor(wG.T @ wG, lower=True), wG.T @ wr)
        obj = float(wr @ wr)
        for _half in range(6):
            cand = p + step
            try:
                hc, Gc = outputs_at(model, cand, data.inputs, Y)
            except NumericsError:                  # the states do not solve there: a shorter step
                step = step / 2
                continue
            rc = linalg.solve_triangular(L, zbar_s - obs.stack(hc), lower=True)
            if float(rc @ rc) <= obj * (1 + 1e-12):
                break
            step = step / 2
        else:
            notes.append("the generalised least-squares refit of p stopped: no step decreased its objective")
            break
        p, h, G = cand, hc, Gc
        if np.all(np.abs(step) <= 1e-9 * (np.abs(p) + 1e-12)):
            break
    return p, h, G, tuple(notes)


def _information_kept(Gs: np.ndarray, V: np.ndarray, Vinv: np.ndarray, noise: np.ndarray) -> tuple:
    """(min generalised eigenvalue of (G^T V^-1 G, G^T D^-1 G), of (G^T V^-1 G, G^T diag(V)^-1 G)): the share of
    the parameters' information the model error leaves against the noise D alone and against uncorrelated
    errors of the same size (1: nothing lost; near 0: that direction of p is not determined)."""
    A = Gs.T @ Vinv @ Gs
    out = []
    for d in (noise, np.diag(V)):
        try:
            out.append(float(linalg.eigh(A, Gs.T @ (Gs / d[:, None]), eigvals_only=True)[0]))
        except linalg.LinAlgError:
            out.append(0.0)
    return tuple(out)


def fit_model_error(model, data, p0, weights: np.ndarray, scaling: InputScaling, kind: str,
                    plain: Estimate | None = None, groups: np.ndarray | None = None,
                    layout: ColumnLayout | None = None, condition_term: bool = False) -> ErrorFit:
    """The :class:`ErrorFit` of ``data`` (sigma known) for ``kind`` "none", "discrepancy" or "embedded": the
    plain fit, the test and the error model (REML) with the generalised least-squares refit of p.  ``plain``:
    the plain fit when already done; ``groups`` (n_q,) integer condition of every input row: of the embedded error
    (None: each row its own) and of the discrepancy (independent between conditions; None: one condition); ``layout`` the columns' instruments and coordinates (one discrepancy per instrument
    over inputs and coordinates; None: one per column over inputs); ``condition_term`` the discrepancy's third
    hyperparameter an offset per condition (omega_k^2 [g = g']) instead of the rough part (not the default, measured
    in bench/RESULTS.md "Issue 29: bands for a condition not seen"; no ``exact_at`` pins with it).  Raises
    numpy.linalg.LinAlgError when a covariance is not positive definite, ValueError for pins with ``condition_term``."""
    if condition_term and scaling.pins:
        raise ValueError("condition_term: an offset per condition cannot vanish at exact_at; give one or the other")
    est = plain if plain is not None else identify(model, data, p0, weights=weights)
    sigma = np.asarray(data.sigma, float)
    obs = (Observations.of(data.counts(), sigma, weights, scaling(data.inputs), conditions=groups,
                           condition_term=condition_term) if layout is None
           else Observations.of(data.counts(), sigma, weights, scaling(data.inputs), layout.instrument,
                                scaling.coordinates(layout.coords), conditions=groups, condition_term=condition_term))
    zbar_s = obs.stack(np.nan_to_num(data.means()))
    Gs = obs.stack(np.asarray(est.G, float))
    r0 = zbar_s - obs.stack(np.asarray(est.fitted, float))
    test = white_lr_test(obs, Gs, r0)
    if kind == "none":
        return ErrorFit(model, weights, sigma, scaling, est, test, est.p.copy(), np.asarray(est.cov, float),
                        layout=layout)
    noise = np.concatenate(obs.noise)
    cond = (np.arange(data.n_q) if groups is None else np.asarray(groups))[np.concatenate(obs.rows)]
    se = np.asarray(est.stderr_gn, float)

    def error_model(Gs, r, starts):
        if kind == "discrepancy":
            f = fit_discrepancy(obs, Gs, r, scaling.pins, starts)
            return f, f.covariance(), f.converged, f.theta
        f = fit_embedded(Gs, cond, noise, se, r, starts)
        return f, f.V, f.converged, f.c

    Y = np.asarray(est.states, float) if model.n_y else None
    fitted, V, converged, theta = error_model(Gs, r0, None)
    p, h, G, notes = _gls(model, data, (est.p.copy(), np.asarray(est.fitted, float), np.asarray(est.G, float)), Y,
                          V, obs, zbar_s)
    moved = np.inf
    for _ in range(OUTER_ITERATIONS - 1):          # REML at the new linearisation, GLS under it, to a fixed point
        fitted, V, converged, new = error_model(obs.stack(G), zbar_s - obs.stack(h), (theta,))
        p, h, G, notes = _gls(model, data, (p, h, G), None, V, obs, zbar_s)
        moved, theta = float(np.max(np.abs(new - theta))), new
        if moved < 1e-3:
            break
    else:
        notes += (f"the alternation of REML and generalised least squares stopped after {OUTER_ITERATIONS} rounds "
                  f"(last change of log hyperparameters {moved:.2g})",)
    if kind == "discrepancy":                    # the information at the final linearisation (bands, not p)
        fitted = replace(fitted, information=reml_information(fitted.theta, obs, obs.stack(G), scaling.pins))
    gp, emb = (fitted, None) if kind == "discrepancy" else (None, fitted)
    if not converged:
        notes += (f"the {kind}'s REML optimiser stopped before convergence (best start kept)",)
    Vinv = linalg.cho_solve((linalg.cholesky(V, lower=True), True), np.eye(len(V)))
    Gs = obs.stack(G)
    cov = linalg.cho_solve(linalg.cho_factor(Gs.T @ Vinv @ Gs, lower=True), np.eye(len(p)))
    r = zbar_s - obs.stack(h)
    kept, corr = _information_kept(Gs, V, Vinv, noise)
    return ErrorFit(model, weights, sigma, scaling, est, test, p, cov, gp, Vinv @ r, Vinv @ Gs, Vinv, kept, corr,
                    notes, emb, layout)
