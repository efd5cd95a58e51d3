r"""Sequential design of experiments (the paper's outlook, after Koerkel et al. 2004).

For experiments k = 1..K:

.. math::

    w_k = \arg\min_{w \in \{0,1\}^{n_S},\, g(w) \le 0} \Psi\bigl(C(p_{k-1}, w)\bigr),\qquad
    p_k = \arg\min_p \tfrac12 \sum_{ijl} w_{k,l} \bigl((z^{(k)}_{ijl} - h_l(y_j(p), p, q_j)) / \sigma_l\bigr)^2,

with :math:`p_0` the nominal parameters and the information of design k taken from the
data available before experiment k (the initial data for k = 1, experiment k - 1 after).
The result shows how the chosen sensors and the confidence ellipsoid change once the
design is computed at identified instead of nominal parameters.

Under a prior (``prior=``), each :math:`w_k` is instead the exact robust choice (pseudo-Bayesian or
standardized maximin) over the prior moved to :math:`p_{k-1}` (:mod:`oed.sequential_robust`); at a point
prior it is the local choice.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from identification.results_protocol import ResultProtocol, jsonable
from identification.vocabulary import renamed_arguments
from .criteria import DEFAULT_CRITERION, Criterion, Kind
from .design import DesignResult, select_sensors_from_information
from .candidate_information import information
from .approximate import check_prior_points
from .sequential_robust import RobustStep, recentred, robust_sensor_step

__all__ = ["SequentialStep", "SequentialResult", "sequential_design"]


@dataclass(frozen=True)
class SequentialStep:
    """One experiment: the design computed at ``p_design`` and the estimate it produced.  Under a prior ``robust``
    holds the robust choice (:class:`oed.sequential_robust.RobustStep`, with the prior moved to ``p_design``) and
    ``design`` that choice as a :class:`DesignResult` (its ``value``: the robust criterion, maximised; see its
    notes); None for a local design."""

    p_design: np.ndarray
    design: DesignResult
    p: np.ndarray
    stderr: np.ndarray
    cov: np.ndarray
    ellipsoid_volume: float
    robust: RobustStep | None = None


@dataclass(frozen=True)
class SequentialResult(ResultProtocol):
    """The designs and estimates of :func:`sequential_design`, one :class:`SequentialStep` per experiment
    (the result protocol: :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    steps : tuple of SequentialStep
    param_names, sensor_names : tuple of str
    axis : str
        The candidates' axis of every design (``"sensors"``).
    chosen : tuple of tuple of str
        The chosen sensors of every experiment's design.
    """

    steps: tuple
    param_names: tuple
    sensor_names: tuple

    axis = "sensors"

    @property
    def chosen(self) -> tuple:
        """The chosen sensors of every experiment's design (``steps[k].design.chosen``)."""
        return tuple(s.design.chosen for s in self.steps)

    def summary(self) -> str:
        """One line per experiment: design, estimate, standard errors, ellipsoid volume."""
        lines = ["Sequential design: experiment, design parameters, chosen sensors, estimate +- std err, "
                 "95 % ellipsoid volume"]
        prev = None
        for k, s in enumerate(self.steps, 1):
            est = ", ".join(f"{n} = {v:.6g} +- {e:.3g}" for n, v, e in zip(self.param_names, s.p, s.stderr))
            pd = ", ".join(f"{v:.6g}" for v in s.p_design)
            change = "" if prev is None else ("  (same design)" if s.design.chosen == prev else "  (design changed)")
            lines.append(f"{k}: at ({pd}) chose {'+'.join(s.design.chosen)} [{s.design.criterion} = "
                         f"{s.design.value:.4g}, {s.design.method}]; {est}; volume {s.ellipsoid_volume:.4g}{change}")
            prev = s.design.chosen
        return "\n".join(lines)

    def to_frame(self):
        """One row per experiment (``experiment`` 1, 2, ...): the chosen sensors (joined by "+"), the criterion
        value and method, the estimate and standard error of every parameter (columns ``<name>`` and
        ``se <name>``, parameter units) and the ellipsoid volume."""
        import pandas as pd
        rows = []
        for s in self.steps:
            row = dict(sensors="+".join(s.design.sensors), value=s.design.value, method=s.design.method)
            row.update({n: float(v) for n, v in zip(self.param_names, s.p)})
            row.update({f"se {n}": float(e) for n, e in zip(self.param_names, s.stderr)})
            row["ellipsoid_volume"] = s.ellipsoid_volume
            rows.append(row)
        return pd.DataFrame(rows, index=pd.RangeIndex(1, len(rows) + 1, name="experiment"))

    def to_dict(self) -> dict:
        """JSON-safe: param_names, sensor_names and per step p_design, the design (:meth:`DesignResult.to_dict`),
        p, stderr, cov and ellipsoid_volume (under a prior also ``robust``: the robust choice's value, per-vector
        utilities, worst-case efficiency, proof and the prior's points and weights at that step)."""
        return jsonable(dict(param_names=self.param_names, sensor_names=self.sensor_names,
                             steps=[_step_dict(s) for s in self.steps]))


def _step_dict(s: SequentialStep) -> dict:
    """One step of :meth:`SequentialResult.to_dict` (``robust`` only under a prior)."""
    d = dict(p_design=s.p_design, design=s.design.to_dict(), p=s.p, stderr=s.stderr, cov=s.cov,
             ellipsoid_volume=s.ellipsoid_volume)
    if s.robust is not None:
        r = s.robust
        d["robust"] = dict(value=r.value, per_sample=r.per_sample, worst_case_efficiency=r.worst_case_efficiency,
                           proven_optimal=r.proven_optimal, method=r.method, gap=r.gap, prior_points=r.prior.points,
                           prior_weights=r.prior.weights)
    return d


@renamed_arguments(experiments="data", p_nominal="p0")
def sequential_design(model, data: Sequence, p0, initial=None, criterion=DEFAULT_CRITERION,
                      kind="gauss_newton", n_sensors=None, alpha: float = 0.05, prior=None, robust: str = "bayes",
                      **design_kw) -> SequentialResult:
    """Re-solve the sensor selection with the parameters identified from each experiment.

    Parameters
    ----------
    model : models.Model or models.dynamic.DynamicModel
    data : sequence of identification.Measurements (DynamicMeasurements for a dynamic model)
        The experiments in the order they are made (known sigma, all candidate sensors present).
        A dynamic model is designed per instrument (each measured at every sampling time of the
        experiment): F_l = sum_t F_(l, t) over the (sensor, time) contributions of its collocation
        (exact, since the weight of every (l, t) pair is w_l), and identified with those weights.
    p0 : array_like (n_p,)
        Parameters for the first design and the start value of every identification.
    initial : Measurements, optional
        Data for the first design's information (the paper's z^ini); default: the first experiment.
    criterion, kind, n_sensors, **design_kw
        Passed to :func:`oed.design.select_sensors_from_information`.  ``kind`` defaults to
        Gauss-Newton: the second-order term S_k is built from residuals of data at parameters
        that were not fitted with that sensor set, and on noisy press data it regularises H enough
        to make the weakly identifying pair (D_y, B0_y) look good (E = 447 second order against
        3.6e6 Gauss-Newton, see tests/oed/test_sequential_and_press.py).
    alpha : float
        Level of the reported confidence ellipsoid.
    prior : None, (P, w), dict or oed.prior.Prior
        Parameter uncertainty around ``p0`` (:func:`oed.prior.make_prior`, non-negative weights): each experiment's
        sensors are then the exact robust choice of ``n_sensors`` (default min(n_p, n_S)) over the prior moved to
        the current estimate (:mod:`oed.sequential_robust`; Gauss-Newton or ``kind="second_order"``);
        ``design_kw`` then takes only ``method`` ("auto", "enumerate", "bnb") and ``time_limit`` (s per solve).
    robust : {"bayes", "maximin"}
        With a prior: the expected criterion, or the worst-case efficiency against each vector's own best set.

    Raises
    ------
    ValueError
        When ``data`` is empty.  Identification and design errors propagate unchanged.
    identification.NotBoundedError
        When the data of an experiment do not bound the parameters (no estimate to design at).
    """
    from identification import identify

    experiments = list(data)
    if not experiments:
        raise ValueError("data: give at least one experiment (Measurements)")
    p0 = np.asarray(p0, float).ravel()
    p_design = p0
    info_data = experiments[0] if initial is None else initial
    pr = None if prior is None else _robust_prior(model, p0, prior, robust, design_kw)
    steps = []
    for experiment in experiments:
        step = None
        if pr is None:
            info = information(model, p_design, data=info_data)      # per sensor (a dynamic model's: per instrument)
            design = select_sensors_from_information(info, criterion=criterion, kind=kind, n_sensors=n_sensors,
                                                     **design_kw)
        else:
            step, design = _robust_choice(model, recentred(pr, p0, p_design), info_data, criterion, kind, n_sensors,
                                          robust, design_kw, len(steps) + 1)
        est = identify(model, experiment, p0, weights=np.asarray(design.weights, float))
        est.require_bounded(f"sequential design, experiment {len(steps) + 1} (the next design is computed at its "
                            "estimate)")
        steps.append(SequentialStep(p_design=p_design.copy(), design=design, p=est.p.copy(),
                                    stderr=est.stderr.copy(), cov=est.cov.copy(),
                                    ellipsoid_volume=est.ellipsoid(alpha).volume(), robust=step))
        p_design, info_data = est.p.copy(), experiment
    return SequentialResult(tuple(steps), model.param_names, model.sensors)


def _robust_prior(model, p0, prior, robust, design_kw):
    """The prior of a robust sequential design around ``p0`` (checked: weights, robust, design_kw)."""
    from .prior import make_prior
    from .prior_sparse import check_non_negative
    if robust not in ("bayes", "maximin"):
        raise ValueError(f"robust: expected 'bayes' or 'maximin', got {robust!r}")
    bad = [k for k, v in design_kw.items() if k not in ("method", "time_limit") and v is not None
           and not (isinstance(v, (tuple, list)) and len(v) == 0)]
    if bad:
        raise ValueError(f"{bad[0]}: not used by the robust sequential design (prior is given: each experiment "
                         "chooses exactly n_sensors sensors); leave it out")
    pr = make_prior(prior, model, p0)
    check_non_negative(pr, "a robust sequential design")
    return pr


def _robust_choice(model, pr, info_data, criterion, kind, n_sensors, robust, design_kw, k):
    """(RobustStep, DesignResult) of experiment ``k``: the robust choice over ``pr`` (already at the estimate)."""
    check_prior_points(model, pr, f"(moved to the estimate before experiment {k})")
    infos = [information(model, ps, data=info_data) for ps in pr.points]
    n_S = infos[0].F.shape[0]
    n = min(model.n_p, n_S) if n_sensors is None else n_sensors
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= n_S:
        raise ValueError(f"n_sensors: expected an integer in 1..{n_S}, got {n_sensors!r}")
    step = robust_sensor_step(infos, pr, int(n), criterion=criterion, kind=kind, robust=robust,
                              method=design_kw.get("method", "auto"), time_limit=design_kw.get("time_limit", 60.0))
    labels = tuple(infos[0].labels)
    mask = tuple(i in step.indices for i in range(n_S))
    what = "expected utility" if robust == "bayes" else "smallest standardized utility"
    design = DesignResult(chosen=tuple(labels[i] for i in step.indices), indices=step.indices, weights=mask,
                          criterion=Criterion.parse(criterion).value, kind=Kind.parse(kind).value, value=step.value,
                          det=None, lower_bound=float("nan"), gap=step.gap, proven_optimal=step.proven_optimal,
                          method=f"{robust} {step.method}", status="optimal" if step.proven_optimal else "not proven",
                          message="", wall_time=0.0, candidates=labels,
                          notes=(f"robust {robust} design over {pr.n} parameter vectors: value is the {what} "
                                 f"(u = -Psi(C), maximised), worst-case efficiency {step.worst_case_efficiency:.6g}",))
    return step, design
