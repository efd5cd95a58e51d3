"""One schema: config keys backed by settings dataclasses take their defaults, validation and objects."""
import dataclasses

import pytest

from identification.studies.detect import DetectSettings
from identification.studies.montecarlo import MonteCarloSettings
from mudoe.config import (DEFAULT_CONFIG, STUDY_DEFAULTS, ConfigError, DetectConfig, ValidateConfig, known_scenarios,
                          known_variants, load_config, parse_config, settings_keys, settings_values)

SECTIONS = (DetectConfig, ValidateConfig)


def _settings_field(settings, name):
    return next(f for f in dataclasses.fields(settings) if f.name == name)


def test_key_names_map_to_settings_fields_in_one_place():
    assert settings_keys(DetectConfig) == {k: k for k in ("tol", "statistic", "correction", "normality",
                                                          "normality_correction", "covariance")}
    assert settings_keys(ValidateConfig) == {"n_runs": "n_rep", "seed": "seed", "scheduler": "scheduler"}


@pytest.mark.parametrize("section", SECTIONS, ids=lambda c: c.__name__)
def test_one_default_per_setting(section):
    """Every settings-backed key defaults to the settings dataclass's default, or to STUDY_DEFAULTS."""
    cfg = section()
    for f in dataclasses.fields(section):
        if "field" not in f.metadata:
            continue
        settings, name = f.metadata["settings"], f.metadata["field"]
        expected = STUDY_DEFAULTS.get((settings, name), _settings_field(settings, name).default)
        assert getattr(cfg, f.name) == expected, (section.__name__, f.name)


def test_study_defaults_are_the_only_departures_and_keep_the_old_numbers():
    # the CLI / study has always used 200 replications from seed 1 ([validate] without these keys)
    assert STUDY_DEFAULTS == {(MonteCarloSettings, "n_rep"): 200, (MonteCarloSettings, "seed"): 1}
    for (settings, name), value in STUDY_DEFAULTS.items():
        assert _settings_field(settings, name).default != value
    cfg = parse_config("", "empty.toml")
    assert (cfg.validate.n_runs, cfg.validate.seed) == (200, 1)


def test_detect_section_hands_out_the_settings_the_study_built_before():
    cfg = parse_config('[detect]\ntol = 0.1\nstatistic = "paper"\ncorrection = "holm"\nnormality = "override"\n'
                       'normality_correction = "none"\ncovariance = "gauss_newton"\nsensors = "all"\n', "d.toml")
    d = cfg.detect
    assert d.settings() == DetectSettings(tol=d.tol, statistic=d.statistic, correction=d.correction,
                                          normality=d.normality, normality_correction="none",
                                          covariance=d.covariance)
    assert settings_values(d) == {"tol": 0.1, "statistic": "paper", "correction": "holm", "normality": "override",
                                  "normality_correction": "none", "covariance": "gauss_newton"}
    assert parse_config("", "e.toml").detect.settings() == DetectSettings()


def test_validate_section_hands_out_the_settings_validate_built_from_keywords():
    cfg = load_config(DEFAULT_CONFIG)
    vc = cfg.validate
    old = MonteCarloSettings(n_rep=vc.n_runs, seed=vc.seed, workers=3, scheduler=None, progress=False,
                             detect=DetectSettings(tol=cfg.detect.tol, normality="override"))
    assert vc.settings(cfg.detect.tol, 3, False) == old


@pytest.mark.parametrize("text, key, line, words", [
    ("[detect]\ntol = 0.05\n\nstatistic = \"t\"\n", "statistic", 4, ["likelihood_ratio", "two_sample"]),
    ("[detect]\nnormality = \"maybe\"\n", "normality", 2, ["check", "override"]),
    ("[detect]\nnormality_correction = \"sidak\"\n", "normality_correction", 2, ["holm", "bonferroni", "none"]),
    ("[detect]\ncovariance = \"exact\"\n", "covariance", 2, ["second_order"]),
    ("[report]\ntitle = \"x\"\n[validate]\nseed = 2\nn_runs = 0\n", "n_runs", 5, ["at least one replication"]),
    ("[validate]\nseed = -3\n", "seed", 2, ["non-negative"]),
])
def test_settings_errors_name_the_toml_key_file_and_line(text, key, line, words):
    with pytest.raises(ConfigError) as ei:
        parse_config(text, "study.toml")
    msg = str(ei.value)
    assert f"study.toml:{line}:" in msg and f"{key}:" in msg
    assert "n_rep" not in msg
    for w in words:
        assert w in msg


@pytest.mark.parametrize("text, key, line", [
    ("[detect]\ntol = 0.05\nn_rep = 3\n", "n_rep", 3),
    ("[validate]\nseed = 1\nnormality_level = 0.1\n", "normality_level", 3),
    ("[oed]\ncriterion = \"E\"\n\ngap_tol = 1e-3\n", "gap_tol", 4),
    ("[[parameters]]\nname = \"k5\"\nstart = 1.0\nstep = 2\n", "step", 4),
])
def test_unknown_key_in_derived_sections_names_file_and_line(text, key, line):
    with pytest.raises(ConfigError) as ei:
        parse_config(text, "study.toml")
    msg = str(ei.value)
    assert f"study.toml:{line}:" in msg and repr(key) in msg


def test_variants_and_scenarios_come_through_their_hooks():
    cfg = parse_config("", "e.toml")
    assert cfg.model.variants == known_variants()["press"]
    with pytest.raises(ConfigError) as ei:
        parse_config("[model]\nvariants = [\"M4\"]\n", "v.toml")
    assert all(v in str(ei.value) for v in known_variants()["press"])
    name = known_scenarios()[0]
    assert parse_config(f"[splits]\nscenarios = [{name!r}]\n", "s.toml").splits.scenarios == (name,)


@pytest.mark.parametrize("text, words", [
    ("[oed]\nvariant = \"M7\"\n", ["unknown variant 'M7'", "M1, M2, M3"]),
    ("[[sensors]]\nname = \"a\"\nsigma = 1.0\n[detect]\nsensors = [\"b\"]\n", ["unknown sensor 'b'", "a"]),
    ("[data]\nlayout = \"wide\"\n", ["unknown value 'wide'", "paper, tidy"]),
    ("[report]\ndpi = 0\n", ["must be positive"]),
    ("[splits.random]\nn = 2\ncal_fraction = 0.0\n", ["must lie in (0, 1)"]),
    ("[data]\nn_series = 1\n", ["at least 2"]),
    ("[[parameters]]\nname = \"k5\"\n", ["needs name, start", "add start"]),
])
def test_one_validator_each_names_the_allowed_values(text, words):
    with pytest.raises(ConfigError) as ei:
        parse_config(text, "study.toml")
    for w in words:
        assert w in str(ei.value)


def test_integer_numbers_keep_their_toml_type():
    cfg = parse_config("[[sensors]]\nname = \"a\"\nsigma = 5\n[[parameters]]\nname = \"k\"\nstart = 5\n", "i.toml")
    assert type(cfg.sensors[0].sigma) is int and type(cfg.parameters[0].start) is float
