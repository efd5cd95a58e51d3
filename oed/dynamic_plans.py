"""The designs a time-series study plans beyond its exact sampling times, as records (issue 30 item 8, issue 31):
the design of its next experiments (constants and control profiles) and its approximate sampling times.

Built by :mod:`mudoe.dynamic_plans`; read by the CLI (``summary``, ``to_dict``) and the report
(:attr:`oed.study_record.StudyRecord.plan`, :mod:`reports.control_design_pages`).  Like every plan of
:mod:`oed.plan_records` they have ``variant``, ``mode`` and ``planned``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.results_protocol import ResultProtocol, jsonable
from .plan_records import RobustPlan

__all__ = ["ExperimentInput", "ExperimentPlan", "ApproximateTimePlan", "row_groups"]


@dataclass(frozen=True)
class ExperimentInput:
    """One input of a dynamic model's experiment: a constant (``grid`` empty, one column of the input row) or a
    control (one column per grid point; ``kind`` "constant": steps, "linear": lines between the grid points)."""

    name: str
    unit: str = ""
    grid: tuple = ()
    kind: str = "constant"

    @property
    def width(self) -> int:
        """Columns of the input row."""
        return len(self.grid) or 1


def row_groups(inputs, row) -> list:
    """[(ExperimentInput, its values from the input row ``row``)] in the row's order (constants, then controls)."""
    out, k = [], 0
    for inp in inputs:
        out.append((inp, np.asarray(row[k:k + inp.width], float)))
        k += inp.width
    return out


def _row_text(inputs, row) -> str:
    parts = []
    for inp, v in row_groups(inputs, row):
        u = f" {inp.unit}" if inp.unit else ""
        parts.append(f"{inp.name} = {v[0]:.6g}{u}" if not inp.grid else
                     f"{inp.name} = [{', '.join(f'{x:.4g}' for x in v)}]{u}")
    return "; ".join(parts)


