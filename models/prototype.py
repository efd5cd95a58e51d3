r"""The virtual prototype: a stand-in for the real 3D Servo Press that generates measurements.

For every load step the prototype solves the quasi-static equilibrium

.. math::

    \nabla_y U_\mathrm{proto}(y; k_5, k_7) - e_{R_y}\,\bigl(q_P - F_\mathrm{fric}(y, s)\bigr) = 0
    \qquad [\mathrm{N},\ \mathrm{N\,mm}],

    F_\mathrm{fric}(y, s) = \sum_{i=1}^{m} \operatorname{clip}\bigl(k_i\,(u_{R,y} - s_i),\;
        \pm f_i\,F_b(y)\bigr),
    \qquad F_b(y) = F_0 + \mu\,|H(y)|,\quad H = -k_{x,\mathrm{guide}}\,u_{R,x},

and then updates the slip positions by the stop operator, s_i <- u_{R,y} - F_i / k_i
(a generalised Maxwell-slip model of the ram guide: m elastic-slip elements of
stiffness k_i (N/mm) whose break-away forces f_i F_b (N) grow with the guide's normal
force |H| (N)).  U_proto is the press linkage of :mod:`models.press` with smooth
clearance bearings F = k (d - g tanh(d/g)) + r k d at the lever fulcrum C and the
eccentric pin A.  The path is followed sequentially (quasi-static, several sub-steps
between set points), so the prototype is path dependent; the sub-step solves are
semismooth Newton iterations with the exact AD (generalised) Jacobian.

A measurement campaign (:func:`generate_campaign`) applies the paper's 29 set points
(15 loading 0 -> 1600 N, 14 unloading back to 0) in ``n_series`` consecutive series
after one unrecorded run-in cycle.  The pneumatic supply scatters each actual force
around its set point (relative standard deviation ``force_scatter``); every sensor
reading carries (i) a random repeatability error N(0, sigma_rep^2) drawn per reading and
(ii) a systematic linearity error of the gauge (a smooth random function of the reading,
drawn once per campaign, standard deviation sigma_man), so that the total error per
reading has the paper's standard deviation sqrt(sigma_rep^2 + sigma_man^2) (15.18, 4.895,
3.904 um) while differences between series see only sigma_rep, as in the paper's
repeatability analysis.  Finally the paper's correction z * q_set / q_actual is applied
(readings at q_set = 0 are left unchanged).  Displacements are in mm in the code and in
micrometres (um) in the files, like the paper's files.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np
from scipy import stats
from scipy.linalg.lapack import dgesv

from .campaign import Campaign
from .mechanism import MechanismError, RigidBody, Support, build_model
from .press import PRESS_SENSORS, Q_PAPER, press_mechanism
from .state import JIT
from .fileio import atomic_write_text

__all__ = ["PrototypeConfig", "VirtualPrototype", "Campaign", "generate_campaign", "write_campaign",
           "read_campaign", "ship_campaign", "repeatability_table", "composed_sigma", "CAMPAIGN_DIR",
           "CAMPAIGN_SEED", "SIGMA_REP_PAPER_UM", "SIGMA_MAN_UM", "SIGMA_PAPER_UM", "TRAIN_SERIES",
           "TEST_SERIES"]

#: the paper's repeatability sigmas (Table "Analysis of the measurement data"), um
SIGMA_REP_PAPER_UM = (5.5147, 3.3108, 1.4974)
#: the sensor manufacturer's error, um (paper, section "Numerical Results")
SIGMA_MAN_UM = (14.142, 3.6055, 3.6055)
#: composed sigmas sqrt(rep^2 + man^2) used by the paper, um
SIGMA_PAPER_UM = (15.18, 4.895, 3.904)

#: where the shipped campaign lives and the seed it is generated with
CAMPAIGN_DIR = Path(__file__).resolve().parent.parent / "data" / "press_campaign"
CAMPAIGN_SEED = 20190731
#: series (0-based) that train M3 and the two held out for the model tests
TRAIN_SERIES = (0, 1, 2, 3)
TEST_SERIES = (4, 5)

_FILE_STEM = "measurements_"


class PrototypeError(ValueError):
    """Bad prototype configuration or campaign argument (the message names it)."""


@dataclass(frozen=True)
class PrototypeConfig:
    """Physical values of the virtual prototype (documented in docs/press_geometry.md).

    Attributes
    ----------
    k5, k7 : float
        True axial stiffnesses of the spindles (N/mm).
    slip_stiffness : tuple of float
        Stiffness k_i of the Maxwell-slip elements of the ram guide (N/mm).
    slip_fraction : tuple of float
        Share f_i of the break-away force carried by element i (sums to 1).
    breakaway_base : float
        F_0 (N): break-away force of the guide without normal force.
    breakaway_slope : float
        mu (-): growth of the break-away force with the horizontal guide reaction |H|.
    normal_smoothing : float
        eps (N) in |H| ~ sqrt(H^2 + eps^2).
    gaps : tuple of (body, joint, g)
        Clearance bearings: body name, joint, gap width g (mm).
    gap_residual : float
        r (-) in F = k (d - g tanh(d/g)) + r k d (the builder needs r > 0 here).
    force_scatter : float
        Relative standard deviation of the supply pressure level of a series (-): every
        actual force of series i is q_set (1 + force_scatter xi_i + force_scatter_point xi_ij).
    force_scatter_point : float
        Relative standard deviation of the point-to-point pressure jitter (-).
    sigma_rep_um, sigma_man_um : tuple of float
        Repeatability and manufacturer (linearity) error per sensor (um).
    linearity_modes : int
        Number of random Fourier modes of the gauge linearity error.
    substeps : int
        Quasi-static sub-steps between consecutive set points.
    """

    k5: float = 530.0
    k7: float = 470.0
    slip_stiffness: tuple = (4000.0, 1000.0, 300.0, 80.0)
    slip_fraction: tuple = (0.3, 0.3, 0.25, 0.15)
    breakaway_base: float = 50.0
    breakaway_slope: float = 0.3
    normal_smoothing: float = 0.1
    gaps: tuple = (("carrier", "C", 0.025), ("ecc", "A", 0.020))
    gap_residual: float = 0.05
    force_scatter: float = 0.015
    force_scatter_point: float = 0.003
    sigma_rep_um: tuple = SIGMA_REP_PAPER_UM
    sigma_man_um: tuple = SIGMA_MAN_UM
    linearity_modes: int = 6
    substeps: int = 4

    def __post_init__(self):
        for name in ("k5", "k7", "breakaway_base", "normal_smoothing", "gap_residual"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise PrototypeError(f"{name} must be positive and finite, got {v!r}")
        for name in ("breakaway_slope", "force_scatter", "force_scatter_point"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise PrototypeError(f"{name} must be non-negative and finite, got {v!r}")
        ks, fs = np.asarray(self.slip_stiffness, float), np.asarray(self.slip_fraction, float)
        if ks.ndim != 1 or ks.size == 0 or ks.shape != fs.shape:
            raise PrototypeError(f"slip_stiffness and slip_fraction must be equally long non-empty sequences, "
                                 f"got {self.slip_stiffness!r} and {self.slip_fraction!r}")
        if not (np.all(ks > 0) and np.all(fs > 0) and np.isfinite(ks).all()):
            raise PrototypeError("slip_stiffness and slip_fraction must be positive")
        if abs(fs.sum() - 1.0) > 1e-9:
            raise PrototypeError(f"slip_fraction must sum to 1, got {fs.sum()!r}")
        for name in ("sigma_rep_um", "sigma_man_um"):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (len(PRESS_SENSORS),) or not np.all(v >= 0):
                raise PrototypeError(f"{name} must hold {len(PRESS_SENSORS)} non-negative values, got {v!r}")
        for g in self.gaps:
            if len(g) != 3 or not (np.isfinite(g[2]) and g[2] > 0):
                raise PrototypeError(f"gaps: each entry must be (body, joint, g > 0 mm), got {g!r}")
        if int(self.substeps) < 1 or int(self.linearity_modes) < 1:
            raise PrototypeError("substeps and linearity_modes must be at least 1")


class VirtualPrototype:
    r"""The noise-free prototype press: mechanism with clearance plus Maxwell-slip guide friction.

    .. math::

        \nabla_y U(y) - e_{R_y}(q_P - F_\mathrm{fric}(y, s)) = 0,\quad
        s_i \leftarrow u_{R,y} - F_i / k_i     \qquad [\mathrm{N}]

    Parameters
    ----------
    config : PrototypeConfig
    """

    def __init__(self, config: PrototypeConfig = PrototypeConfig()):
        if not isinstance(config, PrototypeConfig):
            raise PrototypeError(f"config: expected a PrototypeConfig, got {type(config).__name__}")
        self.config = config
        self.mechanism = self._mechanism(config)
        self.model = build_model(self.mechanism, sensors=PRESS_SENSORS, unknowns=("k5", "k7"),
                                 inputs=("q_P", "q_fric"),
                                 input_map=lambda qd, qv: {"q_P": qd["q_P"] - qd["q_fric"]},
                                 name="virtual_prototype")
        self.p = np.array([config.k5, config.k7])
        self._fun = self._functions()
        self.n_slip = len(config.slip_stiffness)
        compiled = JIT.compile(self._fun) if JIT.active() else None
        self._eval_fun = self._fun if compiled is None else compiled
        self._first_cycles: dict = {}

    @staticmethod
    def _mechanism(cfg):
        mech = press_mechanism(cfg.k5, cfg.k7)
        gaps: dict = {}
        for body, joint, g in cfg.gaps:
            gaps.setdefault(body, {})[joint] = float(g)
        bodies = {b.name for b in mech.of(RigidBody)}
        for body in gaps:
            if body not in bodies:
                raise PrototypeError(f"gaps: body {body!r} is not a rigid body of the press ({', '.join(bodies)})")
        elements = [replace(el, gap=gaps[el.name], gap_residual=float(cfg.gap_residual))
                    if isinstance(el, RigidBody) and el.name in gaps else el for el in mech.elements]
        mech.elements = elements
        mech.name = "press_prototype"
        return mech

    def _functions(self):
        cfg, model = self.config, self.model
        guide = [s for s in self.mechanism.of(Support) if s.name == "ram_guide"]
        if len(guide) != 1 or guide[0].kx is None or guide[0].joint != "R":
            raise MechanismError("the prototype needs the press's horizontal 'ram_guide' support at R")
        kxg = float(guide[0].kx)
        iRx, iRy = model.state_names.index("R.x"), model.state_names.index("R.y")
        y = ca.SX.sym("y", model.n_y)
        s = ca.SX.sym("s", len(cfg.slip_stiffness))
        q = ca.SX.sym("q")
        H = -kxg * y[iRx]                                   # horizontal guide reaction on R (N)
        Fb = cfg.breakaway_base + cfg.breakaway_slope * ca.sqrt(H ** 2 + cfg.normal_smoothing ** 2)
        Fi = []
        for k, f, si in zip(cfg.slip_stiffness, cfg.slip_fraction, ca.vertsplit(s)):
            c = f * Fb
            Fi.append(ca.fmin(ca.fmax(k * (y[iRy] - si), -c), c))
        Fi = ca.vertcat(*Fi)
        Ff = ca.sum1(Fi)
        p = ca.DM(self.p)
        R = model.E_fun(y, p, ca.vertcat(q, Ff))
        h = model.h_fun(y, p, ca.vertcat(q, Ff))
        outs = ca.cse([R, ca.jacobian(R, y), Fi, Ff, H, Fb, h, y[iRy]])   # shared subexpressions once
        return ca.Function("proto", [y, s, q], outs, ["y", "s", "q"], ["R", "J", "Fi", "Ff", "H", "Fb", "h", "uRy"])

    def initial_state(self):
        """Unloaded, friction-free reference: y = 0 (mm, rad), slip positions s = 0 (mm), last force 0 N."""
        return np.zeros(self.model.n_y), np.zeros(self.n_slip), 0.0

    def _solve(self, ws: "_Workspace", y, s, q, where):
        """Semismooth Newton for R(y; s, q) = 0 from y (N); returns the converged y.

        Damped steps y <- y + t dy, J dy = -R (LAPACK LU with partial pivoting), t halved while
        |R| does not decrease (kinks of the clip).  On return ``ws`` holds all outputs of the
        point function at (y, s, q).
        """
        ws.set_state(s, q)
        ws.evaluate(y)
        R = ws.R
        for _ in range(60):
            _, _, dy, info = dgesv(ws.jacobian(), -R, overwrite_a=True, overwrite_b=True)   # LU, pivoting
            if info != 0:
                raise MechanismError(f"virtual prototype: singular Jacobian at {where} (q_P = {q:.6g} N, "
                                     f"LAPACK dgesv info {info})")
            nr = math.sqrt(R.dot(R))            # = np.linalg.norm(R), without its overhead
            t = 1.0
            for _ in range(30):
                y_new = y + t * dy
                ws.evaluate(y_new)
                nr_new = math.sqrt(R.dot(R))
                if nr_new <= (1 - 1e-4 * t) * nr or nr < 1e-9:
                    break
                t *= 0.5
            else:                               # no decrease in 30 halvings: take the last halved step
                y_new = y + t * dy
                ws.evaluate(y_new)
            y = y_new
            step = t * dy
            if max(step.max(), -step.min()) <= 1e-13 * max(1.0, y.max(), -y.min()) or nr_new < 1e-10:
                return y
        ks = np.asarray(self.config.slip_stiffness)
        raise MechanismError(f"virtual prototype: Newton did not converge at {where} (q_P = {q:.6g} N, "
                             f"residual {np.linalg.norm(ws.R):.3g} N; slip stiffness {ks.tolist()})")

    def run(self, forces, state=None):
        """Follow the force path ``forces`` (N) quasi-statically; return readings and the final state.

        Between consecutive forces ``config.substeps`` equal sub-steps are taken (the
        stop operator is exact for monotone sub-steps at fixed break-away force).

        Parameters
        ----------
        forces : array_like (n,)
            Actual process forces q_P (N) in the order they are applied.
        state : (y, s, q_last), optional
            Start state (default :meth:`initial_state`); the path continues from force q_last.

        Returns
        -------
        h : ndarray (n, 3)
            Noise-free sensor displacements D_y, F_x, B0_y (mm).
        info : dict
            ``friction`` (n,) total guide friction F_fric (N, positive opposes upward motion),
            ``normal`` (n,) horizontal guide reaction H (N), ``breakaway`` (n,) F_b (N).
        state : (y, s, q_last)
            Final state, to continue the path.
        """
        f = np.asarray(forces, float)
        if f.ndim != 1 or f.size == 0 or not np.all(np.isfinite(f)):
            raise PrototypeError(f"forces: expected a non-empty 1-D array of finite forces (N), got shape {f.shape}")
        if state is None:
            state = self.initial_state()
        if len(state) != 3:
            raise PrototypeError("state: expected (y, s, q_last) as returned by run()")
        y, s, q_prev = np.array(state[0], float), np.array(state[1], float), float(state[2])
        ks = np.asarray(self.config.slip_stiffness)
        ws = _Workspace(self._eval_fun)
        h = np.empty((f.size, len(PRESS_SENSORS)))
        fr, nn, fb = np.empty(f.size), np.empty(f.size), np.empty(f.size)
        for j, qj in enumerate(f):
            for t in np.linspace(0.0, 1.0, int(self.config.substeps) + 1)[1:]:
                qs = q_prev + t * (qj - q_prev)
                y = self._solve(ws, y, s, qs, f"step {j}")
                s = ws.uRy[0] - ws.Fi / ks                    # stop operator update
            h[j] = ws.h
            fr[j], nn[j], fb[j] = ws.Ff[0], ws.H[0], ws.Fb[0]
            q_prev = qj
        return h, dict(friction=fr, normal=nn, breakaway=fb), (y, s, q_prev)

    def first_cycle(self, forces):
        """:meth:`run` of ``forces`` (N) from :meth:`initial_state`, computed once per force path and kept.

        The noise-free path from the virgin state is the same for every campaign on the
        same set points; returns fresh copies of (h, info, state) as :meth:`run` does.
        """
        f = np.asarray(forces, float)
        key = (f.shape, f.tobytes())
        got = self._first_cycles.get(key)
        if got is None:
            got = self.run(f)
            self._first_cycles[key] = got
        h, info, (y, s, q) = got
        return h.copy(), {k: v.copy() for k, v in info.items()}, (y.copy(), s.copy(), q)


class _Workspace:
    """Arrays bound to a buffer of the prototype's point function (y, s, q) -> (R, J, Fi, Ff, H, Fb, h, uRy).

    :meth:`evaluate` runs the function in place, without conversions to and from CasADi
    matrices (the per-call overhead of ``Function.__call__`` was most of the prototype's
    time).  One workspace per :meth:`VirtualPrototype.run` call, so that runs in threads do
    not share it.  J is kept as its structural nonzeros (:meth:`jacobian` gives it dense).
    """

    def __init__(self, fun: ca.Function):
        self._buf, self._eval = fun.buffer()
        self.y, self.s, self.q = (np.zeros(fun.nnz_in(i)) for i in range(3))
        for i, a in enumerate((self.y, self.s, self.q)):
            self._buf.set_arg(i, memoryview(a))
        n_y = fun.size1_out(0)
        sp = fun.sparsity_out(1)
        self._n_y = n_y
        self._J_at = np.asarray(sp.row(), int) + n_y * np.asarray(sp.get_col(), int)   # column-major positions
        self.R = np.zeros(n_y)
        self.J_nz = np.zeros(sp.nnz())
        self.Fi, self.Ff, self.H, self.Fb, self.h, self.uRy = (np.zeros(fun.nnz_out(i)) for i in range(2, 8))
        for i, a in enumerate((self.R, self.J_nz, self.Fi, self.Ff, self.H, self.Fb, self.h, self.uRy)):
            if a.size != fun.nnz_out(i):
                raise MechanismError(f"virtual prototype: output {fun.name_out(i)} does not fit its buffer")
            self._buf.set_res(i, memoryview(a))

    def jacobian(self):
        """A fresh dense column-major copy of J = dR/dy (N/mm, N/rad) at the last evaluated state."""
        J = np.zeros(self._n_y * self._n_y)
        J[self._J_at] = self.J_nz
        return J.reshape(self._n_y, self._n_y, order="F")

    def set_state(self, s, q):
        """Slip positions s (mm) and force q (N) of the next evaluations."""
        self.s[:] = s
        self.q[0] = q

    def evaluate(self, y):
        """All outputs at state y (mm, rad), written into this workspace's arrays."""
        self.y[:] = y
        self._eval()
        if self._buf.ret() != 0:
            raise MechanismError(f"virtual prototype: evaluation failed (CasADi return code {self._buf.ret()})")


