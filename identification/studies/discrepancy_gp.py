r"""The output discrepancy of a static model: a Gaussian process per sensor over the model's inputs.

The readings of sensor k at input row j, averaged over the n_jk series that hold them, are

.. math::

    \bar z_{jk} = h_k(q_j, p) + \delta_k(q_j) + \rho_{jk} + \bar\varepsilon_{jk},\qquad
    \bar\varepsilon_{jk} \sim N(0, \sigma_k^2 / n_{jk}),

with the smooth discrepancy delta_k a Gaussian process of squared-exponential covariance
s_k^2 exp(-|x - x'|^2 / (2 l_k^2)) on the inputs scaled to [0, 1] (x = (q - q_min) / (q_max - q_min)
per input column, l_k dimensionless) and a rough part rho_jk ~ N(0, tau_k^2), independent between input
rows (conditions the model's inputs do not tell apart, e.g. loading and unloading at one force).
s_k, tau_k are in the unit of sensor k.  Stacked over the selected sensors, r = zbar - h(p) has the
covariance V(theta) = blockdiag_k(s_k^2 C_k o S + tau_k^2 W_k + D_k), D_k = diag(sigma_k^2 / n_jk).

**Conditions** (``conditions`` of :meth:`Observations.of`, one code per input row; None: one condition):
the smooth discrepancy of each condition g is its own draw of the process, delta_k(q, g), independent
between conditions with common hyperparameters, S_oo' = [g(o) = g(o')] (a condition the model's inputs
do not name: a direction of motion, a day, a phase).  A prediction at a condition the data do not hold
has no cross-covariance with the data (``cross`` with its code): the error of a condition not seen is a
new draw of the process fitted on the conditions seen (its prior s_k^2 c(x, x) + tau_k^2 w(x), mean 0).
With one condition in the data the share of the error common to all conditions is not identifiable, and
this (none of it common) is the cautious choice.

``exact_at`` pins delta and its slope to zero at input value v of a named input (for every value
of the other inputs): the factor of that input column is the squared-exponential process conditioned
on f(v) = 0 and f'(v) = 0,

.. math::

    c(a, b) = e^{-(a - b)^2 / 2} - e^{-(a^2 + b^2) / 2}\,(1 + a b),\qquad a = (x - v) / l,\; b = (x' - v) / l,

and the rough part's variance is multiplied by c(a, a) = 1 - e^{-a^2} (1 + a^2) (zero, with zero slope, at v).

The hyperparameters theta = (log(s_k / sigma_k), log l_k, log(tau_k / sigma_k)) maximise the restricted
(REML) likelihood of the residuals, p being a fixed effect with sensitivities G = dh/dp:

.. math::

    -2\ell_R(\theta) = \log|V| + \log|G^\top V^{-1} G| + r^\top P r + \text{const},\qquad
    P = V^{-1} - V^{-1} G (G^\top V^{-1} G)^{-1} G^\top V^{-1},

with the exact gradient d(-2 l_R)/d theta_i = tr(P V_i) - r^T P V_i P r (V_i = dV / d theta_i, analytic),
by L-BFGS-B from a few starts.  The expected information of the REML likelihood, I_ab = tr(P V_a P V_b) / 2
(:func:`reml_information`), gives the sampling variance of the estimated new-draw variance at a condition not
seen (:meth:`GPFit.prior_variance_spread`, delta method over the hyperparameters not on a bound).  Every factorisation is a Cholesky; one that fails is reported, never
replaced by a pseudo-inverse.  V is block diagonal (by instrument, and within one by condition): it is
factorised block by block (:func:`identification.studies.embedded_error.block_reml`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize, stats

from identification.studies.embedded_error import block_reml, condition_blocks, spd_inverse

__all__ = ["InputScaling", "Observations", "GPFit", "fit_discrepancy", "white_lr_test", "WhiteTest",
           "white_lr_null", "kernel_blocks", "reml_objective", "reml_information", "BOUNDS", "AT_BOUND"]

#: bounds of (log(s / sigma), log l, log(tau / sigma)): s, tau from ~3e-4 sigma (effectively zero) to 150 sigma
BOUNDS = ((-8.0, 5.0), (float(np.log(0.03)), float(np.log(5.0))), (-8.0, 5.0))
#: a log hyperparameter within this of a bound is held fixed there by the variance of the estimates
AT_BOUND = 1e-2
_STARTS = ((0.0, float(np.log(0.3)), -2.0), (-2.0, 0.0, 0.0), (1.0, float(np.log(1.0)), -4.0))


@dataclass(frozen=True)
class InputScaling:
    """x = (q - offset) / scale per input column, then per column coordinate (a dynamic model's time t), each
    dimensionless; a column without range keeps scale 1.

    ``pins`` : tuple of (column, scaled value) where the discrepancy and its slope are zero.
    ``d_q`` : the number of input columns (the first d_q of offset and scale; the rest are the coordinates).
    """

    offset: np.ndarray
    scale: np.ndarray
    pins: tuple = ()
    d_q: int | None = None

    @classmethod
    def of(cls, inputs: np.ndarray, exact_at: dict, names: tuple, coords: np.ndarray | None = None) -> "InputScaling":
        """The scaling of the data's inputs (n_q, d_q) and of the columns' coordinates (n_cols, d_c) (``names``:
        the inputs', then the coordinates') with the pins ``exact_at`` {input or coordinate name: value}."""
        parts = [np.asarray(inputs, float)] + ([] if coords is None else [np.asarray(coords, float)])
        lo = np.concatenate([a.min(axis=0) if a.shape[0] else np.zeros(a.shape[1]) for a in parts])
        hi = np.concatenate([a.max(axis=0) if a.shape[0] else np.zeros(a.shape[1]) for a in parts])
        scale = np.where(hi > lo, hi - lo, 1.0)
        pins = tuple((names.index(n), (float(v) - lo[names.index(n)]) / scale[names.index(n)])
                     for n, v in exact_at.items())
        return cls(lo, scale, pins, None if coords is None else np.asarray(inputs).shape[1])

    def __call__(self, inputs: np.ndarray) -> np.ndarray:
        d = len(self.offset) if self.d_q is None else self.d_q
        return (np.atleast_2d(np.asarray(inputs, float)) - self.offset[:d]) / self.scale[:d]

    def coordinates(self, coords: np.ndarray) -> np.ndarray:
        """The scaled column coordinates (n_cols, d_c)."""
        d = len(self.offset) if self.d_q is None else self.d_q
        return (np.asarray(coords, float) - self.offset[d:]) / self.scale[d:]


@dataclass(frozen=True)
class Observations:
    """The stacked residual means of the selected sensor columns, in blocks: one block (one Gaussian process)
    per instrument, holding its columns (a static model: one column; a dynamic one: one per sampling time).

    Attributes
    ----------
    sensors : tuple of int       the selected columns k
    rows : tuple of ndarray      per block, the input row j of each observation
    noise : tuple of ndarray     per block, sigma_k^2 / n_jk of each observation (unit of z squared)
    sigma : ndarray (n_blocks,)  sigma of every block's instrument
    x : tuple of ndarray         per block, the scaled coordinates (inputs, then column coordinates) of each
                                 observation (n_i, d)
    cols : tuple of ndarray      per block, the column k of each observation
    blocks : tuple of ndarray    per block, its selected columns
    conditions : tuple of ndarray or None   per block, the condition code of each observation (None: one
                                 condition, code 0)
    condition_term : bool        the third hyperparameter is a constant per condition (an offset omega_k of
                                 every condition, V gets omega_k^2 S) instead of the rough part (tau_k^2 W,
                                 independent between rows); no pins (exact_at) with it
    """

    sensors: tuple
    rows: tuple
    noise: tuple
    sigma: np.ndarray
    x: tuple
    cols: tuple
    blocks: tuple
    conditions: tuple | None = None
    condition_term: bool = False

    @classmethod
    def of(cls, counts: np.ndarray, sigma: np.ndarray, w: np.ndarray, x: np.ndarray, instrument=None,
           coords: np.ndarray | None = None, conditions: np.ndarray | None = None,
           condition_term: bool = False) -> "Observations":
        """From the counts (n_q, n_S) of a campaign, sigma (n_S,), the weights (n_S,), the scaled inputs (n_q,
        d_q) and, for columns grouped into instruments, the instrument of every column (n_S,) and the columns'
        scaled coordinates (n_S, d_c) (None: every column its own block, no coordinates); ``conditions`` the
        integer condition code of every input row (n_q,) (None: one condition); ``condition_term`` the third
        hyperparameter an offset per condition, not the rough part (:class:`Observations`)."""
        n_S = counts.shape[1]
        instrument = np.arange(n_S) if instrument is None else np.asarray(instrument)
        coords = np.zeros((n_S, 0)) if coords is None else np.asarray(coords, float)
        sens = tuple(int(k) for k in np.flatnonzero(w > 0))
        blocks = tuple(np.array([k for k in sens if instrument[k] == g], int)
                       for g in dict.fromkeys(int(instrument[k]) for k in sorted(sens, key=lambda k: instrument[k])))
        rows, cols, noise, xs, sig = [], [], [], [], []
        for b in blocks:
            r = [np.flatnonzero(counts[:, k] > 0) for k in b]
            rows.append(np.concatenate(r))
            cols.append(np.concatenate([np.full(len(rk), k) for k, rk in zip(b, r)]).astype(int))
            noise.append(np.concatenate([sigma[k] ** 2 / counts[rk, k] for k, rk in zip(b, r)]))
            xs.append(np.concatenate([np.hstack([x[rk], np.repeat(coords[k][None], len(rk), 0)])
                                      for k, rk in zip(b, r)], axis=0))
            sig.append(float(sigma[b[0]]))
        conds = None if conditions is None else tuple(np.asarray(conditions, int)[r] for r in rows)
        return cls(sens, tuple(rows), tuple(noise), np.array(sig), tuple(xs), tuple(cols), blocks, conds,
                   bool(condition_term))

    def condition_codes(self, i: int) -> np.ndarray:
        """The condition code of every observation of block i (n_i,) (zeros for one condition)."""
        return np.zeros(len(self.rows[i]), int) if self.conditions is None else self.conditions[i]

    def same_condition(self, i: int, codes: np.ndarray | None = None) -> np.ndarray | float:
        """S (n*, n_i) = [code* = code of observation o] of block i against ``codes`` (n*,) (None: the block's own
        observations); 1.0 when the data hold one condition and ``codes`` is None."""
        if self.conditions is None and codes is None:
            return 1.0
        own = self.condition_codes(i)
        other = own if codes is None else np.asarray(codes, int)
        return (other[:, None] == own[None, :]).astype(float)

    @property
    def sizes(self) -> list:
        return [len(r) for r in self.rows]

    def block_of(self, k: int) -> int:
        """The block of selected column k."""
        return next(i for i, b in enumerate(self.blocks) if k in b)

    def stack(self, a: np.ndarray) -> np.ndarray:
        """Values a (n_q, n_S, ...) of the observations, stacked block by block (N, ...)."""
        return np.concatenate([a[r, c] for r, c in zip(self.rows, self.cols)], axis=0)


def _factors(xa: np.ndarray, xb: np.ndarray, ell: float, pins: tuple) -> tuple:
    """(c, dc/dlog l) per input column, each (d, na, nb), of the kernel's product form."""
    d = xa.shape[1]
    cs, dcs = [], []
    pinned = dict(pins)
    for col in range(d):
        A, B = xa[:, col][:, None], xb[:, col][None, :]
        u2 = (A - B) ** 2 / ell ** 2
        e = np.exp(-0.5 * u2)
        if col in pinned:
            a, b = (A - pinned[col]) / ell, (B - pinned[col]) / ell
            g = np.exp(-0.5 * (a ** 2 + b ** 2))
            cs.append(e - g * (1 + a * b))
            dcs.append(e * u2 - g * ((a ** 2 + b ** 2) * (1 + a * b) - 2 * a * b))
        else:
            cs.append(e)
            dcs.append(e * u2)
    return np.array(cs), np.array(dcs)


def kernel_blocks(xa: np.ndarray, xb: np.ndarray, ell: float, pins: tuple = ()) -> tuple:
    """(C, dC/dlog l): the correlation of the smooth part between scaled inputs xa (na, d), xb (nb, d)."""
    cs, dcs = _factors(xa, xb, ell, pins)
    C = np.prod(cs, axis=0)
    dC = np.zeros_like(C)
    for col in range(cs.shape[0]):
        others = np.prod(np.delete(cs, col, axis=0), axis=0) if cs.shape[0] > 1 else 1.0
        dC += dcs[col] * others
    return C, dC


def rough_weight(x: np.ndarray, ell: float, pins: tuple = ()) -> tuple:
    """(W, dW/dlog l) (n,): the rough part's variance factor, prod over pins of 1 - e^{-a^2} (1 + a^2)."""
    W = np.ones(x.shape[0])
    dW = np.zeros(x.shape[0])
    for col, v in pins:
        a2 = ((x[:, col] - v) / ell) ** 2
        f = 1 - np.exp(-a2) * (1 + a2)
        df = -2 * a2 ** 2 * np.exp(-a2)
        dW = dW * f + W * df
        W = W * f
    return W, dW


def _block(obs: Observations, i: int, th: np.ndarray, pins: tuple, sel: np.ndarray | None = None) -> tuple:
    """(V_k, [dV_k/d theta]) of sensor block i with its hyperparameters th (3,); ``sel`` (positions within the
    block, all of one condition): that diagonal sub-block only (None: the whole block)."""
    sig = obs.sigma[i]
    s2, ell, t2 = (sig * np.exp(th[0])) ** 2, float(np.exp(th[1])), (sig * np.exp(th[2])) ** 2
    x = obs.x[i] if sel is None else obs.x[i][sel]
    noise = obs.noise[i] if sel is None else obs.noise[i][sel]
    C, dC = kernel_blocks(x, x, ell, pins)
    S = obs.same_condition(i) if sel is None else 1.0
    C, dC = C * S, dC * S
    if obs.condition_term:                          # an offset per condition: omega^2 [g(o) = g(o')]
        O = np.broadcast_to(S, C.shape)
        return s2 * C + t2 * O + np.diag(noise), (2 * s2 * C, s2 * dC, 2 * t2 * O)
    W, dW = rough_weight(x, ell, pins)
    V = s2 * C + np.diag(t2 * W + noise)
    return V, (2 * s2 * C, s2 * dC + np.diag(t2 * dW), np.diag(2 * t2 * W))


def _sub_blocks(obs: Observations) -> list:
    """Per block i, the positions within the block of each of its conditions (index arrays)."""
    return [condition_blocks(obs.condition_codes(i)) for i in range(len(obs.blocks))]


def _reml_parts(obs: Observations, theta: np.ndarray, G: np.ndarray, pins: tuple):
    """(f, Vinv blocks, A = G^T V^-1 G factor, block derivatives) or None when a Cholesky fails (V_k factorised
    condition by condition, its blocks)."""
    derivs, Vi, logdet = [], [], 0.0
    for i, subs in enumerate(_sub_blocks(obs)):
        V, dV = _block(obs, i, theta[3 * i:3 * i + 3], pins)
        Vinv = np.zeros_like(V)
        for sel in subs:
            try:
                L = linalg.cholesky(V[np.ix_(sel, sel)], lower=True)
            except linalg.LinAlgError:
                return None
            logdet += 2 * np.sum(np.log(np.diag(L)))
            Vinv[np.ix_(sel, sel)] = spd_inverse(L)
        Vi.append(Vinv)
        derivs.append(dV)
    Vinv = linalg.block_diag(*Vi)
    A = G.T @ Vinv @ G
    try:
        LA = linalg.cholesky(A, lower=True)
    except linalg.LinAlgError:
        return None
    return logdet + 2 * np.sum(np.log(np.diag(LA))), Vinv, LA, derivs


def reml_objective(theta, obs: Observations, G: np.ndarray, r: np.ndarray, pins: tuple = ()) -> tuple:
    """(-2 l_R(theta) without constant, its exact gradient) for stacked residuals r (N,), G (N, n_p); V is
    factorised block by block (every instrument, within it every condition: :func:`block_reml`)."""
    theta = np.asarray(theta, float)
    Vs, dVs, index = [], [], []
    start = 0
    for i, subs in enumerate(_sub_blocks(obs)):
        which = np.arange(3 * i, 3 * i + 3)
        for sel in subs:
            V, dV = _block(obs, i, theta[3 * i:3 * i + 3], pins, sel)
            Vs.append(V)
            dVs.append((which, np.array(dV)))
            index.append(start + sel)
        start += obs.sizes[i]
    return block_reml(Vs, dVs, index, G, r, len(theta))


def reml_information(theta, obs: Observations, G: np.ndarray, pins: tuple = ()) -> np.ndarray:
    """The expected information of the REML likelihood about theta (3 n_sel, 3 n_sel), I_ab = tr(P V_a P V_b) / 2
    (V_a = dV / d theta_a, analytic; P the REML projection of :func:`reml_objective`).  Raises
    numpy.linalg.LinAlgError when V or G^T V^-1 G is not positive definite."""
    theta = np.asarray(theta, float)
    parts = _reml_parts(obs, theta, G, pins)
    if parts is None:
        raise np.linalg.LinAlgError("the discrepancy's covariance V or G^T V^-1 G is not positive definite")
    _, Vinv, LA, derivs = parts
    VG = Vinv @ G
    P = Vinv - VG @ linalg.cho_solve((LA, True), VG.T)
    full = []                                   # P V_a, each (N, N), V_a embedded in its block
    start = 0
    for i, n in enumerate(obs.sizes):
        for dV in derivs[i]:
            full.append(P[:, start:start + n] @ dV)
        start += n
    n_t = len(full)
    info = np.empty((n_t, n_t))
    starts = np.repeat(np.cumsum([0] + obs.sizes[:-1]), 3)
    sizes = np.repeat(obs.sizes, 3)
    for a in range(n_t):
        for b in range(a, n_t):
            # tr(P V_a P V_b) = sum over the rows of block b and of block a of (P V_a)(P V_b)
            Ma = full[a][starts[b]:starts[b] + sizes[b], :]          # (n_b, n_a): rows of block b of P V_a
            Mb = full[b][starts[a]:starts[a] + sizes[a], :]          # (n_a, n_b)
            info[a, b] = info[b, a] = 0.5 * float(np.sum(Ma * Mb.T))
    return info


@dataclass(frozen=True)
class GPFit:
    """The discrepancy's hyperparameters and the factors its predictions need.

    Attributes
    ----------
    theta : ndarray (3 n_sel,)   (log(s_k / sigma_k), log l_k, log(tau_k / sigma_k)) per selected sensor
    obs : Observations
    pins : tuple                 (column, scaled value) of exact_at
    reml : float                 -2 l_R at theta (without constant)
    converged : bool             the optimiser reported success from the best start
    information : ndarray (3 n_sel, 3 n_sel) or None   the REML expected information about theta
                                 (:func:`reml_information`; None: not computed)
    """

    theta: np.ndarray
    obs: Observations
    pins: tuple
    reml: float
    converged: bool
    information: np.ndarray | None = None

    def amplitude(self, i: int) -> float:
        """s_k of selected sensor i (unit of z)."""
        return float(self.obs.sigma[i] * np.exp(self.theta[3 * i]))

    def length_scale(self, i: int) -> float:
        """l_k of selected sensor i (scaled inputs, dimensionless)."""
        return float(np.exp(self.theta[3 * i + 1]))

    def rough(self, i: int) -> float:
        """tau_k of selected sensor i (unit of z)."""
        return float(self.obs.sigma[i] * np.exp(self.theta[3 * i + 2]))

    def covariance(self) -> np.ndarray:
        """V (N, N): the stacked residual covariance (block diagonal over sensors)."""
        return linalg.block_diag(*[_block(self.obs, i, self.theta[3 * i:3 * i + 3], self.pins)[0]
                                   for i in range(len(self.obs.blocks))])

    def cross(self, i: int, xs: np.ndarray, conditions: np.ndarray | None = None) -> tuple:
        """(k (n*, N): cov(delta(x*), stacked residuals), prior variance (n*,)) for block i at scaled x* (inputs,
        then column coordinates) in the conditions ``conditions`` (n*,) codes (None: code 0, the one condition
        of data without conditions; a code the data do not hold: a condition not seen, k = 0)."""
        ell = self.length_scale(i)
        s2, t2 = self.amplitude(i) ** 2, self.rough(i) ** 2
        k = np.zeros((xs.shape[0], sum(self.obs.sizes)))
        start = sum(self.obs.sizes[:i])
        C, _ = kernel_blocks(xs, self.obs.x[i], ell, self.pins)
        codes = None if conditions is None and self.obs.conditions is None else (
            np.zeros(xs.shape[0], int) if conditions is None else conditions)
        S = self.obs.same_condition(i, codes)
        k[:, start:start + self.obs.sizes[i]] = s2 * C * S + (t2 * S if self.obs.condition_term else 0.0)
        prior = s2 * np.diag(kernel_blocks(xs, xs, ell, self.pins)[0]) + t2 * rough_weight(xs, ell, self.pins)[0]
        return k, prior

    def prior_variance_spread(self, i: int, xs: np.ndarray) -> np.ndarray:
        r"""var(A^(x*)) (n*,): the sampling variance of the estimated new-draw variance A(x) = s_k^2 c(x, x) +
        tau_k^2 w(x) of block i at scaled x* (unit of z to the fourth), by the delta method,
        grad_theta A^T I_ff^{-1} grad_theta A over the free hyperparameters f of all blocks (those not within
        :data:`AT_BOUND` of a bound, where the estimate sits on the bound and is held there; ``information`` the
        REML expected information).  Raises numpy.linalg.LinAlgError when I_ff is not positive definite."""
        if self.information is None:
            raise ValueError("information: this GPFit was built without the REML information")
        lo = np.tile([b[0] for b in BOUNDS], len(self.obs.blocks))
        hi = np.tile([b[1] for b in BOUNDS], len(self.obs.blocks))
        free = np.flatnonzero((self.theta > lo + AT_BOUND) & (self.theta < hi - AT_BOUND))
        ell, s2, t2 = self.length_scale(i), self.amplitude(i) ** 2, self.rough(i) ** 2
        C, dC = kernel_blocks(xs, xs, ell, self.pins)
        W, dW = rough_weight(xs, ell, self.pins)
        grad = np.zeros((xs.shape[0], len(self.theta)))
        grad[:, 3 * i:3 * i + 3] = np.stack([2 * s2 * np.diag(C), s2 * np.diag(dC) + t2 * dW, 2 * t2 * W], axis=1)
        g = grad[:, free]
        if not free.size:
            return np.zeros(xs.shape[0])
        L = linalg.cholesky(self.information[np.ix_(free, free)], lower=True)
        u = linalg.solve_triangular(L, g.T, lower=True)
        return np.sum(u * u, axis=0)


def fit_discrepancy(obs: Observations, G: np.ndarray, r: np.ndarray, pins: tuple = (), starts=None) -> GPFit:
    """theta maximising the REML likelihood of the stacked residuals r (N,) with sensitivities G (N, n_p).

    L-BFGS-B with the exact gradient (:func:`reml_objective`) from each start (``starts``: arrays (3 n_sel,);
    None: each of ``_STARTS`` for every sensor); the best finite optimum is kept.  Raises numpy.linalg.LinAlgError when no start gives a positive definite V
    and G^T V^{-1} G.
    """
    n_sel = len(obs.blocks)
    best = None
    for x0 in (np.tile(st, n_sel) for st in _STARTS) if starts is None else starts:
        if not np.isfinite(reml_objective(x0, obs, G, r, pins)[0]):
            continue
        res = optimize.minimize(reml_objective, x0, args=(obs, G, r, pins), jac=True, method="L-BFGS-B",
                                bounds=list(BOUNDS) * n_sel, options={"maxiter": 300})
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res
    if best is None:
        raise np.linalg.LinAlgError("the discrepancy's covariance V or G^T V^-1 G is not positive definite at "
                                    "any start (Cholesky failed)")
    theta = np.asarray(best.x, float)
    return GPFit(theta, obs, pins, float(best.fun), bool(best.success), reml_information(theta, obs, G, pins))


@dataclass(frozen=True)
class WhiteTest:
    r"""The likelihood-ratio test of 'no model error' against one variance component.

    H0: lambda = 0 against lambda > 0 in V(lambda) = D + lambda diag(sigma_k^2) (a discrepancy of every
    input row and sensor, independent, of variance lambda sigma_k^2); statistic
    LR = -2 l_R(0) + 2 max_{lambda >= 0} l_R(lambda) (REML, chi^2 units), reference distribution the
    boundary-corrected 50:50 mixture of chi2_0 and chi2_1: p = 0.5 P(chi2_1 > LR) for LR > 0, else 1.
    """

    statistic: float
    p_value: float
    lam: float
    dof: int


def _white_f(lam: float, obs: Observations, G: np.ndarray, r: np.ndarray) -> float:
    d = np.concatenate([n + lam * s ** 2 for n, s in zip(obs.noise, obs.sigma)])
    VG = G / d[:, None]
    A = G.T @ VG
    try:
        LA = linalg.cholesky(A, lower=True)
    except linalg.LinAlgError:
        return np.inf
    b = VG.T @ r
    quad = float(r @ (r / d)) - float(b @ linalg.cho_solve((LA, True), b))
    return float(np.sum(np.log(d)) + 2 * np.sum(np.log(np.diag(LA))) + quad)


def white_lr_test(obs: Observations, G: np.ndarray, r: np.ndarray) -> WhiteTest:
    """The test of :class:`WhiteTest` on stacked residuals r (N,) at the plain fit, G (N, n_p)."""
    f0 = _white_f(0.0, obs, G, r)
    if not np.isfinite(f0):
        raise np.linalg.LinAlgError("G^T D^-1 G is not positive definite (Cholesky failed)")
    res = optimize.minimize_scalar(lambda u: _white_f(float(np.exp(u)), obs, G, r), bounds=(-18.0, 10.0),
                                   method="bounded", options={"xatol": 1e-6})
    lr = max(f0 - float(res.fun), 0.0)
    lam = float(np.exp(res.x)) if lr > 0 else 0.0
    p = 0.5 * float(stats.chi2.sf(lr, 1)) if lr > 0 else 1.0
    return WhiteTest(lr, p, lam, int(len(r) - G.shape[1]))


def white_lr_null(obs: Observations, G: np.ndarray, n_draws: int, seed: int = 0) -> np.ndarray:
    r"""Draws (n_draws,) of the exact null distribution of the statistic of :func:`white_lr_test` for the layout
    ``obs`` and the sensitivities G (N, n_p) (the model linear in p near its estimate; chi^2 units).

    Whitened by D^{-1/2}, V(lambda) = I + lambda M with M = diag(sigma_k^2 / noise) (the series counts n_jk); the
    REML likelihood is that of the error contrasts K^T y (K an orthonormal basis of the complement of D^{-1/2} G),
    N(0, I + lambda K^T M K).  With mu_s the eigenvalues of K^T M K and w_s iid N(0, 1) under H0
    (Crainiceanu and Ruppert 2004, one variance component, known noise scale),

    .. math::

        LR = \sup_{\lambda \ge 0} \sum_s \Big[ w_s^2 \frac{\lambda \mu_s}{1 + \lambda \mu_s}
        - \log(1 + \lambda \mu_s) \Big];

    with equal mu (every mean of n series) LR = nu (x - 1 - log x) for x = chi2_nu / nu > 1, else 0.  The supremum
    over a log grid of lambda, refined by golden-section search in its bracket.
    """
    noise = np.concatenate(obs.noise)
    m = np.concatenate([np.full(len(nz), s ** 2) for nz, s in zip(obs.noise, obs.sigma)]) / noise
    X = G / np.sqrt(noise)[:, None]
    Q, _ = linalg.qr(X, mode="full")
    K = Q[:, X.shape[1]:]
    mu = np.clip(linalg.eigvalsh(K.T @ (K * m[:, None])), 0.0, None)
    w2 = np.random.default_rng(seed).standard_normal((n_draws, len(mu))) ** 2

    def f(lam):                                    # lam (n_draws,) -> the log-likelihood ratio at lam
        t = lam[:, None] * mu[None]
        return np.sum(w2 * t / (1 + t) - np.log1p(t), axis=1)
    grid = np.exp(np.linspace(np.log(1e-6 / mu.max()), np.log(1e6 / max(mu.min(), 1e-12 * mu.max())), 241))
    vals = np.stack([f(np.full(n_draws, g)) for g in grid], axis=1)
    best = np.argmax(vals, axis=1)
    lo = np.log(grid[np.clip(best - 1, 0, len(grid) - 1)])
    hi = np.log(grid[np.clip(best + 1, 0, len(grid) - 1)])
    r = (np.sqrt(5) - 1) / 2
    for _ in range(60):                            # golden section on log lambda within the bracket
        a, b = hi - r * (hi - lo), lo + r * (hi - lo)
        left = f(np.exp(a)) > f(np.exp(b))
        hi, lo = np.where(left, b, hi), np.where(left, lo, a)
    return np.maximum(np.maximum(vals.max(axis=1), f(np.exp((lo + hi) / 2))), 0.0)
