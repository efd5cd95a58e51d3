r"""Planar lumped-parameter mechanisms: a declarative spec and its quasi-static model.

A mechanism is held in its undeformed reference configuration (joint coordinates in
mm).  The builder forms the total potential energy symbolically in CasADi,

.. math::

    U(y; p) = \sum_{\text{bars}} U_\text{bar} + \sum_{\text{beams}} U_\text{beam}
            + \sum_{\text{bearings}} U_\text{bearing} + \sum_{\text{supports}} U_\text{support}
            + \sum_{\text{drives}} U_\text{drive} + \sum_{\text{masses}} m g_0 u_y,

and the quasi-static state equation by algorithmic differentiation,

.. math::

    E(y, p, q) = \nabla_y U(y; p) - Q(q) = 0      \quad [\mathrm{N}\ \text{or}\ \mathrm{N\,mm}],

with y the displacements from the reference configuration (mm, rad) and Q the
generalized external forces (N).  Units throughout: mm, N, N/mm, N mm/rad, N mm^2.

State layout
------------
* every joint (and every anchor) is a *pin node* with two translations ``J.x``, ``J.y``
  (mm).  Bars end on pin nodes; beam nodes share the translations of their pin nodes;
* every beam gets one rotation per node ``<beam>.rot[J]`` (rad): beams meeting at a
  joint are hinged there;
* every rigid body has three coordinates ``<body>.x``, ``<body>.y``, ``<body>.rot``
  (translation of the centroid of its joints, mm, and rotation, rad); the body's own
  material point at joint J is tied to the pin node J by a radial *bearing spring*;
  so a joint shared by several bodies has one pin node and one bearing per body;
* every drive adds one coordinate ``<drive>.phi`` (rad) tied to its body's rotation
  by a torsion spring ``k_shaft`` and to the frame by a holding stiffness ``k_hold``.

Element energies (reference length L0, reference chord c0 = X_j - X_i, relative
displacement du = u_j - u_i):

* bar (geometrically exact):  U = k/2 xi^2,
  xi = ||c0 + du|| - L0 = (2 c0.du + du.du) / (||c0 + du|| + L0)   (no cancellation);
* beam element (co-rotational Euler-Bernoulli): with the chord rotation
  rho = atan2(c0 x du, L0^2 + c0.du) and local end rotations t_i = theta_i - rho,
  t_j = theta_j - rho,
  U = k_alpha/2 xi^2 + (EI/L0) (2 t_i^2 + 2 t_i t_j + 2 t_j^2),   k_alpha = EA/L0.
  Its linearisation is the consistent 6x6 element stiffness in local coordinates
  (u_i, v_i, theta_i, u_j, v_j, theta_j) with k_beta = 12 EI / L0^3::

      [ ka   0         0            -ka   0          0          ]
      [ 0    kb        kb L/2        0   -kb         kb L/2     ]
      [ 0    kb L/2    kb L^2/3      0   -kb L/2     kb L^2/6   ]
      [-ka   0         0             ka   0          0          ]
      [ 0   -kb       -kb L/2        0    kb        -kb L/2     ]
      [ 0    kb L/2    kb L^2/6      0   -kb L/2     kb L^2/3   ]

  (the paper prints the pattern with k_beta l and k_beta l^2 throughout; the
  consistent Euler-Bernoulli factors are 1/2, 1/3 and 1/6 as above, i.e. 12EI/l^3,
  6EI/l^2, 4EI/l, 2EI/l);
* bearing:  U = k/2 ||d||^2 with d the gap vector between the body point and the pin
  node, or, with a clearance-like smooth characteristic of width g (mm),
  U = k (d^2/2 - g^2 log cosh(d/g)) + r k d^2/2, radial force
  F = k (d - g tanh(d/g)) + r k d (r = ``RigidBody.gap_residual``, default 0);
* support (frame elasticity):  U = kx/2 u_x^2 + ky/2 u_y^2 (either may be absent);
  a beam node may also have a rotational spring to the frame, U = k_r/2 theta^2;
* drive:  U = k_shaft/2 (theta_body - phi)^2 + k_hold/2 phi^2;
* load:  potential -F.u with F = (fx, fy) * q[input] (or constant without input);
* mass:  m g0 u_y with g0 = ``Mechanism.gravity`` in N/kg (0 switches gravity off).

Any stiffness may be a number or the name of a declared :class:`MechParameter`;
those listed as unknowns become the model parameters p, the others take their
nominal value.  Sensors are pin-node displacement directions named ``J_x``/``J_y`` (mm).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from .contract import Model, Parameter
from .errors import StateSolveError
from .state import solve_state

__all__ = [
    "MechanismError", "Joint", "MechParameter", "Bar", "Beam", "RigidBody", "Support",
    "Drive", "Load", "Mass", "Mechanism", "Assembly", "assemble", "build_model",
    "load_toml", "mechanism_from_dict", "solve_path", "linear_analysis",
]

Number = float | int | str


class MechanismError(ValueError):
    """A mechanism spec is inconsistent; the message names the offending element."""


# ---------------------------------------------------------------------------- spec
@dataclass(frozen=True)
class Joint:
    """A pin node at (x, y) mm.  ``anchor=True`` marks a frame anchor (documentation only)."""

    name: str
    x: float
    y: float
    anchor: bool = False


@dataclass(frozen=True)
class MechParameter:
    """A named stiffness (or other) value; may be declared unknown when building a model.

    ``nominal`` is the value used when the parameter is not an unknown and for the
    reference-state checks; ``lower``/``upper``/``scale``/``unit`` go to
    :class:`models.Parameter`.
    """

    name: str
    nominal: float
    lower: float = -math.inf
    upper: float = math.inf
    scale: float | None = None
    unit: str = ""

    def to_parameter(self) -> Parameter:
        return Parameter(self.name, self.lower, self.upper, self.scale, self.unit)


@dataclass(frozen=True)
class Bar:
    """Two-node axial spring between pin nodes ``i`` and ``j``; stiffness ``k`` in N/mm."""

    name: str
    i: str
    j: str
    k: Number


@dataclass(frozen=True)
class Beam:
    """Multi-node Euler-Bernoulli beam through pin nodes ``nodes`` (one element per span).

    ``EA`` in N, ``EI`` in N mm^2 (numbers or parameter names), same for all spans.
    ``rot_supports`` maps beam nodes to a rotational spring to the frame (N mm/rad),
    e.g. a clamp: U = k_r/2 theta^2.
    """

    name: str
    nodes: tuple[str, ...]
    EA: Number
    EI: Number
    rot_supports: Mapping[str, Number] = field(default_factory=dict)


@dataclass(frozen=True)
class RigidBody:
    """A rigid body carrying the joints ``joints``; ``bearing`` radial stiffness (N/mm).

    ``bearings`` overrides the stiffness per joint; ``gap`` (mm, per joint) switches that
    bearing to the smooth clearance characteristic F = k (d - g tanh(d/g)) + r k d with
    r = ``gap_residual`` (default 0).  The clearance characteristic has zero stiffness
    at d = 0; where no other element holds the joint, give r > 0 (e.g. 1e-3) or the
    reference stiffness check reports the joint as free.
    """

    name: str
    joints: tuple[str, ...]
    bearing: Number
    bearings: Mapping[str, Number] = field(default_factory=dict)
    gap: Mapping[str, float] = field(default_factory=dict)
    gap_residual: float = 0.0


@dataclass(frozen=True)
class Support:
    """Frame elasticity at a pin node: springs ``kx``, ``ky`` (N/mm) to the ground; None = absent."""

    name: str
    joint: str
    kx: Number | None = None
    ky: Number | None = None


@dataclass(frozen=True)
class Drive:
    """A drive coordinate phi (rad): torsion ``k_shaft`` to the body rotation, ``k_hold`` to ground (N mm/rad)."""

    name: str
    body: str
    k_shaft: Number
    k_hold: Number


@dataclass(frozen=True)
class Load:
    """Point force (fx, fy) in N at a pin node, multiplied by input ``input`` if given."""

    name: str
    joint: str
    fx: float = 0.0
    fy: float = 0.0
    input: str | None = None


@dataclass(frozen=True)
class Mass:
    """A lumped mass (kg) at a pin node, weighed when ``Mechanism.gravity`` > 0."""

    name: str
    joint: str
    m: float


@dataclass
class Mechanism:
    """A planar mechanism spec (see the module docstring for the energies).

    Parameters
    ----------
    name : str
    joints : sequence of Joint
    elements : sequence of Bar, Beam, RigidBody, Support, Drive, Load, Mass
    parameters : sequence of MechParameter
    inputs : sequence of str
        Names of the input columns q used by loads.
    sensors : sequence of str
        Default candidate sensors, ``J_x`` or ``J_y``.
    gravity : float
        g0 in N/kg (9.80665) or 0 for no gravity.
    """

    name: str
    joints: Sequence[Joint]
    elements: Sequence[object]
    parameters: Sequence[MechParameter] = ()
    inputs: Sequence[str] = ()
    sensors: Sequence[str] = ()
    gravity: float = 0.0

    # convenience views
    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise MechanismError(f"mechanism {self.name!r}: no joint named {name!r}")

    def of(self, kind) -> list:
        return [e for e in self.elements if isinstance(e, kind)]

    def parameter(self, name: str) -> MechParameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise MechanismError(f"mechanism {self.name!r}: no parameter named {name!r}")

    def all_sensors(self, anchors: bool = False) -> tuple[str, ...]:
        """Every pin-node displacement direction (mm), in joint order; frame anchors only if asked."""
        return tuple(f"{j.name}_{d}" for j in self.joints if anchors or not j.anchor for d in "xy")


_KINDS = {"bar": Bar, "beam": Beam, "body": RigidBody, "support": Support, "drive": Drive,
          "load": Load, "mass": Mass}


# ---------------------------------------------------------------------------- TOML
def mechanism_from_dict(d: Mapping, source: str = "<dict>") -> Mechanism:
    """A :class:`Mechanism` from the nested dict of a TOML document.

    Layout::

        name = "truss"
        inputs = ["P"]
        sensors = ["C_x", "C_y"]
        gravity = 0.0
        [joints]            # name = [x, y] in mm
        A = [0.0, 0.0]
        [anchors]           # same, marked as frame anchors
        [[parameters]]      # name, nominal, lower, upper, scale, unit
        [[elements]]        # kind = bar | beam | body | support | drive | load | mass
        kind = "bar"
        name = "1"
        i = "A"
        j = "C"
        k = 500.0           # or "k1", a parameter name
    """
    def fail(msg):
        raise MechanismError(f"{source}: {msg}")

    if not isinstance(d, Mapping):
        fail("top level must be a table")
    unknown = set(d) - {"name", "joints", "anchors", "parameters", "elements", "inputs", "sensors", "gravity"}
    if unknown:
        fail(f"unknown top-level key(s) {sorted(unknown)}")
    joints = []
    for key, anchor in (("joints", False), ("anchors", True)):
        for jn, xy in dict(d.get(key, {})).items():
            if not (isinstance(xy, (list, tuple)) and len(xy) == 2):
                fail(f"{key}.{jn}: coordinates must be [x, y] in mm, got {xy!r}")
            joints.append(Joint(jn, float(xy[0]), float(xy[1]), anchor))
    params = []
    for k, pd in enumerate(d.get("parameters", [])):
        try:
            params.append(MechParameter(**pd))
        except TypeError as exc:
            fail(f"parameters[{k}] ({pd.get('name', '?')!r}): {exc}")
    elements = []
    for k, ed in enumerate(d.get("elements", [])):
        ed = dict(ed)
        kind = ed.pop("kind", None)
        label = f"elements[{k}] ({ed.get('name', '?')!r})"
        if kind not in _KINDS:
            fail(f"{label}: unknown element kind {kind!r}; known kinds: {', '.join(_KINDS)}")
        ed.setdefault("name", f"{kind}{k}")
        for tup in ("nodes", "joints"):
            if tup in ed:
                ed[tup] = tuple(ed[tup])
        try:
            elements.append(_KINDS[kind](**ed))
        except TypeError as exc:
            fail(f"{label} of kind {kind!r}: {exc}")
    return Mechanism(name=str(d.get("name", Path(source).stem)), joints=joints, elements=elements,
                     parameters=params, inputs=tuple(d.get("inputs", ())),
                     sensors=tuple(d.get("sensors", ())), gravity=float(d.get("gravity", 0.0)))


def load_toml(path) -> Mechanism:
    """Read a mechanism spec from a TOML file (layout in :func:`mechanism_from_dict`)."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise MechanismError(f"{path}: not valid TOML: {exc}") from exc
    return mechanism_from_dict(data, source=str(path))


