"""The project's one cache helper: computed values kept on the object they belong to.

A :class:`Cache` lives on its owner (``model.cache`` for a :class:`models.Model`) and holds
values computed from that owner under ``(namespace, key)``: the model's numerics, the
compiled NLP stage functions and Ipopt solvers of its identifications, the states and
scalings at a start point of repeated fits.  Nothing is kept in module globals keyed on the
owner, and the values go away with the owner.
"""
from __future__ import annotations

from collections import OrderedDict
from typing import Callable, Hashable

__all__ = ["Cache"]

_MISSING = object()


class Cache:
    """Values computed from one owner object, by namespace and key, optionally LRU-bounded.

    Each namespace is a separate table.  A table created with ``maxsize`` keeps at most that
    many entries and drops the least recently used one first; a table without it grows
    without bound (use it for one value per owner, such as a model's numerics).

    Copies and pickles of a cache are empty: the cached CasADi objects (compiled functions,
    Ipopt solvers) do not pickle, and a copied owner (e.g. :meth:`models.Model.with_bounds`)
    rebuilds what it needs on demand.

    Examples
    --------
    >>> cache = Cache()
    >>> cache.get_or_make("squares", 3, lambda: 3 ** 2)
    9
    >>> cache.get("squares", 3)
    9
    """

    __slots__ = ("_tables",)

    def __init__(self):
        self._tables: dict = {}

    def get(self, namespace: str, key: Hashable, default=None):
        """The value stored under (namespace, key), or ``default`` (marks it recently used)."""
        table = self._tables.get(namespace)
        if table is None:
            return default
        entries, maxsize = table
        value = entries.get(key, _MISSING)
        if value is _MISSING:
            return default
        if maxsize is not None:
            entries.move_to_end(key)
        return value

    def put(self, namespace: str, key: Hashable, value, maxsize: int | None = None):
        """Store ``value`` under (namespace, key) and return it.

        ``maxsize`` (a positive integer or None) bounds the namespace's table; it is fixed by
        the first ``put`` into that namespace.
        """
        table = self._tables.get(namespace)
        if table is None:
            if maxsize is not None and not (isinstance(maxsize, int) and maxsize >= 1):
                raise ValueError(f"maxsize: expected None or an integer >= 1, got {maxsize!r}")
            table = self._tables[namespace] = (OrderedDict(), maxsize)
        entries, bound = table
        entries[key] = value
        if bound is not None:
            entries.move_to_end(key)
            while len(entries) > bound:
                entries.popitem(last=False)
        return value

    def get_or_make(self, namespace: str, key: Hashable, make: Callable[[], object], maxsize: int | None = None):
        """The value under (namespace, key); computed by ``make()`` and stored when absent."""
        value = self.get(namespace, key, _MISSING)
        if value is _MISSING:
            value = self.put(namespace, key, make(), maxsize)
        return value

    def size(self, namespace: str) -> int:
        """Number of entries stored in a namespace (0 when it was never used)."""
        table = self._tables.get(namespace)
        return 0 if table is None else len(table[0])

    def clear(self, namespace: str | None = None) -> None:
        """Drop every entry of one namespace, or of all namespaces when ``namespace`` is None."""
        if namespace is None:
            self._tables.clear()
        else:
            self._tables.pop(namespace, None)

    def __reduce__(self):
        return (Cache, ())

    def __repr__(self):
        sizes = ", ".join(f"{name}: {len(t[0])}" for name, t in self._tables.items())
        return f"Cache({sizes})"