# ---------------------------------------------------------------------------- campaign
def _linearity_error(rng, n_modes, sigma_mm, span_mm):
    """A smooth random function e(z) = sigma sqrt(2/m) sum_l a_l cos(w_l z + phi_l) (mm), Var e = sigma^2."""
    a = rng.standard_normal(n_modes)
    w = 2 * np.pi * rng.uniform(0.5, 2.0, n_modes) / span_mm
    phi = rng.uniform(0, 2 * np.pi, n_modes)
    c = sigma_mm * np.sqrt(2.0 / n_modes)
    return lambda z: c * np.sum(a[:, None] * np.cos(np.outer(w, z) + phi[:, None]), axis=0).reshape(np.shape(z))


def generate_campaign(seed: int = CAMPAIGN_SEED, config: PrototypeConfig = PrototypeConfig(), n_series: int = 6,
                      q_set: Sequence[float] = Q_PAPER, prototype: VirtualPrototype | None = None) -> Campaign:
    r"""Simulate a measurement campaign on the virtual prototype (seeded, deterministic).

    .. math::

        z^\mathrm{raw}_{ijk} = h_k(y_{ij}) + e_k(h_k(y_{ij})) + \varepsilon_{ijk},\quad
        \varepsilon_{ijk} \sim N(0, \sigma_{\mathrm{rep},k}^2),\quad
        z_{ijk} = z^\mathrm{raw}_{ijk}\, q^d_j / q_{ij}     \qquad [\mathrm{mm}]

    with q_ij = q^d_j (1 + force_scatter xi_ij), xi ~ N(0, 1) (q = 0 stays 0), y_ij the
    prototype state after the path up to force q_ij (series follow each other after one
    run-in cycle at the set points), e_k the gauge linearity error (std sigma_man,k).

    Parameters
    ----------
    seed : int
        Seed of numpy's default_rng.
    config : PrototypeConfig
    n_series : int
        Number of repeated series n_M (at least 2).
    q_set : sequence of float
        Set-point forces (N), the paper's 29 by default.
    prototype : VirtualPrototype, optional
        A prebuilt prototype for ``config`` (saves the CasADi build).

    Returns
    -------
    Campaign
    """
    if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 2:
        raise PrototypeError(f"n_series must be an integer >= 2, got {n_series!r}")
    qd = np.asarray(q_set, float)
    if qd.ndim != 1 or qd.size < 2 or not np.all(np.isfinite(qd)) or np.any(qd < 0):
        raise PrototypeError(f"q_set: expected a 1-D sequence of at least two non-negative forces (N), got {q_set!r}")
    proto = prototype if prototype is not None else VirtualPrototype(config)
    if proto.config != config:
        raise PrototypeError("prototype: was built for another config than the one passed")
    rng = np.random.default_rng(seed)
    n_S, n_q = len(PRESS_SENSORS), qd.size
    # the noise-free cycle from the virgin state: the span of the gauge linearity errors and the
    # unrecorded run-in cycle (the same path; computed once per prototype and set points)
    h_nom, _, state = proto.first_cycle(qd)
    span = np.maximum(np.ptp(h_nom, axis=0), 1e-3)
    lin = [_linearity_error(rng, int(config.linearity_modes), config.sigma_man_um[k] * 1e-3, span[k])
           for k in range(n_S)]
    # per series, in this order: the series' pressure level, the point jitter, the repeatability
    # errors; drawn in one go (the same stream as drawing them series by series)
    xi = rng.standard_normal((n_series, 1 + n_q + n_q * n_S))
    q_act = qd * (1.0 + config.force_scatter * xi[:, :1] + config.force_scatter_point * xi[:, 1:1 + n_q])
    eps = np.asarray(config.sigma_rep_um) * 1e-3 * xi[:, 1 + n_q:].reshape(n_series, n_q, n_S)
    z_raw = np.empty((n_series, n_q, n_S))
    for i in range(n_series):                 # the series one after the other (the path continues)
        h, _, state = proto.run(q_act[i], state)
        z_raw[i] = h + np.column_stack([lin[k](h[:, k]) for k in range(n_S)]) + eps[i]
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(q_act > 0, qd[None, :] / np.where(q_act > 0, q_act, 1.0), 1.0)
    z = z_raw * factor[:, :, None]
    return Campaign(q_set=qd, q_actual=q_act, z=z, sensors=PRESS_SENSORS, z_raw=z_raw, seed=seed,
                    config=asdict(config))


