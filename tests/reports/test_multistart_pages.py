"""The page 'Multi-start fit of ...' drawn from a small MultiStartRecord (issue 30 item 2)."""
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from identification.fit.multistart import LocalMinimum, MultiStartRecord
from reports.builder import page_texts
from reports.multistart_pages import minima_rows, multistart_pages, multistart_variants, waterfall_plot


def record(objective=(1.5, 1.5 + 1e-9, 40.0, 1.5, np.nan, 3000.0, 40.0, 0.9)) -> MultiStartRecord:
    """8 starts of a 2-parameter fit: the best minimum (3 starts), a second (2 starts), a start that failed, one
    whose fit the data do not bound, one alone at a third minimum."""
    obj = np.array(objective, float)
    outcome = ("minimum", "minimum", "minimum", "minimum", "failed", "minimum", "minimum", "not bounded")
    p = np.array([[1.0, 2.0], [1.0, 2.0], [3.0, 0.5], [1.0, 2.0], [np.nan, np.nan], [9.0, 9.0], [3.0, 0.5],
                  [1e6, 0.0]])
    minima = (LocalMinimum(obj[0], p[0], (0, 1, 3)), LocalMinimum(obj[2], p[2], (2, 6)),
              LocalMinimum(obj[5], p[5], (5,)))
    return MultiStartRecord(param_names=("k", "c"), starts=np.arange(16.0).reshape(8, 2) + 1, p=p, objective=obj,
                            outcome=outcome, status=("ok",) * 8,
                            errors=("", "", "", "", "ConvergenceError: no step", "", "", ""), warnings=((),) * 8,
                            fit_time=np.full(8, 0.1), best=0, reached_best=3, minima=minima, objective_tol=1.5e-6,
                            parameter_tol_se=1e-2, rules=("k uniform in [0, 10]", "c uniform in [0, 10]"), seed=7,
                            backend="serial", wall_time=0.8)


def test_waterfall_sorts_the_starts_draws_plateaus_and_marks_the_estimate():
    ms = record()
    fig = waterfall_plot(ms)
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"                       # 0.9 .. 3000: more than two decades
    plateaus = [c for c in ax.collections if c.get_segments()]
    levels = sorted(seg[0][1] for c in plateaus for seg in c.get_segments())
    assert levels == pytest.approx([1.5, 40.0, 3000.0])
    star = [ln for ln in ax.lines if ln.get_marker() == "*"][0]
    assert star.get_xdata()[0] == 2 and star.get_ydata()[0] == 1.5   # after the not-bounded start at 0.9
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[:3] == ["best minimum: 3 starts", "minimum 2: 2 starts", "minimum 3: 1 start"]
    assert "not bounded by the data: 1 (objective limit)" in labels
    assert ax.get_xlim() == pytest.approx((0.3, 7.7))     # 7 starts drawn, the failed one not


def test_one_level_reads_without_offset_and_linear():
    ms = record(objective=(5.0, 5.0, 5.0, 5.0, np.nan, 5.0, 5.0, 5.0))
    ax = waterfall_plot(ms).axes[0]
    assert ax.get_yscale() == "linear" and ax.get_ylim() == pytest.approx((4.95, 5.05))


def test_minima_table_and_page():
    ms = record()
    head, rows = minima_rows(ms, ("N/mm", ""))
    assert head == ["minimum", "objective Phi", "starts", "reached from", "k [N/mm]", "c"]
    assert rows[0] == ["1 (best)", "1.5", "3", "1, 2, 4", "1", "2"] and rows[2][3] == "6"
    est = SimpleNamespace(diagnostics=SimpleNamespace(starts=ms), param_units=("N/mm", ""))
    single = SimpleNamespace(diagnostics=SimpleNamespace(starts=None))
    results = SimpleNamespace(estimates={"A": est, "B": single})
    assert multistart_variants(results) == ["A"]
    figs = multistart_pages(results, "A")
    text = " ".join(" ".join(page_texts(figs[0])).split())      # the wrapped lines joined
    assert "Multi-start fit of A" in text and "3 of 8 starts reached the best minimum" in text
    assert "start 5: ConvergenceError: no step" in text and "3 distinct local minima" in text
    assert "seed 7" in text and "1 start ended on a fit the data do not bound" in text


def test_a_flat_valley_shows_its_ranges_and_its_note():
    """Minimum 2 of the record is a flat valley in c (starts 3 and 7 at c = 0.5 and 40): the row gives the range, the
    legend and the page name it, the page carries its note."""
    ms = record()
    valley = LocalMinimum(40.0, np.array([3.0, 0.5]), (2, 6), np.array([3.0, 0.5]), np.array([3.0, 40.0]), 40.0 + 1e-9,
                          ("c",), "segment", "c is not determined by the data between 0.5 and 40: 2 starts ended along "
                          "a flat valley over that range")
    ms = MultiStartRecord(**{**{f: getattr(ms, f) for f in ms.__dataclass_fields__},
                             "minima": (ms.minima[0], valley, ms.minima[2]), "valley_tol": 1.5e-6})
    head, rows = minima_rows(ms, ("N/mm", ""))
    assert rows[1] == ["2 (valley)", "40 (all within 1e-09)", "2", "3, 7", "3", "0.5 to 40"]
    labels = [t.get_text() for t in waterfall_plot(ms).axes[0].get_legend().get_texts()]
    assert "minimum 2 (flat valley in c): 2 starts" in labels
    est = SimpleNamespace(diagnostics=SimpleNamespace(starts=ms), param_units=("N/mm", ""))
    text = " ".join(" ".join(page_texts(multistart_pages(SimpleNamespace(estimates={"A": est}), "A")[0])).split())
    assert "Minimum 2 is a flat valley, not isolated" in text and "Not isolated: flat valleys" in text
    assert "Minimum 2: c is not determined by the data between 0.5 and 40: 2 starts ended along a flat valley" in text
    assert "objectives within 1.5e-06 and no barrier between them" in text
