r"""Detection of model uncertainty: the paper's Algorithm 1 (lines 01-17), with a calibrated statistic.

For every split (calibration set, validation set) the parameters are identified twice,
p_cal with covariance C_cal and p_val with C_val (paper eqs. 3 and 7), and tested with

.. math::

    \text{paper (line 08):}\quad
    \alpha_\min = 1 - F_{\chi^2_{n_p}}\big((p_v - p_c)^\top C_c^{-1} (p_v - p_c)\big),

    \text{two-sample Wald:}\quad
    \alpha_\min^{(2)} = 1 - F_{\chi^2_{n_p}}\big((p_v - p_c)^\top (C_c + C_v)^{-1} (p_v - p_c)\big),

    \text{likelihood ratio (default):}\quad
    \alpha_\min^{(LR)} = 1 - F_{\chi^2_{n_p}}\big(2\,[\Phi_{c\cup v}(\hat p_{c\cup v})
        - \Phi_c(p_c) - \Phi_v(p_v)]\big),

with Phi = 1/2 sum w r^2 / sigma^2 the objective of eq. 3 on a set and p_{c u v} the fit of
calibration and validation data together (the null hypothesis "one parameter explains
both").  With sigma unknown the likelihood ratio becomes the F (Chow) test
((RSS_{cuv} - RSS_c - RSS_v) / n_p) / ((RSS_c + RSS_v) / (n_c + n_v - 2 n_p)).

The calibration and validation sets hold disjoint data points, so under a correct model
p_v - p_c has covariance C_c + C_v; the paper's statistic ignores C_v and, for sets of
equal size, is about twice a chi^2_{n_p} variable, which inflates its size (measured by
:mod:`identification.studies.montecarlo`).  The two-sample Wald statistic is exact for models
linear in p but, like every Wald test, depends on the parametrisation: for the press,
whose displacements are nearly linear in the compliances 1/k rather than in k, it is
conservative (family-wise size 2.95 % at TOL = 5 %).  The likelihood ratio is invariant
under reparametrisation, equals the two-sample Wald statistic for linear models, and is
calibrated on the press (see ``bench/RESULTS.md``), so it is the default.  A model is rejected when some split has
alpha_min < TOL / n_tests (Bonferroni, lines 09-16); Holm's step-down procedure is
reported alongside (its model-level decision coincides with Bonferroni's, since both
reject the family exactly when the smallest p-value is below TOL / n_tests; they differ
in which individual splits are flagged).

When a fit of a split is not trustworthy (Bates-Watts curvature, :mod:`identification.inference.curvature`;
checked by :func:`detect`), its Wald p-values (two-sample, paper) rest on a linearisation that
fails: they are marked in the summary and the verdict is taken from the likelihood ratio
(invariant under reparametrisation) whatever ``statistic`` was chosen, saying so.  Statistics
that disagree by more than a factor 100 across the decision line get a numbered note.

Line 05 (normality gate): Shapiro-Wilk test, per sensor, of the differences of pairs of
series z_2 - z_1, z_4 - z_3, ... over all inputs, at the family-wise level over the gated
sensors (Holm by default; :mod:`identification.studies.normality_gate`); the repeatability standard deviation
of a sensor is std(differences) / sqrt(2) (same unit as z).
"""
from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Sequence

import numpy as np
from scipy import special, stats

from models.contract import Model
from identification.errors import DataError, IdentificationError
from identification.fit.estimator import IdentifySettings
from identification.inference.identify import identify
from identification.fit.measurements import Measurements
from identification.studies.normality_gate import GATE_CORRECTIONS, adjusted_pvalues, check_correction, correction_text
from identification.progress import Progress
from identification.inference.regions import CovarianceError, mahalanobis2
from identification.studies.splits import Split, SplitError
from identification.fit.unbounded import not_bounded_reason
from models.state import solve_states

__all__ = ["detect", "DetectSettings", "DetectionResult", "SplitTest", "ModelDecision", "NormalityCheck",
           "NormalityError", "normality_check", "run_split_tests", "decide", "STATISTICS", "CORRECTIONS",
           "DEFAULT_STATISTIC"]

STATISTICS = ("likelihood_ratio", "two_sample", "paper")
#: the statistic that decides unless the user chooses another (all are always reported)
DEFAULT_STATISTIC = "likelihood_ratio"
_ALPHA_FIELDS = {"likelihood_ratio": "alpha_lr", "two_sample": "alpha_two_sample", "paper": "alpha_paper"}


def alpha_field(statistic: str) -> str:
    """Name of the attribute holding a statistic's alpha_min (SplitTest, MonteCarloResult)."""
    try:
        return _ALPHA_FIELDS[statistic]
    except (KeyError, TypeError):
        raise ValueError(f"statistic: expected one of {STATISTICS}, got {statistic!r}") from None
CORRECTIONS = ("bonferroni", "holm")


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
class DetectSettings:
    """Settings of :func:`detect` (defaults follow the paper, with the calibrated statistic).

    Attributes
    ----------
    tol : float                family-wise test level TOL in (0, 1) (paper: 5 %)
    statistic : str            "likelihood_ratio" (default), "two_sample" (Wald, C_cal + C_val) or
                               "paper" (Wald, C_cal only)
    correction : str           "bonferroni" (paper) or "holm"
    normality : str            "check" (raise NormalityError on failure) or "override" (record only)
    normality_level : float    family-wise level of the Shapiro-Wilk gate (paper: 5 % per sensor)
    normality_correction : str "holm" (default), "bonferroni" or "none" (the paper's per-sensor gate,
                               family-wise level 1 - (1 - level)^m over m sensors)
    covariance : str           "second_order" (paper eq. 7) or "gauss_newton"
    identify : IdentifySettings | None  passed to identify()
    """

    tol: float = 0.05
    statistic: str = DEFAULT_STATISTIC
    correction: str = "bonferroni"
    normality: str = "check"
    normality_level: float = 0.05
    normality_correction: str = GATE_CORRECTIONS[0]
    covariance: str = "second_order"
    identify: IdentifySettings | None = None

    def __post_init__(self):
        tol = float(self.tol) if isinstance(self.tol, (int, float, np.floating)) else float("nan")
        if not (0.0 < tol < 1.0):
            raise ValueError(f"tol: the test level TOL must lie in (0, 1), got {self.tol!r}")
        if self.statistic not in STATISTICS:
            raise ValueError(f"statistic: expected one of {STATISTICS}, got {self.statistic!r}")
        if self.correction not in CORRECTIONS:
            raise ValueError(f"correction: expected one of {CORRECTIONS}, got {self.correction!r}")
        if self.normality not in ("check", "override"):
            raise ValueError(f"normality: expected 'check' or 'override', got {self.normality!r}")
        if not (0.0 < float(self.normality_level) < 1.0):
            raise ValueError(f"normality_level: must lie in (0, 1), got {self.normality_level!r}")
        check_correction(self.normality_correction)
        if self.covariance not in ("second_order", "gauss_newton"):
            raise ValueError(f"covariance: expected 'second_order' or 'gauss_newton', got {self.covariance!r}")
        object.__setattr__(self, "tol", tol)


