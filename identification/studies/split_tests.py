r"""Lines 06-08 of Algorithm 1 for one split: the calibration, validation and pooled fits and the three
statistics (see :mod:`identification.studies.detect`)

.. math::

    \alpha_\min = 1 - F_{\chi^2_{n_p}}\big((p_v - p_c)^\top C_c^{-1} (p_v - p_c)\big)\ \text{(paper)},\quad
    \alpha_\min^{(2)} = 1 - F_{\chi^2_{n_p}}\big((p_v - p_c)^\top (C_c + C_v)^{-1} (p_v - p_c)\big),

    \alpha_\min^{(LR)} = 1 - F_{\chi^2_{n_p}}\big(2\,[\Phi_{c\cup v}(\hat p_{c\cup v}) - \Phi_c(p_c) - \Phi_v(p_v)]\big)

(chi^2 units; the F (Chow) test when sigma is estimated).  A fit that fails is recorded as a
:class:`FitFailure` in its :class:`SplitTest`, never raised.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import special, stats

from models.contract import Model
from identification.errors import DataError, IdentificationError
from identification.inference.results import identify
from identification.fit.measurements import Measurements
from identification.inference.regions import CovarianceError, mahalanobis2
from identification.studies.detect_settings import DetectSettings, alpha_field
from identification.studies.splits import Split, SplitError
from identification.fit.unbounded import not_bounded_reason

__all__ = ["SplitTest", "FitFailure", "run_split_tests", "pooled_newton"]


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


#: the errors of a fit that a split test records (anything else propagates)
_FIT_ERRORS = (IdentificationError, DataError)


@dataclass(frozen=True)
class FitFailure:
    """A fit of a split that gave no estimate to test: recorded in its :class:`SplitTest`, never raised.

    Attributes
    ----------
    reason : str       the text recorded (``SplitTest.error`` or ``SplitTest.lr_error``), e.g.
                       "IdentificationError: ..." or "pooled fit not bounded: ..."
    error_type : str   the class name of the error the fit raised ("IdentificationError", "DataError"),
                       "not bounded" when the data do not bound the parameters, "" for a failure text
                       given by the caller (``run_split_tests(pooled=...)``)
    """

    reason: str
    error_type: str = ""

    @classmethod
    def from_error(cls, exc: Exception, prefix: str = "") -> "FitFailure":
        """The failure of a fit that raised ``exc``: reason "<prefix><ErrorType>: <message>"."""
        return cls(f"{prefix}{type(exc).__name__}: {exc}", type(exc).__name__)

    @classmethod
    def of_entry(cls, entry):
        """An entry of ``run_split_tests(fits=..., pooled=...)`` as an estimate or a FitFailure: a recorded
        error (IdentificationError, DataError) or a failure text becomes a FitFailure; any other
        exception is raised."""
        if isinstance(entry, _FIT_ERRORS):
            return cls.from_error(entry)
        if isinstance(entry, BaseException):
            raise entry
        if isinstance(entry, str):
            return cls(entry)
        return entry


def _failed(model_name: str, split: Split, stage: str, msg: str, n_p: int, p_cal=None, C_cal=None, n_cal: int = 0,
            notes=()) -> SplitTest:
    """The test of a split that failed at ``stage``: NaN statistics and validation fit; the calibration
    estimate ``p_cal`` and covariance ``C_cal`` when that fit succeeded (NaN otherwise)."""
    nanv, nanm = np.full(n_p, np.nan), np.full((n_p, n_p), np.nan)
    c, v = split.label()
    nan = math.nan
    return SplitTest(model=model_name, split=split.name, cal_label=c, val_label=v, ok=False, stage=stage, error=msg,
                     p_cal=nanv if p_cal is None else p_cal, p_val=nanv, C_cal=nanm if C_cal is None else C_cal,
                     C_val=nanm, d2_paper=nan, d2_two_sample=nan, alpha_paper=nan, alpha_two_sample=nan, n_cal=n_cal,
                     n_val=0, notes=tuple(notes))


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
    (:attr:`SplitTest.trustworthy`; :func:`~identification.studies.detect.detect` does; Monte Carlo studies skip it for speed).

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
    read), the IdentificationError/DataError its fit raised, a :class:`FitFailure`, or (pooled) a
    failure text (read as ``FitFailure(text)``).
    """
    settings = settings or DetectSettings()
    w = data.sensor_weights(weights)                # validated once, read by every split
    n_sel = int(np.count_nonzero(w > 0))
    run = _Run(model=model, data=data, p0=p0, weights=weights, w=w, settings=settings, name=model_name or model.name,
               states0=states0, curvature=curvature,
               pooled={} if pooled is None else {k: FitFailure.of_entry(e) for k, e in pooled.items()})
    out = []
    for js, split in enumerate(_counted(splits, bar)):
        try:
            split.check(data.n_q, data.n_M, model.n_p, n_sel)
        except SplitError as exc:
            out.append(_failed(run.name, split, "split", str(exc), model.n_p))
            continue
        out.append(_split_test(run, split, (None, None) if fits is None else fits[js]))
    return tuple(out)