# ---------------------------------------------------------------------------- energies
def _elongation(c0, du, L0):
    """xi = ||c0 + du|| - L0 without cancellation (mm)."""
    c = c0 + du
    return (2 * ca.dot(c0, du) + ca.dot(du, du)) / (ca.sqrt(ca.dot(c, c)) + L0)


def _chord_rotation(c0, du, L0):
    """Rigid rotation rho (rad) of a chord c0 -> c0 + du."""
    cross = c0[0] * du[1] - c0[1] * du[0]
    return ca.atan2(cross, L0 ** 2 + ca.dot(c0, du))


def _logcosh_energy(s, g):
    """k-free clearance energy d^2/2 - g^2 log cosh(d/g) as a function of s = d^2 (mm^2), AD-safe at 0."""
    x2 = s / g ** 2
    # series of x^2/2 - log cosh x = x^4/12 - x^6/45 + 17 x^8/2520 - 31 x^10/14175
    series = g ** 2 * (x2 ** 2 / 12 - x2 ** 3 / 45 + 17 * x2 ** 4 / 2520 - 31 * x2 ** 5 / 14175)
    x = ca.sqrt(ca.fmax(x2, 1e-4))
    # log cosh x = x + log(1 + exp(-2x)) - log 2 (stable for large x)
    exact = g ** 2 * (x ** 2 / 2 - (x + ca.log1p(ca.exp(-2 * x)) - math.log(2.0)))
    return ca.if_else(x2 < 1e-4, series, exact)


