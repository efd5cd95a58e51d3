"""Study configuration: a TOML file read into dataclasses with defaults.

A study names the model and its variants, where the data come from (CSV files in the
paper's layout or the tidy long layout, or the virtual prototype with a seed) and in
which units, the sensors and their sigma, the unknown parameters with start values and
bounds, the calibration / validation splits, the test level and statistic, and the
optimal-design criterion and constraints.  Every value has a default (``configs/press.toml``
spells them out for the press study); an unknown key is an error naming the key, the file
and the line.  Units are declared once and converted once, to the model's units (mm, N).

Indices (series, inputs in splits) are **0-based**, like :mod:`identification.splits`.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

__all__ = ["ConfigError", "ModelConfig", "DataConfig", "SensorConfig", "ParameterConfig", "CustomSplitConfig",
           "RandomSplitConfig", "SplitsConfig", "DetectConfig", "OEDConfig", "ValidateConfig", "ReportConfig",
           "StudyConfig", "load_config", "parse_config", "LENGTH_UNITS", "FORCE_UNITS", "MODEL_VARIANTS",
           "DEFAULT_CONFIG"]

#: factor converting a declared length unit to the model's mm
LENGTH_UNITS = {"mm": 1.0, "um": 1e-3, "m": 1e3}
#: factor converting a declared force unit to the model's N
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
#: known models and their variants (friction models of the paper)
MODEL_VARIANTS = {"press": ("M1", "M2", "M3")}

#: the default study shipped with the repository
DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"


class ConfigError(ValueError):
    """The study configuration is invalid; the message names the file, the key and (if known) the line."""


# ---------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class ModelConfig:
    """Which model and which of its variants to study.

    Attributes
    ----------
    name : str
        Model family: ``"press"`` (the press linkage of :mod:`models.press`), or your own
        factory ``"package.module:function"`` with ``function(variant) -> models.Model``
        (README "Add your own model").
    variants : tuple of str
        Press: friction variants ``"M1"`` (none), ``"M2"`` (Coulomb), ``"M3"`` (hysteresis
        network).  Own factory: any names, passed to the factory (default ``("default",)``).
    extra_sensors : bool
        Expose every joint displacement as a candidate sensor (not only D_y, F_x, B0_y).
    friction_file : str
        Trained constants of M2 / M3 (relative to the config file); "" = the shipped
        ``data/press_friction.json``.
    """

    name: str = "press"
    variants: tuple = ("M1", "M2", "M3")
    extra_sensors: bool = False
    friction_file: str = ""


@dataclass(frozen=True)
class DataConfig:
    """Where the measurements come from and in which units.

    Attributes
    ----------
    source : {"csv", "prototype"}
        Read CSV files, or simulate a campaign on the virtual prototype (:mod:`models.prototype`).
    layout : {"paper", "tidy"}
        ``paper``: one file per sensor, first column the set force, then one column per series.
        ``tidy``: one long file with columns series, set force, actual force, sensor, value.
    directory : str
        Folder of the files (relative to the config file).
    files : dict {sensor: file}
        Paper layout: the file of each sensor (default ``measurements_<sensor>.csv``).
    file : str
        Tidy layout: the long table.
    actual_forces_file : str
        Paper layout, optional: actual forces in the same layout (set force, one column per series).
    value_column : {"value", "raw"}
        Tidy layout: which reading column to use (``raw`` = before any force correction).
    displacement_unit : {"mm", "um", "m"}
    force_unit : {"N", "kN"}
    force_correction : bool
        Apply the paper's correction z * q_set / q_actual (needs actual forces; readings at
        q_set = 0 are left unchanged).
    series : tuple of int or None
        0-based series used by the study (e.g. the paper's two held-out series); None = all.
        The repeatability sigma and the normality table always use every series.
    seed, n_series : int
        Prototype source: random seed and number of series.
    """

    source: str = "csv"
    layout: str = "paper"
    directory: str = "../data/press_campaign"
    files: dict = field(default_factory=dict)
    file: str = "campaign_long.csv"
    actual_forces_file: str = ""
    value_column: str = "value"
    displacement_unit: str = "um"
    force_unit: str = "N"
    force_correction: bool = False
    series: tuple | None = None
    seed: int = 20190731
    n_series: int = 6


@dataclass(frozen=True)
class SensorConfig:
    """One sensor and its standard deviation (in the data's displacement unit).

    Give ``sigma`` directly, or ``sigma_man`` (the manufacturer's error): then sigma is
    composed as in the paper, sqrt(sigma_rep^2 + sigma_man^2), with sigma_rep the
    repeatability seen in the data (differences of consecutive series / sqrt 2).
    """

    name: str
    sigma: float | None = None
    sigma_man: float | None = None


@dataclass(frozen=True)
class ParameterConfig:
    """An unknown parameter: start value and bounds (the model's unit, N/mm for the press)."""

    name: str
    start: float
    lower: float = -math.inf
    upper: float = math.inf


@dataclass(frozen=True)
class CustomSplitConfig:
    """A user split: 0-based input (and optionally series) indices of both sets."""

    name: str
    cal_inputs: tuple
    val_inputs: tuple
    cal_series: tuple | None = None
    val_series: tuple | None = None


@dataclass(frozen=True)
class RandomSplitConfig:
    """Monte Carlo cross-validation splits (``n = 0``: none)."""

    n: int = 0
    cal_fraction: float = 0.5
    seed: int = 1
    exclude_zero_force: bool = True


@dataclass(frozen=True)
class SplitsConfig:
    """Calibration / validation splits (Algorithm 1, line 06).

    ``scenarios``: names of the paper's scenarios (:data:`identification.splits.PRESS_SCENARIO_NAMES`),
    or ``["paper"]`` for all four.
    """

    scenarios: tuple = ("paper",)
    random: RandomSplitConfig = field(default_factory=RandomSplitConfig)
    custom: tuple = ()


@dataclass(frozen=True)
class DetectConfig:
    """Algorithm 1: test level, statistic, correction, normality gate, sensors used.

    ``sensors``: ``"oed"`` (the design chosen by the [oed] section), ``"all"``, or a list of names.
    """

    tol: float = 0.05
    statistic: str = "likelihood_ratio"
    correction: str = "bonferroni"
    normality: str = "check"
    covariance: str = "second_order"
    sensors: Any = "oed"


@dataclass(frozen=True)
class OEDConfig:
    """Sensor selection (paper section 4).

    Attributes
    ----------
    criterion : {"A", "D", "E"}
    kind : {"second_order", "gauss_newton"}
    n_sensors : int or None        exact number of sensors (None: n_p)
    min_sensors : int or None      smallest design listed in the table (None: n_p)
    include, exclude : tuple of str  sensors forced in / out
    variant : str                  the model variant whose information is used ("" = the last listed)
    """

    criterion: str = "E"
    kind: str = "second_order"
    n_sensors: int | None = None
    min_sensors: int | None = None
    include: tuple = ()
    exclude: tuple = ()
    variant: str = ""


@dataclass(frozen=True)
class ValidateConfig:
    """Monte Carlo check of covariance and test size (:mod:`identification.montecarlo`).

    ``variant``: the model variant simulated and tested ("" = the first listed).
    """

    n_runs: int = 200
    seed: int = 1
    variant: str = ""


@dataclass(frozen=True)
class ReportConfig:
    """Report options."""

    title: str = "Model uncertainty study"
    dpi: int = 150


@dataclass(frozen=True)
class StudyConfig:
    """A whole study (see the module docstring and README "Config reference")."""

    model: ModelConfig = field(default_factory=ModelConfig)
    data: DataConfig = field(default_factory=DataConfig)
    sensors: tuple = ()
    parameters: tuple = ()
    splits: SplitsConfig = field(default_factory=SplitsConfig)
    detect: DetectConfig = field(default_factory=DetectConfig)
    oed: OEDConfig = field(default_factory=OEDConfig)
    validate: ValidateConfig = field(default_factory=ValidateConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    path: str = "<string>"
    base_dir: str = "."
    text: str = ""

    # ------------------------------------------------------------------ helpers
    @property
    def length_factor(self) -> float:
        """Factor from the declared displacement unit to mm."""
        return LENGTH_UNITS[self.data.displacement_unit]

    @property
    def force_factor(self) -> float:
        """Factor from the declared force unit to N."""
        return FORCE_UNITS[self.data.force_unit]

    def resolve(self, rel: str) -> Path:
        """A path from the config, relative to the config file's folder."""
        p = Path(rel)
        return p if p.is_absolute() else Path(self.base_dir) / p

    def sensor_names(self) -> tuple:
        return tuple(s.name for s in self.sensors)

    def as_dict(self) -> dict:
        """A plain-dict view (for results.json)."""
        def conv(v):
            if hasattr(v, "__dataclass_fields__"):
                return {f.name: conv(getattr(v, f.name)) for f in fields(v) if f.name != "text"}
            if isinstance(v, (list, tuple)):
                return [conv(x) for x in v]
            if isinstance(v, dict):
                return {k: conv(x) for k, x in v.items()}
            if isinstance(v, float) and not math.isfinite(v):
                return str(v)
            return v
        return conv(self)


# ---------------------------------------------------------------------------- parsing
class _Ctx:
    """Where we are: file name and text (for line numbers)."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = text.splitlines()

    def line_of(self, section: str, key: str) -> int | None:
        """Best-effort 1-based line of ``key`` inside ``[section]`` (None if not found)."""
        start = 0
        if section:
            last = section.split(".")[-1].split("[")[0]
            hdr = re.compile(r"^\s*\[\[?\s*" + re.escape(section.split("[")[0]) + r"\s*\]\]?\s*(#.*)?$")
            for i, ln in enumerate(self.lines):
                if hdr.match(ln):
                    start = i
                    break
            else:
                hdr2 = re.compile(r"^\s*\[\[?.*\b" + re.escape(last) + r"\s*\]\]?")
                for i, ln in enumerate(self.lines):
                    if hdr2.match(ln):
                        start = i
                        break
        pat = re.compile(r'^\s*["\']?' + re.escape(key) + r'["\']?\s*=|^\s*\[\[?[^\]]*\b' + re.escape(key)
                         + r'\s*\]\]?|[{,]\s*["\']?' + re.escape(key) + r'["\']?\s*=')
        for i in range(start, len(self.lines)):
            if pat.search(self.lines[i]):
                return i + 1
        return None

    def error(self, section: str, key: str, msg: str) -> ConfigError:
        where = f"[{section}] " if section else ""
        line = self.line_of(section, key) if key else None
        loc = f"{self.path}:{line}" if line else self.path
        return ConfigError(f"{loc}: {where}{key + ': ' if key else ''}{msg}")


def _check_keys(ctx: _Ctx, section: str, table: dict, allowed) -> None:
    if not isinstance(table, dict):
        raise ctx.error("", section, f"expected a table, got {type(table).__name__}")
    for k in table:
        if k not in allowed:
            raise ctx.error(section, k, f"unknown key {k!r}; allowed keys: {', '.join(sorted(allowed))}")


def _num(ctx, section, key, v, positive=False, allow_inf=False, integer=False, nonneg=False):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ctx.error(section, key, f"expected a number, got {v!r}")
    if integer and not isinstance(v, int):
        raise ctx.error(section, key, f"expected an integer, got {v!r}")
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ctx.error(section, key, f"expected a finite number, got {v!r}")
    if positive and not v > 0:
        raise ctx.error(section, key, f"must be positive, got {v!r}")
    if nonneg and v < 0:
        raise ctx.error(section, key, f"must be non-negative, got {v!r}")
    return v


def _str(ctx, section, key, v, choices=None):
    if not isinstance(v, str):
        raise ctx.error(section, key, f"expected a string, got {v!r}")
    if choices is not None and v not in choices:
        raise ctx.error(section, key, f"{v!r} is not one of {', '.join(map(str, choices))}")
    return v


def _bool(ctx, section, key, v):
    if not isinstance(v, bool):
        raise ctx.error(section, key, f"expected true or false, got {v!r}")
    return v


def _int_list(ctx, section, key, v, allow_none=False):
    if v is None and allow_none:
        return None
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise ctx.error(section, key, f"expected a list of integer indices (0-based), got {v!r}")
    if any(x < 0 for x in v):
        raise ctx.error(section, key, f"indices are 0-based and non-negative, got {v!r}")
    return tuple(v)


def _str_list(ctx, section, key, v):
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ctx.error(section, key, f"expected a list of strings, got {v!r}")
    return tuple(v)


def _parse_model(ctx, t):
    _check_keys(ctx, "model", t, {"name", "variants", "extra_sensors", "friction_file"})
    kw = {}
    if "name" in t:
        kw["name"] = _str(ctx, "model", "name", t["name"])
        if kw["name"] not in MODEL_VARIANTS and not re.fullmatch(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*", kw["name"]):
            raise ctx.error("model", "name", f"unknown model {kw['name']!r}; known models: "
                            f"{', '.join(MODEL_VARIANTS)}, or your own factory as \"package.module:function\"")
    name = kw.get("name", ModelConfig.name)
    custom = name not in MODEL_VARIANTS
    if custom and "variants" not in t:
        kw["variants"] = ("default",)
    if "variants" in t:
        v = _str_list(ctx, "model", "variants", t["variants"])
        if not v:
            raise ctx.error("model", "variants", "list at least one variant")
        for x in v:
            if not custom and x not in MODEL_VARIANTS[name]:
                raise ctx.error("model", "variants", f"unknown variant {x!r} of model {name!r}; known: "
                                f"{', '.join(MODEL_VARIANTS[name])}")
        if len(set(v)) != len(v):
            raise ctx.error("model", "variants", f"a variant is listed twice: {list(v)}")
        kw["variants"] = v
    if "extra_sensors" in t:
        kw["extra_sensors"] = _bool(ctx, "model", "extra_sensors", t["extra_sensors"])
    if "friction_file" in t:
        kw["friction_file"] = _str(ctx, "model", "friction_file", t["friction_file"])
    return ModelConfig(**kw)


def _parse_data(ctx, t):
    allowed = {"source", "layout", "directory", "files", "file", "actual_forces_file", "value_column",
               "displacement_unit", "force_unit", "force_correction", "series", "seed", "n_series"}
    _check_keys(ctx, "data", t, allowed)
    kw = {}
    choices = {"source": ("csv", "prototype"), "layout": ("paper", "tidy"), "value_column": ("value", "raw"),
               "displacement_unit": tuple(LENGTH_UNITS), "force_unit": tuple(FORCE_UNITS)}
    for k, ch in choices.items():
        if k in t:
            kw[k] = _str(ctx, "data", k, t[k], ch)
    for k in ("directory", "file", "actual_forces_file"):
        if k in t:
            kw[k] = _str(ctx, "data", k, t[k])
    if "files" in t:
        f = t["files"]
        if not isinstance(f, dict) or not all(isinstance(v, str) for v in f.values()):
            raise ctx.error("data", "files", f"expected a table {{sensor = \"file.csv\"}}, got {f!r}")
        kw["files"] = dict(f)
    if "force_correction" in t:
        kw["force_correction"] = _bool(ctx, "data", "force_correction", t["force_correction"])
    if "series" in t:
        s = _int_list(ctx, "data", "series", t["series"])
        if not s:
            raise ctx.error("data", "series", "list at least one series (0-based), or drop the key for all")
        kw["series"] = s
    if "seed" in t:
        kw["seed"] = _num(ctx, "data", "seed", t["seed"], integer=True, nonneg=True)
    if "n_series" in t:
        kw["n_series"] = _num(ctx, "data", "n_series", t["n_series"], integer=True)
        if kw["n_series"] < 2:
            raise ctx.error("data", "n_series", f"the prototype needs at least 2 series, got {kw['n_series']}")
    return DataConfig(**kw)


def _parse_sensors(ctx, arr):
    if not isinstance(arr, list) or not all(isinstance(x, dict) for x in arr):
        raise ctx.error("", "sensors", "expected [[sensors]] tables")
    out = []
    for i, t in enumerate(arr):
        sec = f"sensors[{i}]"
        _check_keys(ctx, "sensors", t, {"name", "sigma", "sigma_man"})
        if "name" not in t:
            raise ctx.error("sensors", "sigma" if "sigma" in t else "", f"{sec}: every sensor needs a name")
        name = _str(ctx, "sensors", "name", t["name"])
        sig = t.get("sigma")
        man = t.get("sigma_man")
        if sig is not None:
            sig = _num(ctx, "sensors", "sigma", sig)
            if sig <= 0:
                raise ctx.error("sensors", "sigma", f"sensor {name!r}: sigma must be positive, got {sig!r}")
        if man is not None:
            man = _num(ctx, "sensors", "sigma_man", man)
            if man < 0:
                raise ctx.error("sensors", "sigma_man", f"sensor {name!r}: sigma_man must be non-negative, "
                                f"got {man!r}")
        if sig is not None and man is not None:
            raise ctx.error("sensors", "sigma_man", f"sensor {name!r}: give sigma or sigma_man, not both")
        out.append(SensorConfig(name, sig, man))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise ctx.error("", "sensors", f"a sensor is listed twice: {names}")
    return tuple(out)


def _parse_parameters(ctx, arr):
    if not isinstance(arr, list) or not all(isinstance(x, dict) for x in arr):
        raise ctx.error("", "parameters", "expected [[parameters]] tables")
    out = []
    for t in arr:
        _check_keys(ctx, "parameters", t, {"name", "start", "lower", "upper"})
        if "name" not in t or "start" not in t:
            raise ctx.error("parameters", "start" if "name" in t else "name",
                            "every parameter needs a name and a start value")
        name = _str(ctx, "parameters", "name", t["name"])
        start = _num(ctx, "parameters", "start", t["start"])
        lo = _num(ctx, "parameters", "lower", t.get("lower", -math.inf), allow_inf=True)
        up = _num(ctx, "parameters", "upper", t.get("upper", math.inf), allow_inf=True)
        if not lo <= start <= up:
            raise ctx.error("parameters", "start", f"parameter {name!r}: start {start} lies outside "
                            f"[{lo}, {up}]")
        out.append(ParameterConfig(name, float(start), float(lo), float(up)))
    names = [p.name for p in out]
    if len(set(names)) != len(names):
        raise ctx.error("", "parameters", f"a parameter is listed twice: {names}")
    return tuple(out)


def _parse_splits(ctx, t):
    _check_keys(ctx, "splits", t, {"scenarios", "random", "custom"})
    kw = {}
    if "scenarios" in t:
        from identification.splits import PRESS_SCENARIO_NAMES
        sc = _str_list(ctx, "splits", "scenarios", t["scenarios"])
        for s in sc:
            if s != "paper" and s not in PRESS_SCENARIO_NAMES:
                raise ctx.error("splits", "scenarios", f"unknown scenario {s!r}; use \"paper\" (all four) or "
                                f"one of: {', '.join(repr(n) for n in PRESS_SCENARIO_NAMES)}")
        kw["scenarios"] = sc
    if "random" in t:
        r = t["random"]
        _check_keys(ctx, "splits.random", r, {"n", "cal_fraction", "seed", "exclude_zero_force"})
        rk = {}
        if "n" in r:
            rk["n"] = _num(ctx, "splits.random", "n", r["n"], integer=True, nonneg=True)
        if "cal_fraction" in r:
            rk["cal_fraction"] = _num(ctx, "splits.random", "cal_fraction", r["cal_fraction"])
            if not 0 < rk["cal_fraction"] < 1:
                raise ctx.error("splits.random", "cal_fraction", f"must lie in (0, 1), got {rk['cal_fraction']}")
        if "seed" in r:
            rk["seed"] = _num(ctx, "splits.random", "seed", r["seed"], integer=True, nonneg=True)
        if "exclude_zero_force" in r:
            rk["exclude_zero_force"] = _bool(ctx, "splits.random", "exclude_zero_force", r["exclude_zero_force"])
        kw["random"] = RandomSplitConfig(**rk)
    if "custom" in t:
        arr = t["custom"]
        if not isinstance(arr, list) or not all(isinstance(x, dict) for x in arr):
            raise ctx.error("splits", "custom", "expected [[splits.custom]] tables")
        out = []
        for c in arr:
            _check_keys(ctx, "splits.custom", c, {"name", "cal_inputs", "val_inputs", "cal_series", "val_series"})
            for k in ("name", "cal_inputs", "val_inputs"):
                if k not in c:
                    raise ctx.error("splits.custom", "name" if "name" in c else "",
                                    f"a custom split needs name, cal_inputs and val_inputs (missing {k})")
            out.append(CustomSplitConfig(
                _str(ctx, "splits.custom", "name", c["name"]),
                _int_list(ctx, "splits.custom", "cal_inputs", c["cal_inputs"]),
                _int_list(ctx, "splits.custom", "val_inputs", c["val_inputs"]),
                _int_list(ctx, "splits.custom", "cal_series", c.get("cal_series"), allow_none=True),
                _int_list(ctx, "splits.custom", "val_series", c.get("val_series"), allow_none=True)))
        kw["custom"] = tuple(out)
    cfg = SplitsConfig(**kw)
    if not cfg.scenarios and not cfg.custom and cfg.random.n == 0:
        raise ctx.error("splits", "scenarios", "no split defined: give scenarios, [splits.random] n > 0 or "
                        "[[splits.custom]]")
    return cfg


def _parse_detect(ctx, t):
    _check_keys(ctx, "detect", t, {"tol", "statistic", "correction", "normality", "covariance", "sensors"})
    kw = {}
    if "tol" in t:
        kw["tol"] = float(_num(ctx, "detect", "tol", t["tol"]))
        if not 0 < kw["tol"] < 1:
            raise ctx.error("detect", "tol", f"TOL must lie in (0, 1), got {kw['tol']}")
    ch = {"statistic": ("likelihood_ratio", "two_sample", "paper"), "correction": ("bonferroni", "holm"),
          "normality": ("check", "override"), "covariance": ("second_order", "gauss_newton")}
    for k, c in ch.items():
        if k in t:
            kw[k] = _str(ctx, "detect", k, t[k], c)
    if "sensors" in t:
        s = t["sensors"]
        if isinstance(s, str):
            kw["sensors"] = _str(ctx, "detect", "sensors", s, ("oed", "all"))
        else:
            kw["sensors"] = _str_list(ctx, "detect", "sensors", s)
    return DetectConfig(**kw)


def _parse_oed(ctx, t):
    _check_keys(ctx, "oed", t, {"criterion", "kind", "n_sensors", "min_sensors", "include", "exclude", "variant"})
    kw = {}
    if "criterion" in t:
        kw["criterion"] = _str(ctx, "oed", "criterion", t["criterion"], ("A", "D", "E"))
    if "kind" in t:
        kw["kind"] = _str(ctx, "oed", "kind", t["kind"], ("second_order", "gauss_newton"))
    for k in ("n_sensors", "min_sensors"):
        if k in t:
            kw[k] = _num(ctx, "oed", k, t[k], integer=True, positive=True)
    for k in ("include", "exclude"):
        if k in t:
            kw[k] = _str_list(ctx, "oed", k, t[k])
    if "variant" in t:
        kw["variant"] = _str(ctx, "oed", "variant", t["variant"])
    return OEDConfig(**kw)


def _parse_validate(ctx, t):
    _check_keys(ctx, "validate", t, {"n_runs", "seed", "variant"})
    kw = {}
    if "n_runs" in t:
        kw["n_runs"] = _num(ctx, "validate", "n_runs", t["n_runs"], integer=True, positive=True)
    if "seed" in t:
        kw["seed"] = _num(ctx, "validate", "seed", t["seed"], integer=True, nonneg=True)
    if "variant" in t:
        kw["variant"] = _str(ctx, "validate", "variant", t["variant"])
    return ValidateConfig(**kw)


def _parse_report(ctx, t):
    _check_keys(ctx, "report", t, {"title", "dpi"})
    kw = {}
    if "title" in t:
        kw["title"] = _str(ctx, "report", "title", t["title"])
    if "dpi" in t:
        kw["dpi"] = _num(ctx, "report", "dpi", t["dpi"], integer=True, positive=True)
    return ReportConfig(**kw)


_SECTIONS = {"model": _parse_model, "data": _parse_data, "sensors": _parse_sensors,
             "parameters": _parse_parameters, "splits": _parse_splits, "detect": _parse_detect,
             "oed": _parse_oed, "validate": _parse_validate, "report": _parse_report}


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
    ctx = _Ctx(path, text)
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
    _cross_checks(ctx, cfg)
    return cfg


def _cross_checks(ctx, cfg: StudyConfig) -> None:
    d = cfg.data
    if d.force_correction and d.source == "prototype":
        raise ctx.error("data", "force_correction", "the prototype's readings are already corrected; "
                        "force_correction applies to CSV data")
    if d.force_correction and d.layout == "tidy" and d.value_column == "value":
        raise ctx.error("data", "force_correction", "the tidy column 'value' is the corrected reading; set "
                        "value_column = \"raw\" to apply the correction yourself")
    names = cfg.sensor_names()
    for sname in d.files:
        if names and sname not in names:
            raise ctx.error("data.files", sname, f"file given for sensor {sname!r}, which is not listed in "
                            f"[[sensors]] ({', '.join(names)})")
    o = cfg.oed
    for k in ("include", "exclude"):
        for s in getattr(o, k):
            if names and s not in names:
                raise ctx.error("oed", k, f"unknown sensor {s!r}; sensors: {', '.join(names)}")
    if o.variant and o.variant not in cfg.model.variants:
        raise ctx.error("oed", "variant", f"variant {o.variant!r} is not among [model] variants "
                        f"{list(cfg.model.variants)}")
    if cfg.validate.variant and cfg.validate.variant not in cfg.model.variants:
        raise ctx.error("validate", "variant", f"variant {cfg.validate.variant!r} is not among [model] variants "
                        f"{list(cfg.model.variants)}")
    if isinstance(cfg.detect.sensors, tuple):
        for s in cfg.detect.sensors:
            if names and s not in names:
                raise ctx.error("detect", "sensors", f"unknown sensor {s!r}; sensors: {', '.join(names)}")


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
