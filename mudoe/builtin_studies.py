"""The models the package ships with a study of their own (the press), looked up by ``[model] name``.

Generic study code asks :func:`builtin_study` and calls what it returns; it names no built-in
model.  A :class:`BuiltinStudy` says how to build the variants, what the study knows of its
diagnostic rejections and why ``mudoe simulate`` does not apply; :func:`scenario_splits` gives
the named scenario splits the package ships (``[splits] scenarios``: the paper's).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from . import press_study

__all__ = ["BuiltinStudy", "builtin_study", "scenario_splits"]


@dataclass(frozen=True)
class BuiltinStudy:
    """What the study of a built-in model adds to the generic study.

    build_models(cfg) -> {variant: VariantModel}; explanations(campaign, variants) -> tuple of
    :class:`reports.diagnosis.Explanation`; simulate_refusal: why ``mudoe simulate`` does not apply.
    """

    name: str
    build_models: Callable
    explanations: Callable
    simulate_refusal: str


_BUILTIN = {press_study.NAME: BuiltinStudy(press_study.NAME, press_study.build_models, press_study.explanations,
                                           press_study.SIMULATE_REFUSAL)}


def builtin_study(name: str) -> BuiltinStudy | None:
    """The built-in study of ``[model] name`` (None: a model of the user's, ``"package.module:function"``)."""
    return _BUILTIN.get(name)


def scenario_splits(n_q: int, wanted) -> list:
    """The shipped scenario splits named in ``wanted`` (``[splits] scenarios``; "paper": the paper's four)."""
    return press_study.scenario_splits(n_q, wanted)
