"""``mudoe init --model`` for a dynamic (ODE/DAE) factory: a study config with a [dynamic] section.

The template lists the model's parameters, instruments (one sigma each, not one per time) and
experiment inputs (constants, and each control's values at its grid points), sampling times over the
horizon and the splits of a dynamic study; `mudoe simulate` then writes its data.
"""
from __future__ import annotations

import math

__all__ = ["dynamic_template_text"]

_TAIL = """
[simulate]                      # `mudoe simulate CONFIG --out data`: a campaign from the model itself
# truth = {{}}                  # true parameters (default: the start values above)
n_series = 2                    # repeated series (the normality gate differences them); noise: the sigmas
seed = 1

[splits]
scenarios = []                  # the paper's press scenarios do not apply
early_late = true               # readings before the median sampling time against the later ones
# time_windows = [{mid}]        # one split per time e: t < e against t >= e
{custom}
[detect]
tol = 0.05                      # family-wise level
sensors = "all"                 # the instruments used by the tests (each at every sampling time)

[oed]
criterion = "D"                 # A | D | E of the sampling-time design

[validate]
n_runs = 50

[report]
title = "Model uncertainty study"
"""


def _num(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else ("inf" if v > 0 else "-inf")


_CUSTOM = """[[splits.custom]]               # experiments (0-based) against experiments
name = "first vs second experiment"
cal_inputs = [0]
val_inputs = [1]
"""
#: a model without inputs: one run, so no split by experiment (a repeated run is one more empty table)
_NO_CUSTOM = """# [[splits.custom]]             # with repeated runs (more empty [[dynamic.experiments]] tables):
# name = "first vs second run"  # experiments (0-based) against experiments
# cal_inputs = [0]
# val_inputs = [1]
"""


def _experiment(model, scale: float) -> str:
    if not model.inputs:
        return ("[[dynamic.experiments]]             # the model has no inputs: one empty table per run "
                "(repeat it for repeated runs)")
    units = list(model.input_units) + [""] * len(model.inputs)
    lines = ["[[dynamic.experiments]]             # EDIT: the inputs of each experiment (model units)"]
    for k, n in enumerate(model.constants):
        lines.append(f"{n} = {scale:g}" + (f"                  # {units[k]}" if units[k] else ""))
    for c in model.controls:
        vals = ", ".join(f"{scale:g}" for _ in c.grid)
        lines.append(f"{c.name} = [{vals}]   # one value per grid point {', '.join(f'{g:g}' for g in c.grid)}"
                     + (f" ({c.unit})" if getattr(c, "unit", "") else ""))
    return "\n".join(lines)


def dynamic_template_text(model, name: str) -> str:
    """The commented TOML template of a dynamic model (see the module docstring)."""
    horizon = model.horizon or 1.0
    times = [round(horizon * k / 10, 10) for k in range(1, 11)]
    unit = f" ({model.time_unit})" if model.time_unit else ""
    parts = [f"""\
# mudoe study config (TOML) of a dynamic model.  README "Config reference" lists every key.
# Indices (series, experiments) are 0-based.  Paths are relative to this file.

[model]
name = "{name}"   # your factory: function(variant) -> models.Model.ode(...)
variants = ["default"]

[data]
source = "csv"
layout = "tidy"
directory = "data"              # `mudoe simulate CONFIG --out data` writes the file
file = "campaign_long.csv"      # long format: series, experiment, time, sensor, value, unit

[dynamic]
times = [{', '.join(f'{t:g}' for t in times)}]   # sampling times{unit}
# candidate_times = [...]       # candidates of the sampling-time design (default: times)
# n_times = {model.n_p}                   # sampling times chosen (default: one per parameter)
# pairs = false                 # choose (time, instrument) pairs instead
{_experiment(model, 1.0)}
""" + (f"{_experiment(model, 2.0)}\n" if model.inputs else "")]
    for s, u in zip(model.sensors, model.sensor_units):
        parts.append(f'[[sensors]]\nname = "{s}"\nsigma = 0.01                    # one per instrument'
                     f'{" (" + u + ")" if u else ""}, not per time\n' + (f'unit = "{u}"\n' if u else ""))
    for p in model.params:
        start = p.scale or ((p.lower + p.upper) / 2 if math.isfinite(p.lower) and math.isfinite(p.upper) else 1.0)
        unit = f'unit = "{p.unit}"\n' if p.unit else ""
        parts.append(f'[[parameters]]\nname = "{p.name}"\nstart = {_num(start)}               # start value'
                     f'\nlower = {_num(p.lower)}\nupper = {_num(p.upper)}\n' + unit)
    return "\n".join(parts) + _TAIL.format(mid=f"{times[len(times) // 2]:g}",
                                          custom=_CUSTOM if model.inputs else _NO_CUSTOM)
