"""Sizes checked before any work: a lower bound of a run's memory and time from the config alone.

Every config key that sets a size (set points, series, splits, replications, candidate inputs,
report resolution) is turned into a *lower bound* of what the run will need before the model is
built or a file is read:

    memory >= sum over the arrays the key makes of (number of elements) x (bytes per element)
    time   >= (number of fits) x FIT_SECONDS

with the bytes per element and :data:`FIT_SECONDS` taken on the small side (the cheapest fit a
batch engine makes on this kind of machine), so a refusal means the run cannot finish, not that
it would be slow.  A key whose bound exceeds the machine's memory (:func:`memory_budget`) or
:data:`TIME_BUDGET` seconds is refused with the file, line and key, the estimate and the largest
value that fits (``mudoe`` exits 2 before any work).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from .config_errors import ConfigError, config_error
from .registry import builtin_model, known_scenarios, virtual_prototype

__all__ = ["SizeEstimate", "estimates", "check_sizes", "memory_budget", "FIT_SECONDS", "TIME_BUDGET",
           "MAX_PAGE_PIXELS"]

#: a lower bound of one fit's CPU time (s): batch-engine fits of small explicit models take 0.1-1 ms
FIT_SECONDS = 1e-4
#: the longest run accepted (s): a lower bound above a week is refused as absurd
TIME_BUDGET = 7 * 24 * 3600.0
#: matplotlib's Agg renderer refuses images of 2^16 pixels or more in either direction
MAX_PAGE_PIXELS = 2 ** 16
#: the report's page size in inches (A4 landscape, reports.builder.PAGE_SIZE)
_PAGE_INCHES = (11.69, 8.27)
#: lower bounds of the bytes per element kept in memory
_BYTES_READING = 8 * 2 + 20     # a simulated reading: h and z as float64, then at least 20 bytes of CSV text
_BYTES_SPLIT = 400              # a random Split with its index lists (measured: 419 bytes with 3 inputs)
_BYTES_REPLICATION = 300        # a Monte Carlo replication's SeedSequence and result row
_BYTES_RGBA = 4                 # one pixel of a rendered report page


@dataclass(frozen=True)
class SizeEstimate:
    """Lower bounds of memory (bytes) and time (s) caused by one config key.

    ``per_unit_bytes`` / ``per_unit_seconds``: the bound per unit of the key's value, used to state
    the largest value that fits.
    """

    section: str
    key: str
    value: float
    what: str
    bytes: float
    seconds: float
    per_unit_bytes: float
    per_unit_seconds: float


def memory_budget() -> float:
    """The memory a run may use (bytes): the machine's physical memory, or the cgroup's limit if lower."""
    try:
        total = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        total = math.inf
    try:
        text = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if text.isdigit():
            total = min(total, float(text))
    except OSError:
        pass
    return total


def _n_sensors(cfg) -> int:
    return max(1, len(cfg.sensors))


def _n_splits(cfg) -> int:
    s = cfg.splits
    n = len(known_scenarios()) if "paper" in s.scenarios else len(s.scenarios)
    return max(1, n + s.random.n + len(s.custom))


def _simulate(cfg) -> list:
    """``mudoe simulate``: the readings of an own model, or the series of a built-in model's virtual prototype."""
    builtin = builtin_model(cfg.model.name)
    if builtin is not None and builtin.prototype is not None:
        per = builtin.prototype.set_points * _n_sensors(cfg) * _BYTES_READING
        return [SizeEstimate("data", "n_series", cfg.data.n_series, "series of the virtual prototype",
                             cfg.data.n_series * per, 0.0, per, 0.0)]
    sc, n_S = cfg.simulate, _n_sensors(cfg)
    n_q = len(sc.inputs) if sc.inputs else sc.n_inputs * (2 if sc.up_and_down else 1)
    total = sc.n_series * n_q * n_S * _BYTES_READING
    # the readings are series x set points x sensors: blame the key furthest above its default
    if sc.inputs or sc.n_series / 4 >= sc.n_inputs / 11:
        return [SizeEstimate("simulate", "n_series", sc.n_series, f"series x {n_q} set points x {n_S} sensors",
                             total, 0.0, total / sc.n_series, 0.0)]
    return [SizeEstimate("simulate", "n_inputs", sc.n_inputs, f"set points x {sc.n_series} series x {n_S} sensors",
                         total, 0.0, total / sc.n_inputs, 0.0)]


