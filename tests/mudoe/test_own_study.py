"""A study that is not a press (mudoe/example_cstr.py: 3 parameters, 2 states, degC and mol/L in the
files) runs through every command: simulate, identify, oed, detect, report, validate."""
import json
from pathlib import Path

from mudoe.cli import main

def _run(capsys, *argv):
    rc = main(list(argv) + ["--quiet"])
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    return rc, cap.out


def test_cstr_study_through_every_command(tmp_path, capsys, cstr_config):
    cfg = cstr_config(tmp_path)
    out = tmp_path / "out"
    rc, _ = _run(capsys, "simulate", str(cfg), "--out", str(tmp_path / "data"))
    assert rc == 0 and (tmp_path / "data" / "campaign_long.csv").is_file()
    head = (tmp_path / "data" / "campaign_long.csv").read_text().splitlines()[0]
    assert head == "series,index,set_T_degC,sensor,value"

    rc, text = _run(capsys, "identify", str(cfg), "--out", str(out), "--json")
    assert rc == 0
    est = json.loads(text)["arrhenius"]
    assert est["params"] == ["k_ref", "E_a", "k_2"]
    truth = (0.08, 60.0, 0.04)
    assert all(abs(p - t) < 5 * s for p, t, s in zip(est["p"], truth, est["stderr"]))
    txt = (out / "identify.txt").read_text()
    assert all(u in txt for u in ("1/min", "kJ/mol"))

    rc, text = _run(capsys, "oed", str(cfg), "--out", str(out))
    assert rc == 0 and "chosen:" in text and "X_A" in (out / "oed.txt").read_text()

    rc, text = _run(capsys, "detect", str(cfg), "--out", str(out), "--json")
    det = json.loads(text)
    assert rc == 0 and set(det["verdicts"]) == {"arrhenius"} and len(det["tests"]) == 4

    rc, text = _run(capsys, "validate", str(cfg), "--out", str(out), "--runs", "3", "--json")
    assert rc == 0 and (out / "validate.json").is_file()

    rc, text = _run(capsys, "report", str(cfg), "--out", str(out), "--json")
    assert rc == 0
    files = {Path(f).name for f in json.loads(text)["files"]}
    assert "report.pdf" in files and (out / "report.pdf").stat().st_size > 0
    res = json.loads((out / "results.json").read_text())
    flat = json.dumps(res)
    assert all(n in flat for n in ("k_ref", "E_a", "k_2", "degC", "mol/L"))
