r"""Model-discrimination designs: the readings that best separate two candidate models.

For two models a, b with estimates :math:`\hat p_a, \hat p_b`, candidate input rows
:math:`q_i` (one physical experiment point; the two models may read it through different
input vectors) and candidate sensors s, each reading (i, s) gets a divergence

.. math::

    \text{"T"}:\qquad d_{is} = \Bigl(\frac{h_{a,s}(q_i, \hat p_a) - h_{b,s}(q_i, \hat p_b)}{\sigma_s}\Bigr)^2,

the local (fixed-estimate) form of Atkinson and Fedorov's T-optimality: the
non-centrality that reading (i, s) adds to the chi-square test of model b when a is
true, with b's parameters held at :math:`\hat p_b` (refitting b on the new readings can
only lower it, so the sum is an upper bound of the true non-centrality);

.. math::

    \text{"divergence"}:\qquad d_{is} = \frac{(h_{a,s} - h_{b,s})^2}{2\sigma_s^2 + V_{a,is} + V_{b,is}},
    \qquad V_{m,is} = g_{m,is}^\top C_m\, g_{m,is},\quad g_{m,is} = \partial h_{m,s}(q_i, p)/\partial p\,|_{\hat p_m},

the Buzzi-Ferraris and Forzatti / Asprey and Macchietto flavour: the squared difference
of the two models' predictions divided by the variance of the difference of their
predictive distributions of a new reading (each :math:`N(h_m, \sigma_s^2 + V_m)`, the
two independent), so that readings where the models differ only within their parameter
uncertainty count little.  :math:`C_m` is the covariance of the estimate (the
:class:`identification.Estimate`'s ``cov``, or given), g_m the exact sensitivity through
the implicit state (CasADi AD).  The readings are treated as independent (the scalar,
per-reading form; Asprey and Macchietto's matrix form couples readings through
:math:`C_m`).

and the refitted local T-criterion (``"T_refit"``), Atkinson and Fedorov's T with the rival's
parameters re-estimated on the design, linearised at :math:`\hat p_b`:

.. math::

    \Phi_\text{refit}(D) = \min_\delta \sum_{(i,s)\in D}
        \Bigl(\frac{h_{a,s} - h_{b,s} - g_{b,is}^\top \delta}{\sigma_s}\Bigr)^2
      = c_D - b_D^\top A_D^{-1} b_D,

with :math:`A_D = \sum g g^\top/\sigma^2`, :math:`b_D = \sum g (h_a - h_b)/\sigma^2`,
:math:`c_D = \sum (h_a - h_b)^2/\sigma^2` over D: the non-centrality of the rival's
goodness-of-fit (or likelihood-ratio) test when a is true and b is refitted, to first order in
b's parameters (exact when b is linear in them).  Refitting absorbs the part of the difference
that b can mimic, so the fixed-estimate T overstates designs whose difference lies along
b's sensitivities.  :math:`\Phi_\text{refit}` is not a sum: it is maximised by enumerating
the designs (at most ``enumeration_limit``; beyond, an error says so), and designs on which b's
parameters are not identifiable (:math:`A_D` singular) are inadmissible.

The "T" and "divergence" criteria are sums over the chosen readings, :math:`\Phi(D) = \sum_{(i,s)\in D} d_{is}`
(larger is better), and the designs are

* ``n_points=k``, ``n_sensors=None``: k input rows, every given sensor read at each;
* ``n_points=None``, ``n_sensors=m``: every input row, m sensors;
* ``n_points=k``, ``n_sensors=m``: k rows x m sensors, the m sensors read at all k rows;
* ``n_readings=n``: n free (input, sensor) pairs.

Cases 1, 2 and 4 are separable, and the top-k of the scores is optimal (proof at
:func:`top_k`).  Case 3 is a maximum-weight k x m submatrix, NP-hard in general; for a
fixed sensor set the best rows are the top-k of the row sums over that set, so
enumerating the smaller side's subsets (``min(C(n_S, m), C(n_q, k))`` of them) is an
exact algorithm.  Beyond ``enumeration_limit`` an alternating ascent (best rows for the
sensors, best sensors for the rows, from several starts) runs and is compared with the
upper bound

.. math::

    \Phi^* \le \min\Bigl(\sum_{\text{top-}k\ i} \sum_{\text{top-}m\ s} d_{is},\;
                       \sum_{\text{top-}m\ s} \sum_{\text{top-}k\ i} d_{is}\Bigr),

(each row contributes at most its m largest entries, and the best k rows at most the k
largest such sums; the same by columns); ``proven_optimal`` is true only when the design
reaches the bound.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from models.contract import Model
from models.sensitivity import sensitivities
from models.state import solve_states
from identification.results_protocol import ResultProtocol, jsonable

__all__ = ["DiscriminationResult", "DiscriminationError", "select_discriminating", "reading_divergences", "top_k",
           "refit_values"]

_CRITERIA = ("T", "divergence", "T_refit")


class DiscriminationError(ValueError):
    """Bad argument of a discrimination design (the message names it)."""


@dataclass(frozen=True)
class DiscriminationResult(ResultProtocol):
    """Immutable outcome of :func:`select_discriminating` (the result protocol: :meth:`summary`,
    :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    indices : tuple of int
        Chosen candidate input rows (sorted).
    sensors : tuple of str
        Chosen sensors (every one read at every chosen row), in candidate order; for
        ``n_readings`` designs the sensors that occur in ``readings``.
    readings : tuple of (int, str)
        The chosen (row, sensor) readings.
    value : float
        :math:`\\Phi(D) = \\sum_{(i,s)\\in D} d_{is}` (dimensionless; for "T" the non-centrality).
    upper_bound : float
        Proven upper bound on the optimal value (equal to ``value`` when proven optimal).
    proven_optimal : bool
    method : str
        ``top-k`` (separable), ``enumerate-sensors`` / ``enumerate-inputs`` (exact joint) or
        ``alternating`` (heuristic with the bound).
    criterion : str
    divergences : ndarray (n_q, n_S), read-only
        Per-candidate d_is for all candidate rows and sensors.
    difference : ndarray (n_q, n_S), read-only
        h_a - h_b at every candidate (output units).
    candidate_sensors : tuple of str
    n_designs : int
        Designs (or one side's subsets) evaluated.
    axis : str
        The candidates' axis: ``"input_pairs"`` (every reading is a (row, sensor) pair).
    chosen : tuple of str
        The chosen readings' labels ``q<i>:<sensor>`` (as :attr:`oed.InputDesignResult.chosen`).
    """

    indices: tuple
    sensors: tuple
    readings: tuple
    value: float
    upper_bound: float
    proven_optimal: bool
    method: str
    criterion: str
    divergences: np.ndarray
    difference: np.ndarray
    candidate_sensors: tuple
    n_designs: int

    axis = "input_pairs"

    @property
    def chosen(self) -> tuple:
        """The chosen readings' labels ``q<i>:<sensor>``."""
        return tuple(f"q{i}:{s}" for i, s in self.readings)

    def summary(self) -> str:
        """Human-readable summary."""
        return "\n".join([
            f"discrimination design ({self.criterion}) via {self.method}"
            + (" (proven optimal)" if self.proven_optimal else f" (upper bound {self.upper_bound:.6g})"),
            f"  rows: {list(self.indices)}",
            f"  sensors: {', '.join(self.sensors)}",
            f"  value: {self.value:.6g} over {len(self.readings)} readings",
        ])

    def to_frame(self):
        """One row per chosen reading (candidate ``row``, ``sensor``): its divergence d_is (dimensionless) and
        the difference h_a - h_b (output units); ``.attrs``: criterion, value, upper_bound, proven_optimal,
        method."""
        import pandas as pd
        cols = list(self.candidate_sensors)
        rows = [dict(row=int(j), sensor=s, divergence=float(self.divergences[j, cols.index(s)]),
                     difference=float(self.difference[j, cols.index(s)])) for j, s in self.readings]
        df = pd.DataFrame(rows, columns=["row", "sensor", "divergence", "difference"])
        df.attrs.update(criterion=self.criterion, value=self.value, upper_bound=self.upper_bound,
                        proven_optimal=self.proven_optimal, method=self.method)
        return df

    def to_dict(self) -> dict:
        """JSON-safe: the chosen indices, sensors and readings, value, upper_bound, proven_optimal, method,
        criterion, candidate_sensors, n_designs and the per-candidate divergences and differences (n_q, n_S)."""
        return jsonable(dict(indices=self.indices, sensors=self.sensors, readings=self.readings, value=self.value,
                             upper_bound=self.upper_bound, proven_optimal=self.proven_optimal, method=self.method,
                             criterion=self.criterion, candidate_sensors=self.candidate_sensors,
                             n_designs=self.n_designs, divergences=self.divergences, difference=self.difference))


def top_k(scores, k: int) -> np.ndarray:
    r"""Indices of the k largest scores (ties: lower index first), sorted ascending.

    Optimality for separable criteria: maximise :math:`\sum_{e\in D} c_e` over :math:`|D| = k`
    with scores c independent of D.  Let T be the top-k set and D any feasible set with
    :math:`D\ne T`; pick :math:`e\in D\setminus T` and :math:`f\in T\setminus D`.  By
    construction :math:`c_f \ge c_e`, so :math:`D' = D - e + f` is feasible with
    :math:`\Phi(D') \ge \Phi(D)` and :math:`|D'\setminus T| = |D\setminus T| - 1`.  After
    :math:`|D\setminus T|` exchanges D becomes T, hence :math:`\Phi(T)\ge\Phi(D)`.
    """
    scores = np.asarray(scores, float).ravel()
    order = np.argsort(-scores, kind="stable")
    return np.sort(order[:k])


# ---------------------------------------------------------------------------- inputs
def _params_and_cov(p, cov, model, name):
    """(p, C) from an array or an object with ``p`` and ``cov`` (an Estimate)."""
    if hasattr(p, "p") and hasattr(p, "cov"):
        if cov is None:
            cov = p.cov
        p = p.p
    p = np.asarray(p, float).ravel()
    if p.shape != (model.n_p,) or not np.isfinite(p).all():
        raise DiscriminationError(f"{name}: expected {model.n_p} finite values ({', '.join(model.param_names)}), "
                                  f"got {np.asarray(p).shape}")
    outside = [pp.name for pp, v in zip(model.params, p) if not pp.lower <= v <= pp.upper]
    if outside:
        raise DiscriminationError(f"{name}: parameter(s) {', '.join(outside)} outside their bounds")
    if cov is not None:
        cov = np.asarray(cov, float)
        if cov.shape != (model.n_p, model.n_p) or not np.isfinite(cov).all():
            raise DiscriminationError(f"cov for {name}: expected a finite ({model.n_p}, {model.n_p}) matrix, "
                                      f"got shape {cov.shape}")
        cov = 0.5 * (cov + cov.T)
        if np.linalg.eigvalsh(cov).min() < -1e-12 * max(1.0, np.abs(cov).max()):
            raise DiscriminationError(f"cov for {name}: not positive semidefinite")
    return p, cov


def _candidate_rows(candidates, model_a, model_b):
    """(Q_a, Q_b): one matrix for both models or a pair of row-aligned matrices."""
    if isinstance(candidates, (tuple, list)) and len(candidates) == 2 and np.ndim(candidates[0]) == 2:
        qa, qb = (np.asarray(c, float) for c in candidates)
    else:
        qa = qb = np.asarray(candidates, float)
        if qa.ndim == 1:
            qa = qb = qa[:, None]
    for q, m, which in ((qa, model_a, "a"), (qb, model_b, "b")):
        if q.ndim != 2 or q.shape[1] != m.n_q_dim:
            raise DiscriminationError(f"candidates: model_{which} needs rows of {m.n_q_dim} inputs "
                                      f"({', '.join(m.inputs)}), got shape {q.shape}; pass (Q_a, Q_b) when the "
                                      "models read a point through different input vectors")
        if q.shape[0] == 0 or not np.isfinite(q).all():
            raise DiscriminationError("candidates: expected a non-empty matrix of finite inputs (no NaN)")
    if qa.shape[0] != qb.shape[0]:
        raise DiscriminationError(f"candidates: Q_a has {qa.shape[0]} rows, Q_b {qb.shape[0]}; row i of both is "
                                  "one experiment point")
    both = np.hstack([qa, qb]) if qa is not qb else qa
    if np.unique(both, axis=0).shape[0] != both.shape[0]:
        raise DiscriminationError("candidates: duplicate rows; each candidate point must appear once")
    return qa, qb


def _common_sensors(model_a, model_b, sensors):
    if sensors is None:
        names = tuple(s for s in model_a.sensors if s in model_b.sensors)
        if not names:
            raise DiscriminationError("sensors: model_a and model_b have no sensor in common")
        return names
    if isinstance(sensors, str):
        sensors = (sensors,)
    names = tuple(sensors)
    if not names or len(set(names)) != len(names):
        raise DiscriminationError(f"sensors: expected distinct sensor names, got {sensors!r}")
    for m, which in ((model_a, "a"), (model_b, "b")):
        missing = [s for s in names if s not in m.sensors]
        if missing:
            raise DiscriminationError(f"sensors: {', '.join(missing)} not sensors of model_{which} "
                                      f"({', '.join(m.sensors)})")
    return names


def _sigma(sigma, names):
    if isinstance(sigma, dict):
        missing = [s for s in names if s not in sigma]
        if missing:
            raise DiscriminationError(f"sigma: no value for sensor(s) {', '.join(missing)}")
        sig = np.array([float(sigma[s]) for s in names])
    else:
        sig = np.asarray(sigma, float).ravel()
        if sig.size == 1:
            sig = np.full(len(names), float(sig[0]))
    if sig.shape != (len(names),) or not (np.isfinite(sig).all() and np.all(sig > 0)):
        raise DiscriminationError(f"sigma: expected {len(names)} positive finite values (one per sensor "
                                  f"{', '.join(names)}) or a dict, got {sigma!r}")
    return sig


def _count(value, name, upper, what):
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= upper:
        raise DiscriminationError(f"{name}: expected an integer in 1..{upper} ({what}), got {value!r}")
    return int(value)


# ---------------------------------------------------------------------------- divergences
def _outputs(model, p, q, idx, with_gradient):
    Y = solve_states(model, p, q)
    sens = sensitivities(model, p, q, Y)
    return sens.h[:, idx], (sens.G[:, idx, :] if with_gradient else None)


def reading_divergences(model_a, p_a, model_b, p_b, candidates, sensors=None, sigma=1.0, criterion="T",
                        cov_a=None, cov_b=None):
    r"""Per-reading divergences d_is and differences h_a - h_b (see the module docstring).

    Parameters
    ----------
    model_a, model_b : models.Model
    p_a, p_b : array_like or Estimate
        Parameters (an Estimate also supplies its ``cov``).
    candidates : array_like (n_q, d_q) or (Q_a, Q_b)
        Candidate input rows; a pair when the models take different input vectors (row i of
        both is the same experiment point).
    sensors : sequence of str, optional
        Candidate sensors (default: the sensors common to both models).
    sigma : float, array_like (n_S,) or dict
        Reading standard deviations (output units).
    criterion : {"T", "divergence", "T_refit"}
    cov_a, cov_b : array_like (n_p, n_p), optional
        Covariances of the estimates ("divergence" only; default the Estimates' ``cov``).

    Returns
    -------
    (d, diff, sensor_names): ndarrays (n_q, n_S) and a tuple of str.
    """
    for m, which in ((model_a, "model_a"), (model_b, "model_b")):
        if not isinstance(m, Model):
            raise DiscriminationError(f"{which}: expected a models.Model, got {type(m).__name__}")
    if criterion not in _CRITERIA:
        raise DiscriminationError(f"criterion: expected one of {_CRITERIA}, got {criterion!r}")
    pa, ca_ = _params_and_cov(p_a, cov_a, model_a, "p_a")
    pb, cb_ = _params_and_cov(p_b, cov_b, model_b, "p_b")
    qa, qb = _candidate_rows(candidates, model_a, model_b)
    names = _common_sensors(model_a, model_b, sensors)
    sig = _sigma(sigma, names)
    div = criterion == "divergence"
    if criterion == "T_refit":
        criterion = "T"                      # per reading: the fixed-estimate T (the refit is not a sum)
    if div and (ca_ is None or cb_ is None):
        raise DiscriminationError("cov_a, cov_b: the 'divergence' criterion needs the covariance of both "
                                  "estimates (pass Estimates as p_a, p_b or give cov_a, cov_b)")
    ha, ga = _outputs(model_a, pa, qa, model_a.sensor_index(names), div)
    hb, gb = _outputs(model_b, pb, qb, model_b.sensor_index(names), div)
    diff = ha - hb
    if div:
        va = np.einsum("jsp,pr,jsr->js", ga, ca_, ga)
        vb = np.einsum("jsp,pr,jsr->js", gb, cb_, gb)
        d = diff ** 2 / (2.0 * sig ** 2 + va + vb)
    else:
        d = (diff / sig) ** 2
    return d, diff, names


# ---------------------------------------------------------------------------- joint k x m design
def _best_rows(d, cols, k):
    rows = top_k(d[:, list(cols)].sum(axis=1), k)
    return rows, float(d[np.ix_(rows, list(cols))].sum())


def _best_cols(d, rows, m):
    cols = top_k(d[list(rows), :].sum(axis=0), m)
    return cols, float(d[np.ix_(list(rows), cols)].sum())


def _joint_upper_bound(d, k, m):
    row_best = -np.sort(-d, axis=1)[:, :m].sum(axis=1)
    col_best = -np.sort(-d, axis=0)[:k, :].sum(axis=0)
    return float(min(np.sort(row_best)[::-1][:k].sum(), np.sort(col_best)[::-1][:m].sum()))


@dataclass(frozen=True)
class _Search:
    """What a design search found: the chosen rows and sensor columns, the criterion value, an upper bound
    on the optimum (the value itself when proven), whether it is proven optimal, the method and how many
    designs it evaluated."""

    rows: tuple
    cols: tuple
    value: float
    bound: float
    proven: bool
    method: str
    count: int

    @classmethod
    def exact(cls, rows, cols, value: float, method: str, count: int) -> "_Search":
        """A search whose value is proven optimal (its own bound)."""
        return cls(tuple(rows), tuple(cols), float(value), float(value), True, method, int(count))


def _joint_design(d, k, m, limit, n_starts) -> _Search:
    """Exact (enumerating the smaller side) or alternating ascent with the bound."""
    n_q, n_S = d.shape
    n_cols, n_rows = math.comb(n_S, m), math.comb(n_q, k)
    ub = _joint_upper_bound(d, k, m)
    if min(n_cols, n_rows) <= limit:
        best = (-np.inf, None, None)
        if n_cols <= n_rows:
            for cols in combinations(range(n_S), m):
                rows, v = _best_rows(d, cols, k)
                if v > best[0]:
                    best = (v, rows, np.array(cols))
            method, n = "enumerate-sensors", n_cols
        else:
            for rows in combinations(range(n_q), k):
                cols, v = _best_cols(d, rows, m)
                if v > best[0]:
                    best = (v, np.array(rows), cols)
            method, n = "enumerate-inputs", n_rows
        return _Search.exact(best[1], best[2], best[0], method, n)
    starts = [top_k(d.sum(axis=0), m)] + [top_k(d[i], m) for i in top_k(d.max(axis=1), min(n_starts, n_q))]
    best = (-np.inf, None, None)
    n = 0
    for cols in starts:
        value = -np.inf
        while True:
            rows, _ = _best_rows(d, cols, k)
            cols, v = _best_cols(d, rows, m)
            n += 1
            if v <= value * (1 + 1e-15):
                break
            value = v
        if value > best[0]:
            best = (value, rows, cols)
    proven = best[0] >= ub * (1 - 1e-12)
    return _Search(tuple(best[1]), tuple(best[2]), float(best[0]), float(best[0] if proven else ub), bool(proven),
                   "alternating", n)


# ---------------------------------------------------------------------------- front door
def select_discriminating(model_a, p_a, model_b, p_b, candidates, sensors=None, sigma=1.0, n_points=None,
                          n_sensors=None, criterion="T", *, n_readings=None, cov_a=None, cov_b=None,
                          enumeration_limit: int = 200_000, n_starts: int = 10) -> DiscriminationResult:
    r"""Readings that maximise :math:`\Phi(D) = \sum_{(i,s)\in D} d_{is}` between models a and b.

    See the module docstring for d_is ("T": Atkinson-Fedorov non-centrality at the
    estimates; "divergence": normalised by the predictive variances) and for the
    optimality of each design shape.

    Parameters
    ----------
    model_a, model_b : models.Model
        a: the model assumed true; b: the rival to be refuted (for "T" the order matters
        only through which estimate is held; d_is is symmetric in a and b).
    p_a, p_b : array_like or identification.Estimate
    candidates : array_like (n_q, d_q) or (Q_a, Q_b)
        Candidate input rows (no NaN, no duplicates).
    sensors : sequence of str, optional
        Candidate sensors, common to both models (default all common ones).
    sigma : float, array_like or dict
        Reading standard deviation per sensor (output units).
    n_points : int, optional
        Number k of input rows to choose (default: all rows).
    n_sensors : int, optional
        Number m of sensors read at every chosen row (default: all candidate sensors).
    criterion : {"T", "divergence", "T_refit"}
    n_readings : int, optional
        Instead of n_points / n_sensors: n free (row, sensor) readings.
    cov_a, cov_b : array_like, optional
        Covariances of the estimates ("divergence").
    enumeration_limit : int
        Largest number of one side's subsets enumerated for the joint k x m design.
    n_starts : int
        Extra starts of the alternating ascent (beyond the limit).

    Returns
    -------
    DiscriminationResult

    Raises
    ------
    DiscriminationError
        Bad input (the message names the argument).
    """
    d, diff, names = reading_divergences(model_a, p_a, model_b, p_b, candidates, sensors, sigma, criterion,
                                         cov_a, cov_b)
    n_q, n_S = d.shape
    k = _count(n_points, "n_points", n_q, f"at most the {n_q} candidate rows")
    m = _count(n_sensors, "n_sensors", n_S, f"at most the {n_S} candidate sensors")
    n = _count(n_readings, "n_readings", n_q * n_S, f"at most the {n_q * n_S} candidate readings")
    if n is not None and (k is not None or m is not None):
        raise DiscriminationError("n_readings: give either n_readings or n_points / n_sensors, not both")
    if not (isinstance(enumeration_limit, (int, np.integer)) and enumeration_limit >= 0):
        raise DiscriminationError(f"enumeration_limit: expected an integer >= 0, got {enumeration_limit!r}")
    if criterion == "T_refit":
        g = _rival_sensitivities(model_b, p_b, candidates, model_a, names, sigma)
        return _refit_design(d, diff, names, g, k, m, n, int(enumeration_limit))
    if n is not None:
        flat = top_k(d, n)
        pairs = [divmod(int(e), n_S) for e in flat]
        rows = sorted({i for i, _ in pairs})
        cols = sorted({s for _, s in pairs})
        readings = tuple((i, names[s]) for i, s in pairs)
        value = float(d.ravel()[flat].sum())
        return _result(_Search.exact(rows, cols, value, "top-k", 1), readings, criterion, d, diff, names)
    if k is not None and m is not None and k < n_q and m < n_S:
        found = _joint_design(d, k, m, int(enumeration_limit), int(n_starts))
    else:
        cols = top_k(d.sum(axis=0), m) if m is not None else np.arange(n_S)
        rows = top_k(d[:, cols].sum(axis=1), k) if k is not None else np.arange(n_q)
        found = _Search.exact(rows, cols, float(d[np.ix_(rows, cols)].sum()), "top-k", 1)
    readings = tuple((int(i), names[s]) for i in found.rows for s in found.cols)
    return _result(found, readings, criterion, d, diff, names)


def _rival_sensitivities(model_b, p_b, candidates, model_a, names, sigma):
    """g_is = (dh_b,s / dp)(q_i, p_b) / sigma_s, shape (n_q, n_S, n_p)."""
    pb, _ = _params_and_cov(p_b, None, model_b, "p_b")
    _, qb = _candidate_rows(candidates, model_a, model_b)
    _, G = _outputs(model_b, pb, qb, model_b.sensor_index(names), True)
    return G / _sigma(sigma, names)[None, :, None]


def _refit_one(A_e, b_e, d, design):
    """Phi_refit of one design ((row, col) pairs), or None when the rival's information is singular on it."""
    ii, ss = zip(*design)
    A = A_e[ii, ss].sum(axis=0)
    w = np.linalg.eigvalsh(A)
    if w[0] <= 1e-10 * max(w[-1], 1e-300) * A.shape[0]:
        return None
    b = b_e[ii, ss].sum(axis=0)
    return float(d[ii, ss].sum() - b @ np.linalg.solve(A, b))


def _refit_terms(d, diff, g):
    r = np.sqrt(d) * np.sign(diff)                                   # (h_a - h_b) / sigma
    return np.einsum("jsp,jsr->jspr", g, g), g * r[:, :, None]


def refit_values(model_a, p_a, model_b, p_b, candidates, designs, sensors=None, sigma=1.0) -> list:
    r"""The refitted T-criterion :math:`\Phi_\text{refit}(D)` (module docstring) of each design.

    Parameters
    ----------
    model_a, model_b, p_a, p_b, candidates, sensors, sigma
        As in :func:`select_discriminating`.
    designs : sequence of sequences of (int, str)
        Each design's readings (candidate row, sensor name).

    Returns
    -------
    list of float
        One value per design; ``nan`` where the rival's parameters are not identifiable on the
        design's readings (its information singular: no refit exists).
    """
    d, diff, names = reading_divergences(model_a, p_a, model_b, p_b, candidates, sensors, sigma, "T")
    A_e, b_e = _refit_terms(d, diff, _rival_sensitivities(model_b, p_b, candidates, model_a, names, sigma))
    out = []
    for design in designs:
        bad = [s for _, s in design if s not in names]
        if bad or any(not 0 <= int(i) < d.shape[0] for i, _ in design) or not design:
            raise DiscriminationError(f"designs: readings must name candidate rows 0..{d.shape[0] - 1} and sensors "
                                      f"{', '.join(names)}; got {list(design)[:3]}...")
        v = _refit_one(A_e, b_e, d, [(int(i), names.index(s)) for i, s in design])
        out.append(float("nan") if v is None else v)
    return out


def _designs(n_q, n_S, k, m, n):
    """(reading lists of every admissible design shape, their count): each design a list of (row, col)."""
    if n is not None:
        items = [(i, s) for i in range(n_q) for s in range(n_S)]
        return (([items[e] for e in c] for c in combinations(range(len(items)), n)), math.comb(len(items), n))
    row_sets = combinations(range(n_q), k) if k is not None else [tuple(range(n_q))]
    n_rows = math.comb(n_q, k) if k is not None else 1
    col_sets = list(combinations(range(n_S), m)) if m is not None else [tuple(range(n_S))]
    return (([(i, s) for i in rows for s in cols] for rows in row_sets for cols in col_sets),
            n_rows * len(col_sets))


def _refit_design(d, diff, names, g, k, m, n, limit):
    r"""Exact maximiser of :math:`\Phi_\text{refit}` by enumeration (see the module docstring)."""
    n_q, n_S = d.shape
    designs, count = _designs(n_q, n_S, k, m, n)
    if count > limit:
        raise DiscriminationError(f"enumeration_limit: criterion 'T_refit' enumerates the designs and there are "
                                  f"{count} > {limit}; raise enumeration_limit or use criterion 'T'")
    A_e, b_e = _refit_terms(d, diff, g)
    best, best_value = None, -np.inf
    for design in designs:
        value = _refit_one(A_e, b_e, d, design)
        if value is not None and value > best_value:
            best, best_value = design, value
    if best is None:
        raise DiscriminationError(f"n_points/n_readings: no design identifies the rival's parameters (all {count} "
                                  "designs leave its information singular); choose more readings")
    rows = sorted({i for i, _ in best})
    cols = sorted({s for _, s in best})
    readings = tuple((int(i), names[s]) for i, s in best)
    return _result(_Search.exact(rows, cols, best_value, "enumerate-refit", count), readings, "T_refit", d, diff,
                   names)


def _result(found: _Search, readings, criterion: str, d, diff, names) -> "DiscriminationResult":
    """The user's :class:`DiscriminationResult` of a search (read-only copies of the divergence tables)."""
    d, diff = d.copy(), diff.copy()
    d.setflags(write=False)
    diff.setflags(write=False)
    return DiscriminationResult(indices=tuple(int(i) for i in found.rows),
                                sensors=tuple(names[int(s)] for s in found.cols), readings=tuple(readings),
                                value=float(found.value), upper_bound=float(found.bound),
                                proven_optimal=bool(found.proven), method=found.method, criterion=criterion,
                                divergences=d, difference=diff, candidate_sensors=tuple(names),
                                n_designs=int(found.count))
