"""The labels every model shares and the checks of the model constructors' arguments.

:class:`Parameter` (an unknown with bounds, scale and unit), :class:`LabelledModel` (the names and
sizes common to the static :class:`models.Model` and :class:`models.dynamic.DynamicModel`),
:class:`ModelError`, and the conversion of what a user's callable returns into a CasADi column
vector.  Both model modules build on this one (it imports neither), and :mod:`models.contract`
re-exports its names.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

__all__ = ["Parameter", "LabelledModel", "ModelError", "as_parameters", "check_names", "as_column"]


class ModelError(ValueError):
    """A model definition is inconsistent (wrong dimension, bad name, bad bound)."""


@dataclass(frozen=True)
class Parameter:
    """An unknown model parameter.

    Parameters
    ----------
    name : str
        Identifier used in tables and error messages.
    lower, upper : float
        Bounds (``-inf``/``inf`` when absent).  The estimator enforces them.
    scale : float or None
        Typical magnitude (same unit as the parameter).  Used to scale the
        optimisation variable; ``None`` means "take it from the start value".
    unit : str
        Unit for reports, e.g. ``"N/mm"``.
    """

    name: str
    lower: float = -math.inf
    upper: float = math.inf
    scale: float | None = None
    unit: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ModelError(f"parameter name must be a non-empty string, got {self.name!r}")
        lo, up = float(self.lower), float(self.upper)
        if math.isnan(lo) or math.isnan(up):
            raise ModelError(f"parameter {self.name!r}: bounds must not be NaN")
        if lo > up:
            raise ModelError(f"parameter {self.name!r}: lower bound {lo} exceeds upper bound {up}")
        if self.scale is not None and not (np.isfinite(self.scale) and self.scale > 0):
            raise ModelError(f"parameter {self.name!r}: scale must be a positive finite number, got {self.scale!r}")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", up)


def as_parameters(params) -> tuple[Parameter, ...]:
    out = []
    for item in params:
        if isinstance(item, Parameter):
            out.append(item)
        elif isinstance(item, str):
            out.append(Parameter(item))
        elif isinstance(item, dict):
            out.append(Parameter(**item))
        else:
            raise ModelError(f"params: each entry must be a name, a dict or a Parameter, got {item!r}")
    return tuple(out)


def check_names(kind: str, names: Sequence[str]) -> tuple[str, ...]:
    names = tuple(names)
    for n in names:
        if not isinstance(n, str) or not n:
            raise ModelError(f"{kind}: every name must be a non-empty string, got {n!r}")
    seen = set()
    for n in names:
        if n in seen:
            raise ModelError(f"{kind}: name {n!r} appears twice")
        seen.add(n)
    return names


def _stacked(items, what: str, symbolic):
    """The column ``vertcat(items)`` of a list or tuple of scalars: numbers, NumPy scalars or 1x1
    CasADi expressions of the model's symbolic type (``symbolic``: ca.SX or ca.MX).

    Raises ModelError naming the entry that is not a scalar of that type.
    """
    parts = []
    for k, e in enumerate(items):
        if isinstance(e, (ca.DM, symbolic)) or (isinstance(e, np.ndarray) and e.dtype.kind in "biuf"):
            if int(np.prod(e.shape)) != 1:
                raise ModelError(f"{what}: entry {k} of the returned {type(items).__name__} has shape {tuple(e.shape)}; "
                                 "a list may hold scalars only (return ca.vertcat(...) for vectors)")
            if isinstance(e, np.ndarray):
                e = float(e.reshape(-1)[0])
            parts.append(e if isinstance(e, symbolic) else symbolic(e))
        elif isinstance(e, (int, float, np.integer, np.floating)) and not isinstance(e, bool):
            parts.append(symbolic(float(e)))
        else:
            raise ModelError(f"{what}: entry {k} of the returned {type(items).__name__} is a {type(e).__name__}; "
                             f"expected a scalar ca.{symbolic.__name__} expression or a number")
    return ca.vertcat(*parts) if parts else symbolic(0, 1)


def as_column(expr, what: str, symbolic):
    """Turn what a user callable returned into a CasADi column vector (a list of scalars is stacked)."""
    if isinstance(expr, (list, tuple)):
        expr = _stacked(expr, what, symbolic)
    elif isinstance(expr, (int, float, np.ndarray)):
        expr = symbolic(expr)
    elif not isinstance(expr, (ca.SX, ca.MX, ca.DM)):
        raise ModelError(f"{what} must return a CasADi expression, a list of them or an array, got {type(expr).__name__}")
    if expr.is_empty():
        return symbolic(0, 1)
    if expr.size2() != 1:
        if expr.size1() == 1:
            expr = expr.T
        else:
            raise ModelError(f"{what} must return a vector, got shape {expr.shape}")
    return expr



class LabelledModel:
    """The labels every model shares (static :class:`models.Model`, :class:`models.dynamic.DynamicModel`):
    ``params`` (Parameter tuple), ``inputs`` (names of one input row) and ``sensors`` (names)."""

    @property
    def n_p(self) -> int:
        return len(self.params)

    @property
    def n_S(self) -> int:
        return len(self.sensors)

    @property
    def n_q_dim(self) -> int:
        """Length d_q of one input row q."""
        return len(self.inputs)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)
