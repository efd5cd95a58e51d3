"""Generic data: any unit through one unit table, both layouts, parameter units, [simulate] checks."""
import json
import textwrap

import numpy as np
import pytest

from mudoe.cli import main
from mudoe.config import ConfigError, parse_config
from mudoe.data_io import DataFileError, DataUnits, read_paper_layout, read_tidy_layout, study_units, \
    write_paper_layout, write_tidy_layout
from mudoe.example_cstr import build
from mudoe.outdir import MARKER
from mudoe.units import UnitError, convert


def test_unit_table_conversions():
    assert convert(20.0, "degC", "K") == pytest.approx(293.15, abs=1e-12)
    assert convert(293.15, "K", "degC") == pytest.approx(20.0, abs=1e-12)
    assert convert(212.0, "degF", "degC") == pytest.approx(100.0, abs=1e-12)
    assert convert(1.0, "degC", "K", difference=True) == 1.0          # a sigma of 1 degC is 1 K
    np.testing.assert_allclose(convert(np.array([1.0, 0.5]), "mol/L", "mmol/L"), [1000.0, 500.0])
    np.testing.assert_allclose(convert(np.array([1500.0]), "um", "mm"), [1.5])
    assert convert(2.0, "kN", "N") == 2000.0
    with pytest.raises(UnitError, match="temperature is not concentration"):
        convert(1.0, "degC", "mol/L")
    assert convert(1.0, "in", "mm") == pytest.approx(25.4, rel=1e-14)          # any unit pint knows
    assert convert(1.0, "lbf", "N") == pytest.approx(4.4482216152605, rel=1e-14)
    with pytest.raises(UnitError, match="unknown unit 'furlongs_x'"):
        convert(1.0, "furlongs_x", "m")


def _cstr_cfg(extra_data="", sensors=None, params=""):
    sensors = sensors if sensors is not None else "".join(
        f'[[sensors]]\nname = "{s}"\nsigma = 0.004\n' for s in ("C_A", "C_B", "C_C")) + \
        '[[sensors]]\nname = "X_A"\nsigma = 0.5\nunit = "%"\n'
    return parse_config(textwrap.dedent(f"""\
        [model]
        name = "mudoe.example_cstr:build"
        variants = ["arrhenius"]
        [data]
        input_unit = "degC"
        output_unit = "mol/L"
        {extra_data}
        """) + sensors + params, "cstr.toml")


def test_study_units_from_model_and_config():
    u = study_units(_cstr_cfg(), build())
    assert (u.input_file, u.input_model, u.input_name) == ("degC", "K", "T")
    assert u.output_file == ("mol/L",) * 3 + ("%",) and u.output_model == ("mmol/L",) * 3 + ("%",)
    assert u.sigma_to_model(0, 0.004) == pytest.approx(4.0)


def test_incompatible_unit_is_a_config_error():
    import dataclasses
    cfg = _cstr_cfg()
    bad = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, input_unit="mol/L"))
    with pytest.raises(ConfigError, match=r"cstr.toml: \[data\] input_unit: input 'T': cannot convert mol/L to K"):
        study_units(bad, build())


def test_paper_layout_round_trip_in_degC_and_mol_per_L(tmp_path):
    u = study_units(_cstr_cfg(), build())
    m = build()
    T = np.linspace(293.15, 353.15, 7)
    h = m.simulate([0.08, 60.0, 0.04], T[:, None])
    z = h[None] + np.random.default_rng(3).standard_normal((2,) + h.shape)
    paths = write_paper_layout(tmp_path, T, z, m.sensors, units=u)
    head = paths[0].read_text().splitlines()[0]
    assert head.startswith("T_degC,") and paths[0].read_text().splitlines()[1].startswith("20.0")
    c = read_paper_layout({s: p for s, p in zip(m.sensors, paths)}, units=u)
    np.testing.assert_allclose(c.q_set, T, rtol=1e-14)
    np.testing.assert_allclose(c.z, z, rtol=1e-13)


def test_tidy_layout_round_trip_and_header_unit_checks(tmp_path):
    cfg = _cstr_cfg(sensors="".join(f'[[sensors]]\nname = "{s}"\nsigma = 0.004\n' for s in ("C_A", "C_B", "C_C"))
                    + '[[sensors]]\nname = "X_A"\nsigma = 0.004\nunit = "1"\n')
    m = build()
    u = study_units(cfg, m)
    assert u.output_file[-1] == "1" and u.output_model[-1] == "%"
    T = np.linspace(293.15, 353.15, 5)
    z = m.simulate([0.08, 60.0, 0.04], T[:, None])[None].repeat(2, axis=0)
    f = write_tidy_layout(tmp_path / "t.csv", T, z, m.sensors, units=u)
    text = f.read_text()
    assert text.splitlines()[0] == "series,index,set_T_degC,sensor,value"   # mixed units: no suffix
    c = read_tidy_layout(f, sensors=m.sensors, units=u)
    np.testing.assert_allclose(c.z, z, rtol=1e-13)
    # an input column in another temperature unit is converted by pint (the header says what it is)
    f.write_text(text.replace("set_T_degC", "set_T_K", 1))
    np.testing.assert_allclose(read_tidy_layout(f, sensors=m.sensors, units=u).q_set, T - 273.15, rtol=1e-12)
    f.write_text(text.replace("set_T_degC", "set_T_mol", 1))
    with pytest.raises(DataFileError, match=r"t.csv:1: column 'set_T_mol' is in mol .*a unit of \[substance\]\) but "
                                            r"the config declares input_unit = 'degC', a unit of temperature"):
        read_tidy_layout(f, sensors=m.sensors, units=u)
    f.write_text(text.replace(",value", ",value_mol/L", 1))
    with pytest.raises(DataFileError, match="different units"):
        read_tidy_layout(f, sensors=m.sensors, units=u)


