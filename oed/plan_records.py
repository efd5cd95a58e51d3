"""The designs a study plans, as records: sensors / inputs / both, discrimination, sampling times.

Built by :mod:`mudoe.plans` and :mod:`mudoe.kind.time_series`; read by the CLI (``summary``, ``to_dict``)
and the report (:attr:`oed.study_record.StudyRecord.plan`).  Every plan has ``variant``, ``mode`` and
``planned``.  (Moved from ``mudoe.plan_records``, which re-exports them, so that the report, below the
study layer, reads them as typed records.)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from identification.results_protocol import ResultProtocol, jsonable

__all__ = ["PlannedDesign", "RobustPlan", "RobustExactPlan", "DiscriminationPlan", "DynamicDesign", "design_rows_text"]


@dataclass(frozen=True)
class PlannedDesign(ResultProtocol):
    """A design of ``[oed] mode`` (sensors, inputs or both) at parameters ``p``.

    ``result`` is an :class:`oed.DesignResult` (mode sensors) or an :class:`oed.inputs.InputDesignResult`;
    ``planned`` is True when no data were used (p = the [[parameters]] start values, S = 0).
    """

    variant: str
    mode: str
    planned: bool
    p: tuple
    candidates: tuple
    result: object

    def summary(self) -> str:
        """Text of the design (what was chosen, value, proof)."""
        head = (f"{self.mode} design of variant {self.variant} at p = {list(self.p)} "
                + ("(planned before data: Gauss-Newton, S = 0)" if self.planned else "(at the estimate)"))
        return head + "\n" + self.result.summary()

    def to_dict(self) -> dict:
        """JSON-ready view: the chosen sensors / input points, value, bound and proof."""
        r = self.result
        d = dict(variant=self.variant, mode=self.mode, planned=self.planned, p=list(self.p),
                 candidates=list(self.candidates), criterion=r.criterion, value=r.value,
                 lower_bound=r.lower_bound, proven_optimal=r.proven_optimal, method=r.method,
                 notes=list(r.notes))
        if self.mode == "sensors":
            d.update(sensors=list(r.sensors), indices=list(r.indices))
        else:
            d.update(indices=list(r.indices), set_points=[self.candidates[j] for j in r.indices],
                     pairs=[[j, s] for j, s in r.pairs])
            if r.refined is not None:
                f = r.refined
                d.update(refined=dict(set_points=f.inputs.ravel().tolist(), value=f.value,
                                      start_values=list(f.start_values), n_failed=f.n_failed,
                                      lower=f.lower.tolist(), upper=f.upper.tolist(), wall_time=f.wall_time))
        return jsonable(d)

    def to_frame(self):
        """The design's table (:meth:`oed.DesignResult.to_frame` or :meth:`oed.InputDesignResult.to_frame`);
        ``.attrs`` also holds variant, mode and planned."""
        df = self.result.to_frame()
        df.attrs.update(variant=self.variant, mode=self.mode, planned=self.planned)
        return df


@dataclass(frozen=True)
class RobustPlan(ResultProtocol):
    """An approximate design of ``[oed] mode = "inputs"`` with a prior or ``approximate = true`` (issue 31).

    ``design`` is the :class:`oed.approximate.ApproximateDesign` (robust over the prior, or local without
    one: support points, weights, the sensitivity function over the checked points and its certificate);
    ``local`` the local approximate design at ``p`` when ``design`` is robust (else None) and
    ``local_efficiencies`` its efficiency at every parameter vector of the prior against ``design``
    (:func:`oed.design_efficiencies`; the prior's weights are ``design.prior.weights``); ``notes`` what of
    the [oed] section the approximate design did not use.
    """

    variant: str
    planned: bool
    p: tuple
    candidates: tuple
    design: object
    local: object
    local_efficiencies: tuple
    notes: tuple = ()

    mode = "inputs"
    approximate = True

    def summary(self) -> str:
        """Text of the design, its certificate and the local design across the prior."""
        head = (f"approximate input design of variant {self.variant} at p = {list(self.p)} "
                + ("(planned before data: Gauss-Newton, S = 0)" if self.planned else "(at the estimate)"))
        lines = [head, self.design.summary()]
        if self.local is not None:
            e = np.asarray(self.local_efficiencies)
            w = np.asarray(self.design.prior.weights)
            lines += ["local design at p (for comparison):", self.local.summary(),
                      f"efficiency of the local design against the robust one across the prior: min {e.min():.6f}, "
                      f"prior mean {float(w @ e):.6f}, max {e.max():.6f} ({len(e)} parameter vectors)"]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready view: the design with its certificate, the local design and its efficiencies."""
        d = dict(variant=self.variant, mode=self.mode, planned=self.planned, approximate=True, p=list(self.p),
                 candidates=list(self.candidates), criterion=self.design.criterion, robust=self.design.robust,
                 design=self.design.to_dict(), notes=list(self.notes))
        if self.local is not None:
            e = np.asarray(self.local_efficiencies)
            d.update(local=self.local.to_dict(), local_efficiencies=e.tolist(),
                     prior_points=np.asarray(self.design.prior.points).tolist(),
                     prior_weights=np.asarray(self.design.prior.weights).tolist(),
                     local_efficiency_min=float(e.min()),
                     local_efficiency_mean=float(np.asarray(self.design.prior.weights) @ e))
        return jsonable(d)

    def to_frame(self):
        """The support points and weights (:meth:`oed.ApproximateDesign.to_frame`); ``.attrs``: variant,
        robust, criterion."""
        df = self.design.to_frame()
        df.attrs.update(variant=self.variant, robust=self.design.robust, criterion=self.design.criterion)
        return df


@dataclass(frozen=True)
class RobustExactPlan(ResultProtocol):
    """An exact n-run design over a prior (``[oed] prior`` with ``approximate = false``, issue 31): sensors of a
    static study (``mode = "sensors"``), a dynamic study's sampling times (``mode = "times"``) or a static study's
    input rows (``mode = "inputs"``, labelled by their set point in the model's unit).

    ``design`` is the :class:`oed.robust_exact.RobustExactDesign` (pseudo-Bayesian or maximin, by enumeration or
    branch-and-bound, proven optimal or with its proven gap), ``local`` the local exact design at ``p``,
    ``local_efficiencies`` the local design's efficiency at every parameter vector of the prior against the
    robust one (:func:`oed.robust_exact.set_efficiencies`), ``prior_points`` / ``prior_weights`` the prior's rule,
    ``candidates`` the candidates' labels (sensor names, times, or ``sensor@time`` pairs).
    """

    variant: str
    mode: str
    planned: bool
    p: tuple
    candidates: tuple
    design: object
    local: object
    local_efficiencies: tuple
    prior_points: tuple
    prior_weights: tuple
    param_names: tuple = ()
    notes: tuple = ()

    approximate = False

    def chosen_times(self) -> tuple:
        """A sampling-time design's chosen times, sorted (from the labels ``0.5`` or ``cA@0.5``); () for sensors."""
        if self.mode != "times":
            return ()
        return tuple(sorted({float(str(n).rpartition("@")[2]) for n in self.design.names}))

    def summary(self) -> str:
        """Text of the robust design, its proof, the local design and its efficiency across the prior."""
        what = {"times": "sampling-time", "inputs": "input", "both": "joint set point x sensor"}.get(self.mode, "sensor")
        head = (f"exact robust {what} design of variant {self.variant} over a prior of {len(self.prior_weights)} "
                f"parameter vectors, nominal p = {list(self.p)} "
                + ("(planned before data: Gauss-Newton)" if self.planned else "(at the estimate)"))
        e, w = np.asarray(self.local_efficiencies), np.asarray(self.prior_weights)
        lines = [head, self.design.summary(), "local design at p (for comparison):", self.local.summary(),
                 f"efficiency of the local design against the robust one across the prior: min {e.min():.6f}, "
                 f"prior mean {float(w @ e):.6f}, max {e.max():.6f} ({len(e)} parameter vectors)"]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready view: the robust and local designs (chosen, value, proof), the prior and the efficiencies."""
        d, e = self.design, np.asarray(self.local_efficiencies)
        return jsonable(dict(variant=self.variant, mode=self.mode, planned=self.planned, approximate=False,
                             p=list(self.p), candidates=list(self.candidates), criterion=d.criterion, robust=d.robust,
                             chosen=list(d.names), indices=list(d.indices), value=d.value,
                             proven_optimal=d.proven_optimal, status=d.status, gap=d.gap, method=d.method,
                             design=d.to_dict(), local=self.local.to_dict(), local_efficiencies=e.tolist(),
                             local_efficiency_min=float(e.min()),
                             local_efficiency_mean=float(np.asarray(self.prior_weights) @ e),
                             param_names=list(self.param_names),
                             prior_points=[list(x) for x in self.prior_points],
                             prior_weights=list(self.prior_weights), notes=list(self.notes)))

    def to_frame(self):
        """The chosen candidates of the robust design (:meth:`oed.RobustExactDesign.to_frame`); ``.attrs`` also
        variant, mode and the local design's chosen candidates."""
        df = self.design.to_frame()
        df.attrs.update(variant=self.variant, mode=self.mode, local=list(self.local.names))
        return df


@dataclass(frozen=True)
class DiscriminationPlan(ResultProtocol):
    r"""A discrimination design (``[oed] mode = "discrimination"``) and its reference designs.

    ``result`` is the :class:`oed.DiscriminationResult` (variant assumed true, rival to be refuted);
    ``scores`` holds the per-reading T matrix ((h_v - h_rival) / sigma)^2 and, with data, the divergence
    matrix (h_v - h_rival)^2 / (2 sigma^2 + V_v + V_rival) (both (n_q, n_S), per series);
    ``references`` the readings of the comparison designs: ``"evenly spread"`` (the paper's style at the
    same number of set points: rows round(linspace(0, n_q - 1, k)), the same sensors; for n_readings
    designs k = ceil(n / n_S) rows x every sensor, the first n of these readings) and ``"all readings"`` (every candidate set
    point x every candidate sensor).
    """

    variant: str
    rival: str
    planned: bool
    p: tuple
    p_rival: tuple
    candidates: tuple
    n_series: int
    result: object
    scores: dict
    references: dict
    sensor_units: dict = field(default_factory=dict)
    refit: dict = field(default_factory=dict)

    mode = "discrimination"

    def values(self, readings) -> dict:
        """{criterion: n_series * sum of the per-reading scores over ``readings``} ((row, sensor) pairs)."""
        cols = self.result.candidate_sensors
        return {name: float(self.n_series * sum(d[j, cols.index(sn)] for j, sn in readings))
                for name, d in self.scores.items()}

    def design_values(self, name: str) -> dict:
        """:meth:`values` of design ``name`` ("chosen" or a reference) and its ``T_refit`` (n_series times
        the rival-refitted T, :func:`oed.discrimination.refit_values`; nan: the rival is not identifiable
        on those readings)."""
        readings = self.result.readings if name == "chosen" else self.references[name]
        out = self.values(readings)
        if name in self.refit:
            out["T_refit"] = self.n_series * self.refit[name]
        return out

    def summary(self) -> str:
        """Text of the design: chosen readings, T and divergence against the reference designs."""
        r = self.result
        head = (f"discrimination design: {self.variant} assumed true, rival {self.rival}, criterion {r.criterion}, "
                f"{self.n_series} series, " + ("planned before data (start values)" if self.planned
                                                 else "at the estimates"))
        lines = [head, r.summary(), "  readings (set point, sensor, h_true - h_rival, T):"]
        diff = r.difference
        for j, sn in r.readings:
            k = r.candidate_sensors.index(sn)
            unit = self.sensor_units.get(sn, "")
            lines.append(f"    {self.candidates[j]:g}  {sn}  {diff[j, k]:+.6g}{' ' + unit if unit else ''}  "
                         f"{self.scores['T'][j, k]:.4g}")
        lines.append("  design values (" + ", ".join(self.design_values("chosen")) + "):")
        for name, readings in (("chosen", r.readings),) + tuple(self.references.items()):
            vals = ", ".join(f"{k} {v:.4g}" for k, v in self.design_values(name).items())
            lines.append(f"    {name}: {len(readings)} readings/series, {vals}")
        return "\n".join(lines)

    def to_frame(self):
        """One row per chosen reading: its set point (``candidate``), ``sensor``, h_true - h_rival and the
        per-series scores (``T``, with data ``divergence``); ``.attrs``: variant, rival, criterion."""
        import pandas as pd
        r = self.result
        rows = []
        for j, sn in r.readings:
            k = r.candidate_sensors.index(sn)
            rows.append(dict(candidate=self.candidates[j], sensor=sn, difference=float(r.difference[j, k]),
                             **{name: float(d[j, k]) for name, d in self.scores.items()}))
        df = pd.DataFrame(rows)
        df.attrs.update(variant=self.variant, rival=self.rival, criterion=r.criterion)
        return df

    def to_dict(self) -> dict:
        """JSON-ready view: chosen readings (set point, sensor), values, proof and the references."""
        r = self.result
        return jsonable(dict(variant=self.variant, rival=self.rival, mode=self.mode, planned=self.planned,
                    p=list(self.p), p_rival=list(self.p_rival), candidates=list(self.candidates),
                    n_series=self.n_series, criterion=r.criterion, value=self.n_series * r.value,
                    upper_bound=self.n_series * r.upper_bound, proven_optimal=r.proven_optimal, method=r.method,
                    indices=list(r.indices), sensors=list(r.sensors),
                    set_points=[self.candidates[j] for j in r.indices],
                    readings=[[self.candidates[j], sn] for j, sn in r.readings],
                    values=self.design_values("chosen"),
                    references={name: dict(readings=[[self.candidates[j], sn] for j, sn in rd],
                                           values=self.design_values(name))
                                for name, rd in self.references.items()}))


@dataclass(frozen=True)
class DynamicDesign(ResultProtocol):
    """A sampling-time design: the :class:`oed.DesignResult`, the ranked table, the candidates."""

    variant: str
    planned: bool
    p: tuple
    candidates: tuple
    pairs: bool
    result: object
    table: object
    mode = "times"

    def chosen_times(self) -> tuple:
        """The chosen sampling times (sorted)."""
        t = self.candidates
        if not self.pairs:
            return tuple(t[i] for i in self.result.indices)
        n_S = len(self.table.rows[0].mask) // len(t)
        return tuple(sorted({t[i // n_S] for i in self.result.indices}))

    def summary(self) -> str:
        head = (f"sampling-time design of variant {self.variant} at p = {list(self.p)} "
                + ("(planned before data: Gauss-Newton)" if self.planned else "(at the estimate)"))
        text = self.result.summary().replace("  sensors (", "  readings (" if self.pairs else "  sampling times (", 1)
        return head + "\n" + text + "\n" + self.table.note + ":\n" + design_rows_text(self.table)

    def to_frame(self):
        """The ranked designs, one row per design (``rank`` 1 = best): log det C, trace C (A), max eig C (E),
        the flag and the candidates (joined by ", "); ``.attrs``: variant, chosen_times."""
        import pandas as pd
        df = pd.DataFrame([dict(logdet=x.logdet, A=x.A, E=x.E, flag=x.flag, candidates=", ".join(x.sensors))
                           for x in self.table.rows],
                          index=pd.RangeIndex(1, len(self.table.rows) + 1, name="rank"))
        df.attrs.update(variant=self.variant, chosen_times=self.chosen_times())
        return df

    def to_dict(self) -> dict:
        """JSON-ready view: the chosen times (readings), value, proof and the ranked table."""
        r = self.result
        return jsonable(dict(variant=self.variant, mode="times", planned=self.planned, p=list(self.p),
                    candidates=list(self.candidates), pairs=self.pairs, chosen=list(r.chosen),
                    chosen_times=list(self.chosen_times()), criterion=r.criterion, value=r.value,
                    lower_bound=r.lower_bound, proven_optimal=r.proven_optimal, method=r.method,
                    notes=list(r.notes), table_note=self.table.note,
                    table=[dict(candidates=list(x.sensors), A=x.A, logdet=x.logdet, E=x.E, flag=x.flag)
                           for x in self.table.rows]))


def design_rows_text(table) -> str:
    """The ranked designs as text: rank, log det C, trace C, max eig C, the candidates."""
    out = [f"{'rank':>4} {'log det C':>11} {'trace C':>11} {'max eig C':>11}  candidates"]
    for k, r in enumerate(table.rows, 1):
        out.append(f"{k:>4} {r.logdet:>11.4f} {r.A:>11.4e} {r.E:>11.4e}  {', '.join(r.sensors)}"
                   + (f"  ({r.flag})" if r.flag else ""))
    return "\n".join(out)
