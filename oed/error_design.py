r"""Designs that learn the model error (issue 29 item 3): the next runs that most shrink the prediction band where
the model will be used.

After :func:`identification.model_error`, the output of sensor k at input q is
:math:`f_k(q) = h_k(q, p) + \delta_k(q) + \rho_k(q)`: the model, its output discrepancy (a Gaussian process
:math:`\delta_k \sim GP(0, K_k)`) and a rough part :math:`\rho_k` independent between conditions; a reading adds
:math:`\varepsilon \sim N(0, \sigma_k^2 / r)` (r series averaged).  Linearised at the estimate
(:math:`h_k(q, p) \approx h_k(q, \hat p) + g_k(q)^\top (p - \hat p)`, :math:`g = \partial h / \partial p` exact) and
with the hyperparameters fixed at their REML values, the parameters are **flat a priori** (universal kriging): all
their information comes from the data, the campaign measured and the runs added.  The posterior variance of
:math:`f_k(q^*)` after the measured data (:math:`V` their residual covariance, :math:`C = (G^\top V^{-1} G)^{-1}`,
:math:`k_a = \operatorname{cov}(\delta(a), \text{residuals})`, :math:`u_a = g_a - G^\top V^{-1} k_a`) is the kriging
variance of :meth:`identification.studies.model_error_result.ModelErrorResult.predict`, and between two points

.. math::

    \Sigma(a, b) = K(a, b) - k_a^\top V^{-1} k_b + u_a^\top C\, u_b

(a Gaussian posterior, proper once C exists).  New runs S read :math:`y_o = f(o) + \eta_o` at their points o with
the noise :math:`N_S` (:math:`\tau_k^2 w(q) + \sigma_k^2/r` per reading, a new condition per run); conditioning the
current posterior on them is the universal kriging on old and new data together, with the variance at target t

.. math::

    v_t(S) = \Sigma_{tt} + \nu_t - \Sigma_{tS}\,(\Sigma_{SS} + N_S)^{-1}\,\Sigma_{St}

(:math:`\nu_t = \tau_k^2 w(q_t)` the rough part of the target, which no run removes).  It does not depend on the
readings, so it is known before measuring.  The criterion over a region of use (points :math:`q_r` with weights
:math:`\omega_r`, :math:`\sum_r\omega_r = 1`, and the target sensors T), in units of each sensor's
:math:`\sigma_k^2`:

.. math::

    J_{int}(S) = \sum_r \omega_r \frac1{|T|}\sum_{k\in T} \frac{v_{rk}(S)}{\sigma_k^2},\qquad
    J_{worst}(S) = \max_{r,k} \frac{v_{rk}(S)}{\sigma_k^2},

minimised over the sets of n distinct candidate runs (a candidate reads the measured sensors at one input row, or
with ``pairs=True`` one sensor at one row) by :func:`oed.error_design_search.search`: complete enumeration, or a
branch-and-bound with proven bounds (convexity of the relaxation), or greedy + exchange with the gap to the
root bound.  The band half-width is :math:`z_{1-\alpha/2}\sqrt{v}` (unit of z), the one of ``predict`` before the
runs.  With the embedded error (kind "embedded": p + b per condition, :math:`b\sim N(0,\Omega)`) a new run's
noise holds :math:`g\,\Omega\,g^\top` (one b across its sensors) and the target's :math:`\nu = g^\top\Omega g`; without
model error (kind "none") :math:`\Sigma = g^\top C g` of the plain fit.  A dynamic model falls out: the points are
(experiment, instrument, sampling time) columns of the static problem, one process per instrument over inputs and
time.

**Conditions** (a model error computed with ``groups``, e.g. the loading and unloading branches of a press): the
discrepancy of each condition g is its own draw :math:`\delta_k(q, g)`, independent between conditions with common
hyperparameters, so every point above carries its condition and :math:`K(a, b)` holds the factor
:math:`[g_a = g_b]`, :math:`k_a` the cross-covariance with the data of condition :math:`g_a` only.  A candidate run
carries its condition (``candidate_conditions``): one the data hold shrinks that condition's discrepancy (and every
band through the parameters); :data:`identification.studies.model_error_result.NEW_CONDITION` ("new") is the one
condition the data do not hold (no cross-covariance with the data: a new draw), shared by the runs and the region's
points in it.  The region names its condition(s) (``region_conditions``: the region in each, equal shares).
"""
from __future__ import annotations

import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from scipy import linalg, stats

from identification.results_protocol import ResultProtocol, jsonable, notes_lines
from identification.studies.discrepancy_gp import kernel_blocks, rough_weight
from identification.studies.model_error_fit import outputs_at
from identification.studies.model_error_result import NEW_CONDITION
from .error_design_search import SEARCH_METHODS, VarianceProblem, search

__all__ = ["ErrorDesignResult", "ErrorDesignProblem", "error_design_problem", "select_error_design", "CRITERIA",
           "region_grid"]

