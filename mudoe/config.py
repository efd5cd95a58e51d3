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

One schema
----------
The section dataclasses below *are* the schema: a section's allowed keys are its fields, a
key's default is the field's default, and the field's annotation and metadata say how the
TOML value is checked (:func:`_read`).  Keys that drive a library function are declared with
:func:`setting`: their default is the default of the library's settings dataclass, the
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
from dataclasses import MISSING, Field, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from identification.studies.detect import DetectSettings
from identification.studies.montecarlo import MonteCarloSettings
from models.friction import VARIANTS as FRICTION_VARIANTS
from models.press import PRESS_SCENARIO_NAMES

from .checks import check_config
from .units import UnitError, check_unit, convert, dimension, known_units

__all__ = ["ConfigError", "ModelConfig", "DataConfig", "SensorConfig", "ParameterConfig", "CustomSplitConfig",
           "RandomSplitConfig", "SplitsConfig", "SimulateConfig", "DetectConfig", "OEDConfig", "ValidateConfig", "ReportConfig",
           "StudyConfig", "load_config", "parse_config", "LENGTH_UNITS", "FORCE_UNITS", "MODEL_VARIANTS",
           "DEFAULT_CONFIG", "STUDY_DEFAULTS", "known_variants", "known_scenarios", "setting", "settings_keys",
           "settings_values", "config_error"]

#: examples of declared length units and their factor to the model's mm (any pint length unit is accepted)
LENGTH_UNITS = {"mm": 1.0, "um": 1e-3, "m": 1e3}
#: examples of declared force units and their factor to the model's N (any pint force unit is accepted)
FORCE_UNITS = {"N": 1.0, "kN": 1e3}
#: known models and their variants (friction models of the paper); read through :func:`known_variants`
MODEL_VARIANTS = {"press": FRICTION_VARIANTS}

#: The study's own defaults where they differ from the settings dataclass's, keyed by
#: (settings dataclass, field); every other settings-backed key takes the dataclass's default.
#: ``mudoe validate`` has always run a quick size study, 200 replications from seed 1, while
#: :class:`identification.studies.montecarlo.MonteCarloSettings` defaults to 2000 replications from
#: seed 20261121; a config without these keys keeps giving the numbers it gave before.
STUDY_DEFAULTS = {(MonteCarloSettings, "n_rep"): 200, (MonteCarloSettings, "seed"): 1}

#: the default study shipped with the repository
DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"

#: examples of the units a config may declare (README "Data formats"; "" = not declared; any unit pint knows)
UNIT_CHOICES = ("",) + known_units()

#: an own model factory, "package.module:function"
_FACTORY = re.compile(r"[A-Za-z_][\w.]*:[A-Za-z_]\w*")


def known_variants() -> dict:
    """Built-in models and their variants, ``{model name: (variant, ...)}``.

    The one place the config reads them (the press: friction variants M1, M2, M3).
    """
    return dict(MODEL_VARIANTS)


def known_scenarios() -> tuple:
    """Names of the paper's press scenarios (``[splits] scenarios``); the one place the config reads them."""
    return PRESS_SCENARIO_NAMES


class ConfigError(ValueError):
    """The study configuration is invalid; the message names the file, the key and (if known) the line."""


# ---------------------------------------------------------------------------- schema helpers
@dataclass(frozen=True)
class Bounds:
    """Allowed numbers: ``v >= low`` (``v > low`` if ``strict``) and, if ``high`` is given, ``v < high``."""

    low: float
    strict: bool = False
    high: float | None = None

    def admits(self, v) -> bool:
        above = v > self.low if self.strict else v >= self.low
        return above and (self.high is None or v < self.high)

    def __str__(self) -> str:
        if self.high is not None:
            return f"lie in ({self.low}, {self.high})"
        if self.low == 0:
            return "be positive" if self.strict else "be non-negative"
        return f"be {'greater than' if self.strict else 'at least'} {self.low}"


POSITIVE = Bounds(0, strict=True)
NON_NEGATIVE = Bounds(0)
OPEN_UNIT = Bounds(0, strict=True, high=1)


def _key(default, *, choices=None, bounds=None, allow_inf=False, unit=None) -> Field:
    """A config key: its default and how its value is checked (choices, bounds, infinite allowed; ``unit``:
    the value is a unit pint knows, ``"any"`` or of the named dimension, e.g. ``"length"``)."""
    return field(default=default, metadata={"choices": choices, "bounds": bounds, "allow_inf": allow_inf,
                                            "unit": unit})


def _field_of(cls, name: str) -> Field:
    for f in fields(cls):
        if f.name == name:
            return f
    raise AttributeError(f"{cls.__name__} has no field {name!r}")


