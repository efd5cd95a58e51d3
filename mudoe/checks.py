"""Cross-key checks of a study, made before any fit: each error names the file, the line and the key.

Three stages, each as early as what it needs is known:

* :func:`check_config` -- the config alone (called by :func:`mudoe.config.parse_config`): repeated
  [data] series, an empty [detect] sensors list, parameters whose bounds leave nothing to estimate,
  [[splits.custom]] index sets that repeat or overlap, an [oed] design larger than its candidates.
* :func:`check_model` -- the config against the built model (before the data are read): sensor
  names and design sizes of [oed] and [detect] against the model's sensors.
* :func:`check_data` -- the config against the campaign (before any fit): every split fits the
  data (a split index 99 in a campaign of 13 inputs names its ``[[splits.custom]]`` table), every
  sensor has a reading in the study's series (else the data file is named).

Bounds lower == upper are refused, not treated as fixed: a parameter that is not estimated is a
constant of the model (fix it in the factory); keeping it in [[parameters]] would put a zero-width
interval and a singular covariance into every table.
"""
from __future__ import annotations

import numpy as np

from .config_errors import ConfigError, config_error, table_line
from .csv_stream import DataFileError

__all__ = ["check_config", "check_model", "check_data", "table_line", "call_factory", "study_splits"]


_SPLIT_KEYS = ("cal_inputs", "val_inputs", "cal_series", "val_series", "cal_sensors", "val_sensors")


def _custom_error(cfg, k: int, key: str, msg: str):
    """A ConfigError naming the k-th [[splits.custom]] table and ``key``."""
    line = table_line(cfg.text, "splits.custom", k, key) or table_line(cfg.text, "splits.custom", k, "")
    loc = f"{cfg.path}:{line}" if line else cfg.path
    return ConfigError(f"{loc}: [[splits.custom]] {key}: {msg}")


def check_config(cfg, error) -> None:
    """Checks of the config alone; ``error(section, key, msg)`` makes the ConfigError (with the line)."""
    series = cfg.data.series
    if series is not None and len(set(series)) != len(series):
        twice = sorted({i for i in series if series.count(i) > 1})
        raise error("data", "series", f"series {twice} listed twice in {list(series)}; list every series once")
    if isinstance(cfg.detect.sensors, tuple):
        s = cfg.detect.sensors
        if not s:
            raise error("detect", "sensors", "the list is empty: name at least one sensor, or use \"all\" or \"oed\"")
        if len(set(s)) != len(s):
            raise error("detect", "sensors", f"a sensor is listed twice: {list(s)}")
    for p in cfg.parameters:
        if p.lower == p.upper:
            raise error("parameters", "upper", f"parameter {p.name!r}: lower = upper = {p.lower:g} leaves nothing "
                        "to estimate; give lower < upper, or make it a constant of the model (not a [[parameters]] "
                        "entry)")
    o = cfg.oed
    both = sorted(set(o.include) & set(o.exclude))
    if both:
        raise error("oed", "exclude", f"sensor(s) {', '.join(both)} both included and excluded")
    n_cand = int(o.candidates_range[2]) if o.candidates_range else (len(o.candidates) if o.candidates else None)
    if n_cand is not None and o.n_points is not None and o.mode == "inputs" and o.n_points > n_cand:
        raise error("oed", "n_points", f"{o.n_points} input points chosen from {n_cand} candidates; give "
                    f"n_points <= {n_cand} or more candidates")
    from identification.studies.splits import Split, SplitError
    for k, c in enumerate(cfg.splits.custom):
        try:
            Split(c.name, c.cal_inputs, c.val_inputs, c.cal_series, c.val_series, "", c.cal_sensors, c.val_sensors)
        except SplitError as exc:
            key = next((f for f in _SPLIT_KEYS if f in str(exc)), "val_inputs")
            raise _custom_error(cfg, k, key, str(exc)) from None


