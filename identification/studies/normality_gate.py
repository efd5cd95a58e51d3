"""The multiplicity correction of the normality gate (Algorithm 1, line 05).

The gate tests every gated sensor with Shapiro-Wilk; m uncorrected tests at level a reject
Gaussian data with probability 1 - (1 - a)^m (15 % at m = 3, 64 % at m = 20, 95 % at m = 60).
The gate therefore controls its family-wise level a over the m gated sensors:

- ``"holm"`` (default): Holm's step-down adjusted p-values
  p~_(i) = max_{k <= i} min(1, (m - k + 1) p_(k)) (p_(1) <= ... <= p_(m));
- ``"bonferroni"``: p~_k = min(1, m p_k);
- ``"none"``: p~_k = p_k, the paper's per-sensor gate (family-wise level 1 - (1 - a)^m).

The gate fails when some gated sensor has p~_k < a or no p-value (NaN: not computable).
Holm and Bonferroni fail the gate for exactly the same data (both fail it when the smallest
p-value is below a / m); Holm flags at least as many sensors as Bonferroni, never more than the
uncorrected gate.  One function serves :func:`identification.studies.detect.normality_check` and the
batched gate of :mod:`identification.studies.montecarlo`, so that both apply the same correction.
"""
from __future__ import annotations

import numpy as np

__all__ = ["GATE_CORRECTIONS", "adjusted_pvalues", "gate_fails", "check_correction", "correction_text"]

#: the gate's multiplicity corrections (the first is the default)
GATE_CORRECTIONS = ("holm", "bonferroni", "none")


def check_correction(correction: str, name: str = "normality_correction") -> str:
    """``correction`` if it is one of :data:`GATE_CORRECTIONS`, else ValueError naming ``name``."""
    if correction not in GATE_CORRECTIONS:
        raise ValueError(f"{name}: expected one of {GATE_CORRECTIONS}, got {correction!r}")
    return correction


def adjusted_pvalues(p, correction: str = "holm", gated=None) -> np.ndarray:
    """p~ = the p-values adjusted over the gated sensors, along the last axis.

    Parameters
    ----------
    p : array_like (..., n_S)       p-values (NaN: not computable; counted in m, ranked last)
    correction : {"holm", "bonferroni", "none"}
    gated : array_like of bool (n_S,) or None   the sensors of the family (None: all)

    Returns
    -------
    ndarray (..., n_S)  adjusted p-values in [0, 1] on the gated sensors, NaN elsewhere and where p is NaN
    """
    check_correction(correction, "correction")
    p = np.asarray(p, float)
    g = np.ones(p.shape[-1], bool) if gated is None else np.asarray(gated, bool).ravel()
    if g.shape != (p.shape[-1],):
        raise ValueError(f"gated: expected {p.shape[-1]} flags, got {g.size}")
    out = np.full(p.shape, np.nan)
    sub = p[..., g]
    m = sub.shape[-1]
    if m == 0:
        return out
    if correction == "none":
        adj = sub.copy()
    elif correction == "bonferroni":
        adj = np.minimum(1.0, m * sub)
    else:
        order = np.argsort(np.where(np.isnan(sub), np.inf, sub), axis=-1, kind="stable")
        ps = np.take_along_axis(sub, order, axis=-1)
        steps = np.minimum(1.0, (m - np.arange(m)) * np.where(np.isnan(ps), 1.0, ps))
        run = np.maximum.accumulate(steps, axis=-1)
        run = np.where(np.isnan(ps), np.nan, run)
        adj = np.empty_like(run)
        np.put_along_axis(adj, order, run, axis=-1)
    out[..., g] = adj
    return out


def gate_fails(p, level: float, correction: str = "holm", gated=None) -> np.ndarray:
    """Whether the gate fails: some gated sensor has p~_k < ``level`` or p_k NaN (bool, shape p.shape[:-1]).

    A family without gated sensors never fails.
    """
    p = np.asarray(p, float)
    adj = adjusted_pvalues(p, correction, gated)
    g = np.ones(p.shape[-1], bool) if gated is None else np.asarray(gated, bool).ravel()
    sub = adj[..., g]
    return np.any(~(sub >= level), axis=-1)


def correction_text(correction: str, level: float, n_gated: int) -> str:
    """The gate in words: "family-wise 5 % over 3 sensors (Holm)" or "5 % per sensor, no correction"."""
    check_correction(correction, "correction")
    if correction == "none":
        return f"{100 * level:g} % per sensor, no multiplicity correction"
    plural = "s" if n_gated != 1 else ""
    return f"family-wise {100 * level:g} % over {n_gated} sensor{plural} ({correction.capitalize()})"
