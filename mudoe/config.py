"""Study configuration: a TOML file read into dataclasses with defaults.

A study names the model and its variants, where the data come from (CSV files in the
paper's layout or the tidy long layout, or the virtual prototype with a seed) and in
which units, the sensors and their sigma, the unknown parameters with start values and
bounds, the calibration / validation splits, the test level and statistic, and the
optimal-design criterion and constraints.  Every value has a default (``configs/press.toml``
spells them out for the press study); an unknown key is an error naming the key, the file
and the line.  Units are declared once (any unit pint knows, :mod:`mudoe.units`; an unknown unit
is an error naming the key) and converted once, by pint, to the model's units (the press: mm, N).
``[simulate]`` drives ``mudoe simulate`` for an own model.

Indices (series, inputs in splits) are **0-based**, like :mod:`identification.studies.splits`.

Modules
-------
This module reads a file (:func:`load_config`, :func:`parse_config`: one parser per section, then
the checks across sections) and re-exports the names of the modules it is built from:

* :mod:`mudoe.config_sections` -- the section dataclasses and :class:`StudyConfig` (the schema);
* :mod:`mudoe.config_schema` -- how a field declares its key (:func:`setting`, bounds, choices);
* :mod:`mudoe.config_readers` -- the reader and validator of each kind of TOML value;
* :mod:`mudoe.config_errors` -- :class:`ConfigError` and the line lookup of its messages
  (:func:`config_error`);
* :mod:`mudoe.registry` -- the built-in models (variants, scenarios, defaults, virtual prototype),
  each described by its own study module (the press: :mod:`mudoe.press`);
* :mod:`mudoe.checks` -- the cross-key checks (:func:`mudoe.checks.check_config`).

One schema
----------
The section dataclasses *are* the schema: a section's allowed keys are its fields, a
key's default is the field's default, and the field's annotation and metadata say how the
TOML value is checked (:func:`mudoe.config_readers.read_value`).  Keys that drive a library
function are declared with :func:`setting`: their default is the default of the library's settings dataclass, the
settings dataclass validates their values, and the section hands the workflow a settings
object (``cfg.detect.settings()``, ``cfg.validate.settings(...)``).  The keys backed by a
settings field (:func:`settings_keys`):

==============================  ========================================
TOML key                        settings field
==============================  ========================================
[detect] tol                    ``DetectSettings.tol``
[detect] statistic              ``DetectSettings.statistic``
[detect] correction             ``DetectSettings.correction``
[detect] normality              ``DetectSettings.normality``
[detect] normality_correction   ``DetectSettings.normality_correction``
[detect] covariance             ``DetectSettings.covariance``
[validate] n_runs               ``MonteCarloSettings.n_rep``
[validate] seed                 ``MonteCarloSettings.seed``
[validate] scheduler            ``MonteCarloSettings.scheduler``
==============================  ========================================

Their defaults are the settings dataclasses' except where the study has always used its own,
listed in the one table :data:`STUDY_DEFAULTS` ([validate] n_runs = 200, seed = 1).
``n_runs`` keeps its name in the file (documented, and ``mudoe validate --runs`` speaks of
runs); it is mapped to ``n_rep`` in its field declaration only.  The remaining keys (which
sensors, data files, units, variants, the design's criterion and size) are the study's own
and have no settings dataclass: ``[oed]`` holds the arguments of
:func:`oed.design.select_sensors_from_information`, not fields of ``DesignSettings`` /
``BnBSettings`` (the solver's knobs, which the config does not expose).
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import fields
from pathlib import Path

from .checks import check_config
from .config_errors import ConfigContext, ConfigError, EntryContext, config_error
from .config_design import check_design_keys, read_bounds
from .config_prior import check_approximate_range, check_robust_keys, check_robust_prior, read_prior
from .config_readers import (check_keys, one_of, read_str, read_str_list, read_table, read_value, require, tables,
                             unique, validated)
from .config_schema import STUDY_DEFAULTS, setting, settings_keys, settings_values
from .config_sections import (CustomSplitConfig, DataConfig, DetectConfig, DynamicConfig, IdentifyConfig, ModelConfig,
                              OEDConfig, ParameterConfig, QuantifyConfig, RandomSplitConfig, ReportConfig, SensorConfig,
                              SimulateConfig, SplitsConfig, StudyConfig, ValidateConfig)
from .registry import known_scenarios, known_variants, virtual_prototype
from .units import known_units

__all__ = ["ConfigError", "ModelConfig", "DataConfig", "SensorConfig", "ParameterConfig", "CustomSplitConfig",
           "RandomSplitConfig", "SplitsConfig", "SimulateConfig", "DetectConfig", "IdentifyConfig", "OEDConfig",
           "ValidateConfig", "QuantifyConfig", "ReportConfig",
           "DynamicConfig", "StudyConfig", "load_config", "parse_config", "LENGTH_UNITS", "FORCE_UNITS", "MODEL_VARIANTS",
           "DEFAULT_CONFIG", "STUDY_DEFAULTS", "known_variants", "known_scenarios", "setting", "settings_keys",
           "settings_values", "config_error"]

#: examples of declared length units and their factor to the model's mm (any pint length unit is accepted)
LENGTH_UNITS = {"mm": 1.0, "um": 1e-3, "m": 1e3}
#: examples of declared force units and their factor to the model's N (any pint force unit is accepted)
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
#: known models and their variants (the built-in models of :mod:`mudoe.registry`); read through
#: :func:`known_variants`
MODEL_VARIANTS = known_variants()

#: the default study shipped with the repository
DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"

#: examples of the units a config may declare (README "Data formats"; "" = not declared; any unit pint knows)
UNIT_CHOICES = ("",) + known_units()

#: an own model factory, "package.module:function"
_FACTORY = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*")


# ------------------------------------------------------------------ sections
def _parse_model(ctx, t):
    kw = read_table(ctx, "model", ModelConfig, t)
    name = kw.get("name", ModelConfig.name)
    known = known_variants().get(name)
    if known is None and not _FACTORY.fullmatch(name):
        raise ctx.error("model", "name", f"unknown model {name!r}; known models: {', '.join(known_variants())}, "
                        "or your own factory as \"package.module:function\"")
    variants = kw.setdefault("variants", known or ("default",))
    if not variants:
        raise ctx.error("model", "variants", "list at least one variant")
    if known:
        for v in variants:
            one_of(ctx, "model", "variants", v, known, "variant", f"the variants of model {name!r}")
    unique(ctx, "model", "variants", variants, "variant")
    return ModelConfig(**kw)


def _parse_data(ctx, t):
    kw = read_table(ctx, "data", DataConfig, t)
    if kw.get("series") == ():
        raise ctx.error("data", "series", "list at least one series (0-based), or drop the key for all")
    return DataConfig(**kw)


def _parse_sensor(ctx, t):
    check_keys(ctx, "sensors", t, SensorConfig)
    require(ctx, "sensors", t, SensorConfig, "every sensor")
    name = read_str(ctx, "sensors", "name", t["name"])
    kw = {f.name: read_value(ctx, "sensors", f, t[f.name], what=f"sensor {name!r}: {f.name} ")
          for f in fields(SensorConfig) if f.name in t and f.name != "name"}
    if "sigma" in kw and "sigma_man" in kw:
        raise ctx.error("sensors", "sigma_man", f"sensor {name!r}: give sigma or sigma_man, not both")
    return SensorConfig(name, **kw)


def _parse_sensors(ctx, arr):
    out = tuple(_parse_sensor(EntryContext(ctx, "sensors", k), t)
                for k, t in enumerate(tables(ctx, "", "sensors", arr)))
    unique(ctx, "", "sensors", [s.name for s in out], "sensor")
    return out


def _parse_parameter(ctx, t):
    check_keys(ctx, "parameters", t, ParameterConfig)
    require(ctx, "parameters", t, ParameterConfig, "every parameter")
    kw = read_table(ctx, "parameters", ParameterConfig, t)
    p = ParameterConfig(**{k: v if k in ("name", "unit") else float(v) for k, v in kw.items()})
    if not p.lower <= p.start <= p.upper:
        raise ctx.error("parameters", "start", f"parameter {p.name!r}: start {p.start} lies outside "
                        f"[{p.lower}, {p.upper}]")
    return p


def _parse_parameters(ctx, arr):
    out = tuple(_parse_parameter(EntryContext(ctx, "parameters", k), t)
                for k, t in enumerate(tables(ctx, "", "parameters", arr)))
    unique(ctx, "", "parameters", [p.name for p in out], "parameter")
    return out


def _parse_custom_split(ctx, t):
    check_keys(ctx, "splits.custom", t, CustomSplitConfig)
    require(ctx, "splits.custom", t, CustomSplitConfig, "a custom split")
    return CustomSplitConfig(**read_table(ctx, "splits.custom", CustomSplitConfig, t))


def _parse_splits(ctx, t):
    kw = read_table(ctx, "splits", SplitsConfig, t, skip=("random", "custom"))
    for s in kw.get("scenarios", ()):
        one_of(ctx, "splits", "scenarios", s, ("paper",) + tuple(known_scenarios()), "scenario",
               "\"paper\": all four")
    if "random" in t:
        kw["random"] = RandomSplitConfig(**read_table(ctx, "splits.random", RandomSplitConfig, t["random"]))
    if "custom" in t:
        kw["custom"] = tuple(_parse_custom_split(ctx, c) for c in tables(ctx, "splits", "custom", t["custom"]))
    cfg = SplitsConfig(**kw)
    if not cfg.scenarios and not cfg.custom and cfg.random.n == 0 and not cfg.time_windows and not cfg.early_late:
        raise ctx.error("splits", "scenarios", "no split defined: give scenarios, [splits.random] n > 0 or "
                        "[[splits.custom]] (dynamic studies: time_windows or early_late)")
    return cfg


def _parse_detect(ctx, t):
    kw = read_table(ctx, "detect", DetectConfig, t, skip=("sensors",))
    s = t.get("sensors")
    if isinstance(s, str):
        kw["sensors"] = read_str(ctx, "detect", "sensors", s, ("oed", "all"))
    elif s is not None:
        kw["sensors"] = read_str_list(ctx, "detect", "sensors", s)
    return validated(ctx, "detect", DetectConfig(**kw))


def _parse_oed(ctx, t):
    kw = read_table(ctx, "oed", OEDConfig, t, skip=("prior", "bounds"))
    if "prior" in t:
        kw["prior"] = read_prior(ctx, t["prior"])
    if "bounds" in t:
        kw["bounds"] = read_bounds(ctx, t["bounds"])
    o = OEDConfig(**kw)
    check_robust_prior(ctx, o)
    if o.candidates and o.candidates_range:
        raise ctx.error("oed", "candidates_range", "give candidates or candidates_range, not both")
    if o.candidates_range:
        r = o.candidates_range
        if len(r) != 3 or r[2] != int(r[2]) or r[2] < 1 or not r[0] <= r[1]:
            raise ctx.error("oed", "candidates_range", f"expected [start, stop, count] with start <= stop and an "
                            f"integer count >= 1, got {list(r)}")
    if (not o.costs) != (o.budget is None):
        raise ctx.error("oed", "budget" if o.costs else "costs", "give both costs and budget, or neither")
    if o.refine and o.mode != "inputs":
        raise ctx.error("oed", "refine", f"the continuous refinement is for mode = \"inputs\" (mode is {o.mode!r})")
    _check_discrimination_keys(ctx, o)
    return o


def _check_discrimination_keys(ctx, o: OEDConfig) -> None:
    """The keys of ``mode = "discrimination"`` and only there: rival, n_readings (not with n_points /
    n_sensors), discrimination_criterion; no costs, budget or include."""
    if o.mode != "discrimination":
        for key in ("rival", "n_readings"):
            if getattr(o, key):
                raise ctx.error("oed", key, f"only for mode = \"discrimination\" (mode is {o.mode!r})")
        return
    if not o.rival:
        raise ctx.error("oed", "rival", "mode = \"discrimination\" needs rival = the variant to be refuted "
                        "(another [model] variant)")
    if o.n_readings is not None and (o.n_points is not None or o.n_sensors is not None):
        raise ctx.error("oed", "n_readings", "give n_readings (free readings) or n_points / n_sensors, not both")
    for key in ("costs", "include", "max_sensors", "min_sensors"):
        if getattr(o, key):
            raise ctx.error("oed", key, "not used by mode = \"discrimination\" (use n_readings, n_points, "
                            "n_sensors and exclude)")
    if o.planned and o.discrimination_criterion == "divergence":
        raise ctx.error("oed", "discrimination_criterion", "\"divergence\" needs the estimates' covariances, "
                        "which a planned design (no data) has not; use \"T\" or planned = false")


def _check_rival(ctx, cfg) -> None:
    """[oed] rival is a [model] variant other than the assumed-true [oed] variant."""
    o = cfg.oed
    if o.mode != "discrimination":
        return
    one_of(ctx, "oed", "rival", o.rival, cfg.model.variants, "variant", "the [model] variants")
    true = o.variant or cfg.model.variants[-1]
    if o.rival == true:
        raise ctx.error("oed", "rival", f"the rival {o.rival!r} is the variant assumed true ([oed] variant"
                        f"{'' if o.variant else ' defaults to the last [model] variant'}); name another variant")


def _parse_simulate(ctx, t):
    cfg = SimulateConfig(**read_table(ctx, "simulate", SimulateConfig, t))
    ranged = cfg.input_start is not None or cfg.input_stop is not None
    if cfg.inputs and ranged:
        raise ctx.error("simulate", "inputs", "give inputs or input_start/input_stop, not both")
    if ranged and (cfg.input_start is None or cfg.input_stop is None):
        raise ctx.error("simulate", "input_start", "give both input_start and input_stop (and n_inputs)")
    return cfg


def _parse_identify(ctx, t):
    return IdentifyConfig(**read_table(ctx, "identify", IdentifyConfig, t))


def _parse_validate(ctx, t):
    return validated(ctx, "validate", ValidateConfig(**read_table(ctx, "validate", ValidateConfig, t)))


def _parse_quantify(ctx, t):
    return QuantifyConfig(**read_table(ctx, "quantify", QuantifyConfig, t))


def _parse_report(ctx, t):
    return ReportConfig(**read_table(ctx, "report", ReportConfig, t))


_DYNAMIC_KEYS = ("times", "candidate_times", "n_times", "pairs", "experiments")


def _dynamic_times(ctx, key, v) -> tuple:
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


def _dynamic_experiment(ctx, k: int, t) -> dict:
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


def _parse_dynamic(ctx, t) -> DynamicConfig:
    """The ``[dynamic]`` table checked for what needs no model (``ctx``: the config's error context)."""
    if not isinstance(t, dict):
        raise ctx.error("", "dynamic", f"expected a table, got {type(t).__name__}")
    for k in t:
        if k not in _DYNAMIC_KEYS:
            raise ctx.error("dynamic", k, f"unknown key {k!r}; allowed keys: {', '.join(_DYNAMIC_KEYS)}")
    if "times" not in t:
        raise ctx.error("dynamic", next(iter(t), "times"), "a dynamic study needs times = [...] (the sampling times)")
    kw = dict(times=_dynamic_times(ctx, "times", t["times"]))
    if "candidate_times" in t:
        kw["candidate_times"] = _dynamic_times(ctx, "candidate_times", t["candidate_times"])
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
    kw["experiments"] = tuple(_dynamic_experiment(EntryContext(ctx, "dynamic.experiments", k), k, e)
                              for k, e in enumerate(exps))
    return DynamicConfig(**kw)


_SECTIONS = {"model": _parse_model, "data": _parse_data, "sensors": _parse_sensors,
             "parameters": _parse_parameters, "splits": _parse_splits, "detect": _parse_detect,
             "identify": _parse_identify, "simulate": _parse_simulate, "oed": _parse_oed, "validate": _parse_validate,
             "quantify": _parse_quantify, "report": _parse_report,
             "dynamic": _parse_dynamic}


def parse_config(text: str, path: str = "<string>", base_dir: str | Path | None = None) -> StudyConfig:
    """Parse TOML text into a :class:`StudyConfig`.

    Parameters
    ----------
    text : str
        TOML source.
    path : str
        File name used in error messages.
    base_dir : path, optional
        Folder that relative data paths are resolved against (default: the folder of ``path``).

    Raises
    ------
    ConfigError
        Invalid TOML, unknown key (named with file and line), bad value, inconsistent sections.
    """
    ctx = ConfigContext(path, text)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    for k in raw:
        if k not in _SECTIONS:
            raise ctx.error("", k, f"unknown section or key {k!r}; allowed: {', '.join(_SECTIONS)}")
    kw = {name: fn(ctx, raw[name]) for name, fn in _SECTIONS.items() if name in raw}
    if base_dir is None:
        base_dir = Path(path).resolve().parent if path != "<string>" else Path.cwd()
    cfg = StudyConfig(**kw, path=str(path), base_dir=str(base_dir), text=text)
    o = cfg.oed
    check_design_keys(ctx, o, cfg.dynamic is not None, raw.get("oed", {}))
    _check_data(ctx, cfg)
    _check_names(ctx, cfg)
    _check_rival(ctx, cfg)
    check_robust_keys(ctx, o, cfg.dynamic is not None)
    check_approximate_range(ctx, o, cfg.dynamic)
    if o.planned and not (o.candidates or o.candidates_range) and cfg.dynamic is None:   # dynamic: its experiments
        raise ctx.error("oed", "planned", "a planned design needs candidates or candidates_range (the inputs)")
    check_config(cfg, ctx.error)
    return cfg


def _check_data(ctx, cfg: StudyConfig) -> None:
    """The [data] options agree with each other and with [[sensors]]."""
    d = cfg.data
    if d.source == "prototype":
        virtual_prototype().check(d, ctx.error)
    if d.force_correction and d.layout == "tidy" and d.value_column == "value":
        raise ctx.error("data", "force_correction", "the tidy column 'value' is the corrected reading; set "
                        "value_column = \"raw\" to apply the correction yourself")
    names = cfg.sensor_names()
    if names:
        for sname in d.files:
            one_of(ctx, "data.files", sname, sname, names, "sensor", "listed in [[sensors]]")


def _check_names(ctx, cfg: StudyConfig) -> None:
    """Sensors named in [oed] / [detect] are listed in [[sensors]]; variants in [model] variants."""
    names = cfg.sensor_names()
    named = [("oed", k, s) for k in ("include", "exclude") for s in getattr(cfg.oed, k)]
    if isinstance(cfg.detect.sensors, tuple):
        named += [("detect", "sensors", s) for s in cfg.detect.sensors]
    if names:
        for section, key, s in named:
            one_of(ctx, section, key, s, names, "sensor", "listed in [[sensors]]")
    for section, variant in (("oed", cfg.oed.variant), ("validate", cfg.validate.variant),
                             ("simulate", cfg.simulate.variant)):
        if variant:
            one_of(ctx, section, "variant", variant, cfg.model.variants, "variant", "the [model] variants")


def load_config(path: str | Path) -> StudyConfig:
    """Read a study config from a TOML file.

    Raises
    ------
    ConfigError
        Missing or unreadable file, invalid TOML, unknown key (with file and line), bad value.
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: config file not found" + (" (it is a directory)" if p.is_dir() else ""))
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot read the config file ({exc})") from None
    return parse_config(text, str(p), p.resolve().parent)
