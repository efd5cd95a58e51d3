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
  trained by Ipopt on the friction force that the inverse frictionless model attributes
  to four training series (:func:`friction_samples`, :func:`train_preisach`).

The trained constants (q_c, the network, and the frictionless (k5, k7) they rest on) are
stored in ``data/press_friction.json`` (:func:`retrain` rewrites it, :func:`load_friction`
reads it); they are fixed constants of M2/M3, not identified parameters.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np
from .fileio import atomic_write_text

__all__ = ["Coulomb", "PreisachNetwork", "direction_inputs", "memory_inputs", "model_inputs",
           "inverse_forces", "friction_samples", "fit_coulomb", "train_preisach", "retrain",
           "load_friction", "candidate_models", "fit_candidates", "FRICTION_JSON", "FrictionError",
           "TRAINING_DEFAULTS"]

FRICTION_JSON = Path(__file__).resolve().parent.parent / "data" / "press_friction.json"

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
    f = getattr(model, "_inverse_funs", None)
    if f is None:
        y = ca.SX.sym("y", model.n_y)
        p = ca.SX.sym("p", model.n_p)
        q = ca.SX.sym("q", model.n_q_dim)
        E, h = model.E_fun(y, p, q), model.h_fun(y, p, q)
        f = ca.Function("inv", [y, p, q], [E, ca.jacobian(E, y), ca.jacobian(E, q)[:, 0], h, ca.jacobian(h, y)])
        model._inverse_funs = f
    return f


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
    fun = _inverse_functions(model)
    out = np.empty(z.shape[:2])
    for i in range(z.shape[0]):
        y = np.zeros(model.n_y)
        for j in range(z.shape[1]):
            q = q0[j]
            for _ in range(max_iter):
                for _ in range(50):                               # state Newton at fixed q
                    E, Ey, Eq, h, hy = fun(y, p, [q])
                    dy = np.linalg.solve(np.asarray(Ey), -np.asarray(E).ravel())
                    y = y + dy
                    if np.max(np.abs(dy)) <= 1e-13 * max(1.0, np.max(np.abs(y))):
                        break
                E, Ey, Eq, h, hy = fun(y, p, [q])
                dydq = np.linalg.solve(np.asarray(Ey), -np.asarray(Eq).ravel())
                s = (np.asarray(hy) @ dydq)[idx]
                r = z[i, j, idx] - np.asarray(h).ravel()[idx]
                dq = float(np.sum(w * s * r) / np.sum(w * s * s))
                q += dq
                if abs(dq) <= tol * max(1.0, abs(q)):
                    break
            else:
                raise FrictionError(f"inverse model did not converge at series {i}, input {j}")
            out[i, j] = q
    return out


def friction_samples(campaign=None, series: Sequence[int] | None = None, sensors: Sequence[str] = ("D_y", "F_x"),
                     model=None) -> dict:
    r"""Friction forces attributed to training series by the inverse frictionless model.

    .. math::

        f_{ij} = q^d_j - \hat q_{ij}   \qquad [\mathrm{N}],

    where (k5, k7) are first identified with M1 (no friction) on the training series
    (sensors ``sensors``, the paper's composed sigmas of the campaign), and \hat q_ij is
    :func:`inverse_forces` of series i at set point j.

    Parameters
    ----------
    campaign : models.prototype.Campaign, optional
        Default: the shipped campaign (``data/press_campaign``).
    series : sequence of int, optional
        0-based training series (default ``models.prototype.TRAIN_SERIES``, the first four).
    sensors : sequence of str
        Sensors for the M1 fit and the inverse model.
    model : models.Model, optional
        The frictionless press model (built if not given).

    Returns
    -------
    dict with ``q_set`` (n_q,), ``f`` (n_train, n_q) N, ``q_inv`` (n_train, n_q) N,
    ``p_M1`` (2,) N/mm, ``estimate`` (the M1 Estimate), ``sigma`` (sensors,) mm,
    ``series``, ``sensors``.
    """
    from identification import identify
    from .press import K_NOMINAL, press_model
    from .prototype import TRAIN_SERIES, read_campaign
    campaign = read_campaign() if campaign is None else campaign
    series = tuple(TRAIN_SERIES if series is None else series)
    model = press_model() if model is None else model
    data = campaign.measurements(series=series)
    est = identify(model, data, K_NOMINAL, weights=[1.0 if s in sensors else 0.0 for s in model.sensors])
    sig = np.asarray(data.sigma)[model.sensor_index(sensors)]
    q_inv = inverse_forces(model, est.p, data.z, sensors, sig, campaign.q_set)
    return dict(q_set=campaign.q_set.copy(), f=campaign.q_set[None, :] - q_inv, q_inv=q_inv, p_M1=est.p.copy(),
                estimate=est, sigma=sig, series=series, sensors=tuple(sensors))


