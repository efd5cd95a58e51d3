"""Report builder: complete PDF/PNGs/results.json, and nothing half-written when a page fails."""
import json

import numpy as np
import pytest


@pytest.fixture(scope="module")
def results():
    """M1 on the shipped campaign (the paper's two held-out series), OED design, four paper splits."""
    from mudoe.config import DEFAULT_CONFIG, parse_config
    from mudoe.report_record import study_record
    from mudoe.study import StudyResults, prepare, run_bands, run_detect, run_diagnosis, run_identify, run_oed
    text = DEFAULT_CONFIG.read_text().replace('variants = ["M1", "M2", "M3"]', 'variants = ["M1"]')
    text = text.replace('variant = "M3"', 'variant = "M1"').replace("[report]", "[report]\ndpi = 40")
    study = prepare(parse_config(text, "press_m1.toml", DEFAULT_CONFIG.parent))
    r = run_detect(study, run_oed(study, run_identify(study, StudyResults(study))))
    return study_record(run_bands(study, run_diagnosis(study, r)))


def test_build_report_writes_pdf_pngs_and_results_json(results, tmp_path):
    from reports.builder import build_report
    paths = build_report(results, tmp_path / "out")
    names = {p.name for p in paths}
    assert {"report.pdf", "results.json"} <= names
    pdf = (tmp_path / "out" / "report.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and pdf.rstrip().endswith(b"%%EOF")
    assert pdf.count(b"/Type /Page\n") + pdf.count(b"/Type /Page ") + pdf.count(b"/Type/Page") >= 7 or \
        len([n for n in names if n.endswith(".png")]) >= 7
    pngs = sorted(n for n in names if n.endswith(".png"))
    assert len(pngs) >= 7 and all((tmp_path / "out" / n).read_bytes()[:4] == b"\x89PNG" for n in pngs)
    meta = json.loads((tmp_path / "out" / "results.json").read_text())
    assert len(meta["data_sha256"]) == 64 and meta["versions"]["numpy"] == np.__version__
    assert meta["verdicts"] == {"M1": results.detection.verdicts["M1"]}
    assert meta["results"]["estimates"]["M1"]["p"] == pytest.approx(results.estimates["M1"].p.tolist())
    assert "report_build" in meta["timing_s"]
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]


def test_failed_build_leaves_no_partial_file(results, tmp_path, monkeypatch):
    import reports.builder as b
    out = tmp_path / "out"
    out.mkdir()
    (out / "report.pdf").write_bytes(b"old report")

    def boom(_results):
        raise RuntimeError("page failed")

    monkeypatch.setattr(b, "_alpha_pages", boom)      # a late page: earlier pages are already rendered
    with pytest.raises(RuntimeError, match="page failed"):
        b.build_report(results, out, diagnose=False)
    assert sorted(p.name for p in out.iterdir()) == ["report.pdf"]
    assert (out / "report.pdf").read_bytes() == b"old report"


def test_verdict_paragraph_names_model_and_numbers(results):
    from reports.builder import verdict_paragraphs
    (v, par), = verdict_paragraphs(results)
    assert v == "M1" and "TOL = 5 %" in par and "k5 =" in par and par.startswith("M1: rejected")
    assert "Goodness of fit (chi2 test" in par


def test_figures_return_figures_with_units(results):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from reports.figures import confidence_ellipses, measurement_loops, residuals_plot
    s = results.study
    f1 = measurement_loops(s, results.estimates, "F_x")
    assert "(N)" in f1.axes[0].get_xlabel() and "(um)" in f1.axes[0].get_ylabel()
    m = s.models["M1"]
    f2 = confidence_ellipses(results.detection.tests[0], 0.9875, m.param_names, [p.unit for p in m.params])
    assert f2.axes[0].get_xlabel() == "k5 (N/mm)" and f2.axes[0].get_ylabel() == "k7 (N/mm)"
    f4 = confidence_ellipses(results.detection.tests[0], 0.9875)     # no names: generic, no empty unit
    assert f4.axes[0].get_xlabel() == "p1"
    f3 = residuals_plot(s, results.estimates["M1"], "M1")
    assert "(-)" in f3.axes[0].get_ylabel()
    plt.close("all")


def test_pages_of_an_earlier_report_are_removed(results, tmp_path):
    """A report with fewer pages than the one before it in the same folder leaves no stale page."""
    from reports.builder import build_report
    out = tmp_path / "out"
    out.mkdir()
    for name in ("page98_old.png", "page99_older.png", "notes.txt"):
        (out / name).write_text("old")
    (out / "results.json").write_text(json.dumps({"files": ["report.pdf", "page98_old.png", "page99_older.png",
                                                            "results.json"]}))
    paths = build_report(results, out, diagnose=False)
    left = sorted(p.name for p in out.iterdir())
    assert left == sorted({p.name for p in paths} | {"notes.txt"})
    assert "page98_old.png" not in left and "page99_older.png" not in left
