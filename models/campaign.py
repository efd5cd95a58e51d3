"""The one campaign type: repeated series of sensor readings at a sequence of set-point forces.

A :class:`Campaign` is a plain data container in the model's units (forces in N, readings
in mm).  The virtual prototype (:func:`models.prototype.generate_campaign`) and the CSV
readers (:mod:`mudoe.data_io`) both return it; turning it into identification data is the
study's task (:func:`mudoe.press.campaign_measurements`, :func:`mudoe.study.prepare`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Campaign"]


@dataclass(frozen=True, eq=False)
class Campaign:
    """Readings z_ijk (mm) of sensor k in series i at set point j with force q_j (N).

    Attributes
    ----------
    q_set : ndarray (n_q,)                  set-point forces (N)
    q_actual : ndarray (n_M, n_q) or None   actual forces (N) when the data carry them
    z : ndarray (n_M, n_q, n_S)             readings (mm), NaN = missing, force-corrected if asked
    sensors : tuple of str                  sensor names (order of the last axis of z)
    series : tuple of str                   series labels; default ``series_1`` ... ``series_<n_M>``
    files : tuple of str                    files read (empty for the prototype)
    source : str                            one-line description
    sha256 : str                            hash of the files (or of the arrays for the prototype)
    notes : tuple of str                    what was done to the data (e.g. a force correction)
    z_raw : ndarray (n_M, n_q, n_S) or None readings before the force correction (mm), prototype only
    seed : int or None                      seed of a simulated campaign
    config : dict                           the prototype configuration used (for the record)
    """

    q_set: np.ndarray
    q_actual: np.ndarray | None
    z: np.ndarray
    sensors: tuple
    series: tuple = ()
    files: tuple = ()
    source: str = ""
    sha256: str = ""
    notes: tuple = ()
    z_raw: np.ndarray | None = None
    seed: int | None = None
    config: dict = field(default_factory=dict)

    def __post_init__(self):
        if not self.series:
            object.__setattr__(self, "series", tuple(f"series_{i + 1}" for i in range(self.n_M)))

    @property
    def n_M(self) -> int:
        """Number of series."""
        return self.z.shape[0]

    @property
    def n_q(self) -> int:
        """Number of set points."""
        return self.z.shape[1]
