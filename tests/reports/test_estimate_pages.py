"""The estimates page: columns sized to their content (no cut-off model names or split labels), and a
dynamic study's discretisation (mesh, largest output error in % of sigma, bounded or not) on the
estimates page and as a numbered note on the title page, read from what the study computed."""
import dataclasses
import json
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def reactor():
    """The shipped reactor study fitted on all study data (no detection: fast)."""
    from mudoe.config import load_config
    from mudoe.kind.time_series import run_discretisation
    from mudoe.study import StudyResults, prepare, run_identify
    study = prepare(load_config(REPO / "configs" / "reactor.toml"))
    return run_discretisation(study, run_identify(study, StudyResults(study)))


def _overflowing_cells(fig) -> list:
    """The table cells of ``fig`` whose text runs past the cell's right border."""
    from matplotlib.table import Table
    renderer = fig.canvas.get_renderer()
    bad = []
    for ax in fig.axes:
        for t in [c for c in ax.get_children() if isinstance(c, Table)]:
            for cell in t.get_celld().values():
                text = cell.get_text()
                if text.get_text().strip() and text.get_window_extent(renderer).x1 > \
                        cell.get_window_extent(renderer).x1 + 0.5:
                    bad.append(text.get_text())
    return bad


def test_estimates_table_shows_the_full_model_name(reactor):
    import matplotlib.pyplot as plt
    from mudoe.report_record import study_record
    from reports.builder import _estimate_pages, page_texts
    fig, = _estimate_pages(study_record(reactor))
    fig.canvas.draw()
    assert "isothermal" in page_texts(fig)
    assert _overflowing_cells(fig) == []          # "isotherma" was drawn under the next column
    plt.close("all")


def test_content_widths_fit_long_labels_and_shrink_print_only_when_needed():
    import matplotlib.pyplot as plt
    from reports.tables import content_widths, draw_table
    head = ["model", "data", "sensors", "k5 (N/mm)", "k7 (N/mm)", "largest |corr|"]
    rows = [["temperature_profile", "loading+unloading interleaved: calibration", "F_x,B0_y", "537 +- 28",
             "461 +- 30", "+0.986 (k5, k7)"]]
    w, size = content_widths(head, rows, 8, 0.92 * 11.69)
    assert sum(w) == pytest.approx(1.0) and size == 8          # fits at 8 pt: the print is not shrunk
    fig = plt.figure(figsize=(11.69, 8.27))
    draw_table(fig.add_axes([0.04, 0.5, 0.92, 0.1]), head, rows, fontsize=size, col_widths=w)
    fig.canvas.draw()
    assert _overflowing_cells(fig) == []
    wide = [["m", "x" * 60] + ["1.2345e+06 +- 0.0012e+06"] * 8]
    w2, size2 = content_widths(["model", "data"] + [f"p{k}" for k in range(8)], wide, 8, 0.92 * 11.69)
    assert 6.5 <= size2 < 8 and sum(w2) == pytest.approx(1.0)
    plt.close("all")


def test_dynamic_report_states_the_discretisation(reactor, tmp_path):
    """results.json's page texts hold the mesh line on the estimates page and the note on the title page."""
    from mudoe.report_record import study_record
    from reports.builder import build_report
    m = reactor.discretisation["isothermal"]
    assert m.bounded and m.degree == 3 and m.n_elements > 0 and 0 <= m.error_pct <= m.tol_pct == 1.0
    build_report(study_record(reactor), tmp_path, dpi=20, diagnose=False, uncertainty="none")
    meta = json.loads((tmp_path / "results.json").read_text())
    pages = {p["file"]: " ".join(p["texts"]).replace("\n", " ") for p in meta["pages"]}
    line = (f"isothermal: Radau IIA collocation, degree 3, {m.n_elements} elements; largest discretisation error "
            f"{m.error_pct:.2g} % of sigma (bounded below 1 %)")
    title = next(t for f, t in pages.items() if "title" in f)
    estimates = next(t for f, t in pages.items() if "estimates" in f)
    assert line in title and "] isothermal: Radau IIA" in title          # a numbered note
    assert line in estimates and "Discretisation of the fits on all study data" in estimates
    assert meta["results"]["discretisation"]["isothermal"]["n_elements"] == m.n_elements


def test_a_fit_whose_error_is_not_bounded_says_so_in_red(reactor):
    import matplotlib.pyplot as plt
    from mudoe.kind.time_series import mesh_summary
    from mudoe.report_record import study_record
    from reports.builder import _estimate_pages, _title_page
    est = reactor.estimates["isothermal"]
    rec = dataclasses.replace(est.diagnostics.discretisation, bounded=False, error_sigma=0.034,
                              reason="no mesh within 4000 elements")
    m = mesh_summary(dataclasses.replace(est, extra={"discretisation": rec}))
    assert not m.bounded and "3.4 % of sigma" in m.text() and "NOT bounded" in m.text()
    bad = study_record(dataclasses.replace(reactor, discretisation={"isothermal": m}))
    for fig in (_estimate_pages(bad)[0], _title_page(bad)):
        red = [t for t in fig.texts if "NOT bounded" in t.get_text().replace("\n", " ")]
        assert red and all(matplotlib.colors.to_hex(t.get_color()) == matplotlib.colors.to_hex("tab:red")
                           for t in red)
    plt.close("all")


def test_trajectory_grid_merges_times_that_differ_by_rounding_and_states_its_error(reactor):
    """401 points over 2 h put 1.4000000000000001 next to the sampling time 1.4: one time, not a
    collocation error; the caption reads the grid's discretisation error the study computed."""
    import matplotlib.pyplot as plt
    from mudoe.kind.time_series import trajectories
    from mudoe.report_record import study_record
    from reports.dynamic_pages import _trajectory_pages
    tr = trajectories(reactor.study, reactor.estimates["isothermal"], "isothermal", n_fine=401)
    assert 1.4 in tr.t and tr.t.size == 401 and 0 <= tr.error_sigma <= tr.tol_sigma
    r = study_record(dataclasses.replace(reactor, trajectories={"isothermal": tr}))
    words = " ".join(t.get_text() for t in _trajectory_pages(r)[0].texts).replace("\n", " ")
    assert f"discretisation error at most {100 * tr.error_sigma:.2g} % of sigma, below 1 %" in words
    plt.close("all")
