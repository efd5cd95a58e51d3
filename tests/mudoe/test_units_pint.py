"""Units through pint (issue 20 items 6 and 8): any unit pint knows, conversions by pint, no silent default.

An accelerometer model a = k F (sensor in m/s^2, input in N) fitted to 3 series x 10 loads with
sigma known: the standard error of k is exactly sigma / sqrt(n_M sum F^2) (linear model), so a
unit applied wrongly (the issue's "" read as micrometres: data x 1000, stderr 100x too small)
shows as a wrong standard error, not only a wrong label.
"""
import json
import math
import sys
import textwrap

import numpy as np
import pytest

from mudoe.cli import main
from mudoe.data_checks import ABSURD_RATIO, absurd_reading
from mudoe.data_io import DataUnits, write_paper_layout
from mudoe.units import UnitError, check_unit, convert, dimension

ACCEL = '''
from models.contract import Model


def build(variant):
    units = ("m/s^2",) if variant == "declared" else ("",)
    return Model.explicit(["k"], ["F"], ["a"], h=lambda p, q: [p[0] * q[0]], name=f"accelerometer {variant}",
                          sensor_units=units, input_units=("N",))
'''
F = np.linspace(1.0, 10.0, 10)
SIGMA = 0.05
N_M = 3


@pytest.fixture()
def accel(tmp_path, monkeypatch):
    pkg = tmp_path / "accel_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "acc.py").write_text(ACCEL)
    monkeypatch.syspath_prepend(str(tmp_path))
    z = 0.5 * F[None, :, None] + SIGMA * np.random.default_rng(4).standard_normal((N_M, F.size, 1))
    for unit in ("m/s^2", "mm/s^2"):
        write_paper_layout(tmp_path / unit.replace("/", "_per_"), F, z, ["a"],
                           units=DataUnits("N", "N", (unit,), ("m/s^2",)))

    def config(variant, unit_line="", data="m_per_s^2", sigma=SIGMA):
        cfg = tmp_path / f"{variant}.toml"
        cfg.write_text(textwrap.dedent(f"""\
            [model]
            name = "accel_pkg.acc:build"
            variants = ["{variant}"]
            [data]
            directory = "{data}"
            [[sensors]]
            name = "a"
            sigma = {sigma}
            {unit_line}
            [[parameters]]
            name = "k"
            start = 1.0
            [splits]
            scenarios = []
            [splits.random]
            n = 2
            """))
        return cfg

    yield config, tmp_path
    for name in [m for m in sys.modules if m.startswith("accel_pkg")]:
        del sys.modules[name]


def _identify(capsys, cfg, tmp_path, variant):
    assert main(["identify", str(cfg), "--out", str(tmp_path / "out"), "--json", "--quiet"]) == 0
    est = json.loads(capsys.readouterr().out)[variant]
    return est["p"][0], est["stderr"][0]


def _one_line(capsys, argv):
    rc = main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_pint_units_parse_convert_and_refuse():
    assert check_unit("m/s^2") == "m/s^2" and dimension("m/s^2") == "acceleration"
    assert dimension("lbf") == dimension("N") == "force" and dimension("parsec") == "length"
    assert convert(1.0, "mm/s^2", "m/s^2") == pytest.approx(1e-3, rel=1e-15)
    assert convert(np.array([1500.0]), "um", "mm")[0] == 1.5                   # the press: bit for bit
    assert convert(1.0, "mol/m3", "mmol/L") == pytest.approx(1.0, rel=1e-14)    # bare power read as m^3
    with pytest.raises(UnitError, match="cannot convert parsec to N: length is not force"):
        convert(1.0, "parsec", "N")
    with pytest.raises(UnitError, match="cannot convert an undeclared unit to m"):
        convert(1.0, "", "m")


def test_sensor_in_m_per_s2_is_accepted_and_its_standard_error_is_exact(capsys, accel):
    config, tmp = accel
    se_exact = SIGMA / math.sqrt(N_M * np.sum(F ** 2))
    k, se = _identify(capsys, config("declared"), tmp, "declared")
    assert se == pytest.approx(se_exact, rel=1e-6) and abs(k - 0.5) < 4 * se
    # the same data in mm/s^2 (file and sigma): converted by pint, the same estimate
    k2, se2 = _identify(capsys, config("declared", 'unit = "mm/s^2"', "mm_per_s^2", 1e3 * SIGMA), tmp, "declared")
    assert k2 == pytest.approx(k, rel=1e-9) and se2 == pytest.approx(se_exact, rel=1e-6)
    # the model declares no unit, the config does: the data are passed as declared (no x1000)
    k3, se3 = _identify(capsys, config("undeclared", 'unit = "m/s^2"'), tmp, "undeclared")
    assert k3 == pytest.approx(k, rel=1e-9) and se3 == pytest.approx(se_exact, rel=1e-6)


