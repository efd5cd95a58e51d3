"""The page "Model uncertainty" (issue 29 item 4) drawn from records alone: a stub study record whose views hold
an :class:`identification.studies.records.ErrorSummary` (no study, no fit)."""
import dataclasses

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from identification.studies.model_error_result import EmbeddedParameter  # noqa: E402
from identification.studies.model_ranking import ModelRanking  # noqa: E402
from identification.studies.records import ErrorSummary, ModelErrorView, SensorErrorSize  # noqa: E402
from reports.builder import page_texts, report_pages  # noqa: E402
from reports.model_error_pages import model_uncertainty_page, relative_spread, summary_rows  # noqa: E402

from record_stub import stub_record  # noqa: E402


def _view(variant: str, detected: bool, ranking=None, next_runs=("q = 1600 N",)) -> ModelErrorView:
    kind = "discrepancy" if detected else "none"
    sizes = (SensorErrorSize("y", "um", 10.7 if detected else 0.0, 5.6 if detected else 0.0, "q = 680 N", 12.7, 13.8,
                             9.71, 9.89, *((12.75, 12.70) if next_runs and detected else (float("nan"),) * 2),
                             size=np.array([4.0, 10.7, 2.0]), half=np.array([13.0, 12.7, 13.8]),
                             plain=np.array([9.7, 9.71, 9.89])),)
    summary = ErrorSummary(variant=variant, kind=kind, detected=detected, p_value=1e-20 if detected else 0.4,
                           alpha=0.05, size_is="|mean discrepancy|",
                           grid="41 points over the data's range (q 0-1600 N)",
                           sizes=sizes, embedded=(EmbeddedParameter("k5", 2.0, 0.031),) if detected else (),
                           next_runs=next_runs if detected else (),
                           next_how=("2 new run(s) of 2 series each" if detected
                                     else "no error model: no runs to learn it"),
                           x=np.array([0.0, 680.0, 1600.0]), x_label="q [N]")
    return ModelErrorView(variant=variant, result=None, sensors=("y",), units=("um",), input_label="q [N]",
                          q=None, discrepancy=(), heldout=None, summary=summary, ranking=ranking)


def _ranking(margin_se: float) -> ModelRanking:
    return ModelRanking(rows=(), use="B", use_error=False, margin=0.3, margin_total=30.0, runner_up="A",
                        comparable=True, margin_se=margin_se, split_margins=(("s1", 50, 0.2), ("s2", 50, 0.4)))


def test_the_page_is_drawn_from_the_records_with_the_verdict_and_the_numbers():
    rank = _ranking(0.05)
    rec = stub_record({}, model_error_views={"A": _view("A", True, rank), "B": _view("B", False, rank)})
    fig = model_uncertainty_page(rec)
    texts = " ".join(" ".join(page_texts(fig)).split())   # wrapped lines read as one
    plt.close(fig)
    assert "Model uncertainty" in texts and "Which model to use for prediction: predict with B" in texts
    assert "Verdict: choose B" in texts
    assert "10.7 um" in texts and "q = 680 N" in texts and "±12.7 (13.8) um" in texts and "±9.71 (9.89) um" in texts
    assert "12.8 -> 12.7 um" in texts
    assert "Measure next: q = 1600 N" in texts and "k5 ±3.1 %" in texts and "+-" not in texts
    assert "No error model: no runs to learn it." in texts
    assert "Over the data's range: the band to design with (solid)" in texts and "A: band with discrepancy" in texts
    assert "B: band with none" not in texts               # no error model: no curves