def check_model(cfg, model) -> None:
    """[oed] and [detect] against the model's sensors (before the data are read)."""
    sensors = tuple(model.sensors)
    o = cfg.oed
    for key in ("include", "exclude"):
        bad = [s for s in getattr(o, key) if s not in sensors]
        if bad:
            raise config_error(cfg, "oed", key, f"unknown sensor(s) {', '.join(bad)}; the model has "
                               f"{', '.join(sensors)}")
    if isinstance(cfg.detect.sensors, tuple):
        bad = [s for s in cfg.detect.sensors if s not in sensors]
        if bad:
            raise config_error(cfg, "detect", "sensors", f"unknown sensor(s) {', '.join(bad)}; the model has "
                               f"{', '.join(sensors)}")
    if o.mode not in ("sensors", "discrimination"):
        return
    n_cand = len(sensors) - len(set(o.exclude))
    for key in ("n_sensors", "min_sensors", "max_sensors"):
        n = getattr(o, key)
        if n is not None and n > n_cand:
            excl = f" ({len(set(o.exclude))} excluded)" if o.exclude else ""
            raise config_error(cfg, "oed", key, f"{key} = {n} but the model has {len(sensors)} sensors{excl}: "
                               f"{', '.join(sensors)}; give at most {n_cand}")
    if o.n_sensors is not None and o.n_sensors < len(set(o.include)):
        raise config_error(cfg, "oed", "n_sensors", f"n_sensors = {o.n_sensors} but include forces "
                           f"{len(set(o.include))} sensors in: {', '.join(o.include)}")


def check_data(cfg, campaign, splits, n_p: int) -> None:
    """The splits and the sensors' readings against the campaign (before any fit).

    Raises
    ------
    ConfigError
        A split does not fit the data (names its key: [[splits.custom]] table, [splits] scenarios,
        [splits.random] n).
    DataFileError
        A sensor has no reading in the study's series (names the data file).
    """
    from identification.studies.splits import SplitError
    series = list(range(campaign.n_M)) if cfg.data.series is None else list(cfg.data.series)
    z = campaign.z[series]
    for k, s in enumerate(campaign.sensors):
        if not np.isfinite(z[:, :, k]).any():
            files = campaign.files
            where = files[k] if len(files) > k and cfg.data.layout == "paper" else (files[0] if files else cfg.path)
            part = "" if cfg.data.series is None else f" of the study's series {series} ([data] series)"
            raise DataFileError(f"{where}: sensor {s!r} has no reading{part}: every cell is empty or NaN; "
                                "give its readings, or use a model without this sensor")
    custom = {c.name: k for k, c in enumerate(cfg.splits.custom)}
    for sp in splits:
        try:
            sp.check(campaign.n_q, len(series), n_p, 1)
            sp.check_sensors(len(campaign.sensors))
        except SplitError as exc:
            msg = f"{exc} (the data: {campaign.n_q} inputs, {len(series)} series)"
            if sp.name in custom:
                key = next((f for f in _SPLIT_KEYS if f in str(exc)), "cal_inputs")
                raise _custom_error(cfg, custom[sp.name], key, msg) from None
            section, key = ("splits.random", "n") if sp.name.startswith("random ") else ("splits", "scenarios")
            raise config_error(cfg, section, key, msg) from None


def call_factory(factory, name: str, variant: str, error):
    """``factory(variant)``; a factory that calls ``sys.exit`` raises ``error(message)`` (a ConfigError naming
    the file and key) instead of ending the process silently, and a model the factory cannot build (a
    :class:`models.contract.ModelError`, e.g. a right-hand side returning the wrong number of derivatives)
    raises ``error`` naming the factory and the variant with the model's message."""
    from models.contract import ModelError
    try:
        return factory(variant)
    except ModelError as exc:
        raise error(f"the model factory {name}({variant!r}) cannot build its model: {exc}") from None
    except SystemExit as exc:
        raise error(f"the model factory {name}({variant!r}) called sys.exit({exc.code!r}) instead of returning a "
                    "models.Model; raise an exception in the factory to report a problem") from None


def study_splits(cfg, campaign, make) -> tuple:
    """``make(cfg, n_q, q_set)``: the study's splits; a split the data cannot hold names the [splits] key."""
    from identification.studies.splits import SplitError
    try:
        return make(cfg, campaign.n_q, campaign.q_set)
    except SplitError as exc:
        section, key = ("splits.random", "n") if cfg.splits.random.n else ("splits", "scenarios")
        raise config_error(cfg, section, key, f"{exc} (the data hold {campaign.n_q} inputs)") from None
