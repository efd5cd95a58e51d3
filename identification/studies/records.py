"""The records a study fills for its report: what the report draws beyond the library's own results.

The study (:mod:`mudoe`) computes every record here and hands them, inside one
:class:`oed.study_record.StudyRecord`, to the report (:mod:`reports`), which draws them and computes
nothing.  Each record is frozen data in the model's units unless its docstring says otherwise; the
few methods only word what the record holds (e.g. :meth:`Diagnosis.misses`,
:meth:`ModelUncertainty.warning`), with the number formats of :func:`fmt_value` and :func:`fmt_p`:

* the words of a study's pages: :class:`Presentation` and the display of outputs :class:`OutputDisplay`;
* each fit beside its numbers: :class:`GoodnessOfFit` (chi2 = sum ((z - h) / sigma)^2) and
  :class:`FitAssessment` (with the trust of its linearisation);
* the diagnostic split family: :class:`Diagnosis` of :class:`DiagnosisRow` s and the study's
  :class:`Explanation` s (:data:`MISSES` says what a rejection of each kind means);
* the bands of a fit: :class:`PredictionBands` (h +- q sqrt(g^T C g [+ sigma^2]));
* a fit whose linearisation may not be trusted: :class:`ModelUncertainty` of :class:`PairRegion` s;
* the model error of a variant: :class:`ModelErrorView` with its :class:`HeldOutBands` and the engineer's
  :class:`ErrorSummary` (its :class:`SensorErrorSize` s: how large, where, the band to design with, where to
  measure next);
* a dynamic study: :class:`Trajectories` on a fine time grid and :class:`MeshSummary` of each fit;
* a simulated study: :class:`SimulationTruth` (the true parameters, marked on the estimates);
* the press's figures: :class:`ModelCurve`.

This module imports nothing above :mod:`identification.studies`; the report re-exports the records
under their old paths (``reports.view.FitAssessment`` etc., deprecated).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from identification.inference.profile import ConfidenceIntervals, LikelihoodRegion
from identification.inference.results import Estimate
from identification.studies.model_error_result import ModelErrorResult
from identification.studies.model_ranking import ModelRanking

__all__ = ["unit_suffix", "fmt_value", "fmt_p", "fmt_pct", "Presentation", "OutputDisplay", "GoodnessOfFit",
           "FitAssessment", "MISSES", "Explanation", "DiagnosisRow", "Diagnosis", "PredictionBands",
           "UNTRUSTED", "PairRegion", "ModelUncertainty", "HeldOutBands", "SensorErrorSize", "ErrorSummary",
           "ModelErrorView", "Trajectories",
           "SimulationTruth", "MeshSummary", "ModelCurve"]


# ---------------------------------------------------------------------------- number formats
def unit_suffix(unit: str) -> str:
    """' (unit)' or '' for an empty unit (never 'k1 ()')."""
    return f" ({unit})" if unit else ""


def fmt_p(p: float) -> str:
    """A p-value: 2 significant digits, scientific below 1e-3."""
    if p is None or not math.isfinite(p):
        return "n/a"
    return f"{p:.2g}" if p >= 1e-3 else f"{p:.1e}"


def fmt_pct(a: float) -> str:
    """A probability a in percent: 3 significant digits, scientific below 0.01 %."""
    if a is None or not math.isfinite(a):
        return "n/a"
    return f"{100 * a:.3g}" if 100 * a >= 0.01 else f"{100 * a:.1e}"


def fmt_value(value: float, stderr: float) -> tuple[str, str]:
    """Value and standard error with the digits the error supports.

    The error is rounded to two significant digits and the value to the same decimal
    place: (530.04, 13.96) -> ('530', '14'); (0.012345, 0.00067) -> ('0.01235', '0.00067');
    (123456, 1234) -> ('123500', '1200').  Very small or large numbers use a common
    exponent: (1.2345e-8, 3.4e-10) -> ('1.235e-08', '0.034e-08').  Without a finite positive
    error the value gets 4 significant digits and the error reads 'n/a'.
    """
    if value is None or not math.isfinite(value):
        return "failed", "n/a"
    if stderr is None or not math.isfinite(stderr) or stderr <= 0:
        return f"{value:.4g}", "n/a"
    se = float(f"{stderr:.1e}")                  # two significant digits
    d = 1 - math.floor(math.log10(se))           # decimals of the second significant digit
    big = max(abs(value), se)
    e = math.floor(math.log10(big))
    if e >= 6 or e <= -4:
        dm = max(d + e, 0)
        f = 10.0 ** e
        return f"{value / f:.{dm}f}e{e:+03d}", f"{se / f:.{dm}f}e{e:+03d}"
    if d >= 0:
        return f"{value:.{d}f}", f"{se:.{d}f}"
    step = 10.0 ** (-d)
    return f"{round(value / step) * step:.0f}", f"{se:.0f}"


# ---------------------------------------------------------------------------- the words of the pages
@dataclass(frozen=True)
class Presentation:
    """The words a built-in model's study puts on its pages (the press: the paper's); empty for an own model.

    Attributes
    ----------
    quantity : str        what outputs in mm are ("displacement"), shown in axis labels; "" none
    input_label : str     axis label of the first input without its unit ("process force $q_P$"); "" the
                          input's name
    input_unit : str      unit shown when the model declares none ("N"); "" none
    phases : callable or None   deprecated: a built-in model declares its phases as
                          ``mudoe.builtin.BuiltinModel.phases``; the study computes the labels
                          (:attr:`oed.study_record.StudySetup.phases`), the report calls nothing
    """

    quantity: str = ""
    input_label: str = ""
    input_unit: str = ""
    phases: object = None

    def __post_init__(self):
        if self.phases is not None:
            import warnings
            warnings.warn("Presentation(phases=...) is deprecated: give the built-in model's phases as "
                          "mudoe.builtin.BuiltinModel(phases=...); the study computes the labels "
                          "(oed.study_record.StudySetup.phases)", DeprecationWarning, stacklevel=3)


@dataclass(frozen=True)
class OutputDisplay:
    """How model outputs are shown: displayed value = scale * model value, in ``units[k]`` per sensor.

    Attributes
    ----------
    scale : float         display unit per model unit (1e3: mm shown in um)
    units : tuple of str  displayed unit of each sensor ('' undeclared)
    quantity : str        what the outputs are ("displacement" for the press), "" otherwise
    """

    scale: float
    units: tuple
    quantity: str


# ---------------------------------------------------------------------------- each fit beside its numbers
@dataclass(frozen=True)
class GoodnessOfFit:
    """chi2 = sum ((z - h) / sigma)^2 over the used values (dimensionless), its degrees of freedom and p-value.

    Attributes
    ----------
    chi2 : float     the statistic (dimensionless)
    dof : int        its degrees of freedom (used values - parameters)
    pvalue : float   P(chi2_dof >= chi2); NaN when sigma was estimated from the residuals (chi2 = dof by
                     construction)
    """

    chi2: float
    dof: int
    pvalue: float

    def text(self) -> str:
        """The test in words: chi2, dof and p-value, or why it is not testable."""
        if not math.isfinite(self.pvalue):
            return "not testable (sigma estimated from the residuals)"
        return f"chi2 = {self.chi2:.4g} on {self.dof} dof, p = {fmt_p(self.pvalue)}"


@dataclass(frozen=True)
class FitAssessment:
    """What the study says of one fit beside its numbers (:func:`mudoe.fit_assessment.assess`).

    Attributes
    ----------
    goodness : GoodnessOfFit    chi-square test of all used residuals with the sensors' sigma
    trust : str                 the linearisation: "trustworthy", "NOT trustworthy" or "not assessed"
                                (Bates-Watts curvature)
    """

    goodness: GoodnessOfFit
    trust: str


# ---------------------------------------------------------------------------- the diagnostic split family
#: what a rejection on a split of each kind says the model misses
MISSES = {"input range": "an input dependence: the parameters fitted on small inputs do not hold for large ones "
                         "(a nonlinearity, a contact or a stiffening the model lacks, or a systematic sensor error "
                         "that depends on the reading)",
          "phase": "a history dependence: the parameters differ between phases (friction, hysteresis or another "
                   "direction-dependent effect the model lacks)",
          "series": "a change between series: the system drifted or the series are not repeats of one experiment",
          "study split": "something the study's own split separates (see its description)"}


@dataclass(frozen=True)
class Explanation:
    """What a study knows about why a kind of diagnostic split rejects a model on its data.

    Attributes
    ----------
    model : str    the model (variant) whose rejection it explains
    kind : str     the kind of diagnostic split: "input range", "phase" or "series" (:data:`MISSES`)
    text : str     plain sentences in the study's words, shown after the finding they explain
    """

    model: str
    kind: str
    text: str

    def __post_init__(self):
        if self.kind not in MISSES:
            raise ValueError(f"kind: expected one of {sorted(MISSES)}, got {self.kind!r}")
        if not isinstance(self.text, str) or not self.text.strip():
            raise ValueError("text: an explanation needs words")


@dataclass(frozen=True)
class DiagnosisRow:
    """One model on one split of the family: alpha_min, Holm-adjusted p-value, decision.

    Attributes
    ----------
    model, split, kind : str   the model, the split's name and its kind (:data:`MISSES`)
    alpha : float              alpha_min of the split (probability, not %)
    holm : float               Holm-adjusted alpha_min (probability; NaN: the split failed)
    rejected : bool            holm < TOL
    error : str                why the split's fits failed ("" when they did not)
    """

    model: str
    split: str
    kind: str
    alpha: float
    holm: float
    rejected: bool
    error: str = ""


@dataclass(frozen=True)
class Diagnosis:
    """The diagnostic family's results for every model (Holm over the study's and the diagnostic splits).

    Attributes
    ----------
    statistic : str           the statistic of alpha_min ("likelihood_ratio", "two_sample", "paper")
    tol : float               TOL of the Holm step-down procedure (probability)
    rows : tuple of DiagnosisRow
    explanations : tuple of Explanation   from the study; they follow the findings they match
    """

    statistic: str
    tol: float
    rows: tuple
    explanations: tuple = ()

    def misses(self, model: str) -> list[str]:
        """Plain sentences: what the model misses, one per rejected diagnostic split, each followed by
        the study's explanations of that model and kind of split."""
        out = []
        for r in self.rows:
            if r.model == model and r.rejected and r.kind != "study split":
                why = [e.text.strip() for e in self.explanations if e.model == model and e.kind == r.kind]
                out.append(" ".join([f"{model} misses {MISSES[r.kind]} (split '{r.split}', Holm-adjusted p = "
                                     f"{100 * r.holm:.3g} %)."] + why))
        return out


