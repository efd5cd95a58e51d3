"""What a report shows of a study: units, display scale, phases and words.

Everything here is derived from the study's :class:`oed.study_record.StudySetup` (its models, words
and phases), so that every page of a report names the study's own quantities: no page assumes the
press.  What a built-in model's study adds to the words (the press: "displacement", "process force")
arrives as the setup's :class:`identification.studies.records.Presentation`; the phase of every set
point (loading / unloading for the press, an own model's ``mudoe_phases``) as its ``phases``, computed
by the study before the report (:func:`mudoe.report_record.study_phases`).

The records this module used to define (``Presentation``, ``OutputDisplay``, ``GoodnessOfFit``,
``FitAssessment``) live in :mod:`identification.studies.records`; their old names here still work
(deprecated), as do the number formats (:func:`fmt_value`, :func:`fmt_p`, :func:`fmt_pct`,
:func:`unit_suffix`) they need.
"""
from __future__ import annotations

import identification.studies.records as _records
from identification.studies.records import OutputDisplay, fmt_p, fmt_pct, fmt_value, unit_suffix

from .moved import moved

__all__ = ["unit_suffix", "output_display", "input_label", "param_units", "phase_labels", "fmt_value", "fmt_p",
           "fmt_pct", "STATISTIC_WORDS", "sensor_unit", "output_label"]

__getattr__ = moved(__name__, _records, ("Presentation", "OutputDisplay", "GoodnessOfFit", "FitAssessment"))

#: plain names of the three statistics
STATISTIC_WORDS = {"likelihood_ratio": "likelihood ratio", "two_sample": "two-sample Wald",
                   "paper": "paper's Wald (calibration covariance only)"}


def _first_model(study):
    return next(iter(study.models.values()))


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
    """Phase of every set point (tuple of str), or None when the study declares none: the setup's
    ``phases``, as the study computed them (:func:`mudoe.report_record.study_phases`)."""
    return study.phases
