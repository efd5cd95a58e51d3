r"""A planar stand-in for one linkage of the 3D Servo Press (geometry in docs/press_geometry.md).

Quasi-static state equation (see :mod:`models.mechanism`)

.. math::

    E(y, p, q) = \nabla_y U(y; k_5, k_7) - e_{R_y} \, (q_P - q_\mathrm{fric}(q)) = 0
    \qquad [\mathrm{N},\ \mathrm{N\,mm}],

with y in R^34 (mm, rad): 10 joints x 2 + 2 anchors x 2 + 3 lever rotations +
2 rigid bodies x 3 + 1 drive coordinate.  Unknown parameters: the axial stiffnesses
k5 (upper spindle E0-E) and k7 (lower spindle F0-F) in N/mm.  Input: the process force
q_P (N) acting vertically at the ram bearing R; **positive q_P pushes R upwards**
(the reaction of the part on the ram while pressing), so the ram, the lever point D
and the pressure bar move up.  Outputs: joint displacements in mm (multiply by 1000
for micrometres): D_y, F_x, B0_y (the paper's three sensors, in this order) and, with
``extra_sensors=True``, every other joint displacement direction.

Geometry changes against the design-doc guess (/work/shared/design/press_linkage.md),
made so that the sensor pairs behave as in the paper's OED table (pairs (D_y, F_x) and
(F_x, B0_y) identify (k5, k7), (D_y, B0_y) is near-singular): the upper spindle nut E
is lowered to the fulcrum height (y = 400 mm) and guided horizontally in the frame
(``carrier_guide``), the lower spindle moves to x = -80 mm, and the guide-link pivot
B0 moves to (-330, 220) so that the line B0-G passes through the fulcrum C.  Every
force reaching the spindle carrier from outside (lever at C, guide link at G, guide
at E) then acts on a line through C, so moment balance about C fixes the ratio of the
spindle forces N5 : N7 = (x_F - x_C) : (x_C - x_E) for every load that does not act on
the carrier itself: D_y and B0_y (and R_y) see (k5, k7) through one combination only,
in the linear regime exactly, at 1.6 kN separated only by geometric nonlinearity.
A horizontal force at F (the adjoint load of F_x) acts below C and brings a second
combination.  The guide link makes the carrier statically indeterminate, so B0_y
does depend on k5 and k7 (with a statically determinate carrier it would not).
Details and numbers: docs/press_geometry.md.
"""
from __future__ import annotations

from itertools import combinations
from types import MappingProxyType
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from .contract import Model
from .mechanism import (Bar, Beam, Drive, Joint, Load, MechParameter, Mechanism, MechanismError,
                        RigidBody, Support, build_model)

__all__ = ["press_mechanism", "press_model", "press_identifiability", "press_cycle_rows", "press_scenario_rows",
           "PRESS_SENSORS", "PRESS_JOINTS", "PRESS_ANCHORS", "K_NOMINAL", "Q_PAPER", "PRESS_LOADING_ROWS",
           "PRESS_UNLOADING_ROWS", "PRESS_SCENARIO_NAMES", "PRESS_SCENARIOS"]

#: the paper's 29 set points: 15 loading steps 0..1600 N, 14 unloading steps back to 0 N
Q_PAPER = tuple(float(v) for v in np.r_[np.linspace(0.0, 1600.0, 15), np.linspace(1600.0, 0.0, 15)[1:]])

#: names of the paper's four test scenarios, in the order of its Table "Testsets"
PRESS_SCENARIO_NAMES = ("loading: odd vs even", "unloading: odd vs even", "loading vs unloading",
                        "loading+unloading interleaved")

#: the paper's three candidate sensors, in the paper's order
PRESS_SENSORS = ("D_y", "F_x", "B0_y")

#: nominal (k5, k7) in N/mm
K_NOMINAL = (500.0, 500.0)

