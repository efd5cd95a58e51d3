"""A report for a user's own model: a 3-parameter implicit model with chemical units (no press).

The study runs through the study API (config, CSV data, identify, OED, detect) and the report
is checked from the texts the builder drew on every page (results.json "pages"), not pixels:
every parameter is named with its unit, no press word appears, the digits follow the
standard errors, page 1 opens with the verdict table, grids never exceed 6 panels a row.
"""
import json
import re
import sys
import textwrap

import numpy as np
import pytest

TOY = '''
import casadi as ca
from models.contract import Model, Parameter


def phases(T):
    top = int(max(range(len(T)), key=lambda j: T[j]))
    return ["heating" if j <= top else "cooling" for j in range(len(T))]


def make(variant):
    """Equilibrium y1 (1 + K y1) = A exp(-E_a / T) of a product y1, side product y2 = K y1^2; three sensors."""
    params = [Parameter("A", 0.01, 100.0, unit="mol/L"), Parameter("E_a", 1.0, 1e5, unit="K"),
              Parameter("K", 1e-6, 1e3, unit="L/mol")]
    m = Model(params, ["T"], ["c_P", "c_R", "c_Q"], n_y=2,
              E=lambda y, p, q: ca.vertcat(y[0] * (1 + p[2] * y[0]) - p[0] * ca.exp(-p[1] / q[0]),
                                           y[1] - p[2] * y[0] ** 2),
              h=lambda y, p, q: ca.vertcat(y[0], p[0] - y[0], y[1]),
              name=f"equilibrium {variant}", sensor_units=["mol/L"] * 3, input_units=["K"])
    m.mudoe_phases = phases
    return m
'''

TRUE = np.array([2.0, 600.0, 0.8])
PRESS_WORDS = re.compile(r"\b(force|displacement|N/mm|press|k5|k7|loading|unloading)\b", re.IGNORECASE)


@pytest.fixture(scope="module")
def toy_results(tmp_path_factory):
    from mudoe.config import parse_config
    from mudoe.data_io import DataUnits, write_paper_layout
    from mudoe.study import StudyResults, prepare, run_bands, run_detect, run_diagnosis, run_identify, run_oed
    import importlib
    tmp = tmp_path_factory.mktemp("toy")
    pkg = tmp / "mytoy_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "chem.py").write_text(TOY)
    sys.path.insert(0, str(tmp))
    try:
        make = importlib.import_module("mytoy_pkg.chem").make
        T = np.r_[np.linspace(300, 500, 9), np.linspace(500, 300, 9)[1:]]
        h = make("x").simulate(TRUE, T[:, None])
        z = h + 0.002 * np.random.default_rng(3).standard_normal((4,) + h.shape)
        units = DataUnits("K", "K", ("mol/L",) * 3, ("mol/L",) * 3, input_name="T", input_key="input_unit",
                          output_key="output_unit")
        write_paper_layout(tmp / "data", T, z, ["c_P", "c_R", "c_Q"], units=units)
        text = textwrap.dedent("""\
            [model]
            name = "mytoy_pkg.chem:make"
            variants = ["equilibrium"]
            [data]
            directory = "data"
            input_unit = "K"
            output_unit = "mol/L"
            [[sensors]]
            name = "c_P"
            sigma = 0.002
            [[sensors]]
            name = "c_R"
            sigma = 0.002
            [[sensors]]
            name = "c_Q"
            sigma = 0.002
            [[parameters]]
            name = "A"
            start = 2.2
            [[parameters]]
            name = "E_a"
            start = 650.0
            [[parameters]]
            name = "K"
            start = 0.7
            [splits]
            scenarios = []
            [splits.random]
            n = 7
            [detect]
            sensors = "all"
            [oed]
            criterion = "D"
            [report]
            title = "Equilibrium study"
            dpi = 30
            """)
        study = prepare(parse_config(text, str(tmp / "toy.toml"), tmp))
        r = run_detect(study, run_oed(study, run_identify(study, StudyResults(study))))
        yield run_bands(study, run_diagnosis(study, r)), tmp
    finally:
        sys.path.remove(str(tmp))
        for name in [m for m in sys.modules if m.startswith("mytoy_pkg")]:
            del sys.modules[name]


@pytest.fixture(scope="module")
def toy_report(toy_results):
    from mudoe.report_record import study_record
    from reports.builder import build_report
    r, tmp = toy_results
    out = tmp / "report"
    build_report(study_record(r), out)
    meta = json.loads((out / "results.json").read_text())
    return r, meta, {p["file"]: p["texts"] for p in meta["pages"]}


def test_every_parameter_named_with_unit_and_no_press_words(toy_report):
    r, meta, pages = toy_report
    alltext = "\n".join(t for texts in pages.values() for t in texts)
    for head in ("A (mol/L)", "E_a (K)", "K (L/mol)"):
        assert head in alltext
    bad = sorted({m.group(0) for m in PRESS_WORDS.finditer(alltext)})
    assert bad == [], f"press words in a non-press report: {bad}"
    assert "()" not in alltext and " um" not in alltext
    assert "T (K)" in alltext and "c_P (mol/L)" in alltext
    assert "heating" in alltext and "cooling" in alltext         # the declared phases are distinguished


