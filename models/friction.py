r"""Candidate friction models M1, M2, M3 of the press ram guide (paper, section "Friction model").

Each model enters the press state equation through the vertical force at the ram
bearing R (see :func:`models.press.press_model`),

.. math::

    \nabla_y U(y; k_5, k_7) - e_{R_y}\,(q_P - q_\mathrm{fric}(\bar q)) = 0 \qquad [\mathrm{N}],

with q_fric (N) a function of the input vector only:

* M1: q_fric = 0 (``friction=None``);
* M2 (paper eq. 14): q_fric = q_c sign(dq_P/dt), discontinuous only in the inputs: the
  extra input column ``dir`` in {+1 loading, -1 unloading, 0 at rest} comes from the
  set-point sequence (:func:`direction_inputs`); q_c (N) is fixed by :func:`fit_coulomb`;
* M3: the paper's continuous rate-independent memory model
  q_fric = mu(q_P(t_i), q_P(t_{i-1}), q_P,min(t_i), q_P,max(t_i)) (inputs from
  :func:`memory_inputs`), mu an adapted Preisach network of arctan units
  mu(u) = F_s (c_0 + sum_k c_k arctan(w_k . u / Q_s + b_k)) (:class:`PreisachNetwork`),
  trained by Ipopt on the friction force that the inverse frictionless model
  (:func:`inverse_forces`) attributes to four training series.

The trained constants (q_c, the network, and the frictionless (k5, k7) they rest on) are
stored in ``data/press_friction.json`` (:func:`load_friction` reads it); they are fixed
constants of M2/M3, not identified parameters.  Training them is an identification task
and lives in the press study (:func:`mudoe.press.retrain` rewrites the file).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np

__all__ = ["Coulomb", "PreisachNetwork", "direction_inputs", "memory_inputs", "model_inputs",
           "inverse_forces", "fit_coulomb", "load_friction", "candidate_models", "FRICTION_JSON", "FrictionError",
           "VARIANTS", "Q_SCALE", "F_SCALE"]

FRICTION_JSON = Path(__file__).resolve().parent.parent / "data" / "press_friction.json"

#: the candidate press models: M1 without friction, M2 Coulomb, M3 the Preisach network
VARIANTS = ("M1", "M2", "M3")

#: force scale Q_s (N) of the network inputs and output scale F_s (N)
Q_SCALE = 1600.0
F_SCALE = 100.0


class FrictionError(ValueError):
    """Bad argument of a friction function (the message names it)."""


def _sequence(q_sequence, name="q_sequence") -> np.ndarray:
    q = np.asarray(q_sequence, dtype=float)
    if q.ndim == 2 and q.shape[1] >= 1:
        q = q[:, 0]
    if q.ndim != 1 or q.size == 0 or not np.all(np.isfinite(q)):
        raise FrictionError(f"{name}: expected a non-empty 1-D sequence of finite forces (N), got shape {q.shape}")
    return q


# ---------------------------------------------------------------------------- inputs
def direction_inputs(q_sequence) -> np.ndarray:
    r"""Loading direction d_i = sign(q_P(t_i) - q_P(t_{i-1})) (-), d_1 = 0 (at rest).

    Parameters
    ----------
    q_sequence : array_like (n,)
        Process forces (N) in the order they are applied (the set points).

    Returns
    -------
    ndarray (n,) with values in {-1, 0, +1}.
    """
    q = _sequence(q_sequence)
    d = np.zeros(q.size)
    d[1:] = np.sign(np.diff(q))
    return d


def memory_inputs(q_sequence) -> np.ndarray:
    r"""The paper's memory inputs u_i = (q_P(t_i), q_P(t_{i-1}), q_P,min(t_i), q_P,max(t_i)) (N).

    .. math::

        q_\mathrm{min}(t_i) = \begin{cases} \min(q(t_i), q_\mathrm{min}(t_{i-1})) & \dot q(t_i) \ge 0\\
                                             q(t_i) & \dot q(t_i) < 0\end{cases},\qquad
        q_\mathrm{max}(t_i) = \begin{cases} q(t_i) & \dot q(t_i) \ge 0\\
                                             \max(q(t_i), q_\mathrm{max}(t_{i-1})) & \dot q(t_i) < 0\end{cases}

    with the sign of dq/dt(t_i) taken as sign(q(t_i) - q(t_{i-1})) and q(t_0) := q(t_1),
    q_min(t_0) = q_max(t_0) := q(t_1).  The paper prints min(q(t_i), q_max(t_{i-1})) in the
    unloading branch of q_max; that is a typo: with q decreasing it would always return
    q(t_i), so q_max = q_min = q_P on unloading and the model would forget the turning
    point.  We keep the branch maximum (max), symmetric to the q_min recursion, so that
    q_min is the last lower turning point while loading and q_max the last upper turning
    point while unloading.

    Parameters
    ----------
    q_sequence : array_like (n,)
        Process forces (N) in the order they are applied.

    Returns
    -------
    ndarray (n, 4): columns q_P, q_prev, q_min, q_max (N).
    """
    q = _sequence(q_sequence)
    out = np.empty((q.size, 4))
    q_prev, q_min, q_max = q[0], q[0], q[0]
    for i, qi in enumerate(q):
        if qi - q_prev >= 0:
            q_min = min(qi, q_min)
            q_max = qi
        else:
            q_min = qi
            q_max = max(qi, q_max)
        out[i] = (qi, q_prev, q_min, q_max)
        q_prev = qi
    return out


def model_inputs(name: str, q_sequence) -> np.ndarray:
    """Input matrix of candidate model ``name`` ("M1", "M2", "M3") for a force sequence (N).

    M1: (q_P,); M2: (q_P, dir); M3: (q_P, q_prev, q_min, q_max).  Shape (n, d_q).
    """
    q = _sequence(q_sequence)
    if name == "M1":
        return q[:, None].copy()
    if name == "M2":
        return np.column_stack([q, direction_inputs(q)])
    if name == "M3":
        return memory_inputs(q)
    raise FrictionError(f"name: expected 'M1', 'M2' or 'M3', got {name!r}")


# ---------------------------------------------------------------------------- models
class Coulomb:
    r"""M2: q_fric = q_c dir (N), dir = sign(dq_P/dt) an input column.

    Parameters
    ----------
    q_c : float
        Coulomb friction force (N), >= 0.
    """

    input_names = ("dir",)
    input_units = ("",)                  # a sign, dimensionless

    def __init__(self, q_c: float):
        q_c = float(q_c)
        if not (np.isfinite(q_c) and q_c >= 0):
            raise FrictionError(f"q_c: must be a non-negative finite force (N), got {q_c!r}")
        self.q_c = q_c

    def force(self, qvec):
        """q_c * qvec[1] (N) with qvec = [q_P, dir]."""
        return self.q_c * qvec[1]

    def __call__(self, inputs) -> np.ndarray:
        """Numeric friction force (N) for an input matrix (n, 2)."""
        return self.q_c * np.asarray(inputs, float)[:, 1]

    def __repr__(self):
        return f"Coulomb(q_c={self.q_c:.6g} N)"


@dataclass(frozen=True)
class PreisachNetwork:
    r"""M3's adapted Preisach model: a sum of arctan units of the memory inputs.

    .. math::

        \mu(\bar u) = F_s \Bigl(c_0 + \sum_{k=1}^{n_h} c_k \arctan(w_k^\top \bar u / Q_s + b_k)\Bigr)
        \qquad [\mathrm{N}],

    with \bar u = (q_P, q_prev, q_min, q_max) in N, Q_s = 1600 N, F_s = 100 N.

    Attributes
    ----------
    W : ndarray (n_h, 4) ; b : ndarray (n_h,) ; c : ndarray (n_h,) ; c0 : float
    """

    W: np.ndarray
    b: np.ndarray
    c: np.ndarray
    c0: float
    input_names = ("q_prev", "q_min", "q_max")
    input_units = ("N", "N", "N")        # forces, like q_P

    def __post_init__(self):
        W = np.array(self.W, float, ndmin=2)
        b, c = np.array(self.b, float).ravel(), np.array(self.c, float).ravel()
        if W.ndim != 2 or W.shape[1] != 4 or b.shape != (W.shape[0],) or c.shape != (W.shape[0],):
            raise FrictionError(f"W, b, c: expected shapes (n_h, 4), (n_h,), (n_h,), got {W.shape}, {b.shape}, "
                                f"{c.shape}")
        if not (np.isfinite(W).all() and np.isfinite(b).all() and np.isfinite(c).all() and np.isfinite(self.c0)):
            raise FrictionError("W, b, c, c0: network weights must be finite")
        for name, v in (("W", W), ("b", b), ("c", c)):
            v.setflags(write=False)
            object.__setattr__(self, name, v)
        object.__setattr__(self, "c0", float(self.c0))

    @property
    def n_hidden(self) -> int:
        return self.W.shape[0]

    def force(self, qvec):
        """mu(qvec[0:4]) as a CasADi expression (N)."""
        u = ca.vertcat(*[qvec[i] for i in range(4)]) / Q_SCALE
        return F_SCALE * (self.c0 + ca.dot(ca.DM(self.c), ca.atan(ca.mtimes(ca.DM(self.W), u) + ca.DM(self.b))))

    def __call__(self, inputs) -> np.ndarray:
        """Numeric mu (N) for an input matrix (n, 4) of memory inputs (N)."""
        U = np.asarray(inputs, float)
        if U.ndim != 2 or U.shape[1] != 4:
            raise FrictionError(f"inputs: expected shape (n, 4) (q_P, q_prev, q_min, q_max), got {U.shape}")
        return F_SCALE * (self.c0 + np.arctan(U / Q_SCALE @ self.W.T + self.b) @ self.c)

    def to_dict(self) -> dict:
        return dict(W=self.W.tolist(), b=self.b.tolist(), c=self.c.tolist(), c0=self.c0,
                    input_scale_N=Q_SCALE, output_scale_N=F_SCALE)

    @classmethod
    def from_dict(cls, d) -> "PreisachNetwork":
        if d.get("input_scale_N", Q_SCALE) != Q_SCALE or d.get("output_scale_N", F_SCALE) != F_SCALE:
            raise FrictionError("network: stored scales differ from this code's Q_SCALE/F_SCALE")
        return cls(np.array(d["W"]), np.array(d["b"]), np.array(d["c"]), float(d["c0"]))


# ---------------------------------------------------------------------------- inverse model
def _inverse_functions(model):
    """CasADi Function (y, p, q) -> (E, E_y, E_q, h, h_y) of a single-input model (inverse_forces keeps it in model.cache)."""
    y = ca.SX.sym("y", model.n_y)
    p = ca.SX.sym("p", model.n_p)
    q = ca.SX.sym("q", model.n_q_dim)
    E, h = model.E_fun(y, p, q), model.h_fun(y, p, q)
    return ca.Function("inv", [y, p, q], [E, ca.jacobian(E, y), ca.jacobian(E, q)[:, 0], h, ca.jacobian(h, y)])


def _state_newton(fun, p, q, y):
    """The state y with E(y, p, q) = 0 by Newton's method from y (at most 50 steps)."""
    for _ in range(50):
        E, Ey, _, _, _ = fun(y, p, [q])
        dy = np.linalg.solve(np.asarray(Ey), -np.asarray(E).ravel())
        y = y + dy
        if np.max(np.abs(dy)) <= 1e-13 * max(1.0, np.max(np.abs(y))):
            break
    return y


