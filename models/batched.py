"""A CasADi function of column vectors evaluated at n points in one call (mapped, through a FunctionBuffer).

Used by :class:`models.state.Numerics` and by the trajectory numerics of collocated models
(:mod:`models.trajectory`); it imports neither.
"""
from __future__ import annotations

import threading

import casadi as ca
import numpy as np

from .errors import StateSolveError

__all__ = ["BatchedFunction", "batched_function"]


class BatchedFunction:
    """A CasADi function mapped over n points, evaluated through a FunctionBuffer.

    CasADi stores matrices column-major, so the (d, n) argument of the mapped function is
    the C-contiguous (n, d) NumPy array and the (r, c n) output is the C-contiguous array
    (n, c, r); the outputs are densified so that every entry has its slot.
    """

    def __init__(self, f: ca.Function, n: int):
        fm = f.map(n)
        sym = fm.mx_in()
        self._f = ca.Function(f"{f.name()}_dense_{n}", sym, [ca.densify(o) for o in fm.call(sym)])
        self.n = n
        self._in = [(f.size1_in(i), f.size2_in(i)) for i in range(f.n_in())]
        self._out = [(f.size1_out(i), f.size2_out(i)) for i in range(f.n_out())]
        self._local = threading.local()          # this thread's FunctionBuffer (20-50 us to create)
        for r, c in self._in:
            if c != 1:
                raise ValueError(f"batched evaluation needs column-vector inputs, got ({r}, {c})")

    def __call__(self, *args) -> list:
        n = self.n
        if len(args) != len(self._in):
            raise ValueError(f"expected {len(self._in)} arguments, got {len(args)}")
        got = getattr(self._local, "buffer", None)
        if got is None:
            got = self._local.buffer = self._f.buffer()
        buf, ev = got
        keep = []
        for i, (a, (r, _)) in enumerate(zip(args, self._in)):
            a = np.asarray(a, float)
            if a.ndim == 1 or a.shape[0] != n:
                a = np.repeat(a.reshape(1, r), n, axis=0)
            a = np.ascontiguousarray(a, dtype=float)
            if a.shape != (n, r):
                raise ValueError(f"argument {i}: expected shape ({n}, {r}), got {a.shape}")
            keep.append(a)
            buf.set_arg(i, memoryview(a))
        outs = [np.empty((n, c, r)) for r, c in self._out]
        for i, o in enumerate(outs):
            buf.set_res(i, memoryview(o))
        ev()
        if buf.ret() != 0:
            raise StateSolveError(f"evaluation of {self._f.name()} failed (CasADi return code {buf.ret()})")
        return [o.transpose(0, 2, 1) for o in outs]


def batched_function(f: ca.Function, n: int) -> BatchedFunction:
    """Evaluator of a CasADi function of column vectors at n points at once through a FunctionBuffer:
    ``batched_function(f, n)(a_1, ..., a_k)`` takes (n, d_i) arrays (or (d_i,) arrays shared by all
    points) and returns one dense (n, r, c) array per output (see :meth:`models.state.Numerics.batched`)."""
    return BatchedFunction(f, n)
