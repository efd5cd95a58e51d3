"""Bates-Watts relative curvature measures of nonlinearity of a least-squares fit.

With the weighted, standardised residuals r_i = sqrt(w_k) (z_i - eta_i(p)) / sigma_k, the
velocity matrix V. = d eta / dp (n x n_p) and the acceleration array V.. = d^2 eta / dp^2
(n x n_p x n_p) (both of the standardised outputs eta, exact from CasADi through the implicit
state, :meth:`models.sensitivity.Sensitivities.output_hessians`), Bates & Watts (1980,
"Relative curvature measures of nonlinearity", JRSS B 42, 1-25; book 1988, section 7.2)
define, with the QR decomposition V. = Q1 R1 and L = R1^-1:

    U..      = L^T V.. L                          (acceleration in the coordinates where V. is orthonormal)
    A^T(d)   = rho Q1^T U..(d, d)                  parameter-effects (tangential) part
    A^N(d)   = rho (I - Q1 Q1^T) U..(d, d)         intrinsic (normal) part
    Gamma^T  = max_{|d| = 1} |A^T(d)|,    Gamma^N = max_{|d| = 1} |A^N(d)|

with rho = s sqrt(n_p) (s the residual scale; 1 for standardised residuals with the sigma
used by the estimate).  Gamma^N is invariant under reparametrisation p -> g(p), Gamma^T is not.

The linearised (1 - alpha) region is a disk of relative radius sqrt(F(n_p, n - n_p; alpha)) on
the tangent plane, and 1/Gamma is the relative radius of curvature.  Bates & Watts compare the
curvatures with the critical value 1/sqrt(F): the planar assumption (ellipsoid in the
expectation space) needs Gamma^N below it, the uniform-coordinate assumption (ellipsoid on the
parameters) needs Gamma^T below it.  ``trustworthy`` demands both: the parameter ellipsoid and
the Wald intervals rest on both assumptions.

Maximisation over unit directions: the Bates-Watts (1980, appendix) fixed-point iteration
d <- g / |g| with g = sum_m a_m A_m d, a = A(d, d), started from the coordinate axes, their
pairwise sums and differences, the leading eigenvectors of every face, and (n_p <= 3) a dense
grid on the half circle / half sphere; the largest value over every evaluated direction is kept.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from models.sensitivity import sensitivities

__all__ = ["Curvature", "relative_curvature", "estimate_curvature"]

_ITERATIONS = 200
_TOL = 1e-12


@dataclass(frozen=True)
class Curvature:
    """Maximum relative curvatures of a fit (Bates & Watts 1980), dimensionless.

    Attributes
    ----------
    intrinsic : float            Gamma^N, maximum relative intrinsic curvature
    parameter_effects : float    Gamma^T, maximum relative parameter-effects curvature
    critical : float             1 / sqrt(F(n_p, n - n_p; 1 - alpha))
    alpha : float                level of the critical value
    trustworthy : bool           both curvatures below the critical value: the linearised ellipsoid
                                 and the Wald intervals can be trusted at level alpha
    direction_intrinsic, direction_parameter_effects : ndarray (n_p,)
                                 unit parameter directions (standard-error scale, L d) of the maxima,
                                 expressed in parameter units and normalised to length 1
    n, dof : int                 number of values and n - n_p
    """

    intrinsic: float
    parameter_effects: float
    critical: float
    alpha: float
    trustworthy: bool
    direction_intrinsic: np.ndarray
    direction_parameter_effects: np.ndarray
    n: int
    dof: int

    def __post_init__(self):
        for name in ("direction_intrinsic", "direction_parameter_effects"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def intrinsic_ratio(self) -> float:
        """Gamma^N sqrt(F): above 1 the expectation surface bends visibly within the region."""
        return self.intrinsic / self.critical

    @property
    def parameter_effects_ratio(self) -> float:
        """Gamma^T sqrt(F): above 1 the parameter lines are visibly non-uniform within the region."""
        return self.parameter_effects / self.critical

    def __str__(self):
        verdict = "trustworthy" if self.trustworthy else "NOT trustworthy"
        return (f"relative curvature (Bates-Watts): intrinsic {self.intrinsic:.3g}, parameter-effects "
                f"{self.parameter_effects:.3g}, critical 1/sqrt(F) = {self.critical:.3g} at alpha = "
                f"{self.alpha:g}: linearised ellipsoid {verdict}")


def _max_norm(A: np.ndarray, starts: np.ndarray) -> tuple:
    """max over unit d of |sum_ab A[:, a, b] d_a d_b| and its direction (A: m x p x p)."""
    p = A.shape[1]
    if A.shape[0] == 0 or not np.any(A):
        d = np.zeros(p)
        d[0] = 1.0
        return 0.0, d

    def value(D):
        acc = np.einsum("mab,ka,kb->km", A, D, D)
        return np.linalg.norm(acc, axis=1)

    vals = value(starts)
    order = np.argsort(vals)[::-1][:min(len(vals), 12)]
    best_v, best_d = float(vals[order[0]]), starts[order[0]].copy()
    for i in order:
        d = starts[i].copy()
        v_old = -1.0
        for _ in range(_ITERATIONS):
            a = np.einsum("mab,a,b->m", A, d, d)
            v = float(np.linalg.norm(a))
            if v > best_v:
                best_v, best_d = v, d.copy()
            g = np.einsum("m,mab,b->a", a, A, d)
            ng = np.linalg.norm(g)
            if ng == 0.0 or abs(v - v_old) <= _TOL * max(v, 1.0):
                break
            d, v_old = g / ng, v
    return best_v, best_d


def _start_directions(A_all: np.ndarray, p: int) -> np.ndarray:
    """Coordinate axes, pairwise (d_a +- d_b)/sqrt 2, face eigenvectors, and a dense grid for p <= 3."""
    eye = np.eye(p)
    dirs = [eye[a] for a in range(p)]
    for a in range(p):
        for b in range(a + 1, p):
            dirs += [(eye[a] + eye[b]) / math.sqrt(2), (eye[a] - eye[b]) / math.sqrt(2)]
    faces = A_all.reshape(-1, p, p)
    norms = np.linalg.norm(faces.reshape(len(faces), -1), axis=1)
    for m in np.argsort(norms)[::-1][:min(len(faces), 2 * p + 4)]:
        w, V = np.linalg.eigh(faces[m])
        dirs += [V[:, np.argmax(np.abs(w))]]
    if p == 2:
        t = np.linspace(0.0, np.pi, 361)[:-1]
        dirs += list(np.column_stack([np.cos(t), np.sin(t)]))
    elif p == 3:
        k = np.arange(2000) + 0.5
        z = k / 2000.0                      # half sphere z > 0 (d and -d give the same curvature)
        phi = np.pi * (1 + 5 ** 0.5) * k
        r = np.sqrt(1 - z ** 2)
        dirs += list(np.column_stack([r * np.cos(phi), r * np.sin(phi), z]))
    return np.array(dirs)


def relative_curvature(V1: np.ndarray, V2: np.ndarray, dof: int, scale: float = 1.0,
                       alpha: float = 0.05) -> Curvature:
    """Maximum relative intrinsic and parameter-effects curvature (Bates & Watts 1980).

    Parameters
    ----------
    V1 : ndarray (n, n_p)           velocity d eta / dp of the standardised model outputs
    V2 : ndarray (n, n_p, n_p)      acceleration d^2 eta / dp^2
    dof : int                       n_data - n_p (F degrees of freedom; rows of V1 may be collapsed
                                    repeated values, each scaled by sqrt(count))
    scale : float                   residual scale s of the standardised outputs (1 when eta is
                                    divided by the sigma in use)
    alpha : float                   level of the critical value 1 / sqrt(F(n_p, dof; 1 - alpha))

    Returns
    -------
    Curvature
    """
    if not (0 < alpha < 1):
        raise ValueError(f"alpha must lie in (0, 1), got {alpha}")
    V1 = np.asarray(V1, float)
    V2 = np.asarray(V2, float)
    n, p = V1.shape
    if V2.shape != (n, p, p):
        raise ValueError(f"V2: expected shape {(n, p, p)}, got {V2.shape}")
    if dof < 1:
        raise ValueError(f"dof: need n - n_p >= 1 for the F critical value, got {dof}")
    Q1, R1 = np.linalg.qr(V1)
    rdiag = np.abs(np.diag(R1))
    if rdiag.min() <= 1e-13 * max(rdiag.max(), 1e-300):
        raise np.linalg.LinAlgError("V1 is rank deficient: curvature is undefined (parameters not identifiable)")
    L = np.linalg.inv(R1)
    rho = scale * math.sqrt(p)
    U = np.einsum("ca,ncd,db->nab", L, V2, L)
    AT = rho * np.einsum("nm,nab->mab", Q1, U)
    AN = rho * (U - np.einsum("nm,mab->nab", Q1, AT / rho))
    starts = _start_directions(np.concatenate([AT, AN]), p)
    gT, dT = _max_norm(AT, starts)
    gN, dN = _max_norm(AN, starts)
    crit = 1.0 / math.sqrt(float(stats.f.ppf(1 - alpha, p, dof)))

    def in_params(d):
        v = L @ d
        return v / np.linalg.norm(v)

    return Curvature(intrinsic=float(gN), parameter_effects=float(gT), critical=crit, alpha=alpha,
                     trustworthy=bool(gN < crit and gT < crit), direction_intrinsic=in_params(dN),
                     direction_parameter_effects=in_params(dT), n=dof + p, dof=dof)


def estimate_curvature(est, model, data, alpha: float = 0.05) -> Curvature:
    """Curvature of an :class:`identification.Estimate` from its model and data.

    The standardised outputs are sqrt(w_k) h_jk / sigma_k (sigma as used by the estimate, so
    s = 1), one row per input and selected sensor with its repeated series folded in by
    sqrt(count); the acceleration comes exactly from
    :meth:`models.sensitivity.Sensitivities.output_hessians`.
    """
    sens = sensitivities(model, est.p, data.inputs, est.states)
    Hh = sens.output_hessians()                               # (n_q, n_S, n_p, n_p)
    counts = np.sum(np.isfinite(est.residuals), axis=0)        # (n_q, n_S)
    fac = np.sqrt(counts * est.weights[None, :]) / est.sigma[None, :]
    keep = fac > 0
    V1 = (sens.G * fac[:, :, None])[keep]
    V2 = (Hh * fac[:, :, None, None])[keep]
    return relative_curvature(V1, V2, est.dof, 1.0, alpha)