# ---------------------------------------------------------------------------- prediction bands
@dataclass(frozen=True, eq=False)
class PredictionBands:
    """Pointwise bands h +- q sqrt(g^T C g) and h +- q sqrt(g^T C g + sigma^2) of one fit's outputs at the
    measured inputs (model units).

    Attributes
    ----------
    h : ndarray (n_q, n_S)          fitted outputs
    half_mean : ndarray (n_q, n_S)  half width for the mean response, q * sqrt(g^T C g)
    half_new : ndarray (n_q, n_S)   half width for a new observation, q * sqrt(g^T C g + sigma^2)
    quantile : float                the t (sigma estimated) or normal quantile q used
    level : float                   the two-sided confidence level (probability)
    """

    h: np.ndarray
    half_mean: np.ndarray
    half_new: np.ndarray
    quantile: float
    level: float

    def __post_init__(self):
        object.__setattr__(self, "quantile", float(self.quantile))
        object.__setattr__(self, "level", float(self.level))


# ---------------------------------------------------------------------------- uncertainty of a fit
#: the words of linearisation_trust for a fit that must not be read through its ellipse
UNTRUSTED = "NOT trustworthy"


@dataclass(frozen=True)
class PairRegion:
    """The likelihood-ratio region {D(a, b) <= c} of one parameter pair, or why it could not be computed.

    Attributes
    ----------
    pair : (int, int)                the parameters' indices (i < j)
    region : LikelihoodRegion or None   the region (None: not computed)
    error : str                      why it was not computed ("" when it was)
    """

    pair: tuple
    region: LikelihoodRegion | None
    error: str = ""


