"""The Estimate users get: the fit record with intervals, regions, curvature and a summary, and
:func:`identify`, the fit of the problem (:meth:`identification.fit.problem.Problem.fit`) returned as
that Estimate."""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from html import escape

import numpy as np
from scipy import stats

from identification.fit.estimator import IdentifySettings
from identification.fit.problem import Problem
from identification.fit.record import FitRecord
from identification.inference.curvature import Curvature, estimate_curvature
from identification.inference.bootstrap import bootstrap_intervals
from identification.inference.intervals import ConfidenceIntervals, resolve_params, validate_alpha
from identification.inference.profile import profile_intervals, unbounded_summary
from identification.inference.regions import Ellipsoid
from identification.results_protocol import ResultProtocol, jsonable

__all__ = ["Estimate", "identify"]


@dataclass(frozen=True, eq=False, repr=False)
class Estimate(FitRecord, ResultProtocol):
    """Result of :func:`identification.identify`: a :class:`identification.fit.record.FitRecord` (the
    fields listed there) with marginal intervals (:meth:`conf_int`), the joint ellipsoid, the
    Bates-Watts curvature and the result protocol (:meth:`summary`, :meth:`to_frame`, :meth:`to_dict`,
    ``_repr_html_``; :mod:`identification.results_protocol`)."""

    @classmethod
    def from_record(cls, record: FitRecord) -> "Estimate":
        """The Estimate of a fit record (same numbers; the record itself when it already is one)."""
        if isinstance(record, cls):
            return record
        return cls(**record.record_fields())

    @cached_property
    def curvature(self) -> Curvature:
        """Bates-Watts maximum relative intrinsic and parameter-effects curvatures at alpha = 0.05,
        exact from the second derivatives of the model outputs (:mod:`identification.inference.curvature`)."""
        if self.model is None or self.data is None:
            raise ValueError("curvature: this Estimate carries no model/data (build it with identify())")
        self.require_bounded("curvature")
        return estimate_curvature(self, self.model, self.data, 0.05)

    def _summary_notes(self, intervals) -> tuple:
        """The estimator's notes plus the curvature diagnostics (when model and data are known)."""
        notes = list(self.notes)
        if self.model is not None and self.data is not None and self.dof >= 1:
            try:
                c = self.curvature
            except np.linalg.LinAlgError as exc:
                notes.append(f"curvature not computed: {exc}")
            else:
                if not c.trustworthy:
                    notes.append(f"the linearisation is NOT trustworthy: Bates-Watts relative curvature "
                                 f"intrinsic {c.intrinsic:.3g}, parameter-effects {c.parameter_effects:.3g} vs "
                                 f"critical 1/sqrt(F) = {c.critical:.3g} (alpha = 0.05); the ellipsoid and the "
                                 f"Wald intervals above can be badly wrong: use conf_int(method=\"profile\") "
                                 f"(likelihood-ratio intervals) instead")
                    notes.append(self._profile_note(intervals))
        elif intervals is not None:
            notes.append(self._profile_note(intervals))
        return tuple(notes)

    def _profile_note(self, ci) -> str:
        """The intervals ``ci`` the caller computed (profile or bootstrap) as one note; without them, how to get them."""
        if ci is None:
            return ("profile-likelihood intervals not computed here (summary() only reads): "
                    "ci = est.conf_int(method=\"profile\"); est.summary(intervals=ci) shows them")
        pct = f"{100 * (1 - ci.alpha):g} %"
        parts = ", ".join(f"{n} [{lo:.5g}, {hi:.5g}]" for n, lo, hi in zip(ci.param_names, ci.lower, ci.upper))
        return (f"{pct} {ci.method} intervals (trust these, not the Wald columns): {parts}"
                + ("; " + "; ".join(ci.notes) if ci.notes else ""))

    def _quantile(self, alpha: float) -> float:
        if not (0 < alpha < 1):
            raise ValueError(f"alpha must lie in (0, 1), got {alpha}")
        if self.sigma_estimated:
            return float(stats.t.ppf(1 - alpha / 2, self.dof))
        return float(stats.norm.ppf(1 - alpha / 2))

    #: the interval methods of :meth:`conf_int`
    CONF_INT_METHODS = ("wald", "profile", "bootstrap")

    def conf_int(self, alpha: float = 0.05, method: str = "wald", params=None, kind: str = "second_order", *,
                 model=None, data=None, n: int = 200, seed=0, workers: int | None = 1, progress=None,
                 settings=None, scheduler=None):
        """Marginal (1 - alpha) confidence intervals of the parameters.

        ``method="wald"`` (default): p_i -+ c se_i with c the normal quantile z(1 - alpha/2) (sigma
        known) or Student t(n - n_p; 1 - alpha/2) (sigma estimated), se from the second-order
        (``kind="second_order"``) or Gauss-Newton covariance.

        ``method="profile"``: {theta : 2 (min_{p_i = theta} Phi - Phi(p_hat)) <= c} with c =
        chi2_1(1 - alpha), or F(1, n - n_p; 1 - alpha) when sigma was estimated (Bates-Watts
        profile-t); see :func:`identification.inference.profile.profile_intervals` (``settings``: a
        ``ProfileSettings``).

        ``method="bootstrap"``: parametric bootstrap percentile intervals from ``n`` refits of data
        simulated from the fit (``seed``, ``workers`` local processes or ``scheduler`` a Dask
        address or Client, ``progress`` a :class:`identification.progress.Progress`); see
        :func:`identification.inference.bootstrap.bootstrap_intervals`.

        For an estimate that is not bounded (:attr:`bounded` False) the Wald intervals of the parameters
        that run off are (-inf, inf) (infinite standard errors); the profile intervals have a finite end
        (the likelihood ratio against the infimum of the objective) and an infinite one; the bootstrap
        raises NotBoundedError.

        Every method returns a frozen :class:`identification.inference.intervals.ConfidenceIntervals`
        (``lower``, ``upper``, ``method``, ``notes``; ``np.asarray(ci)`` is the (m, 2) array of [lower,
        upper] rows, ``ci.to_frame()`` a pandas DataFrame); an unbounded side is -inf / +inf with a note.  They use the ``model`` and ``data`` the
        estimate was fitted to (kept by :func:`identify`; pass them for an estimate built otherwise).

        Parameters
        ----------
        alpha : float in (0, 0.5)   the miss probability: 0.05 gives 95 % intervals
        method : "wald", "profile" or "bootstrap"
        params : names or 0-based indices, optional (default all, in model order)

        Raises
        ------
        ValueError
            alpha outside (0, 0.5), an unknown method or parameter name (the message names the argument).
        """
        alpha = validate_alpha(alpha)
        if method not in self.CONF_INT_METHODS:
            raise ValueError(f"method: unknown interval method {method!r}; choose one of "
                             f"{', '.join(repr(m) for m in self.CONF_INT_METHODS)}")
        idx = resolve_params(params, tuple(self.param_names))
        if method == "wald":
            se = self._se(kind)
            c = self._quantile(alpha)
            return ConfidenceIntervals(param_names=tuple(self.param_names[i] for i in idx), estimate=self.p[idx],
                                       lower=(self.p - c * se)[idx], upper=(self.p + c * se)[idx], method="wald",
                                       alpha=alpha)
        model = self.model if model is None else model
        data = self.data if data is None else data
        if method == "profile":
            return profile_intervals(model, data, self, alpha, idx, settings=settings)
        return bootstrap_intervals(model, data, self, alpha, idx, n=n, seed=seed, workers=workers,
                                   progress=progress, scheduler=scheduler)

    def _se(self, kind):
        if kind == "second_order":
            return self.stderr
        if kind == "gauss_newton":
            return self.stderr_gn
        raise ValueError(f"kind must be 'second_order' or 'gauss_newton', got {kind!r}")

    def ellipsoid(self, alpha: float = 0.05, kind: str = "second_order") -> Ellipsoid:
        """The joint (1 - alpha) confidence ellipsoid G(alpha, p, C) (paper eq. 6).

        ``alpha`` in (0, 0.5) is the miss probability (0.05 gives the 95 % ellipsoid), as in
        :meth:`conf_int`; anything else raises ValueError naming the argument.  NotBoundedError when
        the data do not bound the parameters.
        """
        self.require_bounded("ellipsoid")
        alpha = validate_alpha(alpha)
        C = self.cov if kind == "second_order" else self.cov_gn if kind == "gauss_newton" else None
        if C is None:
            raise ValueError(f"kind must be 'second_order' or 'gauss_newton', got {kind!r}")
        if self.sigma_estimated:
            g2 = self.n_p * float(stats.f.ppf(1 - alpha, self.n_p, self.dof))
        else:
            g2 = float(stats.chi2.ppf(1 - alpha, self.n_p))
        return Ellipsoid(self.p.copy(), C.copy(), alpha, g2, self.param_names)

    # ------------------------------------------------------------------ tables (pandas, Jupyter)
    def to_frame(self, alpha: float = 0.05, kind: str = "second_order"):
        """The parameter table as a pandas DataFrame indexed by parameter: ``estimate``, ``stderr``
        (second-order), ``stderr_gn`` (Gauss-Newton), ``wald_lower`` and ``wald_upper`` (the (1 - alpha) Wald
        interval p_i -+ c se_i of :meth:`conf_int` with the ``kind`` covariance; parameter units) and ``unit``;
        ``.attrs`` holds alpha, kind and the model name."""
        import pandas as pd
        ci = self.conf_int(alpha, kind=kind)
        df = pd.DataFrame({"estimate": self.p, "stderr": self.stderr, "stderr_gn": self.stderr_gn,
                           "wald_lower": ci.lower, "wald_upper": ci.upper, "unit": list(self.param_units)},
                          index=pd.Index(list(self.param_names), name="parameter"))
        df.attrs.update(alpha=ci.alpha, kind=kind, model=self.model_name)
        return df

    def _repr_html_(self) -> str:
        """Jupyter's view: the status line, the parameter table (:meth:`to_frame`) and the numbered notes."""
        head = (f"<p><b>Identification of {escape(self.model_name or 'model')}</b>: {escape(str(self.status))} "
                f"({escape(str(self.message))}); n = {self.n_data}, dof = {self.dof}, objective "
                f"{self.objective:.6g}" + (" (sigma estimated)" if self.sigma_estimated else "") + "</p>")
        table = self.to_frame().to_html(float_format=lambda v: f"{v:.7g}")
        if self.unbounded is not None:          # where the parameters run off: the text summary says it
            return head + table + f"<pre>{escape(self.summary())}</pre>"
        notes = self._summary_notes(None)
        items = "".join(f"<li>{escape(n)}</li>" for n in notes)
        return head + table + (f"<p>Notes:</p><ol>{items}</ol>" if notes else "")

    # ------------------------------------------------------------------ report
    def summary(self, alpha: float = 0.05, intervals: ConfidenceIntervals | None = None) -> str:
        """A table of estimates, standard errors and Wald intervals, ending with numbered notes (for an estimate
        that is not bounded: where the parameters run off and what the data determine).

        ``summary`` only reads: it runs no fit.  ``intervals`` (e.g. ``est.conf_int(method="profile")``) are
        shown as a note; when the Bates-Watts curvature says the linearisation is not trustworthy, the note
        says how to compute them.
        """
        if self.unbounded is not None:
            return unbounded_summary(self, alpha, intervals)
        ci = self.conf_int(alpha)
        lines = [f"Identification of {self.model_name or 'model'}",
                 f"  status: {self.status} ({self.message}); iterations {self.iterations}, "
                 f"{self.solve_time:.3g} s",
                 f"  data: n = {self.n_data} values, dof = {self.dof}; sensors used: "
                 f"{', '.join(s for s, w in zip(self.sensors, self.weights) if w > 0)}",
                 f"  objective {self.objective:.6g}, RSS {self.rss:.6g}, reduced chi2 {self.reduced_chi2:.4g}"
                 + (" (sigma estimated)" if self.sigma_estimated else ""),
                 ""]
        w = max(9, max(len(n) for n in self.param_names))
        pct = f"{100 * (1 - alpha):g}%"
        lines.append(f"{'parameter':<{w}} {'estimate':>14} {'std err':>11} {'std err GN':>11} "
                     f"{pct + ' lower':>14} {pct + ' upper':>14}  unit")
        for i, n in enumerate(self.param_names):
            lines.append(f"{n:<{w}} {self.p[i]:>14.7g} {self.stderr[i]:>11.4g} {self.stderr_gn[i]:>11.4g} "
                         f"{ci.lower[i]:>14.7g} {ci.upper[i]:>14.7g}  {self.param_units[i]}")
        if self.n_p > 1:
            lines.append("")
            lines.append("correlation (second-order covariance):")
            for i, n in enumerate(self.param_names):
                lines.append(f"  {n:<{w}} " + " ".join(f"{c:>7.3f}" for c in self.correlation[i]))
            lines.append("")
            lines.append(str(self.sloppy_direction))
        notes = self._summary_notes(intervals)
        if notes:
            lines.append("")
            lines.append("Notes:")
            for k, note in enumerate(notes, 1):
                lines.append(f"[{k}] {note}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """The essentials as JSON-safe values (what a report's results.json holds per variant): model, params,
        units, p, stderr, stderr_gn, cov, cov_gn, correlation, conf_int_95 (the 95 % Wald intervals, (n_p, 2)
        [lower, upper] rows), status, message, iterations, solve_time (s), n_data, dof, objective, rss,
        reduced_chi2, sigma, sigma_estimated, sensors, weights and notes (NaN as null, +-inf as "inf"/"-inf")."""
        return jsonable(dict(model=self.model_name, params=list(self.param_names), units=list(self.param_units),
                             p=self.p, stderr=self.stderr, stderr_gn=self.stderr_gn, cov=self.cov, cov_gn=self.cov_gn,
                             correlation=self.correlation, conf_int_95=np.asarray(self.conf_int(0.05)),
                             status=self.status, message=self.message, iterations=self.iterations,
                             solve_time=self.solve_time, n_data=self.n_data, dof=self.dof, objective=self.objective,
                             rss=self.rss, reduced_chi2=self.reduced_chi2, sigma=self.sigma,
                             sigma_estimated=self.sigma_estimated, sensors=list(self.sensors), weights=self.weights,
                             notes=list(self.notes)))

def identify(model, data, p0, weights=None, settings: IdentifySettings | None = None, Y0=None,
             discretisation=None, *, starts: int = 1, seed=0, workers: int | None = 1, scheduler=None) -> Estimate:
    """Weighted nonlinear least squares in full space (paper eq. 3), with covariance (eq. 7):
    min_p 0.5 sum_ijk w_k ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2 subject to E(y_j, p, q_j) = 0.

    The numbers are those of :meth:`identification.fit.problem.Problem.fit` on
    ``Problem(model, data, discretisation)`` (see :func:`identification.fit.estimator.fit_static` for
    the parameters, the pipeline and the errors raised; a dynamic model is collocated with its
    discretisation error controlled, :func:`identification.fit.dynamic_fit.identify_dynamic`); the
    result is an :class:`Estimate`, which adds the intervals (:meth:`Estimate.conf_int`), the
    ellipsoid, the curvature and :meth:`Estimate.summary`.

    Parameters
    ----------
    model : models.Model (static, or dynamic with DynamicMeasurements)
    data : Measurements or DynamicMeasurements
    p0 : array_like (n_p,)       start values (inside the bounds), in the parameters' units
    weights : array_like (n_S,), optional   sensor weights (0/1 selects sensors)
    settings : IdentifySettings, optional
    Y0 : array (n_q, n_y), optional         initial guess of the states (static models)
    discretisation : DiscretisationSettings, optional   collocation settings (dynamic models)
    starts : int >= 1                       fits from p0 and ``starts - 1`` further starts drawn in the bounds
                                            (:mod:`identification.fit.multistart`); the best local minimum is
                                            returned, every start in ``est.diagnostics.starts`` and a note of
                                            summary(); 1 (default): the single fit from p0
    seed : int >= 0, numpy SeedSequence or None   draws the further starts (None: fresh entropy, recorded)
    workers : int or None                   local processes for the starts (1: serially here; None: every core)
    scheduler : Dask address or distributed.Client, optional   run the starts there (``workers`` ignored)

    Returns
    -------
    Estimate
    """
    problem = Problem(model, data, discretisation)
    return Estimate.from_record(problem.fit(p0, weights=weights, settings=settings, Y0=Y0, starts=starts, seed=seed,
                                            workers=workers, scheduler=scheduler))