def test_every_parameter_pair_and_every_split_has_an_ellipse(toy_report):
    r, meta, pages = toy_report
    det = r.detection
    ell = {f: t for f, t in pages.items() if "_ellipses" in f}
    assert len(ell) >= 2                                         # 7 splits > 6 columns: paginated
    labels = [t for texts in ell.values() for t in texts]
    for name in ("A (mol/L)", "E_a (K)", "K (L/mol)"):          # 3 pairs: each parameter on 2 axes per split
        assert labels.count(name) == 2 * len(det.splits), name
    titles = [t for texts in ell.values() for t in texts if t.startswith("equilibrium: ")]
    assert len(titles) == 3 * len(det.splits)


def test_digits_follow_the_standard_errors(toy_report):
    from reports.view import fmt_value
    r, meta, pages = toy_report
    e = r.estimates["equilibrium"]
    est = [t for f, texts in pages.items() if "_estimates" in f for t in texts]
    for p, s in zip(e.p, e.stderr):
        v, se = fmt_value(p, s)
        assert f"{v} +- {se}" in est
        digits = se.replace(".", "").lstrip("0").split("e")[0]
        assert len(digits) == 2                                  # two significant digits of the error
        decimals = lambda x: len(x.split("e")[0].split(".")[1]) if "." in x else 0   # noqa: E731
        assert decimals(v) == decimals(se)
    assert abs(e.p - TRUE).max() / TRUE.max() < 0.05            # the fit itself is sound


def test_page_one_opens_with_the_verdict_table(toy_report):
    r, meta, pages = toy_report
    first = pages[sorted(pages)[0]]
    assert first[0] == "Equilibrium study"
    i_table = first.index("Verdicts (Algorithm 1)")
    i_prose = next(i for i, t in enumerate(first) if t.startswith("equilibrium: "))
    assert i_table < i_prose
    d = r.detection.decision("equilibrium").decision
    word = d
    assert word in first and "ACCEPT" not in "\n".join(first) and "accept" not in "\n".join(first)
    assert any(t.startswith("Goodness of fit") or "goodness of fit" in t for t in first)
    e = r.estimates["equilibrium"]
    assert ("trustworthy" if e.curvature.trustworthy else "NOT trustworthy") in first   # the Bates-Watts column


def test_d_criterion_is_log_det_in_table_and_text(toy_report):
    r, meta, pages = toy_report
    oed = [t for f, texts in pages.items() if "_oed" in f for t in texts]
    assert "Psi_D (log det C)" in oed
    assert any(f"log det C = {r.oed.value:.4f}" in " ".join(t.split()) for t in oed)      # the text
    assert f"{r.oed.value:.4f}" in oed                                                      # the table cell


@pytest.mark.parametrize("value,se,expect", [
    (530.04, 13.96, ("530", "14")), (0.012345, 0.00067, ("0.01235", "0.00067")),
    (123456.0, 1234.0, ("123500", "1200")), (5.0, 0.0996, ("5.00", "0.10")), (-2.5, 0.051, ("-2.500", "0.051")),
    (1.2345e-8, 3.4e-10, ("1.235e-08", "0.034e-08")), (3.0, float("nan"), ("3", "n/a")),
    (float("nan"), 1.0, ("failed", "n/a")), (2.0, 0.0, ("2", "n/a"))])
def test_fmt_value(value, se, expect):
    from reports.view import fmt_value
    assert fmt_value(value, se) == expect


def test_prediction_bands_match_the_delta_method(toy_results):
    from scipy import stats
    from mudoe.band_runs import prediction_bands
    r, _ = toy_results
    e = r.estimates["equilibrium"]
    b = prediction_bands(e, 0.95)
    j, k = 3, 1
    g = e.G[j, k]
    z = stats.norm.ppf(0.975)                                    # sigma given: normal quantile
    assert b.half_mean[j, k] == pytest.approx(z * np.sqrt(g @ e.cov @ g), rel=1e-12)
    assert b.half_new[j, k] == pytest.approx(z * np.sqrt(g @ e.cov @ g + e.sigma[k] ** 2), rel=1e-12)
    with pytest.raises(ValueError, match="level"):
        prediction_bands(e, 0.05)


def test_holm_adjusted_p_values():
    from mudoe.diagnosis_runs import holm_adjusted
    p = [0.01, 0.04, 0.03, float("nan"), 0.5]
    # m = 5 planned tests: sorted 0.01, 0.03, 0.04, 0.5 -> 5*0.01, max(., 4*0.03), max(., 3*0.04), max(., 2*0.5)
    exp = [0.05, 0.12, 0.12, float("nan"), 1.0]
    np.testing.assert_allclose(holm_adjusted(p), exp)


def test_what_the_model_misses_page(toy_report):
    r, meta, pages = toy_report
    diag = meta["diagnosis"]
    kinds = {row["kind"] for row in diag["rows"]}
    assert kinds == {"study split", "input range", "phase", "series"}
    assert len(diag["rows"]) == len(r.detection.splits) + 3
    for row in diag["rows"]:
        if row["alpha"] is not None:
            assert row["holm"] >= row["alpha"]
            assert row["rejected"] == (row["holm"] < 0.05)
    misses = [t for f, texts in pages.items() if "_misses" in f for t in texts]
    assert "heating vs cooling (phase)" in misses and "low vs high input" in misses
    assert any(t.startswith("Findings:") or "Findings:" in t for t in misses)