# ---------------------------------------------------------------------------- statistics
def repeatability_table(z, pairs=((1, 0), (3, 2), (5, 4))):
    r"""Shapiro-Wilk test of the series differences and the repeatability sigma per sensor.

    .. math::

        \tilde z_k = (z_{2kj} - z_{1kj},\ z_{4kj} - z_{3kj},\ z_{6kj} - z_{5kj})_{j},\qquad
        \sigma_{\mathrm{rep},k} = \operatorname{std}(\tilde z_k) / \sqrt 2

    (same unit as z).  Parameters: z (n_M, n_q, n_S); pairs of 0-based series indices
    (a, b) giving the differences z_a - z_b.  Returns a dict with ``p_value`` (n_S,) and
    ``sigma`` (n_S,) (std with ddof = 1), ``statistic`` (n_S,).
    """
    z = np.asarray(z, float)
    if z.ndim != 3:
        raise PrototypeError(f"z: expected shape (n_M, n_q, n_S), got {z.shape}")
    for a, b in pairs:
        if not (0 <= a < z.shape[0] and 0 <= b < z.shape[0]) or a == b:
            raise PrototypeError(f"pairs: ({a}, {b}) are not two distinct series of {z.shape[0]}")
    d = np.concatenate([z[a] - z[b] for a, b in pairs], axis=0)      # (len(pairs) * n_q, n_S)
    p, w, sig = [], [], []
    for k in range(z.shape[2]):
        dk = d[:, k][np.isfinite(d[:, k])]
        res = stats.shapiro(dk)
        p.append(float(res.pvalue))
        w.append(float(res.statistic))
        sig.append(float(np.std(dk, ddof=1) / np.sqrt(2.0)))
    return dict(p_value=np.array(p), statistic=np.array(w), sigma=np.array(sig))