def _inverse_point(fun, p, z_sel, idx, w, q, y, tol, max_iter):
    r"""Gauss-Newton on the scalar force q (N) for one reading vector z_sel (mm) of the sensors ``idx``.

    q <- q + sum_k w_k s_k r_k / sum_k w_k s_k^2 with r = z - h(y(q)), s = dh/dq = h_y dy/dq,
    dy/dq = -E_y^{-1} E_q (exact AD derivatives); y is warm started.  Returns (q, y, converged).
    """
    for _ in range(max_iter):
        y = _state_newton(fun, p, q, y)
        E, Ey, Eq, h, hy = fun(y, p, [q])
        dydq = np.linalg.solve(np.asarray(Ey), -np.asarray(Eq).ravel())
        s = (np.asarray(hy) @ dydq)[idx]
        r = z_sel - np.asarray(h).ravel()[idx]
        dq = float(np.sum(w * s * r) / np.sum(w * s * s))
        q += dq
        if abs(dq) <= tol * max(1.0, abs(q)):
            return q, y, True
    return q, y, False


def inverse_forces(model, p, z, sensors: Sequence[str], sigma, q_start, tol: float = 1e-9,
                   max_iter: int = 30) -> np.ndarray:
    r"""Inverse frictionless model: the force q (N) whose M1 outputs best match readings z.

    .. math::

        \hat q_{ij} = \arg\min_q \sum_{k \in \text{sensors}} \bigl((z_{ijk} - h_k(y(q), p)) / \sigma_k\bigr)^2,
        \qquad E(y(q), p, q) = 0,

    solved by Gauss-Newton on the scalar q with the exact sensitivity
    dh/dq = -h_y E_y^{-1} E_q (Newton on y inside, warm started).

    Parameters
    ----------
    model : models.Model
        The frictionless press model (single input q_P).
    p : array_like (2,)
        (k5, k7) in N/mm.
    z : array_like (n_M, n_q, n_S_model)
        Readings (mm) in the model's sensor order.
    sensors : sequence of str
        Sensors used for the fit.
    sigma : array_like (len(sensors),)
        Their standard deviations (mm).
    q_start : array_like (n_q,)
        Start forces (N), e.g. the set points.

    Returns
    -------
    ndarray (n_M, n_q) of forces (N).
    """
    if model.n_q_dim != 1:
        raise FrictionError(f"model: the inverse model needs the frictionless press (one input), got {model.inputs}")
    z = np.asarray(z, float)
    if z.ndim != 3 or z.shape[2] != model.n_S:
        raise FrictionError(f"z: expected shape (n_M, n_q, {model.n_S}), got {z.shape}")
    idx = model.sensor_index(sensors)
    w = 1.0 / np.asarray(sigma, float) ** 2
    if w.shape != (len(idx),) or not np.all(np.isfinite(w)):
        raise FrictionError(f"sigma: expected {len(idx)} positive values, got {sigma!r}")
    q0 = np.asarray(q_start, float).ravel()
    if q0.shape != (z.shape[1],):
        raise FrictionError(f"q_start: expected {z.shape[1]} forces, got {q0.size}")
    p = np.asarray(p, float)
    fun = model.cache.get_or_make("friction.inverse", None, lambda: _inverse_functions(model))
    out = np.empty(z.shape[:2])
    for i in range(z.shape[0]):
        y = np.zeros(model.n_y)
        for j in range(z.shape[1]):
            q, y, converged = _inverse_point(fun, p, z[i, j, idx], idx, w, q0[j], y, tol, max_iter)
            if not converged:
                raise FrictionError(f"inverse model did not converge at series {i}, input {j}")
            out[i, j] = q
    return out


