"""Study config: defaults, the shipped press.toml, unknown keys (file and line), bad values."""
import math

import pytest

from mudoe.config import DEFAULT_CONFIG, ConfigError, load_config, parse_config


def test_shipped_press_config_parses_with_paper_values():
    cfg = load_config(DEFAULT_CONFIG)
    assert cfg.model.variants == ("M1", "M2", "M3")
    assert cfg.data.series == (4, 5)
    assert cfg.length_factor == 1e-3 and cfg.force_factor == 1.0
    assert [s.sigma_man for s in cfg.sensors] == [14.142, 3.6055, 3.6055]
    assert cfg.oed.criterion == "E" and cfg.oed.n_sensors == 2
    assert cfg.detect.tol == 0.05
    assert cfg.resolve(cfg.data.directory).resolve() == (DEFAULT_CONFIG.parent.parent / "data" / "press_campaign")


def test_empty_config_gives_defaults():
    cfg = parse_config("", "empty.toml")
    assert cfg.model.name == "press" and cfg.data.layout == "paper" and cfg.splits.scenarios == ("paper",)
    assert cfg.detect.statistic == "likelihood_ratio" and cfg.oed.kind == "second_order"
    assert cfg.parameters == () and cfg.sensors == ()


def test_units_converted_once():
    cfg = parse_config('[data]\ndisplacement_unit = "m"\nforce_unit = "kN"\n', "u.toml")
    assert cfg.length_factor == 1e3 and cfg.force_factor == 1e3


@pytest.mark.parametrize("text, key, line", [
    ("[model]\nname = \"press\"\ncolour = 3\n", "colour", 3),
    ("[data]\nlayout = \"paper\"\n\n[data.files]\nX = \"a.csv\"\n[detect]\ntoll = 0.1\n", "toll", 7),
    ("bogus = 1\n", "bogus", 1),
    ("[[sensors]]\nname = \"D_y\"\nsigmaa = 1.0\n", "sigmaa", 3),
    ("[splits.random]\nn = 2\nseeed = 3\n", "seeed", 3),
])
def test_unknown_key_names_key_file_and_line(text, key, line):
    with pytest.raises(ConfigError) as ei:
        parse_config(text, "study.toml")
    msg = str(ei.value)
    assert f"study.toml:{line}:" in msg and repr(key) in msg


@pytest.mark.parametrize("text, words", [
    ("[model]\nname = \"lathe\"\n", ["unknown model", "lathe"]),
    ("[model]\nvariants = [\"M9\"]\n", ["unknown variant", "M9"]),
    ("[[sensors]]\nname = \"D_y\"\nsigma = -1.0\n", ["sigma must be positive"]),
    ("[[sensors]]\nname = \"D_y\"\nsigma_man = -1.0\n", ["sigma_man must be non-negative"]),
    ("[data]\ndisplacement_unit = \"N\"\n", ["expected a unit of length", "'mm', 'um', 'm'", "a unit of force"]),
    ("[data]\nforce_unit = \"parsec\"\n", ["expected a unit of force", "'parsec', a unit of length"]),
    ("[data]\noutput_unit = \"furlongs_x\"\n", ["unknown unit 'furlongs_x'"]),
    ("[detect]\ntol = 1.5\n", ["TOL must lie in (0, 1)"]),
    ("[detect]\nstatistic = \"t\"\n", ["likelihood_ratio", "two_sample"]),
    ("[[parameters]]\nname = \"k5\"\nstart = 5.0\nlower = 10.0\n", ["outside"]),
    ("[splits]\nscenarios = [\"nope\"]\n", ["unknown scenario"]),
    ("[oed]\ncriterion = \"Q\"\n", ["A, D, E"]),
    ("[data]\nseries = [-1]\n", ["0-based"]),
    ("[model\n", ["invalid TOML"]),
])
def test_bad_values_are_config_errors(text, words):
    with pytest.raises(ConfigError) as ei:
        parse_config(text, "study.toml")
    for w in words:
        assert w in str(ei.value)


def test_custom_and_random_splits_parse():
    cfg = parse_config("[splits]\nscenarios = []\n[splits.random]\nn = 3\n[[splits.custom]]\nname = \"a\"\n"
                       "cal_inputs = [1, 2, 3]\nval_inputs = [4, 5, 6]\n", "s.toml")
    assert cfg.splits.random.n == 3 and cfg.splits.custom[0].cal_inputs == (1, 2, 3)
    assert cfg.splits.custom[0].cal_series is None


def test_custom_splits_take_sensor_columns_and_check_them():
    text = ("[splits]\nscenarios = []\n[[splits.custom]]\nname = \"a\"\ncal_inputs = [1, 2]\nval_inputs = [1, 2]\n"
            "cal_sensors = [0, 1]\nval_sensors = [2]\n")
    c = parse_config(text, "s.toml").splits.custom[0]
    assert (c.cal_sensors, c.val_sensors) == ((0, 1), (2,))
    with pytest.raises(ConfigError, match=r"s.toml:\d+: \[\[splits.custom\]\] val_inputs: .*overlap"):
        parse_config(text.replace("val_sensors = [2]", "val_sensors = [1, 2]"), "s.toml")
    with pytest.raises(ConfigError, match=r"s.toml:7: \[splits.custom\] cal_sensors: indices are 0-based"):
        parse_config(text.replace("cal_sensors = [0, 1]", "cal_sensors = [-1]"), "s.toml")


def test_missing_config_file(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "nope.toml")


def test_as_dict_is_json_ready():
    import json
    d = load_config(DEFAULT_CONFIG).as_dict()
    json.dumps(d)
    assert d["data"]["series"] == [4, 5] and not math.isnan(d["detect"]["tol"])