def _rot(theta):
    """R(theta) - I, written without cancellation."""
    s = ca.sin(theta)
    cm1 = -2 * ca.sin(theta / 2) ** 2
    return s, cm1


# ---------------------------------------------------------------------------- assembly
class Assembly:
    """A checked mechanism with its symbolic state, energy and state equation.

    Attributes
    ----------
    mech : Mechanism
    state_names : tuple of str
        Names of the d_y state components (``J.x``, ``beam.rot[J]``, ``body.rot``, ...).
    unknowns : tuple of str
        Parameter names that are model parameters p (in order).
    y, p, q : casadi.SX
        Symbols; q holds ``mech.inputs`` (or the ``inputs`` passed to :func:`assemble`).
    U : casadi.SX
        Potential energy of the elastic elements, supports and masses (N mm).
    Q : casadi.SX
        Generalized external force vector (N).
    E : casadi.SX
        dU/dy - Q.
    """

    def __init__(self, mech, unknowns, inputs, input_map, linear_bearings=False):
        self.mech = mech
        self.unknowns = tuple(unknowns)
        self.inputs = tuple(inputs)
        self._index = {}
        names = []
        for jt in mech.joints:
            for d in "xy":
                self._index[("pin", jt.name, d)] = len(names)
                names.append(f"{jt.name}.{d}")
        for bm in mech.of(Beam):
            for jn in bm.nodes:
                self._index[(bm.name, "rot", jn)] = len(names)
                names.append(f"{bm.name}.rot[{jn}]")
        for bd in mech.of(RigidBody):
            for d in ("x", "y", "rot"):
                self._index[(bd.name, d)] = len(names)
                names.append(f"{bd.name}.{d}")
        for dr in mech.of(Drive):
            self._index[(dr.name, "phi")] = len(names)
            names.append(f"{dr.name}.phi")
        self.state_names = tuple(names)
        n = len(names)
        self.y = ca.SX.sym("y", n)
        self.p = ca.SX.sym("p", len(self.unknowns))
        self.q = ca.SX.sym("q", len(self.inputs))
        pvals = {pp.name: float(pp.nominal) for pp in mech.parameters}
        for k, nm in enumerate(self.unknowns):
            pvals[nm] = self.p[k]
        self._pvals = pvals
        qd = {nm: self.q[k] for k, nm in enumerate(self.inputs)}
        if input_map is not None:
            mapped = dict(input_map(qd, self.q))
            qd.update(mapped)
        self._qeff = qd
        self.U = self._energy(linear_bearings)
        self.Q = self._loads()
        self.E = ca.gradient(self.U, self.y) - self.Q

    @property
    def n_y(self) -> int:
        return len(self.state_names)

    # -- helpers
    def val(self, v, where: str):
        if v is None:
            return 0.0
        if isinstance(v, str):
            if v not in self._pvals:
                raise MechanismError(f"{where}: unknown parameter {v!r}; declared: "
                                     f"{', '.join(self._pvals) or '(none)'}")
            return self._pvals[v]
        return float(v)

    def u(self, joint):
        return ca.vertcat(self.y[self._index[("pin", joint, "x")]], self.y[self._index[("pin", joint, "y")]])

    def X(self, joint):
        jt = self.mech.joint(joint)
        return np.array([jt.x, jt.y])

    def body_point_disp(self, bd, joint):
        """Displacement (mm) of the material point of body ``bd`` at ``joint``."""
        ref = np.mean([self.X(j) for j in bd.joints], axis=0)
        r = self.X(joint) - ref
        t = self.y[self._index[(bd.name, "rot")]]
        s, cm1 = _rot(t)
        ub = ca.vertcat(self.y[self._index[(bd.name, "x")]], self.y[self._index[(bd.name, "y")]])
        return ub + ca.vertcat(cm1 * r[0] - s * r[1], s * r[0] + cm1 * r[1])

    def _energy(self, linear_bearings):
        m = self.mech
        U = ca.SX(0)
        for b in m.of(Bar):
            c0 = self.X(b.j) - self.X(b.i)
            L0 = float(np.linalg.norm(c0))
            xi = _elongation(ca.DM(c0), self.u(b.j) - self.u(b.i), L0)
            U += 0.5 * self.val(b.k, f"bar {b.name!r}") * xi ** 2
        for bm in m.of(Beam):
            EA = self.val(bm.EA, f"beam {bm.name!r} EA")
            EI = self.val(bm.EI, f"beam {bm.name!r} EI")
            for a, b in zip(bm.nodes[:-1], bm.nodes[1:]):
                c0 = self.X(b) - self.X(a)
                L0 = float(np.linalg.norm(c0))
                du = self.u(b) - self.u(a)
                xi = _elongation(ca.DM(c0), du, L0)
                rho = _chord_rotation(ca.DM(c0), du, L0)
                ti = self.y[self._index[(bm.name, "rot", a)]] - rho
                tj = self.y[self._index[(bm.name, "rot", b)]] - rho
                U += 0.5 * EA / L0 * xi ** 2 + EI / L0 * (2 * ti ** 2 + 2 * ti * tj + 2 * tj ** 2)
            for jn, kr in bm.rot_supports.items():
                U += 0.5 * self.val(kr, f"beam {bm.name!r} rot_support at {jn!r}") * \
                    self.y[self._index[(bm.name, "rot", jn)]] ** 2
        for bd in m.of(RigidBody):
            for jn in bd.joints:
                k = self.val(bd.bearings.get(jn, bd.bearing), f"body {bd.name!r} bearing at {jn!r}")
                d = self.body_point_disp(bd, jn) - self.u(jn)
                s = ca.dot(d, d)
                g = bd.gap.get(jn)
                if g is None or linear_bearings:
                    U += 0.5 * k * s
                else:
                    U += k * _logcosh_energy(s, float(g)) + 0.5 * float(bd.gap_residual) * k * s
        for sp in m.of(Support):
            uj = self.u(sp.joint)
            if sp.kx is not None:
                U += 0.5 * self.val(sp.kx, f"support {sp.name!r} kx") * uj[0] ** 2
            if sp.ky is not None:
                U += 0.5 * self.val(sp.ky, f"support {sp.name!r} ky") * uj[1] ** 2
        for dr in m.of(Drive):
            t = self.y[self._index[(dr.body, "rot")]]
            phi = self.y[self._index[(dr.name, "phi")]]
            U += 0.5 * self.val(dr.k_shaft, f"drive {dr.name!r} k_shaft") * (t - phi) ** 2
            U += 0.5 * self.val(dr.k_hold, f"drive {dr.name!r} k_hold") * phi ** 2
        if m.gravity:
            for ms in m.of(Mass):
                U += float(ms.m) * float(m.gravity) * self.u(ms.joint)[1]
        return U

    def _loads(self):
        Q = ca.SX.zeros(self.n_y)
        for ld in self.mech.of(Load):
            scale = 1.0 if ld.input is None else self._qeff[ld.input]
            ix, iy = self._index[("pin", ld.joint, "x")], self._index[("pin", ld.joint, "y")]
            Q[ix] += float(ld.fx) * scale
            Q[iy] += float(ld.fy) * scale
        return Q

    def sensor_expr(self, sensors):
        out = []
        for s in sensors:
            jn, _, d = s.rpartition("_")
            out.append(self.y[self._index[("pin", jn, d)]])
        return ca.vertcat(*out) if out else ca.SX(0, 1)

    def nominal(self) -> np.ndarray:
        """Nominal values of the unknown parameters."""
        return np.array([self.mech.parameter(n).nominal for n in self.unknowns], float)


