r"""Approximate designs on a continuous range, local or robust, with the equivalence-theorem certificate.

An approximate design :math:`\xi = \{(x_i, w_i)\}_{i=1}^k`, :math:`w_i > 0`, :math:`\sum_i w_i = 1`, puts the
share :math:`w_i` of the runs at the point :math:`x_i` (an input row of a static model, or a sampling time of
a dynamic model's experiments) in the box :math:`[\ell, u]`; its information at the parameter vector
:math:`P_s` is :math:`M_s(\xi) = \sum_i w_i F_s(x_i)`, with :math:`F_s(x)` the exact (CasADi AD) planned
information of one run at x (:func:`oed.candidate_information.information`, axis ``inputs`` or ``times``).  Solved:

.. math::

    \max_\xi \sum_s \pi_s u(M_s(\xi))\ \ (\text{local: one vector; pseudo-Bayesian}),\qquad
    \max_\xi \min_s c_s(\xi)\ \ (\text{standardized maximin}),

with the utilities of :mod:`oed.robust` (D: log det, A: -trace of the inverse, E: -1/smallest eigenvalue).

Algorithm: weights on a coarse tensor grid (:mod:`oed.approx_weights`), then ``rounds`` times: a local
grid ``zoom`` times finer around every support point and every high local maximum of the sensitivity
function, and the weights again on those points; support points closer than the merge distance are
merged (weighted mean) and their weights re-optimised.  For explicit static models the support points of
local and pseudo-Bayesian designs are then moved continuously to local maxima of the sensitivity function
(L-BFGS-B with its exact CasADi gradient, :mod:`oed.approx_polish`) and the weights re-optimised, kept only
if neither the criterion nor the equivalence gap gets worse (the points reached are checked either way).
The certificate is computed, never assumed: the
sensitivity function (:math:`g(x) = \sum_s \pi_s d_s(x)`, or the worst-case measure's for maximin) at
the final design is evaluated at every point ever evaluated (the coarse grid, all local grids and the
points the continuous refinement reached), its
maximum is reported with the equivalence-theorem gap and the efficiency lower bound that follows from
it.  The maximum is over those points (a grid refined around every local maximum to the final
spacing), not a proven maximum over the continuum.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from models.dynamic import merge_times
from .approx_polish import explicit_polisher
from .approx_weights import bayes_weights, information_of, maximin_weights, multiplicative_weights, standardized
from .criteria import DEFAULT_CRITERION, Criterion
from .prior import Prior, make_prior, readonly
from .prior_sparse import check_non_negative
from .candidate_information import information
from .robust import (bayes_efficiency_bound, bayes_gap, directional, efficiency_from_c, maximin_bound,
                     utilities)
from identification.fit.problem import strategy_for
from identification.results_protocol import ResultProtocol

__all__ = ["ApproximateSettings", "ApproximateDesign", "approximate_design", "check_approximate_route", "design_efficiencies",
           "information_source"]

ROBUST = ("bayes", "maximin")


@dataclass(frozen=True)
class ApproximateSettings:
    """Settings of :func:`approximate_design`.

    Attributes
    ----------
    grid : int
        Coarse grid points per varying input (or of the time range).
    rounds : int
        Refinement rounds; the final spacing is the coarse spacing / zoom**rounds.
    zoom : int
        Refinement factor per round.
    half_width : int
        Local grid: the centre +- half_width spacings per varying input.
    merge_tol : float
        Support points closer than merge_tol x the range (or two final spacings) are merged.
    n_multiplicative : int
        Multiplicative iterations on the coarse grid.
    prior_rule : str or None
        Rule of a dict prior (:func:`oed.prior.make_prior`); None: ``"gauss"`` (bayes), ``"grid"`` (maximin).
    prior_order : int
    seed : int
    polish_rounds : int
        Explicit static models, local and pseudo-Bayesian designs (and the local optima of maximin designs):
        rounds of the continuous refinement of the support points by L-BFGS-B with the exact CasADi gradient of
        the sensitivity function (:mod:`oed.approx_polish`); 0: none.
    """

    grid: int = 121
    rounds: int = 8
    zoom: int = 4
    half_width: int = 4
    merge_tol: float = 1e-3
    n_multiplicative: int = 200
    prior_rule: str | None = None
    prior_order: int = 5
    seed: int = 0
    polish_rounds: int = 3

    def __post_init__(self):
        least = {"grid": 3, "rounds": 0, "zoom": 2, "half_width": 1, "n_multiplicative": 0, "prior_order": 1,
                 "polish_rounds": 0}
        for name, low in least.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ValueError(f"{name}: expected an integer >= {low}, got {v!r}")
        if not (isinstance(self.merge_tol, (int, float)) and 0 <= self.merge_tol < 1):
            raise ValueError(f"merge_tol: expected a number in [0, 1), got {self.merge_tol!r}")


@dataclass(frozen=True)
class ApproximateDesign(ResultProtocol):
    r"""An approximate design with its equivalence-theorem certificate (the result protocol:
    :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    points : ndarray (k, d)
        Support points (input rows, or sampling times as a column), read-only.
    weights : ndarray (k,)
        Their weights, summing to 1.
    names : tuple of str
        Names of the columns of ``points``.
    criterion : str
        ``"A"``, ``"D"`` or ``"E"``.
    robust : str
        ``"local"``, ``"bayes"`` or ``"maximin"``.
    value : float
        Local/bayes: :math:`\sum_s\pi_s u_s` (D: expected log det M; A: minus expected trace of
        :math:`M^{-1}`; E: minus expected :math:`1/\lambda_{\min}`).  Maximin: the worst-case efficiency
        against the computed local optima.
    sensitivity_max, reference : float
        Maximum of the sensitivity function over the points checked and its value at the optimum
        (bayes D: n_p); ``gap`` = sensitivity_max - reference.
    efficiency_bound : float
        Local/bayes: lower bound on the efficiency against the optimal design implied by the gap.
        Maximin: lower bound on the ratio of the worst-case efficiency to the maximin optimum's.
    worst_case_bound : float
        Maximin: certified lower bound on the worst-case efficiency (the local optima's own gaps
        included); nan otherwise.
    local_gaps : ndarray (n_s,)
        Maximin: the certificates' gaps of the local optima; empty otherwise.
    efficiencies : ndarray (n_s,)
        Maximin: the design's efficiency at every parameter vector; empty otherwise.
    measure : ndarray (n_s,)
        The measure on the parameter vectors of the sensitivity function (bayes: the prior weights;
        maximin: the worst-case measure).
    quadrature_error : float
        Estimated quadrature error of ``value`` (:meth:`oed.prior.Prior.error`); nan if not estimated.
    checked : ndarray (n_c, d), sensitivity : ndarray (n_c,)
        The points where the sensitivity function was evaluated and its values (sorted by the first column).
    spacing : float
        Final local-grid spacing relative to the range.
    prior : Prior
    multiplicity : int
        E: the largest multiplicity of a smallest eigenvalue over the parameter vectors (> 1: the
        certificate uses the eigenspace average, a valid but possibly loose bound); 1 otherwise.
    wall_time : float
    notes : tuple of str
    axis : str
        The design points' axis: ``"inputs"`` (input rows) or ``"times"`` (sampling times).
    chosen : tuple of tuple of float
        The support points (rows of ``points``), with the weights ``weights``.
    """

    points: np.ndarray
    weights: np.ndarray
    names: tuple
    criterion: str
    robust: str
    value: float
    sensitivity_max: float
    reference: float
    efficiency_bound: float
    worst_case_bound: float
    local_gaps: np.ndarray
    efficiencies: np.ndarray
    measure: np.ndarray
    quadrature_error: float
    checked: np.ndarray
    sensitivity: np.ndarray
    spacing: float
    prior: Prior
    multiplicity: int = 1
    wall_time: float = 0.0
    notes: tuple = field(default_factory=tuple)
    axis: str = "inputs"

    @property
    def chosen(self) -> tuple:
        """The support points (rows of ``points``)."""
        return tuple(tuple(float(v) for v in x) for x in self.points)

    @property
    def gap(self) -> float:
        """Equivalence-theorem gap: sensitivity_max - reference (0 at the optimum)."""
        return float(self.sensitivity_max - self.reference)

    def summary(self) -> str:
        """Human-readable multi-line summary."""
        kind = {"local": "local", "bayes": "pseudo-Bayesian", "maximin": "standardized maximin"}[self.robust]
        lines = [f"approximate {kind} {self.criterion}-optimal design, {len(self.weights)} support points "
                 f"({self.prior.n} parameter vectors)"]
        for x, w in zip(self.points, self.weights):
            lines.append(f"  {', '.join(f'{n}={v:.6g}' for n, v in zip(self.names, x))}: weight {w:.6f}")
        lines.append(f"  sensitivity max {self.sensitivity_max:.9g} (optimum {self.reference:.9g}, gap "
                     f"{self.gap:.3g}) over {len(self.sensitivity)} points")
        if self.robust == "maximin":
            lines.append(f"  worst-case efficiency {self.value:.6f}, certified >= {self.worst_case_bound:.6f}; "
                         f"maximin efficiency >= {self.efficiency_bound:.6f}")
        else:
            lines.append(f"  value {self.value:.9g}, efficiency >= {self.efficiency_bound:.6f}"
                         + (f", quadrature error ~ {self.quadrature_error:.2g}"
                            if np.isfinite(self.quadrature_error) else ""))
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_frame(self):
        """The support points and weights as a pandas DataFrame (one row per point)."""
        import pandas as pd
        df = pd.DataFrame(np.asarray(self.points), columns=list(self.names))
        df["weight"] = np.asarray(self.weights)
        return df

    def to_dict(self) -> dict:
        """JSON-safe dict of the design and its certificate (nan as None)."""
        def num(v):
            return None if not np.isfinite(v) else float(v)
        return {"criterion": self.criterion, "robust": self.robust, "names": list(self.names),
                "points": np.asarray(self.points).tolist(), "weights": np.asarray(self.weights).tolist(),
                "value": num(self.value), "sensitivity_max": num(self.sensitivity_max),
                "reference": num(self.reference), "gap": num(self.gap), "efficiency_bound": num(self.efficiency_bound),
                "worst_case_bound": num(self.worst_case_bound), "quadrature_error": num(self.quadrature_error),
                "efficiencies": [float(v) for v in self.efficiencies], "n_parameter_vectors": self.prior.n,
                "prior_rule": self.prior.rule, "n_checked": int(len(self.sensitivity)),
                "spacing": float(self.spacing), "multiplicity": int(self.multiplicity),
                "wall_time": float(self.wall_time), "notes": list(self.notes)}

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr>{''.join(f'<td>{v:.6g}</td>' for v in x)}<td>{w:.6f}</td></tr>"
                       for x, w in zip(self.points, self.weights))
        head = "".join(f"<th>{n}</th>" for n in self.names) + "<th>weight</th>"
        return (f"<p>approximate {self.robust} {self.criterion}-optimal design: sensitivity max "
                f"{self.sensitivity_max:.6g} (optimum {self.reference:.6g}), efficiency &ge; "
                f"{self.efficiency_bound:.6f}</p><table><tr>{head}</tr>{rows}</table>")


class _Store:
    """Every point evaluated so far and its information at every parameter vector (grows; never re-evaluates).
    Points are snapped to 1e-10 of the range, so that points of different local grids that agree to rounding
    are one point."""

    def __init__(self, info, P, box):
        self.info, self.P = info, P
        self.lo, self.span = box[0], np.where(box[1] > box[0], box[1] - box[0], 1.0)
        self.X = np.zeros((0, self.lo.size))
        self.F = None
        self._index = {}

    def add(self, X) -> np.ndarray:
        """Indices in the store of the rows of X, in their order (rows not yet in the store are evaluated)."""
        X = self.lo + np.round((np.asarray(X, float) - self.lo) / self.span, 10) * self.span + 0.0
        new = []
        for row in X:
            key = row.tobytes()
            if key not in self._index:
                self._index[key] = self.X.shape[0] + len(new)
                new.append(row)
        if new:
            Fn = self.info(np.array(new), self.P)
            self.F = Fn if self.F is None else np.concatenate([self.F, Fn])
            self.X = np.concatenate([self.X, np.array(new)])
        return np.array([self._index[row.tobytes()] for row in X], dtype=int)


def _coarse(lo, hi, n):
    axes = [np.linspace(a, b, n) if b > a else np.array([a]) for a, b in zip(lo, hi)]
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)


def _local(centres, h, lo, hi, k):
    steps = [np.arange(-k, k + 1) * hj if hj > 0 else np.zeros(1) for hj in h]
    offs = np.stack([g.ravel() for g in np.meshgrid(*steps, indexing="ij")], axis=1)
    return np.clip((centres[:, None, :] + offs[None, :, :]).reshape(-1, lo.size), lo, hi)


@dataclass(frozen=True)
class _Sensitivity:
    """The sensitivity function of a design over the store: values g, its value at the optimum (reference), the
    measure on the parameter vectors, the coefficient a_s of every vector's directional derivative, utilities."""

    g: np.ndarray
    reference: float
    measure: np.ndarray
    coef: np.ndarray
    U: object


def _sensitivity(mode, crit, F, w, prior_w, u_star) -> _Sensitivity:
    """The sensitivity function of the design w over the points of F (module docstring)."""
    n_p = F.shape[-1]
    U = utilities(crit, information_of(w, F))
    d = directional(U.grad, F)
    if mode == "bayes":
        g, _ = bayes_gap(U, d, prior_w)
        pw = np.asarray(prior_w, float)
        return _Sensitivity(g, float(np.dot(prior_w, U.inner)), pw, pw, U)
    c, kappa = standardized(crit, U.u, u_star, n_p)
    b = maximin_bound(c, kappa, d, U.inner)
    return _Sensitivity(b.sensitivity, float(np.dot(b.measure, kappa * U.inner)), b.measure, b.measure * kappa, U)


def _peaks(X, g, ref, n_p):
    """The high local maxima of g (1-D: discrete local maxima; else the best points), at most 4 n_p."""
    if np.count_nonzero(np.ptp(X, axis=0) > 0) <= 1:
        col = int(np.argmax(np.ptp(X, axis=0)))
        order = np.argsort(X[:, col], kind="stable")
        gs = g[order]
        peaks = order[(gs >= np.r_[-np.inf, gs[:-1]]) & (gs >= np.r_[gs[1:], -np.inf])]
    else:
        peaks = np.argsort(-g)[: 2 * n_p]
    peaks = peaks[g[peaks] >= ref - 0.25 * abs(ref)]
    return peaks[np.argsort(-g[peaks])][: 4 * n_p]


def _weights(mode, crit, F, prior_w, u_star, w0):
    if mode == "bayes":
        return bayes_weights(F, prior_w, crit, w0=w0)
    return maximin_weights(F, crit, u_star, w0=w0)


def _full(n, S, wS):
    w = np.zeros(n)
    w[S] = wS
    return w


def _start(store, box, crit, mode, prior_w, u_star, settings, start):
    """First support: the peaks of the sensitivity function of the multiplicative algorithm's weights on the
    coarse grid (bayes), or the given start points (maximin: the local optima's support points)."""
    lo, hi = box
    idx = store.add(_coarse(lo, hi, settings.grid))
    n_p = store.F.shape[-1]
    if start is None:
        wc = multiplicative_weights(store.F[idx], prior_w, crit, settings.n_multiplicative)
        sens = _sensitivity(mode, crit, store.F, _full(store.X.shape[0], idx, wc), prior_w, u_star)
        S = np.union1d(_peaks(store.X, sens.g, sens.reference, n_p), idx[wc >= 0.5 * wc.max()])
    else:
        S = np.unique(store.add(start))
    wS = _weights(mode, crit, store.F[S], prior_w, u_star, np.full(S.size, 1.0 / S.size))
    return S[wS > 0], wS[wS > 0]


def _optimise(store, box, crit, mode, prior_w, u_star, settings, start=None):
    """Support indices and weights after the refinement rounds: every support point and high local maximum of the
    sensitivity function moves to the best point of a local grid around it, then the weights are re-optimised
    (module docstring); also the final spacing h."""
    lo, hi = box
    h = np.where(hi > lo, (hi - lo) / (settings.grid - 1), 0.0)
    S, wS = _start(store, box, crit, mode, prior_w, u_star, settings, start)
    for _ in range(settings.rounds):
        h = h / settings.zoom
        sens = _sensitivity(mode, crit, store.F, _full(store.X.shape[0], S, wS), prior_w, u_star)
        centres = store.X[np.union1d(S, _peaks(store.X, sens.g, sens.reference, store.F.shape[-1]))]
        local = _local(centres, h, lo, hi, settings.half_width)
        groups = np.split(store.add(local), len(centres))
        g = _sensitivity(mode, crit, store.F, _full(store.X.shape[0], S, wS), prior_w, u_star).g
        newS = np.unique([gr[np.argmax(g[gr])] for gr in groups])
        carried = {int(i): v for i, v in zip(S, wS)}
        w0 = np.array([carried.get(int(i), 0.0) for i in newS]) + 1e-3 / newS.size
        ws = _weights(mode, crit, store.F[newS], prior_w, u_star, w0 / w0.sum())
        S, wS = newS[ws > 0], ws[ws > 0]
    return S, wS, h


def _merge(store, S, wS, h, box, settings):
    """Support indices (in the store) and weights after merging points closer than the merge distance."""
    lo, hi = box
    tol = np.maximum(settings.merge_tol * np.where(hi > lo, hi - lo, 1.0), 2.0 * h)
    order = np.lexsort(store.X[S].T[::-1])
    S, wS = S[order], wS[order]
    groups, cur = [], [0]
    for i in range(1, S.size):
        if np.all(np.abs(store.X[S[i]] - store.X[S[cur[-1]]]) <= tol):
            cur.append(i)
        else:
            groups.append(cur)
            cur = [i]
    groups.append(cur)
    pts = np.array([np.average(store.X[S[gr]], axis=0, weights=wS[gr]) for gr in groups])
    idx, inv = np.unique(store.add(pts), return_inverse=True)
    return idx, np.bincount(inv, weights=np.array([wS[gr].sum() for gr in groups]))


@dataclass(frozen=True)
class _Solution:
    """Support (indices in the store, weights), the sensitivity function over the store, final spacing h."""

    idx: np.ndarray
    weights: np.ndarray
    sens: _Sensitivity
    h: np.ndarray


def _polish(store, sol, box, crit, prior_w, polisher, settings):
    """``settings.polish_rounds`` times: the support points moved to local maxima of the sensitivity function
    (exact CasADi gradient, :mod:`oed.approx_polish`), points that met merged, the weights re-optimised; a round
    is kept only if the criterion does not decrease and the equivalence gap over the store does not grow
    (pseudo-Bayesian and local designs)."""
    idx, ws = sol
    for _ in range(settings.polish_rounds):
        sens = _sensitivity("bayes", crit, store.F, _full(store.X.shape[0], idx, ws), prior_w, None)
        moved = store.add(polisher.polish(store.X[idx], sens.coef[:, None, None] * sens.U.grad, box[0], box[1]))
        if np.array_equal(moved, idx):
            break
        new, wm = _merge(store, moved, ws, np.zeros(box[0].size), box, settings)
        wn = _weights("bayes", crit, store.F[new], prior_w, None, wm / wm.sum())
        after = _sensitivity("bayes", crit, store.F, _full(store.X.shape[0], new, wn), prior_w, None)
        before = _sensitivity("bayes", crit, store.F, _full(store.X.shape[0], idx, ws), prior_w, None)
        if _objective_value("bayes", crit, store.F[new], wn, prior_w, None) < \
                _objective_value("bayes", crit, store.F[idx], ws, prior_w, None) or \
                np.max(after.g) - after.reference > np.max(before.g) - before.reference:
            break
        idx, ws = new[wn > 0], wn[wn > 0]
    return idx, ws


def _objective_value(mode, crit, F, w, prior_w, u_star) -> float:
    U = utilities(crit, information_of(w, F))
    if mode == "bayes":
        return float(np.dot(prior_w, U.u))
    return float(np.min(standardized(crit, U.u, u_star, F.shape[-1])[0]))


def _solve(store, box, crit, mode, prior_w, u_star, settings, start=None, polisher=None) -> _Solution:
    """The optimised, merged (and, for explicit models, polished) design and its sensitivity function."""
    S, wS, h = _optimise(store, box, crit, mode, prior_w, u_star, settings, start)
    idx, wm = _merge(store, S, wS, h, box, settings)
    ws = _weights(mode, crit, store.F[idx], prior_w, u_star, wm / wm.sum())
    idx, ws = idx[ws > 0], ws[ws > 0]
    if polisher is not None and mode == "bayes" and settings.polish_rounds:
        idx, ws = _polish(store, (idx, ws), box, crit, prior_w, polisher, settings)
    sens = _sensitivity(mode, crit, store.F, _full(store.X.shape[0], idx, ws), prior_w, u_star)
    order = np.lexsort(store.X[idx].T[::-1])
    return _Solution(idx[order], ws[order], sens, h)


# ---------------------------------------------------------------------------- the front door
def information_source(model, sigma, inputs=None, sensors=None, n_series: int = 1):
    """(info(X, P) -> F of shape (n_x, n_s, n_p, n_p), names of the design columns): the information of one run at
    every point X (a static model's input rows, a dynamic model's sampling times of the experiments ``inputs``) at
    every parameter vector P, as :func:`approximate_design` evaluates it; arguments checked."""
    return _information_source(model, sigma, inputs, sensors, n_series, _axis(model))


def _information_source(model, sigma, inputs, sensors, n_series, axis):
    """(info(X, P) -> F of shape (n_x, n_s, n_p, n_p), names of the design columns): the information of one run
    at every point X (axis ``inputs``: input rows; ``times``: sampling times of the experiments ``inputs``, every
    chosen instrument) at every parameter vector, by :func:`oed.candidate_information.information`; arguments checked."""
    if sensors is not None:
        sensors = [sensors] if isinstance(sensors, str) else list(sensors)
        unknown = [s for s in sensors if s not in model.sensors]
        if unknown or not sensors:
            raise ValueError(f"sensors: unknown {unknown or 'empty selection'}; the model has {list(model.sensors)}")
    if axis == "inputs":
        if inputs is not None:
            raise ValueError("inputs: only for a dynamic model (the static model's inputs are the design points)")

        def rows(X, P):
            return np.stack([information(model, ps, axis="inputs", candidates=X, sigma=sigma, sensors=sensors,
                                         n_series=n_series).F for ps in P], axis=1)
        return rows, tuple(model.inputs)
    if inputs is None:
        raise ValueError("inputs: a dynamic model needs the experiments (rows of inputs) sampled at the times")
    inputs = np.atleast_2d(np.asarray(inputs, float))

    def times(X, P):
        t = X[:, 0]
        # times closer than the round-off tolerance are one instant (models.dynamic.merge_times): refined grids
        # around a support point can hold such twins, which the model's data checks refuse
        u = merge_times(t, horizon=t.max())
        at = np.abs(t[:, None] - u[None, :]).argmin(axis=1)
        out = np.empty((t.size, len(P), model.n_p, model.n_p))
        for s, ps in enumerate(P):
            out[:, s] = information(model, ps, axis="times", times=u, inputs=inputs, sigma=sigma, sensors=sensors,
                                    n_series=n_series).F[at]
        return out
    return times, ("t",)


def _axis(model) -> str:
    """The axis of an approximate design: a static model's input rows, a dynamic model's sampling times (the
    model's strategy answers, :attr:`identification.fit.problem.ProblemStrategy.design_axis`)."""
    return strategy_for(model).design_axis


def _check_box(model, bounds, dynamic):
    d = 1 if dynamic else model.n_q_dim
    what = "the sampling-time range (t_min, t_max)" if dynamic else f"input bounds (lower, upper) of shape ({d},)"
    try:
        lo, hi = (np.broadcast_to(np.asarray(b, float).ravel(), (d,)).copy() for b in bounds)
    except (TypeError, ValueError):
        raise ValueError(f"bounds: expected {what}, got {bounds!r}") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
        raise ValueError(f"bounds: expected finite lower <= upper ({what}), got {bounds!r}")
    if not np.any(hi > lo):
        raise ValueError("bounds: approximate designs need a continuous range (lower < upper in at least one "
                         f"input); got lower = upper = {lo}")
    if dynamic:
        model.check_times([lo[0]], "bounds")
        model.check_times([hi[0]], "bounds")
    return lo, hi


def check_prior_points(model, prior: Prior, where: str = "(a quadrature point)"):
    """Raise ValueError naming ``prior`` when a prior point lies outside the model's parameter bounds."""
    lower = np.array([q.lower for q in model.params], float)
    upper = np.array([q.upper for q in model.params], float)
    out = (prior.points < lower) | (prior.points > upper)
    if np.any(out):
        s, j = np.argwhere(out)[0]
        raise ValueError(f"prior: {model.param_names[j]} = {prior.points[s, j]:g} {where} lies outside "
                         f"the model's bounds [{lower[j]:g}, {upper[j]:g}]; narrow the prior")


def _resolve_prior(model, p, prior, robust, settings) -> tuple:
    """(Prior, mode): the nominal point for ``prior=None`` (local), else the rule of the prior."""
    if robust not in ROBUST:
        raise ValueError(f"robust: expected one of {ROBUST}, got {robust!r}")
    if prior is None:
        return make_prior((np.asarray(p, float)[None, :], [1.0]), model, p), "local"
    rule = settings.prior_rule or ("grid" if robust == "maximin" else "gauss")
    pr = make_prior(prior, model, p, rule=rule, order=settings.prior_order, seed=settings.seed)
    check_non_negative(pr, "an approximate design")
    check_prior_points(model, pr)
    return pr, robust


def approximate_design(model, p, *, sigma, bounds, criterion=DEFAULT_CRITERION, prior=None, robust: str = "bayes", inputs=None,
                       sensors=None, n_series: int = 1,
                       settings: ApproximateSettings = ApproximateSettings()) -> ApproximateDesign:
    r"""The approximate design :math:`\max_\xi \sum_s\pi_s u(M_s(\xi))` or :math:`\max_\xi\min_s c_s(\xi)` on a
    continuous range, with its equivalence-theorem certificate (module docstring).

    Parameters
    ----------
    model : models.Model or models.dynamic.DynamicModel
        Static model: the design points are input rows.  Dynamic model: the sampling times of the
        experiments ``inputs`` (every experiment sampled at the design's times).
    p : array_like (n_p,)
        Nominal parameters (the local design's; the value of parameters without a prior).
    sigma : float or array_like
        Standard deviation per sensor (instrument).
    bounds : (array_like, array_like)
        Static: input bounds (lower, upper), shape (d_q,) each (lower = upper fixes an input);
        dynamic: the time range (t_min, t_max).
    criterion : {"A", "D", "E"}
    prior : None, (P, w), dict or Prior
        None: the local design at p; else see :func:`oed.prior.make_prior`.
    robust : {"bayes", "maximin"}
        With a prior: pseudo-Bayesian (prior-weighted) or standardized maximin over the prior's points.
    inputs : array_like (n_q, d_q) or None
        Dynamic models only: the experiments.
    sensors : sequence of str or None
        Sensors (instruments) measured (default all).
    n_series : int
    settings : ApproximateSettings

    Returns
    -------
    ApproximateDesign

    Raises
    ------
    ValueError
        Bad input; the message names the argument or key.
    """
    t0 = time.perf_counter()
    axis = _axis(model)
    crit = Criterion.parse(criterion)
    lo, hi = _check_box(model, bounds, axis == "times")
    info, names = _information_source(model, sigma, inputs, sensors, n_series, axis)
    pr, mode = _resolve_prior(model, p, prior, robust, settings)

    def polisher(P):      # the support points of input rows of an explicit model move continuously
        if axis != "inputs":
            return None
        return explicit_polisher(model, P, sigma, None if sensors is None else list(np.atleast_1d(sensors)),
                                 n_series)
    if mode == "maximin":
        return replace(_maximin(model, info, pr, (lo, hi), crit, names, settings, t0, polisher), axis=axis)
    store = _Store(info, pr.points, (lo, hi))
    sol = _solve(store, (lo, hi), crit, "bayes", pr.weights, None, settings, polisher=polisher(pr.points))
    idx, ws, g, ref, mu, U, h = sol.idx, sol.weights, sol.sens.g, sol.sens.reference, sol.sens.measure, sol.sens.U, \
        sol.h
    gap = float(np.max(g) - ref)
    value = pr.mean(U.u)
    qerr = float("nan") if mode == "local" else pr.error(
        lambda P: utilities(crit, information_of(ws, info(store.X[idx], P))).u)
    order = np.argsort(store.X[:, 0], kind="stable")
    return ApproximateDesign(
        points=readonly(store.X[idx]), weights=readonly(ws), names=names, criterion=crit.value, robust=mode,
        value=value, sensitivity_max=float(np.max(g)), reference=ref,
        efficiency_bound=bayes_efficiency_bound(crit, U, pr.weights, gap, model.n_p), worst_case_bound=float("nan"),
        local_gaps=readonly([]), efficiencies=readonly([]), measure=readonly(mu), quadrature_error=qerr,
        checked=readonly(store.X[order]), sensitivity=readonly(g[order]),
        spacing=float(np.max(h[hi > lo] / (hi - lo)[hi > lo])), prior=pr, multiplicity=int(np.max(U.multiplicity)),
        wall_time=time.perf_counter() - t0, notes=_notes(crit, U, store), axis=axis)


def _notes(crit, U, store) -> tuple:
    notes = [f"certificate: the sensitivity function's maximum over {store.X.shape[0]} points (a coarse grid refined "
             "around every high local maximum), not a proven maximum over the continuum"]
    if crit is Criterion.E and np.max(U.multiplicity) > 1:
        notes.append(f"E: smallest eigenvalue of multiplicity {int(np.max(U.multiplicity))}; the certificate uses "
                     "the eigenspace average supergradient (a valid, possibly loose bound)")
    return tuple(notes)


def _maximin(model, info, pr: Prior, box, crit, names, settings, t0, polisher) -> ApproximateDesign:
    """Local optima at every parameter vector, then the standardized maximin design and its bounds."""
    lo, hi = box
    u_star, gaps, starts = np.empty(pr.n), np.empty(pr.n), []
    for s in range(pr.n):
        st = _Store(info, pr.points[s:s + 1], box)
        loc = _solve(st, box, crit, "bayes", np.ones(1), None, settings, polisher=polisher(pr.points[s:s + 1]))
        u_star[s], gaps[s] = loc.sens.U.u[0], float(np.max(loc.sens.g) - loc.sens.reference)
        starts.append(st.X[loc.idx])
    store = _Store(info, pr.points, (lo, hi))
    sol = _solve(store, box, crit, "maximin", None, u_star, settings, np.vstack(starts))
    idx, ws, U, h = sol.idx, sol.weights, sol.sens.U, sol.h
    c, kappa = standardized(crit, U.u, u_star, model.n_p)
    b = maximin_bound(c, kappa, directional(U.grad, store.F), U.inner)
    eff = efficiency_from_c(crit, c)
    if crit is Criterion.D:
        certified = float(np.min(np.exp(c - np.maximum(gaps, 0.0) / model.n_p)))
        ratio = float(np.exp(b.lower - b.upper))
    else:
        phi_star = -u_star
        certified = float(np.min((phi_star - np.maximum(gaps, 0.0)) / -U.u))
        ratio = float(b.upper / b.lower)
    order = np.argsort(store.X[:, 0], kind="stable")
    return ApproximateDesign(
        points=readonly(store.X[idx]), weights=readonly(ws), names=names, criterion=crit.value, robust="maximin",
        value=float(np.min(eff)), sensitivity_max=float(np.max(b.sensitivity)), reference=float(np.dot(
            b.measure, kappa * U.inner)), efficiency_bound=ratio, worst_case_bound=certified,
        local_gaps=readonly(gaps), efficiencies=readonly(eff), measure=readonly(b.measure),
        quadrature_error=float("nan"), checked=readonly(store.X[order]), sensitivity=readonly(b.sensitivity[order]),
        spacing=float(np.max(h[hi > lo] / (hi - lo)[hi > lo])), prior=pr, multiplicity=int(np.max(U.multiplicity)),
        wall_time=time.perf_counter() - t0, notes=_notes(crit, U, store))


def design_efficiencies(model, design: ApproximateDesign, reference: ApproximateDesign, *, sigma, inputs=None,
                        sensors=None, n_series: int = 1) -> np.ndarray:
    r"""Efficiency of ``design`` against ``reference`` at every parameter vector :math:`P_s` of ``reference.prior``:
    D: :math:`\exp((u_D(M_s(\xi)) - u_D(M_s(\xi_{ref})))/n_p)`, A, E: :math:`u(M_s(\xi_{ref}))/u(M_s(\xi))` (the
    ratio of trace of the inverse, or of the inverse smallest eigenvalue), with the criterion of ``reference``;
    e.g. the local design across the prior against the robust one.  ``sigma``, ``inputs``, ``sensors`` and
    ``n_series`` as the designs were made with.

    Returns
    -------
    ndarray (n_s,)
    """
    if design.names != reference.names:
        raise ValueError(f"design: its columns {design.names} are not the reference's {reference.names}")
    info, _ = _information_source(model, sigma, inputs, sensors, n_series, _axis(model))
    crit = Criterion.parse(reference.criterion)
    P = reference.prior.points
    u = utilities(crit, information_of(design.weights, info(np.asarray(design.points), P))).u
    u_ref = utilities(crit, information_of(reference.weights, info(np.asarray(reference.points), P))).u
    if crit is Criterion.D:
        return np.exp((u - u_ref) / P.shape[1])
    return u_ref / u


def check_approximate_route(approximate: bool, exact_args: dict) -> None:
    """The checks shared by the ``approximate=True`` routes of the design verbs: a prior asks for an approximate
    design, and no argument of the exact route is given."""
    if not approximate:
        raise ValueError("prior: exact robust designs (expected or worst-case criterion of an n-run design) are "
                         "not implemented; use approximate=True for a robust approximate design")
    used = [k for k, v in exact_args.items()
            if v is not None and v is not False and not (isinstance(v, (tuple, list)) and len(v) == 0)]
    if used:
        raise ValueError(f"{used[0]}: not used by an approximate design (approximate=True); leave it out")