#: joint coordinates in mm (y up); anchors E0, F0 are frame points, not joints
PRESS_JOINTS = {
    "A0": (150.0, 650.0),     # eccentric bearing on the frame
    "A": (153.5, 630.3),      # eccentric pin (eccentricity 20 mm, angle -80 deg)
    "B": (150.0, 400.0),      # lever input
    "C": (-150.0, 400.0),     # lever fulcrum on the spindle carrier
    "D": (0.0, 400.0),        # gear-unit output
    "R": (-40.0, 85.0),       # ram bearing: process force acts here, vertically
    "E": (-210.0, 400.0),     # upper spindle nut, guided horizontally (design doc: y = 460)
    "F": (-80.0, 340.0),      # lower spindle nut (design doc: x = -90)
    "G": (-210.0, 340.0),     # guide-link joint
    "B0": (-330.0, 220.0),    # guide-link pivot on the frame (line B0-G passes through C; design doc: y = 250)
}
PRESS_ANCHORS = {"E0": (-210.0, 720.0), "F0": (-80.0, 20.0)}   # F0 design doc: x = -90


def press_mechanism(k5: float = K_NOMINAL[0], k7: float = K_NOMINAL[1]) -> Mechanism:
    """The press linkage spec (nominal k5, k7 in N/mm; values documented in docs/press_geometry.md)."""
    joints = [Joint(n, x, y) for n, (x, y) in PRESS_JOINTS.items()]
    joints += [Joint(n, x, y, anchor=True) for n, (x, y) in PRESS_ANCHORS.items()]
    k_bearing = 5000.0
    elements = [
        # 1 eccentric (rigid body) with its drive
        RigidBody("ecc", ("A0", "A"), bearing=k_bearing),
        Drive("drive", "ecc", k_shaft=2.0e6, k_hold=2.0e7),
        # 2 spindle carrier (rigid body)
        RigidBody("carrier", ("C", "E", "F", "G"), bearing=k_bearing),
        # 3 lever: beam C-D-B (two elements)
        Beam("lever", ("C", "D", "B"), EA=5.6e7, EI=7.5e9),
        # bars 4-8
        Bar("4", "A", "B", 5000.0),       # connecting rod
        Bar("5", "E0", "E", "k5"),        # upper spindle (unknown)
        Bar("6", "G", "B0", 5000.0),      # guide link
        Bar("7", "F0", "F", "k7"),        # lower spindle (unknown)
        Bar("8", "D", "R", 10000.0),      # pressure bar
        # frame elasticity
        Support("frame_A0", "A0", kx=1000.0, ky=600.0),
        Support("frame_B0", "B0", kx=5000.0, ky=5000.0),
        Support("frame_E0", "E0", kx=3000.0, ky=800.0),
        Support("frame_F0", "F0", kx=3000.0, ky=800.0),
        Support("ram_guide", "R", kx=3000.0),
        Support("carrier_guide", "E", kx=5000.0),
        # process force
        Load("process", "R", fy=1.0, input="q_P"),
    ]
    params = [MechParameter("k5", float(k5), 1e-6, 1e6, 500.0, "N/mm"),
              MechParameter("k7", float(k7), 1e-6, 1e6, 500.0, "N/mm")]
    return Mechanism("press_linkage", joints, elements, params, inputs=("q_P",), sensors=PRESS_SENSORS)


