"""The sections of a study config as frozen dataclasses: the schema of the TOML file.

One dataclass per section ([model], [data], [[sensors]], [[parameters]], [splits], [simulate],
[detect], [identify], [oed], [validate], [report], [dynamic]) and :class:`StudyConfig`, the whole study.  A section's fields
are its allowed keys and their defaults (:mod:`mudoe.config_schema`); the defaults that belong to a
built-in model (the default model, its variants, its data folder, its virtual prototype's seed and
series) are read from :mod:`mudoe.registry`.  The file is read into them by :mod:`mudoe.config`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from identification.studies.detect import DetectSettings
from identification.studies.montecarlo import MonteCarloSettings
from oed.criteria import DEFAULT_CRITERION

from .config_schema import NON_NEGATIVE, OPEN_UNIT, POSITIVE, Bounds, config_key, setting, settings_values
from .registry import DEFAULT_MODEL, default_model, known_variants, virtual_prototype
from .units import convert

__all__ = ["ModelConfig", "DataConfig", "SensorConfig", "ParameterConfig", "CustomSplitConfig", "RandomSplitConfig",
           "SplitsConfig", "SimulateConfig", "DetectConfig", "IdentifyConfig", "OEDConfig", "ValidateConfig",
           "QuantifyConfig", "ReportConfig", "DynamicConfig", "StudyConfig"]


def _default_variants() -> tuple:
    return known_variants()[DEFAULT_MODEL]


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

    name: str = DEFAULT_MODEL
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

    source: str = config_key("csv", choices=("csv", "prototype"))
    layout: str = config_key("paper", choices=("paper", "tidy"))
    directory: str = default_model().data_directory
    files: dict[str, str] = field(default_factory=dict)
    file: str = "campaign_long.csv"
    actual_forces_file: str = ""
    value_column: str = config_key("value", choices=("value", "raw"))
    displacement_unit: str = config_key("um", unit="length")
    force_unit: str = config_key("N", unit="force")
    input_unit: str = config_key("", unit="any")
    output_unit: str = config_key("", unit="any")
    force_correction: bool = False
    series: tuple[int, ...] | None = None
    seed: int = config_key(virtual_prototype().seed, bounds=NON_NEGATIVE)
    n_series: int = config_key(virtual_prototype().n_series, bounds=Bounds(2))


@dataclass(frozen=True)
class SensorConfig:
    """One sensor, its standard deviation and the unit of its readings and sigma in the files.

    ``unit`` ("" = [data] output_unit, else the model's / displacement_unit rule) is converted once
    to the model's unit of the sensor.

    Give ``sigma`` directly, or ``sigma_man`` (the manufacturer's error): then sigma is
    composed as in the paper, sqrt(sigma_rep^2 + sigma_man^2), with sigma_rep the
    repeatability seen in the data (differences of consecutive series / sqrt 2).  The model
    error (:mod:`mudoe.model_error_runs`) takes sigma_rep of a composed sigma: sigma_man is
    taken as systematic and held by the model error; detection takes the composed sigma.
    """

    name: str
    sigma: float | None = config_key(None, bounds=POSITIVE)
    sigma_man: float | None = config_key(None, bounds=NON_NEGATIVE)
    unit: str = config_key("", unit="any")


@dataclass(frozen=True)
class ParameterConfig:
    """An unknown parameter: start value and bounds in ``unit`` (default the model's unit; N/mm for the press).

    ``unit`` (any unit pint knows, e.g. "1/K") names that unit; when the model declares another unit
    of the same dimension, start and bounds are converted to the model's unit by pint; a unit of
    another dimension is an error.
    """

    name: str
    start: float
    lower: float = config_key(-math.inf, allow_inf=True)
    upper: float = config_key(math.inf, allow_inf=True)
    unit: str = config_key("", unit="any")


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

    n: int = config_key(0, bounds=NON_NEGATIVE)
    cal_fraction: float = config_key(0.5, bounds=OPEN_UNIT)
    seed: int = config_key(1, bounds=NON_NEGATIVE)
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
    input_start: float | None = config_key(None)
    input_stop: float | None = config_key(None)
    n_inputs: int = config_key(11, bounds=Bounds(2))
    up_and_down: bool = False
    n_series: int = config_key(4, bounds=Bounds(2))
    seed: int = config_key(1, bounds=NON_NEGATIVE)
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
class IdentifyConfig:
    """The fits of every variant: min_p Phi(p) (paper eq. 3, objective units) from ``starts`` start values.

    Attributes
    ----------
    starts : int >= 1     fits from the [[parameters]] starts and ``starts - 1`` scrambled Sobol points drawn
                          in the bounds (:mod:`identification.fit.multistart`); the best local minimum is the
                          estimate and the report gets a "multi-start" page per variant (1: the single fit)
    seed : int >= 0       draws the further starts
    """

    starts: int = config_key(1, bounds=Bounds(1))
    seed: int = config_key(0, bounds=NON_NEGATIVE)


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
                                   candidates' range (oed.refine_inputs: multi-start; Newton for D, Ipopt for A, E)
    prior : dict                   {parameter: (distribution, *args)}, the parameter uncertainty of a robust
                                   approximate design (mode "inputs") or of the exact robust design of sensors
                                   or sampling times (mode "sensors"; mudoe.config_prior; {} = none: local)
    robust : {"", "bayes", "maximin"}  with a prior: the pseudo-Bayesian (default) or maximin criterion
    approximate : bool             mode "inputs": the approximate design (support points, weights and the
                                   equivalence certificate) on the candidates' range instead of n_points
                                   exact points (implied by a prior without n_points; a prior with n_points
                                   and approximate = false: the exact robust choice of n_points rows); a
                                   dynamic study's mode "sensors": the approximate sampling times (weights on
                                   the range of the candidate times, with the certificate)
    bounds : dict                  a dynamic study's mode "inputs": {input: (lower, upper)} of its constants
                                   and controls (model units; a control's every grid value); an input not
                                   named: the range of the study's experiments (mudoe.config_design)
    n_candidates : int             a dynamic study's mode "inputs": random experiments drawn within the bounds
                                   (seeded by ``seed``) as candidates beside the study's own experiments
    seed : int                     draws the candidate experiments
    time_limit : float             seconds for an input design (the exact choice and the continuous
                                   refinement, a dynamic model's mesh control included); the output says when
                                   it was reached
    """

    criterion: str = config_key(DEFAULT_CRITERION, choices=("A", "D", "E"))
    kind: str = config_key("second_order", choices=("second_order", "gauss_newton"))
    n_sensors: int | None = config_key(None, bounds=POSITIVE)
    min_sensors: int | None = config_key(None, bounds=POSITIVE)
    include: tuple[str, ...] = ()
    exclude: tuple[str, ...] = ()
    variant: str = ""
    mode: str = config_key("sensors", choices=("sensors", "inputs", "both", "discrimination"))
    planned: bool = False
    max_sensors: int | None = config_key(None, bounds=POSITIVE)
    costs: tuple[float, ...] = ()
    budget: float | None = config_key(None, bounds=NON_NEGATIVE)
    candidates: tuple[float, ...] = ()
    candidates_range: tuple[float, ...] = ()
    n_points: int | None = config_key(None, bounds=POSITIVE)
    n_series: int = config_key(1, bounds=POSITIVE)
    rival: str = ""
    discrimination_criterion: str = config_key("T", choices=("T", "divergence", "T_refit"))
    n_readings: int | None = config_key(None, bounds=POSITIVE)
    refine: bool = False
    prior: dict = field(default_factory=dict)
    robust: str = config_key("", choices=("bayes", "maximin"))
    approximate: bool = False
    bounds: dict = field(default_factory=dict)
    n_candidates: int = config_key(8, bounds=POSITIVE)
    seed: int = config_key(0, bounds=NON_NEGATIVE)
    time_limit: float = config_key(60.0, bounds=POSITIVE)

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
    ("" = the first listed).  ``model_error`` (study only): ``mudoe validate`` also reports the held-out
    coverage of the variant's bands with and without its model error (:mod:`mudoe.model_error_runs`).
    """

    n_runs: int = setting(MonteCarloSettings, "n_rep")
    seed: int = setting(MonteCarloSettings, "seed", bounds=NON_NEGATIVE)
    scheduler: str | None = setting(MonteCarloSettings, "scheduler")
    variant: str = ""
    model_error: bool = True

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
class QuantifyConfig:
    """``mudoe quantify`` and the report's "Model uncertainty" page (issue 29).

    ``next_runs``: the number of new runs (input rows) proposed for every variant whose error model is a
    discrepancy or an embedded error, the ones that most shrink its prediction band over the data's input range
    (:func:`oed.select_error_design`, integrated criterion; :mod:`mudoe.model_error_runs`); 0 proposes none.
    """

    next_runs: int = config_key(2, bounds=NON_NEGATIVE)


@dataclass(frozen=True)
class ReportConfig:
    """Report options."""

    title: str = "Model uncertainty study"
    dpi: int = config_key(150, bounds=POSITIVE)
    #: which fitted models get the pages "Uncertainty of ..." (profile intervals, likelihood regions):
    #: "untrusted" those whose linearisation is not trustworthy, "all", or "none"
    uncertainty: str = config_key("untrusted", choices=("untrusted", "all", "none"))
    #: the pages "Model error of ..." of every variant (issue 29; each costs a model_error with its held-out table)
    model_error: bool = True


@dataclass(frozen=True)
class DynamicConfig:
    """The ``[dynamic]`` section of a time-series study (an ODE/DAE model, ``Model.ode``; :mod:`mudoe.kind.time_series`)::

        [dynamic]
        times = [0.2, 0.4, 0.6]          # sampling times of the data (the model's time unit)
        candidate_times = [...]          # candidates of the sampling-time design (default: times)
        n_times = 4                      # sampling times chosen (default: one per parameter)
        pairs = false                    # choose (time, instrument) pairs instead of times
        [[dynamic.experiments]]          # one table per experiment: its inputs by name (model units);
                                         # empty for a model without inputs (one empty table per run)
        cA0 = 1.0                        # a constant input
        T = [350, 360, 370]              # a control: one value per grid point of its grid

    Every instrument has one sigma ([[sensors]], not one per time).  The checks that need the model
    (times within the horizon, input names, the number of grid values of a control) are made when the
    study is prepared (:func:`mudoe.kind.time_series.experiment_rows`).

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
    identify: IdentifyConfig = field(default_factory=IdentifyConfig)
    oed: OEDConfig = field(default_factory=OEDConfig)
    validate: ValidateConfig = field(default_factory=ValidateConfig)
    quantify: QuantifyConfig = field(default_factory=QuantifyConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    dynamic: DynamicConfig | None = None   # [dynamic]: a time-series study (mudoe.kind.time_series)
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

