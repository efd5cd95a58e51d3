"""The power study's campaign generator (bench.bench_detect.PrototypeCampaign): one prototype per copy."""
import pickle

import numpy as np

from bench.bench_detect import PrototypeCampaign


def test_prototype_is_built_once_per_copy_and_not_pickled():
    g = PrototypeCampaign(names=("M1",))
    a = g(np.random.default_rng(1))
    g(np.random.default_rng(2))
    assert g.n_builds == 1 and g.n_calls == 2
    assert g.cpu_total >= g.cpu_campaign > 0
    blob = pickle.dumps(g)
    assert len(blob) < 10_000                       # the prototype's CasADi functions stay behind
    copy = pickle.loads(blob)
    assert copy.n_builds == 0 and copy.n_calls == 0
    b = copy(np.random.default_rng(1))              # a worker's copy builds its own prototype once
    copy(np.random.default_rng(3))
    assert copy.n_builds == 1 and copy.n_calls == 2
    np.testing.assert_array_equal(a.z, b.z)