def press_model(extra_sensors: bool = False, friction=None, k5: float = K_NOMINAL[0],
                k7: float = K_NOMINAL[1]) -> Model:
    """The press :class:`models.Model` with parameters (k5, k7) and input q_P.

    Parameters
    ----------
    extra_sensors : bool
        Add every other joint displacement direction after D_y, F_x, B0_y (20 in all;
        the frame anchors E0, F0 are not joints and are left out).
    friction : object, optional
        A friction model with ``input_names`` (extra input columns after q_P) and
        ``force(qvec)`` returning a CasADi scalar q_fric (N) from the full input vector
        ``qvec = [q_P, *input_names]``; the vertical force at R becomes q_P - q_fric.  Its optional
        ``input_units`` label those columns (default N; "" for a dimensionless sign such as M2's ``dir``).
    k5, k7 : float
        Nominal values (the model's ``p_nominal``), N/mm.
    """
    mech = press_mechanism(k5, k7)
    sensors = list(PRESS_SENSORS)
    if extra_sensors:
        sensors += [s for s in mech.all_sensors() if s not in sensors]
    inputs: Sequence[str] = ("q_P",)
    units: Sequence[str] = ("N",)
    input_map = None
    if friction is not None:
        names = tuple(getattr(friction, "input_names", ()))
        if not callable(getattr(friction, "force", None)):
            raise MechanismError(f"friction {friction!r}: needs a method force(qvec) -> casadi scalar")
        if "q_P" in names:
            raise MechanismError(f"friction {friction!r}: input_names must not repeat 'q_P'")
        inputs = ("q_P",) + names
        units = ("N",) + tuple(getattr(friction, "input_units", ("N",) * len(names)))

        def input_map(qd, qvec):
            return {"q_P": qd["q_P"] - friction.force(qvec)}
    return build_model(mech, sensors=sensors, unknowns=("k5", "k7"), inputs=inputs, input_map=input_map,
                       input_units=units,
                       name="press_linkage" if friction is None else f"press_linkage+{type(friction).__name__}")


def press_identifiability(q_P: float = 1600.0, sensors: Sequence[str] = PRESS_SENSORS,
                          k5: float = K_NOMINAL[0], k7: float = K_NOMINAL[1]) -> dict:
    r"""Compliances and (k5, k7)-sensitivities of the press sensors, per sensor pair.

    Linear regime: c_s = dh_s/dq_P (mm/N) and S_s = d c_s / d(k5, k7) at y = 0.  At the
    load q_P (N): the implicit-function sensitivity dh/dp = h_p - h_y E_y^{-1} E_p of the
    solved state (mm per N/mm).  For each sensor pair the singular values of the 2x2
    sensitivity (scaled by the parameter scale 500 N/mm) and their ratio (0 = the pair
    cannot separate k5 from k7).

    Returns
    -------
    dict with keys ``sensors``, ``compliance`` (mm/kN), ``S_lin`` (mm/kN per 500 N/mm),
    ``S_load`` (mm per 500 N/mm at q_P), ``h_load`` (mm), ``pairs`` {(a, b): dict(sv_lin,
    ratio_lin, sv_load, ratio_load)}.
    """
    from .mechanism import linear_analysis, solve_path
    model = press_model(extra_sensors=True, k5=k5, k7=k7)
    idx = model.sensor_index(sensors)
    p = model.p_nominal
    c, S = linear_analysis(model, p)
    qs = np.linspace(0.0, q_P, 9)[1:, None]
    y = solve_path(model, p, qs)[-1]
    ys, ps, qq = ca.SX.sym("y", model.n_y), ca.SX.sym("p", model.n_p), ca.SX.sym("q", model.n_q_dim)
    E, h = model.E_fun(ys, ps, qq), model.h_fun(ys, ps, qq)
    f = ca.Function("f", [ys, ps, qq], [ca.jacobian(E, ys), ca.jacobian(E, ps), ca.jacobian(h, ys),
                                         ca.jacobian(h, ps), h])
    Ey, Ep, hy, hp, hv = (np.array(a) for a in f(y, p, [q_P]))
    Sq = hp - hy @ np.linalg.solve(Ey, Ep)
    scale = np.array([pp.scale for pp in model.params])
    S_lin = S[idx] * scale * 1e3
    S_load = Sq[idx] * scale
    pairs = {}
    for a, b in combinations(range(len(idx)), 2):
        sl = np.linalg.svd(S_lin[[a, b]], compute_uv=False)
        sq = np.linalg.svd(S_load[[a, b]], compute_uv=False)
        pairs[(sensors[a], sensors[b])] = dict(sv_lin=sl, ratio_lin=sl[1] / sl[0], sv_load=sq,
                                              ratio_load=sq[1] / sq[0])
    return dict(sensors=tuple(sensors), compliance=c[idx] * 1e3, S_lin=S_lin, S_load=S_load,
                h_load=hv.ravel()[idx], pairs=pairs, q_P=q_P)


