"""Virtual prototype: physics (friction, clearance, path dependence), campaign, files, repeatability."""
import csv

import numpy as np
import pytest

from models.mechanism import RigidBody
from models.press import Q_PAPER
from models.prototype import (CAMPAIGN_DIR, CAMPAIGN_SEED, SIGMA_MAN_UM, PrototypeConfig, PrototypeError,
                              VirtualPrototype, composed_sigma, generate_campaign, read_campaign,
                              repeatability_table, write_campaign)

Q = np.array(Q_PAPER)


@pytest.fixture(scope="module")
def proto():
    return VirtualPrototype()


@pytest.fixture(scope="module")
def cycle(proto):
    """Two noise-free cycles from the virgin state; the second one is the steady cycle."""
    h1, info1, st = proto.run(Q)
    h2, info2, st2 = proto.run(Q, st)
    return h2, info2, st2


@pytest.fixture(scope="module")
def shipped():
    return read_campaign()


# ---------------------------------------------------------------------------- physics
def test_prototype_mechanism_has_clearance_bearings_with_residual_stiffness(proto):
    cfg = proto.config
    bodies = {b.name: b for b in proto.mechanism.of(RigidBody)}
    for body, joint, g in cfg.gaps:
        assert bodies[body].gap[joint] == g and 0.020 <= g <= 0.030
        assert bodies[body].gap_residual > 0
    assert proto.model.n_y == 34 and proto.model.inputs == ("q_P", "q_fric")


def test_friction_stays_within_the_load_dependent_breakaway_force(cycle, proto):
    h, info, _ = cycle
    cfg = proto.config
    Fb = cfg.breakaway_base + cfg.breakaway_slope * np.sqrt(info["normal"] ** 2 + cfg.normal_smoothing ** 2)
    np.testing.assert_allclose(info["breakaway"], Fb, rtol=1e-12)
    assert np.all(np.abs(info["friction"]) <= info["breakaway"] * (1 + 1e-12))
    # fully sliding on the upper loading branch, reversed on the lower unloading branch
    np.testing.assert_allclose(info["friction"][6:15], info["breakaway"][6:15], rtol=1e-9)
    np.testing.assert_allclose(info["friction"][20:], -info["breakaway"][20:], rtol=1e-9)
    # the break-away force grows with the load through the guide's normal force
    assert info["breakaway"][14] > info["breakaway"][1] + 40.0
    # after the reversal the elements stick first: |friction| < break-away
    assert abs(info["friction"][15]) < 0.5 * info["breakaway"][15]


def test_hysteresis_unloading_branch_lies_above_loading_branch(cycle):
    h, _, _ = cycle
    for j in range(1, 14):
        k = 28 - j                                            # same set force on the unloading branch
        assert Q[k] == pytest.approx(Q[j])
        assert h[k, 0] - h[j, 0] > 0.05                       # D_y, mm: more than 50 um hysteresis
        assert h[k, 1] - h[j, 1] < -0.003                     # F_x moves the other way
    # residual displacement at zero force after unloading (friction holds the ram)
    assert h[-1, 0] > 0.02


def test_steady_cycle_repeats_and_equilibrium_holds(proto, cycle):
    h2, _, st2 = cycle
    h3, _, st3 = proto.run(Q, st2)
    np.testing.assert_allclose(h3, h2, atol=1e-9)
    y, s, q = st3
    R = np.asarray(proto._fun(y, s, q)[0]).ravel()
    assert np.max(np.abs(R)) < 1e-8


def test_substeps_barely_matter(proto, cycle):
    fine = VirtualPrototype(PrototypeConfig(substeps=16))
    _, _, st = fine.run(Q)
    h_fine, _, _ = fine.run(Q, st)
    assert np.max(np.abs(h_fine - cycle[0])) < 2e-3                # mm: under 2 um


def test_bad_configuration_names_the_argument():
    with pytest.raises(PrototypeError, match="slip_fraction"):
        PrototypeConfig(slip_fraction=(0.5, 0.2, 0.2, 0.2))
    with pytest.raises(PrototypeError, match="k5"):
        PrototypeConfig(k5=-1.0)
    with pytest.raises(PrototypeError, match="gaps"):
        PrototypeConfig(gaps=(("carrier", "C", 0.0),))
    with pytest.raises(PrototypeError, match="gaps"):
        VirtualPrototype(PrototypeConfig(gaps=(("wheel", "C", 0.02),)))
    with pytest.raises(PrototypeError, match="n_series"):
        generate_campaign(n_series=1)
    with pytest.raises(PrototypeError, match="forces"):
        VirtualPrototype().run([])


