"""What a report shows of a study: units, display scale, phases, words, and the hooks for later additions.

Everything here is derived from a :class:`mudoe.study.StudyResults` (its models, config and
estimates), so that every page of a report names the study's own quantities: no page
assumes the press.  What a built-in model's study adds to the words (the press: "displacement",
"process force", loading / unloading) arrives as the study's :class:`Presentation`.

Hooks (one documented place each, for results the study does not hold yet):

* :class:`FitAssessment` -- the goodness of fit and the "trust of the linearisation" columns of
  the verdict table, as the study assessed each fit (``StudyResults.assessments``,
  :mod:`mudoe.fit_assessment`).
* :func:`phase_labels` -- a phase label per set point: loading / unloading for the press,
  the model's ``mudoe_phases(q_set)`` (a user declaration, like ``mudoe_inputs``) otherwise,
  or ``None`` (no phases).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["unit_suffix", "Presentation", "OutputDisplay", "output_display",
           "input_label", "param_units", "phase_labels", "GoodnessOfFit", "FitAssessment",
           "fmt_value", "fmt_p", "fmt_pct", "STATISTIC_WORDS", "sensor_unit", "output_label"]

#: plain names of the three statistics
STATISTIC_WORDS = {"likelihood_ratio": "likelihood ratio", "two_sample": "two-sample Wald",
                   "paper": "paper's Wald (calibration covariance only)"}


def unit_suffix(unit: str) -> str:
    """' (unit)' or '' for an empty unit (never 'k1 ()')."""
    return f" ({unit})" if unit else ""


@dataclass(frozen=True)
class Presentation:
    """The words a built-in model's study puts on its pages (the press: the paper's); empty for an own model.

    Attributes
    ----------
    quantity : str        what outputs in mm are ("displacement"), shown in axis labels; "" none
    input_label : str     axis label of the first input without its unit ("process force $q_P$"); "" the
                          input's name
    input_unit : str      unit shown when the model declares none ("N"); "" none
    phases : callable or None   ``phases(q_set) -> tuple of str``, a phase label per set point
                          ("loading" / "unloading"); None: the model's own ``mudoe_phases`` or none
    """

    quantity: str = ""
    input_label: str = ""
    input_unit: str = ""
    phases: object = None


def _first_model(study):
    return next(iter(study.models.values()))


@dataclass(frozen=True)
class OutputDisplay:
    """How model outputs are shown: displayed value = scale * model value, in ``units[k]`` per sensor."""

    scale: float
    units: tuple
    quantity: str        # "displacement" for the press, "" otherwise


def output_display(study) -> OutputDisplay:
    """Outputs in the model's sensor units; lengths in mm are shown in um (the paper's unit)."""
    m = _first_model(study)
    units = tuple(m.sensor_units) if m.sensor_units else ("",) * len(m.sensors)
    if units and all(u == "mm" for u in units):
        return OutputDisplay(1e3, ("um",) * len(units), study.presentation.quantity)
    return OutputDisplay(1.0, units, "")


def sensor_unit(study, sensor: str) -> str:
    """Displayed unit of one sensor ('' when undeclared)."""
    m = _first_model(study)
    d = output_display(study)
    return d.units[list(m.sensors).index(sensor)] if sensor in m.sensors else ""


def output_label(study, sensor: str) -> str:
    """Axis label of one sensor's output: name, quantity (press only) and unit."""
    q = output_display(study).quantity
    return f"{sensor}{(' ' + q) if q else ''}{unit_suffix(sensor_unit(study, sensor))}"


def input_label(study) -> str:
    """Axis label of the first input: its name and unit (the press: 'process force q_P (N)')."""
    m = _first_model(study)
    name = m.inputs[0]
    unit = m.input_units[0] if m.input_units else ""
    shown = study.presentation
    if shown.input_label:
        return f"{shown.input_label}{unit_suffix(unit or shown.input_unit)}"
    return f"{name}{unit_suffix(unit)}"


def param_units(study) -> tuple:
    """Unit of each parameter of the first model ('' when undeclared)."""
    return tuple(p.unit for p in _first_model(study).params)


def phase_labels(study):
    """Phase of every set point (tuple of str), or None when the study declares none.

    The press: 'loading' while the set force does not decrease, 'unloading' after its
    maximum.  Other models: ``model.mudoe_phases(q_set)`` when the model defines it.
    """
    q = np.asarray(study.campaign.q_set, float)
    if study.presentation.phases is not None:
        return tuple(study.presentation.phases(q))
    fn = getattr(_first_model(study), "mudoe_phases", None)
    if fn is None:
        return None
    labels = tuple(str(x) for x in fn(q))
    if len(labels) != q.size:
        raise ValueError(f"mudoe_phases: returned {len(labels)} labels for {q.size} set points")
    return labels


@dataclass(frozen=True)
class GoodnessOfFit:
    """chi2 = sum ((z - h) / sigma)^2 over the used values, its degrees of freedom and p-value.

    ``pvalue`` is NaN when sigma was estimated from the residuals (chi2 = dof by construction).
    """

    chi2: float
    dof: int
    pvalue: float

    def text(self) -> str:
        if not math.isfinite(self.pvalue):
            return "not testable (sigma estimated from the residuals)"
        return f"chi2 = {self.chi2:.4g} on {self.dof} dof, p = {fmt_p(self.pvalue)}"


@dataclass(frozen=True)
class FitAssessment:
    """What the study says of one fit beside its numbers (:func:`mudoe.fit_assessment.assess`).

    goodness : GoodnessOfFit    chi-square test of all used residuals with the sensors' sigma
    trust : str                 the linearisation: "trustworthy", "NOT trustworthy" or "not assessed"
                                (Bates-Watts curvature)
    """

    goodness: GoodnessOfFit
    trust: str


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
