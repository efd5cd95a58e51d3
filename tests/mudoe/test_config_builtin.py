"""The press behind the registry of built-in models (issue 21): generic config, data and size code
reach the press's variants, scenarios, defaults and virtual prototype through
:mod:`mudoe.registry`, and say the same as before."""
import ast
from pathlib import Path

import numpy as np
import pytest

from mudoe.config import ConfigError, DataConfig, ModelConfig, parse_config
from mudoe.data_io import DataFileError, load_campaign
from mudoe.limits import check_sizes, estimates

MUDOE = Path(__file__).resolve().parents[2] / "mudoe"
#: the generic modules: no built-in model's name, no import of a built-in model's package
GENERIC = ("config.py", "config_errors.py", "config_readers.py", "config_schema.py", "config_sections.py",
           "checks.py", "data_io.py", "data_units.py", "limits.py", "units.py", "csv_stream.py", "data_checks.py",
           "registry.py")
PROTOTYPE = """
[data]
source = "prototype"
n_series = 2
"""


def test_registry_describes_the_press():
    from models.friction import VARIANTS
    from models.press import PRESS_SCENARIO_NAMES
    from models.prototype import CAMPAIGN_SEED
    from mudoe.registry import DEFAULT_MODEL, builtin_model, known_scenarios, known_variants, virtual_prototype
    assert known_variants() == {"press": VARIANTS} and known_scenarios() == PRESS_SCENARIO_NAMES
    assert builtin_model("press").name == DEFAULT_MODEL == ModelConfig().name == "press"
    assert builtin_model("mypkg.models:build") is None
    assert virtual_prototype().set_points == 29 and virtual_prototype().seed == CAMPAIGN_SEED
    cfg = parse_config("")
    assert cfg.model.variants == VARIANTS and cfg.data.seed == CAMPAIGN_SEED == DataConfig().seed
    assert (cfg.data.n_series, cfg.data.directory) == (6, "../data/press_campaign")


@pytest.mark.parametrize("module", GENERIC)
def test_generic_code_never_tests_a_model_name(module):
    """No comparison with the string "press" and no import of models.press / friction / prototype."""
    tree = ast.parse((MUDOE / module).read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            consts = [c.value for c in [node.left, *node.comparators] if isinstance(c, ast.Constant)]
            assert "press" not in consts, f"{module}:{node.lineno}"
        if isinstance(node, ast.ImportFrom) and node.module:
            assert node.module not in ("models.press", "models.friction", "models.prototype"), \
                f"{module}:{node.lineno}"


def test_prototype_refuses_force_correction():
    with pytest.raises(ConfigError) as ei:
        parse_config(PROTOTYPE + "force_correction = true\n", "p.toml")
    assert str(ei.value) == ("p.toml:5: [data] force_correction: the prototype's readings are already corrected; "
                             "force_correction applies to CSV data")


def test_prototype_campaign_and_its_unknown_sensor():
    cfg = parse_config(PROTOTYPE, "p.toml")
    c = load_campaign(cfg, ("D_y", "F_x"))
    assert c.z.shape == (2, 29, 2) and c.series == ("series_1", "series_2")
    assert c.source == "virtual prototype (seed 20190731, 2 series)" and np.isfinite(c.z).all()
    with pytest.raises(DataFileError) as ei:
        load_campaign(cfg, ("D_y", "nope"))
    assert str(ei.value) == ('[data] source = "prototype" provides sensors D_y, F_x, B0_y only; the model asks for '
                             'D_y, nope (set [model] extra_sensors = false)')


def test_sizes_of_the_virtual_prototype_and_the_paper_scenarios():
    cfg = parse_config(PROTOTYPE.replace("n_series = 2", "n_series = 1000000000") + """
[[sensors]]
name = "D_y"
sigma = 1.0
[[sensors]]
name = "F_x"
sigma = 1.0
""", "p.toml")
    sim, = estimates(cfg, "simulate")
    assert (sim.section, sim.key, sim.per_unit_bytes) == ("data", "n_series", 29 * 2 * 36)
    with pytest.raises(ConfigError) as ei:
        check_sizes(cfg, "identify", budget=16e9)
    assert str(ei.value) == ("p.toml:4: [data] n_series: 1000000000 series of the virtual prototype would need at "
                             "least 2.09e+03 GB of memory (this machine has 16 GB); use fewer (this lower bound "
                             "alone allows at most 7662835)")
    runs = estimates(cfg, "validate", runs=10)[-1]
    assert runs.what == "replications x 4 splits x 3 fits"       # scenarios = ["paper"]: the press's four
    own = parse_config('[model]\nname = "pkg.mod:build"\n[splits]\nscenarios = []\n[splits.random]\nn = 2\n')
    assert estimates(own, "validate", runs=10)[-1].what == "replications x 2 splits x 3 fits"


def test_press_entry_gives_what_the_study_asks_of_a_built_in_model():
    """What study code asks of a built-in model instead of testing its name: a variant's model and inputs,
    the rows of its scenarios, the explanations of its diagnosis."""
    from models.press import PRESS_SENSORS
    from mudoe.registry import builtin_model
    press, cfg = builtin_model("press"), parse_config("")
    m, inputs_fn = press.build("M1", cfg)
    assert tuple(m.sensors) == PRESS_SENSORS and inputs_fn is None
    m2, inputs_fn = press.build("M2", cfg)
    assert inputs_fn(np.array([0.0, 100.0, 0.0])).shape[0] == 3
    assert tuple(press.scenario_rows(29)) == press.scenarios
    assert press.explanations(load_campaign(parse_config(PROTOTYPE), PRESS_SENSORS), ("M1", "M2")) == ()
