"""Plausibility of the readings of a campaign: a reading absurd for its sensor is refused.

A reading z_ijk is absurd when it lies more than :data:`ABSURD_RATIO` robust spreads from its
sensor's median, |z_ijk - med_k| > ABSURD_RATIO * s_k, with s_k the median absolute deviation of
the sensor's finite readings (all series, all inputs), or the median |z| when the MAD is 0.  With
ABSURD_RATIO = 1e6 no measured signal is refused (a load curve from 0 to its maximum lies within 2
MADs of its median, Gaussian noise within ~5, an exponential decay over five decades 3e2, over ten
decades 9e4); a unit or export error is (the issue's 1e14 um press reading among readings of
~700 um is 2.8e11 MADs away and made the fitted sigma 7.6e9 mm; an 800 m one, 2e6).
Refusing it (exit 2, naming file, series, set point and value) is the choice here: a warning would
still let every estimate and test of the run rest on that reading.
"""
from __future__ import annotations

import numpy as np

__all__ = ["ABSURD_RATIO", "absurd_reading", "absurd_reading_message"]

#: robust spreads (MADs) beyond which a reading is refused
ABSURD_RATIO = 1e6


def absurd_reading(z) -> tuple | None:
    """(series i, input j, sensor k, ratio) of the reading of ``z`` (n_M, n_q, n_S) farthest beyond
    ABSURD_RATIO robust spreads of its sensor, or None when every reading is plausible."""
    z = np.asarray(z, float)
    worst = None
    for k in range(z.shape[2]):
        v = z[:, :, k]
        ok = np.isfinite(v)
        if ok.sum() < 3:
            continue
        med = float(np.median(v[ok]))
        dev = np.abs(v - med)
        scale = float(np.median(dev[ok]))
        if scale == 0.0:
            scale = float(np.median(np.abs(v[ok])))
        if scale == 0.0:
            continue
        ratio = np.where(ok, dev / scale, 0.0)
        i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        if ratio[i, j] > ABSURD_RATIO and (worst is None or ratio[i, j] > worst[3]):
            worst = (int(i), int(j), k, float(ratio[i, j]))
    return worst


def absurd_reading_message(campaign, units, where: str) -> str:
    """The error text of the absurd reading of ``campaign`` ("" when none): file, series, set point,
    value in the file's unit and the sensor's median, and what to do."""
    found = absurd_reading(campaign.z)
    if found is None:
        return ""
    i, j, k, ratio = found
    sensor = campaign.sensors[k]
    z_file = units.z_to_file(campaign.z)[:, :, k]
    unit = units.output_file[k]
    v = z_file[i, j]
    med = float(np.median(z_file[np.isfinite(z_file)]))
    files = campaign.files
    path = files[k] if len(files) >= len(campaign.sensors) else (files[0] if files else where)
    return (f"{path}: sensor {sensor!r}, series {campaign.series[i]!r}, set point {j + 1}: reading {v:g} {unit} is "
            f"{ratio:.2g} robust spreads from the sensor's median {med:g} {unit} (more than {ABSURD_RATIO:g}): "
            "a unit or export error? Fix the value or its declared unit, or mark it missing (empty cell or NaN)")
