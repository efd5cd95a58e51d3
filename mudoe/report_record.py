"""The one record a report draws, filled by the study: :func:`study_record` of a :class:`mudoe.study.StudyResults`.

The report (:mod:`reports`) reads an :class:`oed.study_record.StudyRecord` and nothing of the study
layer: what it used to ask while drawing is computed here first -- the config as a
:class:`oed.study_record.ConfigRecord` (its values, ``StudyConfig.as_dict()``), where the data came
from, and the phase of every set point (:func:`study_phases`: a built-in model's ``phases``, or an own
model's ``mudoe_phases(q_set)``).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from oed.study_record import ConfigRecord, DataSource, StudyRecord, StudySetup

from .registry import builtin_model

__all__ = ["study_phases", "config_record", "study_setup", "study_record"]


def study_phases(study) -> tuple | None:
    """Phase of every set point (tuple of str), or None when the study declares none.

    The press (its :attr:`mudoe.builtin.BuiltinModel.phases`): 'loading' while the set force does not
    decrease, 'unloading' after its maximum.  Other models: ``model.mudoe_phases(q_set)`` when the
    first model defines it (one label per set point).

    Raises
    ------
    ValueError
        ``mudoe_phases`` returned a number of labels other than the number of set points.
    """
    q = np.asarray(study.campaign.q_set, float)
    declared = study.presentation.phases                    # deprecated: Presentation(phases=...)
    if declared is None:
        builtin = builtin_model(study.cfg.model.name)
        declared = builtin.phases if builtin is not None else None
    if declared is not None:
        return tuple(declared(q))
    fn = getattr(next(iter(study.models.values())), "mudoe_phases", None)    # a user declaration, optional
    if fn is None:
        return None
    labels = tuple(str(x) for x in fn(q))
    if len(labels) != q.size:
        raise ValueError(f"mudoe_phases: returned {len(labels)} labels for {q.size} set points")
    return labels


def config_record(cfg) -> ConfigRecord:
    """What a report shows of a :class:`mudoe.config.StudyConfig`."""
    series = cfg.data.series
    return ConfigRecord(path=str(cfg.path), text=cfg.text, values=cfg.as_dict(), title=cfg.report.title,
                        dpi=int(cfg.report.dpi), uncertainty=cfg.report.uncertainty,
                        series=None if series is None else tuple(series))


def study_setup(study) -> StudySetup:
    """What a report shows of a :class:`mudoe.study.Study` (static or dynamic)."""
    c = study.campaign
    source = DataSource(source=c.source, files=tuple(c.files), sha256=c.sha256, n_M=c.n_M, n_q=c.n_q)
    kind = study.kind
    rows = kind.report_pages == "fits"                      # the pages against the set point: campaign and phases
    shown = study.presentation
    if shown.phases is not None:                            # the labels are data below; the callable stays here
        shown = dataclasses.replace(shown, phases=None)
    return StudySetup(config=config_record(study.cfg), source=source, campaign=c if rows else None,
                      sensors=tuple(study.sensors), sigma=study.sigma, sigma_table=tuple(study.sigma_table),
                      normality=study.normality, models=dict(study.models), data=dict(study.data), p0=study.p0,
                      splits=tuple(study.splits), notes=tuple(study.notes), presentation=shown,
                      phases=study_phases(study) if rows else None, inputs=None if rows else study.inputs,
                      pages=kind.report_pages, input_rows=kind.input_rows, normality_over=kind.normality_over,
                      truth=study.truth)


def study_record(results) -> StudyRecord:
    """The :class:`oed.study_record.StudyRecord` of a :class:`mudoe.study.StudyResults`: its setup
    (:func:`study_setup`) and every result the report draws."""
    r = results
    return StudyRecord(study=study_setup(r.study), estimates=dict(r.estimates), estimate_errors=dict(r.estimate_errors),
                       assessments=dict(r.assessments), oed=r.oed, oed_table=r.oed_table, oed_variant=r.oed_variant,
                       plan=r.plan, design_sensors=tuple(r.design_sensors), design_how=r.design_how,
                       detection=r.detection, detection_error=r.detection_error, diagnosis=r.diagnosis,
                       uncertainty=dict(r.uncertainty), bands=dict(r.bands), validation=r.validation,
                       model_error=dict(r.model_error), model_error_errors=dict(r.model_error_errors),
                       model_error_views=dict(r.model_error_views), trajectories=dict(r.trajectories),
                       discretisation=dict(r.discretisation), timing=dict(r.timing), notes=tuple(r.notes))
