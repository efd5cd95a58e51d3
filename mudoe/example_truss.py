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
    from models.mechanism import Bar, Joint, Load, MechParameter, Mechanism, Support, build_model
    mech = Mechanism(
        "two_bar_truss",
        joints=[Joint("A", 0.0, 0.0), Joint("B", 800.0, 0.0), Joint("P", 300.0, -400.0)],
        elements=[Bar("1", "A", "P", "k1"), Bar("2", "B", "P", "k2"),
                  Support("wall_A", "A", kx=1e6, ky=1e6), Support("wall_B", "B", kx=1e6, ky=1e6),
                  Load("hook", "P", fy=-1.0, input="F")],
        parameters=[MechParameter("k1", 200.0, 1.0, 1e5, 200.0, "N/mm"),
                    MechParameter("k2", 300.0, 1.0, 1e5, 300.0, "N/mm")],
        inputs=("F",), sensors=sensors)
    return build_model(mech, unknowns=("k1", "k2"), name=f"truss {variant}")


def build(variant: str = "linear") -> Model:
    """The README truss with both sensors P_x, P_y (mm; unknowns k1, k2 in N/mm)."""
    return _truss(variant, ("P_x", "P_y"))


def build_one_sensor(variant: str = "linear") -> Model:
    """The README truss measured with the horizontal displacement P_x of the hook only."""
    return _truss(variant, ("P_x",))