# ---------------------------------------------------------------------------- test scenarios (Algorithm 1, line 06)
def press_cycle_rows(n_q: int = len(Q_PAPER), peak: int | None = None) -> tuple[tuple, tuple]:
    """0-based input rows of the loading branch (0..peak, rising force) and of the unloading branch
    (peak..n_q-1, falling force) of a load cycle of n_q set points; the peak row is in both.

    Raises
    ------
    ValueError
        n_q even without ``peak`` (no middle peak), or fewer than 3 loading and 3 unloading points
        besides the unloaded ends (the message names n_q and peak).
    """
    n_q = int(n_q)
    if peak is None:
        if n_q % 2 == 0:
            raise ValueError(f"n_q: the paper's scenarios need an odd number of loads (rise, peak, fall), got {n_q}; "
                             "give peak= explicitly")
        peak = (n_q - 1) // 2
    peak = int(peak)
    if n_q < 7 or not (3 <= peak <= n_q - 4):
        raise ValueError(f"n_q, peak: need at least 3 loading and 3 unloading points besides the unloaded ends, got "
                         f"n_q = {n_q}, peak = {peak}")
    return tuple(range(0, peak + 1)), tuple(range(peak, n_q))


def press_scenario_rows(n_q: int = len(Q_PAPER), peak: int | None = None) -> Mapping:
    """The paper's four test scenarios (Table "Testsets") on a load cycle of n_q set points, 0-based.

    Returns {name: (calibration rows, validation rows, description)} in the paper's order
    (:data:`PRESS_SCENARIO_NAMES`); the unloaded first and last points are never used.  For
    n_q = 29 (peak row 14, q^d_15 = 1600 N):

    ========================= ======================== ========================
    scenario                  calibration (paper)      validation (paper)
    ========================= ======================== ========================
    loading: odd vs even      q2, q4, .., q14          q3, q5, .., q15
    unloading: odd vs even    q15, q17, .., q27        q16, q18, .., q28
    loading vs unloading      q2 .. q14                q15 .. q28
    loading+unloading         q3, q5, .., q27          q2, q4, .., q28
    ========================= ======================== ========================

    Build the splits with ``identification.studies.splits.splits_from_scenarios(press_scenario_rows, n_q)``.

    Raises
    ------
    ValueError
        As :func:`press_cycle_rows`.
    """
    loading, unloading = press_cycle_rows(n_q, peak)
    peak, n_q = loading[-1], unloading[-1] + 1
    rows = (
        (tuple(range(1, peak, 2)), tuple(range(2, peak + 1, 2)),
         "loading branch: calibration on the odd, validation on the even paper indices"),
        (tuple(range(peak, n_q - 2, 2)), tuple(range(peak + 1, n_q - 1, 2)),
         "unloading branch (from the peak): alternate points"),
        (tuple(range(1, peak)), tuple(range(peak, n_q - 1)),
         "calibrate on loading, validate on unloading (hysteresis)"),
        (tuple(range(2, n_q - 1, 2)), tuple(range(1, n_q - 1, 2)), "both branches, alternate points"),
    )
    return MappingProxyType(dict(zip(PRESS_SCENARIO_NAMES, rows)))


#: 0-based rows of :data:`Q_PAPER` on the loading branch (0 .. 1600 N) and on the unloading branch (1600 .. 0 N)
PRESS_LOADING_ROWS, PRESS_UNLOADING_ROWS = press_cycle_rows()

#: the paper's four scenarios on :data:`Q_PAPER`: {name: (calibration rows, validation rows, description)}
PRESS_SCENARIOS = press_scenario_rows()
