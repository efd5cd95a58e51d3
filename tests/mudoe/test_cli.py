"""The CLI: every bad input gives exit code 2 and one line on stderr, no traceback; commands write outputs."""
import json
import os
import subprocess
import sys
from pathlib import Path


from cli_texts import one_line_error as _one_line_error
from mudoe.cli import main
from mudoe.outdir import MARKER

REPO = Path(__file__).resolve().parents[2]


def _edit(path, old, new):
    path.write_text(path.read_text().replace(old, new, 1))


def test_missing_config_file(tmp_path, capsys):
    _one_line_error(capsys, ["identify", str(tmp_path / "none.toml"), "--quiet"], "config file not found")


def test_unknown_key_in_config(tmp_path, capsys, campaign_dirs):
    cfg = campaign_dirs["paper_cfg"]
    cfg.write_text(cfg.read_text() + "\n[report]\ntitel = \"x\"\n")
    n = len(cfg.read_text().splitlines()) - 0
    _one_line_error(capsys, ["identify", str(cfg), "--quiet"], f"paper.toml:{n}:", "'titel'")


def test_missing_data_file(capsys, campaign_dirs):
    (campaign_dirs["paper"] / "measurements_F_x.csv").unlink()
    _one_line_error(capsys, ["identify", str(campaign_dirs["paper_cfg"])],      # without --quiet too
                    "measurements_F_x.csv", "not found")


def test_wrong_header(capsys, campaign_dirs):
    _edit(campaign_dirs["paper"] / "measurements_D_y.csv", "force_N", "time_s")
    _one_line_error(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--quiet"],
                    "measurements_D_y.csv:1:", "wrong header")


def test_wrong_header_tidy(capsys, campaign_dirs):
    _edit(campaign_dirs["tidy"] / "campaign_long.csv", "sensor,", "gauge,")
    _one_line_error(capsys, ["identify", str(campaign_dirs["tidy_cfg"]), "--quiet"],
                    "campaign_long.csv:1:", "missing column(s) sensor")


def test_ragged_row(capsys, campaign_dirs):
    f = campaign_dirs["paper"] / "measurements_B0_y.csv"
    lines = f.read_text().splitlines()
    lines[6] = lines[6] + ",1.0"
    f.write_text("\n".join(lines) + "\n")
    _one_line_error(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--quiet"],
                    "measurements_B0_y.csv:7:", "ragged row")


def test_text_in_numeric_column(capsys, campaign_dirs):
    f = campaign_dirs["tidy"] / "campaign_long.csv"
    lines = f.read_text().splitlines()
    parts = lines[10].split(",")
    parts[-1] = "12,5um".replace(",", ";")
    lines[10] = ",".join(parts)
    f.write_text("\n".join(lines) + "\n")
    _one_line_error(capsys, ["identify", str(campaign_dirs["tidy_cfg"]), "--quiet"],
                    "campaign_long.csv:11:", "is not a number")


def test_nan_in_force_column(capsys, campaign_dirs):
    f = campaign_dirs["paper"] / "measurements_D_y.csv"
    lines = f.read_text().splitlines()
    parts = lines[3].split(",")
    parts[0] = "NaN"
    lines[3] = ",".join(parts)
    f.write_text("\n".join(lines) + "\n")
    _one_line_error(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--quiet"],
                    "measurements_D_y.csv:4:", "set forces must be known")


def test_nan_readings_are_allowed(capsys, campaign_dirs):
    f = campaign_dirs["paper"] / "measurements_F_x.csv"
    lines = f.read_text().splitlines()
    parts = lines[8].split(",")
    parts[2] = "NaN"
    lines[8] = ",".join(parts)
    f.write_text("\n".join(lines) + "\n")
    out = campaign_dirs["root"] / "out"
    rc = main(["identify", str(campaign_dirs["paper_cfg"]), "--out", str(out), "--json", "--quiet"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    obj = json.loads(cap.out)
    assert obj["M1"]["n_data"] == 3 * 29 * 3 - 1
    assert json.loads((out / "identify.json").read_text())["M1"]["p"] == obj["M1"]["p"]
    assert not [p for p in out.iterdir() if p.name.startswith(".") and p.name != MARKER]   # no temp files left


def test_negative_sigma(capsys, campaign_dirs):
    _edit(campaign_dirs["paper_cfg"], "sigma = 5.0", "sigma = -5.0")
    _one_line_error(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--quiet"],
                    "paper.toml:", "sigma must be positive")


def test_unknown_model(capsys, campaign_dirs):
    _edit(campaign_dirs["paper_cfg"], 'name = "press"', 'name = "lathe"')
    _one_line_error(capsys, ["detect", str(campaign_dirs["paper_cfg"]), "--quiet"], "unknown model 'lathe'")


def test_unknown_sensor_in_config(capsys, campaign_dirs):
    _edit(campaign_dirs["paper_cfg"], 'name = "B0_y"', 'name = "G_x"')
    _one_line_error(capsys, ["identify", str(campaign_dirs["paper_cfg"]), "--quiet"], "unknown sensor", "G_x")


def test_unknown_sensor_in_tidy_file(capsys, campaign_dirs):
    f = campaign_dirs["tidy"] / "campaign_long.csv"
    lines = f.read_text().splitlines()
    lines[3] = lines[3].replace("B0_y", "Z_q")
    f.write_text("\n".join(lines) + "\n")
    _one_line_error(capsys, ["identify", str(campaign_dirs["tidy_cfg"]), "--quiet"],
                    "campaign_long.csv:4:", "unknown sensor 'Z_q'")


def test_bad_arguments(capsys, campaign_dirs):
    _one_line_error(capsys, ["frobnicate", "x.toml"], "invalid choice")
    _one_line_error(capsys, ["identify"], "CONFIG")


def test_help_on_every_subcommand(capsys):
    for cmd in ("identify", "oed", "detect", "report", "validate", "simulate"):
        assert main([cmd, "--help"]) == 0
        assert "--out" in capsys.readouterr().out


def test_detect_and_oed_commands_write_outputs(capsys, campaign_dirs):
    out = campaign_dirs["root"] / "res"
    assert main(["oed", str(campaign_dirs["paper_cfg"]), "--out", str(out), "--quiet"]) == 0
    txt = capsys.readouterr().out
    assert "chosen:" in txt and (out / "oed.json").is_file()
    assert main(["detect", str(campaign_dirs["paper_cfg"]), "--out", str(out), "--json", "--quiet"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert set(obj["verdicts"]) == {"M1"}
    assert len(obj["tests"]) == 4 and all(t["ok"] for t in obj["tests"])
    # data simulated from M1 itself: M1 must not be rejected at TOL = 5 % on this seed
    assert obj["verdicts"]["M1"] == "not rejected"


def test_python_dash_m_bad_input_subprocess(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[model]\nname = \"press\"\nvariant = [\"M1\"]\n")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-m", "mudoe", "identify", str(bad)], capture_output=True, text=True,
                       cwd=REPO, env=env, timeout=120)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.toml:3:" in lines[0] and "'variant'" in lines[0]
