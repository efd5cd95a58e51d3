"""The press in a study: what the generic study code asks of a built-in model, answered for the press.

The generic study code (:mod:`mudoe.study`, :mod:`mudoe.study_models`) knows no press: it asks
:func:`mudoe.builtin_studies.builtin_study` for the study of ``[model] name`` and calls its
functions.  The press knowledge itself lives in :mod:`mudoe.press` (variants, friction,
explanations) and :mod:`models.press` (the paper's scenarios); this module only adapts it.
"""
from __future__ import annotations

from identification.studies.splits import splits_from_scenarios
from models.campaign import Campaign
from models.press import PRESS_SCENARIO_NAMES, press_scenario_rows

from .config import StudyConfig
from .press import diagnosis_explanations, press_variant
from .study_base import VariantModel

__all__ = ["NAME", "SIMULATE_REFUSAL", "build_models", "explanations", "scenario_splits"]

#: ``[model] name`` of the press
NAME = "press"

#: why ``mudoe simulate`` does not simulate the press
SIMULATE_REFUSAL = "[simulate] is for own models; the press simulates its virtual prototype"


def build_models(cfg: StudyConfig) -> dict:
    """{variant: VariantModel} of the press variants of the config (before the [[parameters]] bounds)."""
    return {v: VariantModel(*press_variant(v, cfg)) for v in cfg.model.variants}


def explanations(campaign: Campaign, variants) -> tuple:
    """What the press study knows of its diagnostic rejections (:func:`mudoe.press.diagnosis_explanations`)."""
    return diagnosis_explanations(campaign, tuple(variants))


def scenario_splits(n_q: int, wanted) -> list:
    """The paper's scenario splits named in ``wanted`` ("paper": all four) over ``n_q`` set points."""
    names = PRESS_SCENARIO_NAMES if "paper" in wanted else wanted
    return [sp for sp in splits_from_scenarios(press_scenario_rows, n_q) if sp.name in names]