def test_tiny_relative_spreads_print_as_below_a_hundredth_of_a_percent():
    # "k5 +-0.00383 %" before: digits below 0.01 % of |p| are noise for the engineer
    assert relative_spread(0.0874) == "±8.74\u00a0%" and relative_spread(0.031) == "±3.1\u00a0%"    # no-break
    assert relative_spread(3.83e-5) == "<\u00a0±0.01\u00a0%" and relative_spread(1e-4) == "±0.01\u00a0%"
    assert relative_spread(float("nan")) == "-"
    view = _view("A", True)
    tiny = dataclasses.replace(view.summary, embedded=(EmbeddedParameter("k5", 2.0, 3.83e-5),))
    rec = stub_record({}, model_error_views={"A": dataclasses.replace(view, summary=tiny)})
    fig = model_uncertainty_page(rec)
    texts = " ".join(" ".join(page_texts(fig)).split())
    plt.close(fig)
    assert "k5 < ±0.01 %." in texts and "0.00383" not in texts


def test_a_tie_says_either_model_predicts_as_well():
    rec = stub_record({}, model_error_views={"A": _view("A", True, _ranking(0.5))})
    fig = model_uncertainty_page(rec)
    texts = " ".join(" ".join(page_texts(fig)).split())   # wrapped lines read as one
    plt.close(fig)
    assert "a tie within 2 SE" in texts and "either model predicts as well" in texts


def test_summary_rows_shade_the_detected_variant_only():
    head, rows, flags = summary_rows([_view("A", True), _view("B", False)])
    assert len(rows) == 2 and len(head) == len(rows[0])
    assert any(flags[0]) and not any(flags[1])
    assert rows[1][4] == "0" and rows[1][-1] == "-"        # no error model: size 0, no next runs


def test_the_page_is_listed_only_when_a_view_has_a_summary():
    import dataclasses
    with_summary = stub_record({}, model_error_views={"A": _view("A", True)})
    without = stub_record({}, model_error_views={"A": dataclasses.replace(_view("A", True), summary=None)})
    assert "model_uncertainty" in [n for n, _ in report_pages(with_summary, with_diagnosis=False, uncertainty="none")]
    assert "model_uncertainty" not in [n for n, _ in report_pages(without, with_diagnosis=False, uncertainty="none")]


def test_the_page_says_which_sigma_the_bands_take_once():
    noise = "The model-error bands take sigma_rep, the repeatability of the series (y 1.2 um), as the noise."
    rank = _ranking(0.05)
    views = {v: dataclasses.replace(_view(v, v == "A", rank), noise=noise) for v in ("A", "B")}
    fig = model_uncertainty_page(stub_record({}, model_error_views=views))
    texts = " ".join(" ".join(page_texts(fig)).split())
    plt.close(fig)
    assert texts.count(noise) == 1 and "Verdict: choose B" in texts and "±12.7 (13.8) um" in texts
    fig = model_uncertainty_page(stub_record({}, model_error_views={"A": _view("A", True, rank)}))
    texts = " ".join(" ".join(page_texts(fig)).split())
    plt.close(fig)
    assert "the noise" not in texts                        # no sentence given: none drawn


def test_the_coverage_table_marks_a_condition_not_seen_predicted_from_one_condition():
    from identification.studies.model_error_result import HeldOut
    from reports.model_error_pages import UNSEEN_MARK, coverage_rows, unseen_footnote

    def held(name, n_unseen, n_cond):
        return HeldOut(name, 56, 0.2, 0.964, 0.6, 3.6, 3.0, -1.0, 1.0, 0.5, n_unseen, n_cond)

    class Result:
        heldout = (held("odd vs even", 0, 1), held("loading vs unloading", 52, 1), held("days 1-4 vs 5", 28, 4))

    head, rows = coverage_rows(Result)
    assert head[-2:] == ["cal. conditions", "not seen"]
    assert [r[3] for r in rows] == ["96.4", f"96.4 {UNSEEN_MARK}", "96.4"]
    assert [r[-2:] for r in rows] == [[1, "-"], [1, 52], [4, 28]]
    foot = unseen_footnote(Result)
    assert foot.startswith(UNSEEN_MARK) and "69-76 % in Monte Carlo" in foot and "lower bound" in foot

    class Calibrated:
        heldout = (held("days 1-4 vs 5", 28, 4),)

    assert unseen_footnote(Calibrated) == ""
