"""The press study explains M3's input-range rejection on the shipped campaign (bench_diagnose_m3):
the explanation is the study's data, shown after the finding in the report and the terminal."""
import dataclasses

import numpy as np
import pytest

from mudoe.config import DEFAULT_CONFIG, parse_config
from mudoe.press import M3_INPUT_RANGE_BENCH, diagnosis_explanations
from models.prototype import read_campaign
from identification.studies.records import Diagnosis, DiagnosisRow, Explanation
from reports.diagnosis import findings_text


def test_explanation_only_for_the_shipped_campaign_and_M3():
    shipped = read_campaign()
    (e,) = diagnosis_explanations(shipped, ("M1", "M2", "M3"))
    assert e.model == "M3" and e.kind == "input range"
    assert "linearity error" in e.text and f"{100 * M3_INPUT_RANGE_BENCH['no gauge linearity error']:.3g} %" in e.text
    assert diagnosis_explanations(shipped, ("M1", "M2")) == ()
    z = np.array(shipped.z, copy=True)
    z[0, 3, 1] += 1e-3                                  # one reading 1 um off: other data, no claim
    assert diagnosis_explanations(dataclasses.replace(shipped, z=z), ("M3",)) == ()


def test_findings_carry_the_matching_explanation_only():
    rows = (DiagnosisRow("A", "low vs high input", "input range", 1e-9, 3e-9, True),
            DiagnosisRow("B", "low vs high input", "input range", 1e-9, 3e-9, True),
            DiagnosisRow("A", "first vs second half", "series", 0.4, 1.0, False))
    diag = Diagnosis("likelihood_ratio", 0.05, rows, (Explanation("A", "input range", "Known cause: X."),))
    (a,) = diag.misses("A")
    (b,) = diag.misses("B")
    assert a.endswith("Known cause: X.") and "input dependence" in a and "Known cause" not in b
    text = findings_text(diag, ["A", "B"])
    assert text.count("  - ") == 2 and "Known cause: X." in text
    with pytest.raises(ValueError, match="kind"):
        Explanation("A", "temperature", "x")


def test_press_report_page_and_terminal_state_the_finding(tmp_path, capsys):
    """M3 alone on the shipped campaign: the 'What the model misses' page and `mudoe detect` say why
    the input-range split rejects it."""
    from mudoe.report_record import study_record
    from mudoe.study import StudyResults, prepare, run_detect, run_diagnosis, run_identify
    from reports.builder import page_texts, report_pages
    text = DEFAULT_CONFIG.read_text().replace('variants = ["M1", "M2", "M3"]', 'variants = ["M3"]')
    text = text.replace('sensors = "oed"', 'sensors = ["F_x", "B0_y"]').replace('variant = "M1"', 'variant = "M3"')
    study = prepare(parse_config(text, str(DEFAULT_CONFIG), DEFAULT_CONFIG.parent))
    assert [e.model for e in study.explanations] == ["M3"]
    results = run_identify(study, StudyResults(study))
    results = run_diagnosis(study, run_detect(study, results))
    row = next(r for r in results.diagnosis.rows if r.split == "low vs high input")
    assert row.rejected and row.alpha == pytest.approx(M3_INPUT_RANGE_BENCH["as shipped"], rel=0.05)
    pages = dict(report_pages(study_record(results), results.diagnosis))
    figs = pages["misses"]()
    shown = " ".join(" ".join(page_texts(f)) for f in (figs if isinstance(figs, list) else [figs]))
    assert "low vs high input" in shown and "without the gauges' linearity error" in " ".join(shown.split())
    assert "without the gauges' linearity error" in findings_text(results.diagnosis, ["M3"])
