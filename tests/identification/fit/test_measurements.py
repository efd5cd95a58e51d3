"""Measurements: validation, NaN handling, immutability and subsetting (property-based)."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from identification import DataError, Measurements

dims = st.tuples(st.integers(1, 4), st.integers(1, 6), st.integers(1, 3))


@st.composite
def campaigns(draw):
    n_M, n_q, n_S = draw(dims)
    z = draw(arrays(float, (n_M, n_q, n_S), elements=st.floats(-1e6, 1e6, allow_nan=False)))
    holes = draw(arrays(bool, (n_M, n_q, n_S)))
    holes[0, 0, :] = False            # every sensor keeps at least one value
    z = np.where(holes, np.nan, z)
    q = draw(arrays(float, (n_q, 2), elements=st.floats(-1e3, 1e3, allow_nan=False)))
    sigma = draw(st.one_of(st.none(), arrays(float, (n_S,), elements=st.floats(1e-9, 1e3))))
    return Measurements(q, z, sigma)


@settings(max_examples=60, deadline=None)
@given(campaigns())
def test_counts_means_and_ndata_respect_nan(m):
    mask = np.isfinite(m.z)
    assert m.n_data() == mask.sum()
    assert np.array_equal(m.counts(), mask.sum(axis=0))
    means = m.means()
    for j in range(m.n_q):
        for k in range(m.n_S):
            vals = m.z[:, j, k][mask[:, j, k]]
            if vals.size:
                assert means[j, k] == pytest.approx(vals.mean(), rel=1e-12, abs=1e-9)
            else:
                assert np.isnan(means[j, k])


@settings(max_examples=60, deadline=None)
@given(campaigns(), st.data())
def test_subset_returns_new_consistent_objects(m, data):
    qi = data.draw(st.lists(st.integers(0, m.n_q - 1), min_size=1, unique=True))
    si = data.draw(st.lists(st.integers(0, m.n_M - 1), min_size=1, unique=True))
    keep = np.isfinite(m.z[np.ix_(si, qi, range(m.n_S))]).reshape(-1, m.n_S).any(axis=0)
    if not keep.all():
        with pytest.raises(DataError, match="no finite value"):
            m.subset(inputs=qi, series=si)
        return
    sub = m.subset(inputs=qi, series=si)
    assert sub is not m and sub.z.shape == (len(si), len(qi), m.n_S)
    np.testing.assert_array_equal(sub.inputs, m.inputs[qi])
    np.testing.assert_array_equal(sub.z, m.z[np.ix_(si, qi, range(m.n_S))])
    assert sub.series == tuple(m.series[i] for i in si)


@settings(max_examples=30, deadline=None)
@given(campaigns())
def test_immutable(m):
    with pytest.raises(ValueError):
        m.z[0, 0, 0] = 1.0
    with pytest.raises(AttributeError):
        m.sigma = None


@settings(max_examples=40, deadline=None)
@given(campaigns())
def test_pickle_round_trip(m):
    """Measurements reach worker processes (pickle) unchanged and still immutable."""
    import pickle
    r = pickle.loads(pickle.dumps(m))
    np.testing.assert_array_equal(r.inputs, m.inputs)
    np.testing.assert_array_equal(r.z, m.z)
    assert (r.sigma is None) == (m.sigma is None)
    if m.sigma is not None:
        np.testing.assert_array_equal(r.sigma, m.sigma)
    assert (r.sensors, r.input_names, r.series) == (m.sensors, m.input_names, m.series)
    with pytest.raises(AttributeError):
        r.sigma = None


@pytest.mark.parametrize("kwargs, match", [
    (dict(inputs=np.ones((3, 1)), z=np.ones((2, 4, 1))), "z: has 4 inputs along axis 1 but inputs has 3 rows"),
    (dict(inputs=np.ones((3, 1)), z=np.ones((3, 1))), r"z: expected shape \(n_M, n_q, n_S\)"),
    (dict(inputs=np.ones((2, 1)), z=[[[1.0, np.nan], [2.0, np.nan]]]), "sensor 's2' .*NaN only"),
    (dict(inputs=np.ones((2, 1)), z=np.ones((1, 2, 2)), sigma=[1.0, 0.0]), "sigma: must be positive .* 's2'"),
    (dict(inputs=np.ones((2, 1)), z=np.ones((1, 2, 2)), sigma=[1.0, -2.0]), "sigma: must be positive"),
    (dict(inputs=np.ones((2, 1)), z=np.ones((1, 2, 2)), sigma=[1.0]), "sigma: expected 2 values"),
    (dict(inputs=[[1.0], [np.nan]], z=np.ones((1, 2, 1))), "inputs: non-finite value at row 1"),
    (dict(inputs=np.ones((2, 1)), z=np.full((1, 2, 1), np.inf)), "z: infinite value"),
    (dict(inputs=np.ones((2, 1)), z=[[["a"], ["b"]]]), "z: not numeric"),
    (dict(inputs=np.ones((2, 1)), z=np.ones((1, 2, 1)), sensors=["a", "b"]), "sensors: 2 names"),
])
def test_bad_input(kwargs, match):
    with pytest.raises(DataError, match=match):
        Measurements(**kwargs)


def test_select_and_bad_selection():
    m = Measurements(np.arange(3.0), np.arange(18.0).reshape(2, 3, 3), [1, 2, 3], sensors=["a", "b", "c"])
    s = m.select(["c", "a"])
    assert s.sensors == ("c", "a") and list(s.sigma) == [3, 1]
    np.testing.assert_array_equal(s.z[..., 0], m.z[..., 2])
    with pytest.raises(DataError, match="unknown sensor 'x'"):
        m.select(["x"])
    with pytest.raises(DataError, match="out of range"):
        m.subset(inputs=[5])
    with pytest.raises(DataError, match="appears twice"):
        m.subset(series=[0, 0])
    with pytest.raises(DataError, match="weights: expected 3"):
        m.n_data([1, 1])
