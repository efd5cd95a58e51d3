"""The README's two-bar truss ("Add your own model") as an importable model factory.

Bars of stiffness k1, k2 (N/mm) from the walls A (0, 0) and B (800, 0) mm to the hook P
(300, -400) mm, loaded by F (N) downwards.  :func:`build` has both sensors P_x, P_y (mm), as
in the README; :func:`build_one_sensor` measures P_x only -- the study
``configs/truss_one_sensor.toml``, where k1 and k2 are only weakly identified and the
linearised ellipse is a poor picture of the uncertainty (issue 12).
"""
from __future__ import annotations

from models.contract import Model

__all__ = ["build", "build_one_sensor"]


def _truss(variant: str, sensors: tuple) -> Model:
    from models.library import two_bar_truss
    return two_bar_truss(name=f"truss {variant}", sensors=sensors)


def build(variant: str = "linear") -> Model:
    """The README truss with both sensors P_x, P_y (mm; unknowns k1, k2 in N/mm)."""
    return _truss(variant, ("P_x", "P_y"))


def build_one_sensor(variant: str = "linear") -> Model:
    """The README truss measured with the horizontal displacement P_x of the hook only."""
    return _truss(variant, ("P_x",))