# ---------------------------------------------------------------------------- checks
def _check_names(mech: Mechanism):
    seen = {}
    for jt in mech.joints:
        if not isinstance(jt.name, str) or not jt.name or "_" in jt.name or "." in jt.name:
            raise MechanismError(f"mechanism {mech.name!r}: joint name {jt.name!r} must be a non-empty "
                                 "string without '_' or '.' (sensor names are <joint>_x / <joint>_y)")
        if jt.name in seen:
            raise MechanismError(f"mechanism {mech.name!r}: joint {jt.name!r} is declared twice")
        if not (np.isfinite(jt.x) and np.isfinite(jt.y)):
            raise MechanismError(f"joint {jt.name!r}: coordinates must be finite, got ({jt.x}, {jt.y})")
        seen[jt.name] = jt
    enames = set()
    for el in mech.elements:
        if type(el) not in _KINDS.values():
            raise MechanismError(f"mechanism {mech.name!r}: unknown element kind {type(el).__name__} "
                                 f"({el!r}); known kinds: {', '.join(_KINDS)}")
        key = (type(el).__name__, el.name)
        if key in enames:
            raise MechanismError(f"mechanism {mech.name!r}: {type(el).__name__.lower()} {el.name!r} is declared twice")
        enames.add(key)
        if isinstance(el, (Beam, RigidBody, Drive)) and el.name in seen:
            raise MechanismError(f"{type(el).__name__.lower()} {el.name!r}: name clashes with a joint "
                                 "(state names would collide)")
    own = [el.name for el in mech.elements if isinstance(el, (Beam, RigidBody, Drive))]
    for n in own:
        if own.count(n) > 1:
            raise MechanismError(f"mechanism {mech.name!r}: beams, bodies and drives share the name {n!r}")
    pn = [p.name for p in mech.parameters]
    for n in pn:
        if pn.count(n) > 1:
            raise MechanismError(f"mechanism {mech.name!r}: parameter {n!r} is declared twice")
    return seen