def composed_sigma(z, sigma_man_um: Sequence[float] = SIGMA_MAN_UM):
    r"""The paper's sensor sigma sqrt(sigma_rep^2 + sigma_man^2) in um, from readings z in mm.

    sigma_rep is :func:`repeatability_table` of z (converted to um); sigma_man the
    manufacturer's error (um).  Returns an array (n_S,) in um.
    """
    rep = repeatability_table(np.asarray(z, float) * 1e3)["sigma"]
    man = np.asarray(sigma_man_um, float)
    if man.shape != rep.shape:
        raise PrototypeError(f"sigma_man_um: expected {rep.size} values, got {man.size}")
    return np.sqrt(rep ** 2 + man ** 2)


# ---------------------------------------------------------------------------- files
def _fmt(v: float) -> str:
    return f"{v:.4f}"


def write_campaign(campaign: Campaign, directory=CAMPAIGN_DIR) -> list[Path]:
    """Write a campaign in the paper's layout plus a tidy long table (atomically).

    Files (displacements in um, forces in N):

    * ``measurements_<sensor>.csv``: header ``force_N,series_1,...``; one row per set point:
      the set force, then the corrected reading of each series (the paper's
      ``Messungen_*.csv`` layout);
    * ``campaign_long.csv``: ``series,index,set_force_N,actual_force_N,sensor,raw_um,value_um``
      (1-based series and set-point index; value = corrected reading);
    * ``campaign.json``: seed and prototype configuration.

    Returns the written paths.
    """
    if not isinstance(campaign, Campaign):
        raise PrototypeError(f"campaign: expected a Campaign, got {type(campaign).__name__}")
    if campaign.z_raw is None or campaign.q_actual is None:
        raise PrototypeError("campaign: the prototype layout needs actual forces and raw readings (a simulated "
                             "campaign); write measured data with mudoe.data_io")
    d = Path(directory)
    written = []
    for k, sname in enumerate(campaign.sensors):
        lines = ["force_N," + ",".join(f"series_{i + 1}" for i in range(campaign.n_M))]
        for j, q in enumerate(campaign.q_set):
            lines.append(",".join([_fmt(q)] + [_fmt(1e3 * campaign.z[i, j, k]) for i in range(campaign.n_M)]))
        p = d / f"{_FILE_STEM}{sname}.csv"
        atomic_write_text(p, "\n".join(lines) + "\n")
        written.append(p)
    lines = ["series,index,set_force_N,actual_force_N,sensor,raw_um,value_um"]
    for i in range(campaign.n_M):
        for j, q in enumerate(campaign.q_set):
            for k, sname in enumerate(campaign.sensors):
                lines.append(f"{i + 1},{j + 1},{_fmt(q)},{_fmt(campaign.q_actual[i, j])},{sname},"
                             f"{_fmt(1e3 * campaign.z_raw[i, j, k])},{_fmt(1e3 * campaign.z[i, j, k])}")
    p = d / "campaign_long.csv"
    atomic_write_text(p, "\n".join(lines) + "\n")
    written.append(p)
    meta = dict(seed=campaign.seed, n_series=campaign.n_M, sensors=list(campaign.sensors),
                units=dict(force="N", displacement="um"), config=campaign.config,
                generator="models.prototype.ship_campaign()")
    p = d / "campaign.json"
    atomic_write_text(p, json.dumps(meta, indent=1, sort_keys=True, default=list) + "\n")
    written.append(p)
    return written