def test_press_units_are_one_case_of_the_table(tmp_path, synthetic):
    q, z, sensors = synthetic
    u = DataUnits("kN", "N", ("m",) * 3, ("mm",) * 3)
    write_paper_layout(tmp_path, q, z, sensors, units=u)
    assert (tmp_path / "measurements_D_y.csv").read_text().startswith("force_kN,")
    c = read_paper_layout({s: tmp_path / f"measurements_{s}.csv" for s in sensors}, "m", "kN")
    np.testing.assert_allclose(c.z, z, rtol=1e-13)


def test_parameter_unit_key(tmp_path):
    params = "".join(f'[[parameters]]\nname = "{n}"\nstart = {v}\nunit = "{u}"\n'
                     for n, v, u in (("k_ref", 0.1, "1/min"), ("E_a", 50.0, "kJ/mol"), ("k_2", 0.05, "1/min")))
    cfg = _cstr_cfg(params=params)
    assert [p.unit for p in cfg.parameters] == ["1/min", "kJ/mol", "1/min"]
    from mudoe.study_models import apply_parameters, config_start_values
    # another unit of the same dimension: start and bounds converted by pint to the model's kJ/mol
    cfg_j = _cstr_cfg(params=params.replace('start = 50.0\nunit = "kJ/mol"', 'start = 5e4\nunit = "J/mol"'))
    m = apply_parameters(cfg_j, build())
    assert config_start_values(cfg_j, m)[1] == pytest.approx(50.0, rel=1e-14) and m.params[1].unit == "kJ/mol"
    with pytest.raises(ConfigError, match=r"E_a: unit '1/s' but the model declares 'kJ/mol': cannot convert"):
        apply_parameters(_cstr_cfg(params=params.replace('"kJ/mol"', '"1/s"')), build())


def test_unknown_unit_in_config_names_the_line():
    with pytest.raises(ConfigError, match=r"u.toml:2: \[data\] input_unit: unknown unit 'Celsius'"):
        parse_config('[data]\ninput_unit = "Celsius"\n', "u.toml")


@pytest.mark.parametrize("section, msg", [
    ("[simulate]\ninputs = [1.0]\ninput_start = 0.0\ninput_stop = 1.0\n", "not both"),
    ("[simulate]\ninput_start = 0.0\n", "give both input_start and input_stop"),
    ("[simulate]\ninputs = []\n", "non-empty list of numbers"),
    ("[simulate]\nn_series = 1\n", r"\[simulate\] n_series: must be at least 2"),
    ("[simulate]\ntruth = {a = \"x\"}\n", "expected a number"),
])
def test_simulate_section_errors(section, msg):
    with pytest.raises(ConfigError, match=msg):
        parse_config(section, "s.toml")


def test_simulate_own_study_writes_its_own_layout_not_press_data(tmp_path, capsys, cstr_config):
    cfg = cstr_config(tmp_path, layout="paper")
    out = tmp_path / "data"
    assert main(["simulate", str(cfg), "--out", str(out), "--quiet", "--json", "--seed", "3"]) == 0
    rec = json.loads(capsys.readouterr().out)
    names = sorted(p.name for p in out.iterdir() if p.name != MARKER)
    assert names == ["measurements_C_A.csv", "measurements_C_B.csv", "measurements_C_C.csv", "measurements_X_A.csv",
                     "simulate.json"]
    assert rec["truth"] == {"k_ref": 0.08, "E_a": 60.0, "k_2": 0.04} and rec["seed"] == 3
    assert (out / "measurements_C_A.csv").read_text().startswith("T_degC,series_1,series_2,series_3,series_4\n20.0,")


def test_simulate_without_set_points_is_one_line(tmp_path, capsys, cstr_config):
    cfg = cstr_config(tmp_path)
    cfg.write_text("\n".join(ln for ln in cfg.read_text().splitlines() if not ln.startswith("input_")) + "\n")
    assert main(["simulate", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[simulate] give the set points" in err[0]
    assert not (tmp_path / "o").exists()


def test_simulate_press_keeps_the_virtual_prototype(tmp_path, capsys):
    from mudoe.config import DEFAULT_CONFIG
    cfg = tmp_path / "press.toml"
    cfg.write_text(DEFAULT_CONFIG.read_text().replace("n_series = 6", "n_series = 2"))
    out = tmp_path / "p"
    assert main(["simulate", str(cfg), "--out", str(out), "--quiet", "--seed", "5"]) == 0
    assert (out / "measurements_D_y.csv").is_file() and (out / "campaign_long.csv").is_file()