def check(mech: Mechanism) -> None:
    """Topological and geometric checks of a spec; raise :class:`MechanismError` naming the element."""
    joints = _check_names(mech)

    def need(jn, where):
        if jn not in joints:
            raise MechanismError(f"{where}: refers to joint {jn!r}, which is not declared "
                                 f"(joints: {', '.join(joints)})")

    connected = set()
    for b in mech.of(Bar):
        need(b.i, f"bar {b.name!r}")
        need(b.j, f"bar {b.name!r}")
        L = math.hypot(joints[b.j].x - joints[b.i].x, joints[b.j].y - joints[b.i].y)
        if not L > 1e-9:
            raise MechanismError(f"bar {b.name!r}: zero length between joints {b.i!r} and {b.j!r}")
        connected |= {b.i, b.j}
    for bm in mech.of(Beam):
        if len(bm.nodes) < 2:
            raise MechanismError(f"beam {bm.name!r}: needs at least two nodes, got {list(bm.nodes)}")
        if len(set(bm.nodes)) != len(bm.nodes):
            raise MechanismError(f"beam {bm.name!r}: a node appears twice in {list(bm.nodes)}")
        for jn in bm.nodes:
            need(jn, f"beam {bm.name!r}")
        for a, b in zip(bm.nodes[:-1], bm.nodes[1:]):
            if not math.hypot(joints[b].x - joints[a].x, joints[b].y - joints[a].y) > 1e-9:
                raise MechanismError(f"beam {bm.name!r}: element {a!r}-{b!r} has zero length")
        for jn in bm.rot_supports:
            if jn not in bm.nodes:
                raise MechanismError(f"beam {bm.name!r}: rot_support at {jn!r}, which is not a node of the beam")
        connected |= set(bm.nodes)
    bodies = {}
    for bd in mech.of(RigidBody):
        if not bd.joints:
            raise MechanismError(f"body {bd.name!r}: carries no joints")
        if len(set(bd.joints)) != len(bd.joints):
            raise MechanismError(f"body {bd.name!r}: a joint appears twice in {list(bd.joints)}")
        for jn in bd.joints:
            need(jn, f"body {bd.name!r}")
        for jn in list(bd.bearings) + list(bd.gap):
            if jn not in bd.joints:
                raise MechanismError(f"body {bd.name!r}: bearing data for joint {jn!r}, which the body does not carry")
        for jn, g in bd.gap.items():
            if not (np.isfinite(g) and g > 0):
                raise MechanismError(f"body {bd.name!r}: bearing gap at {jn!r} must be positive, got {g!r}")
        if not (np.isfinite(bd.gap_residual) and bd.gap_residual >= 0):
            raise MechanismError(f"body {bd.name!r}: gap_residual must be >= 0, got {bd.gap_residual!r}")
        bodies[bd.name] = bd
        connected |= set(bd.joints)
    for sp in mech.of(Support):
        need(sp.joint, f"support {sp.name!r}")
        if sp.kx is None and sp.ky is None:
            raise MechanismError(f"support {sp.name!r}: neither kx nor ky given")
        connected.add(sp.joint)
    for dr in mech.of(Drive):
        if dr.body not in bodies:
            raise MechanismError(f"drive {dr.name!r}: refers to body {dr.body!r}, which is not declared")
    for ld in mech.of(Load):
        need(ld.joint, f"load {ld.name!r}")
        if ld.input is not None and ld.input not in mech.inputs:
            raise MechanismError(f"load {ld.name!r}: input {ld.input!r} is not among the mechanism inputs "
                                 f"{list(mech.inputs)}")
    for ms in mech.of(Mass):
        need(ms.joint, f"mass {ms.name!r}")
    for jn in joints:
        if jn not in connected:
            raise MechanismError(f"joint {jn!r} is dangling: no bar, beam, body or support connects it")