@dataclass(frozen=True, eq=False)
class _Run:
    """What the split tests of one :func:`run_split_tests` call share."""

    model: Model
    data: Measurements
    p0: object
    weights: object           # as given (passed on to identify)
    w: np.ndarray             # the validated sensor weights (n_S,)
    settings: DetectSettings
    name: str
    states0: object           # (n_q, n_y) states at p0, or None
    curvature: bool
    pooled: dict              # {split.pooled_key: pooled estimate or FitFailure}, filled as the splits run

    def start(self, inputs) -> np.ndarray | None:
        """The states at p0 of the input rows ``inputs`` (warm start of a fit), or None."""
        return None if self.states0 is None else self.states0[list(inputs)]

    def fit(self, split: Split, which: str, given) -> tuple:
        """(estimate, covariance of the settings' kind) of the ``which`` ("calibration" or "validation") set
        of ``split``, or (FitFailure, None) when building its data or its fit raised; ``given`` (an entry of
        ``run_split_tests(fits=...)``) replaces the fit when not None."""
        if given is None:
            cal = which == "calibration"
            try:
                data = split.calibration(self.data) if cal else split.validation(self.data)
                given = identify(self.model, data, self.p0, weights=self.weights, settings=self.settings.identify,
                                 Y0=self.start(split.cal_inputs if cal else split.val_inputs))
            except _FIT_ERRORS as exc:
                return FitFailure.from_error(exc), None
        est = FitFailure.of_entry(given)
        if isinstance(est, FitFailure):
            return est, None
        return est, (est.cov if self.settings.covariance == "second_order" else est.cov_gn)


def _split_test(run: _Run, split: Split, given: tuple) -> SplitTest:
    """The fits and the three statistics of one split (``given``: its (calibration, validation) fits
    computed elsewhere, None entries fitted here)."""
    n_p, name = run.model.n_p, run.name
    est_c, C_c = run.fit(split, "calibration", given[0])
    if isinstance(est_c, FitFailure):
        return _failed(name, split, "calibration fit", est_c.reason, n_p)
    if not_bounded_reason(est_c):        # the data of this set do not bound p: no estimate to test
        return _failed(name, split, "calibration fit", not_bounded_reason(est_c), n_p, n_cal=est_c.n_data,
                       notes=est_c.notes)
    est_v, C_v = run.fit(split, "validation", given[1])
    why = est_v.reason if isinstance(est_v, FitFailure) else not_bounded_reason(est_v)
    if why:
        return _failed(name, split, "validation fit", why, n_p, p_cal=est_c.p, C_cal=C_c, n_cal=est_c.n_data,
                       notes=est_c.notes)
    notes = tuple(f"calibration fit: {n}" for n in est_c.notes) + tuple(f"validation fit: {n}" for n in est_v.notes)
    c, v = split.label()
    fits = dict(model=name, split=split.name, cal_label=c, val_label=v, p_cal=est_c.p, p_val=est_v.p, C_cal=C_c,
                C_val=C_v, n_cal=est_c.n_data, n_val=est_v.n_data, notes=notes)
    try:
        d2p = mahalanobis2(est_v.p, est_c.p, C_c, "C_cal")
        d2t = mahalanobis2(est_v.p, est_c.p, C_c + C_v, "C_cal + C_val")
    except CovarianceError as exc:
        nan = math.nan
        return SplitTest(ok=False, stage="statistic", error=f"CovarianceError: {exc}", d2_paper=nan,
                         d2_two_sample=nan, alpha_paper=nan, alpha_two_sample=nan, **fits)
    lr, a_lr, lr_err = _likelihood_ratio(run, split, est_c, est_v)
    trust, cnote = _linearisation(est_c, est_v) if run.curvature else (None, "")
    return SplitTest(ok=True, stage="", error="", d2_paper=d2p, d2_two_sample=d2t,
                     alpha_paper=float(special.chdtrc(n_p, d2p)), alpha_two_sample=float(special.chdtrc(n_p, d2t)),
                     lr=lr, alpha_lr=a_lr, lr_error=lr_err, trustworthy=trust, curvature_note=cnote, **fits)


