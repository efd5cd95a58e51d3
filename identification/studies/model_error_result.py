"""The result of :func:`identification.studies.model_error.model_error` and its tables."""
from __future__ import annotations

import dataclasses

from dataclasses import dataclass, field
from html import escape

import numpy as np
from scipy import stats

from identification.inference.intervals import ConfidenceIntervals, validate_alpha
from identification.studies.model_error_fit import Band, ErrorFit
from identification.results_protocol import ResultProtocol

__all__ = ["ModelErrorResult", "HeldOut", "SensorDiscrepancy", "EmbeddedParameter", "ErrorTest", "PureErrorCheck",
           "NEW_CONDITION"]

#: the ``condition`` of :meth:`ModelErrorResult.predict` for a condition the data do not hold
NEW_CONDITION = "new"


@dataclass(frozen=True)
class ErrorTest:
    """The likelihood-ratio test of 'no model error' (REML, one variance component, chi^2 units).

    ``statistic`` LR >= 0, ``p_value`` = 0.5 P(chi2_1 > LR) (1 at LR = 0: the 50:50 mixture of chi2_0 and
    chi2_1), ``excess`` the variance component lambda (a discrepancy of variance lambda sigma_k^2 per input
    row and sensor, dimensionless), ``dof`` residual degrees of freedom.
    """

    statistic: float
    p_value: float
    excess: float
    dof: int
    reference: str = "0.5 chi2_0 + 0.5 chi2_1"


@dataclass(frozen=True)
class PureErrorCheck:
    r"""The stated sigma of one sensor against the pure error of the repeated series.

    Under H0 (the readings' repeatable noise has standard deviation ``sigma``), dof s^2 / sigma^2 ~ chi2_dof with s
    the pooled pure error (``pure_error``, unit of z) on ``dof`` degrees of freedom; ``p_below`` = P(chi2_dof <=
    dof s^2 / sigma^2) (small: the repeats scatter clearly less than sigma says), ``p_above`` = 1 - p_below.
    A stated sigma above the repeatability may hold a systematic error (a gauge error that varies with the
    reading) which the discrepancy, fitted on the same readings, holds too: the new-reading bands then count it
    twice.  Independence of the series is assumed.
    """

    sensor: str
    sigma: float
    pure_error: float
    dof: int
    p_below: float
    p_above: float

    @property
    def ratio(self) -> float:
        """pure_error / sigma (dimensionless)."""
        return self.pure_error / self.sigma

    def to_dict(self) -> dict:
        return {"sensor": self.sensor, "sigma": self.sigma, "pure_error": self.pure_error, "ratio": self.ratio,
                "dof": self.dof, "p_below": self.p_below, "p_above": self.p_above}


@dataclass(frozen=True)
class SensorDiscrepancy:
    """The discrepancy of one sensor: smooth amplitude s and length scale (in each input's unit:
    l times the input's range; a dynamic model: then in the time unit, l times the sampling span), rough part
    tau; s, tau in the unit of the sensor and in sigma units."""

    sensor: str
    amplitude: float
    length_scale: float
    length_scales: tuple
    rough: float
    sigma: float

    def to_dict(self) -> dict:
        return {"sensor": self.sensor, "amplitude": self.amplitude, "amplitude_over_sigma": self.amplitude / self.sigma,
                "length_scale_scaled": self.length_scale, "length_scales": list(self.length_scales),
                "rough": self.rough, "rough_over_sigma": self.rough / self.sigma, "sigma": self.sigma}


@dataclass(frozen=True)
class EmbeddedParameter:
    """The spread of one parameter between conditions (kind "embedded"): omega in the parameter's unit and
    relative to the parameter's value (omega / |p|)."""

    name: str
    omega: float
    relative: float

    def to_dict(self) -> dict:
        return {"name": self.name, "omega": self.omega, "relative": self.relative}


