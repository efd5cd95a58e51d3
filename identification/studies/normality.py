"""Line 05 of Algorithm 1: the Shapiro-Wilk test of the differences of repeated series, per sensor.

tilde z_k = (z_{2,j,k} - z_{1,j,k}, z_{4,j,k} - z_{3,j,k}, ...)_{j = 1..n_q} (unit of z) is tested per
sensor k; the gate passes when every gated sensor has an adjusted p-value >= the level (multiplicity
correction over the gated sensors, below); the repeatability standard deviation of a sensor is
std(tilde z_k) / sqrt(2) (same unit as z).

The multiplicity correction of the gate: the gate tests every gated sensor with Shapiro-Wilk; m
uncorrected tests at level a reject Gaussian data with probability 1 - (1 - a)^m (15 % at m = 3, 64 % at
m = 20, 95 % at m = 60). The gate therefore controls its family-wise level a over the m gated sensors:

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

import dataclasses
import math
import re
from collections.abc import Mapping
from identification.vocabulary import renamed_arguments
from dataclasses import dataclass

import numpy as np
from scipy import stats

from identification.errors import DataError
from identification.results_protocol import ResultProtocol, jsonable, notes_lines
from identification.fit.measurements import Measurements

__all__ = ["NormalityCheck", "NormalityError", "normality_check", "series_text",
           "GATE_CORRECTIONS", "adjusted_pvalues", "gate_fails", "check_correction", "correction_text"]

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


class NormalityError(DataError):
    """Line 05 of Algorithm 1 failed: the differences of repeated series are not Gaussian.

    Attributes
    ----------
    check : NormalityCheck
    """

    def __init__(self, message: str, check: "NormalityCheck | None" = None):
        super().__init__(message)
        self.check = check


@dataclass(frozen=True)
class NormalityCheck(ResultProtocol):
    """Shapiro-Wilk test of z_{2m} - z_{2m-1} (m = 1..n_M/2, all inputs) per sensor (the result protocol:
    :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    sensors : tuple of str
    pvalue : ndarray (n_S,)        Shapiro-Wilk p-values (NaN when not computable)
    sigma_rep : ndarray (n_S,)     repeatability std(differences) / sqrt(2), unit of z
    n_diff : ndarray (n_S,)        number of differences used
    level : float                  family-wise level of the gate (per sensor with correction "none")
    gated : tuple of str           sensors whose result decides the gate (the selected sensors)
    passed : bool                  every gated sensor has an adjusted p-value >= level
    overridden : bool              the gate failed and normality="override" let the run continue
    pairs : tuple                  0-based series pairs (first, second) differenced
    note : str
    series : tuple of str          labels of the series the test ran on (``Measurements.series``)
    correction : str               multiplicity correction over the gated sensors ("holm", "bonferroni",
                                   "none"; the gate's correction above)
    adjusted : ndarray (n_S,)      adjusted p-values of the gated sensors (NaN for the others; derived)
    """

    sensors: tuple
    pvalue: np.ndarray
    sigma_rep: np.ndarray
    n_diff: np.ndarray
    level: float
    gated: tuple
    passed: bool
    overridden: bool = False
    pairs: tuple = ()
    note: str = ""
    series: tuple = ()
    correction: str = "none"
    adjusted: np.ndarray = dataclasses.field(default=None, compare=False)

    def __post_init__(self):
        gated = [s in self.gated for s in self.sensors]
        object.__setattr__(self, "adjusted", adjusted_pvalues(self.pvalue, check_correction(self.correction), gated))
        for name in ("pvalue", "sigma_rep", "n_diff", "adjusted"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def gate_text(self) -> str:
        """The gate in words: "Shapiro-Wilk at family-wise 5 % over 3 sensors (Holm)"."""
        return "Shapiro-Wilk at " + correction_text(self.correction, self.level, len(self.gated))

    def failing(self) -> tuple:
        """The gated sensors that fail the gate (adjusted p-value below the level, or none computable)."""
        return tuple(s for k, s in enumerate(self.sensors) if s in self.gated and not self.adjusted[k] >= self.level)

    def series_text(self) -> str:
        """The tested series as a reader names them: "5, 6", "1-6" or the labels ("" when unknown)."""
        return series_text(self.series)

    def pairs_text(self) -> str:
        """The differences formed, in series labels: "z6-z5" ("(none)" with fewer than two series)."""
        lab = (_series_numbers(self.series) or [f"({x})" for x in self.series]
               or [str(i + 1) for i in range(2 * len(self.pairs))])
        return ", ".join(f"z{lab[b]}-z{lab[a]}" for a, b in self.pairs) or "(none)"

    def table(self, units: Mapping | None = None, data_name: str = "series") -> str:
        """The per-sensor table: p-value (%), sigma_rep and its unit, number of differences, gate.

        ``units`` {sensor: (factor, unit)} shows sigma_rep as factor * sigma_rep in unit (default:
        the unit of z, unnamed); ``data_name`` names the data in the column headers (e.g. "study
        series"), so that the p-values say what they were computed on.
        """
        units = units or {}
        p_head, s_head = f"SW p % ({data_name})", f"sigma_rep ({data_name})"
        wp, ws = max(12, len(p_head)), max(11, len(s_head))
        adj = self.correction != "none"
        lines = [f"{'sensor':<10} {p_head:>{wp}} {s_head:>{ws}} {'unit':<8} {'n':>4}  "
                 + (f"{self.correction + ' p %':>14}  " if adj else "") + "gate"]
        bad = self.failing()
        for k, s in enumerate(self.sensors):
            pv = self.pvalue[k]
            factor, unit = units.get(s, (1.0, ""))
            ok = "" if s not in self.gated else ("FAIL" if s in bad else "pass")
            lines.append(f"{s:<10} {100 * pv:>{wp}.2f} {factor * self.sigma_rep[k]:>{ws}.4g} {unit or '-':<8} "
                         f"{int(self.n_diff[k]):>4}  " + (f"{100 * self.adjusted[k]:>14.2f}  " if adj else "") + ok)
        return "\n".join(lines)

    def summary(self, units: Mapping | None = None, data_name: str = "series") -> str:
        """The gate and its verdict, the per-sensor :meth:`table` and the note (numbered)."""
        status = "passed" if self.passed else ("FAILED, overridden by the user" if self.overridden else "FAILED")
        head = (f"Normality gate, {self.gate_text()} on the differences {self.pairs_text()} of the {data_name} "
                f"{self.series_text()}".rstrip() + f": {status}")
        return "\n".join([head, self.table(units, data_name)] + notes_lines([self.note] if self.note else []))

    def to_frame(self):
        """One row per sensor: Shapiro-Wilk p-value and adjusted p-value (in [0, 1]), sigma_rep (unit of z),
        the number of differences and the gate ("pass", "FAIL", "" for a sensor not gated); ``.attrs``: level,
        correction, passed."""
        import pandas as pd
        bad = self.failing()
        df = pd.DataFrame({"pvalue": self.pvalue, "pvalue_adjusted": self.adjusted, "sigma_rep": self.sigma_rep,
                           "n_diff": self.n_diff.astype(int),
                           "gate": ["" if s not in self.gated else ("FAIL" if s in bad else "pass")
                                    for s in self.sensors]},
                          index=pd.Index(list(self.sensors), name="sensor"))
        df.attrs.update(level=self.level, correction=self.correction, passed=self.passed, overridden=self.overridden)
        return df

    def to_dict(self, units: Mapping | None = None, data_name: str = "series") -> dict:
        """The check as JSON-safe values (what results.json holds): p-values, sigma_rep as factor * value in
        unit (``units`` {sensor: (factor, unit)}), the series it was computed on (named by ``data_name``)."""
        units = units or {}
        fu = [units.get(s, (1.0, "")) for s in self.sensors]
        return jsonable(dict(computed_on=f"{data_name} {self.series_text()}".strip(), series=list(self.series),
                             sensors=self.sensors, pvalue=self.pvalue,
                             sigma_rep=[f * v for (f, _), v in zip(fu, self.sigma_rep)],
                             sigma_rep_unit=[u for _, u in fu], passed=self.passed, overridden=self.overridden,
                             level=self.level, correction=self.correction, pvalue_adjusted=self.adjusted,
                             gated=list(self.gated), gate=self.gate_text(), note=self.note))


def _series_numbers(labels) -> list:
    """The trailing numbers of series labels sharing one prefix ("series_5" -> "5"), else []."""
    found = [re.fullmatch(r"(.*?)(\d+)", str(x)) for x in labels]
    if not found or not all(found) or len({f.group(1) for f in found}) != 1:
        return []
    return [f.group(2) for f in found]


def series_text(labels) -> str:
    """Series labels for a reader: consecutive numbers as a range ("1-6"), else a list ("5, 6")."""
    nums = _series_numbers(labels)
    if not nums:
        return ", ".join(str(x) for x in labels)
    ints = [int(n) for n in nums]
    if len(ints) > 2 and ints == list(range(ints[0], ints[0] + len(ints))):
        return f"{ints[0]}-{ints[-1]}"
    return ", ".join(nums)


@renamed_arguments(level="alpha")
def normality_check(data: Measurements, alpha: float = 0.05, weights=None,
                    correction: str = GATE_CORRECTIONS[0]) -> NormalityCheck:
    """Line 05: Shapiro-Wilk on the differences of pairs of series, per sensor, at a family-wise level alpha.

    tilde z_k = (z_{2,j,k} - z_{1,j,k}, z_{4,j,k} - z_{3,j,k}, ...)_{j = 1..n_q}; the pairs are
    consecutive series (an odd last series is left out).  Returns the p-values and the
    repeatability sigma std(tilde z_k) / sqrt(2) (unit of z); never raises on a failed test.
    The gate passes when every gated sensor (weight > 0) has an adjusted p-value >= ``alpha``;
    ``correction`` ("holm", "bonferroni" or "none", the paper's per-sensor gate) adjusts over the
    gated sensors (:func:`adjusted_pvalues`).
    """
    if not isinstance(data, Measurements):
        raise TypeError(f"data: expected an identification.Measurements, got {type(data).__name__}")
    check_correction(correction, "correction")
    w = data.sensor_weights(weights)
    n_pairs = data.n_M // 2
    pairs = tuple((2 * m, 2 * m + 1) for m in range(n_pairs))
    gated = tuple(s for s, wk in zip(data.sensors, w) if wk > 0)
    pv = np.full(data.n_S, np.nan)
    sig = np.full(data.n_S, np.nan)
    nd = np.zeros(data.n_S)
    notes = []
    if n_pairs == 0:
        return NormalityCheck(sensors=data.sensors, pvalue=pv, sigma_rep=sig, n_diff=nd, level=alpha, gated=gated,
                              passed=False, pairs=pairs,
                              note="only one series: differences of repeated series cannot be formed",
                              series=tuple(data.series), correction=correction)
    if data.n_M % 2:
        notes.append(f"series {data.n_M} (odd count) left out of the differences")
    for k in range(data.n_S):
        d = np.concatenate([data.z[b, :, k] - data.z[a, :, k] for a, b in pairs])
        d = d[np.isfinite(d)]
        nd[k] = d.size
        if d.size >= 2:
            sig[k] = float(np.std(d, ddof=1)) / math.sqrt(2.0)
        if d.size >= 3 and np.ptp(d) > 0:
            pv[k] = float(stats.shapiro(d).pvalue)
        else:
            notes.append(f"sensor {data.sensors[k]!r}: {d.size} differences"
                         + (" all equal" if d.size >= 3 else "") + "; Shapiro-Wilk not computable")
    chk = NormalityCheck(sensors=data.sensors, pvalue=pv, sigma_rep=sig, n_diff=nd, level=float(alpha), gated=gated,
                         passed=False, pairs=pairs,
                         note="; ".join(notes), series=tuple(data.series), correction=correction)
    return dataclasses.replace(chk, passed=not chk.failing())