@dataclass(frozen=True)
class _PooledMinimum:
    p: np.ndarray
    objective: float
    rss: float
    steps: int


def pooled_newton(model, data_u, split, est_c, est_v, w: np.ndarray, max_steps: int = 8):
    r"""min_p Phi_cal(p) + Phi_val(p) by exact reduced-space Newton, or None.

    Starts at the precision-weighted mean p_bar = (F_c + F_v)^{-1} (F_c p_c + F_v p_v) of the
    two estimates (within O(|p_v - p_c|^2) of the pooled optimum) with the states of the two
    fits, and takes the estimator's own exact Newton steps (J^T W J + S, see
    :func:`identification.fit.refinement.refine`).  The result is used only when the Newton decrement
    g^T H^{-1} g < 1e-12 (chi^2 units: within 1e-6 standard errors of the optimum); otherwise
    (None) the caller runs the full-space :func:`~identification.inference.results.identify` on the pooled data.  ``w`` (n_S,) are the
    validated sensor weights of the fits.
    """
    from identification.errors import StateSolveError
    from identification.fit.refinement import ReducedProblem, refine
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


def _pooled_fit(run: _Run, split: Split, est_c, est_v):
    """The fit of the calibration and validation data together (:func:`pooled_newton` from the two
    estimates, else :func:`~identification.inference.results.identify`), or a FitFailure (the fit raised, or the data do not bound p)."""
    qs = sorted({j for j, _ in split.pooled_points(run.data.n_M)})
    data_u = split.pooled(run.data)
    est_u = pooled_newton(run.model, data_u, split, est_c, est_v, w=run.w)
    if est_u is not None:
        return est_u
    try:
        est_u = identify(run.model, data_u, run.p0, weights=run.weights, settings=run.settings.identify,
                         Y0=run.start(qs))
    except _FIT_ERRORS as exc:
        return FitFailure.from_error(exc, "pooled fit failed: ")
    if not_bounded_reason(est_u):
        return FitFailure(f"pooled fit {not_bounded_reason(est_u)}", "not bounded")
    return est_u


def _likelihood_ratio(run: _Run, split: Split, est_c, est_v) -> tuple:
    """(statistic, p-value, error) of the likelihood-ratio test of one split.

    The pooled fit (calibration and validation data together) is shared by splits with the
    same pooled points (``run.pooled`` caches it).  Since the point sets are disjoint,
    Phi_pooled(p) = Phi_cal(p) + Phi_val(p) >= Phi_cal(p_cal) + Phi_val(p_val) at every p, so
    the statistic is >= 0 up to the solver tolerance; a clearly negative value means a fit
    missed its optimum and is reported instead of used.
    """
    key = split.pooled_key(run.data.n_M)
    est_u = run.pooled.get(key)
    if est_u is None:
        est_u = run.pooled[key] = _pooled_fit(run, split, est_c, est_v)
    if isinstance(est_u, FitFailure):
        return math.nan, math.nan, est_u.reason
    n_p = run.model.n_p
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

