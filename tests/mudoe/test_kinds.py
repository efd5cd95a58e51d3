"""mudoe.kind: one strategy per kind of study, chosen once from the built models (issue 28 item 5)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from mudoe.config import ConfigError, load_config, parse_config
from mudoe.kind import STATIC, TIME_SERIES, kind_of, study_kind
from mudoe.study_base import VariantModel

REPO = Path(__file__).resolve().parents[2]


def test_kind_of_a_model():
    from mudoe.example_cstr import build as cstr
    from mudoe.example_reactor import build as reactor
    assert kind_of(reactor("isothermal")) is TIME_SERIES
    assert kind_of(cstr("arrhenius")) is STATIC
    assert kind_of({"not": "a model"}) is None


def _cfg(tmp_path, extra: str = ""):
    text = (REPO / "configs" / "cstr.toml").read_text().replace('directory = "../data/cstr"',
                                                               f'directory = "{REPO / "data" / "cstr"}"')
    return parse_config(text + extra, str(tmp_path / "study.toml"))


def test_study_kind_refuses_mixed_variants_and_no_model(tmp_path):
    from mudoe.example_cstr import build as cstr
    from mudoe.example_reactor import build as reactor
    cfg = _cfg(tmp_path)
    with pytest.raises(ConfigError, match="mix dynamic"):
        study_kind(cfg, {"a": VariantModel(reactor("isothermal")), "b": VariantModel(cstr("arrhenius"))})
    with pytest.raises(ConfigError, match=r"\('b'\) returned dict, expected a models.Model"):
        study_kind(cfg, {"a": VariantModel(cstr("arrhenius")), "b": VariantModel({})})
    assert study_kind(cfg, {"a": VariantModel(cstr("arrhenius"))}) is STATIC


def test_a_dynamic_section_needs_dynamic_models(tmp_path):
    from mudoe.example_cstr import build as cstr
    cfg = _cfg(tmp_path, "\n[dynamic]\ntimes = [1.0, 2.0]\n[[dynamic.experiments]]\n")
    with pytest.raises(ConfigError, match=r"\[dynamic\] is for dynamic models"):
        study_kind(cfg, {"a": VariantModel(cstr("arrhenius"))})


@pytest.mark.parametrize("name, kind, pages", [("oscillator", TIME_SERIES, "trajectories"), ("cstr", STATIC, "fits")])
def test_a_prepared_study_carries_its_kind(name, kind, pages):
    from mudoe.study import prepare
    study = prepare(load_config(REPO / "configs" / f"{name}.toml"))
    assert study.kind is kind and study.kind.report_pages == pages


def test_quantify_of_a_time_series_study_is_no_longer_refused(tmp_path):
    """model_error takes a dynamic model (issue 29): quantify goes on to read the data (missing here)."""
    from mudoe.study import prepare
    text = (REPO / "configs" / "oscillator.toml").read_text().replace('directory = "../data/oscillator"',
                                                                      f'directory = "{tmp_path / "none"}"')
    cfg = parse_config(text, str(tmp_path / "osc.toml"))
    with pytest.raises(ValueError, match="campaign_long.csv: cannot read"):
        prepare(cfg, command="quantify")


def test_only_the_fit_strategy_reads_the_models_kind():
    """The static/dynamic question is asked once, by the fit strategy (identification.fit.problem.strategy_for);
    mudoe's kind_of maps the strategy to a study kind and asks nothing itself (issue 28 target: the switches of the
    whole repository <= 4: the DynamicModel's flag, strategy_for, the collocation of a DynamicModel)."""
    found = []
    for pkg in ("models", "identification", "oed", "reports", "mudoe"):
        for p in sorted((REPO / pkg).rglob("*.py")):
            for line in p.read_text().splitlines():
                if re.search(r"is_dynamic|isinstance\(.*Dynamic", line):
                    found.append(f"{p.relative_to(REPO)}:{line.strip()}")
    assert found == ["models/collocation.py:if not isinstance(dynamic, DynamicModel):",
                     "models/dynamic.py:is_dynamic = True",
                     "identification/fit/problem.py:return COLLOCATED if getattr(model, \"is_dynamic\", False) else STATIC"]
