"""Virtual prototype, fast path: the kept first cycle, the noise drawn in one go and the compiled
functions give the campaign of the series-by-series definition (same numbers)."""
import numpy as np
import pytest

from models.press import PRESS_SENSORS, Q_PAPER
from models.prototype import PrototypeConfig, VirtualPrototype, generate_campaign
from models.state import JIT, set_jit

Q = np.array(Q_PAPER)


@pytest.fixture(scope="module")
def proto():
    return VirtualPrototype()


def _linearity(rng, cfg, span):
    """The gauge linearity errors e_k(z) = sigma_k sqrt(2/m) sum_l a_l cos(w_l z + phi_l) (mm), as documented."""
    m = int(cfg.linearity_modes)
    errs = []
    for k in range(len(PRESS_SENSORS)):
        a = rng.standard_normal(m)
        w = 2 * np.pi * rng.uniform(0.5, 2.0, m) / span[k]
        phi = rng.uniform(0, 2 * np.pi, m)
        c = cfg.sigma_man_um[k] * 1e-3 * np.sqrt(2.0 / m)
        errs.append((a, w, phi, c))
    return lambda h: np.column_stack([c * np.sum(a[:, None] * np.cos(np.outer(w, h[:, k]) + phi[:, None]), axis=0)
                                      for k, (a, w, phi, c) in enumerate(errs)])


def _series_by_series(proto, seed, n_series):
    """The campaign by its definition: nominal cycle, run-in cycle (both from the virgin state),
    then per series the pressure level, the point jitter, the path and the repeatability errors."""
    cfg = proto.config
    rng = np.random.default_rng(seed)
    h_nom, _, _ = proto.run(Q)
    lin = _linearity(rng, cfg, np.maximum(np.ptp(h_nom, axis=0), 1e-3))
    _, _, state = proto.run(Q)
    q_act, z_raw = [], []
    for _ in range(n_series):
        level = cfg.force_scatter * rng.standard_normal()
        q = Q * (1.0 + level + cfg.force_scatter_point * rng.standard_normal(Q.size))
        h, _, state = proto.run(q, state)
        eps = np.asarray(cfg.sigma_rep_um) * 1e-3 * rng.standard_normal((Q.size, len(PRESS_SENSORS)))
        q_act.append(q)
        z_raw.append(h + lin(h) + eps)
    return np.array(q_act), np.array(z_raw)


def test_campaign_equals_its_series_by_series_definition(proto):
    c = generate_campaign(seed=123, n_series=2, prototype=proto)
    q_act, z_raw = _series_by_series(VirtualPrototype(), 123, 2)
    np.testing.assert_array_equal(c.q_actual, q_act)
    np.testing.assert_allclose(c.z_raw, z_raw, rtol=1e-12, atol=0)
    pos = Q > 0
    np.testing.assert_allclose(c.z[:, pos], (z_raw[:, pos] * (Q[pos] / q_act[:, pos])[:, :, None]), rtol=1e-12)


def test_first_cycle_is_the_run_from_the_virgin_state_and_is_not_shared(proto):
    h, info, (y, s, q) = proto.first_cycle(Q)
    h_run, info_run, (y_run, s_run, q_run) = VirtualPrototype().run(Q)
    np.testing.assert_array_equal(h, h_run)
    np.testing.assert_array_equal(info["friction"], info_run["friction"])
    np.testing.assert_array_equal(y, y_run)
    np.testing.assert_array_equal(s, s_run)
    assert q == q_run == 0.0
    h[:] = np.nan                                 # the caller's copy: the kept cycle stays intact
    s[:] = np.nan
    h2, _, (_, s2, _) = proto.first_cycle(Q)
    np.testing.assert_array_equal(h2, h_run)
    np.testing.assert_array_equal(s2, s_run)


def test_compiled_prototype_gives_the_same_campaign(proto):
    prev = set_jit(True)
    try:
        compiled = VirtualPrototype()
    finally:
        set_jit(prev)
    if JIT.failed:
        pytest.skip("no working C compiler: the prototype evaluates with the CasADi virtual machine")
    a = generate_campaign(seed=7, n_series=2, prototype=compiled)
    b = generate_campaign(seed=7, n_series=2, prototype=proto)
    np.testing.assert_allclose(a.z_raw, b.z_raw, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(a.q_actual, b.q_actual)


def test_prototype_for_another_config_is_refused(proto):
    from models.prototype import PrototypeError
    with pytest.raises(PrototypeError, match="prototype"):
        generate_campaign(seed=1, config=PrototypeConfig(substeps=2), prototype=proto)
