"""Vectorised NumPy evaluation of a CasADi SX Function at many points.

A CasADi SX Function is a straight-line program: a list of scalar instructions (read an input
nonzero, a constant, a unary or binary operation, write an output nonzero) over a small work
vector.  :class:`VectorisedSX` replays that program once with NumPy arrays in the work slots,
one entry per evaluation point, so every instruction costs one NumPy ufunc call over all points
instead of one virtual-machine step per point.  Arguments shared by all points (e.g. the
parameters) stay scalars, so the work that depends on them alone is done once.

For many points this is 3-6x faster than CasADi's serial ``Function.map`` (whose virtual
machine spends 5-10 ns per instruction and point); for a few points the per-instruction Python
overhead (about 1 us) makes the mapped CasADi call faster.  The numbers are the same
operations in the same order, so they agree with CasADi's to the last bit or two (NumPy's and
the C library's ``exp`` may round differently).

Only functions made of scalar operations are supported (no calls of other functions, no
``OP_PARAMETER``); :func:`vectorisable` tells whether a function qualifies.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
from scipy import special

__all__ = ["VectorisedSX", "vectorisable", "CHUNK"]

#: points evaluated per pass (the work arrays of a pass stay in the CPU cache)
CHUNK = 8192


def _flag(fn):
    return lambda *a: 1.0 * fn(*a)


_UNARY = {
    ca.OP_ASSIGN: lambda x: x, ca.OP_NEG: np.negative, ca.OP_EXP: np.exp, ca.OP_LOG: np.log,
    ca.OP_SQRT: np.sqrt, ca.OP_SQ: np.square, ca.OP_TWICE: lambda x: x + x, ca.OP_SIN: np.sin,
    ca.OP_COS: np.cos, ca.OP_TAN: np.tan, ca.OP_ASIN: np.arcsin, ca.OP_ACOS: np.arccos, ca.OP_ATAN: np.arctan,
    ca.OP_SINH: np.sinh, ca.OP_COSH: np.cosh, ca.OP_TANH: np.tanh, ca.OP_ASINH: np.arcsinh,
    ca.OP_ACOSH: np.arccosh, ca.OP_ATANH: np.arctanh, ca.OP_FABS: np.abs, ca.OP_SIGN: np.sign,
    ca.OP_INV: lambda x: 1.0 / x, ca.OP_FLOOR: np.floor, ca.OP_CEIL: np.ceil, ca.OP_ERF: special.erf,
    ca.OP_ERFINV: special.erfinv, ca.OP_NOT: _flag(lambda x: np.equal(x, 0.0)), ca.OP_LOG1P: np.log1p,
    ca.OP_EXPM1: np.expm1,
}

_BINARY = {
    ca.OP_ADD: np.add, ca.OP_SUB: np.subtract, ca.OP_MUL: np.multiply, ca.OP_DIV: np.divide,
    ca.OP_POW: np.power, ca.OP_CONSTPOW: np.power, ca.OP_LT: _flag(np.less), ca.OP_LE: _flag(np.less_equal),
    ca.OP_EQ: _flag(np.equal), ca.OP_NE: _flag(np.not_equal),
    ca.OP_AND: _flag(lambda x, y: np.logical_and(np.not_equal(x, 0.0), np.not_equal(y, 0.0))),
    ca.OP_OR: _flag(lambda x, y: np.logical_or(np.not_equal(x, 0.0), np.not_equal(y, 0.0))),
    ca.OP_FMOD: np.fmod, ca.OP_COPYSIGN: np.copysign, ca.OP_FMIN: np.fmin, ca.OP_FMAX: np.fmax,
    ca.OP_ATAN2: np.arctan2, ca.OP_HYPOT: np.hypot,
    ca.OP_IF_ELSE_ZERO: lambda c, x: np.where(np.not_equal(c, 0.0), x, 0.0),
}

_INPUT, _OUTPUT, _CONST = ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST


def _program(f: ca.Function):
    """The instruction list of ``f`` as tuples (kind, ...) for :meth:`VectorisedSX._run`, or None
    when an instruction is not supported."""
    prog = []
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        if op == _INPUT:
            i, nz = f.instruction_input(k)
            prog.append((0, f.instruction_output(k)[0], i, nz))
        elif op == _OUTPUT:
            i, nz = f.instruction_output(k)
            prog.append((1, f.instruction_input(k)[0], i, nz))
        elif op == _CONST:
            prog.append((2, f.instruction_output(k)[0], float(f.instruction_constant(k))))
        elif op in _UNARY:
            prog.append((3, f.instruction_output(k)[0], _UNARY[op], f.instruction_input(k)[0]))
        elif op in _BINARY:
            a, b = f.instruction_input(k)[:2]
            prog.append((4, f.instruction_output(k)[0], _BINARY[op], a, b))
        else:
            return None
    return prog


def vectorisable(f: ca.Function) -> bool:
    """True when ``f`` is an SX Function of scalar operations that :class:`VectorisedSX` replays."""
    return f.is_a("SXFunction") and _program(f) is not None


class VectorisedSX:
    """An SX Function evaluated at n points at once by NumPy (see the module docstring).

    ``VectorisedSX(f)(a_1, ..., a_k, n=n)`` takes per argument either an array (n, nnz_i) (row j
    = the argument's nonzeros at point j) or a 1-D array of its nnz_i nonzeros shared by all
    points, and returns per output a C-contiguous array (nnz_o, n): row i = the output's i-th
    nonzero (column-major, as CasADi stores them) at every point, so that a sum over the points
    (``out.sum(axis=1)``) runs along contiguous memory (NumPy's pairwise summation, round-off
    O(log n) eps instead of O(n) eps).

    Raises
    ------
    ValueError
        When ``f`` is not vectorisable (see :func:`vectorisable`) or an argument has the wrong size.
    """

    def __init__(self, f: ca.Function):
        prog = _program(f) if f.is_a("SXFunction") else None
        if prog is None:
            raise ValueError(f"function {f.name()!r} is not an SX function of scalar operations")
        self.function = f
        self._prog = prog
        self._sz_w = f.sz_w()
        self._nnz_in = [f.nnz_in(i) for i in range(f.n_in())]
        self._nnz_out = [f.nnz_out(i) for i in range(f.n_out())]

    def __call__(self, *args, n: int) -> list:
        if len(args) != len(self._nnz_in):
            raise ValueError(f"{self.function.name()}: expected {len(self._nnz_in)} arguments, got {len(args)}")
        arrs = []
        for i, (a, nnz) in enumerate(zip(args, self._nnz_in)):
            a = np.asarray(a, float)
            if a.ndim == 2 and a.shape == (n, nnz):
                arrs.append((True, np.ascontiguousarray(a.T)))     # one contiguous row per nonzero
            elif a.size == nnz:
                arrs.append((False, [float(v) for v in a.ravel()]))
            else:
                raise ValueError(f"{self.function.name()}: argument {i}: expected shape ({n}, {nnz}) or "
                                 f"{nnz} shared values, got {a.shape}")
        outs = [np.empty((nnz, n)) for nnz in self._nnz_out]
        with np.errstate(all="ignore"):              # as CasADi: inf and NaN propagate silently
            for start in range(0, n, CHUNK):
                stop = min(start + CHUNK, n)
                cols = [[row[start:stop] for row in a] if per_point else a for per_point, a in arrs]
                self._run(cols, outs, start, stop)
        return outs

    def _run(self, cols, outs, start, stop):
        w = [0.0] * self._sz_w
        for ins in self._prog:
            kind = ins[0]
            if kind == 4:
                w[ins[1]] = ins[2](w[ins[3]], w[ins[4]])
            elif kind == 3:
                w[ins[1]] = ins[2](w[ins[3]])
            elif kind == 0:
                w[ins[1]] = cols[ins[2]][ins[3]]
            elif kind == 2:
                w[ins[1]] = ins[2]
            else:
                outs[ins[2]][ins[3], start:stop] = w[ins[1]]
