"""DesignResult.to_frame / _repr_html_ (issue 21 item 6): one row per candidate sensor, the summary as HTML;
DesignTable.to_frame: one row per combination."""
import numpy as np

from oed import design_table, select_sensors_from_information

NAMES = ("u1", "u2", "F_top", "F_base", "T<x>", "v")


def _information(seed=3, n=6, p=3):
    J = np.random.default_rng(seed).standard_normal((n, 4, p))
    return np.einsum("kip,kir->kpr", J, J)


def test_frame_holds_the_results_arrays_one_row_per_candidate():
    F = _information()
    costs = [1.0, 2.0, 1.5, 3.0, 1.0, 2.5]
    res = select_sensors_from_information(F, criterion="D", costs=costs, budget=6.0, include=["F_top"],
                                          exclude=[5], sensor_names=NAMES, method="enumerate")
    df = res.to_frame()
    assert tuple(df.index) == NAMES and df.index.name == "candidate"
    assert np.array_equal(df["selected"].to_numpy(), np.asarray(res.weights))
    assert tuple(df.index[df["selected"]]) == res.sensors
    assert np.array_equal(df["cost"].to_numpy(), np.asarray(costs)) and res.costs == tuple(costs)
    assert list(df["fixed"]) == ["", "", "in", "", "", "out"]
    assert np.array_equal(df["information_share"].to_numpy(), np.asarray(res.information_share))
    # the share tr(M^-1 F_k) / n_p: the chosen sensors' shares add up to 1
    w = np.asarray(res.weights)
    M = F[w].sum(axis=0)
    ref = [np.trace(np.linalg.solve(M, f)) / 3 for f in F]
    assert np.allclose(df["information_share"], ref, rtol=1e-12, atol=0)
    assert abs(df["information_share"][df["selected"]].sum() - 1.0) < 1e-12
    assert df.attrs["value"] == res.value and df.attrs["method"] == "enumerate"
    assert df.attrs["proven_optimal"] is res.proven_optimal


def test_frame_without_budget_has_no_cost_column():
    res = select_sensors_from_information(_information(), criterion="A", n_sensors=3, sensor_names=NAMES)
    df = res.to_frame()
    assert "cost" not in df.columns and res.costs is None
    assert int(df["selected"].sum()) == 3 and set(df["fixed"]) == {""}


def test_html_shows_the_summary_and_the_selected_sensors():
    res = select_sensors_from_information(_information(), criterion="E", n_sensors=3, sensor_names=NAMES)
    page = res._repr_html_()
    assert page.count("<table") == 2
    for name in res.sensors:
        assert name in page
    assert "T&lt;x&gt;" in page and "T<x>" not in page          # names are escaped
    assert f"{res.value:.10g}" in page and res.method in page and "selected" in page


def test_no_design_found_leaves_the_share_empty():
    F = _information(n=4, p=3)
    F[:, :, 2] = F[:, 2, :] = 0.0                                    # parameter 3 is never identified
    res = select_sensors_from_information(F, criterion="D", n_sensors=2, method="enumerate")
    assert res.status == "infeasible" and res.information_share == ()
    df = res.to_frame()
    assert not df["selected"].any() and df["information_share"].isna().all()
    assert "infeasible" in res._repr_html_()


def test_table_frame_holds_every_row():
    table = design_table(_information(n=5), sensor_names=NAMES[:5], min_sensors=3)
    df = table.to_frame()
    assert list(df.index) == [r.mask for r in table.rows] and df.attrs["kind"] == table.kind
    for col in ("A", "det", "logdet", "E"):
        assert np.array_equal(df[col].to_numpy(), [getattr(r, col) for r in table.rows])
    assert list(df["sensors"]) == [", ".join(r.sensors) for r in table.rows]
    assert list(df["flag"]) == [r.flag for r in table.rows]
    page = table._repr_html_()
    assert all(f"<th>{r.mask}</th>" in page for r in table.rows) and "T&lt;x&gt;" in page