# ---------------------------------------------------------------------------- training
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


def train_preisach(U, f, n_hidden: int = 4, reg: float = 1e-2, sigma_f: float = 20.0, n_starts: int = 8,
                   seed: int = 0) -> tuple[PreisachNetwork, dict]:
    r"""Train the arctan network mu on friction samples with Ipopt (exact AD derivatives).

    .. math::

        \min_{W, b, c, c_0}\ \frac12 \sum_{i,j} \Bigl(\frac{\mu(u_j) - f_{ij}}{\sigma_f}\Bigr)^2
            + \frac{\lambda}{2} \bigl(\|W\|_F^2 + \|c\|^2\bigr)

    (mu and f in N, sigma_f in N, lambda = ``reg`` dimensionless; biases are not
    regularised).  ``n_starts`` seeded random starts; the best local optimum is kept.

    Parameters
    ----------
    U : array_like (n_q, 4)
        Memory inputs (N), :func:`memory_inputs`.
    f : array_like (n_series, n_q) or (n_q,)
        Friction force samples (N).

    Returns
    -------
    (PreisachNetwork, info dict with ``objective``, ``rms`` (N), ``starts`` objectives, ``status``)
    """
    from identification.ipopt_solver import IpoptSettings, solve_nlp
    from identification.errors import IdentificationError
    U = np.asarray(U, float)
    f = np.atleast_2d(np.asarray(f, float))
    if U.ndim != 2 or U.shape[1] != 4:
        raise FrictionError(f"U: expected shape (n_q, 4), got {U.shape}")
    if f.shape[1] != U.shape[0] or not np.isfinite(f).all():
        raise FrictionError(f"f: expected finite (n_series, {U.shape[0]}) forces, got {f.shape}")
    if isinstance(n_hidden, bool) or int(n_hidden) < 1:
        raise FrictionError(f"n_hidden: must be a positive integer, got {n_hidden!r}")
    if not (reg >= 0 and sigma_f > 0):
        raise FrictionError(f"reg >= 0 and sigma_f > 0 required, got reg={reg!r}, sigma_f={sigma_f!r}")
    nh, n_M, n_q = int(n_hidden), f.shape[0], U.shape[0]
    nx = 4 * nh + 2 * nh + 1

    def unpack(x):
        return (ca.reshape(x[:4 * nh], nh, 4), x[4 * nh:5 * nh], x[5 * nh:6 * nh], x[6 * nh])

    def build():
        x = ca.SX.sym("x", nx)
        fbar = ca.SX.sym("fbar", n_q)
        W, b, c, c0 = unpack(x)
        A = ca.atan(ca.mtimes(ca.DM(U / Q_SCALE), W.T) + ca.repmat(b.T, n_q, 1))   # (n_q, nh)
        mu = F_SCALE * (c0 + ca.mtimes(A, c))
        obj = 0.5 * n_M * ca.sumsqr((mu - fbar) / sigma_f) + 0.5 * reg * (ca.sumsqr(W) + ca.sumsqr(c))
        return x, obj, ca.SX(0, 1), fbar

    fbar = f.mean(axis=0)
    const = 0.5 * float(np.sum((f - fbar) ** 2)) / sigma_f ** 2     # within-series scatter (not fitted)
    rng = np.random.default_rng(seed)
    settings = IpoptSettings(tol=1e-10, max_iter=3000)
    best, objs, status = None, [], None
    for _ in range(int(n_starts)):
        x0 = np.concatenate([rng.normal(0, 2.0, 4 * nh), rng.normal(0, 1.0, nh), rng.normal(0, 0.3, nh), [0.0]])
        try:
            res = solve_nlp(build, x0, -np.inf, np.inf, np.zeros(0), np.zeros(0), fbar, settings,
                            what="training of the Preisach network", key=("preisach", nh, n_M, reg, sigma_f,
                                                                          U.tobytes()))
        except IdentificationError:
            objs.append(float("nan"))
            continue
        objs.append(res.f + const)
        if best is None or res.f < best.f:
            best, status = res, res.status
    if best is None:
        raise FrictionError("train_preisach: Ipopt failed from every start")
    x = best.x
    W = x[:4 * nh].reshape(4, nh).T      # CasADi reshape is column-major
    net = PreisachNetwork(W, x[4 * nh:5 * nh], x[5 * nh:6 * nh], float(x[6 * nh]))
    rms = float(np.sqrt(np.mean((net(U)[None, :] - f) ** 2)))
    return net, dict(objective=best.f + const, rms=rms, starts=objs, status=status, n_hidden=nh, reg=reg,
                     sigma_f=sigma_f, n_params=nx)


