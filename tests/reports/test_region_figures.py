"""reports.region_figures: the LR region next to the ellipse, and the profile-t plot (issue 12)."""
from __future__ import annotations

import casadi as ca
import matplotlib
import numpy as np

matplotlib.use("Agg")

from identification import Measurements, identify  # noqa: E402
from identification.inference.profile import lr_region  # noqa: E402
from models import Model  # noqa: E402
from reports.region_figures import lr_region_figure, profile_figure  # noqa: E402


def _linear():
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] * q[0])
    x = np.linspace(0, 1, 6)
    z = (1 + 2 * x)[None, :, None] + 0.1 * np.random.default_rng(0).standard_normal((2, 6, 1))
    data = Measurements(x, z, [0.1])
    return model, data, identify(model, data, [0.0, 0.0])


def test_region_figure_contour_lies_on_the_ellipse_for_a_linear_model():
    import matplotlib.pyplot as plt
    model, data, est = _linear()
    reg = lr_region(model, data, est, (0, 1), n_grid=15, grid="axes")
    prof = est.conf_int(method="profile", model=model, data=data).profiles
    fig = lr_region_figure(reg, units=("mm", "mm/N"), profiles=prof, title="linear")
    ax = fig.axes[0]
    contour_xy = np.vstack([p.vertices for c in ax.collections for p in c.get_paths() if len(p.vertices)])
    # the profile traces of a linear model are the conjugate axes of the ellipse: straight lines through p_hat
    for line, pr in zip(ax.get_lines()[1:3], prof):
        np.testing.assert_allclose(line.get_xdata(), pr.params[:, 0])
        slope = np.diff(line.get_ydata()) / np.diff(line.get_xdata())
        np.testing.assert_allclose(slope, slope[0], rtol=1e-6)
    d = contour_xy - reg.estimate
    q = np.einsum("ni,ij,nj->n", d, np.linalg.inv(reg.cov), d)
    # contour vertices lie on grid edges, linearly interpolated: D is convex, so they lie inside the
    # ellipse, by at most the interpolation error h^2 / 8 |D''| = h^2 Ci_kk / 4 along an edge
    Ci = np.linalg.inv(reg.cov)
    err = max((reg.X[0, 1] - reg.X[0, 0]) ** 2 * Ci[0, 0], (reg.Y[1, 0] - reg.Y[0, 0]) ** 2 * Ci[1, 1]) / 4
    assert q.size > 20
    assert np.all(q <= reg.threshold + 1e-9) and np.all(q >= reg.threshold - err), (q.min(), q.max(), err)
    assert ax.get_xlabel() == "a (mm)" and len(ax.get_legend().get_texts()) == 5
    plt.close(fig)


def test_profile_figure_draws_the_profile_and_the_wald_line():
    import matplotlib.pyplot as plt
    model = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    x = np.linspace(0.2, 3.0, 8)
    z = (10 * (1 - np.exp(-0.7 * x)))[None, :, None] + 0.4 * np.random.default_rng(2).standard_normal((3, 8, 1))
    data = Measurements(x, z, [0.4])
    est = identify(model, data, [8.0, 1.0])
    ci = est.conf_int(method="profile", model=model, data=data, params=["b2"])
    fig = profile_figure(ci.profiles[0], est.stderr[1], unit="1/s")
    lines = fig.axes[0].get_lines()
    np.testing.assert_allclose(lines[0].get_xdata(), ci.profiles[0].values)
    np.testing.assert_allclose(lines[0].get_ydata(), ci.profiles[0].tau)
    plt.close(fig)
