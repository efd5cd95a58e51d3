"""One vocabulary for the public verbs (issue 28, item 8), and the one-release bridge from the old names.

The words every public verb uses for the same thing:

============  =====================================================================================
``p0``        a start of an iteration (a fit, a profile, a replication's fit), shape (n_p,)
``p``         the point at which something is evaluated (a design's nominal parameters, the truth
              that a simulation study draws from), shape (n_p,)
``data``      the measurements a verb reads (:class:`identification.Measurements`, or the
              time-series :class:`identification.DynamicMeasurements`)
``inputs``    the input rows q_j that are applied, shape (n_q, d_q)
``candidates`` the input rows to choose from, shape (n_candidates, d_q)
``n_series``  the number of repeated measurement series of every input
``n_rep``     the number of replications of a study (Monte Carlo campaigns, bootstrap resamples)
``alpha``     every level: a test's size, 1 - a region's confidence
============  =====================================================================================

A verb that used another word for one of these takes the old keyword for one release: the call works,
with a :class:`DeprecationWarning` that names the new keyword (:func:`renamed_arguments`).
"""
from __future__ import annotations

import functools
import inspect
import warnings

__all__ = ["VOCABULARY", "SYNONYMS", "NUMERICAL_TOLERANCES", "renamed_arguments"]

#: the public words (see the module docstring)
VOCABULARY = ("p0", "p", "data", "inputs", "candidates", "n_series", "n_rep", "alpha")

#: words that public verbs no longer use, with the word that replaced them
SYNONYMS = {
    "p_true": "p", "p_nominal": "p",
    "measurements": "data", "experiments": "data",
    "n_M": "n_series", "n_boot": "n_rep",
    "tol": "alpha", "level": "alpha",
}

#: public verbs whose ``tol`` is a numerical tolerance, not a level (not renamed)
NUMERICAL_TOLERANCES = {"identification.solve_state": "tol"}


def renamed_arguments(**old_to_new: str):
    """Decorate a verb whose keyword arguments were renamed: ``f(old=x)`` calls ``f(new=x)`` with a
    :class:`DeprecationWarning` naming the new keyword (kept for one release).

    Parameters
    ----------
    **old_to_new : str or (str, callable)
        The old keyword and the parameter of the decorated function that replaces it, or that parameter and
        the conversion of an old value into a new one (e.g. ``level=("alpha", lambda c: 1 - c)`` for a
        confidence level that became a size).

    Raises
    ------
    TypeError
        At decoration, when a new name is not a parameter of the function or an old one still is; at a call,
        when both the old and the new keyword are given.
    """
    def decorate(func):
        params = inspect.signature(func).parameters
        renames = {old: (new, None) if isinstance(new, str) else tuple(new) for old, new in old_to_new.items()}
        for old, (new, _) in renames.items():
            if new not in params:
                raise TypeError(f"renamed_arguments: {func.__qualname__} has no parameter {new!r} (for {old!r})")
            if old in params:
                raise TypeError(f"renamed_arguments: {func.__qualname__} still has the old parameter {old!r}")

        @functools.wraps(func)
        def wrapper(*args, **kwargs):
            for old, (new, convert) in renames.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{func.__name__}(): give {new}= only ({old}= is its old name)")
                    warnings.warn(f"{func.__name__}(): the keyword {old}= is deprecated, use {new}= "
                                  f"(the old name is removed in the next release)", DeprecationWarning, stacklevel=2)
                    value = kwargs.pop(old)
                    kwargs[new] = value if convert is None else convert(value)
            return func(*args, **kwargs)

        wrapper.renamed_arguments = {old: new for old, (new, _) in renames.items()}
        return wrapper
    return decorate
