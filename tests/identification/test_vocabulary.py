"""The one vocabulary of the public verbs (issue 28, item 8) and the bridge from the old keywords."""
from __future__ import annotations

import inspect
import warnings

import pytest

import identification
import oed
from identification.vocabulary import NUMERICAL_TOLERANCES, SYNONYMS, VOCABULARY, renamed_arguments


def _public_verbs():
    import mudoe
    for pkg in (identification, oed, mudoe):
        for name in pkg.__all__:
            obj = getattr(pkg, name)
            if inspect.isfunction(obj):
                yield f"{pkg.__name__}.{name}", obj


def test_no_public_verb_uses_an_old_word():
    old = {f"{where}({arg})": SYNONYMS[arg] for where, f in _public_verbs()
           for arg in inspect.signature(f).parameters
           if arg in SYNONYMS and NUMERICAL_TOLERANCES.get(where) != arg}
    assert old == {}


def test_the_vocabulary_and_its_synonyms_do_not_overlap():
    assert not set(SYNONYMS) & set(VOCABULARY)
    assert set(SYNONYMS.values()) <= set(VOCABULARY)


def _f(data, p0=None, *, alpha=0.05):
    return data, p0, alpha


def test_an_old_keyword_works_with_a_warning_naming_the_new_one():
    g = renamed_arguments(measurements="data", tol="alpha")(_f)
    with pytest.warns(DeprecationWarning, match=r"tol= is deprecated, use alpha="):
        assert g(1, tol=0.1) == (1, None, 0.1)
    with pytest.warns(DeprecationWarning, match=r"measurements= is deprecated, use data="):
        assert g(measurements=2) == (2, None, 0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert g(3, p0=4, alpha=0.2) == (3, 4, 0.2)
    assert list(inspect.signature(g).parameters) == ["data", "p0", "alpha"]


def test_old_and_new_keyword_together_is_an_error():
    g = renamed_arguments(tol="alpha")(_f)
    with pytest.raises(TypeError, match="give alpha= only"):
        g(1, tol=0.1, alpha=0.2)


@pytest.mark.parametrize("mapping, match", [({"tol": "beta"}, "no parameter 'beta'"),
                                             ({"data": "alpha"}, "still has the old parameter 'data'")])
def test_a_wrong_rename_fails_at_decoration(mapping, match):
    with pytest.raises(TypeError, match=match):
        renamed_arguments(**mapping)(_f)


def test_an_old_keyword_can_be_converted():
    g = renamed_arguments(level=("alpha", lambda c: 1.0 - c))(_f)
    with pytest.warns(DeprecationWarning, match="level= is deprecated, use alpha="):
        assert g(1, level=0.9) == pytest.approx((1, None, 0.1))
