"""What generic study code knows of a model shipped with mudoe: the interface of a built-in model.

Generic code (the config schema and its checks, the data reader, the size limits, the study) never
tests a model's name; it looks the model up in :mod:`mudoe.registry` and calls what the model's own
study module (the press: :mod:`mudoe.press`) put into its :class:`BuiltinModel`.  A model of a user's
factory ("package.module:function") has no entry: the generic path applies.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

__all__ = ["BuiltinModel", "VirtualPrototype"]


@dataclass(frozen=True)
class VirtualPrototype:
    """A simulated test rig: the campaign of ``[data] source = "prototype"``.

    Attributes
    ----------
    campaign : callable        ``campaign(data, sensors) -> models.campaign.Campaign``: the simulated
                               series of ``data`` (a :class:`mudoe.config_sections.DataConfig`: seed,
                               n_series) for the model's ``sensors``, in the model's units
    check : callable           ``check(data, error)``: refuse [data] keys that do not apply to the
                               prototype, ``error(section, key, msg)`` makes the ConfigError
    set_points : int           set points of one simulated series (the size limits' lower bound)
    seed, n_series : int       defaults of [data] seed and n_series
    generate : callable        ``generate(seed, n_series)``: the rig's whole campaign (``mudoe simulate``)
    write : callable           ``write(campaign, folder) -> list of paths``: that campaign as data files
    """

    campaign: Callable
    check: Callable
    set_points: int
    seed: int
    n_series: int
    generate: Callable
    write: Callable


@dataclass(frozen=True)
class BuiltinModel:
    """A model shipped with mudoe, as generic study code sees it (``[model] name = name``).

    Attributes
    ----------
    name : str                      the [model] name
    variants : tuple of str         the [model] variants it accepts (default: all of them)
    scenarios : tuple of str        names of its splits that ``[splits] scenarios`` may list ("paper": all)
    scenario_rows : callable        ``scenario_rows(n_q)``: the rows of those splits
                                    (:func:`identification.studies.splits.splits_from_scenarios`)
    data_directory : str            the default [data] directory (relative to the shipped configs)
    build : callable                ``build(variant, cfg) -> (models.Model, inputs_fn or None)``: one
                                    variant of a study config (:class:`mudoe.config.StudyConfig`)
    explanations : callable         ``explanations(campaign, variants) -> tuple`` of
                                    :class:`identification.studies.records.Explanation`: what is known of
                                    its diagnostic rejections on this campaign
    prototype : VirtualPrototype or None   its simulated test rig, if it has one
    presentation : identification.studies.records.Presentation or None   the words its report pages use
                                    (None: the generic ones)
    phases : callable or None       ``phases(q_set) -> tuple of str``, a phase label per set point (the press:
                                    loading / unloading); the study computes the labels before the report
                                    (:func:`mudoe.report_record.study_phases`); None: the model's own
                                    ``mudoe_phases`` or none
    """

    name: str
    variants: tuple
    scenarios: tuple
    scenario_rows: Callable
    data_directory: str
    build: Callable
    explanations: Callable
    prototype: VirtualPrototype | None = None
    presentation: object = None
    phases: Callable | None = None