def _fmt_end(x: float, se: float) -> str:
    if math.isinf(x):
        return "+inf" if x > 0 else "-inf"
    return fmt_value(x, se)[0]


@dataclass(frozen=True)
class ModelUncertainty:
    """Profile and Wald intervals, pair regions and identifiability of one model's fit.

    Attributes
    ----------
    variant : str                  the model (variant) name
    estimate : identification.Estimate
    trust : str                    "trustworthy", "NOT trustworthy" or "not assessed"
    wald : ndarray (n_p, 2)        (1 - alpha) Wald intervals p -+ q se
    profile : ConfidenceIntervals or None   the profile-likelihood intervals (None: failed, see profile_error)
    profile_error : str
    regions : tuple of PairRegion  every parameter pair (i < j)
    alpha : float
    seconds : float                wall time of the computation
    extent : ConfidenceIntervals or None   the profiles at the pair regions' threshold (:func:`region_alpha`):
                                   the extent of every region along each parameter, and the traces drawn
    extent_error : str
    """

    variant: str
    estimate: Estimate
    trust: str
    wald: np.ndarray
    profile: ConfidenceIntervals | None
    profile_error: str
    regions: tuple
    alpha: float
    seconds: float
    extent: ConfidenceIntervals | None = None
    extent_error: str = ""

    @property
    def pct(self) -> str:
        return f"{100 * (1 - self.alpha):g} %"

    def warning(self) -> str:
        """The sentence telling the engineer which picture to believe (plain text)."""
        e, v = self.estimate, self.variant
        if self.trust == UNTRUSTED:
            c = e.curvature
            return (f"Do NOT trust the confidence ellipses and the +- standard errors of {v}: its linearisation is "
                    f"NOT trustworthy (Bates-Watts maximum relative curvature: intrinsic {c.intrinsic:.3g}, "
                    f"parameter-effects {c.parameter_effects:.3g}; critical value 1/sqrt(F(p, n - p; 0.05)) = "
                    f"{c.critical:.3g}). Use the {self.pct} profile-likelihood intervals of the table below and the "
                    "likelihood-ratio regions (solid red contours), not the Wald intervals and the dashed ellipses.")
        if self.trust == "trustworthy":
            c = e.curvature
            return (f"The linearisation of {v} is trustworthy (Bates-Watts maximum relative curvature: intrinsic "
                    f"{c.intrinsic:.3g}, parameter-effects {c.parameter_effects:.3g}, both below the critical value "
                    f"{c.critical:.3g}): its ellipses and Wald intervals may be used; the profile-likelihood "
                    "intervals and likelihood-ratio regions below show how closely they agree.")
        return (f"The linearisation of {v} was not assessed (no residual degrees of freedom or no curvature): "
                f"prefer the {self.pct} profile-likelihood intervals below to the Wald intervals.")

    def sloppy_text(self) -> str:
        """The weakest direction of the information matrix in words ('' for one parameter)."""
        sd = self.estimate.sloppy_direction
        if sd is None:
            return ""
        return (f"Identifiability: {sd}. The data determine that combination of the parameters poorly; the "
                "regions are long along it.")

    def interval_rows(self) -> tuple:
        """(head, rows, flags) of the interval table: parameter (unit), estimate +- se, Wald and profile
        intervals with the digits of the standard error, and the profile ends relative to the Wald ones."""
        e = self.estimate
        head = ["parameter", "estimate +- std. error", f"{self.pct} Wald interval",
                f"{self.pct} profile-likelihood interval", "profile vs Wald end"]
        rows, flags = [], []
        for i, (name, unit) in enumerate(zip(e.param_names, e.param_units)):
            p, se = float(e.p[i]), float(e.stderr[i])
            v, s = fmt_value(p, se)
            wl, wu = self.wald[i]
            row = [f"{name}{unit_suffix(unit)}", f"{v} +- {s}", f"[{_fmt_end(wl, se)}, {_fmt_end(wu, se)}]"]
            if self.profile is None:
                row += ["failed", self.profile_error[:60]]
                flag = True
            else:
                lo, up = float(self.profile.lower[i]), float(self.profile.upper[i])
                row.append(f"[{_fmt_end(lo, se)}, {_fmt_end(up, se)}]")
                ratio = []
                for side, end, wend in (("lower", lo, wl), ("upper", up, wu)):
                    if math.isinf(end):
                        ratio.append(f"{side} unbounded")
                    else:
                        ratio.append(f"{side} {abs(end - p) / max(abs(wend - p), 1e-300):.2g}x")
                row.append(", ".join(ratio))
                flag = any(math.isinf(x) for x in (lo, up)) or any(
                    abs(abs(end - p) / max(abs(wend - p), 1e-300) - 1) > 0.2
                    for end, wend in ((lo, wl), (up, wu)) if math.isfinite(end))
            rows.append(row)
            flags.append([False, False, flag, flag, flag])
        return head, rows, flags

    def notes(self) -> tuple:
        """Notes of the profile computation and of the regions (unbounded sides, unsolved points)."""
        out = list(self.profile.notes) if self.profile is not None else [f"profile: {self.profile_error}"]
        if self.extent_error:
            out.append(f"extent of the regions (profiles at the pair level): {self.extent_error}")
        for r in self.regions:
            if r.region is None:
                a, b = (self.estimate.param_names[k] for k in r.pair)
                out.append(f"region of ({a}, {b}) not computed: {r.error}")
        return tuple(out)


