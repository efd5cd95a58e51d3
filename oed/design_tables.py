r"""Tables of a sensor design for pandas and Jupyter: :meth:`oed.DesignResult.to_frame` and ``_repr_html_``,
:meth:`oed.DesignTable.to_frame`.

One row per candidate sensor k: whether it is chosen, its cost (when the design had a budget), whether
it was forced in or out, and its information share in the chosen design

.. math::  s_k = \operatorname{tr}\bigl(M^{-1} F_k\bigr) / n_p,\qquad M = \sum_j w_j F_j,

(dimensionless; the shares of the chosen sensors add up to 1, an unchosen sensor's share is what it
would add relative to the design).  Reads the result only: it computes nothing but layout.
"""
from __future__ import annotations

import html

import numpy as np

__all__ = ["design_frame", "design_html", "table_frame"]


def design_frame(res):
    """The pandas DataFrame of a :class:`oed.DesignResult`, indexed by candidate (see the module docstring);
    the scalar results (criterion, kind, value, det, lower bound, gap, proof, method, status) in ``.attrs``."""
    import pandas as pd
    n = len(res.weights)
    names = res.candidates if len(res.candidates) == n else tuple(f"s{k}" for k in range(n))
    cols = {"selected": np.asarray(res.weights, dtype=bool)}
    if res.costs is not None:
        cols["cost"] = np.asarray(res.costs, dtype=float)
    cols["fixed"] = ["in" if k in res.include else ("out" if k in res.exclude else "") for k in range(n)]
    cols["information_share"] = (np.asarray(res.information_share, dtype=float) if len(res.information_share) == n
                                 else np.full(n, np.nan))
    df = pd.DataFrame(cols, index=pd.Index(names, name="candidate"))
    df.attrs.update(criterion=res.criterion, kind=res.kind, value=res.value, det=res.det,
                    lower_bound=res.lower_bound, gap=res.gap, proven_optimal=res.proven_optimal, method=res.method,
                    status=res.status, notes=res.notes)
    return df


def design_html(res) -> str:
    """HTML of a :class:`oed.DesignResult`: its summary as a two-column table, the candidate table of
    :func:`design_frame`, then the message, the near-singularity warning and the notes."""
    rows = [("criterion", f"{res.criterion} ({res.kind})"), ("method", res.method),
            ("status", res.status + (" (proven optimal)" if res.proven_optimal else "")),
            ("selected", ", ".join(res.sensors) if res.sensors else "-"), ("value", f"{res.value:.10g}"),
            ("lower bound", f"{res.lower_bound:.10g}"), ("gap", f"{res.gap:.3g}"),
            ("wall time", f"{res.wall_time:.3f} s")]
    if res.det is not None:
        rows.insert(5, ("det C", f"{res.det:.6g}"))
    head = "".join(f"<tr><th style=\"text-align:left\">{html.escape(k)}</th><td>{html.escape(v)}</td></tr>"
                   for k, v in rows)
    parts = [f"<table>{head}</table>", design_frame(res).to_html(float_format=lambda v: f"{v:.6g}")]
    extra = ([f"message: {res.message}"] if res.message else []) \
        + ([f"WARNING: {res.near_singular}"] if res.near_singular else []) + [f"note: {n}" for n in res.notes]
    if extra:
        parts.append("<ul>" + "".join(f"<li>{html.escape(x)}</li>" for x in extra) + "</ul>")
    return "\n".join(parts)


def table_frame(table):
    """The pandas DataFrame of a :class:`oed.DesignTable`: one row per combination (in the table's order),
    indexed by its mask, with the sensors (joined by ", "), A, det, log det, E, flag and reason; the
    covariance kind in ``.attrs``."""
    import pandas as pd
    df = pd.DataFrame({"sensors": [", ".join(r.sensors) for r in table.rows],
                       "A": np.array([r.A for r in table.rows], dtype=float),
                       "det": np.array([r.det for r in table.rows], dtype=float),
                       "logdet": np.array([r.logdet for r in table.rows], dtype=float),
                       "E": np.array([r.E for r in table.rows], dtype=float),
                       "flag": [r.flag for r in table.rows], "reason": [r.reason for r in table.rows]},
                      index=pd.Index([r.mask for r in table.rows], name="combination"))
    df.attrs["kind"] = table.kind
    return df