#: the criteria over the region: the weighted mean or the largest posterior prediction variance
CRITERIA = ("integrated", "worst")
#: what the parameters are a priori (universal kriging: flat, all information from the data)
PARAMETER_PRIOR = "flat (universal kriging: the parameters' information comes from the measured data and the new runs)"


# ---------------------------------------------------------------------------- region and validation
def region_grid(box: Mapping, names: tuple, size: int, criterion: str) -> tuple:
    """(points (n_r, d_q), weights (n_r,)) of a box {input: (low, high)} over every input ``names``: the product
    Gauss-Legendre rule of ``size`` nodes per input (``criterion`` "integrated": the mean over the box) or the
    uniform grid of ``size`` levels per input, ends included, equal weights ("worst")."""
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
        raise ValueError(f"region_size: expected an integer >= 1, got {size!r}")
    missing = [n for n in names if n not in box]
    unknown = [n for n in box if n not in names]
    if missing or unknown:
        raise ValueError(f"region: a box needs (low, high) for every input {list(names)}"
                         + (f"; missing {missing}" if missing else "") + (f"; unknown {unknown}" if unknown else ""))
    axes, wts = [], []
    for n in names:
        try:
            lo, hi = (float(v) for v in box[n])
        except (TypeError, ValueError):
            raise ValueError(f"region[{n!r}]: expected (low, high), got {box[n]!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise ValueError(f"region[{n!r}]: expected finite low <= high, got ({lo}, {hi})")
        if criterion == "integrated":
            t, w = np.polynomial.legendre.leggauss(int(size))
            axes.append(lo + (hi - lo) * (t + 1) / 2)
            wts.append(w / 2)
        else:
            axes.append(np.linspace(lo, hi, int(size)))
            wts.append(np.full(int(size), 1.0 / size))
    mesh = np.meshgrid(*axes, indexing="ij")
    wmesh = np.meshgrid(*wts, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1), np.prod([w.ravel() for w in wmesh], axis=0)


def _rows(a, d: int, name: str) -> np.ndarray:
    """Input rows (n, d) of ``a`` (ValueError naming ``name``)."""
    try:
        x = np.asarray(a, float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers of shape (n, {d}), got {a!r}") from None
    x = x.reshape(-1, 1) if x.ndim == 1 and d == 1 else x
    if x.ndim != 2 or x.shape[1] != d or x.shape[0] == 0:
        raise ValueError(f"{name}: expected input rows of shape (n, {d}), got shape {np.shape(a)}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name}: every input must be finite")
    return x


def _region(region, weights, names: tuple, size: int, criterion: str) -> tuple:
    if isinstance(region, Mapping):
        if weights is not None:
            raise ValueError("region_weights: a box region brings its own quadrature weights; give none")
        return region_grid(region, names, size, criterion)
    pts = _rows(region, len(names), "region")
    if weights is None:
        return pts, np.full(len(pts), 1.0 / len(pts))
    w = np.asarray(weights, float).ravel()
    if w.shape != (len(pts),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"region_weights: expected {len(pts)} finite non-negative weights with a positive sum")
    return pts, w / w.sum()


def _names(value, allowed: tuple, name: str) -> tuple:
    """Sensor names (a subset of ``allowed``; None: all of them)."""
    if value is None:
        return allowed
    value = (value,) if isinstance(value, str) else tuple(value)
    bad = [v for v in value if v not in allowed]
    if bad or not value:
        raise ValueError(f"{name}: expected names among the sensors of the model error {list(allowed)}, got "
                         f"{list(value)}")
    return tuple(dict.fromkeys(value))


def _checked_result(result):
    fit = getattr(result, "fit", None)
    if fit is None or not hasattr(result, "kind") or getattr(fit, "layout", None) is None:
        raise ValueError("result: expected the ModelErrorResult of identification.model_error (with its fit)")
    if result.kind == "discrepancy" and fit.gp is None:
        raise ValueError("result: kind 'discrepancy' without its Gaussian process")
    if fit.gp is not None and fit.gp.obs.condition_term:      # its third hyperparameter is no rough part
        raise ValueError("result: a discrepancy with an offset per condition (condition_term) has no error design")
    return fit


def _condition_code(result, label, name: str) -> int:
    """The code of one condition label: the index of a label of ``result.groups``, -1 for :data:`NEW_CONDITION`
    (a condition the data do not hold), 0 for None without groups (the data's one condition)."""
    groups = tuple(result.groups)
    if isinstance(label, str) and label == NEW_CONDITION:
        return -1
    if label is None and not groups:
        return 0
    for i, g in enumerate(groups):
        if isinstance(g, str) == isinstance(label, str) and bool(np.all(g == label)):
            return i
    allowed = (f"one of the model error's conditions {list(groups)} or {NEW_CONDITION!r} (a condition the data do "
               "not hold)") if groups else (f"None (the data's one condition) or {NEW_CONDITION!r} (a condition the "
                                            "data do not hold): the model error names no conditions (groups)")
    raise ValueError(f"{name}: unknown condition {label!r}; expected {allowed}")


def _labels(value) -> list | None:
    """A sequence of labels as a list, None for one label (a string, a number, None)."""
    if value is None or isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
        return None
    return list(value)


def _region_conditions(result, value) -> tuple:
    """The conditions the region is used in (labels, codes): ``value`` one label or a sequence of them (the region
    in each, an equal share of the weight); None: every condition the data hold (the data's one without groups)."""
    if value is None:
        labels = list(result.groups) if result.groups else [None]
    else:
        seq = _labels(value)
        labels = [value] if seq is None else seq
        if not labels:
            raise ValueError("region_conditions: expected a condition label or a non-empty sequence of them")
    codes = [_condition_code(result, lab, "region_conditions") for lab in labels]
    if len(set(codes)) != len(codes):
        raise ValueError(f"region_conditions: a condition is named twice in {labels!r}")
    return tuple(labels), np.array(codes, int)


def _candidate_conditions(result, value, n_c: int) -> tuple:
    """(rows (n_e,), labels (n_e,), codes (n_e,)): every candidate run as an input row in its condition; ``value``
    one label (every row in it), one per candidate row (n_c,), or None (every row in every condition the data hold;
    the data's one without groups)."""
    if value is None:
        labels = list(result.groups) if result.groups else [None]
        rows = np.repeat(np.arange(n_c), len(labels))
        return rows, tuple(labels) * n_c, np.tile([_condition_code(result, g, "candidate_conditions")
                                                  for g in labels], n_c)
    seq = _labels(value)
    if seq is not None and len(seq) != n_c:
        raise ValueError(f"candidate_conditions: expected one condition label or one per candidate row ({n_c}), "
                         f"got {len(seq)}")
    labels = [value] * n_c if seq is None else seq
    return np.arange(n_c), tuple(labels), np.array([_condition_code(result, g, "candidate_conditions")
                                                   for g in labels], int)


def _int_in(v, lo: int, hi: int, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
        raise ValueError(f"{name}: expected an integer in {lo}..{hi}, got {v!r}")
    return int(v)


# ---------------------------------------------------------------------------- the posterior covariance
@dataclass(frozen=True)
class _Points:
    """Latent points: input rows q (n, d_q), static-problem columns k (n,), h's sensitivities g (n, n_p) and the
    condition code of each (n,) (a code of the data's conditions, -1 a condition the data do not hold)."""

    q: np.ndarray
    col: np.ndarray
    g: np.ndarray
    cond: np.ndarray

    def take(self, idx) -> "_Points":
        return _Points(self.q[idx], self.col[idx], self.g[idx], self.cond[idx])


def _points(fit, p, rows: np.ndarray, cols: np.ndarray, codes: np.ndarray) -> _Points:
    """Every (row, column) pair, row-major, with g = dh_k/dp at the row (exact, CasADi), in the rows' conditions
    ``codes`` (n_rows,)."""
    _, G = outputs_at(fit.model, p, rows)
    q = np.repeat(rows, len(cols), axis=0)
    c = np.tile(cols, len(rows))
    g = G[:, cols, :].reshape(len(rows) * len(cols), -1)
    return _Points(q, c, g, np.repeat(np.asarray(codes, int), len(cols)))


def _scaled(fit, pts: _Points) -> tuple:
    """(scaled coordinates (n, d) of the points, their discrepancy block (n,))."""
    x = fit.scaling(pts.q)
    lay = fit.layout
    if lay.coord_names:
        x = np.hstack([x, fit.scaling.coordinates(lay.coords)[pts.col]])
    blk = np.array([fit.gp.obs.block_of(int(k)) for k in pts.col], int)
    return x, blk


def _covariance(fit, C: np.ndarray, pts: _Points) -> tuple:
    r"""(Sigma (n, n): the current posterior covariance of f at the points, nu (n,): their rough variance) of the
    discrepancy's universal kriging (module docstring); without a discrepancy g C g^T and zeros."""
    if fit.gp is None:
        return pts.g @ C @ pts.g.T, np.zeros(len(pts.col))
    gp = fit.gp
    x, blk = _scaled(fit, pts)
    n, N = len(blk), sum(gp.obs.sizes)
    K, kx, nu = np.zeros((n, n)), np.zeros((n, N)), np.zeros(n)
    for i in np.unique(blk):
        m = blk == i
        ell = gp.length_scale(int(i))
        same = pts.cond[m][:, None] == pts.cond[m][None, :]          # one draw of the discrepancy per condition
        K[np.ix_(m, m)] = gp.amplitude(int(i)) ** 2 * kernel_blocks(x[m], x[m], ell, gp.pins)[0] * same
        kx[m] = gp.cross(int(i), x[m], pts.cond[m])[0]
        nu[m] = gp.rough(int(i)) ** 2 * rough_weight(x[m], ell, gp.pins)[0]
    u = pts.g - kx @ fit.Vinv_G
    S = K - kx @ fit.Vinv @ kx.T + u @ C @ u.T
    return (S + S.T) / 2, nu


# ---------------------------------------------------------------------------- the problem
@dataclass(frozen=True, eq=False)
class ErrorDesignProblem:
    """The design problem of :func:`error_design_problem`: the region, the candidates and the whitened
    :class:`oed.error_design_search.VarianceProblem`.

    Attributes
    ----------
    core : VarianceProblem
    region : ndarray (n_r, d_q)           the region's points (model input units)
    region_weights : ndarray (n_r,)       their weights (sum 1)
    candidates : ndarray (n_c, d_q)       the candidate input rows
    candidate_rows : ndarray (n_cand,)    the row of every candidate (a row, or a (row, sensor) pair)
    candidate_sensors : tuple of tuple    the sensors every candidate reads
    target_labels : tuple of str          the target columns (a sensor; a dynamic model: sensor at a time)
    target_sigma : ndarray (n_tc,)        their sigma (unit of z)
    criterion : str
    repeats : int
    input_names : tuple of str
    irreducible : ndarray (n_T,)          the targets' variance no run removes (rough part or embedded deviation,
                                          sigma^2 units, region-major like ``core.d``)
    target_sensors : tuple of str         the sensor of every target column
    candidate_conditions : tuple          the condition label of every candidate (None: the data's one condition;
                                          :data:`NEW_CONDITION`: a condition the data do not hold)
    region_conditions : tuple             the condition label of every region point (the region's points repeated
                                          in each condition named, condition-major)
    """

    core: VarianceProblem
    region: np.ndarray
    region_weights: np.ndarray
    candidates: np.ndarray
    candidate_rows: np.ndarray
    candidate_sensors: tuple
    target_labels: tuple
    target_sigma: np.ndarray
    criterion: str
    repeats: int
    input_names: tuple
    irreducible: np.ndarray
    target_sensors: tuple
    candidate_conditions: tuple = ()
    region_conditions: tuple = ()

    @property
    def floor(self) -> float:
        """J of the irreducible variances alone: no set of runs goes below it (sigma^2 units)."""
        return float(self.core.criterion(self.irreducible))

    @property
    def n_candidates(self) -> int:
        return self.core.n_candidates

    def _sets(self, indices) -> np.ndarray:
        s = np.asarray(indices, int).reshape(-1) if np.ndim(indices) <= 1 else np.asarray(indices, int)
        s = s[None] if s.ndim == 1 else s
        if s.size and (s.min() < 0 or s.max() >= self.n_candidates):
            raise ValueError(f"indices: candidate indices must be in 0..{self.n_candidates - 1}")
        return s

    def value(self, indices=()) -> float:
        """J after adding the candidates ``indices`` (sigma^2 units; () the value now)."""
        return float(self.core.values(self._sets(indices))[0])

    def variances(self, indices=()) -> np.ndarray:
        """The posterior variances (n_r, n_tc) at the region's points and target columns after adding
        ``indices`` (unit of z squared)."""
        v = self.core.variances(self._sets(indices))[0]
        return v.reshape(len(self.region), -1) * self.target_sigma[None] ** 2

    def half_widths(self, indices=(), alpha: float = 0.05) -> np.ndarray:
        """z_{1-alpha/2} sqrt(variances) (n_r, n_tc), unit of z."""
        if not (isinstance(alpha, (int, float)) and 0 < alpha < 1):
            raise ValueError(f"alpha: expected a number in (0, 1), got {alpha!r}")
        return float(stats.norm.ppf(1 - alpha / 2)) * np.sqrt(np.clip(self.variances(indices), 0.0, None))


def _columns(fit, names: tuple) -> np.ndarray:
    """The selected static-problem columns of the instruments ``names``."""
    lay = fit.layout
    return np.array([k for k in range(len(lay.instrument)) if fit.weights[k] > 0
                     and lay.names[lay.instrument[k]] in names], int)


def _label(lay, k: int) -> str:
    name = lay.names[lay.instrument[k]]
    if not lay.coord_names:
        return name
    return name + " at " + ", ".join(f"{c}={v:g}" for c, v in zip(lay.coord_names, lay.coords[k]))


def _noise(result, fit, pts: _Points, nu: np.ndarray, repeats: int) -> np.ndarray:
    """The noise covariance of a run's readings (n_o, n_o): rough part and sigma^2 / repeats (discrepancy; none),
    or g Omega g^T and sigma^2 / repeats (embedded)."""
    N = np.diag(nu + fit.sigma[pts.col] ** 2 / repeats)
    if result.kind == "embedded":
        Om = np.diag(np.array([e.omega for e in result.embedded], float) ** 2)
        N = N + pts.g @ Om @ pts.g.T
    return N


def error_design_problem(result, candidates, *, region, region_weights=None, criterion: str = "integrated",
                         sensors=None, measure=None, pairs: bool = False, repeats: int = 1,
                         region_size: int = 9, candidate_conditions=None,
                         region_conditions=None) -> ErrorDesignProblem:
    r"""The problem :math:`\min_{|S|=n} J(S)` of the module docstring for a model error ``result``, without
    solving it (:meth:`ErrorDesignProblem.value` of any set; :func:`select_error_design` solves it).

    Parameters
    ----------
    result : ModelErrorResult         of :func:`identification.model_error` (static or dynamic model)
    candidates : array_like (n_c, d_q)  candidate input rows (model input units)
    region : array_like (n_r, d_q) or mapping {input: (low, high)}   where the model will be used: points, or a box
                                      (a product Gauss-Legendre rule of ``region_size`` nodes per input for
                                      "integrated", a uniform grid with its ends for "worst")
    region_weights : array_like (n_r,), optional   weights of the points (None: equal)
    criterion : "integrated" or "worst"
    sensors : sequence of str, optional   the sensors whose band matters (None: every sensor of the model error)
    measure : sequence of str, optional   the sensors a new run reads (None: every sensor of the model error)
    pairs : bool                      candidates are (row, sensor) pairs (one reading each) instead of rows
    repeats : int >= 1                series averaged per run (the noise sigma^2 / repeats; the rough part stays)
    region_size : int                 nodes per input of a box region
    candidate_conditions : label, sequence of n_c labels, or None
        the condition of every candidate row (the discrepancy only): a label of ``result.groups`` (a run there
        shrinks that condition's discrepancy), :data:`NEW_CONDITION` ("new": the one condition the data do not hold,
        shared with the region's points in it), one label for every row, or None: every row offered in every
        condition the data hold (without groups: the data's one condition)
    region_conditions : label, sequence of labels, or None
        the condition(s) the model will be used in (the discrepancy only): the region in each of them, an equal share
        of the weight each; None: every condition the data hold (without groups: the data's one condition)
    """
    fit = _checked_result(result)
    if result.kind != "discrepancy" and (candidate_conditions is not None or region_conditions is not None):
        raise ValueError(f"{'candidate' if candidate_conditions is not None else 'region'}_conditions: runs and "
                         f"regions in named conditions need the discrepancy (kind 'discrepancy'); the error model is "
                         f"{result.kind!r}")
    if criterion not in CRITERIA:
        raise ValueError(f"criterion: expected one of {CRITERIA}, got {criterion!r}")
    names = tuple(fit.model.inputs)
    pts_r, w_r = _region(region, region_weights, names, region_size, criterion)
    cand = _rows(candidates, len(names), "candidates")
    targets = _names(sensors, tuple(result.sensors), "sensors")
    measured = _names(measure, tuple(result.sensors), "measure")
    repeats = _int_in(repeats, 1, 10 ** 9, "repeats")
    if not isinstance(pairs, (bool, np.bool_)):
        raise ValueError(f"pairs: expected True or False, got {pairs!r}")
    lay = fit.layout
    if result.kind == "discrepancy":
        r_labels, r_codes = _region_conditions(result, region_conditions)
        e_rows, e_labels, e_codes = _candidate_conditions(result, candidate_conditions, len(cand))
    else:                              # no discrepancy: every run a new condition, the region in the data's
        r_labels, r_codes = (None,), np.zeros(1, int)
        e_rows, e_labels, e_codes = np.arange(len(cand)), (None,) * len(cand), np.zeros(len(cand), int)
    n_r0 = len(pts_r)
    pts_r, w_r = np.vstack([pts_r] * len(r_codes)), np.tile(w_r, len(r_codes)) / len(r_codes)
    tcols, mcols = _columns(fit, targets), _columns(fit, measured)
    T = _points(fit, fit.p, pts_r, tcols, np.repeat(r_codes, n_r0))
    O = _points(fit, fit.p, cand[e_rows], mcols, e_codes)
    allp = _Points(np.vstack([T.q, O.q]), np.concatenate([T.col, O.col]), np.vstack([T.g, O.g]),
                   np.concatenate([T.cond, O.cond]))
    S, nu = _covariance(fit, np.asarray(result.cov, float), allp)
    nT = len(T.col)
    groups, rows, sens, conds = [], [], [], []
    inst = lay.instrument[mcols]
    for j in range(len(e_rows)):
        base = j * len(mcols)
        parts = ([np.arange(len(mcols))] if not pairs else
                 [np.flatnonzero(inst == g) for g in dict.fromkeys(inst.tolist())])
        for part in parts:
            groups.append(base + part)
            rows.append(int(e_rows[j]))
            conds.append(e_labels[j])
            sens.append(tuple(dict.fromkeys(lay.names[lay.instrument[mcols[m]]] for m in part)))
    Linv = np.zeros((len(O.col), len(O.col)))
    for gr in groups:
        N = _noise(result, fit, O.take(gr), nu[nT + gr], repeats)
        try:
            L = linalg.cholesky(N, lower=True)
        except linalg.LinAlgError:
            raise ValueError("result: the noise covariance of a new run is not positive definite (a sensor's sigma "
                             "is zero?)") from None
        Linv[np.ix_(gr, gr)] = linalg.solve_triangular(L, np.eye(len(gr)), lower=True)
    sig_t = fit.sigma[T.col]
    floor = nu[:nT].copy()
    if result.kind == "embedded":
        Om = np.diag(np.array([e.omega for e in result.embedded], float) ** 2)
        floor = floor + np.einsum("tp,pq,tq->t", T.g, Om, T.g)
    d = np.diag(S)[:nT] + floor
    A = (S[:nT, nT:] @ Linv.T) / sig_t[:, None]
    B = Linv @ S[nT:, nT:] @ Linv.T
    w = np.repeat(w_r, len(tcols)) / len(tcols)
    core = VarianceProblem(d / sig_t ** 2, A, (B + B.T) / 2, tuple(np.asarray(g, int) for g in groups), w,
                           criterion == "worst")
    return ErrorDesignProblem(core, pts_r, w_r, cand, np.array(rows, int), tuple(sens),
                              tuple(_label(lay, int(k)) for k in tcols), fit.sigma[tcols].copy(), criterion, repeats,
                              names, floor / sig_t ** 2, tuple(lay.names[lay.instrument[k]] for k in tcols),
                              tuple(conds), tuple(lab for lab in r_labels for _ in range(n_r0)))


# ---------------------------------------------------------------------------- the result
@dataclass(frozen=True, eq=False)
class ErrorDesignResult(ResultProtocol):
    """The n runs that most shrink the prediction band over the region (:func:`select_error_design`; the result
    protocol: :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    model_name, kind : str               the model and its error model ("discrepancy", "embedded", "none")
    criterion : str                      "integrated" (weighted mean) or "worst" (largest) posterior variance
    chosen : tuple of int                the chosen candidates (indices into the candidates, or the pairs)
    chosen_inputs : ndarray (n, d_q)     their input rows (model input units)
    chosen_sensors : tuple of tuple      the sensors each chosen run reads
    input_names : tuple of str
    target_labels : tuple of str         the target columns (sensor, or sensor at a time)
    target_sensors : tuple of str        the sensor of every target column
    value_before, value_after : float    J now and after the runs (each sensor's sigma^2 units)
    irreducible : float                  J of the part no run removes (the targets' rough part or embedded
                                         deviation): below every design's value
    lower_bound : float                  proven: no n candidates give J below it
    gap : float                          value_after - lower_bound (0 when proven by enumeration)
    proven : bool                        optimal over the candidates within the branch-and-bound's tolerance
    status, method : str                 "optimal", "time_limit", "node_limit", "heuristic"; "enumerate", "bnb",
                                         "greedy"
    nodes, n_evaluated : int
    region : ndarray (n_r, d_q)
    region_weights : ndarray (n_r,)
    half_before, half_after : ndarray (n_r, n_tc)   band half-widths z_{1-alpha/2} sqrt(v) (unit of z)
    alpha : float
    repeats : int                        series per new run
    parameter_prior : str
    wall_time : float                    seconds
    notes : tuple of str
    chosen_conditions : tuple            the condition of each chosen run (None: the data's one condition;
                                         :data:`NEW_CONDITION`: the condition the data do not hold)
    region_conditions : tuple            the condition of every region point (None: the data's one condition)
    """

    model_name: str
    kind: str
    criterion: str
    chosen: tuple
    chosen_inputs: np.ndarray
    chosen_sensors: tuple
    input_names: tuple
    target_labels: tuple
    target_sensors: tuple
    value_before: float
    value_after: float
    irreducible: float
    lower_bound: float
    gap: float
    proven: bool
    status: str
    method: str
    nodes: int
    n_evaluated: int
    region: np.ndarray
    region_weights: np.ndarray
    half_before: np.ndarray
    half_after: np.ndarray
    alpha: float
    repeats: int
    parameter_prior: str = PARAMETER_PRIOR
    wall_time: float = 0.0
    notes: tuple = ()
    chosen_conditions: tuple = ()
    region_conditions: tuple = ()

    @property
    def _named(self) -> bool:
        """Conditions are named (a label other than the data's one condition)."""
        return any(c is not None for c in tuple(self.chosen_conditions) + tuple(self.region_conditions))

    def _runs(self) -> str:
        conds = self.chosen_conditions if self._named else (None,) * len(self.chosen_sensors)
        return "; ".join(", ".join(f"{n} = {v:.6g}" for n, v in zip(self.input_names, row))
                         + f" [{', '.join(sens)}]" + ("" if c is None else f" in {c}")
                         for row, sens, c in zip(np.asarray(self.chosen_inputs), self.chosen_sensors, conds))

    def summary(self) -> str:
        """The chosen runs, the criterion before and after with the proof, the band per target over the region
        (mean and largest half-width before and after) and numbered notes."""
        proof = ("proven optimal" if self.proven else f"NOT proven optimal: {self.status}, proven gap "
                 f"{self.gap:.3g} (lower bound {self.lower_bound:.6g})")
        via = {"enumerate": "by enumeration", "bnb": f"by branch-and-bound, {self.nodes} nodes",
               "greedy": "by greedy + exchange"}[self.method]
        what = "weighted mean" if self.criterion == "integrated" else "largest"
        lines = [f"Design that learns the model error of {self.model_name or 'the model'} ({self.kind}): "
                 f"{len(self.chosen)} run(s), {self.repeats} series each",
                 f"  runs: {self._runs()}",
                 f"  {what} posterior prediction variance over the region ({len(self.region)} points"
                 + (f" in {', '.join(map(str, dict.fromkeys(self.region_conditions)))}" if self._named else "")
                 + ", sigma^2 units): "
                 f"{self.value_before:.6g} -> {self.value_after:.6g}, of which no run removes {self.irreducible:.6g} "
                 f"({proof}; {via}, {self.n_evaluated} sets evaluated, {self.wall_time:.2f} s)", "",
                 "band half-width (unit of the sensor; over the region" + (" and the sampling times" if
                 len(self.target_labels) > len(set(self.target_sensors)) else "") + ")",
                 f"{'sensor':<16} {'mean before':>12} {'after':>10} {'max before':>11} {'after':>10}"]
        w = np.asarray(self.region_weights)
        sens = np.asarray(self.target_sensors)
        for name in dict.fromkeys(self.target_sensors):
            m = sens == name
            hb, ha = self.half_before[:, m], self.half_after[:, m]
            lines.append(f"{name:<16.16} {w @ hb.mean(axis=1):>12.4g} {w @ ha.mean(axis=1):>10.4g} {hb.max():>11.4g} "
                         f"{ha.max():>10.4g}")
        return "\n".join(lines + notes_lines(self.notes))

    def to_frame(self):
        """One row per region point and target: the inputs, ``target``, ``weight``, ``half_before``, ``half_after``
        (unit of z) and ``shrink`` (after / before); ``.attrs``: criterion, values, proof, the chosen runs."""
        import pandas as pd
        n_r, n_t = self.half_before.shape
        df = pd.DataFrame(np.repeat(np.asarray(self.region), n_t, axis=0), columns=list(self.input_names))
        if self._named:
            df["condition"] = [str(c) for c in np.repeat(np.array(self.region_conditions, object), n_t)]
        df["target"] = list(self.target_labels) * n_r
        df["weight"] = np.repeat(np.asarray(self.region_weights), n_t)
        df["half_before"] = np.asarray(self.half_before).ravel()
        df["half_after"] = np.asarray(self.half_after).ravel()
        with np.errstate(divide="ignore", invalid="ignore"):
            df["shrink"] = df["half_after"] / df["half_before"]
        df.attrs.update(criterion=self.criterion, value_before=self.value_before, value_after=self.value_after,
                        lower_bound=self.lower_bound, gap=self.gap, proven=self.proven, method=self.method,
                        chosen=list(self.chosen), chosen_inputs=np.asarray(self.chosen_inputs).tolist(),
                        chosen_conditions=[None if c is None else str(c) for c in self.chosen_conditions])
        return df

    def to_dict(self) -> dict:
        """Every field as plain JSON types."""
        return jsonable(self)

    def __repr__(self) -> str:
        return (f"ErrorDesignResult(model={self.model_name!r}, criterion={self.criterion!r}, chosen={list(self.chosen)}, "
                f"value {self.value_before:.4g} -> {self.value_after:.4g}, proven={self.proven})")


def select_error_design(result, candidates, n: int, *, region, region_weights=None, criterion: str = "integrated",
                        sensors=None, measure=None, pairs: bool = False, repeats: int = 1, region_size: int = 9,
                        alpha: float | None = None, method: str = "auto", time_limit: float = 60.0,
                        enumeration_limit: int = 20_000, gap_tol: float = 1e-9, candidate_conditions=None,
                        region_conditions=None) -> ErrorDesignResult:
    r""":math:`\min_{|S| = n} J(S)`: the n candidate runs after which the posterior prediction variance of model
    plus model error over the region is smallest (weighted mean or largest, each sensor in its sigma^2 units;
    module docstring), with its proof.

    Parameters
    ----------
    result, candidates, region, region_weights, criterion, sensors, measure, pairs, repeats, region_size,
    candidate_conditions, region_conditions
        As :func:`error_design_problem` (a candidate offered in several conditions is one candidate per condition:
        ``chosen`` indexes those, ``chosen_conditions`` names them).
    n : int                 runs (distinct candidates; list a row twice to allow a repeat)
    alpha : float, optional the bands' miss probability (None: the result's)
    method : "auto", "enumerate", "bnb" or "greedy"
        "auto": enumeration up to ``enumeration_limit`` sets, else branch-and-bound; "greedy": greedy + exchange
        with its gap to the root relaxation's bound (a heuristic, proven only when that gap closes).
    time_limit : float      seconds; at the limit the best set found, ``proven`` False, the proven gap and a
                            RuntimeWarning
    enumeration_limit : int
    gap_tol : float         the branch-and-bound's relative tolerance

    Returns
    -------
    ErrorDesignResult

    Raises
    ------
    ValueError
        A bad argument; the message names it.
    """
    t0 = time.perf_counter()
    prob = error_design_problem(result, candidates, region=region, region_weights=region_weights,
                                criterion=criterion, sensors=sensors, measure=measure, pairs=pairs, repeats=repeats,
                                region_size=region_size, candidate_conditions=candidate_conditions,
                                region_conditions=region_conditions)
    n = _int_in(n, 1, prob.n_candidates, "n")
    alpha = result.alpha if alpha is None else alpha
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not 0 < alpha < 1:
        raise ValueError(f"alpha: expected a number in (0, 1), got {alpha!r}")
    alpha = float(alpha)
    if method not in SEARCH_METHODS:
        raise ValueError(f"method: expected one of {SEARCH_METHODS}, got {method!r}")
    if isinstance(time_limit, bool) or not isinstance(time_limit, (int, float)) or not time_limit > 0:
        raise ValueError(f"time_limit: expected seconds > 0, got {time_limit!r}")
    _int_in(enumeration_limit, 0, 10 ** 12, "enumeration_limit")
    if not (isinstance(gap_tol, (int, float)) and 0 <= gap_tol < 1):
        raise ValueError(f"gap_tol: expected a number in [0, 1), got {gap_tol!r}")
    out = search(prob.core, n, method, float(time_limit), int(enumeration_limit), float(gap_tol))
    chosen = tuple(int(c) for c in out.indices)
    notes = [f"parameters {PARAMETER_PRIOR}; linearised at the estimate, the error model's hyperparameters fixed "
             "at their REML values: the variances do not depend on the readings to come",
             "a new run is a new condition: its rough part (or, embedded error, its parameter deviation) is new, and "
             "the target's own rough part stays in the band (no run removes it)"]
    if not out.proven:
        notes.append(f"the design is NOT proven optimal ({out.status}); proven gap {out.gap:.3g} in sigma^2 units")
        if out.status in ("time_limit", "node_limit"):
            warnings.warn(f"select_error_design stopped at its {out.status} (time_limit={time_limit:g} s): the design "
                          f"is not proven optimal; proven gap {out.gap:.3g}", RuntimeWarning, stacklevel=2)
    if any(c is not None for c in prob.candidate_conditions + prob.region_conditions):
        notes.append("conditions: the discrepancy of each condition is its own draw (independent between conditions, "
                     "common hyperparameters); a run in a condition the data hold shrinks that condition's discrepancy "
                     f"(and, through the parameters, every condition's band); a run in {NEW_CONDITION!r} is a draw of "
                     "the one condition the data do not hold, shared with the region's points there")
    if not result.identifiable:
        notes.append("the model error and the parameters cannot be told apart (result.identifiable False): the "
                     "band is that of the prediction, not of the parameters")
    return ErrorDesignResult(
        model_name=str(result.model_name), kind=str(result.kind), criterion=criterion, chosen=chosen,
        chosen_inputs=prob.candidates[prob.candidate_rows[list(chosen)]].copy(),
        chosen_sensors=tuple(prob.candidate_sensors[c] for c in chosen), input_names=prob.input_names,
        target_labels=prob.target_labels, target_sensors=prob.target_sensors, value_before=prob.value(()),
        value_after=float(out.value), irreducible=prob.floor,
        lower_bound=float(out.lower_bound), gap=float(out.gap), proven=out.proven, status=out.status,
        method=out.method, nodes=out.nodes, n_evaluated=out.n_evaluated, region=prob.region.copy(),
        region_weights=prob.region_weights.copy(), half_before=prob.half_widths((), alpha),
        half_after=prob.half_widths(chosen, alpha), alpha=alpha, repeats=prob.repeats,
        wall_time=time.perf_counter() - t0, notes=tuple(notes),
        chosen_conditions=tuple(prob.candidate_conditions[c] for c in chosen),
        region_conditions=prob.region_conditions)