# ---------------------------------------------------------------------------- Coulomb force of samples
def fit_coulomb(q_set, f) -> float:
    r"""Least-squares Coulomb force q_c = sum_ij d_j f_ij / sum_ij d_j^2 (N).

    The 1-D least-squares fit of f_ij ~ q_c d_j to the inverse-model friction forces f (N)
    with the directions d_j = :func:`direction_inputs` (q_set): half the mean gap between
    the loading and unloading friction forces when both branches have equally many points.
    Clipped at 0 (a Coulomb force cannot be negative).
    """
    d = direction_inputs(q_set)
    f = np.atleast_2d(np.asarray(f, float))
    if f.shape[1] != d.size:
        raise FrictionError(f"f: expected (n_series, {d.size}) forces, got {f.shape}")
    den = f.shape[0] * np.sum(d ** 2)
    if den == 0:
        raise FrictionError("q_set: constant force sequence, no loading direction to fit q_c")
    return max(0.0, float(np.sum(f * d[None, :]) / den))


# ---------------------------------------------------------------------------- storage
def load_friction(path=FRICTION_JSON) -> dict:
    """The stored friction constants: dict with ``coulomb`` (:class:`Coulomb`), ``network``
    (:class:`PreisachNetwork`) and ``raw`` (the JSON content)."""
    path = Path(path)
    if not path.is_file():
        raise FrictionError(f"path: {path} does not exist; run mudoe.press.retrain()")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise FrictionError(f"{path}:{exc.lineno}: not valid JSON ({exc.msg}, column {exc.colno}); give the file "
                            "written by mudoe.press.retrain()") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FrictionError(f"{path}: cannot read ({exc})") from None
    try:
        return dict(coulomb=Coulomb(raw["q_c_N"]), network=PreisachNetwork.from_dict(raw["network"]), raw=raw)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        what = f"missing key {exc}" if isinstance(exc, KeyError) else str(exc)
        raise FrictionError(f"{path}: not a friction constants file ({what}); give the file written by "
                            "mudoe.press.retrain()") from None


def candidate_models(path=FRICTION_JSON) -> dict:
    """The three candidate press models {"M1": Model, "M2": Model, "M3": Model} (stored constants)."""
    from .press import press_model
    fr = load_friction(path)
    return {"M1": press_model(), "M2": press_model(friction=fr["coulomb"]),
            "M3": press_model(friction=fr["network"])}