def test_undeclared_unit_is_an_error_naming_the_key(capsys, accel):
    config, tmp = accel
    line = _one_line(capsys, ["identify", str(config("undeclared")), "--out", str(tmp / "o"), "--quiet"])
    assert "[[sensors]] unit: sensor 'a' has no unit" in line and "undeclared.toml" in line
    line = _one_line(capsys, ["identify", str(config("declared", 'unit = "furlongs_x"')), "--out", str(tmp / "o"),
                              "--quiet"])
    assert "declared.toml:" in line and "unit: unknown unit 'furlongs_x'" in line
    line = _one_line(capsys, ["identify", str(config("declared", 'unit = "N"')), "--out", str(tmp / "o"), "--quiet"])
    assert "sensor 'a': cannot convert N to m/s^2: force is not acceleration" in line


def test_header_units_lbf_converted_parsec_refused(capsys, accel):
    config, tmp = accel
    f = tmp / "m_per_s^2" / "measurements_a.csv"
    text = f.read_text()
    assert text.startswith("force_N,")
    k, se = _identify(capsys, config("declared"), tmp, "declared")
    f.write_text(text.replace("force_N", "force_lbf", 1))       # the loads are now in lbf: k in N scales by 1/4.448
    k_lbf, _ = _identify(capsys, config("declared"), tmp, "declared")
    assert k_lbf == pytest.approx(k / 4.4482216152605, rel=1e-9)
    f.write_text(text.replace("force_N", "force_parsec", 1))
    line = _one_line(capsys, ["identify", str(config("declared")), "--out", str(tmp / "o"), "--quiet"])
    assert "measurements_a.csv:1: column 'force_parsec' is in parsec" in line and "a unit of length" in line


def test_absurd_reading_is_refused_with_file_series_and_set_point(capsys, accel):
    config, tmp = accel
    f = tmp / "m_per_s^2" / "measurements_a.csv"
    rows = f.read_text().splitlines()
    cells = rows[5].split(",")
    cells[2] = "1e14"
    rows[5] = ",".join(cells)
    f.write_text("\n".join(rows) + "\n")
    line = _one_line(capsys, ["identify", str(config("declared")), "--out", str(tmp / "o"), "--quiet"])
    assert "measurements_a.csv: sensor 'a', series 'series_2', set point 5: reading 1e+14 m/s^2" in line
    assert "mark it missing" in line


def test_plausible_signals_are_not_absurd():
    rng = np.random.default_rng(0)
    load = np.r_[np.linspace(0, 1000, 15), np.linspace(1000, 0, 15)[1:]]
    decay = np.exp(-np.linspace(0, 10 * math.log(10), 30))                 # ten decades: 9e4 MADs
    for signal in (load, decay, np.zeros(30)):
        z = signal[None, :, None] + 1e-9 * rng.standard_normal((2, signal.size, 1))
        assert absurd_reading(z) is None
    z = load[None, :, None] + rng.standard_normal((2, load.size, 1))
    z[1, 7, 0] = 1e14
    i, j, k, ratio = absurd_reading(z)
    assert (i, j, k) == (1, 7, 0) and ratio > ABSURD_RATIO


def test_parameter_in_another_unit_is_converted_for_simulate(tmp_path, capsys, cstr_config):
    """[[parameters]] E_a in J/mol against the model's kJ/mol: start and bounds converted by pint; the
    simulated truth (default: the starts) is recorded in the model's unit."""
    cfg = cstr_config(tmp_path, layout="paper")
    text = cfg.read_text().replace("start = 50.0\nlower = 1.0\nupper = 300.0\nunit = \"kJ/mol\"",
                                   "start = 5e4\nlower = 1e3\nupper = 3e5\nunit = \"J/mol\"")
    cfg.write_text(text.replace("E_a = 60.0, ", ""))
    assert main(["simulate", str(cfg), "--out", str(tmp_path / "d"), "--quiet", "--json", "--seed", "3"]) == 0
    rec = json.loads(capsys.readouterr().out)
    assert rec["truth"]["E_a"] == pytest.approx(50.0, rel=1e-14) and rec["truth_units"]["E_a"] == "kJ/mol"
    cfg.write_text(text.replace('unit = "J/mol"', 'unit = "J/K"'))
    line = _one_line(capsys, ["simulate", str(cfg), "--out", str(tmp_path / "e"), "--quiet"])
    assert "[[parameters]] E_a: unit 'J/K' but the model declares 'kJ/mol': cannot convert" in line
