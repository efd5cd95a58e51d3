"""The kinds of study: one strategy per kind of model, chosen once from the built models.

:class:`~mudoe.kind.base.StudyKind` names what differs (the data format and its config section,
the design run, what the report draws, how models are bounded and started, the template);
:data:`STATIC` (:mod:`mudoe.kind.static`: a model of set points, wide CSV) and
:data:`TIME_SERIES` (:mod:`mudoe.kind.time_series`: an ODE/DAE model, long time-series CSV,
``[dynamic]``) implement it.  :func:`study_kind` is the one place that looks at the models to choose,
by their fit strategy (:func:`kind_of`); everything else asks ``study.kind``.
"""
from __future__ import annotations

from identification.fit.problem import CollocatedStrategy, StaticStrategy, strategy_for

from ..config import ConfigError, StudyConfig
from .base import Simulation, StudyKind
from .static import STATIC, StaticKind
from .time_series import TIME_SERIES, TimeSeriesKind

__all__ = ["StudyKind", "Simulation", "StaticKind", "TimeSeriesKind", "STATIC", "TIME_SERIES", "kind_of",
           "study_kind"]


#: the study kind of each of the fit floor's strategies (:mod:`identification.fit.problem`)
_BY_STRATEGY = {StaticStrategy: STATIC, CollocatedStrategy: TIME_SERIES}


def kind_of(model) -> StudyKind | None:
    """The kind of study of one model: that of its fit strategy
    (:func:`identification.fit.problem.strategy_for`, the one place the kind of a model is asked):
    :data:`TIME_SERIES` for an ODE/DAE model (collocated), :data:`STATIC` for a static
    :class:`models.Model`; None for anything else (not a model mudoe can study)."""
    strategy = strategy_for(model)
    return _BY_STRATEGY[type(strategy)] if isinstance(model, strategy.model_type) else None


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
