"""README "Add your own model": a two-bar truss factory runs through identify and detect."""
import json
import sys
import textwrap

import numpy as np
import pytest

from mudoe.cli import main

TRUSS = '''
from models.mechanism import Bar, Joint, Load, MechParameter, Mechanism, Support, build_model


def build(variant):
    mech = Mechanism(
        "two_bar_truss",
        joints=[Joint("A", 0.0, 0.0), Joint("B", 800.0, 0.0), Joint("P", 300.0, -400.0)],
        elements=[Bar("1", "A", "P", "k1"), Bar("2", "B", "P", "k2"),
                  Support("wall_A", "A", kx=1e6, ky=1e6), Support("wall_B", "B", kx=1e6, ky=1e6),
                  Load("hook", "P", fy=-1.0, input="F")],
        parameters=[MechParameter("k1", 200.0, 1.0, 1e5, 200.0, "N/mm"),
                    MechParameter("k2", 300.0, 1.0, 1e5, 300.0, "N/mm")],
        inputs=("F",), sensors=("P_x", "P_y"))
    return build_model(mech, unknowns=("k1", "k2"), name=f"truss {variant}")
'''


@pytest.fixture()
def truss_study(tmp_path, monkeypatch):
    pkg = tmp_path / "mytruss_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "truss.py").write_text(TRUSS)
    monkeypatch.syspath_prepend(str(tmp_path))
    from mudoe.data_io import write_paper_layout
    import importlib
    build = importlib.import_module("mytruss_pkg.truss").build
    q = np.r_[np.linspace(0, 1000, 11), np.linspace(1000, 0, 11)[1:]]
    h = build("x").simulate([210.0, 290.0], q[:, None])
    z = h + 0.004 * np.random.default_rng(1).standard_normal((4,) + h.shape)
    write_paper_layout(tmp_path / "truss_data", q, z, ["P_x", "P_y"])
    cfg = tmp_path / "truss.toml"
    cfg.write_text(textwrap.dedent("""\
        [model]
        name = "mytruss_pkg.truss:build"
        variants = ["linear"]
        [data]
        directory = "truss_data"
        [[sensors]]
        name = "P_x"
        sigma = 4.0
        [[sensors]]
        name = "P_y"
        sigma = 4.0
        [[parameters]]
        name = "k1"
        start = 200.0
        [[parameters]]
        name = "k2"
        start = 300.0
        [detect]
        sensors = "all"
        """))
    yield cfg
    for name in [m for m in sys.modules if m.startswith("mytruss_pkg")]:
        del sys.modules[name]


def test_own_model_identify_and_detect(truss_study, capsys, tmp_path):
    out = tmp_path / "out"
    assert main(["identify", str(truss_study), "--out", str(out), "--json", "--quiet"]) == 0
    est = json.loads(capsys.readouterr().out)["linear"]
    assert est["params"] == ["k1", "k2"]
    assert abs(est["p"][0] - 210.0) < 4 * est["stderr"][0] and abs(est["p"][1] - 290.0) < 4 * est["stderr"][1]
    assert main(["detect", str(truss_study), "--out", str(out), "--json", "--quiet"]) == 0
    det = json.loads(capsys.readouterr().out)
    assert det["verdicts"] == {"linear": "not rejected"} and len(det["tests"]) == 4


def test_own_model_bad_factory_is_one_line(truss_study, capsys):
    truss_study.write_text(truss_study.read_text().replace("truss:build", "truss:nothere"))
    assert main(["identify", str(truss_study), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has no function 'nothere'" in err[0]
