r"""The weighted least-squares terms of an explicit model in one evaluation over the data.

For a model without states (y = h(p, q)) with per-(input, sensor) means zbar_jk and weights
wt_jk = c_jk / sigma_k^2 (c_jk the weighted counts), one call returns the sums over the inputs

.. math::

    f = \tfrac12 \sum_{jk} wt_{jk}\, r_{jk}^2,\quad r_{jk} = h_k(p, q_j) - \bar z_{jk},\qquad
    g = \sum_{jk} wt_{jk} r_{jk}\, \nabla_p h_{jk},\qquad
    F = \sum_{jk} wt_{jk}\, \nabla_p h_{jk} \nabla_p h_{jk}^T,

    a = \sum_{jk} |wt_{jk} r_{jk}|\, |\nabla_p h_{jk}|,\qquad
    S = \sum_{jk} wt_{jk} r_{jk}\, \nabla^2_p h_{jk}\quad\text{(second order only)},

i.e. the reduced objective (without the within-group scatter), its gradient, the Gauss-Newton
information J^T Omega J, the bound of the gradient's round-off and the second-order term of the
exact Hessian J^T Omega J + S, all exact by CasADi AD (the model's cached ``sens`` and
``lag_hess``).  These are the terms of :class:`identification.fit.refinement.ReducedProblem` in one
evaluation instead of a mapped call, four NumPy sums and a second mapped call for S.

Few inputs (below :data:`models.state.VECTORISE_MIN`): the per-input function mapped over the
inputs with the sums as the map's reduction, expanded to one SX function, evaluated through one
``FunctionBuffer`` per fit whose data arguments are set once.  Many inputs: the per-input
function replayed by NumPy over all inputs (:class:`models.vectorised.VectorisedSX`), then
summed.
"""
from __future__ import annotations

import threading
from typing import NamedTuple

import casadi as ca
import numpy as np

from models.contract import Model
from models.errors import StateSolveError
from models.state import VECTORISE_MIN, numerics
from models.vectorised import VectorisedSX, vectorisable

__all__ = ["ExplicitTerms", "explicit_terms"]

#: mapped functions of at most this many inputs are expanded to one SX function (faster calls)
_EXPAND_MAX = 256


class ExplicitTerms(NamedTuple):
    """The sums of the module docstring at one p, in scaled parameters p = s_p ⊙ x: ``g``, ``F``,
    ``g_abs`` and ``S`` are those of Phi(s_p ⊙ x) w.r.t. x (g ⊙ s_p, D F D, a ⊙ s_p, D S D with
    D = diag(s_p)); ``S`` is None unless asked for.  Read-only views of one array."""

    f: float
    g: np.ndarray
    F: np.ndarray
    g_abs: np.ndarray
    S: np.ndarray | None


def _point_functions(model: Model):
    """Per-input SX functions (x, s_p, q, zbar, wt) -> packed (f_j, g_j, F_j, a_j[, S_j]) (scaled,
    F and S symmetric by construction), kept in ``model.cache``."""
    got = model.cache.get("identify.explicit_kernel", None)
    if got is not None:
        return got
    num = numerics(model)
    n_p, n_S = model.n_p, model.n_S
    x, sp, q = ca.SX.sym("x", n_p), ca.SX.sym("s_p", n_p), ca.SX.sym("q", model.n_q_dim)
    zb, wt = ca.SX.sym("zbar", n_S), ca.SX.sym("wt", n_S)
    p = x * sp
    y = ca.SX(0, 1)
    h, _, _, _, hp = num.sens(y, p, q)
    hx = ca.mtimes(ca.densify(hp), ca.diag(sp))              # dh/dx
    lam = wt * (h - zb)                                      # d f_j / d h_j
    f = 0.5 * ca.dot(lam, h - zb)
    g = ca.densify(ca.mtimes(hx.T, lam))
    F = ca.densify(ca.mtimes(hx.T, ca.mtimes(ca.diag(wt), hx)))
    F = ca.triu(F) + ca.triu(F, False).T                    # exactly symmetric
    a = ca.densify(ca.mtimes(ca.fabs(hx).T, ca.fabs(lam)))
    S = ca.densify(num.lag_hess(y, p, q, lam, ca.SX(0, 1))) * ca.mtimes(sp, sp.T)
    S = 0.5 * (S + S.T)
    args = [x, sp, q, zb, wt]
    first = [f, g, ca.vec(F), a]
    fns = (ca.Function("ls_terms", args, [ca.vertcat(*first)]),
           ca.Function("ls_terms2", args, [ca.vertcat(*first, ca.vec(S))]))
    return model.cache.put("identify.explicit_kernel", None, fns)