def _check_sensors(mech, sensors):
    for s in sensors:
        jn, sep, d = str(s).rpartition("_")
        if not sep or d not in ("x", "y"):
            raise MechanismError(f"sensor {s!r}: names must be <joint>_x or <joint>_y")
        if jn not in {j.name for j in mech.joints}:
            raise MechanismError(f"sensor {s!r}: refers to joint {jn!r}, which is not declared")


def check_stiffness(asm: Assembly, rtol: float = 1e-10) -> None:
    """Raise if dE/dy at the reference state (y = 0, nominal p, q = 0) is singular.

    Checked first with clearance bearings replaced by linear ones (a genuinely
    under-constrained mechanism), then with the clearance characteristics (zero
    stiffness at d = 0).  The singular direction is reported by its largest state
    components.
    """
    _check_rank(Assembly(asm.mech, (), asm.inputs, None, linear_bearings=True), rtol, "")
    gaps = [f"{bd.name}@{jn}" for bd in asm.mech.of(RigidBody) for jn in bd.gap if not bd.gap_residual > 0]
    if gaps:
        _check_rank(Assembly(asm.mech, (), asm.inputs, None), rtol,
                    f" because clearance bearings ({', '.join(gaps)}) have zero stiffness at zero gap; "
                    "give those bodies gap_residual > 0")