# ---------------------------------------------------------------------------- campaign and files
def test_regenerating_the_shipped_campaign_gives_identical_files(tmp_path):
    fresh = generate_campaign(seed=CAMPAIGN_SEED)
    written = write_campaign(fresh, tmp_path)
    assert {p.name for p in written} == {p.name for p in CAMPAIGN_DIR.iterdir() if not p.name.startswith(".")}
    for p in written:
        assert p.read_bytes() == (CAMPAIGN_DIR / p.name).read_bytes(), p.name
    other = generate_campaign(seed=CAMPAIGN_SEED + 1)
    assert np.max(np.abs(other.z - fresh.z)) > 1e-3


def test_campaign_layout_matches_the_paper(shipped):
    c = shipped
    assert c.z.shape == (6, 29, 3) and c.sensors == ("D_y", "F_x", "B0_y")
    np.testing.assert_allclose(c.q_set, Q, atol=1e-4)
    assert np.all(np.diff(c.q_set[:15]) > 0) and np.all(np.diff(c.q_set[14:]) < 0)
    assert c.q_set[0] == 0 and c.q_set[-1] == 0 and c.q_set[14] == pytest.approx(1600.0)
    for k, s in enumerate(c.sensors):
        with open(CAMPAIGN_DIR / f"measurements_{s}.csv", newline="") as fh:
            rows = list(csv.reader(fh))
        assert rows[0] == ["force_N"] + [f"series_{i}" for i in range(1, 7)]
        tab = np.array(rows[1:], float)
        np.testing.assert_allclose(tab[:, 0], c.q_set, atol=1e-4)
        np.testing.assert_allclose(tab[:, 1:], 1e3 * c.z[:, :, k].T, atol=1e-4)   # um


def test_force_scatter_and_the_paper_correction(shipped):
    c = shipped
    pos = c.q_set > 0
    rel = c.q_actual[:, pos] / c.q_set[pos] - 1
    assert 0.003 < np.std(rel) < 0.03                          # 1-2 % scatter of the actual forces
    assert np.all(c.q_actual[:, ~pos] == 0)
    np.testing.assert_allclose(c.z[:, pos], c.z_raw[:, pos] * (c.q_set[pos] / c.q_actual[:, pos])[:, :, None],
                               atol=2e-7)
    np.testing.assert_array_equal(c.z[:, ~pos], c.z_raw[:, ~pos])


def test_shapiro_wilk_on_series_differences_passes_and_sigmas_match(shipped):
    tab = repeatability_table(shipped.z * 1e3)                 # um
    assert np.all(tab["p_value"] > 0.05), tab["p_value"]
    cfg = PrototypeConfig()
    ratio = tab["sigma"] / np.array(cfg.sigma_rep_um)
    assert np.all((ratio > 0.75) & (ratio < 1.35)), tab["sigma"]
    comp = composed_sigma(shipped.z)
    np.testing.assert_allclose(comp, np.sqrt(tab["sigma"] ** 2 + np.array(SIGMA_MAN_UM) ** 2))
    np.testing.assert_allclose(comp, [15.18, 4.895, 3.904], rtol=0.1)   # the paper's composed sigmas


def test_repeatability_table_rejects_bad_pairs():
    with pytest.raises(PrototypeError, match="pairs"):
        repeatability_table(np.zeros((2, 5, 1)), pairs=((1, 0), (3, 2)))
    with pytest.raises(PrototypeError, match="z"):
        repeatability_table(np.zeros((2, 5)))


def test_force_displacement_figure_shows_six_series_and_hysteresis(shipped):
    from reports.press_figures import plot_campaign
    fig = plot_campaign(sensor="D_y", campaign=shipped)
    ax = fig.axes[0]
    lines = ax.get_lines()
    assert len(lines) == 6
    for ln in lines:
        x, y = ln.get_data()
        assert np.allclose(x, shipped.q_set)
        assert y[21] - y[7] > 50.0                   # um: unloading above loading at 800 N
    with pytest.raises(ValueError, match="sensor"):
        plot_campaign(sensor="X_y", campaign=shipped)