class _Mapped:
    """The per-input function mapped over n inputs with summed outputs, and per thread one
    ``FunctionBuffer`` of it with its output array and the evaluator whose arguments it holds
    (creating a buffer costs about 20-50 us, as much as five evaluations of a small problem)."""

    def __init__(self, f: ca.Function):
        self.function = f
        self._local = threading.local()

    def buffer(self):
        """[buffer, evaluate, output array, owner] of this thread (owner: the evaluator that set
        the arguments last, None at first)."""
        got = getattr(self._local, "state", None)
        if got is None:
            buf, ev = self.function.buffer()
            out = np.empty(self.function.nnz_out(0))
            buf.set_res(0, memoryview(out))
            got = self._local.state = [buf, ev, out, None]
        return got


def _mapped(model: Model, second: bool, n: int) -> _Mapped:
    """The per-input function of ``second`` order mapped over n inputs with summed outputs."""
    key = (second, n)
    got = model.cache.get("identify.explicit_kernel_map", key)
    if got is None:
        f = _point_functions(model)[int(second)]
        fm = f.map(f"{f.name()}_sum_{n}", "serial", n, [0, 1], [0])
        if n <= _EXPAND_MAX:
            fm = fm.expand()
        got = model.cache.put("identify.explicit_kernel_map", key, _Mapped(fm), maxsize=16)
    return got


def explicit_terms(model: Model, inputs: np.ndarray, zbar: np.ndarray, wt: np.ndarray,
                   s_p: np.ndarray) -> "_Bound | None":
    """An evaluator ``terms(x, second_order) -> ExplicitTerms`` of the sums of the module docstring
    at p = s_p ⊙ x for the data (inputs (n_q, d_q), zbar and wt (n_q, n_S)), or None when the
    model has states or is not stated in SX (the caller then uses the general path)."""
    if model.n_y or model.symbolic != "SX":
        return None
    return _Bound(model, np.asarray(inputs, float), np.asarray(zbar, float), np.asarray(wt, float),
                  np.asarray(s_p, float))


class _Bound:
    """The evaluator returned by :func:`explicit_terms` (one per fit; not shared between threads)."""

    def __init__(self, model, inputs, zbar, wt, s_p):
        self._model = model
        self._n = n = inputs.shape[0]
        self._n_p = n_p = model.n_p
        self._sp = np.ascontiguousarray(s_p)
        self._data = (np.ascontiguousarray(inputs), np.ascontiguousarray(zbar), np.ascontiguousarray(wt))
        self._x = np.zeros(n_p)
        self._cuts = np.cumsum([1, n_p, n_p * n_p, n_p])
        self._vec = None
        self._buffers = [None, None]
        if n >= VECTORISE_MIN:
            fns = _point_functions(model)
            if vectorisable(fns[1]):
                self._vec = [VectorisedSX(f) for f in fns]

    def _buffer(self, second: bool):
        mapped = self._buffers[second]
        if mapped is None:
            mapped = self._buffers[second] = _mapped(self._model, second, self._n)
        state = mapped.buffer()
        buf = state[0]
        if state[3] is not self:                 # another evaluator used this thread's buffer last
            buf.set_arg(0, memoryview(self._x))
            buf.set_arg(1, memoryview(self._sp))
            for i, a in enumerate(self._data, 2):
                buf.set_arg(i, memoryview(a))
            state[3] = self
        return state

    def __call__(self, x: np.ndarray, second_order: bool) -> ExplicitTerms:
        if self._vec is not None:
            v = self._vec[second_order](x, self._sp, *self._data, n=self._n)[0].sum(axis=1)   # pairwise sums
        else:
            buf, ev, out, _ = self._buffer(second_order)
            self._x[:] = x
            ev()
            if buf.ret() != 0:
                raise StateSolveError(f"evaluation of the least-squares terms failed (CasADi return code {buf.ret()})")
            v = out.copy()
        v.setflags(write=False)
        n_p, (c1, c2, c3, c4) = self._n_p, self._cuts
        return ExplicitTerms(float(v[0]), v[c1:c2], v[c2:c3].reshape(n_p, n_p), v[c3:c4],
                             v[c4:].reshape(n_p, n_p) if second_order else None)