# ---------------------------------------------------------------------------- storage
TRAINING_DEFAULTS = dict(n_hidden=4, reg=1e-2, sigma_f=20.0, n_starts=8, seed=0)


def retrain(campaign=None, path=FRICTION_JSON, write: bool = True, **training) -> dict:
    """Recompute q_c (M2) and the network (M3) from the training series; optionally write ``path``.

    Steps: :func:`friction_samples` (M1 fit on the four training series, inverse model),
    :func:`fit_coulomb`, :func:`train_preisach` on :func:`memory_inputs` of the set points
    (``training`` overrides :data:`TRAINING_DEFAULTS`).  Returns the stored dict.
    """
    opts = dict(TRAINING_DEFAULTS)
    unknown = set(training) - set(opts)
    if unknown:
        raise FrictionError(f"training: unknown option(s) {sorted(unknown)}; known: {sorted(opts)}")
    opts.update(training)
    s = friction_samples(campaign)
    q_c = fit_coulomb(s["q_set"], s["f"])
    U = memory_inputs(s["q_set"])
    net, info = train_preisach(U, s["f"], **opts)
    out = dict(
        description="Trained friction constants of the press candidate models M2 (Coulomb) and M3 "
                    "(Preisach network); generated by models.friction.retrain()",
        training_series=[int(i) + 1 for i in s["series"]], sensors=list(s["sensors"]),
        k_M1_N_per_mm=s["p_M1"].tolist(), q_c_N=q_c, network=net.to_dict(), training=opts,
        training_result=dict(objective=info["objective"], rms_N=info["rms"], status=info["status"],
                             n_params=info["n_params"],
                             rms_coulomb_N=float(np.sqrt(np.mean((q_c * direction_inputs(s["q_set"])[None, :]
                                                                  - s["f"]) ** 2)))),
    )
    if write:
        atomic_write_text(Path(path), json.dumps(out, indent=1) + "\n")
    return out


def load_friction(path=FRICTION_JSON) -> dict:
    """The stored friction constants: dict with ``coulomb`` (:class:`Coulomb`), ``network``
    (:class:`PreisachNetwork`) and ``raw`` (the JSON content)."""
    path = Path(path)
    if not path.is_file():
        raise FrictionError(f"path: {path} does not exist; run models.friction.retrain()")
    raw = json.loads(path.read_text())
    return dict(coulomb=Coulomb(raw["q_c_N"]), network=PreisachNetwork.from_dict(raw["network"]), raw=raw)


def candidate_models(path=FRICTION_JSON) -> dict:
    """The three candidate press models {"M1": Model, "M2": Model, "M3": Model} (stored constants)."""
    from .press import press_model
    fr = load_friction(path)
    return {"M1": press_model(), "M2": press_model(friction=fr["coulomb"]),
            "M3": press_model(friction=fr["network"])}


def fit_candidates(campaign=None, series: Sequence[int] | None = None, sensors: Sequence[str] = ("D_y", "F_x"),
                   models: dict | None = None, inputs: Sequence[int] | None = None) -> dict:
    r"""Identify (k5, k7) with M1, M2 and M3 on (held-out) series of a campaign.

    .. math::

        \min_{k_5, k_7} \sum_{i, j, k \in \text{sensors}} \bigl((z_{ijk} - h_k(y_j, k_5, k_7, \bar q_j))
        / \sigma_k\bigr)^2,\quad E(y_j, k_5, k_7, \bar q_j) = 0,

    sigma_k = the campaign's composed sigma sqrt(sigma_rep^2 + sigma_man^2) (mm), \bar q_j
    the model's inputs from :func:`model_inputs` of the set points.

    Parameters
    ----------
    campaign : Campaign, optional      default: the shipped campaign
    series : sequence of int, optional default: ``models.prototype.TEST_SERIES`` (the held-out two)
    sensors : sequence of str          sensors with weight 1 (the others weight 0)
    models : dict, optional            {name: Model}, default :func:`candidate_models`
    inputs : sequence of int, optional 0-based set points to use (default all 29)

    Returns
    -------
    dict {name: Estimate}
    """
    from identification import identify
    from .press import K_NOMINAL
    from .prototype import TEST_SERIES, read_campaign
    campaign = read_campaign() if campaign is None else campaign
    models = candidate_models() if models is None else models
    out = {}
    for name, model in models.items():
        data = campaign.measurements(series=TEST_SERIES if series is None else series,
                                     inputs=model_inputs(name, campaign.q_set))
        if inputs is not None:
            data = data.subset(inputs=list(inputs))
        unknown = set(sensors) - set(model.sensors)
        if unknown:
            raise FrictionError(f"sensors: {sorted(unknown)} are not sensors of {model.name!r}")
        out[name] = identify(model, data, K_NOMINAL, weights=[1.0 if s in sensors else 0.0 for s in model.sensors])
    return out