def read_campaign(directory=CAMPAIGN_DIR) -> Campaign:
    """Read a campaign written by :func:`write_campaign` (from the long table; mm, N)."""
    d = Path(directory)
    long = d / "campaign_long.csv"
    if not long.is_file():
        raise PrototypeError(f"directory: {d} holds no campaign_long.csv")
    with open(long, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise PrototypeError(f"{long}: no data rows")
    sensors = tuple(dict.fromkeys(r["sensor"] for r in rows))
    n_M = max(int(r["series"]) for r in rows)
    n_q = max(int(r["index"]) for r in rows)
    q_set = np.full(n_q, np.nan)
    q_act = np.full((n_M, n_q), np.nan)
    z_raw = np.full((n_M, n_q, len(sensors)), np.nan)
    z = np.full_like(z_raw, np.nan)
    for r in rows:
        i, j, k = int(r["series"]) - 1, int(r["index"]) - 1, sensors.index(r["sensor"])
        q_set[j] = float(r["set_force_N"])
        q_act[i, j] = float(r["actual_force_N"])
        z_raw[i, j, k] = 1e-3 * float(r["raw_um"])
        z[i, j, k] = 1e-3 * float(r["value_um"])
    if np.isnan(z).any() or np.isnan(q_act).any():
        raise PrototypeError(f"{long}: incomplete table (missing series/index/sensor combinations)")
    meta = {}
    if (d / "campaign.json").is_file():
        meta = json.loads((d / "campaign.json").read_text())
    return Campaign(q_set=q_set, q_actual=q_act, z_raw=z_raw, z=z, sensors=sensors, seed=meta.get("seed"),
                    config=meta.get("config", {}))


def ship_campaign(directory=CAMPAIGN_DIR, seed: int = CAMPAIGN_SEED) -> list[Path]:
    """Generate the shipped campaign (default config, fixed seed) and write it to ``directory``."""
    return write_campaign(generate_campaign(seed=seed), directory)


if __name__ == "__main__":   # regenerate data/press_campaign
    for path in ship_campaign():
        print(path)
