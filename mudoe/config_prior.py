"""The robust-design keys of ``[oed]`` (issue 31): ``prior``, ``robust`` and ``approximate``.

With ``mode = "sensors"`` (and ``approximate = false``) a prior gives the exact robust n-run design: a static
study's sensors (planned before data, or at the estimate with data) or a dynamic study's sampling times
(:mod:`mudoe.robust_plans`); with ``mode = "inputs"`` and ``n_points`` the exact robust choice of ``n_points``
candidate input rows (a dynamic study: experiments; a static study without ``n_points``, or with ``approximate =
true``: the robust approximate design); with ``mode = "both"`` and ``n_points`` the exact robust choice of
(set point, sensor) pairs.  ``approximate = true`` on a dynamic study (mode "sensors") gives the approximate
sampling times, robust with a prior (:func:`check_robust_keys`).

``prior`` is a table, one key per uncertain parameter, its value ``[distribution, arguments...]``::

    [oed]
    mode = "inputs"
    prior = { k5 = ["uniform", 400.0, 700.0], k7 = ["lognormal", 470.0, 0.2] }
    robust = "bayes"               # or "maximin"

(the sub-table ``[oed.prior]`` with one line per parameter reads the same).  The distributions and
their arguments are :func:`oed.prior.make_prior`'s: ``uniform`` lower, upper; ``normal`` mean, sd;
``lognormal`` median, log-sd; ``truncnormal`` mean, sd, lower, upper.  What needs the model (the
parameter exists, bounds contain its start value) is checked when the design is planned
(:func:`mudoe.robust_plans.config_prior`); here only the form.
"""
from __future__ import annotations

import math

from .config_errors import ConfigContext, ConfigError

__all__ = ["DISTRIBUTION_ARGS", "prior_error", "read_prior", "check_robust_prior", "check_robust_keys",
           "check_exact_robust_keys", "check_approximate_range"]

#: number of arguments of each distribution (the same as :data:`oed.prior.DISTRIBUTIONS`; a test checks it)
DISTRIBUTION_ARGS = {"uniform": 2, "normal": 2, "lognormal": 2, "truncnormal": 4}


def prior_error(ctx: ConfigContext, name: str, msg: str) -> ConfigError:
    """A :class:`ConfigError` naming ``[oed] prior.<name>`` and its line in the file."""
    line = ctx.line_of("oed", name) or ctx.line_of("oed.prior", name) or ctx.line_of("oed", "prior")
    loc = f"{ctx.path}:{line}" if line else str(ctx.path)
    return ConfigError(f"{loc}: [oed] prior.{name}: {msg}")


def read_prior(ctx: ConfigContext, v) -> dict:
    """``{parameter: (distribution, *float args)}`` of the TOML value of ``[oed] prior`` (form checked)."""
    if not isinstance(v, dict) or not v:
        raise ctx.error("oed", "prior", "expected a table {parameter = [\"distribution\", arguments...]}, "
                        f"e.g. prior = {{ k5 = [\"uniform\", 400.0, 700.0] }}, got {v!r}")
    out = {}
    for name, spec in v.items():
        if not isinstance(spec, list) or not spec or not isinstance(spec[0], str):
            raise prior_error(ctx, name, f"expected [\"distribution\", arguments...], got {spec!r}")
        dist, args = spec[0].strip().lower(), spec[1:]
        if dist not in DISTRIBUTION_ARGS:
            raise prior_error(ctx, name, f"unknown distribution {spec[0]!r}; use one of: "
                              f"{', '.join(DISTRIBUTION_ARGS)}")
        if len(args) != DISTRIBUTION_ARGS[dist]:
            raise prior_error(ctx, name, f"{dist} takes {DISTRIBUTION_ARGS[dist]} numbers, got {len(args)}")
        for a in args:
            if isinstance(a, bool) or not isinstance(a, (int, float)) or not math.isfinite(a):
                raise prior_error(ctx, name, f"the arguments of {dist} must be finite numbers, got {a!r}")
        out[name] = (dist,) + tuple(float(a) for a in args)
    return out


def check_robust_prior(ctx: ConfigContext, o) -> None:
    """``robust`` needs a prior."""
    if o.robust and not o.prior:
        raise ctx.error("oed", "robust", f"robust = {o.robust!r} needs a prior (e.g. prior = {{ k5 = "
                        "[\"uniform\", 400.0, 700.0] }): the parameter vectors to be robust over")