# ---------------------------------------------------------------------------- the model error of a variant
@dataclass(frozen=True)
class HeldOutBands:
    """The validation readings of one split and the new-reading bands fitted on its calibration part, all in the
    sensors' file units and relative to the plain prediction (so that bands of a few um show on outputs of mm).

    Attributes
    ----------
    split : str
    q : ndarray (n,)                    first input of the validation rows (file unit)
    readings : ndarray (n_M, n, n_S)    reading - plain prediction (NaN: not in the validation set)
    plain : (lower, upper)              the plain band, each (n, n_S), relative to the plain prediction
    with_error : (lower, upper) or None the band with the error model (None: the error model is "none")
    coverage_plain, coverage_error : float   the split's held-out coverage of the two bands
    """

    split: str
    q: np.ndarray
    readings: np.ndarray
    plain: tuple
    with_error: tuple | None
    coverage_plain: float
    coverage_error: float


@dataclass(frozen=True)
class SensorErrorSize:
    """How large one sensor's model error is over the data's input range and the band to design with, all in the
    sensor's file unit: the size s(q) = |mean discrepancy delta(q)| (kind "discrepancy"), or the (1 - alpha)
    half-width of the parameters' spread g^T Omega g (kind "embedded", zero mean), or 0 (kind "none").

    Attributes
    ----------
    sensor, unit : str
    max_abs, rms : float            max and root mean square of s(q) over the grid
    at : str                        where s peaks, e.g. "q_P = 1600 N" (a dynamic model: "F = 2, t = 0.4 s")
    half_median, half_max : float   half-width of the (1 - alpha) new-reading band with the error model over the grid
    plain_median, plain_max : float the same of the plain band (parameters and sensor noise only)
    next_before, next_after : float mean half-width of the new-reading band over the range before and after the
                                    next runs (NaN: none proposed)
    size, half, plain : ndarray (n_x,)   s(q), the two half-widths at the summary's ``x`` (empty without ``x``)
    """

    sensor: str
    unit: str
    max_abs: float
    rms: float
    at: str
    half_median: float
    half_max: float
    plain_median: float
    plain_max: float
    next_before: float = float("nan")
    next_after: float = float("nan")
    size: np.ndarray = field(default_factory=lambda: np.zeros(0))
    half: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plain: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class ErrorSummary:
    """The engineer's summary of one variant's model error (computed by the study, :mod:`mudoe.model_error_runs`).

    Attributes
    ----------
    variant, kind : str             the error model ("none", "discrepancy", "embedded")
    detected : bool
    p_value, alpha : float          of the 'no model error' test; the bands' level is 1 - alpha
    size_is : str                   what the size s(q) of :class:`SensorErrorSize` is for this kind
    grid : str                      where the numbers are taken, e.g. "21 points over q_P 0-1600 N"
    sizes : tuple of SensorErrorSize   one per selected sensor
    embedded : tuple of EmbeddedParameter   the parameters that carry the error (embedded, chosen or beside it)
    next_runs : tuple of str        the runs that most shrink the band over the range, e.g. ("q_P = 1600 N", ...)
                                    (empty: none proposed)
    next_how : str                  how they were chosen (candidates, criterion, series per run) or why none
    x : ndarray (n_x,)              a static model of one input: the grid's input values (its file unit), where the
                                    sizes' curves are taken (empty otherwise)
    x_label : str                   the input with its unit, e.g. "q_P [N]"
    """

    variant: str
    kind: str
    detected: bool
    p_value: float
    alpha: float
    size_is: str
    grid: str
    sizes: tuple
    embedded: tuple = ()
    next_runs: tuple = ()
    next_how: str = ""
    x: np.ndarray = field(default_factory=lambda: np.zeros(0))
    x_label: str = ""


