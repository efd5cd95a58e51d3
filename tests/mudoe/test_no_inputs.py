"""A dynamic model without inputs (one batch run; issue 30): the model, its data (inputs=None or
np.zeros((n_q, 0))), the long CSV, the config (an empty [[dynamic.experiments]] table) and the command
line (init, simulate, identify) follow one rule: an experiment is an input row of length 0."""
import json
import textwrap

import casadi as ca
import numpy as np
import pytest

from identification import DataError, DynamicMeasurements, identify
from identification.fit.dynamic_fit import simulate_campaign
from models import Model
from mudoe.cli import main
from mudoe.kind.long_csv import read_long_csv, write_long_csv

P_TRUE = [2.0, 0.5]
FACTORY = textwrap.dedent('''\
    import casadi as ca
    from models import Model, Parameter


    def build(variant="default"):
        return Model.ode([Parameter("k1", 0.0, 100.0, scale=1.0, unit="1/h"),
                          Parameter("k2", 0.0, 100.0, scale=1.0, unit="1/h")],
                         states=["cA", "cB"], inputs=[], sensors=["cA", "cB"],
                         rhs=lambda x, p, u: ca.vertcat(-p[0] * x[0], p[0] * x[0] - p[1] * x[1]),
                         x0=lambda p, u: ca.vertcat(1.0, 0.0), h=lambda x, p, u: x, name="batch run",
                         state_units=("mol/L", "mol/L"), sensor_units=("mol/L", "mol/L"), time_unit="h")
    ''')


def batch(inputs=()):
    return Model.ode(["k1", "k2"], ["cA", "cB"], inputs, ["cA", "cB"],
                     rhs=lambda x, p, u: ca.vertcat(-p[0] * x[0], p[0] * x[0] - p[1] * x[1]),
                     x0=lambda p, u: ca.vertcat(1.0, 0.0), h=lambda x, p, u: x)


def test_model_and_data_without_inputs(tmp_path):
    assert batch(None).inputs == batch([]).inputs == () and batch(None).n_q_dim == 0
    t = np.linspace(0.2, 2.0, 10)
    data = simulate_campaign(batch(), P_TRUE, np.zeros((1, 0)), t, [0.01, 0.01], n_series=2, seed=3)
    assert data.inputs.shape == (1, 0)
    same = DynamicMeasurements(None, t, data.z, [0.01, 0.01], sensors=data.sensors)
    assert same.inputs.shape == (1, 0) and np.array_equal(same.flat().z, data.flat().z, equal_nan=True)
    est = identify(batch(), data, p0=[1.0, 1.0])
    assert np.all(np.abs(est.p - P_TRUE) < 4 * est.stderr)
    path = tmp_path / "batch.csv"
    write_long_csv(path, data, units=["mol/L", "mol/L"])
    back = read_long_csv(path, np.zeros((1, 0)), ["cA", "cB"], ["mol/L", "mol/L"], sigma=[0.01, 0.01])
    assert back.inputs.shape == (1, 0) and np.allclose(back.z, data.z)
    with pytest.raises(DataError, match=r"inputs: expected one row per experiment.*np.zeros\(\(n_q, 0\)\) or None"):
        DynamicMeasurements([], t, data.z, [0.01, 0.01])


def test_cli_init_simulate_identify_without_inputs(tmp_path, capsys, monkeypatch):
    (tmp_path / "batchrun.py").write_text(FACTORY)
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = tmp_path / "study.toml"
    assert main(["init", "--model", "batchrun:build", str(cfg)]) == 0
    text = cfg.read_text()
    assert text.count("\n[[dynamic.experiments]]") == 1 and "\n[[splits.custom]]" not in text
    cfg.write_text(text.replace("[simulate]", "[simulate]\ntruth = {k1 = 2.0, k2 = 0.5}"))
    assert main(["simulate", str(cfg), "--out", str(tmp_path / "data"), "--quiet"]) == 0
    rows = (tmp_path / "data" / "campaign_long.csv").read_text().splitlines()
    assert rows[0] == "series,experiment,time,sensor,value,unit" and len(rows) == 1 + 2 * 10 * 2
    capsys.readouterr()
    assert main(["identify", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--json"]) == 0
    est = json.loads(capsys.readouterr().out)["default"]
    assert abs(est["p"][0] - 2.0) < 0.1 and abs(est["p"][1] - 0.5) < 0.05


def test_cli_a_blow_up_at_p0_is_bad_input_naming_the_time(tmp_path, capsys, monkeypatch):
    # issue 30 (bad input): cA' = k1 cA^2, cA(0) = 1 blows up at t* = 1 / k1 = 1 h at the start k1 = 1 (within the
    # 2 h horizon; the data's k1 = 0.2 does not): exit 2, one line naming the variant, the model and the time
    (tmp_path / "blowrun.py").write_text(FACTORY.replace("ca.vertcat(-p[0] * x[0], p[0] * x[0] - p[1] * x[1])",
                                                         "ca.vertcat(p[0] * x[0] ** 2, -p[1] * x[1])")
                                         .replace("ca.vertcat(1.0, 0.0)", "ca.vertcat(1.0, 1.0)"))
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = tmp_path / "study.toml"
    assert main(["init", "--model", "blowrun:build", str(cfg)]) == 0
    text = cfg.read_text().replace("[simulate]", "[simulate]\ntruth = {k1 = 0.2, k2 = 0.5}")
    cfg.write_text(text)
    assert main(["simulate", str(cfg), "--out", str(tmp_path / "data"), "--quiet"]) == 0
    head, tail = text.split('name = "k1"', 1)
    start = tail.index("start = ")
    end = tail.index("\n", start)
    cfg.write_text(head + 'name = "k1"' + tail[:start] + "start = 1.0" + tail[end:])
    capsys.readouterr()
    rc = main(["identify", str(cfg), "--out", str(tmp_path / "out"), "--quiet"])
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1, lines
    assert lines[0].startswith("mudoe identify: error: variant default: p0: the trajectory blows up at the start "
                               "values: integration of 'batch run' failed at p = [1.0, "), lines[0]
    assert "the trajectory blows up (|x| -> inf near t = 1)" in lines[0], lines[0]
    assert not (tmp_path / "out").exists()
