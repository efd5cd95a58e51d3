"""One protocol for every public result (issue 28, item 7): ``summary()``, ``to_frame()``, ``to_dict()``, ``_repr_html_``.

A result of the library (an :class:`identification.Estimate`, a :class:`identification.DetectionResult`, a
design of :mod:`oed`, a plan record of :mod:`mudoe`, ...) derives from :class:`ResultProtocol` and gives

* ``summary()``: a text in the style of statsmodels (a head, the table, numbered notes ``[k]`` at the end
  where the result has notes);
* ``to_frame()``: its main table as a pandas DataFrame (scalars in ``.attrs``);
* ``to_dict()``: a JSON-safe dict (``json.dumps(r.to_dict(), allow_nan=False)`` works: arrays are lists,
  NaN is null, +-inf the strings "inf" / "-inf"), the same content that a report's ``results.json`` holds
  for that result (:mod:`reports.serialize` writes it through ``to_dict``);
* ``_repr_html_()``: the view in a notebook, by default the head of the summary, the frame and the text.

This module is one of identification's shared modules: it imports no floor (import-linter's contract in
pyproject.toml), so that every layer above models can host a result.  pandas is imported by ``to_frame``
only, when it is called.
"""
from __future__ import annotations

import dataclasses
import math
from html import escape

import numpy as np

__all__ = ["ResultProtocol", "RESULT_METHODS", "jsonable", "notes_lines", "is_result"]

#: the methods every public result has (the test tests/test_result_protocol.py checks them on every class)
RESULT_METHODS = ("summary", "to_frame", "to_dict", "_repr_html_")


def jsonable(obj):
    """Recursively convert numpy arrays/scalars, tuples, dataclasses to JSON-safe values.

    dict keys become str, tuples and arrays lists, numpy scalars Python ones, NaN None, +-inf the strings
    "inf" / "-inf", a dataclass the dict of its fields; anything else unknown its ``str``.  Applied twice it
    gives the same value (the output is already JSON-safe)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        if math.isnan(v):
            return None
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return v
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if obj is None or isinstance(obj, (str, int)):
        return obj
    return str(obj)


def notes_lines(notes) -> list:
    """The closing block of a summary: ``["", "Notes:", "[1] ...", ...]``, or ``[]`` without notes."""
    notes = [str(n) for n in notes]
    if not notes:
        return []
    return ["", "Notes:"] + [f"[{k}] {n}" for k, n in enumerate(notes, 1)]


def is_result(obj) -> bool:
    """True when ``obj`` (an instance or a class) has every method of :data:`RESULT_METHODS`."""
    return all(callable(getattr(obj, m, None)) for m in RESULT_METHODS)


class ResultProtocol:
    """The mixin of every public result: ``summary``, ``to_frame``, ``to_dict`` and ``_repr_html_``.

    A result class overrides the first three (the ones here raise NotImplementedError, so that a class that
    forgot one fails loudly and in tests/test_result_protocol.py); ``_repr_html_`` has a default built from
    them.  The mixin holds no field and no state."""

    __slots__ = ()

    def summary(self) -> str:
        """The text summary (head, table, numbered notes)."""
        raise NotImplementedError(f"{type(self).__name__}.summary")

    def to_frame(self):
        """The main table as a pandas DataFrame."""
        raise NotImplementedError(f"{type(self).__name__}.to_frame")

    def to_dict(self) -> dict:
        """A JSON-safe dict of the result (see :func:`jsonable`)."""
        raise NotImplementedError(f"{type(self).__name__}.to_dict")

    def _repr_html_(self) -> str:
        """Jupyter's view: the first line of :meth:`summary` in bold, the table of :meth:`to_frame`, and the
        whole text summary folded below it."""
        text = self.summary()
        head = text.splitlines()[0] if text else type(self).__name__
        table = self.to_frame().to_html(float_format=lambda v: f"{v:.6g}")
        return (f"<p><b>{escape(head)}</b></p>" + table
                + f"<details><summary>text summary</summary><pre>{escape(text)}</pre></details>")
