"""The ``[oed]`` keys that depend on the kind of study: a static study's input design over set points, a dynamic
study's design of its next experiments (issue 30 item 8).

A dynamic study with ``mode = "inputs"`` designs ``n_points`` new experiments (default 1, the next one): their
constants and control profiles (one value per grid point of each control) within ``bounds``, chosen among the
study's own experiments and ``n_candidates`` random experiments within the bounds (seeded by ``seed``), and with
``refine = true`` moved continuously within the bounds (:func:`mudoe.dynamic_plans.input_design`)::

    [oed]
    mode = "inputs"
    n_points = 1                               # experiments designed (default 1)
    bounds = { TL = [0.0, 0.03], u = [-12.0, 12.0] }   # model units; a control: every grid value
    n_candidates = 8                           # random candidate experiments (besides the study's own)
    refine = true                              # continuous refinement within the bounds (Ipopt)
    time_limit = 60                            # seconds for the whole design

An input not named in ``bounds`` keeps the range of the study's experiments (a control: of all its grid values);
``lower = upper`` holds it fixed.  What needs the model (the input names) is checked when the design is made
(:func:`mudoe.dynamic_plans.input_bounds`); here only the form and the keys' combinations.
"""
from __future__ import annotations

import math

from .config_errors import ConfigContext

__all__ = ["read_bounds", "check_design_keys", "DYNAMIC_INPUT_KEYS"]

#: the [oed] keys of a dynamic study's input design only
DYNAMIC_INPUT_KEYS = ("bounds", "n_candidates", "seed")


def read_bounds(ctx: ConfigContext, v) -> dict:
    """``{input: (lower, upper)}`` of the TOML value of ``[oed] bounds`` (form checked: finite, lower <= upper)."""
    if not isinstance(v, dict) or not v:
        raise ctx.error("oed", "bounds", "expected a table {input = [lower, upper]}, e.g. bounds = { u = [-12.0, "
                        f"12.0] }}, got {v!r}")
    out = {}
    for name, b in v.items():
        ok = (isinstance(b, list) and len(b) == 2
              and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in b))
        if not ok:
            raise ctx.error("oed", "bounds", f"input {name!r}: expected [lower, upper] (two finite numbers), got {b!r}")
        if not b[0] <= b[1]:
            raise ctx.error("oed", "bounds", f"input {name!r}: lower {b[0]:g} > upper {b[1]:g}")
        out[name] = (float(b[0]), float(b[1]))
    return out


def check_design_keys(ctx: ConfigContext, o, dynamic: bool, given) -> None:
    """The [oed] design keys against the kind of study (``given``: the keys written in the [oed] table).

    A static study's ``mode`` inputs / both need ``n_points`` (unless a prior or ``approximate``) and candidate
    set points; a dynamic study's ``mode = "inputs"`` designs experiments (no set points, no sensor include /
    exclude / costs), ``mode = "both"`` is refused with what to use instead.
    """
    if not dynamic or o.mode != "inputs":
        for k in DYNAMIC_INPUT_KEYS:
            if k in given:
                where = "a static study's inputs are the set points (candidates, candidates_range)" if not dynamic \
                    else f"mode is {o.mode!r}"
                raise ctx.error("oed", k, f"only for the design of a dynamic study's experiments (mode = \"inputs\"); "
                                f"{where}")
    if not dynamic:
        if o.mode in ("inputs", "both"):
            if o.n_points is None and not (o.prior or o.approximate):
                raise ctx.error("oed", "mode", f"mode = {o.mode!r} needs n_points (how many to choose)")
            if not (o.candidates or o.candidates_range):
                raise ctx.error("oed", "mode", f"mode = {o.mode!r} needs candidates or candidates_range")
        return
    if o.mode == "both":
        raise ctx.error("oed", "mode", "a joint design of a dynamic study's experiments and instruments is not "
                        "available in mudoe oed: use mode = \"inputs\" (every instrument read at every sampling time) "
                        "or mode = \"sensors\" (the sampling times), or oed.select_inputs(..., sensors=\"joint\", "
                        "times=...) in Python")
    if o.mode != "inputs":
        return
    for k in ("candidates", "candidates_range"):
        if k in given:
            raise ctx.error("oed", k, "set points are a static study's candidates; a dynamic study's candidate "
                            "experiments are its own and n_candidates random ones within bounds")
    for k in ("include", "exclude", "costs", "budget", "max_sensors", "n_sensors"):
        if k in given:
            raise ctx.error("oed", k, "not used by the design of a dynamic study's experiments (every instrument "
                            "is read at every sampling time of [dynamic] times); leave it out")