@dataclass(frozen=True)
class ModelErrorView:
    """What the page of one variant's model error draws (computed by the study).

    Attributes
    ----------
    variant : str
    result : identification.ModelErrorResult    the model error on all study data (kind "auto")
    sensors, units : tuple                      the selected sensors and their file units
    input_label : str                           the first input with its unit, e.g. "q_P [N]"
    q : ndarray (n_q,)                          first input of the study's input rows (file unit)
    discrepancy : (mean, lower, upper)          each (n_q, n_S): the discrepancy and its band (file units)
    heldout : HeldOutBands or None              the split of the lowest plain held-out coverage
    embedded : tuple of EmbeddedParameter       the embedded error (chosen or fitted beside the chosen one)
    curves : tuple of str                       a dynamic model: the label of every experiment; q (n_e n_t,)
                                                then holds each experiment's sampling times one after the other
                                                and the page draws one curve per experiment against time
    summary : ErrorSummary or None              the engineer's numbers (how large, where, band, next runs)
    ranking : ModelRanking or None              the ranking of the study's variants (the same in every view)
    noise : str                                 one sentence: which sensor sigma the bands take as the noise of a
                                                reading, and why ("" : not said)
    """

    variant: str
    result: ModelErrorResult
    sensors: tuple
    units: tuple
    input_label: str
    q: np.ndarray
    discrepancy: tuple
    heldout: HeldOutBands | None
    embedded: tuple = ()
    curves: tuple = ()
    summary: ErrorSummary | None = None
    ranking: ModelRanking | None = None
    noise: str = ""


