"""The kinds of study: one strategy per kind of model, chosen once from the built models.

:class:`~mudoe.kind.base.StudyKind` names what differs (the data format and its config section,
the design run, what the report draws, how models are bounded and started, the template);
:data:`STATIC` (:mod:`mudoe.kind.static`: a model of set points, wide CSV) and
:data:`TIME_SERIES` (:mod:`mudoe.kind.time_series`: an ODE/DAE model, long time-series CSV,
``[dynamic]``) implement it.  :func:`study_kind` is the one place that looks at the models to choose;
everything else asks ``study.kind``.
"""
from __future__ import annotations

from models.contract import Model

from ..config import ConfigError, StudyConfig
from .base import Simulation, StudyKind
from .static import STATIC, StaticKind
from .time_series import TIME_SERIES, TimeSeriesKind

__all__ = ["StudyKind", "Simulation", "StaticKind", "TimeSeriesKind", "STATIC", "TIME_SERIES", "kind_of",
           "study_kind"]


def kind_of(model) -> StudyKind | None:
    """The kind of study of one model: :data:`TIME_SERIES` for an ODE/DAE model, :data:`STATIC` for a
    :class:`models.Model`, None for anything else (not a model mudoe can study)."""
    if getattr(model, "is_dynamic", False):
        return TIME_SERIES
    return STATIC if isinstance(model, Model) else None


def study_kind(cfg: StudyConfig, built: dict) -> StudyKind:
    """The kind of the study's variants ({variant: VariantModel}), checked against the config.

    Raises
    ------
    ConfigError
        A variant that is no model, variants of different kinds, or a ``[dynamic]`` section for
        static models.
    """
    kinds = {}
    for v, b in built.items():
        kinds[v] = kind_of(b.model)
        if kinds[v] is None:
            raise ConfigError(f"{cfg.path}: [model] name: {cfg.model.name}({v!r}) returned "
                              f"{type(b.model).__name__}, expected a models.Model")
    found = set(kinds.values())
    if len(found) > 1:
        raise ConfigError(f"{cfg.path}: [model] variants mix dynamic (ODE/DAE) and static models")
    kind = found.pop() if found else STATIC
    if cfg.dynamic is not None and kind is not TIME_SERIES:
        raise ConfigError(f"{cfg.path}: [dynamic] is for dynamic models (models.Model.ode); {cfg.model.name} "
                          "returns a static model")
    return kind
