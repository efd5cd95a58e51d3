"""The figures of an approximate design (reports.approx_figures): nothing hides the curve or another line
(issue 31 audit: on the reactor's sampling-time page the legend covered the sensitivity curve's trough and the
"prior mean" line lay hidden under the reference line at 1)."""
import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from reports.approx_figures import efficiency_curve, sensitivity_plot  # noqa: E402


def _legend_above_axes(ax) -> bool:
    fig = ax.figure
    fig.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    return legend.y0 >= ax.get_window_extent().y1


def test_the_sensitivity_legend_sits_above_the_curve():
    # the reactor's shape: optimum 4 touched at 0.2, 0.48 and 2 h, a trough near 1.2 h in the lower right
    x = np.linspace(0.2, 2.0, 200)
    g = (4.0 - 0.8 * np.sin(np.pi * (x - 0.48) / 1.52) ** 2 * (x > 0.48)
         - 0.07 * np.sin(np.pi * (x - 0.2) / 0.28) ** 2 * (x <= 0.48))
    fig = sensitivity_plot(x, g, 4.0, [0.2, 0.48, 2.0], "time (h)")
    ax = fig.axes[0]
    assert _legend_above_axes(ax)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "sensitivity function (checked points)", "optimum value 4", "maximum 4", "support points"]
    plt.close(fig)


def test_the_prior_mean_is_drawn_over_a_thin_reference_at_one():
    e, w = np.array([0.9984, 0.9995, 1.0005, 1.0016]), np.full(4, 0.25)         # prior mean 1.0000
    fig = efficiency_curve(e, w)
    ax = fig.axes[0]
    ref, mean = (next(ln for ln in ax.get_lines() if ln.get_label().startswith(s))
                 for s in ("robust design", "local design: prior mean 1.0000"))
    assert ref.get_ydata()[0] == 1.0 and abs(mean.get_ydata()[0] - 1.0) < 1e-12
    assert mean.get_zorder() > ref.get_zorder() and mean.get_linewidth() > ref.get_linewidth()
    assert ref.get_linestyle() != "-" and mean.get_linestyle() == ":"        # both broken lines: each shows
    assert _legend_above_axes(ax)
    plt.close(fig)