@dataclass(frozen=True)
class HeldOut:
    """One split: its validation readings predicted from the fits on its calibration part.

    ``coverage_*`` the fraction of validation readings (selected sensors) inside the (1 - alpha)
    new-reading band without model error (``plain``), with the output discrepancy and with the embedded
    error; ``widening_*`` the median ratio of the band widths (with / without); ``log_score_*`` the mean
    log predictive density of a reading (log of 1 / unit of z); ``n_values`` the readings counted; ``n_unseen``
    those of them at rows in a condition the calibration part has not seen
    (:func:`identification.studies.model_error.unseen_rows`: the discrepancy predicts them as a new draw);
    ``n_conditions`` the conditions the calibration part holds (the named groups among its rows; without
    groups 1).  A band at a condition not seen rests on the discrepancy's amplitude estimated from those
    ``n_conditions`` conditions: with one it is a plug-in from one realisation, calibrated by no assumption
    (:attr:`unseen_from_one`; Monte Carlo: :data:`identification.studies.model_error.UNSEEN_COVERAGE_MC`).
    """

    split: str
    n_values: int
    coverage_plain: float
    coverage_discrepancy: float
    coverage_embedded: float
    widening_discrepancy: float
    widening_embedded: float
    log_score_plain: float
    log_score_discrepancy: float
    log_score_embedded: float
    n_unseen: int = 0
    n_conditions: int = 1

    @property
    def unseen(self) -> bool:
        """True when some validation readings lie in a condition the calibration part has not seen."""
        return self.n_unseen > 0

    @property
    def unseen_from_one(self) -> bool:
        """True when the split predicts a condition not seen from a calibration part of one condition: the
        discrepancy's band there is a plug-in from one realisation of the error, not calibrated."""
        return self.unseen and self.n_conditions <= 1

    def coverage(self, kind: str) -> float:
        """The coverage of the ``kind`` ("none", "discrepancy", "embedded") bands."""
        return getattr(self, f"coverage_{'plain' if kind == 'none' else kind}")

    def log_score(self, kind: str) -> float:
        return getattr(self, f"log_score_{'plain' if kind == 'none' else kind}")

    def widening(self, kind: str) -> float:
        return 1.0 if kind == "none" else getattr(self, f"widening_{kind}")

    def to_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return [_jsonable(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None
    if isinstance(v, (np.integer, np.bool_)):
        return v.item()
    return v


@dataclass(frozen=True, eq=False)
class ModelErrorResult(ResultProtocol):
    """The model error of a static model (:func:`identification.studies.model_error.model_error`; the result
    protocol: :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    model_name : str
    kind : str                   "none", "discrepancy" or "embedded": the error model of p, predict, discrepancy
    detected : bool              the test's p-value < alpha
    test : ErrorTest
    alpha : float
    sensors : tuple of str       the sensors the error was estimated on (selected, weight > 0)
    param_names : tuple of str
    p, cov : ndarray             parameters (their units) and covariance under the chosen error model
    p_plain, cov_plain : ndarray  the fit without model error (second-order covariance)
    discrepancies : tuple of SensorDiscrepancy   (kind "discrepancy", else empty)
    embedded : tuple of EmbeddedParameter        (kind "embedded", else empty)
    identifiable : bool          False: the discrepancy can mimic a change of the parameters
    information_kept : float     share of the noise-only information about p the model error leaves (min over
                                 directions; 1 for kind "none")
    correlation_kept : float     share of what uncorrelated errors of the same size would leave (same direction
                                 rule; 1 for kind "none")
    heldout : tuple of HeldOut   one per split (empty without splits)
    exact_at : dict              {input name: value} where the discrepancy and its slope are zero
    sigma : ndarray (n_S,)       sensor standard deviations used (unit of z)
    sigma_source : str           "given" or "pure error (repeated series)"
    how : str                    how ``kind`` was chosen
    notes : tuple of str
    groups : tuple               the distinct condition labels of ``groups`` (empty: none named)
    pure_error : tuple of PureErrorCheck   sigma given and repeated series: the stated sigma of every selected
                                 sensor against its pure error (empty otherwise)
    """

    model_name: str
    kind: str
    detected: bool
    test: ErrorTest
    alpha: float
    sensors: tuple
    param_names: tuple
    p: np.ndarray
    cov: np.ndarray
    p_plain: np.ndarray
    cov_plain: np.ndarray
    discrepancies: tuple
    embedded: tuple
    identifiable: bool
    information_kept: float
    correlation_kept: float
    heldout: tuple
    exact_at: dict
    sigma: np.ndarray
    sigma_source: str
    how: str
    notes: tuple = ()
    fit: ErrorFit | None = field(default=None, repr=False)
    groups: tuple = ()
    pure_error: tuple = ()

    # ------------------------------------------------------------------ numbers
    def conf_int(self, alpha: float | None = None) -> ConfidenceIntervals:
        """Wald intervals p_i -+ z(1 - alpha/2) sqrt(C_ii) under the chosen error model (parameter units)."""
        a = validate_alpha(self.alpha if alpha is None else alpha)
        se = np.sqrt(np.diag(self.cov))
        c = float(stats.norm.ppf(1 - a / 2))
        notes = () if self.identifiable else ("the discrepancy and the parameters cannot be told apart: these "
                                              "intervals are wide for that reason",)
        return ConfidenceIntervals(param_names=self.param_names, estimate=self.p.copy(), lower=self.p - c * se,
                                   upper=self.p + c * se, method="wald", alpha=a, notes=notes)

    def predict(self, inputs, alpha: float = 0.05, new_reading: bool = False, condition=None) -> Band:
        """The outputs at input rows (n*, d_q) (model's input units) with their (1 - alpha) band: parameter
        uncertainty and model error, and with ``new_reading`` the sensor noise of one reading; ``mean``,
        ``lower``, ``upper`` (n*, n_S) in the unit of z, NaN for the sensors not selected.

        ``condition`` (the discrepancy only): one label or one per row (n*,); a label of ``groups`` predicts in
        that condition, :data:`NEW_CONDITION` (or, with groups, any other label) in a condition the data do not
        hold (the discrepancy a new draw of its process: mean 0, its prior band); None (also per row): the data's
        condition (with ``groups`` named: a condition not seen).  The held-out bands of a split:
        ``condition=[NEW_CONDITION if u else None for u in unseen_rows(split, data)]``
        (:func:`identification.studies.model_error.unseen_rows`) on the fit to its calibration part.

        A dynamic model: the input rows are experiments and the arrays are (n*, n_t, n_S), experiments x the
        campaign's sampling times (``band.grid[0]``, the model's time unit) x instruments (``band.sensors``),
        NaN at a time where the campaign holds no reading of that instrument."""
        q = self._inputs(inputs)
        return self._arranged(self.fit.predict(q, validate_alpha(alpha), bool(new_reading),
                                               self._conditions(condition, len(q))))

    def discrepancy(self, inputs, alpha: float = 0.05, condition=None) -> Band:
        """The discrepancy delta(q*) at input rows (n*, d_q) with its (1 - alpha) band (unit of z; zero for
        kind "none", NaN for the sensors not selected) in ``condition`` (as :meth:`predict`); a dynamic model:
        (n*, n_t, n_S) as :meth:`predict`."""
        q = self._inputs(inputs)
        return self._arranged(self.fit.discrepancy(q, validate_alpha(alpha), self._conditions(condition, len(q))))

    def _conditions(self, condition, n: int) -> np.ndarray | None:
        """The integer condition codes (n,) of ``condition`` (-1: a condition not seen), None for the data's one."""
        if condition is None:
            return None if not self.groups else np.full(n, -1)
        labels = [condition] * n if isinstance(condition, (str, bytes)) or not hasattr(condition, "__len__") \
            else list(condition)
        if len(labels) != n:
            raise ValueError(f"condition: expected one label or one per input row ({n}), got {len(labels)}")
        codes = {lab: i for i, lab in enumerate(self.groups)}
        try:
            return np.array([-1 if lab is None and self.groups else 0 if lab is None else
                             -1 if lab == NEW_CONDITION else codes.get(lab, -1 if self.groups else 0) for lab in labels])
        except TypeError:
            raise ValueError("condition: the labels must be hashable (numbers or strings)") from None

    def _arranged(self, band: Band) -> Band:
        """The band per instrument and coordinate (:meth:`identification.fit.problem.ColumnLayout.arrange`)."""
        lay = self.fit.layout
        if lay is None or not lay.coord_names:
            return band
        return dataclasses.replace(band, mean=lay.arrange(band.mean), lower=lay.arrange(band.lower),
                                   upper=lay.arrange(band.upper), sensors=tuple(lay.names), grid=lay.grid)

    def _inputs(self, inputs) -> np.ndarray:
        try:
            q = np.asarray(inputs, float)
        except (TypeError, ValueError):
            raise ValueError(f"inputs: expected numbers of shape (n, {self.fit.model.n_q_dim}), got {inputs!r}") from None
        d = self.fit.model.n_q_dim
        q = q.reshape(-1, 1) if q.ndim == 1 and d == 1 else np.atleast_2d(q)
        if q.ndim != 2 or q.shape[1] != d or q.shape[0] == 0:
            raise ValueError(f"inputs: expected shape (n, {d}) ({', '.join(self.fit.model.inputs)}), got {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError("inputs: every input must be finite")
        return q

    # ------------------------------------------------------------------ tables
    def to_frame(self):
        """The held-out table as a pandas DataFrame indexed by split (``.attrs``: kind, detected, p-value)."""
        import pandas as pd
        df = pd.DataFrame([h.to_dict() for h in self.heldout],
                          columns=list(HeldOut.__dataclass_fields__)).set_index("split")
        df.attrs.update(model=self.model_name, kind=self.kind, detected=self.detected,
                        p_value=self.test.p_value, alpha=self.alpha)
        return df

    def to_dict(self) -> dict:
        """Every number as plain JSON types (NaN and inf as None)."""
        ci = self.conf_int()
        return _jsonable({
            "model": self.model_name, "kind": self.kind, "how": self.how, "detected": self.detected,
            "test": {k: getattr(self.test, k) for k in ErrorTest.__dataclass_fields__}, "alpha": self.alpha,
            "sensors": list(self.sensors), "parameters": list(self.param_names), "p": self.p, "cov": self.cov,
            "conf_int": {"lower": ci.lower, "upper": ci.upper}, "p_plain": self.p_plain, "cov_plain": self.cov_plain,
            "discrepancies": [d.to_dict() for d in self.discrepancies],
            "embedded": [e.to_dict() for e in self.embedded], "identifiable": self.identifiable,
            "information_kept": self.information_kept,
            "correlation_kept": self.correlation_kept, "heldout": [h.to_dict() for h in self.heldout],
            "exact_at": dict(self.exact_at), "sigma": self.sigma, "sigma_source": self.sigma_source,
            "notes": list(self.notes), "groups": [str(g) for g in self.groups],
            "pure_error": [c.to_dict() for c in self.pure_error]})

    def summary(self) -> str:
        """The verdict, the test, the parameters with and without model error, the discrepancy per sensor,
        the held-out table and numbered notes."""
        t = self.test
        lines = [f"Model error of {self.model_name or 'model'}: {'DETECTED' if self.detected else 'not detected'} "
                 f"(likelihood ratio {t.statistic:.4g}, p = {t.p_value:.3g} against {t.reference}, alpha "
                 f"{self.alpha:g}); kind: {self.kind} ({self.how})",
                 f"  sensors: {', '.join(self.sensors)}; sigma {self.sigma_source}; parameters "
                 f"{'identifiable' if self.identifiable else 'NOT identifiable'} under the model error "
                 f"(information kept {100 * self.information_kept:.3g} % of the noise-only)", ""]
        ci = self.conf_int()
        se0 = np.sqrt(np.diag(self.cov_plain))
        lines.append(f"{'parameter':<10} {'p plain':>12} {'se plain':>10} {'p':>12} {'se':>10} "
                     f"{'lower':>12} {'upper':>12}")
        for i, n in enumerate(self.param_names):
            lines.append(f"{n:<10} {self.p_plain[i]:>12.6g} {se0[i]:>10.4g} {self.p[i]:>12.6g} "
                         f"{np.sqrt(self.cov[i, i]):>10.4g} {ci.lower[i]:>12.6g} {ci.upper[i]:>12.6g}")
        if self.discrepancies:
            lines += ["", f"{'sensor':<10} {'s/sigma':>8} {'l (scaled)':>10} {'tau/sigma':>9}"]
            lines += [f"{d.sensor:<10} {d.amplitude / d.sigma:>8.3g} {d.length_scale:>10.3g} "
                      f"{d.rough / d.sigma:>9.3g}" for d in self.discrepancies]
        if self.embedded:
            lines += ["", f"{'parameter':<10} {'omega':>12} {'omega/|p|':>10}  (spread between conditions)"]
            lines += [f"{e.name:<10} {e.omega:>12.4g} {e.relative:>10.3g}" for e in self.embedded]
        if self.heldout:
            lines += ["", f"held-out {100 * (1 - self.alpha):g} % new-reading bands (coverage %, median widening)",
                      f"  {'split':<34} {'n':>4} {'plain':>6} {'discr.':>7} {'widen':>6} {'embed.':>6} {'widen':>6} "
                      f"{'cal. cond.':>10} {'unseen':>6}"]
            lines += [f"  {h.split:<34.34} {h.n_values:>4} {100 * h.coverage_plain:>6.1f} "
                      f"{100 * h.coverage_discrepancy:>6.1f}{'*' if h.unseen_from_one else ' '} "
                      f"{h.widening_discrepancy:>6.2f} {100 * h.coverage_embedded:>6.1f} {h.widening_embedded:>6.2f} "
                      f"{h.n_conditions:>10} {h.n_unseen:>6}" for h in self.heldout]
            if any(h.unseen_from_one for h in self.heldout):
                lines.append("  * readings in a condition not seen, predicted from one condition: not calibrated, "
                             "a lower bound of the error (notes)")
        if self.notes:
            lines += ["", "Notes:"] + [f"[{k}] {n}" for k, n in enumerate(self.notes, 1)]
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        return f"<pre>{escape(self.summary())}</pre>"

    def __repr__(self) -> str:
        return (f"ModelErrorResult(model={self.model_name!r}, kind={self.kind!r}, detected={self.detected}, "
                f"p_value={self.test.p_value:.3g})")
