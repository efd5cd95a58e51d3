"""``mudoe init``: a commented study config template for a user's model factory.

With ``--model package.module:function`` the factory is called once (variant ``"default"``) and
the template lists its parameters (start value from the parameter's scale, unit), inputs and
sensors (with units); without it the template has placeholders to fill in.  An existing file is
never overwritten.
"""
from __future__ import annotations

import math
from pathlib import Path

from models.contract import Model

from .config import ConfigError
from models.fileio import create_text

from .checks import call_factory
from .study import load_factory
from .units import UNITS

__all__ = ["template_text", "write_template"]

_HEAD = """\
# mudoe study config (TOML).  Every key has a default; README "Config reference" lists them all.
# Indices (series, inputs) are 0-based.  Paths are relative to this file.

[model]
name = "{name}"   # your factory: function(variant) -> models.Model
variants = ["default"]          # names passed to the factory, one fit per variant

[data]
source = "csv"
layout = "{layout}"                # "paper": one file per sensor; "tidy": one long table
directory = "data"              # folder of the CSV files (`mudoe simulate` writes them)
file = "campaign_long.csv"      # tidy layout: the table
{units}
"""

_TAIL = """
[simulate]                      # `mudoe simulate CONFIG --out data`: a campaign from the model itself
# truth = {{}}                  # true parameters (default: the start values above)
# inputs = [1.0, 2.0, 3.0]      # set points in the input unit, or a range:
# input_start = 0.0
# input_stop = 1.0
n_inputs = 11
n_series = 4                    # repeated series; noise from the sensors' sigma
seed = 1

[splits]
scenarios = []                  # the paper's press scenarios do not apply to your model
[splits.random]
n = 4                           # random calibration / validation splits of the inputs
cal_fraction = 0.5
seed = 1
exclude_zero_force = false
# [[splits.custom]]             # your own 0-based index sets
# name = "low vs high"
# cal_inputs = [0, 1, 2]
# val_inputs = [3, 4, 5]

[detect]
tol = 0.05                      # family-wise level
sensors = "all"                 # "all", "oed" (the [oed] design) or a list of sensor names

[oed]
criterion = "D"                 # A | D | E

[validate]
n_runs = 50                     # Monte Carlo replications of `mudoe validate`

[report]
title = "Model uncertainty study"
"""


def _num(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else ("inf" if v > 0 else "-inf")


def _start(scale, lower: float, upper: float) -> float:
    """A start value: the parameter's scale, else the middle of finite bounds, else 1."""
    if scale:
        return float(scale)
    if math.isfinite(lower) and math.isfinite(upper):
        return (lower + upper) / 2
    return 1.0


def template_text(model: Model | None = None, name: str = "mypackage.mymodel:build") -> str:
    """The commented TOML template for ``model`` (placeholders when None)."""
    if model is None:
        sensors = [("y1", "")]
        params = [("p1", 1.0, -math.inf, math.inf, "")]
        units = "# data units are the model's own unless declared (README \"Data formats\")"
        layout = "tidy"
    else:
        sensors = [(s, u if u in UNITS else "") for s, u in zip(model.sensors, model.sensor_units)]
        params = [(p.name, _start(p.scale, p.lower, p.upper), p.lower, p.upper, p.unit) for p in model.params]
        q_unit = model.input_units[0] if model.input_units and model.input_units[0] in UNITS else ""
        units = (f"input_unit = \"{q_unit}\"   # unit of the input column {model.inputs[0]!r} in the files "
                 "(any unit of mudoe.units.UNITS; converted once to the model's)\n"
                 "# output_unit = \"\"           # unit of the readings in the files (default: the model's); "
                 "per sensor: unit = \"...\"")
        layout = "tidy"
    parts = [_HEAD.format(name=name, layout=layout, units=units)]
    for s, u in sensors:
        parts.append(f'[[sensors]]\nname = "{s}"\nsigma = 1.0                     # standard deviation of a reading'
                     f'{" (" + u + ")" if u else ""}; or sigma_man\n' + (f'unit = "{u}"\n' if u else ""))
    for n, start, lo, up, u in params:
        parts.append(f'[[parameters]]\nname = "{n}"\nstart = {_num(start)}               # start value of the fit'
                     f'\nlower = {_num(lo)}\nupper = {_num(up)}\n' + (f'unit = "{u}"\n' if u else ""))
    return "\n".join(parts) + _TAIL.format()


def write_template(path, model_name: str | None = None) -> Path:
    """Write :func:`template_text` to ``path`` (a new file).

    Raises
    ------
    ConfigError
        ``path`` exists (never overwritten), or the factory cannot be loaded or returns no Model.
    """
    path = Path(path)
    if path.exists():
        raise ConfigError(f"{path}: exists; mudoe init never overwrites a file, choose a new name")
    if model_name is None:
        text = template_text()
    else:
        factory = load_factory(model_name, "--model")
        model = call_factory(factory, model_name, "default", lambda msg: ConfigError(f"--model: {msg}"))
        if getattr(model, "is_dynamic", False):      # an ODE/DAE model: a [dynamic] study
            from .dynamic_template import dynamic_template_text
            text = dynamic_template_text(model, model_name)
        elif not isinstance(model, Model):
            raise ConfigError(f"--model: {model_name}('default') returned {type(model).__name__}, expected a "
                              "models.Model")
        else:
            text = template_text(model, model_name)
    if not path.parent.is_dir():
        raise ConfigError(f"{path}: the folder {path.parent} does not exist; create it or choose another path")
    try:
        return create_text(path, text)
    except FileExistsError:
        raise ConfigError(f"{path}: exists (written meanwhile by another process); mudoe init never overwrites "
                          "a file, choose a new name") from None