# ---------------------------------------------------------------------------- normality (line 05)
@dataclass(frozen=True)
class NormalityCheck:
    """Shapiro-Wilk test of z_{2m} - z_{2m-1} (m = 1..n_M/2, all inputs) per sensor.

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
                                   "none"; :mod:`identification.studies.normality_gate`)
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


def normality_check(data: Measurements, level: float = 0.05, weights=None,
                    correction: str = GATE_CORRECTIONS[0]) -> NormalityCheck:
    """Line 05: Shapiro-Wilk on the differences of pairs of series, per sensor, at a family-wise level.

    tilde z_k = (z_{2,j,k} - z_{1,j,k}, z_{4,j,k} - z_{3,j,k}, ...)_{j = 1..n_q}; the pairs are
    consecutive series (an odd last series is left out).  Returns the p-values and the
    repeatability sigma std(tilde z_k) / sqrt(2) (unit of z); never raises on a failed test.
    The gate passes when every gated sensor (weight > 0) has an adjusted p-value >= ``level``;
    ``correction`` ("holm", "bonferroni" or "none", the paper's per-sensor gate) adjusts over the
    gated sensors (:func:`identification.studies.normality_gate.adjusted_pvalues`).
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
        return NormalityCheck(data.sensors, pv, sig, nd, level, gated, False, pairs=pairs,
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
    chk = NormalityCheck(data.sensors, pv, sig, nd, float(level), gated, False, pairs=pairs,
                         note="; ".join(notes), series=tuple(data.series), correction=correction)
    return dataclasses.replace(chk, passed=not chk.failing())


# ---------------------------------------------------------------------------- one split
@dataclass(frozen=True, eq=False)
class SplitTest:
    """The fits of one split (calibration, validation, pooled) and the three statistics.

    Attributes
    ----------
    model, split : str
    cal_label, val_label : str     1-based input labels (as the paper's table)
    ok : bool                      both fits and the Wald statistics were computed (alpha_lr may still be NaN)
    stage, error : str             where and why it failed ("" when ok)
    p_cal, p_val : ndarray (n_p,)  estimates (NaN if the fit failed)
    C_cal, C_val : ndarray         covariances (NaN if the fit failed)
    d2_paper, d2_two_sample : float  (p_val - p_cal)^T C^{-1} (p_val - p_cal) (chi^2 units)
    alpha_paper, alpha_two_sample : float  p-values alpha_min (NaN if not computed)
    n_cal, n_val : int             number of values used by each fit
    notes : tuple of str           estimator notes of the fits
    lr : float                     likelihood-ratio statistic 2 (Phi_pooled - Phi_cal - Phi_val) (chi^2 units),
                                   or the F statistic when sigma is estimated
    alpha_lr : float               its p-value (NaN when the pooled fit failed; see lr_error)
    lr_error : str                 why the likelihood ratio is missing ("" when computed)
    trustworthy : bool or None     both fits' linearisations trustworthy (Bates-Watts curvature);
                                   None when not checked (run_split_tests(curvature=False)) or not computable
    curvature_note : str           which fit is not trustworthy and its curvatures ("" otherwise)
    """

    model: str
    split: str
    cal_label: str
    val_label: str
    ok: bool
    stage: str
    error: str
    p_cal: np.ndarray
    p_val: np.ndarray
    C_cal: np.ndarray
    C_val: np.ndarray
    d2_paper: float
    d2_two_sample: float
    alpha_paper: float
    alpha_two_sample: float
    n_cal: int = 0
    n_val: int = 0
    notes: tuple = ()
    lr: float = math.nan
    alpha_lr: float = math.nan
    lr_error: str = ""
    trustworthy: bool | None = None
    curvature_note: str = ""

    def __post_init__(self):
        for name in ("p_cal", "p_val", "C_cal", "C_val"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def alpha(self, statistic: str) -> float:
        """alpha_min of one statistic (NaN when it could not be computed)."""
        return getattr(self, alpha_field(statistic))


def _failed(model_name, split, stage, msg, n_p, p_cal=None, C_cal=None, n_cal=0, notes=()):
    nanv, nanm = np.full(n_p, np.nan), np.full((n_p, n_p), np.nan)
    c, v = split.label()
    return SplitTest(model_name, split.name, c, v, False, stage, msg,
                     nanv if p_cal is None else p_cal, nanv, nanm if C_cal is None else C_cal, nanm,
                     math.nan, math.nan, math.nan, math.nan, n_cal, 0, tuple(notes))


def _fit(model, data, p0, weights, settings, Y0=None, given=None):
    if isinstance(given, Exception):
        raise given
    est = identify(model, data, p0, weights=weights, settings=settings.identify, Y0=Y0) if given is None else given
    C = est.cov if settings.covariance == "second_order" else est.cov_gn
    return est, C


def _linearisation(est_c, est_v) -> tuple:
    """(trustworthy, note) of a split from the Bates-Watts curvature of its two fits; trustworthy is
    None when a curvature cannot be computed (no dof, rank-deficient sensitivities)."""
    verdicts, bad = [], []
    for label, est in (("calibration", est_c), ("validation", est_v)):
        if est.dof < 1:
            verdicts.append(None)
            continue
        try:
            c = est.curvature
        except (np.linalg.LinAlgError, ValueError):
            verdicts.append(None)
            continue
        verdicts.append(c.trustworthy)
        if not c.trustworthy:
            bad.append(f"{label} fit: intrinsic {c.intrinsic:.3g}, parameter-effects {c.parameter_effects:.3g} "
                       f"vs critical {c.critical:.3g}")
    if bad:
        return False, "; ".join(bad)
    return (None if None in verdicts else True), ""


def _counted(items, bar):
    """Yield every item, then advance ``bar`` (a tqdm bar or None) by one when its loop body is done."""
    for item in items:
        yield item
        if bar is not None:
            bar.update(1)


def run_split_tests(model: Model, data: Measurements, splits: Sequence[Split], p0, weights=None,
                    settings: DetectSettings | None = None, model_name: str | None = None,
                    states0=None, curvature: bool = False, bar=None, fits=None, pooled=None) -> tuple:
    """Lines 06-08 for every split: fits (p_cal, C_cal), (p_val, C_val), the pooled fit and the
    three alpha_min (likelihood ratio, two-sample Wald, paper).

    With ``curvature`` the Bates-Watts curvature of both fits is checked
    (:attr:`SplitTest.trustworthy`; :func:`detect` does; Monte Carlo studies skip it for speed).

    A failed fit or a singular covariance is recorded in its :class:`SplitTest` (``ok=False``,
    with the stage and the reason), never dropped and never raised.  A fit whose data do not bound
    the parameters (``Estimate.bounded`` False: the best fit runs off to infinity) has no estimate to
    test: its split fails at that fit with the reason "not bounded: ..." (the verdict is "undecided"
    unless another split rejects); a pooled fit that is not bounded leaves the likelihood ratio out
    with that reason.  ``states0`` (n_q, n_y),
    the states at p0 for every input of ``data``, warm-starts the fits (same result, faster).
    ``bar`` (a tqdm bar, e.g. from :meth:`identification.progress.Progress.bar`) is advanced by
    one per split done.

    ``fits`` (one (calibration, validation) pair per split) and ``pooled`` ({split.pooled_key:
    pooled fit}) give fits computed elsewhere (e.g. by :func:`identification.fit.batch.fit_batch` for
    many replications at once): an entry is an estimate (the fields of :class:`Estimate` the tests
    read), the IdentificationError/DataError its fit raised, or (pooled) a failure text.
    """
    settings = settings or DetectSettings()
    name = model_name or model.name
    n_sel = int(np.count_nonzero(data.sensor_weights(weights) > 0))
    out = []
    pooled = {} if pooled is None else dict(pooled)
    for js, split in enumerate(_counted(splits, bar)):
        given = (None, None) if fits is None else fits[js]
        try:
            split.check(data.n_q, data.n_M, model.n_p, n_sel)
        except SplitError as exc:
            out.append(_failed(name, split, "split", str(exc), model.n_p))
            continue
        try:
            est_c, C_c = _fit(model, split.calibration(data) if given[0] is None else None, p0, weights, settings,
                              None if states0 is None else states0[list(split.cal_inputs)], given[0])
        except (IdentificationError, DataError) as exc:
            out.append(_failed(name, split, "calibration fit", f"{type(exc).__name__}: {exc}", model.n_p))
            continue
        if not_bounded_reason(est_c):        # the data of this set do not bound p: no estimate to test
            out.append(_failed(name, split, "calibration fit", not_bounded_reason(est_c), model.n_p,
                               n_cal=est_c.n_data, notes=est_c.notes))
            continue
        try:
            est_v, C_v = _fit(model, split.validation(data) if given[1] is None else None, p0, weights, settings,
                              None if states0 is None else states0[list(split.val_inputs)], given[1])
        except (IdentificationError, DataError) as exc:
            out.append(_failed(name, split, "validation fit", f"{type(exc).__name__}: {exc}", model.n_p,
                               est_c.p, C_c, est_c.n_data, est_c.notes))
            continue
        if not_bounded_reason(est_v):
            out.append(_failed(name, split, "validation fit", not_bounded_reason(est_v), model.n_p,
                               est_c.p, C_c, est_c.n_data, est_c.notes))
            continue
        notes = tuple(f"calibration fit: {n}" for n in est_c.notes) + tuple(f"validation fit: {n}" for n in est_v.notes)
        c, v = split.label()
        try:
            d2p = mahalanobis2(est_v.p, est_c.p, C_c, "C_cal")
            d2t = mahalanobis2(est_v.p, est_c.p, C_c + C_v, "C_cal + C_val")
        except CovarianceError as exc:
            out.append(SplitTest(name, split.name, c, v, False, "statistic", f"CovarianceError: {exc}", est_c.p,
                                 est_v.p, C_c, C_v, math.nan, math.nan, math.nan, math.nan, est_c.n_data,
                                 est_v.n_data, notes))
            continue
        n_p = model.n_p
        lr, a_lr, lr_err = _likelihood_ratio(model, data, split, p0, weights, settings, states0, est_c, est_v,
                                             pooled)
        trust, cnote = _linearisation(est_c, est_v) if curvature else (None, "")
        out.append(SplitTest(name, split.name, c, v, True, "", "", est_c.p, est_v.p, C_c, C_v, d2p, d2t,
                             float(special.chdtrc(n_p, d2p)), float(special.chdtrc(n_p, d2t)),
                             est_c.n_data, est_v.n_data, notes, lr, a_lr, lr_err, trust, cnote))
    return tuple(out)


@dataclass(frozen=True)
class _PooledMinimum:
    p: np.ndarray
    objective: float
    rss: float
    steps: int


def _pooled_newton(model, data_u, split, est_c, est_v, weights, max_steps: int = 8):
    r"""min_p Phi_cal(p) + Phi_val(p) by exact reduced-space Newton, or None.

    Starts at the precision-weighted mean p_bar = (F_c + F_v)^{-1} (F_c p_c + F_v p_v) of the
    two estimates (within O(|p_v - p_c|^2) of the pooled optimum) with the states of the two
    fits, and takes the estimator's own exact Newton steps (J^T W J + S, see
    :func:`identification.fit.refinement.refine`).  The result is used only when the Newton decrement
    g^T H^{-1} g < 1e-12 (chi^2 units: within 1e-6 standard errors of the optimum); otherwise
    (None) the caller runs the full-space :func:`identify` on the pooled data.
    """
    from identification.errors import StateSolveError
    from identification.fit.refinement import ReducedProblem, refine
    w = data_u.sensor_weights(weights)
    sig = (np.asarray(data_u.sigma, float) if data_u.sigma is not None
           else np.full(model.n_S, float(np.sqrt(est_c.rss / max(est_c.n_data, 1))) or 1.0))
    Fc, Fv = est_c.information, est_v.information
    try:
        p = np.linalg.solve(Fc + Fv, Fc @ est_c.p + Fv @ est_v.p)
    except np.linalg.LinAlgError:
        return None
    if not (np.all(p > model.lower) and np.all(p < model.upper)):
        return None
    qs_c, qs_v = list(split.cal_inputs), list(split.val_inputs)
    qs = sorted(set(qs_c) | set(qs_v))
    Y = np.empty((len(qs), model.n_y))
    for j_list, est in ((qs_c, est_c), (qs_v, est_v)):
        if est.states is None or est.states.shape[0] != len(j_list):
            return None
        for r, j in enumerate(j_list):
            Y[qs.index(j)] = est.states[r]
    problem = ReducedProblem.of(model, data_u, w, sig, np.where(np.abs(p) > 0, np.abs(p), 1.0))
    try:
        ref = refine(problem, problem.evaluate(p, Y), max_steps, stop_decrement=1e-12)
    except (StateSolveError, IdentificationError):
        return None
    if not ref.decrement < 1e-12:
        return None
    resid = data_u.z - ref.point.sens.h[None]
    return _PooledMinimum(ref.point.p, ref.point.objective, float(np.nansum(resid[:, :, w > 0] ** 2)), ref.steps)


def _likelihood_ratio(model, data, split, p0, weights, settings, states0, est_c, est_v, pooled):
    """(statistic, p-value, error) of the likelihood-ratio test of one split.

    The pooled fit (calibration and validation data together) is shared by splits with the
    same pooled points (``pooled`` caches it).  Since the point sets are disjoint,
    Phi_pooled(p) = Phi_cal(p) + Phi_val(p) >= Phi_cal(p_cal) + Phi_val(p_val) at every p, so
    the statistic is >= 0 up to the solver tolerance; a clearly negative value means a fit
    missed its optimum and is reported instead of used.
    """
    key = split.pooled_key(data.n_M)
    est_u = pooled.get(key)
    if est_u is None:
        qs = sorted({j for j, _ in split.pooled_points(data.n_M)})
        data_u = split.pooled(data)
        est_u = _pooled_newton(model, data_u, split, est_c, est_v, weights)
        if est_u is None:
            try:
                est_u = identify(model, data_u, p0, weights=weights, settings=settings.identify,
                                 Y0=None if states0 is None else states0[qs])
            except (IdentificationError, DataError) as exc:
                est_u = f"pooled fit failed: {type(exc).__name__}: {exc}"
            if not_bounded_reason(est_u):
                est_u = f"pooled fit {not_bounded_reason(est_u)}"
        pooled[key] = est_u
    if isinstance(est_u, str):
        return math.nan, math.nan, est_u
    n_p = model.n_p
    if est_c.sigma_estimated:
        dof = est_c.n_data + est_v.n_data - 2 * n_p
        rss_sep = est_c.rss + est_v.rss
        num = est_u.rss - rss_sep
        if dof <= 0 or not rss_sep > 0:
            return math.nan, math.nan, f"F test needs n_cal + n_val > 2 n_p and RSS > 0 (dof {dof})"
        scale = rss_sep
        stat = (num / n_p) / (rss_sep / dof)
    else:
        num = 2.0 * (est_u.objective - est_c.objective - est_v.objective)
        scale = 2.0 * max(est_u.objective, 1.0)
        stat = num
    if num < -1e-7 * scale:
        return math.nan, math.nan, (f"the pooled fit's objective is below the sum of the separate fits' by "
                                    f"{-num:.3g} (chi^2 units): a fit missed its optimum; try other start values")
    stat = max(stat, 0.0)
    if est_c.sigma_estimated:
        return float(stat), float(stats.f.sf(stat, n_p, dof)), ""
    return float(stat), float(special.chdtrc(n_p, stat)), ""


# ---------------------------------------------------------------------------- decision (lines 09-17)
@dataclass(frozen=True)
class ModelDecision:
    """The verdict of Algorithm 1 for one model, one statistic and one multiple-test correction.

    Attributes
    ----------
    model : str
    decision : str        "rejected" (model uncertainty detected), "not rejected" or "undecided"
                          (the one vocabulary of terminal, JSON and report)
    statistic, correction : str
    tol : float           family-wise level TOL
    n_tests : int         planned number of tests (all splits, failed ones included)
    threshold : float     TOL / n_tests (the first, smallest threshold of Holm)
    flagged : tuple       splits whose hypothesis is rejected under this correction
    failed : tuple        splits without a p-value
    min_alpha : float     smallest alpha_min over the computed splits (NaN if none)
    reason : str
    """

    model: str
    decision: str
    statistic: str
    correction: str
    tol: float
    n_tests: int
    threshold: float
    flagged: tuple
    failed: tuple
    min_alpha: float
    reason: str


def decide(tests: Sequence[SplitTest], tol: float, statistic: str = DEFAULT_STATISTIC,
           correction: str = "bonferroni") -> ModelDecision:
    """Bonferroni: reject when some alpha_min < TOL / n_tests (lines 09-16).  Holm: step-down.

    Failed splits (or a split whose statistic could not be computed, e.g. a failed pooled
    fit for the likelihood ratio) count in n_tests (the correction covers every planned
    test) and rank last in Holm's ordering.  Without a rejection, a failed split makes the
    verdict "undecided".
    """
    tol = float(tol)
    if not (0.0 < tol < 1.0):
        raise ValueError(f"tol: must lie in (0, 1), got {tol!r}")
    if correction not in CORRECTIONS:
        raise ValueError(f"correction: expected one of {CORRECTIONS}, got {correction!r}")
    if statistic not in STATISTICS:
        raise ValueError(f"statistic: expected one of {STATISTICS}, got {statistic!r}")
    if not tests:
        raise ValueError("tests: no split tests to decide on")
    n = len(tests)
    model = tests[0].model
    a = np.array([t.alpha(statistic) if t.ok else np.nan for t in tests])
    failed = tuple(t.split for t, ai in zip(tests, a) if not np.isfinite(ai))
    if correction == "bonferroni":
        flag = np.isfinite(a) & (a < tol / n)
    else:
        order = np.argsort(np.where(np.isfinite(a), a, np.inf), kind="stable")
        flag = np.zeros(n, bool)
        for rank, i in enumerate(order):
            if np.isfinite(a[i]) and a[i] < tol / (n - rank):
                flag[i] = True
            else:
                break
    flagged = tuple(tests[i].split for i in np.flatnonzero(flag))
    amin = float(np.nanmin(a)) if np.any(np.isfinite(a)) else math.nan
    if flagged:
        dec = "rejected"
        i = int(np.nanargmin(a))
        reason = (f"alpha_min = {100 * a[i]:.3g} % < TOL/n_tests = {100 * tol / n:.3g} % on split "
                  f"{tests[i].split!r}")
    elif failed:
        dec = "undecided"
        reason = "; ".join((f"split {t.split!r} failed at the {t.stage}: {t.error}" if not t.ok else
                            f"split {t.split!r}: {statistic} not computed: {t.lr_error}")
                           for t, ai in zip(tests, a) if not np.isfinite(ai))
    else:
        dec = "not rejected"
        reason = f"every alpha_min >= TOL/n_tests = {100 * tol / n:.3g} % (smallest {100 * amin:.3g} %)"
    return ModelDecision(model, dec, statistic, correction, tol, n, tol / n, flagged, failed, amin, reason)


# ---------------------------------------------------------------------------- result
class _Notes:
    """Numbered notes of a summary: ``add(text)`` appends and returns its marker "[k]"."""

    def __init__(self, texts=()):
        self.texts = list(texts)

    def add(self, text: str) -> str:
        self.texts.append(text)
        return f"[{len(self.texts)}]"


def _alpha_mark(a: float, threshold: float) -> str:
    """alpha_min in % for the summary table, "*" when below the per-test level ("n/a" when NaN)."""
    if not np.isfinite(a):
        return "n/a"
    return f"{100 * a:.3g}" + ("*" if a < threshold else "") if a >= 1e-4 else "<0.01*"


def _disagreement(t: SplitTest, threshold: float, tol: float) -> str:
    """A warning when the three alpha_min of a split differ by more than a factor 100 and fall on
    both sides of the per-test level or of TOL ("" otherwise)."""
    a = {st: t.alpha(st) for st in STATISTICS}
    fin = {st: v for st, v in a.items() if np.isfinite(v)}
    if len(fin) < 2:
        return ""
    lo, hi = min(fin.values()), max(fin.values())
    ratio = math.inf if lo <= 0 else hi / lo
    crosses = any(lo < line <= hi for line in (threshold, tol))
    if not (ratio > 100 and crosses):
        return ""
    vals = ", ".join(f"{st} {100 * v:.3g} %" for st, v in fin.items())
    return (f"the statistics disagree by orders of magnitude ({vals}; ratio "
            f"{'inf' if not math.isfinite(ratio) else f'{ratio:.3g}'}) across the decision line: the model is "
            "far from linear in its parameters on this split or a fit is poorly determined; trust the likelihood "
            "ratio and check the fits (curvature, conf_int(method=\"profile\"))")


@dataclass(frozen=True, eq=False)
class DetectionResult:
    """Immutable result of :func:`detect`.

    Attributes
    ----------
    settings : DetectSettings
    models : tuple of str
    splits : tuple of Split
    tests : tuple of SplitTest     every (model, split), models outer
    decisions : tuple of ModelDecision   the primary verdict per model (settings' statistic, correction)
    all_decisions : tuple of ModelDecision  every model x statistic x correction
    normality : tuple of (model, NormalityCheck)
    design : tuple of (model, tuple of sensor names used, how chosen)
    notes : tuple of str
    """

    settings: DetectSettings
    models: tuple
    splits: tuple
    tests: tuple
    decisions: tuple
    all_decisions: tuple
    normality: tuple
    design: tuple
    notes: tuple = ()

    def decision(self, model: str | None = None, statistic: str | None = None,
                 correction: str | None = None) -> ModelDecision:
        """The verdict for a model (default: the only / first one); without statistic and correction
        the primary verdict (the likelihood ratio's when a linearisation is not trustworthy)."""
        model = self.models[0] if model is None else model
        if model not in self.models:
            raise KeyError(f"model: {model!r} not in {list(self.models)}")
        if statistic is None and correction is None:
            return next(d for d in self.decisions if d.model == model)
        st = statistic or self.settings.statistic
        co = correction or self.settings.correction
        for d in self.all_decisions:
            if d.model == model and d.statistic == st and d.correction == co:
                return d
        raise KeyError(f"no decision for {(model, st, co)}")

    @property
    def verdicts(self) -> Mapping:
        """{model: "rejected" | "not rejected" | "undecided"} (primary statistic and correction)."""
        return MappingProxyType({d.model: d.decision for d in self.decisions})

    def tests_of(self, model: str) -> tuple:
        return tuple(t for t in self.tests if t.model == model)

    def alphas(self, model: str | None = None, statistic: str | None = None) -> np.ndarray:
        """alpha_min per split (NaN for failed splits)."""
        model = self.models[0] if model is None else model
        st = statistic or self.settings.statistic
        return np.array([t.alpha(st) if t.ok else np.nan for t in self.tests_of(model)])

    def summary(self, units: Mapping | None = None, data_name: str = "series") -> str:
        """Per model: a table of the three statistics per split, the verdicts, numbered notes.

        ``units`` {sensor: (factor, unit)} and ``data_name`` label the normality table
        (:meth:`NormalityCheck.table`; e.g. the display unit and "study series").  Decisions use
        the words "rejected", "not rejected" and "undecided"; ">>" marks the deciding one.
        """
        s = self.settings
        n = len(self.splits)
        notes = _Notes(self.notes)
        explain = {"likelihood_ratio": "(likelihood ratio: pooled fit vs separate calibration and validation fits)",
                   "two_sample": "(Wald on p_val - p_cal with C_cal + C_val)",
                   "paper": "(paper: p_val in G(alpha, p_cal, C_cal))"}
        lines = [f"Detection of model uncertainty (Algorithm 1): TOL = {100 * s.tol:g} %, n_tests = {n}, "
                 f"per-test level TOL/n_tests = {100 * s.tol / n:.4g} %",
                 f"decision statistic: {s.statistic} {explain[s.statistic]}, correction: {s.correction}",
                 ""]
        switched = [d.model for d in self.decisions if d.statistic != s.statistic]
        if switched:
            lines[-1:-1] = [f"  for {', '.join(switched)} the likelihood ratio decides instead: a fit's linearisation "
                            "is not trustworthy (Bates-Watts curvature), the Wald statistics are unreliable"]
        lines += self._normality_lines(notes, units, data_name)
        lines += [f"sensors for {mname}: {', '.join(used)} ({how})" for mname, used, how in self.design]
        if self.design:
            lines.append("")
        for mname in self.models:
            lines += self._model_lines(mname, notes)
        lines.append("* alpha_min < TOL/n_tests; ~ = Wald p-value unreliable (linearisation not trustworthy); "
                     "R = hypothesis of the split rejected (LR, 2-sample, paper); >> = the decision")
        if s.statistic == "paper":
            notes.add("the paper's statistic ignores the validation estimate's covariance C_val; under a correct "
                      "model its size exceeds TOL (see identification.studies.montecarlo)")
        if notes.texts:
            lines += ["", "Notes:"] + [f"[{k}] {t}" for k, t in enumerate(notes.texts, 1)]
        return "\n".join(lines)

    def _normality_lines(self, notes: "_Notes", units: Mapping | None, data_name: str) -> list:
        """The summary's normality-gate blocks, one per distinct check."""
        lines, seen = [], []
        for mname, chk in self.normality:
            if any(chk is c for c in seen):
                continue
            seen.append(chk)
            head = (f"Normality gate (line 05), {chk.gate_text()} on the differences "
                    f"{chk.pairs_text()} of the {data_name} {chk.series_text()}"
                    + (f" [data of {mname}]" if len(self.models) > 1 else ""))
            status = "passed" if chk.passed else ("FAILED, overridden by the user "
                                                  + notes.add("normality='override': the Gaussian error assumption "
                                                              "failed its check; the p-values below rely on it")
                                                  if chk.overridden else "FAILED")
            lines += [head + f": {status}", chk.table(units, data_name)]
            if chk.note:
                lines[-1] += " " + notes.add(chk.note)
            lines.append("")
        return lines

    def _model_lines(self, mname: str, notes: "_Notes") -> list:
        """The summary's block of one model: a row per split, then every decision."""
        s = self.settings
        thr = s.tol / len(self.splits)
        w = max(10, max(len(sp.name) for sp in self.splits))
        lines = [f"Model {mname}",
                 f"  {'split':<{w}} {'calibration':<22} {'validation':<22} {'alpha LR %':>10} "
                 f"{'alpha 2-sample %':>16} {'alpha paper %':>13}  Bonf. LR/2s/paper  Holm LR/2s/paper"]
        dec = {(d.statistic, d.correction): d for d in self.all_decisions if d.model == mname}
        prim = self.decision(mname)
        for t in self.tests_of(mname):
            if not t.ok:
                lines.append(f"  {t.split:<{w}} {t.cal_label:<22} {t.val_label:<22} {'failed':>10} {'failed':>16} "
                             f"{'failed':>13}  " + notes.add(f"{mname}, {t.split}: {t.stage} failed: {t.error}"))
                continue
            m = {st: _alpha_mark(t.alpha(st), thr) for st in STATISTICS}
            if t.trustworthy is False:
                m = {st: v + ("~" if st != "likelihood_ratio" else "") for st, v in m.items()}
            fl = ["".join("R" if t.split in dec[(st, co)].flagged else "-" for st in STATISTICS)
                  for co in CORRECTIONS]
            lines.append(f"  {t.split:<{w}} {t.cal_label:<22} {t.val_label:<22} {m['likelihood_ratio']:>10} "
                         f"{m['two_sample']:>16} {m['paper']:>13}  {fl[0]:>17}  {fl[1]:>16}")
            if t.lr_error:
                lines[-1] += " " + notes.add(f"{mname}, {t.split}: likelihood ratio not computed: {t.lr_error}")
            if t.trustworthy is False:
                lines[-1] += " " + notes.add(
                    f"{mname}, {t.split}: linearisation NOT trustworthy ({t.curvature_note}); the Wald columns "
                    "(2-sample, paper; marked ~) rest on it and are unreliable: the likelihood ratio decides")
            disagree = _disagreement(t, thr, s.tol)
            if disagree:
                lines[-1] += " " + notes.add(f"{mname}, {t.split}: {disagree}")
            for nt in t.notes:
                lines[-1] += " " + notes.add(f"{mname}, {t.split}: {nt}")
        for st in STATISTICS:
            for co in CORRECTIONS:
                d = dec[(st, co)]
                primary = st == prim.statistic and co == prim.correction
                reason = prim.reason if primary else d.reason
                lines.append(f"  {'>> ' if primary else '   '}{st:<16} {co:<10}: {d.decision:<12} ({reason})")
        lines.append("")
        return lines

    def __repr__(self):
        v = ", ".join(f"{m}: {d}" for m, d in self.verdicts.items())
        return f"DetectionResult({v}; {len(self.splits)} splits, statistic={self.settings.statistic})"


# ---------------------------------------------------------------------------- detect: validation
def _detect_settings(settings: DetectSettings | None, **given) -> DetectSettings:
    """The settings of a run: ``settings``, or the keywords given (None = the DetectSettings default).

    Raises TypeError when ``settings`` and a keyword it holds are both given.
    """
    given = {k: v for k, v in given.items() if v is not None}
    if settings is None:
        return DetectSettings(**given)
    if not isinstance(settings, DetectSettings):
        raise TypeError(f"settings: expected DetectSettings, got {type(settings).__name__}")
    if given:
        raise TypeError(f"settings and {', '.join(given)}: give the keyword(s) inside settings "
                        f"(dataclasses.replace(settings, {', '.join(f'{k}=...' for k in given)})), not both")
    return settings


def _checked_splits(splits) -> tuple:
    """The splits as a non-empty tuple of Split objects with unique names (SplitError, TypeError)."""
    splits = (splits,) if isinstance(splits, Split) else tuple(splits)
    if not splits:
        raise SplitError("splits: at least one split (test scenario) is needed")
    for sp in splits:
        if not isinstance(sp, Split):
            raise TypeError(f"splits: expected Split objects, got {type(sp).__name__}")
    names = [sp.name for sp in splits]
    if len(set(names)) != len(names):
        raise SplitError(f"splits: names must be unique, got {names}")
    return splits


def _checked_models(model) -> dict:
    """{name: Model} from one Model or a non-empty mapping of them (TypeError, DataError)."""
    if isinstance(model, Mapping):
        models = dict(model)
        if not models:
            raise DataError("model: the mapping of models is empty")
    elif isinstance(model, Model):
        models = {model.name: model}
    else:
        raise TypeError(f"model: expected a models.Model or a mapping of them, got {type(model).__name__}")
    for name, m in models.items():
        if not isinstance(m, Model):
            raise TypeError(f"model[{name!r}]: expected a models.Model, got {type(m).__name__}")
    return models


def _as_mapping(what, value, names):
    if isinstance(value, Mapping):
        missing = [n for n in names if n not in value]
        if missing:
            raise DataError(f"{what}: no entry for model(s) {missing}")
        return {n: value[n] for n in names}
    return {n: value for n in names}


def _checked_design(design, weights) -> None:
    """``design`` is None, sensor names or weights, exclusive with ``weights`` (DataError)."""
    if weights is not None and design is not None:
        raise DataError("weights, design: give one of them, not both")
    if isinstance(design, str):
        raise DataError(f"design={design!r}: detect takes the design as sensor names or weights, not a criterion "
                        "or a single string; choose the sensors first with oed.select_sensors(model, data, p, "
                        f"criterion={design!r}) and pass the result's .sensors (or .weights) as design")


def _checked_data(name: str, data, splits: tuple) -> Measurements:
    """The campaign of one model, checked against every split's indices (TypeError, SplitError)."""
    if not isinstance(data, Measurements):
        raise TypeError(f"measurements[{name!r}]: expected an identification.Measurements, got {type(data).__name__}")
    for sp in splits:
        sp.check(data.n_q, data.n_M)
    return data


def _start_values(name: str, p0, model: Model) -> np.ndarray:
    """p0 of one model as a float vector (n_p,) (DataError naming the model)."""
    try:
        p0v = np.asarray(p0, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError(f"p0[{name!r}]: not numeric: {p0!r}") from None
    if p0v.shape != (model.n_p,):
        raise DataError(f"p0[{name!r}]: expected {model.n_p} start values ({', '.join(model.param_names)}), "
                        f"got {p0v.size}")
    return p0v


# ---------------------------------------------------------------------------- detect: design (lines 02-03)
def _design_weights(model: Model, data: Measurements, design, weights, design_how: str | None) -> tuple:
    """(sensor weights (n_S,) or None for all sensors, how they were chosen) from ``design`` or ``weights``."""
    if design is None:
        if weights is None:
            return None, design_how or "all sensors given"
        return data.sensor_weights(weights), design_how or "sensor weights given"
    items = list(design)
    if items and all(isinstance(x, str) for x in items):
        unknown = [x for x in items if x not in model.sensors]
        if unknown:
            raise DataError(f"design: unknown sensor(s) {unknown}; the model has {list(model.sensors)}")
        return np.array([1.0 if s in items else 0.0 for s in model.sensors]), design_how or "sensor names given"
    try:
        w = np.asarray(items, float)
    except (TypeError, ValueError):
        raise DataError(f"design: expected None, sensor names or weights, got {design!r}") from None
    if w.shape != (model.n_S,):
        raise DataError(f"design: expected {model.n_S} sensor weights, got {w.size}")
    return w, design_how or "sensor weights given"


def _check_split_sizes(splits: tuple, data: Measurements, model: Model, w) -> None:
    """Every set of every split holds at least n_p values on the selected sensors (SplitError)."""
    n_sel = int(np.count_nonzero(data.sensor_weights(w) > 0))
    for sp in splits:
        sp.check(data.n_q, data.n_M, model.n_p, n_sel)


# ---------------------------------------------------------------------------- detect: normality gate (line 05)
class _NormalityGate:
    """Line 05 once per distinct campaign z and sensor selection: :func:`normality_check`, then
    raise :class:`NormalityError` (normality="check") or record the override in ``notes``."""

    def __init__(self, settings: DetectSettings, notes: list):
        self.settings = settings
        self.notes = notes
        self.seen: list = []          # (z, selection weights, NormalityCheck) already checked

    def check(self, data: Measurements, w) -> NormalityCheck:
        wk = data.sensor_weights(w)
        found = None
        for z, w_seen, chk in self.seen:
            if z is data.z or (z.shape == data.z.shape and np.array_equal(z, data.z, equal_nan=True)):
                if np.array_equal(w_seen, wk):
                    found = chk
        if found is not None:
            return found
        chk = normality_check(data, self.settings.normality_level, w, self.settings.normality_correction)
        if not chk.passed:
            chk = self._failed(chk)
        self.seen.append((data.z, wk, chk))
        return chk

    def _failed(self, chk: NormalityCheck) -> NormalityCheck:
        bad = chk.failing()
        adj = "" if chk.correction == "none" else f" ({chk.correction}-adjusted over {len(chk.gated)} sensors)"
        msg = (f"normality gate (Algorithm 1, line 05) failed for sensor(s) {', '.join(bad)}: Shapiro-Wilk "
               f"p-value(s){adj} {', '.join(f'{100 * chk.adjusted[chk.sensors.index(s)]:.3g} %' for s in bad)} "
               f"< {100 * chk.level:g} % on the differences of repeated series"
               + (f" ({chk.note})" if chk.note else "")
               + "; acquire new data, or pass normality='override' to continue on record")
        if self.settings.normality == "check":
            raise NormalityError(msg, chk)
        self.notes.append(f"override: {msg}")
        return dataclasses.replace(chk, passed=False, overridden=True)


# ---------------------------------------------------------------------------- detect: fits and decisions
def _start_states(model: Model, p0: np.ndarray, data: Measurements):
    """States (n_q, n_y) at p0 for every input of ``data`` (warm start of the fits), or None."""
    try:
        return solve_states(model, p0, data.inputs) if data.d_q == model.n_q_dim else None
    except IdentificationError:
        return None          # each fit then reports the failing state solve itself


def _split_tests_shown(progress: Progress | None, model: Model, data: Measurements, splits: tuple, *args,
                       model_name: str, **kwargs) -> tuple:
    """:func:`run_split_tests` with a bar of one model's splits on ``progress`` (none when None)."""
    if progress is None:
        return run_split_tests(model, data, splits, *args, model_name=model_name, **kwargs)
    with progress.bar(len(splits), f"detect {model_name}", unit="split") as bar:
        return run_split_tests(model, data, splits, *args, model_name=model_name, bar=bar, **kwargs)


def _dynamic(model) -> bool:
    ms = model.values() if isinstance(model, Mapping) else (model,)
    return any(getattr(m, "is_dynamic", False) for m in ms)


def model_decisions(tests: tuple, names: tuple, settings: DetectSettings) -> tuple:
    """(primary decision per model, every model x statistic x correction decision) of split tests
    (lines 09-17; :mod:`identification.studies.dynamic_detect` after marking undecided splits)."""
    return _decisions(tests, names, settings)


def _decisions(tests: tuple, names: tuple, settings: DetectSettings) -> tuple:
    """(primary decision per model, every model x statistic x correction decision) (lines 09-17)."""
    all_dec, primary = [], []
    for name in names:
        mt = [t for t in tests if t.model == name]
        dec = {}
        for st in STATISTICS:
            for co in CORRECTIONS:
                dec[(st, co)] = decide(mt, settings.tol, st, co)
                all_dec.append(dec[(st, co)])
        primary.append(_primary(mt, dec, settings))
    return tuple(primary), tuple(all_dec)


def _primary(mt: list, dec: dict, settings: DetectSettings) -> ModelDecision:
    """The verdict of one model: the chosen statistic's, or the likelihood ratio's when a fit's
    linearisation is not trustworthy (the Wald statistics then rest on a failed approximation)."""
    bad = [t.split for t in mt if t.trustworthy is False]
    d = dec[(settings.statistic, settings.correction)]
    if not bad:
        return d
    why = (f"the linearisation of split(s) {', '.join(repr(b) for b in bad)} is not trustworthy (Bates-Watts "
           "curvature), so the Wald statistics are unreliable")
    if settings.statistic == "likelihood_ratio":
        return dataclasses.replace(d, reason=f"{d.reason}; decided by the likelihood ratio (parametrisation "
                                             f"invariant): {why}")
    lr = dec[("likelihood_ratio", settings.correction)]
    return dataclasses.replace(lr, reason=f"{lr.reason}; decided by the likelihood ratio instead of "
                                          f"{settings.statistic}: {why}")


# ---------------------------------------------------------------------------- main entry
def detect(model, measurements, splits: Sequence[Split], p0, tol: float | None = None, statistic: str | None = None,
           correction: str | None = None, weights=None, design=None, normality: str | None = None,
           settings: DetectSettings | None = None, design_how: str | None = None,
           progress: Progress | None = None) -> DetectionResult:
    r"""Algorithm 1: is the model rejected by calibration / validation tests?

    For each split: p_cal, C_cal and p_val, C_val by :func:`identify` (eqs. 3, 7), then

        alpha_paper = 1 - F_chi2(n_p)((p_val - p_cal)^T C_cal^{-1} (p_val - p_cal))
        alpha_2s    = 1 - F_chi2(n_p)((p_val - p_cal)^T (C_cal + C_val)^{-1} (p_val - p_cal))
        alpha_LR    = 1 - F_chi2(n_p)(2 [Phi_pooled(p_pooled) - Phi_cal(p_cal) - Phi_val(p_val)])

    (chi^2 units, dimensionless p-values; p_pooled from one more fit of calibration and
    validation data together) and the model is rejected when some alpha_min of the chosen
    statistic is below TOL / n_tests (Bonferroni; Holm reported as well).  All splits are
    evaluated (the paper stops at the first rejection; the verdict is the same).

    Steps: validate the arguments, the sensor design (lines 02-03, given), the normality gate
    (line 05), the split fits and statistics (lines 06-08, :func:`run_split_tests`), the
    decisions (lines 09-17, :func:`decide`), the result.

    Parameters
    ----------
    model : models.Model or mapping {name: Model}
        One candidate, or several (e.g. M1, M2, M3) tested on the same splits.
    measurements : Measurements or mapping {name: Measurements}
        The campaign (per model when their inputs differ).  sigma per sensor should be known
        (the paper fixes it); with sigma=None it is estimated and the chi^2 law is approximate.
    splits : sequence of Split
        The n_tests scenarios (e.g. ``splits_from_scenarios(models.press.PRESS_SCENARIOS, 29)``).
    p0 : array_like (n_p,) or mapping {name: array}
        Start values of every fit.
    tol : float, optional
        Family-wise level TOL in (0, 1) (default :class:`DetectSettings`' 5 %).
    statistic : {"likelihood_ratio", "two_sample", "paper"}, optional
        Which alpha_min decides (all three are always reported; default likelihood_ratio).
    correction : {"bonferroni", "holm"}, optional
    weights : array_like (n_S,), optional
        Sensor weights (0/1) of the fits; exclusive with ``design``.
    design : None, sequence of str or array_like (n_S,)
        Lines 02-03, chosen beforehand: sensor names or weights.  An optimal design is chosen
        with ``oed.select_sensors(model, data, p, criterion=...)``; pass its ``sensors``.
    normality : {"check", "override"}, optional
        "check" (default) raises :class:`NormalityError` when a selected sensor fails the
        Shapiro-Wilk gate; "override" records the failure and continues.
    settings : DetectSettings, optional
        All settings at once; exclusive with tol, statistic, correction and normality.
    design_how : str, optional
        How the design was chosen (e.g. "E-optimal design of 2 sensors"), recorded in
        ``DetectionResult.design``; default "sensor names given", "sensor weights given" or
        "all sensors given".
    progress : identification.progress.Progress, optional
        A bar advanced per split fitted (models x splits; default None: no output).

    Returns
    -------
    DetectionResult

    Raises
    ------
    ValueError
        tol outside (0, 1), unknown statistic / correction / normality.
    TypeError
        ``settings`` together with tol, statistic, correction or normality; bad argument types
        (e.g. ``progress`` not a Progress).
    NormalityError
        Line 05 failed and normality="check".
    DataError, SplitError
        Bad arguments (named in the message), e.g. a criterion string as design.  A fit failing
        on a split does not raise: it is recorded and the model's verdict becomes "undecided"
        unless another split rejects it.
    """
    settings = _detect_settings(settings, tol=tol, statistic=statistic, correction=correction, normality=normality)
    if _dynamic(model):           # ODE/DAE models: their collocation, splits by experiment and time window
        from identification.studies.dynamic_detect import detect_dynamic
        if weights is not None:
            raise DataError("weights: a dynamic model takes design= (instrument or sensor@time names)")
        return detect_dynamic(model, measurements, splits, p0, settings=settings, design=design,
                              design_how=design_how, progress=progress)
    splits = _checked_splits(splits)
    models = _checked_models(model)
    names = tuple(models)
    datas = _as_mapping("measurements", measurements, names)
    p0s = _as_mapping("p0", p0, names)
    _checked_design(design, weights)
    if progress is not None and not isinstance(progress, Progress):
        raise TypeError(f"progress: expected an identification.progress.Progress or None, got {type(progress).__name__}")
    notes, tests, normal, designs = [], [], [], []
    gate = _NormalityGate(settings, notes)
    for name in names:
        m = models[name]
        data = _checked_data(name, datas[name], splits)
        w, how = _design_weights(m, data, design, weights, design_how)
        _check_split_sizes(splits, data, m, w)
        designs.append((name, tuple(s for k, s in enumerate(m.sensors) if w is None or w[k] > 0), how))
        normal.append((name, gate.check(data, w)))
        if data.sigma is None:
            notes.append(f"{name}: sigma unknown and estimated per fit; the chi^2 law of alpha_min is then "
                         "approximate")
        p0v = _start_values(name, p0s[name], m)
        tests.extend(_split_tests_shown(progress, m, data, splits, p0v, w, settings, model_name=name,
                                        states0=_start_states(m, p0v, data), curvature=True))
    primary, all_decisions = _decisions(tuple(tests), names, settings)
    return DetectionResult(settings, names, splits, tuple(tests), primary, all_decisions, tuple(normal),
                           tuple(designs), tuple(notes))