# ---------------------------------------------------------------------------- a dynamic study
@dataclass(frozen=True)
class Trajectories:
    """Outputs h(x(t)) of every experiment on a fine time grid and their delta-method half-widths.

    Attributes
    ----------
    t : ndarray (n_t,)                       the fine time grid (model time unit)
    h, half_mean, half_new : ndarray (n_q, n_t, n_S)   outputs and half-widths q sqrt(g^T C g [+ sigma^2])
                                             (model units)
    level : float                            the bands' two-sided level (probability)
    quantile : str                           name of the quantile q ("normal", "Student t")
    residuals : ndarray (n_M, n_q, n_t_data, n_S) or None   (z - h) / sigma at the data's times (dimensionless)
    error_sigma : float                      largest discretisation error of h on the fine grid, in sigmas
    tol_sigma : float                        its tolerance (sigmas)
    fitted : ndarray (n_q, n_t_data, n_S) or None   h at the data's times (model units; NaN past an
                                             experiment's last time): the abscissa of residuals against outputs
    """

    t: np.ndarray
    h: np.ndarray
    half_mean: np.ndarray
    half_new: np.ndarray
    level: float
    quantile: str
    residuals: np.ndarray | None = None
    error_sigma: float = math.nan
    tol_sigma: float = math.nan
    fitted: np.ndarray | None = None