def _check_rank(lin, rtol, why):
    K = np.array(ca.Function("K", [lin.y, lin.q], [ca.jacobian(lin.E, lin.y)])(
        np.zeros(lin.n_y), np.zeros(len(lin.inputs))))
    d = np.diag(K).copy()
    for k, dk in enumerate(d):
        if not dk > 0:
            raise MechanismError(f"mechanism {lin.mech.name!r}: stiffness matrix is singular{why}; state "
                                 f"{lin.state_names[k]!r} has no stiffness at all")
    s = 1 / np.sqrt(d)
    Ks = K * s[:, None] * s[None, :]
    w, V = np.linalg.eigh(0.5 * (Ks + Ks.T))
    if w[0] <= rtol * w[-1]:
        v = V[:, 0] * s
        v = v / np.max(np.abs(v))
        big = [f"{lin.state_names[k]} ({v[k]:+.2f})" for k in np.argsort(-np.abs(v))[:4] if abs(v[k]) > 0.05]
        raise MechanismError(f"mechanism {lin.mech.name!r}: stiffness matrix dE/dy is singular at the reference "
                             f"state (under-constrained; scaled eigenvalue ratio {w[0] / w[-1]:.1e}){why}; free motion "
                             f"involves {', '.join(big)}")


def assemble(mech: Mechanism, unknowns: Sequence[str] | None = None, inputs: Sequence[str] | None = None,
             input_map: Callable | None = None, check_rank: bool = True) -> Assembly:
    """Check a spec and build its symbolic energy and state equation.

    Parameters
    ----------
    mech : Mechanism
    unknowns : sequence of str, optional
        Parameter names that become the model parameters p (default: all declared).
    inputs : sequence of str, optional
        Input columns q (default ``mech.inputs``); must include every input used by a load.
    input_map : callable (qdict, qvec) -> dict, optional
        Replaces load inputs by expressions of the full input vector (e.g. a friction
        correction ``{"q_P": qvec[0] - friction}``).
    check_rank : bool
        Check that dE/dy at the reference state is non-singular.
    """
    check(mech)
    unknowns = tuple(p.name for p in mech.parameters) if unknowns is None else tuple(unknowns)
    declared = {p.name for p in mech.parameters}
    for u in unknowns:
        if u not in declared:
            raise MechanismError(f"unknown parameter {u!r} is not declared in mechanism {mech.name!r} "
                                 f"(declared: {', '.join(sorted(declared)) or '(none)'})")
    inputs = tuple(mech.inputs) if inputs is None else tuple(inputs)
    for ld in mech.of(Load):
        if ld.input is not None and ld.input not in inputs:
            raise MechanismError(f"load {ld.name!r}: input {ld.input!r} is not among the inputs {list(inputs)}")
    asm = Assembly(mech, unknowns, inputs, input_map)
    if check_rank:
        check_stiffness(asm)
    return asm