@dataclass(frozen=True)
class ExperimentPlan(ResultProtocol):
    r"""The design of a time-series study's next ``n`` experiments (``[oed] mode = "inputs"``): their constants and
    control profiles within ``lower`` / ``upper``.

    ``result`` is the :class:`oed.inputs.InputDesignResult` over the candidate experiments ``candidates`` (the
    study's own, then random ones within the bounds; ``labels`` their names), with its continuous refinement when
    ``[oed] refine`` ran; with a prior, None and ``robust`` the :class:`oed.plan_records.RobustExactPlan` of the
    exact robust choice.  ``designed`` are the designed rows (the refined ones when refined).  ``values`` holds
    the criterion value (D: log det C, A: trace C, E: max eig C of the Gauss-Newton covariance
    :math:`C = (\sum F)^{-1}` at ``p``, per series times ``n_series``) of ``"design"`` (the designed experiments),
    ``"current"`` (the study's experiments ``current``) and ``"current + design"``; ``each`` that of every current
    experiment alone (inf: it alone does not identify the parameters); ``efficiency`` the design's efficiency per
    experiment against the current experiments (D: :math:`(\det(M_d/n_d) / \det(M_c/n_c))^{1/n_p}`; A, E: the
    ratio of trace :math:`(M/n)^{-1}` or of :math:`1/\lambda_{min}(M/n)`, current over design).
    """

    variant: str
    planned: bool
    p: tuple
    param_names: tuple
    inputs: tuple
    lower: tuple
    upper: tuple
    current: tuple
    candidates: tuple
    labels: tuple
    criterion: str
    result: object
    designed: tuple
    values: dict
    each: tuple
    efficiency: float
    time_limit: float
    time_limit_hit: bool
    n_series: int = 1
    robust: object = None
    notes: tuple = ()

    mode = "inputs"
    approximate = False

    @property
    def chosen(self) -> tuple:
        """The labels of the chosen candidate experiments."""
        idx = self.robust.design.indices if self.robust is not None else self.result.indices
        return tuple(self.labels[i] for i in idx)

    @property
    def time_limit_reason(self) -> str:
        """What reached the time limit (the first note or refinement message saying so; "" when none)."""
        texts = list(self.result.notes) if self.result is not None else []
        if self.result is not None and self.result.refined is not None:
            texts += list(self.result.refined.messages)
        return next((t for t in texts if "time limit" in t), "")

    @property
    def refined(self) -> bool:
        """Whether the designed rows are a continuous refinement of the chosen candidates."""
        return self.result is not None and self.result.refined is not None

    def summary(self) -> str:
        """The designed experiments (constants and profiles), the proof, the values against the current ones."""
        crit = "log det C" if self.criterion == "D" else {"A": "trace C", "E": "max eig C"}[self.criterion]
        how = ("exact robust choice over the prior" if self.robust is not None else
               "exact choice" + (" and continuous refinement" if self.refined else ""))
        lines = [f"design of {len(self.designed)} new experiment(s) of variant {self.variant} ({self.criterion}, "
                 f"{how}) at p = {list(self.p)} " + ("(planned before data at the start values)" if self.planned
                                                    else "(at the estimate)"),
                 f"  chosen among {len(self.candidates)} candidate experiments: {', '.join(self.chosen)}"]
        for k, row in enumerate(self.designed, 1):
            lines.append(f"  designed experiment {k}: {_row_text(self.inputs, row)}")
        lines.append(f"  {crit} per {self.n_series} series: design {self.values['design']:.6g}, current experiments "
                     f"({len(self.current)}) {self.values['current']:.6g}, current + design "
                     f"{self.values['current + design']:.6g}")
        lines.append(f"  efficiency per experiment of the design against the current experiments: "
                     f"{self.efficiency:.4g}")
        for k, v in enumerate(self.each, 1):
            lines.append(f"  current experiment {k} alone: {crit} {v:.6g}  ({_row_text(self.inputs, self.current[k - 1])})")
        if self.robust is not None:
            lines += ["", self.robust.summary()]
        elif self.result is not None:
            lines += ["", self.result.summary()]
        if self.time_limit_hit:
            lines.append(f"  time limit ([oed] time_limit = {self.time_limit:g} s) reached: {self.time_limit_reason}")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_frame(self):
        """One row per designed experiment (``experiment`` 1, 2, ...): its input columns (model units)."""
        import pandas as pd
        names = [f"{i.name}@{t:g}" if i.grid else i.name for i in self.inputs for t in (i.grid or (None,))]
        df = pd.DataFrame(np.asarray(self.designed, float).reshape(len(self.designed), -1), columns=names,
                          index=pd.RangeIndex(1, len(self.designed) + 1, name="experiment"))
        df.attrs.update(variant=self.variant, criterion=self.criterion, values=dict(self.values),
                        efficiency=self.efficiency)
        return df

    def to_dict(self) -> dict:
        """JSON-ready view: the designed experiments (rows and by input), the choice and its proof, the values."""
        res = None if self.result is None else self.result.to_dict()
        designed = [{inp.name: (v.tolist() if inp.grid else float(v[0])) for inp, v in row_groups(self.inputs, row)}
                    for row in self.designed]
        return jsonable(dict(
            variant=self.variant, mode=self.mode, planned=self.planned, approximate=False, p=list(self.p),
            param_names=list(self.param_names), criterion=self.criterion,
            inputs=[dict(name=i.name, unit=i.unit, grid=list(i.grid), kind=i.kind) for i in self.inputs],
            lower=list(self.lower), upper=list(self.upper), current=[list(r) for r in self.current],
            candidates=[list(r) for r in self.candidates], labels=list(self.labels), chosen=list(self.chosen),
            designed_rows=[list(r) for r in self.designed], designed=designed, refined=self.refined,
            values=dict(self.values), current_each=list(self.each), efficiency_per_experiment=self.efficiency,
            n_series=self.n_series, time_limit=self.time_limit, time_limit_hit=self.time_limit_hit,
            result=res, robust=None if self.robust is None else self.robust.to_dict(), notes=list(self.notes)))


@dataclass(frozen=True)
class ApproximateTimePlan(RobustPlan):
    """The approximate sampling-time design of a time-series study (``approximate = true``, mode "sensors"):
    :class:`oed.plan_records.RobustPlan` over the range of the candidate times (``candidates``) for the study's
    experiments; ``design`` robust over ``[oed] prior`` or local, ``local`` the local design with a prior."""

    mode = "times"

    def chosen_times(self) -> tuple:
        """The support points of the design (times, sorted)."""
        return tuple(sorted(float(x[0]) for x in np.asarray(self.design.points, float).reshape(-1, 1)))

    def summary(self) -> str:
        """Text of the design, its certificate and the local design across the prior."""
        return super().summary().replace("approximate input design", "approximate sampling-time design", 1)
