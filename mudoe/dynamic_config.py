"""The ``[dynamic]`` section of a study config: a study of an ODE/DAE model (``Model.ode``).

::

    [dynamic]
    times = [0.2, 0.4, 0.6]          # sampling times of the data (the model's time unit)
    candidate_times = [...]          # candidates of the sampling-time design (default: times)
    n_times = 4                      # sampling times chosen (default: one per parameter)
    pairs = false                    # choose (time, instrument) pairs instead of times
    [[dynamic.experiments]]          # one table per experiment: its inputs by name (model units); empty for a
                                     # model without inputs (one empty table per run)
    cA0 = 1.0                        # a constant input
    T = [350, 360, 370]              # a control: one value per grid point of its grid

Every instrument has one sigma ([[sensors]], not one per time).  The checks that need the model (times
within the horizon, input names, the number of grid values of a control) are made when the study is
prepared (:func:`mudoe.dynamic_study.experiment_rows`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .config_errors import EntryContext

__all__ = ["DynamicConfig", "parse_dynamic"]

_KEYS = ("times", "candidate_times", "n_times", "pairs", "experiments")


@dataclass(frozen=True)
class DynamicConfig:
    """A dynamic study's sampling times and experiments (see the module docstring).

    Attributes
    ----------
    times : tuple of float             sampling times of the data / of a simulated campaign
    candidate_times : tuple of float   candidates of the time design (empty: ``times``)
    n_times : int or None              times (or pairs) chosen by the design (None: n_p)
    pairs : bool                       design over (time, instrument) pairs
    experiments : tuple of dict        {input name: value, or list of control grid values}
    """

    times: tuple = ()
    candidate_times: tuple = ()
    n_times: int | None = None
    pairs: bool = False
    experiments: tuple = ()

    def candidates(self) -> tuple:
        """The candidate sampling times of the design."""
        return self.candidate_times or self.times


def _times(ctx, key, v) -> tuple:
    if not isinstance(v, list) or not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                   for x in v):
        raise ctx.error("dynamic", key, f"expected a non-empty list of numbers (times), got {v!r}")
    t = tuple(float(x) for x in v)
    bad = [x for x in t if not math.isfinite(x) or x < 0]
    if bad:
        raise ctx.error("dynamic", key, f"sampling times must be finite and >= 0, got {bad[0]:g}")
    for a, b in zip(t, t[1:]):
        if not b > a:
            raise ctx.error("dynamic", key, f"sampling times must be strictly increasing; {b:g} follows {a:g}")
    return t


def _experiment(ctx, k: int, t) -> dict:
    if not isinstance(t, dict):       # empty: an experiment of a model without inputs
        raise ctx.error("dynamic.experiments", "", f"experiment {k + 1}: expected a table of input values")
    out = {}
    for name, v in t.items():
        vals = v if isinstance(v, list) else [v]
        if not vals or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                               for x in vals):
            raise ctx.error("dynamic.experiments", name, f"experiment {k + 1}: expected a finite number (or a list "
                            f"of numbers for a control), got {v!r}")
        out[name] = tuple(float(x) for x in vals) if isinstance(v, list) else float(v)
    return out


def parse_dynamic(ctx, t) -> DynamicConfig:
    """The ``[dynamic]`` table checked for what needs no model (``ctx``: the config's error context)."""
    if not isinstance(t, dict):
        raise ctx.error("", "dynamic", f"expected a table, got {type(t).__name__}")
    for k in t:
        if k not in _KEYS:
            raise ctx.error("dynamic", k, f"unknown key {k!r}; allowed keys: {', '.join(_KEYS)}")
    if "times" not in t:
        raise ctx.error("dynamic", next(iter(t), "times"), "a dynamic study needs times = [...] (the sampling times)")
    kw = dict(times=_times(ctx, "times", t["times"]))
    if "candidate_times" in t:
        kw["candidate_times"] = _times(ctx, "candidate_times", t["candidate_times"])
    if "n_times" in t:
        n = t["n_times"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ctx.error("dynamic", "n_times", f"expected an integer >= 1, got {n!r}")
        if n > len(kw.get("candidate_times", kw["times"])):
            raise ctx.error("dynamic", "n_times", f"{n} times asked for but only "
                            f"{len(kw.get('candidate_times', kw['times']))} candidates")
        kw["n_times"] = n
    if "pairs" in t:
        if not isinstance(t["pairs"], bool):
            raise ctx.error("dynamic", "pairs", f"expected true or false, got {t['pairs']!r}")
        kw["pairs"] = t["pairs"]
    exps = t.get("experiments")
    if not isinstance(exps, list) or not exps:
        raise ctx.error("dynamic", "experiments" if "experiments" in t else "times",
                        "a dynamic study needs its experiments: one [[dynamic.experiments]] table each")
    kw["experiments"] = tuple(_experiment(EntryContext(ctx, "dynamic.experiments", k), k, e)
                              for k, e in enumerate(exps))
    return DynamicConfig(**kw)
