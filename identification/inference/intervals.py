"""Marginal confidence intervals: one result type whatever the method, and the shared argument checks.

A :class:`ConfidenceIntervals` holds (1 - alpha) intervals [lower, upper] of selected parameters
from the Wald approximation p_i -+ c se_i, the profile likelihood 2 (min_{p_i = theta} Phi -
Phi(p_hat)) <= c or the parametric bootstrap; ``np.asarray(ci)`` is the (m, 2) array and
``ci.to_frame()`` a pandas DataFrame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from identification.results_protocol import ResultProtocol, jsonable, notes_lines

__all__ = ["ConfidenceIntervals", "validate_alpha", "resolve_params", "profile_threshold", "region_threshold"]


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def validate_alpha(alpha) -> float:
    """alpha as a float in (0, 0.5); anything else raises ValueError naming the argument."""
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise ValueError(f"alpha: expected a number in (0, 0.5), got {alpha!r}") from None
    if not (0.0 < a < 0.5):
        raise ValueError(f"alpha: must lie in (0, 0.5), got {alpha!r}; alpha is the miss probability: "
                         "0.05 gives a 95 % interval")
    return a


def resolve_params(params, names: tuple) -> list:
    """Indices of ``params`` (None: all; names or 0-based indices) in ``names``."""
    if params is None:
        return list(range(len(names)))
    if isinstance(params, (str, int, np.integer)):
        params = [params]
    idx = []
    for q in params:
        if isinstance(q, (int, np.integer)) and not isinstance(q, bool):
            if not 0 <= int(q) < len(names):
                raise ValueError(f"params: index {q} out of range; the parameters are {', '.join(names)}")
            idx.append(int(q))
        elif isinstance(q, str) and q in names:
            idx.append(names.index(q))
        else:
            raise ValueError(f"params: unknown parameter {q!r}; the parameters are {', '.join(names)}")
    if len(set(idx)) != len(idx):
        raise ValueError(f"params: a parameter is named twice in {list(params)}")
    return idx


def profile_threshold(alpha: float, sigma_estimated: bool, dof: int) -> float:
    """c of a single-parameter profile: chi2_1(1 - alpha), or F(1, dof; 1 - alpha) when sigma was estimated."""
    if sigma_estimated:
        return float(stats.f.ppf(1 - alpha, 1, dof))
    return float(stats.chi2.ppf(1 - alpha, 1))


def region_threshold(alpha: float, sigma_estimated: bool, dof: int) -> float:
    """c of a two-parameter region: chi2_2(1 - alpha), or 2 F(2, dof; 1 - alpha) when sigma was estimated."""
    if sigma_estimated:
        return 2.0 * float(stats.f.ppf(1 - alpha, 2, dof))
    return float(stats.chi2.ppf(1 - alpha, 2))



@dataclass(frozen=True)
class ConfidenceIntervals(ResultProtocol):
    """Marginal (1 - alpha) confidence intervals of selected parameters (the result protocol: :meth:`summary`,
    :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    param_names : tuple of str     the selected parameters
    estimate : ndarray (m,)        their estimates
    lower, upper : ndarray (m,)    interval ends (same unit as the parameter; +-inf: unbounded side)
    method : str                   "wald", "profile" or "bootstrap"
    alpha : float                  miss probability
    notes : tuple of str           unbounded sides, failed refits, fallbacks
    profiles : tuple               ParameterProfile per parameter (method "profile")
    replicates : ndarray (k, n_p)  successful bootstrap estimates (method "bootstrap")
    n_failed : int                 failed bootstrap refits (counted, excluded from the percentiles)
    fallbacks : tuple of (int, str)   bootstrap refits the batch engine left to identify (replicate, why)
    """

    param_names: tuple
    estimate: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    method: str
    alpha: float
    notes: tuple = ()
    profiles: tuple = ()
    replicates: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    n_failed: int = 0
    fallbacks: tuple = ()

    def __post_init__(self):
        for name in ("estimate", "lower", "upper", "replicates"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))

    @property
    def array(self) -> np.ndarray:
        """(m, 2) read-only array of [lower, upper] rows."""
        return _readonly(np.column_stack([self.lower, self.upper]))

    def __array__(self, dtype=None, copy=None):
        """``np.asarray(ci)``: the (m, 2) array of [lower, upper] rows."""
        a = np.column_stack([self.lower, self.upper])
        return a if dtype is None else a.astype(dtype)

    def __len__(self) -> int:
        return len(self.param_names)

    def to_frame(self):
        """A pandas DataFrame indexed by parameter: estimate, lower, upper (the method and alpha in ``.attrs``)."""
        import pandas as pd
        df = pd.DataFrame({"estimate": self.estimate, "lower": self.lower, "upper": self.upper},
                          index=pd.Index(self.param_names, name="parameter"))
        df.attrs.update(method=self.method, alpha=self.alpha, notes=self.notes)
        return df

    def _repr_html_(self) -> str:
        return self.to_frame().to_html(float_format=lambda v: f"{v:.7g}")

    def __getitem__(self, key):
        """(lower, upper) of a parameter by name; an integer or a tuple index reads the (m, 2) array
        (``ci[i, 0]`` is the lower end of the i-th interval)."""
        if not isinstance(key, str):
            return self.array[key]
        name = key
        if name not in self.param_names:
            raise KeyError(f"unknown parameter {name!r}; the intervals are of {', '.join(self.param_names)}")
        i = self.param_names.index(name)
        return float(self.lower[i]), float(self.upper[i])

    def __str__(self):
        pct = f"{100 * (1 - self.alpha):g} %"
        lines = [f"{pct} {self.method} intervals"]
        for n, e, lo, up in zip(self.param_names, self.estimate, self.lower, self.upper):
            lines.append(f"  {n}: {e:.7g} in [{lo:.7g}, {up:.7g}]")
        lines += [f"  [{k}] {note}" for k, note in enumerate(self.notes, 1)]
        return "\n".join(lines)

    def summary(self) -> str:
        """A table of the estimates and the interval ends per parameter, ending with the numbered notes."""
        w = max(9, max((len(n) for n in self.param_names), default=0))
        pct = f"{100 * (1 - self.alpha):g} %"
        lines = [f"{pct} {self.method} confidence intervals" + (f" ({len(self.replicates)} bootstrap refits, "
                                                                 f"{self.n_failed} failed)"
                                                                 if self.method == "bootstrap" else ""),
                 "", f"{'parameter':<{w}} {'estimate':>14} {'lower':>14} {'upper':>14}"]
        lines += [f"{n:<{w}} {e:>14.7g} {lo:>14.7g} {up:>14.7g}"
                  for n, e, lo, up in zip(self.param_names, self.estimate, self.lower, self.upper)]
        return "\n".join(lines + notes_lines(self.notes))

    def to_dict(self) -> dict:
        """The intervals as JSON-safe values: method, alpha, params, estimate, lower, upper (an unbounded side
        as "-inf" / "inf"), notes, n_failed and fallbacks (bootstrap); the profiles and the replicates are left
        out (``profiles``, ``replicates`` on the object)."""
        return jsonable(dict(method=self.method, alpha=self.alpha, params=list(self.param_names),
                             estimate=self.estimate, lower=self.lower, upper=self.upper, notes=list(self.notes),
                             n_failed=self.n_failed, fallbacks=list(self.fallbacks)))
