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


REPO = Path(__file__).resolve().parents[2]
WORDS = ("rejected", "not rejected", "undecided")


def _terminal_normality(text: str) -> tuple[str, dict]:
    """(header line, {sensor: (p %, sigma_rep, unit)}) of the normality table of `mudoe detect`."""
    lines = text.splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("Normality gate"))
    rows = {}
    for ln in lines[k + 2:]:
        if not ln.strip():
            break
        sensor, p, sig, unit = ln.split()[:4]
        rows[sensor] = (p, sig, unit)
    return lines[k] + "\n" + lines[k + 1], rows


def test_terminal_json_and_report_agree_on_units_labels_and_words(tmp_path, capsys):
    """The cstr study: sigma_rep (value and unit), the Shapiro-Wilk p-values and what they were
    computed on, and the decision word are the same in `mudoe detect`'s terminal text, its JSON and
    the report's pages (the builder's text model: what the PDF shows)."""
    from mudoe.config import load_config
    from mudoe.report_record import study_record
    from mudoe.study import StudyResults, prepare, run_detect, run_identify, run_oed
    from reports.builder import page_texts, report_pages

    cfg_path = REPO / "configs" / "cstr.toml"
    rc, terminal = _run(capsys, "detect", str(cfg_path), "--out", str(tmp_path))
    assert rc == 0
    det_json = json.loads((tmp_path / "detect.json").read_text())

    study = prepare(load_config(cfg_path))
    results = run_detect(study, run_oed(study, run_identify(study, StudyResults(study))))
    pages = dict(report_pages(study_record(results), None, with_diagnosis=False))
    title, normality = pages["title"](), pages["normality"]()
    normality = normality if isinstance(normality, list) else [normality]
    title_texts = page_texts(title)
    norm_texts = [t for fig in normality for t in page_texts(fig)]

    # what the p-values were computed on: named in all three
    head, term_rows = _terminal_normality(terminal)
    assert "of the study series 1-4" in head and "SW p % (study series)" in head and "sigma_rep (study series)" in head
    (gate,) = det_json["normality"]
    assert gate["computed_on"] == "study series 1-4"
    p_head = next(t for t in norm_texts if t.startswith("SW p %"))
    s_head = next(t for t in norm_texts if t.startswith("sigma_rep"))
    assert "study series" in p_head and "study series" in s_head

    # the report's row of each sensor: sensor, p %, sigma_rep, sigma_man, sigma used, unit, how
    sensors = results.study.sensors
    assert set(term_rows) == set(sensors) == set(gate["sensors"])
    for k, s in enumerate(sensors):
        i = norm_texts.index(s)
        rep_p, rep_sig, rep_unit = norm_texts[i + 1], norm_texts[i + 2], norm_texts[i + 5]
        p, sig, unit = term_rows[s]
        assert (p, sig, unit) == (rep_p, rep_sig, rep_unit)
        assert (f"{100 * gate['pvalue'][k]:.2f}", f"{gate['sigma_rep'][k]:.4g}", gate["sigma_rep_unit"][k]) == \
            (p, sig, unit)
    # concentrations are shown in the model's mmol/L, the conversion in %, nowhere in another unit
    assert [term_rows[s][2] for s in sensors] == ["mmol/L", "mmol/L", "mmol/L", "%"]

    # the decision word: terminal (the >> line), JSON and page 1's verdict table
    (primary,) = [ln for ln in terminal.splitlines() if ln.strip().startswith(">>")]
    word_terminal = primary.split(":", 1)[1].split("(")[0].strip()
    word_json = det_json["verdicts"]["arrhenius"]
    i = title_texts.index("arrhenius")
    word_report = title_texts[i + 1]
    assert word_terminal == word_json == word_report and word_json in WORDS
    assert not any(w.upper() in terminal for w in ("REJECTED", "ACCEPT"))


def test_detect_shows_a_bar_per_model_over_its_splits(tmp_path, capsys):
    """`mudoe detect` (without --quiet) shows the split fits and the diagnostic fits as tqdm bars."""
    rc = main(["detect", str(REPO / "configs" / "cstr.toml"), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 0 and "Traceback" not in err
    assert "detect arrhenius" in err and "4/4" in err and "split" in err
    assert "diagnostic splits arrhenius" in err
