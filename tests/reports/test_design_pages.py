"""The report's design page of [oed] mode inputs / both / discrimination (issue 13 item 6)."""
import textwrap

import casadi as ca
import numpy as np
import pytest

from models import Model
from mudoe.config import parse_config
from mudoe.study import PlannedDesign, plan_without_data
from oed.inputs import select_inputs
from reports.builder import page_texts, report_pages
from reports.design_pages import design_pages

from record_stub import stub_record


def _texts(figs):
    import matplotlib.pyplot as plt
    out = []
    for fig in figs:
        fig.canvas.draw()
        out.append(" | ".join(page_texts(fig)))
        plt.close(fig)
    return out


def _explicit():
    return Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * ca.exp(-p[1] * q[0])))


def _results(plan, model):
    return stub_record({plan.variant: model}, plan=plan)


def test_input_design_page_shows_the_exact_rows_next_to_the_refinement():
    m = _explicit()
    q = np.linspace(1.0, 1000.0, 12)
    res = select_inputs(m, [200.0, 0.005], candidates=q[:, None], sigma=[1.0, 0.5], n_points=2, criterion="D",
                        refine=True)
    assert res.refined is not None and res.refined.n_failed < len(res.refined.start_values)
    plan = PlannedDesign("own", "inputs", True, (200.0, 0.005), tuple(q), res)
    [text] = _texts(design_pages(_results(plan, m)))
    for j, lev in zip(res.indices, res.refined.inputs.ravel()):
        assert f"{q[j]:g}" in text and f"{lev:.6g}" in text            # exact level and its refinement, one row
    assert "refined set point" in text and "proven optimal" in text
    assert f"{res.refined.value:.4g}" in text and f"{res.value:.4g}" in text


def test_joint_design_page_lists_the_chosen_pairs():
    m = _explicit()
    q = np.linspace(1.0, 1000.0, 8)
    res = select_inputs(m, [200.0, 0.005], candidates=q[:, None], sigma=[1.0, 0.5], n_points=3, sensors="joint")
    plan = PlannedDesign("own", "both", True, (200.0, 0.005), tuple(q), res)
    [text] = _texts(design_pages(_results(plan, m)))
    assert "Joint input x sensor design" in text and "Chosen 3 of 16 candidate (set point, sensor) pairs" in text
    for j, s in res.pairs:
        assert f"{q[j]:g} | {s}" in text


PLANNED = textwrap.dedent("""\
    [model]
    name = "press"
    variants = ["M2", "M3"]

    [data]
    source = "csv"
    directory = "no_such_folder"
    displacement_unit = "um"

    [[sensors]]
    name = "D_y"
    sigma = 15.18
    [[sensors]]
    name = "F_x"
    sigma = 4.895
    [[sensors]]
    name = "B0_y"
    sigma = 3.904

    [[parameters]]
    name = "k5"
    start = 520.0
    lower = 1.0
    upper = 1.0e5
    [[parameters]]
    name = "k7"
    start = 443.0
    lower = 1.0
    upper = 1.0e5

    [oed]
    planned = true
    mode = "discrimination"
    variant = "M3"
    rival = "M2"
    n_readings = 4
    candidates = [0.0, 400.0, 800.0, 1200.0, 1600.0, 1200.0, 800.0, 400.0, 0.0]
    """)


@pytest.fixture(scope="module")
def discrimination_plan():
    return plan_without_data(parse_config(PLANNED, "rivals.toml", "."))


def test_discrimination_page_shows_readings_and_values_against_the_even_design(discrimination_plan):
    from models.friction import candidate_models
    plan = discrimination_plan
    [text] = _texts(design_pages(_results(plan, candidate_models()["M3"])))
    assert "M3 (assumed true) against M2" in text
    for name, readings in (("chosen", plan.result.readings),) + tuple(plan.references.items()):
        v = plan.design_values(name)
        assert f"{name} | {len(readings)} | {v['T']:.4g} | {v['T_refit']:.4g}" in text
    T = plan.scores["T"]
    for j, s in plan.result.readings:
        assert f"{plan.candidates[j]:g} | {s} |" in text and f"{T[j, plan.result.candidate_sensors.index(s)]:.3g}" in text
    assert plan.values(plan.result.readings)["T"] >= plan.values(plan.references["evenly spread"])["T"]
    assert "divergence" not in text.split("per series")[0].split("|")[-1]     # planned: no covariances, no column


def test_report_lists_the_design_page_after_the_sensor_design_only_with_a_plan(discrimination_plan):
    from models.friction import candidate_models
    with_plan = [n for n, _ in report_pages(_results(discrimination_plan, candidate_models()["M3"]),
                                            with_diagnosis=False)]
    assert with_plan[with_plan.index("oed") + 1] == "design"
    without = [n for n, _ in report_pages(stub_record({}), with_diagnosis=False)]
    assert "design" not in without
