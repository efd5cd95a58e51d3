"""oed.best_designs: the ``top`` designs of one size, ranked as if every design were sorted, and the chosen one listed."""
import itertools

import numpy as np
import pytest

from oed.best_designs import best_designs
from oed.criteria import batch_criteria


def _information(n, n_p, seed, ties=0):
    """Rank-one information of ``n`` candidates; the last ``ties`` repeat the first ones (equal criteria)."""
    a = np.random.default_rng(seed).standard_normal((n, n_p))
    a[n - ties:] = a[:ties]
    return np.einsum("ki,kj->kij", a, a)


def _ranked_by_sorting_all(F, size, criterion):
    """Masks of every design of ``size``, sorted by the criterion (stable: ties in enumeration order)."""
    combos = list(itertools.combinations(range(F.shape[0]), size))
    W = np.zeros((len(combos), F.shape[0]))
    for r, c in enumerate(combos):
        W[r, list(c)] = 1.0
    res = batch_criteria(F, None, W)
    val = {"A": res.A, "D": res.logdet, "E": res.E}[criterion]
    val = np.where(~res.singular & np.isfinite(val), val, np.inf)
    order = np.argsort(val, kind="stable")
    return ["".join("1" if k in combos[i] else "0" for k in range(F.shape[0])) for i in order]


@pytest.mark.parametrize("criterion", ["A", "D", "E"])
def test_the_top_designs_over_several_batches_are_those_of_a_full_sort(criterion):
    F = _information(16, 4, seed=5, ties=3)              # 8008 designs of 6: two batches of the enumeration
    expected = _ranked_by_sorting_all(F, 6, criterion)
    table = best_designs(F, None, [f"t{k}" for k in range(16)], 6, criterion, top=10)
    assert [r.mask for r in table.rows] == expected[:10]
    assert table.note == "the 10 best of all 8008 designs of 6"
    # the values the rows report are the criterion's of that design (evaluated alone: batched round-off apart)
    for r in table.rows:
        w = np.array([c == "1" for c in r.mask], float)
        one = batch_criteria(F, None, w[None])
        assert np.allclose([r.logdet, r.A, r.E], [one.logdet[0], one.A[0], one.E[0]], rtol=1e-12, atol=0)


def test_the_chosen_design_is_listed_after_a_long_enumeration():
    # 177,100 designs of 6 of 25: more than the enumeration once kept in memory (it then dropped the chosen
    # design when it was not among the best)
    F = _information(25, 6, seed=2)
    chosen = (0, 1, 2, 3, 4, 5)
    table = best_designs(F, None, [f"t{k}" for k in range(25)], 6, "D", chosen=chosen, top=10)
    assert len(table.rows) == 11 and table.rows[-1].mask == "1" * 6 + "0" * 19
    assert table.note == "the 10 best of all 177100 designs of 6"
    values = [r.logdet for r in table.rows[:10]]
    assert values == sorted(values) and values[-1] <= table.rows[-1].logdet


def test_neighbours_of_the_chosen_design_are_counted():
    F = _information(25, 6, seed=2)
    table = best_designs(F, None, [f"t{k}" for k in range(25)], 6, "D", chosen=(0, 1, 2, 3, 4, 5),
                         top=4, max_enumerate=100)
    assert table.note.startswith("the best of the chosen design and its 114 neighbours")      # 6 out x 19 in
    assert len(table.rows) == 5 and table.rows[-1].mask == "1" * 6 + "0" * 19


def test_a_negative_top_is_refused():
    with pytest.raises(ValueError, match="top"):
        best_designs(_information(6, 2, seed=1), None, list("abcdef"), 2, "D", top=-1)
