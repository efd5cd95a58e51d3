r"""Continuous refinement of an exact n-run robust design (input rows or sampling times) over the range.

The exact design chooses n distinct candidates (:mod:`oed.robust_exact`); here its points
:math:`x_1..x_n` move within the box :math:`[\ell, u]` to improve the same robust criterion,

.. math::

    \max_{x_1..x_n\in[\ell,u]} \sum_s \pi_s u\bigl(M_s(x)\bigr)\ \ (\text{bayes}),\qquad
    \max_{x_1..x_n\in[\ell,u]} \min_s c_s\bigl(M_s(x)\bigr)\ \ (\text{maximin}),\qquad
    M_s(x) = \frac1n\sum_i F_s(x_i),

with the utilities of :mod:`oed.robust` and, for maximin, the standardization :math:`u^*_s` of the exact design
(each vector's own exact n-run optimum over the candidates; a refined design may exceed it, efficiency > 1).

Algorithm (every model: static input rows, a dynamic model's sampling times): coordinate ascent on local grids.
Each round evaluates :math:`F_s` at a local tensor grid of :math:`\pm` ``half_width`` spacings around every point
(one information call per round, all points and vectors at once), then moves one point at a time to its grid
point of highest criterion (the others fixed) until no move improves; the spacing, starting at the candidates'
spacing, is divided by ``zoom`` after each round in which no point ended on the rim of its grid (a point still
travelling keeps the spacing; at most :data:`MAX_ROUNDS_FACTOR` x ``rounds`` rounds, noted when reached).
Explicit static models then take a final L-BFGS-B step on all rows at once with the exact CasADi gradient
:math:`\partial\Phi/\partial x_i = \sum_s\pi_s\operatorname{tr}(\nabla u_s\,\partial F_s(x_i)/\partial x_i)/n`
(:mod:`oed.approx_polish`; bayes only).
Every move is kept only if it raises the criterion, so the refined value is at least the exact design's,
both evaluated by the same information function (a dynamic model's information at a time is computed on
the times of the call; it agrees with the candidates' to the discretisation tolerance).

The efficiency against the approximate robust design :math:`\xi` (same prior, criterion and range,
:func:`oed.approximate.approximate_design`): bayes D :math:`\exp((\Phi(x) - \Phi(\xi))/n_p)`, A, E
:math:`\Phi(\xi)/\Phi(x)`; maximin: the ratio of the two worst-case efficiencies against the same
:math:`u^*_s`.  It is at most 1 + the approximate design's certified gap (an n-run design is an approximate design
with weights 1/n).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from identification.results_protocol import ResultProtocol, jsonable
from .approx_weights import information_of, standardized
from .criteria import Criterion
from .robust import efficiency_from_c, utilities

__all__ = ["RobustRefineSettings", "RobustRefined", "refine_robust", "refine_robust_times", "MAX_ROUNDS_FACTOR"]

#: at most this many times ``rounds`` rounds in all (rounds whose points travel to the rim of their grid keep the
#: spacing)
MAX_ROUNDS_FACTOR = 4


@dataclass(frozen=True)
class RobustRefineSettings:
    """Settings of :func:`refine_robust`: ``rounds`` of local grids of +- ``half_width`` spacings, the spacing divided
    by ``zoom`` per round, at most ``sweeps`` coordinate sweeps per round; ``polish``: the final L-BFGS-B step
    (explicit static models, bayes)."""

    rounds: int = 8
    zoom: int = 4
    half_width: int = 2
    sweeps: int = 20
    polish: bool = True

    def __post_init__(self):
        for name, low in (("rounds", 1), ("zoom", 2), ("half_width", 1), ("sweeps", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ValueError(f"{name}: expected an integer >= {low}, got {v!r}")


@dataclass(frozen=True)
class RobustRefined(ResultProtocol):
    """The refined points of an exact robust design (the result protocol: :meth:`summary`, :meth:`to_frame`,
    :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    points : ndarray (n, d)        refined input rows, or sampling times as a column
    start : ndarray (n, d)         the exact design's points
    names : tuple of str           columns of ``points``
    value, start_value : float     the robust criterion (module docstring) of the refined / exact points
    per_sample : ndarray (n_s,)    u_s of the refined points
    worst_case_efficiency : float  maximin: against u*_s; nan for bayes
    approximate_efficiency : float against the approximate robust design (nan when not computed)
    approximate_value : float      that design's criterion (maximin: its worst-case efficiency against u*_s; nan
                                   when not computed)
    approximate_gap : float        its equivalence-theorem gap (nan when not computed)
    criterion, robust : str
    spacing : float                final grid spacing relative to the range
    wall_time : float
    notes : tuple of str
    """

    points: np.ndarray
    start: np.ndarray
    names: tuple
    value: float
    start_value: float
    per_sample: np.ndarray
    worst_case_efficiency: float
    approximate_efficiency: float
    approximate_value: float
    approximate_gap: float
    criterion: str
    robust: str
    spacing: float
    wall_time: float
    notes: tuple = ()

    def summary(self) -> str:
        """The refined points against the exact ones, both values and the efficiency against the approximate design."""
        lines = [f"refined exact {self.robust} {self.criterion} design of {len(self.points)} runs: value "
                 f"{self.value:.9g} (exact design {self.start_value:.9g}), final spacing {self.spacing:.2g} of the "
                 f"range, {self.wall_time:.2f} s"]
        for a, b in zip(self.start, self.points):
            lines.append(f"  {', '.join(f'{n}={x:.6g}' for n, x in zip(self.names, a))} -> "
                         f"{', '.join(f'{x:.6g}' for x in b)}")
        if self.robust == "maximin":
            lines.append(f"  worst-case efficiency {self.worst_case_efficiency:.6f} against each vector's own exact "
                         "n-run optimum")
        if np.isfinite(self.approximate_efficiency):
            lines.append(f"  efficiency against the approximate {self.robust} design {self.approximate_efficiency:.6f}"
                         f" (its value {self.approximate_value:.9g}, certified gap {self.approximate_gap:.2g})")
        return "\n".join(lines + [f"  note: {n}" for n in self.notes])

    def to_frame(self):
        """One row per run: the exact point (``start <name>``) and the refined one (``<name>``)."""
        import pandas as pd
        df = pd.DataFrame(np.asarray(self.points), columns=list(self.names))
        for j, n in enumerate(self.names):
            df[f"start {n}"] = np.asarray(self.start)[:, j]
        return df

    def to_dict(self) -> dict:
        """JSON-safe: every field."""
        return jsonable(self)


def _distinct(info):
    """``info`` called on the distinct rows of X only (coinciding points: one evaluation, shared)."""
    def call(X, P):
        U, inv = np.unique(np.asarray(X, float), axis=0, return_inverse=True)
        return info(U, P)[np.ravel(inv)]
    return call


def _criterion(crit, robust, prior_w, u_star, n_p):
    """Phi(M stack (n_s, n_p, n_p)) -> (value, u)."""
    def phi(M):
        u = utilities(crit, M).u
        if not np.all(np.isfinite(u)):
            return -np.inf, u
        if robust == "bayes":
            return float(np.dot(prior_w, u)), u
        return float(np.min(standardized(crit, u, u_star, n_p)[0])), u
    return phi


def _local_grid(x, h, lo, hi, k):
    """The tensor grid x + h * {-k..k} per coordinate (fixed coordinates, h = 0, stay), clipped to the box."""
    axes = [np.unique(np.clip(x[j] + h[j] * np.arange(-k, k + 1), lo[j], hi[j])) for j in range(x.size)]
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)


def _round(info, P, X, FX, h, box, phi, settings):
    """One round of coordinate ascent on local grids: (X, FX, edge), edge True when a point moved to the rim of its
    local grid (inside the box), so that the next round keeps the spacing."""
    lo, hi = box
    n = X.shape[0]
    centres = X.copy()
    grids = [_local_grid(X[i], h, lo, hi, settings.half_width) for i in range(n)]
    Fg = info(np.vstack(grids), P)
    split = np.cumsum([g.shape[0] for g in grids])[:-1]
    Fgs = np.split(Fg, split, axis=0)
    best = phi(FX.sum(axis=0) / n)[0]
    for _ in range(settings.sweeps):
        moved = False
        for i in range(n):
            rest = FX.sum(axis=0) - FX[i]
            vals = np.array([phi((rest + Fgs[i][g]) / n)[0] for g in range(grids[i].shape[0])])
            g = int(np.argmax(vals))
            if vals[g] > best:
                X[i], FX[i], best, moved = grids[i][g], Fgs[i][g], float(vals[g]), True
        if not moved:
            break
    rim = np.abs(np.abs(X - centres) - settings.half_width * h[None, :]) <= 1e-12 * np.maximum(h[None, :], 1e-300)
    inside = (X > lo[None, :]) & (X < hi[None, :])
    return X, FX, bool(np.any(rim & inside & (h[None, :] > 0)))


def _polish(info, P, X, FX, box, phi, polisher, prior_w, crit):
    """Bayes, explicit static models: L-BFGS-B on all rows with the exact gradient; kept if it improves."""
    n, d = X.shape
    lo, hi = box

    def fun(z):
        Xz = z.reshape(n, d)
        Fz = info(Xz, P)
        M = Fz.sum(axis=0) / n
        v, _ = phi(M)
        if not np.isfinite(v):
            return 1e30, np.zeros_like(z)
        U = utilities(crit, M)
        A = np.asarray(prior_w)[:, None, None] * U.grad / n
        return -v, -np.concatenate([polisher.value_grad(x, A)[1] for x in Xz])

    res = minimize(fun, X.ravel(), jac=True, method="L-BFGS-B", bounds=list(zip(np.tile(lo, n), np.tile(hi, n))),
                   options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 200})
    Xn = np.clip(res.x.reshape(n, d), lo, hi)
    Fn = info(Xn, P)
    if phi(Fn.sum(axis=0) / n)[0] > phi(FX.sum(axis=0) / n)[0]:
        return Xn, Fn, True
    return X, FX, False


def refine_robust(info, X0, prior, box, *, criterion, robust, u_star, spacing, names, polisher=None,
                  approximate=None, settings: RobustRefineSettings = RobustRefineSettings()) -> RobustRefined:
    r"""The refinement of the module docstring from the exact design's points ``X0`` (n, d).

    Parameters
    ----------
    info : callable
        ``info(X (m, d), P (n_s, n_p)) -> F (m, n_s, n_p, n_p)``, the information of one run at every point and vector
        (:func:`oed.approximate.information_source`).
    X0 : array_like (n, d)
    prior : oed.prior.Prior
    box : (ndarray (d,), ndarray (d,))
        Lower and upper bounds; fixed coordinates have lower = upper.
    criterion : {"A", "D", "E"}
    robust : {"bayes", "maximin"}
    u_star : ndarray (n_s,) or None
        Maximin: the standard (each vector's own exact n-run optimum).
    spacing : ndarray (d,)
        The first round's grid spacing per coordinate (the candidates' spacing).
    names : tuple of str
    polisher : oed.approx_polish.SensitivityPolisher or None
        Explicit static models: the exact gradient for the final step (bayes).
    approximate : oed.approximate.ApproximateDesign or None
        The approximate robust design for the efficiency.
    settings : RobustRefineSettings
    """
    t0 = time.perf_counter()
    crit = Criterion.parse(criterion)
    info = _distinct(info)
    P, w = np.asarray(prior.points, float), np.asarray(prior.weights, float)
    lo, hi = (np.asarray(b, float).ravel() for b in box)
    X = np.clip(np.array(X0, float).reshape(len(X0), -1), lo, hi)
    n_p = P.shape[1]
    phi = _criterion(crit, robust, w, None if u_star is None else np.asarray(u_star, float), n_p)
    FX = info(X, P)
    start_value = phi(FX.sum(axis=0) / X.shape[0])[0]
    X_start = X.copy()
    h = np.where(hi > lo, np.asarray(spacing, float), 0.0)
    notes = []
    done = 0
    for _ in range(MAX_ROUNDS_FACTOR * settings.rounds):
        X, FX, edge = _round(info, P, X, FX, h, (lo, hi), phi, settings)
        if not edge:          # a point still travelling keeps the spacing; else zoom in
            h, done = h / settings.zoom, done + 1
        if done == settings.rounds:
            break
    if done < settings.rounds:
        notes.append(f"stopped after {MAX_ROUNDS_FACTOR * settings.rounds} rounds with points still travelling "
                     f"(only {done} of {settings.rounds} zooms made)")
    if polisher is not None and settings.polish and robust == "bayes":
        X, FX, kept = _polish(info, P, X, FX, (lo, hi), phi, polisher, w, crit)
        notes.append("L-BFGS-B with the exact CasADi gradient " + ("improved the points" if kept else
                                                                    "did not improve them (grid points kept)"))
    value, u = phi(FX.sum(axis=0) / X.shape[0])
    wce = float("nan")
    if robust == "maximin":
        wce = float(np.min(efficiency_from_c(crit, standardized(crit, u, u_star, n_p)[0])))
    a_eff = a_val = a_gap = float("nan")
    if approximate is not None:
        a_val, a_gap = float(approximate.value), float(approximate.gap)
        if robust == "maximin":
            ua = utilities(crit, information_of(approximate.weights, info(np.asarray(approximate.points), P))).u
            wca = float(np.min(efficiency_from_c(crit, standardized(crit, ua, u_star, n_p)[0])))
            a_eff, a_val = wce / wca, wca
        else:
            a_eff = float(np.exp((value - a_val) / n_p) if crit is Criterion.D else a_val / value)
    span = np.where(hi > lo, hi - lo, 1.0)
    return RobustRefined(points=_ro(X), start=_ro(X_start), names=tuple(names), value=float(value),
                         start_value=float(start_value), per_sample=_ro(u), worst_case_efficiency=wce,
                         approximate_efficiency=float(a_eff), approximate_value=a_val, approximate_gap=a_gap,
                         criterion=crit.value, robust=robust, spacing=float(np.max(h * settings.zoom / span)),
                         wall_time=time.perf_counter() - t0, notes=tuple(notes))


def _ro(a):
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def refine_robust_times(model, p, design, times, inputs, sigma, prior, u_star, *, criterion, robust, sensors=None,
                        n_series: int = 1, approx_settings=None,
                        settings: RobustRefineSettings = RobustRefineSettings()) -> RobustRefined:
    r"""The continuous refinement (:func:`refine_robust`) of an exact robust sampling-time design (``design``, a
    :class:`oed.robust_exact.RobustExactDesign` over the candidate ``times``) on [min(times), max(times)], first
    spacing the smallest gap between candidate times, information by
    :func:`oed.approximate.information_source`; with its efficiency against the approximate robust design on the
    same range (:func:`oed.approximate.approximate_design`, same prior points, ``approx_settings``)."""
    from .approximate import ApproximateSettings, approximate_design, information_source
    t = np.unique(np.asarray(times, float).ravel())
    if t.size < 2:
        raise ValueError("refine: the refinement of sampling times needs a range (at least two candidate times)")
    info, names = information_source(model, sigma, inputs, sensors, n_series)
    approx = approximate_design(model, p, sigma=sigma, bounds=(t.min(), t.max()), criterion=criterion, prior=prior,
                                robust=robust, inputs=inputs, sensors=sensors, n_series=n_series,
                                settings=approx_settings or ApproximateSettings())
    return refine_robust(info, t[list(design.indices)][:, None], prior, (t[:1], t[-1:]), criterion=criterion,
                         robust=robust, u_star=u_star, spacing=np.array([np.min(np.diff(t))]), names=names,
                         approximate=approx, settings=settings)