def build_model(mech: Mechanism, sensors: Sequence[str] | None = None, unknowns: Sequence[str] | None = None,
                inputs: Sequence[str] | None = None, input_map: Callable | None = None,
                input_units: Sequence[str] | None = None, name: str | None = None) -> Model:
    """The quasi-static :class:`models.Model` E(y, p, q) = dU/dy - Q(q) = 0 of a mechanism (N, N mm).

    Outputs are pin-node displacements (mm) named ``J_x``/``J_y``; the state is the one
    described in the module docstring; parameters p are the declared ``unknowns`` (all
    declared parameters by default).  The returned model carries three extra plain
    attributes: ``mechanism`` (the spec), ``state_names`` and ``p_nominal``.
    """
    sensors = tuple(mech.sensors if sensors is None else sensors)
    if not sensors:
        raise MechanismError(f"mechanism {mech.name!r}: no sensors given")
    _check_names(mech)
    _check_sensors(mech, sensors)
    asm = assemble(mech, unknowns, inputs, input_map)
    Ef = ca.Function("E", [asm.y, asm.p, asm.q], [asm.E])
    hf = ca.Function("h", [asm.y, asm.p, asm.q], [asm.sensor_expr(sensors)])
    params = [mech.parameter(n).to_parameter() for n in asm.unknowns]
    model = Model(params, asm.inputs, sensors, asm.n_y, E=lambda y, p, q: Ef(y, p, q),
                  h=lambda y, p, q: hf(y, p, q), name=name or mech.name,
                  sensor_units=("mm",) * len(sensors),
                  input_units=tuple(input_units) if input_units is not None else ("N",) * len(asm.inputs),
                  description=f"planar mechanism {mech.name!r}: {asm.n_y} states")
    # plain (picklable) extras; the symbolic Assembly is not kept (SX does not pickle)
    model.mechanism = mech
    model.state_names = asm.state_names
    model.p_nominal = asm.nominal()
    return model


# ---------------------------------------------------------------------------- numerics
def solve_path(model: Model, p, inputs, y0=None, tol: float = 1e-12, max_iter: int = 50) -> np.ndarray:
    """States y_j with E(y_j, p, q_j) = 0 along the rows of ``inputs`` (Newton, continuation).

    Each row is solved by the project's state solver (:func:`models.state.solve_state`:
    damped Newton with the exact AD Jacobian, converged when ||dy||_inf <= tol (1 + ||y||_inf),
    mm and rad), started from the previous row's solution (``y0`` or the model's guess for the
    first row).  Returns shape (n_q, n_y).

    Raises
    ------
    MechanismError
        Naming the input row where Newton failed or dE/dy was singular.
    """

    p = np.asarray(p, float)
    inputs = np.atleast_2d(np.asarray(inputs, float))
    out = np.empty((inputs.shape[0], model.n_y))
    y = None if y0 is None else np.asarray(y0, float)
    for j, q in enumerate(inputs):
        try:
            y = solve_state(model, p, q, y0=y, tol=tol, max_iter=max_iter)
        except StateSolveError as exc:
            raise MechanismError(f"model {model.name!r}: input row {j} ({q}): {exc}") from None
        out[j] = y
    return out


def linear_analysis(model: Model, p, q0=None, load_input: int = 0):
    """Linear compliances dh/dq and parameter sensitivities d^2h/(dq dp) at the reference state.

    Returns ``(c, S)`` with c[s] = dh_s/dq_load (mm/N) and S[s, i] = d c[s] / d p_i
    (mm/N per parameter unit), both at y = 0 (the linear, small-load regime).  For a
    load proportional to q, dh/dp at load q equals q * S.
    """
    p = np.asarray(p, float)
    y = ca.SX.sym("y", model.n_y)
    ps = ca.SX.sym("p", model.n_p)
    q = ca.SX.sym("q", model.n_q_dim)
    E = model.E_fun(y, ps, q)
    K = ca.jacobian(E, y)
    B = -ca.jacobian(E, q)[:, load_input]
    H = ca.jacobian(model.h_fun(y, ps, q), y)
    u = ca.solve(K, B)
    c = ca.mtimes(H, u)
    f = ca.Function("lin", [y, ps, q], [c, ca.jacobian(c, ps)])
    q0 = np.zeros(model.n_q_dim) if q0 is None else np.asarray(q0, float)
    cv, Sv = f(np.zeros(model.n_y), p, q0)
    return np.array(cv).ravel(), np.array(Sv)