def check_robust_keys(ctx: ConfigContext, o, dynamic: bool) -> None:
    """prior / approximate against ``mode`` and the kind of study:

    * mode "sensors", a prior, approximate = false: the exact robust n-run design of a static study's sensors
      (planned, or at the estimate with data) or of a dynamic study's sampling times
      (:func:`check_exact_robust_keys`);
    * a dynamic study's mode "sensors" with approximate = true: the approximate sampling times (with a prior:
      robust);
    * mode "inputs": a static study's approximate design (without refine, include, exclude, costs), or with a prior
      and n_points its exact robust choice of n_points set points; a dynamic study's exact robust choice of
      n_points experiments (approximate designs of control profiles and the refinement under a prior are refused);
    * mode "both" with a prior and n_points: the exact robust choice of (set point, sensor) pairs; an approximate
      joint design is refused with what to use instead.
    """
    if not (o.prior or o.approximate):
        return
    key = "prior" if o.prior else "approximate"
    if o.mode == "both" and not dynamic:
        if o.approximate:
            raise ctx.error("oed", "approximate", "an approximate joint design of set points and sensors is not "
                            "available: use mode = \"inputs\" with approximate = true (every sensor read at each "
                            "support point), or approximate = false with a prior and n_points (the exact robust "
                            "choice of (set point, sensor) pairs)")
        if o.n_points is None:
            raise ctx.error("oed", "prior", "with mode = \"both\" a prior gives the exact robust choice of n_points "
                            "(set point, sensor) pairs: give n_points")
        check_exact_robust_keys(ctx, o, dynamic)
        return
    if o.mode == "sensors" and dynamic and o.approximate:
        return                              # the approximate sampling times (robust with a prior)
    if o.prior and not o.approximate and o.mode == "sensors":
        check_exact_robust_keys(ctx, o, dynamic)
        return
    if o.mode != "inputs":
        extra = (" (a prior with mode = \"sensors\" and approximate = false gives the exact robust design)"
                 if o.mode == "sensors" else "")
        raise ctx.error("oed", key, f"robust and approximate designs are for mode = \"inputs\" (mode is {o.mode!r})"
                        + extra)
    if dynamic:
        if o.approximate:
            raise ctx.error("oed", "approximate", "approximate designs of a dynamic study's experiments (control "
                            "profiles and constants) are not available (oed.select_inputs refuses them): approximate "
                            "= true with mode = \"sensors\" gives the approximate sampling times; a prior with "
                            "approximate = false the exact robust choice of n_points experiments")
        if o.refine:
            raise ctx.error("oed", "refine", "the continuous refinement under a prior is not implemented "
                            "(oed.select_inputs); leave refine out, or drop the prior to refine the local design")
        return
    if o.refine:
        raise ctx.error("oed", "refine", "an approximate design already places its points on the continuous range; "
                        "leave refine out")
    for k in ("include", "exclude", "costs"):
        if getattr(o, k):
            raise ctx.error("oed", k, f"not used by an approximate design ({key} is given; every sensor is read at "
                            "each support point); leave it out")


def check_exact_robust_keys(ctx: ConfigContext, o, dynamic: bool) -> None:
    """The exact robust design (a prior, approximate = false) chooses exactly ``n`` candidates: no include,
    exclude, costs, budget or max_sensors."""
    for k in ("include", "exclude", "costs", "budget", "max_sensors"):
        if getattr(o, k) not in ((), None):
            raise ctx.error("oed", k, "not used by the exact robust design (prior is given: it chooses exactly "
                            "n_sensors candidates, n_points (set point, sensor) pairs, or [dynamic] n_times "
                            "sampling times); leave it out")


def check_approximate_range(ctx: ConfigContext, o, dyn) -> None:
    """An approximate design places its support points on the range [min, max] of the candidates: they must span
    one (at least two distinct values).  The approximate route is a static study's ``mode = "inputs"`` with
    ``approximate = true`` or a prior without ``n_points`` (the candidate set points, ``[oed] candidates`` or
    ``candidates_range``), and a dynamic study's ``mode = "sensors"`` with ``approximate = true`` (the candidate
    sampling times, ``[dynamic] candidate_times`` or ``times``); ``dyn`` is the ``[dynamic]`` section or None."""
    if dyn is not None:
        if not (o.approximate and o.mode == "sensors"):
            return
        section, key = "dynamic", "candidate_times" if dyn.candidate_times else "times"
        values, what = [float(t) for t in dyn.candidates()], "candidate sampling times"
    else:
        if o.mode != "inputs" or not (o.approximate or (o.prior and o.n_points is None)):
            return
        section, key = "oed", "candidates_range" if o.candidates_range else "candidates"
        values, what = [float(q) for q in o.candidate_points()], "candidate set points"
    if not values or max(values) > min(values):
        return                              # no candidates at all: the design keys' own checks say so
    route = "approximate = true" if o.approximate else "a prior without n_points"
    raise ctx.error(section, key, f"the approximate design ({route}) places its support points on the range "
                    f"[min, max] of the {what}, but they span no range (every one is {values[0]:g}); give at least "
                    "two distinct values" + ("" if dyn is not None or o.approximate else
                                             ", or n_points for the exact robust choice of n_points set points"))