def _study(cfg, command: str, runs: int | None) -> list:
    """The commands that read the data and fit: prototype series, random splits, replications, candidates, dpi."""
    out = []
    n_var, n_split = len(cfg.model.variants), _n_splits(cfg)
    if cfg.data.source == "prototype":
        per = virtual_prototype().set_points * _n_sensors(cfg) * _BYTES_READING
        out.append(SizeEstimate("data", "n_series", cfg.data.n_series, "series of the virtual prototype",
                                cfg.data.n_series * per, 0.0, per, 0.0))
    n_rand = cfg.splits.random.n
    if n_rand:
        fits = 3 * n_var if command in ("detect", "report") else 0
        per = _BYTES_SPLIT
        out.append(SizeEstimate("splits.random", "n", n_rand, f"random splits ({fits} fits each)" if fits
                                else "random splits", n_rand * per, n_rand * fits * FIT_SECONDS, per,
                                fits * FIT_SECONDS))
    if command == "validate":
        n = cfg.validate.n_runs if runs is None else runs
        key = "n_runs" if runs is None else "--runs"
        per_s = 3 * n_split * FIT_SECONDS
        out.append(SizeEstimate("validate", key, n, f"replications x {n_split} splits x 3 fits",
                                n * _BYTES_REPLICATION, n * per_s, _BYTES_REPLICATION, per_s))
    if command in ("oed", "report") and cfg.oed.candidates_range:
        count = cfg.oed.candidates_range[2]
        n_p = max(1, len(cfg.parameters))
        per = 8 * (1 + 2 * _n_sensors(cfg) * n_p * n_p)
        out.append(SizeEstimate("oed", "candidates_range", count, "candidate set points (information matrices "
                                "of every sensor)", count * per, 0.0, per, 0.0))
    if command == "report":
        dpi = cfg.report.dpi
        w, h = (dpi * x for x in _PAGE_INCHES)
        out.append(SizeEstimate("report", "dpi", dpi, f"dots per inch: a page of {w:.0f} x {h:.0f} pixels",
                                w * h * _BYTES_RGBA, 0.0, _PAGE_INCHES[0] * _PAGE_INCHES[1] * _BYTES_RGBA * dpi, 0.0))
    return out


def estimates(cfg, command: str, runs: int | None = None) -> list:
    """The :class:`SizeEstimate` of every size key the ``mudoe`` ``command`` uses (``runs``: ``--runs``)."""
    if command == "simulate":
        return _simulate(cfg)
    if command == "oed" and cfg.oed.planned:
        return [e for e in _study(cfg, "oed", None) if e.section == "oed"]
    return _study(cfg, command, runs)


def _count(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


def _gb(b: float) -> str:
    return f"{b / 1e9:.3g} GB"


def _duration(s: float) -> str:
    return f"{s / 86400:.3g} days" if s >= 86400 else f"{s / 3600:.3g} h"


def _largest(e: SizeEstimate, budget: float, seconds: float) -> float:
    """The largest value of the key within both budgets (memory is linear in the value, pixels quadratic)."""
    if e.key == "dpi":
        return math.floor(min(math.sqrt(budget / (_PAGE_INCHES[0] * _PAGE_INCHES[1] * _BYTES_RGBA)),
                              (MAX_PAGE_PIXELS - 1) / _PAGE_INCHES[0]))
    caps = [budget / e.per_unit_bytes if e.per_unit_bytes else math.inf,
            seconds / e.per_unit_seconds if e.per_unit_seconds else math.inf]
    return math.floor(min(caps))


def check_sizes(cfg, command: str, runs: int | None = None, budget: float | None = None,
                seconds: float = TIME_BUDGET) -> None:
    """Refuse a config whose sizes cannot fit the machine, before any work.

    Parameters
    ----------
    cfg : mudoe.config.StudyConfig
    command : str
        The ``mudoe`` command (which keys it uses).
    runs : int, optional
        ``mudoe validate --runs`` (replaces ``[validate] n_runs``).
    budget : float, optional
        Memory available (bytes); default :func:`memory_budget`.
    seconds : float
        Longest run accepted (s).

    Raises
    ------
    ConfigError
        Naming the file, line and key, the lower bounds of memory and time and the largest value
        that fits.
    """
    budget = memory_budget() if budget is None else budget
    for e in estimates(cfg, command, runs):
        too_wide = e.key == "dpi" and e.value * _PAGE_INCHES[0] >= MAX_PAGE_PIXELS
        if e.bytes <= budget and e.seconds <= seconds and not too_wide:
            continue
        need = [f"at least {_gb(e.bytes)} of memory (this machine has {_gb(budget)})" if e.bytes > budget else "",
                f"at least {_duration(e.seconds)} at {FIT_SECONDS * 1e3:g} ms per fit" if e.seconds > seconds else "",
                f"an image wider than matplotlib's {MAX_PAGE_PIXELS} pixels" if too_wide else ""]
        msg = (f"{_count(e.value)} {e.what} would need {' and '.join(n for n in need if n)}; "
               f"use fewer (this lower bound alone allows at most {_count(_largest(e, budget, seconds))})")
        if e.key == "--runs":
            raise ConfigError(f"--runs: {msg}")
        raise config_error(cfg, e.section, e.key, msg)