@dataclass(frozen=True)
class SimulationTruth:
    """The true parameters of a simulated campaign, as the study's config knows them.

    Attributes
    ----------
    variant : str       the model variant simulated
    values : dict       {parameter: true value} (model units)
    source : str        where the study found that the data are this simulation (words for the report)
    """

    variant: str
    values: dict
    source: str = ""


@dataclass(frozen=True)
class MeshSummary:
    """What a report shows of the discretisation of a dynamic fit (from its
    :class:`identification.fit.dynamic_fit.DiscretisationRecord`).

    Attributes
    ----------
    degree, n_elements : int   the Radau IIA mesh
    error_pct : float          largest estimated output error at the readings, % of sigma
    tol_pct : float            its tolerance (% of sigma)
    shift_se : float           largest linearised shift of the estimate without discretisation error, in
                               standard errors
    tol_se : float             its tolerance (standard errors)
    bounded : bool             both within their tolerances
    reason : str               why not ("" when bounded)
    method : str               the discretisation
    """

    degree: int
    n_elements: int
    error_pct: float
    tol_pct: float
    shift_se: float
    tol_se: float
    bounded: bool
    reason: str = ""
    method: str = "Radau IIA collocation"

    def text(self) -> str:
        """One line: mesh, largest output error in % of sigma, bounded or NOT bounded (and why)."""
        head = (f"{self.method}, degree {self.degree}, {self.n_elements} elements; largest discretisation error "
                f"{self.error_pct:.2g} % of sigma")
        if self.bounded:
            return (f"{head} (bounded below {self.tol_pct:.2g} %), estimate shifted by at most {self.shift_se:.2g} "
                    f"standard errors (below {self.tol_se:.2g})")
        why = self.reason or "no finer mesh was tried"
        return (f"{head}, estimate shift {self.shift_se:.3g} standard errors: discretisation error NOT bounded "
                f"(tolerances {self.tol_pct:.2g} % of sigma, {self.tol_se:.2g} standard errors: {why}); the "
                "estimate and its verdicts may reflect the discretisation, not the model")


# ---------------------------------------------------------------------------- the press's figures
@dataclass(frozen=True)
class ModelCurve:
    """The outputs h(y_j, p_hat, q_j) of one candidate model at its estimate, as
    :func:`reports.press_figures.plot_models` draws them.

    Attributes
    ----------
    outputs : ndarray (n_q, n_S)   h(y_j, p_hat, q_j) over the campaign's set points (m)
    sensors : tuple of str         the model's sensors (columns of ``outputs``)
    reduced_chi2 : float           the fit's reduced chi^2 (shown in the legend; dimensionless)
    """

    outputs: np.ndarray
    sensors: tuple
    reduced_chi2: float