def setting(settings: type, name: str, bounds: Bounds | None = None) -> Field:
    """A config key backed by field ``name`` of the settings dataclass ``settings``.

    Its default is that field's default (or the study's own, :data:`STUDY_DEFAULTS`); its value is
    validated by ``settings`` itself; ``bounds`` only for what ``settings`` does not check.
    """
    f = _field_of(settings, name)
    if f.default is MISSING:
        raise TypeError(f"name: {settings.__name__}.{name} has no plain default; back the key by a field "
                        "with one")
    default = STUDY_DEFAULTS.get((settings, name), f.default)
    return field(default=default, metadata={"settings": settings, "field": name, "bounds": bounds})


def settings_keys(section) -> dict:
    """``{TOML key: settings field}`` of a section (class or instance): its keys backed by a settings field."""
    return {f.name: f.metadata["field"] for f in fields(section) if "field" in f.metadata}


def settings_values(section) -> dict:
    """``{settings field: value}`` of a section instance: its settings-backed keys under the fields' names."""
    return {fld: getattr(section, key) for key, fld in settings_keys(section).items()}


def _settings_class(section) -> type:
    return next(f.metadata["settings"] for f in fields(section) if "settings" in f.metadata)


# ---------------------------------------------------------------------------- dataclasses
def _default_variants() -> tuple:
    return known_variants()[ModelConfig.name]


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
    variants: tuple[str, ...] = field(default_factory=_default_variants)
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
    displacement_unit : str
        Unit of readings that are lengths (the model's sensor unit is a length): any pint length
        unit ("mm", "um", "m", "in", ...).
    force_unit : str
        Unit of an input that is a force (the model's input unit is a force): any pint force unit
        ("N", "kN", "lbf", ...).
    input_unit, output_unit : str
        Any unit pint knows (:mod:`mudoe.units`) for the input column and the readings in the files
        ("" = the model's own unit, or force_unit / displacement_unit as above); a sensor's
        ``unit`` in [[sensors]] overrides output_unit.  Converted once to the model's units.
    force_correction : bool
        Apply the paper's correction z * q_set / q_actual (needs actual forces; readings at
        q_set = 0 are left unchanged).
    series : tuple of int or None
        0-based series used by the study (e.g. the paper's two held-out series); None = all.
        The repeatability sigma and the normality table always use every series.
    seed, n_series : int
        Prototype source: random seed and number of series (at least 2).
    """

    source: str = _key("csv", choices=("csv", "prototype"))
    layout: str = _key("paper", choices=("paper", "tidy"))
    directory: str = "../data/press_campaign"
    files: dict[str, str] = field(default_factory=dict)
    file: str = "campaign_long.csv"
    actual_forces_file: str = ""
    value_column: str = _key("value", choices=("value", "raw"))
    displacement_unit: str = _key("um", unit="length")
    force_unit: str = _key("N", unit="force")
    input_unit: str = _key("", unit="any")
    output_unit: str = _key("", unit="any")
    force_correction: bool = False
    series: tuple[int, ...] | None = None
    seed: int = _key(20190731, bounds=NON_NEGATIVE)
    n_series: int = _key(6, bounds=Bounds(2))


@dataclass(frozen=True)
class SensorConfig:
    """One sensor, its standard deviation and the unit of its readings and sigma in the files.

    ``unit`` ("" = [data] output_unit, else the model's / displacement_unit rule) is converted once
    to the model's unit of the sensor.

    Give ``sigma`` directly, or ``sigma_man`` (the manufacturer's error): then sigma is
    composed as in the paper, sqrt(sigma_rep^2 + sigma_man^2), with sigma_rep the
    repeatability seen in the data (differences of consecutive series / sqrt 2).
    """

    name: str
    sigma: float | None = _key(None, bounds=POSITIVE)
    sigma_man: float | None = _key(None, bounds=NON_NEGATIVE)
    unit: str = _key("", unit="any")


@dataclass(frozen=True)
class ParameterConfig:
    """An unknown parameter: start value and bounds in ``unit`` (default the model's unit; N/mm for the press).

    ``unit`` (any unit pint knows, e.g. "1/K") names that unit; when the model declares another unit
    of the same dimension, start and bounds are converted to the model's unit by pint; a unit of
    another dimension is an error.
    """

    name: str
    start: float
    lower: float = _key(-math.inf, allow_inf=True)
    upper: float = _key(math.inf, allow_inf=True)
    unit: str = _key("", unit="any")


@dataclass(frozen=True)
class CustomSplitConfig:
    """A user split: 0-based input (and optionally series and sensor column) indices of both sets
    (:class:`identification.studies.splits.Split`)."""

    name: str
    cal_inputs: tuple[int, ...]
    val_inputs: tuple[int, ...]
    cal_series: tuple[int, ...] | None = None
    val_series: tuple[int, ...] | None = None
    cal_sensors: tuple[int, ...] | None = None
    val_sensors: tuple[int, ...] | None = None


@dataclass(frozen=True)
class RandomSplitConfig:
    """Monte Carlo cross-validation splits (``n = 0``: none)."""

    n: int = _key(0, bounds=NON_NEGATIVE)
    cal_fraction: float = _key(0.5, bounds=OPEN_UNIT)
    seed: int = _key(1, bounds=NON_NEGATIVE)
    exclude_zero_force: bool = True


@dataclass(frozen=True)
class SplitsConfig:
    """Calibration / validation splits (Algorithm 1, line 06).

    ``scenarios``: names of the paper's scenarios (:func:`known_scenarios`), or ``["paper"]`` for all four.
    """

    scenarios: tuple[str, ...] = ("paper",)
    random: RandomSplitConfig = field(default_factory=RandomSplitConfig)
    custom: tuple = ()
    #: dynamic studies: one split per time e, the readings at t < e against t >= e
    time_windows: tuple[float, ...] = ()
    #: dynamic studies: the readings before the median sampling time against the later ones
    early_late: bool = False


@dataclass(frozen=True)
class SimulateConfig:
    """``mudoe simulate`` for an own model: a campaign simulated from the model itself.

    z_ijk = h_k(y_j, p_true, q_j) + sigma_k e_ijk with e_ijk ~ N(0, 1) (seeded), sigma_k the
    sensors' sigma ([[sensors]] sigma, the files' unit), written into ``--out`` in the study's
    [data] layout, file names and units.  The press ignores this section (its virtual prototype).

    Attributes
    ----------
    truth : dict {parameter: value}   true parameters (model units; default the [[parameters]] starts)
    inputs : tuple of float           the set points in the [data] input unit, or instead
    input_start, input_stop, n_inputs  an even range of ``n_inputs`` set points
    up_and_down : bool                 then back down again (loading and unloading)
    n_series : int                     repeated series (at least 2)
    seed : int
    variant : str                      the model variant simulated ("" = the first listed)
    """

    truth: dict[str, float] = field(default_factory=dict)
    inputs: tuple[float, ...] = ()
    input_start: float | None = _key(None)
    input_stop: float | None = _key(None)
    n_inputs: int = _key(11, bounds=Bounds(2))
    up_and_down: bool = False
    n_series: int = _key(4, bounds=Bounds(2))
    seed: int = _key(1, bounds=NON_NEGATIVE)
    variant: str = ""

    def input_values(self) -> "np.ndarray":
        """The set points (the [data] input unit): ``inputs``, or the range (and back down)."""
        import numpy as np
        if self.inputs:
            return np.asarray(self.inputs, float)
        q = np.linspace(self.input_start, self.input_stop, self.n_inputs)
        return np.r_[q, q[-2::-1]] if self.up_and_down else q


@dataclass(frozen=True)
class DetectConfig:
    """Algorithm 1: test level, statistic, correction, normality gate, covariance, sensors used.

    The first five keys are fields of :class:`identification.studies.detect.DetectSettings` (same
    names, same defaults, validated there).  ``sensors`` (study only): ``"oed"`` (the design
    chosen by the [oed] section), ``"all"``, or a list of names.
    """

    tol: float = setting(DetectSettings, "tol")
    statistic: str = setting(DetectSettings, "statistic")
    correction: str = setting(DetectSettings, "correction")
    normality: str = setting(DetectSettings, "normality")
    normality_correction: str = setting(DetectSettings, "normality_correction")
    covariance: str = setting(DetectSettings, "covariance")
    sensors: Any = "oed"

    def settings(self) -> DetectSettings:
        """The :class:`DetectSettings` of Algorithm 1: this section's keys, every other field its default."""
        return DetectSettings(**settings_values(self))


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
    mode : {"sensors", "inputs", "both", "discrimination"}
                                   what is chosen: sensors, input points (every sensor measured),
                                   input x sensor pairs, or a discrimination design (oed.discrimination)
    planned : bool                 design before data, at the [[parameters]] start values (no data read)
    max_sensors : int or None      upper bound on the number of sensors (mode "sensors")
    costs : tuple of float         one cost per candidate (sensor, input point or pair), with budget
    budget : float or None
    candidates : tuple of float    candidate set points (force unit; modes inputs/both, and planned designs)
    candidates_range : tuple of float  [start, stop, count]: count evenly spaced set points instead
    n_points : int or None         input points (mode inputs) or (point, sensor) pairs (mode both) chosen
    n_series : int                 repetitions of every input in a planned design
    rival : str                    mode "discrimination": the rival variant to be refuted (the design
                                   separates it from ``variant``, which is assumed true)
    discrimination_criterion : {"T", "divergence", "T_refit"}
                                   mode "discrimination": local T-optimality (rival held at its
                                   parameters), the divergence normalised by both estimates' prediction
                                   variances (needs data), or T with the rival refitted (linearised;
                                   exact by enumeration of the designs)
    n_readings : int or None       mode "discrimination": number of free (set point, sensor) readings
    refine : bool                  mode "inputs": also refine the chosen set points continuously within the
                                   candidates' range (oed.refine_inputs: Ipopt, multi-start; slow on the press)
    """

    criterion: str = _key("E", choices=("A", "D", "E"))
    kind: str = _key("second_order", choices=("second_order", "gauss_newton"))
    n_sensors: int | None = _key(None, bounds=POSITIVE)
    min_sensors: int | None = _key(None, bounds=POSITIVE)
    include: tuple[str, ...] = ()
    exclude: tuple[str, ...] = ()
    variant: str = ""
    mode: str = _key("sensors", choices=("sensors", "inputs", "both", "discrimination"))
    planned: bool = False
    max_sensors: int | None = _key(None, bounds=POSITIVE)
    costs: tuple[float, ...] = ()
    budget: float | None = _key(None, bounds=NON_NEGATIVE)
    candidates: tuple[float, ...] = ()
    candidates_range: tuple[float, ...] = ()
    n_points: int | None = _key(None, bounds=POSITIVE)
    n_series: int = _key(1, bounds=POSITIVE)
    rival: str = ""
    discrimination_criterion: str = _key("T", choices=("T", "divergence", "T_refit"))
    n_readings: int | None = _key(None, bounds=POSITIVE)
    refine: bool = False

    def candidate_points(self) -> np.ndarray:
        """The candidate set points: ``candidates``, or ``candidates_range`` = [start, stop, count]."""
        if self.candidates_range:
            a, b, n = self.candidates_range
            return np.linspace(a, b, int(n))
        return np.asarray(self.candidates, float)


@dataclass(frozen=True)
class ValidateConfig:
    """Monte Carlo check of covariance and test size (:mod:`identification.studies.montecarlo`).

    ``n_runs``, ``seed`` and ``scheduler`` are ``MonteCarloSettings.n_rep``, ``.seed`` and
    ``.scheduler`` (defaults: :data:`STUDY_DEFAULTS`; ``scheduler`` absent: local processes,
    else a Dask scheduler address "tcp://HOST:8786", README "Running on several machines").
    ``variant`` (study only): the model variant simulated and tested
    ("" = the first listed).
    """

    n_runs: int = setting(MonteCarloSettings, "n_rep")
    seed: int = setting(MonteCarloSettings, "seed", bounds=NON_NEGATIVE)
    scheduler: str | None = setting(MonteCarloSettings, "scheduler")
    variant: str = ""

    def settings(self, tol: float, workers: int | None = None, progress: bool = True,
                 normality_correction: str = "holm") -> MonteCarloSettings:
        """The :class:`MonteCarloSettings` of the size study: ``n_rep`` and ``seed`` from this section.

        The tests run at level ``tol`` with the normality gate recorded, not enforced (its failure
        rate counted with ``normality_correction``, ``[detect]``), and every other field at its
        default: the settings :func:`identification.studies.montecarlo.validate` builds from its keyword arguments.
        """
        det = DetectSettings(tol=tol, normality="override", normality_correction=normality_correction)
        return MonteCarloSettings(**settings_values(self), workers=workers, progress=progress, detect=det)


@dataclass(frozen=True)
class ReportConfig:
    """Report options."""

    title: str = "Model uncertainty study"
    dpi: int = _key(150, bounds=POSITIVE)
    #: which fitted models get the pages "Uncertainty of ..." (profile intervals, likelihood regions):
    #: "untrusted" those whose linearisation is not trustworthy, "all", or "none"
    uncertainty: str = _key("untrusted", choices=("untrusted", "all", "none"))


@dataclass(frozen=True)
class StudyConfig:
    """A whole study (see the module docstring and README "Config reference")."""

    model: ModelConfig = field(default_factory=ModelConfig)
    data: DataConfig = field(default_factory=DataConfig)
    sensors: tuple = ()
    parameters: tuple = ()
    splits: SplitsConfig = field(default_factory=SplitsConfig)
    simulate: SimulateConfig = field(default_factory=SimulateConfig)
    detect: DetectConfig = field(default_factory=DetectConfig)
    oed: OEDConfig = field(default_factory=OEDConfig)
    validate: ValidateConfig = field(default_factory=ValidateConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    dynamic: Any = None              # mudoe.dynamic_config.DynamicConfig of a dynamic study
    path: str = "<string>"
    base_dir: str = "."
    text: str = ""

    # ------------------------------------------------------------------ helpers
    @property
    def length_factor(self) -> float:
        """Factor from the declared displacement unit to mm."""
        return float(convert(1.0, self.data.displacement_unit, "mm"))

    @property
    def force_factor(self) -> float:
        """Factor from the declared force unit to N."""
        return float(convert(1.0, self.data.force_unit, "N"))

    def resolve(self, rel: str) -> Path:
        """A path from the config, relative to the config file's folder."""
        p = Path(rel)
        return p if p.is_absolute() else Path(self.base_dir) / p

    def sensor_names(self) -> tuple:
        return tuple(s.name for s in self.sensors)

    def as_dict(self) -> dict:
        """A plain-dict view (for results.json)."""
        return _plain(self)


def _plain(v):
    """A JSON-ready view of a config value (dataclasses as dicts, non-finite floats as strings)."""
    if hasattr(v, "__dataclass_fields__"):
        return {f.name: _plain(getattr(v, f.name)) for f in fields(v) if f.name != "text"}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return v


# ---------------------------------------------------------------------------- parsing
class _Ctx:
    """Where we are: file name and text (for line numbers)."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = text.splitlines()

    def _section_start(self, section: str) -> int:
        """0-based line of the header of ``[section]`` (0 if not found)."""
        last = section.split(".")[-1].split("[")[0]
        hdr = re.compile(r"^\s*\[\[?\s*" + re.escape(section.split("[")[0]) + r"\s*\]\]?\s*(#.*)?$")
        hdr2 = re.compile(r"^\s*\[\[?.*\b" + re.escape(last) + r"\s*\]\]?")
        for pattern in (hdr, hdr2):
            for i, ln in enumerate(self.lines):
                if pattern.match(ln):
                    return i
        return 0

    def line_of(self, section: str, key: str) -> int | None:
        """Best-effort 1-based line of ``key`` inside ``[section]`` (None if not found)."""
        start = self._section_start(section) if section else 0
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


# ------------------------------------------------------------------ one validator each
def _check_keys(ctx: _Ctx, section: str, table, schema) -> None:
    """``table`` is a TOML table whose keys are fields of the dataclass ``schema``."""
    if not isinstance(table, dict):
        raise ctx.error("", section, f"expected a table, got {type(table).__name__}")
    allowed = {f.name for f in fields(schema)}
    for k in table:
        if k not in allowed:
            raise ctx.error(section, k, f"unknown key {k!r}; allowed keys: {', '.join(sorted(allowed))}")


def _require(ctx: _Ctx, section: str, table: dict, schema, what: str) -> None:
    """Every field of ``schema`` without a default is a key of ``table``."""
    need = [f.name for f in fields(schema) if f.default is MISSING and f.default_factory is MISSING]
    for k in need:
        if k not in table:
            raise ctx.error(section, next(iter(table), ""), f"{what} needs {', '.join(need)}; add {k}")


def _tables(ctx: _Ctx, section: str, key: str, arr) -> list:
    """An array of tables (``[[section.key]]``)."""
    if not isinstance(arr, list) or not all(isinstance(x, dict) for x in arr):
        raise ctx.error(section, key, f"expected [[{section + '.' if section else ''}{key}]] tables")
    return arr


def _names(values) -> str:
    return ", ".join(repr(v) if " " in str(v) else str(v) for v in values)


def _one_of(ctx: _Ctx, section: str, key: str, value, known, what: str = "value", note: str = "") -> None:
    """``value`` is one of ``known``; the message lists them (and ``note`` says what they are)."""
    if value not in known:
        raise ctx.error(section, key, f"unknown {what} {value!r}; use one of: {_names(known)}"
                        + (f" ({note})" if note else ""))


def _unique(ctx: _Ctx, section: str, key: str, names, what: str) -> None:
    if len(set(names)) != len(names):
        raise ctx.error(section, key, f"a {what} is listed twice: {list(names)}")


def _num(ctx, section, key, v, *, integer=False, bounds=None, allow_inf=False, what=""):
    """A TOML number (an integer if ``integer``), finite unless ``allow_inf``, within ``bounds``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ctx.error(section, key, f"expected a number, got {v!r}")
    if integer and not isinstance(v, int):
        raise ctx.error(section, key, f"expected an integer, got {v!r}")
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ctx.error(section, key, f"expected a finite number, got {v!r}")
    if bounds is not None and not bounds.admits(v):
        raise ctx.error(section, key, f"{what}must {bounds}, got {v!r}")
    return v


def _str(ctx, section, key, v, choices=None):
    if not isinstance(v, str):
        raise ctx.error(section, key, f"expected a string, got {v!r}")
    if choices is not None:
        _one_of(ctx, section, key, v, choices)
    return v


def _unit(ctx, section, key, v, dim):
    """A unit pint knows ("" = undeclared, unless ``dim`` names the dimension it must have)."""
    try:
        check_unit(v)
    except UnitError as exc:
        raise ctx.error(section, key, str(exc)) from None
    if dim != "any" and (v == "" or dimension(v) != dim):
        got = "nothing" if v == "" else f"{v!r}, a unit of {dimension(v)}"
        raise ctx.error(section, key, f"expected a unit of {dim} (e.g. {_DIM_EXAMPLES.get(dim, '')}), got {got}")
    return v


_DIM_EXAMPLES = {"length": "'mm', 'um', 'm', 'in'", "force": "'N', 'kN', 'lbf'"}


def _bool(ctx, section, key, v):
    if not isinstance(v, bool):
        raise ctx.error(section, key, f"expected true or false, got {v!r}")
    return v


def _int_list(ctx, section, key, v):
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


def _str_table(ctx, section, key, v):
    if not isinstance(v, dict) or not all(isinstance(x, str) for x in v.values()):
        raise ctx.error(section, key, f"expected a table {{sensor = \"file.csv\"}}, got {v!r}")
    return dict(v)


def _float_list(ctx, section, key, v):
    """A non-empty TOML list of finite numbers (to give none, leave the key out)."""
    if not isinstance(v, list) or not v:
        raise ctx.error(section, key, f"expected a non-empty list of numbers, got {v!r}")
    for x in v:
        _num(ctx, section, key, x)
    return tuple(float(x) for x in v)


def _float_table(ctx, section, key, v):
    if not isinstance(v, dict):
        raise ctx.error(section, key, f"expected a table {{name = value}}, got {v!r}")
    for x in v.values():
        _num(ctx, section, key, x)
    return {k: float(x) for k, x in v.items()}


#: readers of the other annotations of schema fields (``X | None`` is read as X: TOML has no null)
_READERS = {"bool": _bool, "tuple[str, ...]": _str_list, "tuple[int, ...]": _int_list, "dict[str, str]": _str_table,
            "tuple[float, ...]": _float_list, "dict[str, float]": _float_table}


def _read(ctx: _Ctx, section: str, f: Field, v, what: str = ""):
    """The TOML value ``v`` of the key ``f`` (a schema field), checked by its annotation and metadata.

    Numbers keep their TOML type (an integer ``sigma = 5`` stays 5); ``what`` prefixes a bounds message.
    """
    kind, meta = f.type.removesuffix(" | None"), f.metadata
    if kind in ("int", "float"):
        return _num(ctx, section, f.name, v, integer=kind == "int", bounds=meta.get("bounds"),
                    allow_inf=meta.get("allow_inf", False), what=what)
    if kind == "str":
        v = _str(ctx, section, f.name, v, meta.get("choices"))
        return v if meta.get("unit") is None else _unit(ctx, section, f.name, v, meta["unit"])
    if kind not in _READERS:
        raise TypeError(f"{section}.{f.name}: no reader for a {f.type!r} key")
    return _READERS[kind](ctx, section, f.name, v)


def _read_table(ctx: _Ctx, section: str, schema, table, skip=()) -> dict:
    """The keys of ``table`` (fields of ``schema``), each read by :func:`_read`; ``skip``: read by the caller."""
    _check_keys(ctx, section, table, schema)
    return {f.name: _read(ctx, section, f, table[f.name]) for f in fields(schema)
            if f.name in table and f.name not in skip}


def _validated(ctx: _Ctx, section: str, cfg):
    """``cfg`` once its settings dataclass accepts the values of the keys it backs."""
    try:
        _settings_class(cfg)(**settings_values(cfg))
    except (TypeError, ValueError) as exc:
        name, _, msg = str(exc).partition(": ")
        key = next((k for k, fld in settings_keys(cfg).items() if fld == name), "")
        raise ctx.error(section, key, msg if key else str(exc)) from None
    return cfg


# ------------------------------------------------------------------ sections
def _parse_model(ctx, t):
    kw = _read_table(ctx, "model", ModelConfig, t)
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
            _one_of(ctx, "model", "variants", v, known, "variant", f"the variants of model {name!r}")
    _unique(ctx, "model", "variants", variants, "variant")
    return ModelConfig(**kw)


def _parse_data(ctx, t):
    kw = _read_table(ctx, "data", DataConfig, t)
    if kw.get("series") == ():
        raise ctx.error("data", "series", "list at least one series (0-based), or drop the key for all")
    return DataConfig(**kw)


def _parse_sensor(ctx, t):
    _check_keys(ctx, "sensors", t, SensorConfig)
    _require(ctx, "sensors", t, SensorConfig, "every sensor")
    name = _str(ctx, "sensors", "name", t["name"])
    kw = {f.name: _read(ctx, "sensors", f, t[f.name], what=f"sensor {name!r}: {f.name} ")
          for f in fields(SensorConfig) if f.name in t and f.name != "name"}
    if "sigma" in kw and "sigma_man" in kw:
        raise ctx.error("sensors", "sigma_man", f"sensor {name!r}: give sigma or sigma_man, not both")
    return SensorConfig(name, **kw)


def _parse_sensors(ctx, arr):
    out = tuple(_parse_sensor(ctx, t) for t in _tables(ctx, "", "sensors", arr))
    _unique(ctx, "", "sensors", [s.name for s in out], "sensor")
    return out


def _parse_parameter(ctx, t):
    _check_keys(ctx, "parameters", t, ParameterConfig)
    _require(ctx, "parameters", t, ParameterConfig, "every parameter")
    kw = _read_table(ctx, "parameters", ParameterConfig, t)
    p = ParameterConfig(**{k: v if k in ("name", "unit") else float(v) for k, v in kw.items()})
    if not p.lower <= p.start <= p.upper:
        raise ctx.error("parameters", "start", f"parameter {p.name!r}: start {p.start} lies outside "
                        f"[{p.lower}, {p.upper}]")
    return p


def _parse_parameters(ctx, arr):
    out = tuple(_parse_parameter(ctx, t) for t in _tables(ctx, "", "parameters", arr))
    _unique(ctx, "", "parameters", [p.name for p in out], "parameter")
    return out


def _parse_custom_split(ctx, t):
    _check_keys(ctx, "splits.custom", t, CustomSplitConfig)
    _require(ctx, "splits.custom", t, CustomSplitConfig, "a custom split")
    return CustomSplitConfig(**_read_table(ctx, "splits.custom", CustomSplitConfig, t))


def _parse_splits(ctx, t):
    kw = _read_table(ctx, "splits", SplitsConfig, t, skip=("random", "custom"))
    for s in kw.get("scenarios", ()):
        _one_of(ctx, "splits", "scenarios", s, ("paper",) + tuple(known_scenarios()), "scenario",
                "\"paper\": all four")
    if "random" in t:
        kw["random"] = RandomSplitConfig(**_read_table(ctx, "splits.random", RandomSplitConfig, t["random"]))
    if "custom" in t:
        kw["custom"] = tuple(_parse_custom_split(ctx, c) for c in _tables(ctx, "splits", "custom", t["custom"]))
    cfg = SplitsConfig(**kw)
    if not cfg.scenarios and not cfg.custom and cfg.random.n == 0 and not cfg.time_windows and not cfg.early_late:
        raise ctx.error("splits", "scenarios", "no split defined: give scenarios, [splits.random] n > 0 or "
                        "[[splits.custom]] (dynamic studies: time_windows or early_late)")
    return cfg


def _parse_detect(ctx, t):
    kw = _read_table(ctx, "detect", DetectConfig, t, skip=("sensors",))
    s = t.get("sensors")
    if isinstance(s, str):
        kw["sensors"] = _str(ctx, "detect", "sensors", s, ("oed", "all"))
    elif s is not None:
        kw["sensors"] = _str_list(ctx, "detect", "sensors", s)
    return _validated(ctx, "detect", DetectConfig(**kw))


def _parse_oed(ctx, t):
    o = OEDConfig(**_read_table(ctx, "oed", OEDConfig, t))
    if o.candidates and o.candidates_range:
        raise ctx.error("oed", "candidates_range", "give candidates or candidates_range, not both")
    if o.candidates_range:
        r = o.candidates_range
        if len(r) != 3 or r[2] != int(r[2]) or r[2] < 1 or not r[0] <= r[1]:
            raise ctx.error("oed", "candidates_range", f"expected [start, stop, count] with start <= stop and an "
                            f"integer count >= 1, got {list(r)}")
    if (not o.costs) != (o.budget is None):
        raise ctx.error("oed", "budget" if o.costs else "costs", "give both costs and budget, or neither")
    if o.mode in ("inputs", "both"):
        if o.n_points is None:
            raise ctx.error("oed", "mode", f"mode = {o.mode!r} needs n_points (how many to choose)")
        if not (o.candidates or o.candidates_range):
            raise ctx.error("oed", "mode", f"mode = {o.mode!r} needs candidates or candidates_range")
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
    _one_of(ctx, "oed", "rival", o.rival, cfg.model.variants, "variant", "the [model] variants")
    true = o.variant or cfg.model.variants[-1]
    if o.rival == true:
        raise ctx.error("oed", "rival", f"the rival {o.rival!r} is the variant assumed true ([oed] variant"
                        f"{'' if o.variant else ' defaults to the last [model] variant'}); name another variant")


def _parse_simulate(ctx, t):
    cfg = SimulateConfig(**_read_table(ctx, "simulate", SimulateConfig, t))
    ranged = cfg.input_start is not None or cfg.input_stop is not None
    if cfg.inputs and ranged:
        raise ctx.error("simulate", "inputs", "give inputs or input_start/input_stop, not both")
    if ranged and (cfg.input_start is None or cfg.input_stop is None):
        raise ctx.error("simulate", "input_start", "give both input_start and input_stop (and n_inputs)")
    return cfg


def _parse_validate(ctx, t):
    return _validated(ctx, "validate", ValidateConfig(**_read_table(ctx, "validate", ValidateConfig, t)))


def _parse_report(ctx, t):
    return ReportConfig(**_read_table(ctx, "report", ReportConfig, t))


def _parse_dynamic(ctx, t):
    from .dynamic_config import parse_dynamic
    return parse_dynamic(ctx, t)


def config_error(cfg: StudyConfig, section: str, key: str, msg: str) -> ConfigError:
    """A ConfigError naming the config file, the line of ``key`` in ``[section]`` and the key."""
    return _Ctx(cfg.path, cfg.text).error(section, key, msg)


_SECTIONS = {"model": _parse_model, "data": _parse_data, "sensors": _parse_sensors,
             "parameters": _parse_parameters, "splits": _parse_splits, "detect": _parse_detect,
             "simulate": _parse_simulate, "oed": _parse_oed, "validate": _parse_validate, "report": _parse_report,
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
    _check_data(ctx, cfg)
    _check_names(ctx, cfg)
    _check_rival(ctx, cfg)
    o = cfg.oed
    if o.planned and not (o.candidates or o.candidates_range) and cfg.dynamic is None:   # dynamic: its experiments
        raise ctx.error("oed", "planned", "a planned design needs candidates or candidates_range (the inputs)")
    check_config(cfg, ctx.error)
    return cfg


def _check_data(ctx, cfg: StudyConfig) -> None:
    """The [data] options agree with each other and with [[sensors]]."""
    d = cfg.data
    if d.force_correction and d.source == "prototype":
        raise ctx.error("data", "force_correction", "the prototype's readings are already corrected; "
                        "force_correction applies to CSV data")
    if d.force_correction and d.layout == "tidy" and d.value_column == "value":
        raise ctx.error("data", "force_correction", "the tidy column 'value' is the corrected reading; set "
                        "value_column = \"raw\" to apply the correction yourself")
    names = cfg.sensor_names()
    if names:
        for sname in d.files:
            _one_of(ctx, "data.files", sname, sname, names, "sensor", "listed in [[sensors]]")


def _check_names(ctx, cfg: StudyConfig) -> None:
    """Sensors named in [oed] / [detect] are listed in [[sensors]]; variants in [model] variants."""
    names = cfg.sensor_names()
    named = [("oed", k, s) for k in ("include", "exclude") for s in getattr(cfg.oed, k)]
    if isinstance(cfg.detect.sensors, tuple):
        named += [("detect", "sensors", s) for s in cfg.detect.sensors]
    if names:
        for section, key, s in named:
            _one_of(ctx, section, key, s, names, "sensor", "listed in [[sensors]]")
    for section, variant in (("oed", cfg.oed.variant), ("validate", cfg.validate.variant),
                             ("simulate", cfg.simulate.variant)):
        if variant:
            _one_of(ctx, section, "variant", variant, cfg.model.variants, "variant", "the [model] variants")


def config_error(cfg: StudyConfig, section: str, key: str, msg: str) -> ConfigError:
    """A :class:`ConfigError` for a check made after parsing: names ``cfg``'s file, the line of ``key``
    in ``[section]`` (when the key is in the file) and the key."""
    return _Ctx(cfg.path, cfg.text).error(section, key, msg)


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
