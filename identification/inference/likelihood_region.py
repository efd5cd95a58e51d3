"""Likelihood-ratio regions of a parameter pair on a grid (:func:`lr_region`).

D_ij(theta_i, theta_j) = 2 (min over the other parameters of Phi with (p_i, p_j) = (theta_i, theta_j)
- Phi(p_hat)) on a grid for a pair of parameters (the others re-optimised by
:class:`identification.inference.profile_solver.Profiler`, warm-started from the previous grid point).

The grid's constrained fits are fits of one model with different fixed values: with
``solver=BATCHED_ROWS`` (default) the rows of the grid but the centre one are solved in batches of a few rows
(:func:`identification.fit.batch.fit_batch` on the derived model of
:func:`identification.fit.fixed.fixed_model`, the fixed values as per-member input columns, so K
points cost K n_q row evaluations per sweep), each point started from its solved neighbour in
the row before the block; points the batch does not converge are solved by the per-point Newton.
``python -m bench.bench_bootstrap_batch --profiles-only`` measured 2.1-4.2x less CPU per grid
point than the per-point path on valley grids (1.4-5.1x on axes grids; 11 x 11 and 25 x 25,
explicit and implicit 3-parameter models; the same statistic to 3e-10).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from models.contract import Model
from models.errors import StateSolveError
from identification.fit.batch import fit_batch
from identification.fit.fixed import fixed_batch, fixed_model, full_parameters
from identification.fit.measurements import Measurements
from identification.inference.intervals import region_threshold, resolve_params, validate_alpha
from identification.inference.profile_solver import (ProfileError, ProfileSettings, Profiler, Solved, check_pair,
                                                      readonly)

__all__ = ["LikelihoodRegion", "lr_region", "GRID_BLOCK_ROWS", "GridSolver", "PER_POINT", "BATCHED_ROWS", "grid_solver"]


#: rows of the grid solved as one batch by lr_region(solver=BATCHED_ROWS), each point started from its column's
#: point in the solved row before the block (1: row by row; 4 measured fastest of 1, 2, 4 with the same
#: continuation quality)
GRID_BLOCK_ROWS = 4


def _grid_per_point(prof: Profiler, idx: list, X: np.ndarray, Y: np.ndarray, C: np.ndarray, ph: np.ndarray) -> tuple:
    """(D, failed, outside, note) of the grid by the per-point solver, warm-started along rows from the
    point nearest the estimate (see :func:`lr_region`)."""
    n = X.shape[0]
    D = np.full((n, n), np.nan)
    failed = []
    outside = 0
    lo, up = prof.lo[idx], prof.up[idx]
    r0, c0 = _grid_centre(X, Y, C, ph)
    row_start = {}
    for rows in (range(r0, n), range(r0 - 1, -1, -1)):
        for r in rows:
            base = row_start.get(r - 1 if rows.step > 0 else r + 1, prof.best)
            for cc in list(range(c0, n)) + list(range(c0 - 1, -1, -1)):
                if cc == c0 - 1:
                    base = row_start.get(r, base)
                v = np.array([X[r, cc], Y[r, cc]])
                if np.any(v < lo) or np.any(v > up):
                    outside += 1
                    continue
                try:
                    s = prof.solve(idx, v, base)
                except ProfileError as exc:
                    failed.append(f"({v[0]:.6g}, {v[1]:.6g}): {exc}")
                    continue
                D[r, cc] = max(prof.statistic(s), 0.0)
                base = s
                if cc == c0:
                    row_start[r] = s
    return D, failed, outside, ""


def _grid_centre(X, Y, C, ph) -> tuple:
    """(row, column) of the grid point nearest the estimate (in standard errors)."""
    sd = np.sqrt(np.abs(np.diag(C))) + 1e-300
    near = ((X - ph[0]) / sd[0]) ** 2 + ((Y - ph[1]) / sd[1]) ** 2
    return tuple(int(k) for k in np.unravel_index(int(np.argmin(near)), near.shape))


@dataclass(frozen=True)
class _GridPoint:
    """A solved grid point: the full parameters, the states and (once needed) the Solved there."""

    p: np.ndarray
    states: np.ndarray
    solved: Solved | None = None


def _as_solved(prof: Profiler, sol: dict, key) -> Solved:
    """The Solved of grid point ``key`` (evaluated once for a batch point; the estimate when unsolved)."""
    g = sol.get(key)
    if g is None:
        return prof.best
    if g.solved is None:
        try:
            point = prof.problem.evaluate(g.p, g.states)
        except StateSolveError:
            return prof.best
        g = sol[key] = _GridPoint(g.p, g.states, prof.solved_at(point, False))
    return g.solved


def _row_per_point(prof: Profiler, idx, X, Y, r, c0, D, sol, failed, base_of) -> int:
    """Solve the unsolved points of row r one by one, outwards from column c0; the start of a point is
    its solved neighbour in the row (towards c0), else ``base_of(cc)``.  Returns the points solved."""
    n = X.shape[1]
    prev = None
    done = 0
    for cc in list(range(c0, n)) + [None] + list(range(c0 - 1, -1, -1)):
        if cc is None:
            prev = (r, c0) if (r, c0) in sol else None
            continue
        if (r, cc) in sol:
            prev = (r, cc)
            continue
        v = np.array([X[r, cc], Y[r, cc]])
        if np.any(v < prof.lo[idx]) or np.any(v > prof.up[idx]):
            continue
        base = _as_solved(prof, sol, prev) if prev is not None else base_of(cc)
        try:
            s = prof.solve(idx, v, base)
        except ProfileError as exc:
            failed.append(f"({v[0]:.6g}, {v[1]:.6g}): {exc}")
            continue
        D[r, cc] = max(prof.statistic(s), 0.0)
        sol[(r, cc)] = _GridPoint(np.asarray(s.point.p, float), np.asarray(s.point.states, float), s)
        prev = (r, cc)
        done += 1
    return done


def _grid_batched(prof: Profiler, idx: list, X: np.ndarray, Y: np.ndarray, C: np.ndarray, ph: np.ndarray) -> tuple:
    """(D, failed, outside, note) of the grid: the centre row point by point, the others in blocks of
    GRID_BLOCK_ROWS rows as batches of constrained fits (see :func:`lr_region`)."""
    model, data, est = prof.model, prof.data, prof.est
    n = X.shape[0]
    D = np.full((n, n), np.nan)
    failed = []
    lo, up = prof.lo[idx], prof.up[idx]
    inside = (X >= lo[0]) & (X <= up[0]) & (Y >= lo[1]) & (Y <= up[1])
    r0, c0 = _grid_centre(X, Y, C, ph)
    sol = {}                                     # (row, column) -> _GridPoint
    _row_per_point(prof, idx, X, Y, r0, c0, D, sol, failed, lambda cc: prof.best)
    fm = fixed_model(model, idx)
    rest = [k for k in range(model.n_p) if k not in idx]
    p0 = np.asarray(prof.best.point.p, float)[rest]
    ref = prof.best.point.objective
    redo = 0
    for rows, step in ((list(range(r0 + 1, n)), 1), (list(range(r0 - 1, -1, -1)), -1)):
        for b0 in range(0, len(rows), GRID_BLOCK_ROWS):
            block = rows[b0:b0 + GRID_BLOCK_ROWS]
            rb = block[0] - step             # the solved row the block starts from (same column)
            pts = [(r, cc) for r in block for cc in range(n) if inside[r, cc] and (rb, cc) in sol]
            if pts:
                starts = np.array([sol[(rb, cc)].p[rest] for _, cc in pts])
                states = np.array([sol[(rb, cc)].states.reshape(data.n_q, model.n_y) for _, cc in pts])
                values = np.array([[X[r, cc], Y[r, cc]] for r, cc in pts])
                bf = fit_batch(fm, fixed_batch(data.inputs, data.z, est.sigma, values), p0, est.weights,
                               starts=starts, start_states=states, fallback=False)
                for k, (r, cc) in enumerate(pts):
                    if bf.converged[k]:
                        res = bf.results[k]
                        D[r, cc] = max(2.0 * (res.objective - ref), 0.0)
                        sol[(r, cc)] = _GridPoint(full_parameters(model.n_p, idx, res.p, values[k]),
                                                  np.asarray(res.states, float))
            for r in block:
                redo += _row_per_point(prof, idx, X, Y, r, c0, D, sol, failed,
                                       lambda cc, rp=r - step: _as_solved(prof, sol, (rp, cc)))
    note = ""
    if redo:
        note = (f"{redo} grid points were solved point by point (the batch of their row did not converge there, "
                "or their neighbour in the previous row was not solved)")
    return D, failed, int(np.sum(~inside)), note



@dataclass(frozen=True)
class GridSolver:
    """A strategy of :func:`lr_region` for the grid's constrained fits, chosen once per region.

    Attributes
    ----------
    name : str
    solve : callable    (profiler, pair indices, X, Y, pair covariance, pair estimate) -> (D, failed
                        points, points outside the bounds, note)
    """

    name: str
    solve: Callable


#: every grid point by the per-point constrained Newton, warm-started along rows from the centre
PER_POINT = GridSolver("per point", _grid_per_point)
#: the centre row per point, the other rows in blocks of GRID_BLOCK_ROWS as batched fits (fit_batch)
BATCHED_ROWS = GridSolver("batched rows", _grid_batched)


def grid_solver(solver: GridSolver, n_p: int, batch: "bool | None" = None) -> GridSolver:
    """The strategy of :func:`lr_region`: ``solver`` as given (:data:`PER_POINT` for a model of two
    parameters: no free parameter to batch).  ``batch`` (deprecated, a bool) is the old spelling:
    True -> :data:`BATCHED_ROWS`, False -> :data:`PER_POINT`, with a DeprecationWarning."""
    if batch is not None:
        if not isinstance(batch, (bool, np.bool_)):
            raise TypeError(f"batch: expected True or False (deprecated; pass solver=PER_POINT or BATCHED_ROWS), "
                            f"got {batch!r}")
        warnings.warn("lr_region(batch=...) is deprecated: pass solver=BATCHED_ROWS (the default) or "
                      "solver=PER_POINT (identification.inference.likelihood_region)", DeprecationWarning,
                      stacklevel=3)
        solver = BATCHED_ROWS if batch else PER_POINT
    if not isinstance(solver, GridSolver):
        raise TypeError(f"solver: expected a GridSolver (PER_POINT, BATCHED_ROWS), got {solver!r}")
    return PER_POINT if solver is BATCHED_ROWS and n_p <= 2 else solver


# ---------------------------------------------------------------------------- pair regions
def _valley_grid(prof: Profiler, idx: list, C: np.ndarray, ph: np.ndarray, c: float, n: int, span: float,
                 lim) -> tuple:
    """X, Y (n, n) of the valley grid of :func:`lr_region` (column k: p_i = a_k) and a note ('' or the
    values of a where the profile point could not be solved and the linearised valley was used)."""
    i, j = idx
    model = prof.model
    half = span * math.sqrt(c * C[0, 0])
    a_lo, a_hi = (lim[0] if lim is not None else (ph[0] - half, ph[0] + half))
    a = np.linspace(max(a_lo, model.lower[i]), min(a_hi, model.upper[i]), n)
    v = np.linspace(-span * math.sqrt(c), span * math.sqrt(c), n)
    rest = [k for k in range(model.n_p) if k != i]
    jr = rest.index(j)
    centre = np.empty(n)
    width = np.empty(n)
    lin_sd = math.sqrt(max(C[1, 1] - C[0, 1] ** 2 / C[0, 0], 0.0))
    k0 = int(np.argmin(np.abs(a - ph[0])))
    unsolved = []
    for ks in (range(k0, n), range(k0 - 1, -1, -1)):
        base = prof.best
        for k in ks:
            try:
                s = prof.solve([i], [a[k]], base)
                K = s.H[np.ix_(rest, rest)]
                sd = math.sqrt(float(np.linalg.inv(K)[jr, jr]))
                if not (math.isfinite(sd) and sd > 0):
                    raise np.linalg.LinAlgError("singular")
                centre[k], width[k] = s.point.p[j], sd
                base = s
            except (ProfileError, np.linalg.LinAlgError):
                unsolved.append(a[k])
                centre[k] = ph[1] + C[0, 1] / C[0, 0] * (a[k] - ph[0])
                width[k] = lin_sd
    X = np.tile(a, (n, 1))
    Y = centre[None, :] + v[:, None] * width[None, :]
    note = ""
    if unsolved:
        note = (f"valley grid: the profile of {model.param_names[i]} could not be solved at {len(unsolved)} of {n} "
                "values; the linearised valley was used there")
    return X, Y, note


@dataclass(frozen=True)
class LikelihoodRegion:
    """The likelihood-ratio statistic of a parameter pair on a grid.

    D(a, b) = 2 (min over the other parameters of Phi with (p_i, p_j) = (a, b) - Phi(p_hat)),
    the region {D <= threshold}.

    Attributes
    ----------
    names : (str, str)
    X, Y : ndarray (n, n)           grid values of p_i and p_j (row r, column k); a rectangle
                                    (``grid="axes"``) or the principal axes of the ellipse
                                    (``grid="principal"``)
    statistic : ndarray (n, n)      D on the grid (NaN where the point could not be solved or lies
                                    outside the bounds; see notes)
    threshold : float               chi2_2(1 - alpha) or 2 F(2, dof; 1 - alpha)
    alpha : float
    estimate : ndarray (2,)         (p_i, p_j) at the estimate
    cov : ndarray (2, 2)            their block of the second-order covariance (the linearised ellipse
                                    is d^T cov^-1 d <= threshold)
    notes : tuple of str            unsolved points, a region reaching the edge of the grid
    indices : (int, int)            positions of the pair in the parameter vector
    """

    names: tuple
    X: np.ndarray
    Y: np.ndarray
    statistic: np.ndarray
    threshold: float
    alpha: float
    estimate: np.ndarray
    cov: np.ndarray
    notes: tuple = ()
    indices: tuple = (0, 1)

    def __post_init__(self):
        for name in ("X", "Y", "statistic", "estimate", "cov"):
            object.__setattr__(self, name, readonly(getattr(self, name)))

    def linearised(self) -> np.ndarray:
        """The quadratic form d^T cov^-1 d on the grid (n, n): the statistic of a linear model."""
        dx, dy = self.X - self.estimate[0], self.Y - self.estimate[1]
        Ci = np.linalg.inv(self.cov)
        return Ci[0, 0] * dx ** 2 + 2 * Ci[0, 1] * dx * dy + Ci[1, 1] * dy ** 2


def lr_region(model: Model, data: Measurements, est, pair, alpha: float = 0.05, n_grid: int = 25,
              span: float = 1.6, grid: str = "principal", settings: ProfileSettings | None = None,
              limits=None, solver: GridSolver = BATCHED_ROWS, batch: "bool | None" = None) -> LikelihoodRegion:
    """Likelihood-ratio statistic of the pair ``pair = (i, j)`` on an n_grid x n_grid grid.

    ``grid="principal"`` (default): the grid p = p_hat + V diag(sqrt(w)) (u, v) with C = V diag(w) V^T
    the pair's covariance block and u, v in [-span sqrt(c), span sqrt(c)], so that the linearised
    ellipse is the circle of radius sqrt(c) and a thin, strongly correlated region still falls on
    many grid points; ``grid="valley"``: a curvilinear grid that follows the valley of the objective
    -- columns at n_grid values a of p_i (``limits[0]``, or span x the ellipse's half-width), rows
    across it at p_j = b*(a) + v sd_j(a), b*(a) the profile of p_i (p_j and the others re-optimised),
    sd_j(a) the standard error of p_j there with p_i fixed and v in [-span sqrt(c), span sqrt(c)] --
    for thin curved regions (strong correlation) that no rectangle resolves; ``grid="axes"``: the rectangle of span x the ellipse's half-extents, or
    ``limits = ((lo_i, hi_i), (lo_j, hi_j))`` when given (parameter units, clipped to the bounds; e.g.
    the extent of the profile traces, when the region reaches far beyond the ellipse).  The other
    parameters are re-optimised at every grid point (exact reduced Newton, Ipopt fallback),
    warm-started along rows from the grid centre.  A point that cannot be solved or lies outside the
    bounds is NaN, counted in ``notes``; a region that reaches the edge of the grid is noted too.

    ``solver=BATCHED_ROWS`` (default): the row through the point nearest the estimate is solved point by
    point as above; the other rows, in blocks of :data:`GRID_BLOCK_ROWS` outwards from it, are one
    :func:`identification.fit.batch.fit_batch` call per block on the derived model
    :func:`identification.fit.fixed.fixed_model` (the pair's values as per-member input columns), each
    point started from its column's solved point in the row before the block (towards the
    centre); a point the batch does not converge (or ends on a bound) is solved point by point
    from its neighbour, counted in ``notes``.  ``solver=PER_POINT``, or a model of two parameters (no
    free parameter left): every point by the per-point solver.  The strategy is chosen once
    (:func:`grid_solver`); ``batch=True/False`` is the deprecated spelling of the two.
    """
    alpha = validate_alpha(alpha)
    idx = resolve_params(list(pair), tuple(est.param_names))
    if len(idx) != 2:
        raise ValueError(f"pair: expected two different parameters, got {pair!r}")
    if not (isinstance(n_grid, (int, np.integer)) and n_grid >= 3):
        raise ValueError(f"n_grid: expected an integer >= 3, got {n_grid!r}")
    if not (span > 0 and math.isfinite(span)):
        raise ValueError(f"span: expected a positive number, got {span!r}")
    if grid not in ("principal", "axes", "valley"):
        raise ValueError(f"grid: expected 'principal', 'axes' or 'valley', got {grid!r}")
    if limits is not None:
        lim = np.asarray(limits, float)
        if lim.shape != (2, 2) or not np.all(np.isfinite(lim)) or np.any(lim[:, 1] <= lim[:, 0]):
            raise ValueError(f"limits: expected ((lo_i, hi_i), (lo_j, hi_j)) with finite lo < hi, got {limits!r}")
        if grid == "principal":
            grid = "axes"
    valley_note = ""
    check_pair(model, data, est)
    if getattr(est, "unbounded", None) is not None:     # no finite minimum to grid around
        est.require_bounded("lr_region")
    settings = settings or ProfileSettings()
    prof = Profiler(model, data, est, settings)
    c = region_threshold(alpha, est.sigma_estimated, est.dof)
    C = np.asarray(est.cov)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(C)):
        C = np.asarray(est.cov_gn)[np.ix_(idx, idx)]
    ph = np.asarray(est.p, float)[idx]
    n = int(n_grid)
    if grid == "axes":
        half = span * np.sqrt(c * np.diag(C))
        box = lim if limits is not None else np.column_stack([ph - half, ph + half])
        x = np.linspace(max(box[0, 0], model.lower[idx[0]]), min(box[0, 1], model.upper[idx[0]]), n)
        y = np.linspace(max(box[1, 0], model.lower[idx[1]]), min(box[1, 1], model.upper[idx[1]]), n)
        X, Y = np.meshgrid(x, y)
    elif grid == "valley":
        X, Y, valley_note = _valley_grid(prof, idx, C, ph, c, n, span, lim if limits is not None else None)
    else:
        w, V = np.linalg.eigh(0.5 * (C + C.T))
        L = V * np.sqrt(np.clip(w, 0.0, None))[None, :]
        u = np.linspace(-span * math.sqrt(c), span * math.sqrt(c), n)
        U, W = np.meshgrid(u, u)
        X = ph[0] + L[0, 0] * U + L[0, 1] * W
        Y = ph[1] + L[1, 0] * U + L[1, 1] * W
    chosen = grid_solver(solver, model.n_p, batch)  # chosen once (a pair alone: nothing to fit, per point)
    D, failed, outside, batch_note = chosen.solve(prof, idx, X, Y, C, ph)
    notes = [valley_note] if valley_note else []
    if batch_note:
        notes.append(batch_note)
    if failed:
        notes.append(f"{len(failed)} of {D.size} grid points could not be solved (NaN); first: {failed[0]}")
    if outside:
        notes.append(f"{outside} of {D.size} grid points lie outside the parameter bounds (NaN)")
    edge = np.concatenate([D[0], D[-1], D[:, 0], D[:, -1]])
    if np.any(edge[np.isfinite(edge)] <= c):
        notes.append("the region reaches the edge of the grid: it extends beyond it (use a larger span)")
    return LikelihoodRegion((est.param_names[idx[0]], est.param_names[idx[1]]), X, Y, D, c, alpha, ph, C,
                            tuple(notes), tuple(idx))
