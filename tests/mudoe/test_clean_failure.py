"""Clean failure of the CLI: --out checked first, extreme data, solver chatter, Ctrl-C, --version, init."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mudoe.cli import main
from mudoe.console import Chatter

REPO = Path(__file__).resolve().parents[2]
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(REPO))


def _one_line(capsys, argv, code, *words):
    rc = main(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == code, err
    assert "Traceback" not in err and len(lines) == 1, err
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def test_out_is_a_file_fails_before_any_work(capsys, campaign_dirs):
    f = campaign_dirs["root"] / "afile"
    f.write_text("x")
    _one_line(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--out", str(f)], 2, "--out", "not a folder")


def test_out_not_creatable(capsys, campaign_dirs):
    # /proc refuses new entries even for root; nothing is created and no fit runs (no progress line)
    _one_line(capsys, ["validate", str(campaign_dirs["paper_cfg"]), "--out", "/proc/mudoe_out"], 2,
              "--out", "/proc")
    assert not Path("/proc/mudoe_out").exists()


def test_out_checked_before_the_config(capsys, tmp_path):
    f = tmp_path / "afile"
    f.write_text("x")
    _one_line(capsys, ["detect", str(tmp_path / "none.toml"), "--out", str(f)], 2, "--out")


@pytest.mark.parametrize("value", ["1e300", "-1e300", "inf", "-Infinity"])
def test_extreme_value_in_data(capsys, campaign_dirs, value):
    f = campaign_dirs["paper"] / "measurements_D_y.csv"
    lines = f.read_text().splitlines()
    parts = lines[5].split(",")
    parts[2] = value
    lines[5] = ",".join(parts)
    f.write_text("\n".join(lines) + "\n")
    out = campaign_dirs["root"] / "out"
    _one_line(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--out", str(out)], 2,
              "measurements_D_y.csv:6:", "'series_2'")
    assert not out.exists()


def test_extreme_value_in_tidy_data(capsys, campaign_dirs):
    f = campaign_dirs["tidy"] / "campaign_long.csv"
    lines = f.read_text().splitlines()
    parts = lines[7].split(",")
    parts[-1] = "1e300"
    lines[7] = ",".join(parts)
    f.write_text("\n".join(lines) + "\n")
    _one_line(capsys, ["identify", str(campaign_dirs["tidy_cfg"]), "--quiet"], 2,
              "campaign_long.csv:8:", "out of range")


def _casadi_warning():
    import casadi as ca
    x = ca.SX.sym("x")
    s = ca.nlpsol("s", "ipopt", {"x": x, "f": (x - 1) ** 2, "g": ca.log(x)},
                  {"ipopt.print_level": 0, "print_time": 0})
    s(x0=-1, lbg=-10, ubg=10)
    return s.stats()["return_status"]


def test_chatter_is_captured_own_lines_pass(capsys):
    with Chatter() as ch:
        status = _casadi_warning()
        print("mudoe: my progress line", file=sys.stderr)
    cap = capsys.readouterr()
    assert status == "Invalid_Number_Detected"
    assert "mudoe: my progress line" in cap.err
    assert "CasADi" not in cap.err and "Ipopt" not in cap.out and "CasADi" not in cap.out
    assert "nlp_g failed: NaN detected" in ch.text


def test_chatter_captures_file_descriptors(capfd):
    with Chatter() as ch:
        os.write(1, b"C-level stdout\n")
        os.write(2, b"C-level stderr\n")
    cap = capfd.readouterr()
    assert "C-level" not in cap.out + cap.err
    assert "C-level stdout" in ch.text and "C-level stderr" in ch.text
    os.write(2, b"restored\n")
    assert "restored" in capfd.readouterr().err


def test_version(capsys):
    from importlib.metadata import version
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"mudoe {version('mudoe')}"


def test_init_writes_a_template_and_never_overwrites(capsys, tmp_path):
    from mudoe.config import load_config
    path = tmp_path / "study.toml"
    assert main(["init", str(path)]) == 0
    cfg = load_config(path)
    assert cfg.model.name == "mypackage.mymodel:build" and "#" in path.read_text()
    before = path.read_text()
    capsys.readouterr()
    _one_line(capsys, ["init", str(path)], 2, "exists", "never overwrites")
    assert path.read_text() == before


def test_init_bad_factory(capsys, tmp_path):
    _one_line(capsys, ["init", str(tmp_path / "s.toml"), "--model", "no_such_pkg_x.mod:build"], 2,
              "--model", "cannot import")
    assert not (tmp_path / "s.toml").exists()


def test_ctrl_c_stops_with_130_and_writes_nothing(tmp_path, campaign_dirs):
    out = tmp_path / "out"
    p = subprocess.Popen([sys.executable, "-m", "mudoe", "validate", str(campaign_dirs["paper_cfg"]), "--runs",
                          "100000", "--out", str(out)], cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    seen = []
    for line in p.stderr:                  # wait until the Monte Carlo loop has started
        seen.append(line)
        if "Monte Carlo size study" in line:
            break
    time.sleep(1.0)
    p.send_signal(signal.SIGINT)
    try:
        _, rest = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        p.kill()
        raise
    err = "".join(seen) + rest
    assert p.returncode == 130, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == "mudoe: interrupted"
    assert not (out / "validate.json").exists()


def test_init_from_a_model_factory_lists_its_names_and_units(capsys, tmp_path):
    from mudoe.config import load_config
    path = tmp_path / "cstr.toml"
    assert main(["init", str(path), "--model", "mudoe.example_cstr:build"]) == 0
    cfg = load_config(path)
    assert cfg.model.name == "mudoe.example_cstr:build" and cfg.data.input_unit == "K"
    assert [(s.name, s.unit) for s in cfg.sensors] == [("C_A", "mmol/L"), ("C_B", "mmol/L"), ("C_C", "mmol/L"),
                                                       ("X_A", "%")]
    assert [(p.name, p.unit) for p in cfg.parameters] == [("k_ref", "1/min"), ("E_a", "kJ/mol"), ("k_2", "1/min")]


# ---------------------------------------------------------------------------- the rest of issue 14's list
ABSURD = '''
from models.contract import Model


def build(variant):
    """y = c + 1 / (1 + k x): constant data do not bound k, which runs to absurd values."""
    return Model.explicit(["c", "k"], ["x"], ["y"], h=lambda p, q: [p[0] + 1 / (1 + p[1] * q[0])],
                          name=f"saturation {variant}")
'''


@pytest.fixture()
def absurd_study(tmp_path, monkeypatch):
    """A user's model whose data leave a parameter unbounded (the issue's p = -8e12 fit)."""
    import textwrap

    import numpy as np

    from mudoe.data_io import write_paper_layout
    pkg = tmp_path / "absurd_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "sat.py").write_text(ABSURD)
    monkeypatch.syspath_prepend(str(tmp_path))
    x = np.linspace(0.5, 5, 20)
    z = 1.0 + 0.01 * np.sin(7 * x)[None, :, None] + 0.01 * np.random.default_rng(2).standard_normal((2, 20, 1))
    from mudoe.data_io import DataUnits
    write_paper_layout(tmp_path / "data", x, z, ["y"], units=DataUnits("1", "1", ("1",), ("1",), input_name="x"))
    cfg = tmp_path / "absurd.toml"
    cfg.write_text(textwrap.dedent("""\
        [model]
        name = "absurd_pkg.sat:build"
        variants = ["v"]
        [data]
        directory = "data"
        input_unit = "1"                # the model declares no units: the config must (issue 20)
        output_unit = "1"
        [[sensors]]
        name = "y"
        sigma = 0.01
        [[parameters]]
        name = "c"
        start = 1.0
        [[parameters]]
        name = "k"
        start = 1.0
        [splits]
        scenarios = []
        [splits.random]
        n = 2
        """))
    return cfg


@pytest.mark.parametrize("command", ["identify", "detect"])
def test_absurd_estimate_is_a_failed_computation(capsys, tmp_path, absurd_study, command):
    """The issue's "Solve_Succeeded with k1 = -8e12 and NaN standard errors": exit 1, one line saying
    the data do not bound k (issue 20: the run-off is certified, no longer "absurd values"), no
    traceback, no result file that could be read as a success."""
    out = tmp_path / "out"
    line = _one_line(capsys, [command, str(absurd_study), "--out", str(out), "--quiet"], 1, "not bounded",
                     "k -> +inf")
    assert line.startswith(f"mudoe {command}: failed:"), line
    assert not (out / f"{command}.json").exists()


def test_out_is_an_existing_folder_that_cannot_be_written(capsys, campaign_dirs):
    # /proc exists and is a folder, but refuses new entries even for root (os.access would say yes)
    _one_line(capsys, ["detect", str(campaign_dirs["paper_cfg"]), "--out", "/proc"], 2,
              "--out", "cannot write into folder /proc")


def test_simulate_a_user_study_without_a_simulate_section(capsys, tmp_path):
    """A user's study without [simulate] gets an error, not press data (the issue's D_y, F_x, B0_y)."""
    text = (REPO / "configs" / "cstr.toml").read_text()
    text = text[:text.index("[simulate]")] + text[text.index("[splits]"):]
    text = text.replace('directory = "../data/cstr"', f'directory = "{REPO / "data" / "cstr"}"')
    cfg = tmp_path / "nosim.toml"
    cfg.write_text(text)
    out = tmp_path / "sim"
    _one_line(capsys, ["simulate", str(cfg), "--out", str(out)], 2, "[simulate]", "give the set points")
    assert not out.exists()


def test_extreme_value_in_a_user_study(capsys, tmp_path):
    """1e300 in the cstr study's tidy data (degC, mol/L): exit 2, file:line, nothing written."""
    src = REPO / "data" / "cstr" / "campaign_long.csv"
    lines = src.read_text().splitlines()
    parts = lines[9].split(",")
    parts[-1] = "1e300"
    lines[9] = ",".join(parts)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "campaign_long.csv").write_text("\n".join(lines) + "\n")
    text = (REPO / "configs" / "cstr.toml").read_text().replace('directory = "../data/cstr"', 'directory = "data"')
    cfg = tmp_path / "cstr.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    _one_line(capsys, ["detect", str(cfg), "--out", str(out)], 2, "campaign_long.csv:10:")
    assert not out.exists()
