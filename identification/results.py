"""The immutable result of an identification: estimate, covariances, diagnostics."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy import stats

from .curvature import Curvature, estimate_curvature
from .identifiability import SloppyDirection, sloppy_direction
from .regions import Ellipsoid

__all__ = ["Estimate"]


@dataclass(frozen=True, eq=False)
class Estimate:
    """Result of :func:`identification.identify`.

    Attributes
    ----------
    p : ndarray (n_p,)            estimated parameters
    param_names : tuple of str
    states : ndarray (n_q, n_y)   states y_j(p) at the estimate
    fitted : ndarray (n_q, n_S)   model outputs h(y_j, p, q_j)
    residuals : ndarray (n_M, n_q, n_S)  z - h (NaN where missing), all sensors
    weights : ndarray (n_S,)      sensor weights used
    sigma : ndarray (n_S,)        sensor sigmas used for the covariance (estimated if unknown)
    sigma_estimated : bool        sigma was estimated as s^2 = RSS / (n - n_p)
    n_data, dof : int             number of used values, n - n_p
    rss : float                   unweighted residual sum of squares over the selected sensors
    objective : float             0.5 sum_k w_k sum_ij ((z_ijk - h_jk)/sigma_k)^2 (sigma as used)
    information : ndarray         J^T Omega J (Gauss-Newton information), (n_p, n_p)
    S : ndarray                   second-order term S(Omega), (n_p, n_p)
    H : ndarray                   J^T Omega J + S
    cov : ndarray                 second-order (Bard) covariance H^-1 J^T Omega^2 J H^-T
    cov_gn : ndarray              Gauss-Newton covariance
    G : ndarray (n_q, n_S, n_p)   total sensitivities dh/dp
    status, message : str         Ipopt's status and its meaning
    iterations : int ; solve_time : float (s) ; refinement_steps : int
    grad_norm : float             ||J^T Omega r|| at the estimate (scaled by parameter scale)
    notes : tuple of str          numbered notes printed by summary()
    model, data                   the models.Model and the Measurements of the fit (None when the
                                  Estimate was built by hand; needed by :attr:`curvature`)
    unbounded : Unbounded or None the data do not bound the parameters: the best fit runs off to
                                  infinity along ``unbounded.direction`` (:mod:`identification.unbounded`);
                                  p is then a point on that path, the standard errors of the parameters
                                  that run off are inf, status is "Not_Bounded".  None: a finite optimum
    """

    p: np.ndarray
    param_names: tuple
    param_units: tuple
    sensors: tuple
    states: np.ndarray
    fitted: np.ndarray
    residuals: np.ndarray
    weights: np.ndarray
    sigma: np.ndarray
    sigma_estimated: bool
    n_data: int
    dof: int
    rss: float
    objective: float
    information: np.ndarray
    S: np.ndarray
    H: np.ndarray
    cov: np.ndarray
    cov_gn: np.ndarray
    G: np.ndarray
    status: str
    message: str
    iterations: int
    solve_time: float
    refinement_steps: int
    grad_norm: float
    notes: tuple = ()
    model_name: str = ""
    extra: dict = field(default_factory=dict)
    model: object = field(default=None, repr=False)
    data: object = field(default=None, repr=False)
    unbounded: object = None

    def __post_init__(self):
        for name in ("p", "states", "fitted", "residuals", "weights", "sigma", "information", "S", "H",
                     "cov", "cov_gn", "G"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    # ------------------------------------------------------------------ derived, cached
    @property
    def n_p(self) -> int:
        return self.p.size

    @property
    def bounded(self) -> bool:
        """The data bound the parameters (a finite optimum); False: see :attr:`unbounded`."""
        return self.unbounded is None

    def require_bounded(self, what: str) -> None:
        """Raise NotBoundedError naming ``what`` needs a bounded estimate (no-op when bounded)."""
        if self.unbounded is not None:
            from .errors import NotBoundedError
            raise NotBoundedError(f"{what}: needs a bounded estimate, but {self.unbounded.reason}; use "
                                  "conf_int(method=\"profile\") and summary() for what the data determine")

    @property
    def success(self) -> bool:
        return self.status == "Solve_Succeeded"

    @cached_property
    def stderr(self) -> np.ndarray:
        """Standard errors from the second-order covariance."""
        return np.sqrt(np.diag(self.cov))

    @cached_property
    def stderr_gn(self) -> np.ndarray:
        """Standard errors from the Gauss-Newton covariance."""
        return np.sqrt(np.diag(self.cov_gn))

    @cached_property
    def correlation(self) -> np.ndarray:
        d = self.stderr
        return self.cov / np.outer(d, d)

    @cached_property
    def reduced_chi2(self) -> float:
        """sum_ijk w_k (r_ijk / sigma_k)^2 / (n - n_p) (1 by construction when sigma was estimated)."""
        return 2.0 * self.objective / self.dof if self.dof > 0 else float("nan")

    @cached_property
    def curvature(self) -> Curvature:
        """Bates-Watts maximum relative intrinsic and parameter-effects curvatures at alpha = 0.05,
        exact from the second derivatives of the model outputs (:mod:`identification.curvature`)."""
        if self.model is None or self.data is None:
            raise ValueError("curvature: this Estimate carries no model/data (build it with identify())")
        self.require_bounded("curvature")
        return estimate_curvature(self, self.model, self.data, 0.05)

    @cached_property
    def sloppy_direction(self) -> SloppyDirection | None:
        """The worst and best determined combinations of relative parameter changes and their
        standard-error ratio, from the information scaled by |p| (None for one parameter)."""
        return sloppy_direction(self.information, self.p, self.param_names)

    def _summary_notes(self) -> tuple:
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
                    notes.append(self._profile_note())
        return tuple(notes)

    def _profile_note(self) -> str:
        """The 95 % profile-likelihood intervals as one note (shown when the linearisation is not trusted)."""
        from .errors import IdentificationError
        try:
            ci = self.conf_int(0.05, method="profile")
        except (IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            return f"profile-likelihood intervals could not be computed: {exc}"
        parts = ", ".join(f"{n} [{lo:.5g}, {hi:.5g}]" for n, lo, hi in zip(self.param_names, ci.lower, ci.upper))
        return (f"95 % profile-likelihood intervals (trust these, not the Wald columns): {parts}"
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
        (``kind="second_order"``) or Gauss-Newton covariance.  Returns an ndarray (m, 2) of
        [lower, upper] rows, as before this method grew other methods.

        ``method="profile"``: {theta : 2 (min_{p_i = theta} Phi - Phi(p_hat)) <= c} with c =
        chi2_1(1 - alpha), or F(1, n - n_p; 1 - alpha) when sigma was estimated (Bates-Watts
        profile-t); see :func:`identification.profile.profile_intervals` (``settings``: a
        ``ProfileSettings``).

        ``method="bootstrap"``: parametric bootstrap percentile intervals from ``n`` refits of data
        simulated from the fit (``seed``, ``workers`` local processes or ``scheduler`` a Dask
        address or Client, ``progress`` a :class:`identification.progress.Progress`); see
        :func:`identification.bootstrap.bootstrap_intervals`.

        For an estimate that is not bounded (:attr:`bounded` False) the Wald intervals of the parameters
        that run off are (-inf, inf) (infinite standard errors); the profile intervals have a finite end
        (the likelihood ratio against the infimum of the objective) and an infinite one; the bootstrap
        raises NotBoundedError.

        Both return a frozen :class:`identification.profile.ConfidenceIntervals` (``lower``,
        ``upper``, ``method``, ``notes``; ``.array`` is the (m, 2) layout of the Wald result); an
        unbounded side is -inf / +inf with a note.  They use the ``model`` and ``data`` the
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
        from . import profile as profile_mod      # deferred: profile imports the estimator, which imports this
        alpha = profile_mod.validate_alpha(alpha)
        if method not in self.CONF_INT_METHODS:
            raise ValueError(f"method: unknown interval method {method!r}; choose one of "
                             f"{', '.join(repr(m) for m in self.CONF_INT_METHODS)}")
        idx = profile_mod.resolve_params(params, tuple(self.param_names))
        if method == "wald":
            se = self._se(kind)
            c = self._quantile(alpha)
            return np.column_stack([self.p - c * se, self.p + c * se])[idx]
        model = self.model if model is None else model
        data = self.data if data is None else data
        if method == "profile":
            return profile_mod.profile_intervals(model, data, self, alpha, idx, settings=settings)
        from .bootstrap import bootstrap_intervals
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
        from . import profile as profile_mod
        alpha = profile_mod.validate_alpha(alpha)
        C = self.cov if kind == "second_order" else self.cov_gn if kind == "gauss_newton" else None
        if C is None:
            raise ValueError(f"kind must be 'second_order' or 'gauss_newton', got {kind!r}")
        if self.sigma_estimated:
            g2 = self.n_p * float(stats.f.ppf(1 - alpha, self.n_p, self.dof))
        else:
            g2 = float(stats.chi2.ppf(1 - alpha, self.n_p))
        return Ellipsoid(self.p.copy(), C.copy(), alpha, g2, self.param_names)

    # ------------------------------------------------------------------ report
    def summary(self, alpha: float = 0.05) -> str:
        """A table of estimates, standard errors and intervals, ending with numbered notes (for an estimate
        that is not bounded: where the parameters run off, the profile intervals and what the data determine)."""
        if self.unbounded is not None:
            from .unbounded import unbounded_summary
            return unbounded_summary(self, alpha)
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
                         f"{ci[i, 0]:>14.7g} {ci[i, 1]:>14.7g}  {self.param_units[i]}")
        if self.n_p > 1:
            lines.append("")
            lines.append("correlation (second-order covariance):")
            for i, n in enumerate(self.param_names):
                lines.append(f"  {n:<{w}} " + " ".join(f"{c:>7.3f}" for c in self.correlation[i]))
            lines.append("")
            lines.append(str(self.sloppy_direction))
        notes = self._summary_notes()
        if notes:
            lines.append("")
            lines.append("Notes:")
            for k, note in enumerate(notes, 1):
                lines.append(f"[{k}] {note}")
        return "\n".join(lines)

    def __repr__(self):
        if self.unbounded is not None:
            return f"Estimate(not bounded: {self.unbounded.reason})"
        vals = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.param_names, self.p))
        return f"Estimate({vals}; status={self.status})"
