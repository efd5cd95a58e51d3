"""The result of one weighted least-squares fit (step 4 of
:func:`identification.fit.estimator.fit_static`): identifiability, the covariances of eq. 7,
plausibility, the diagnostic notes and the :class:`identification.fit.record.FitRecord`."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import special

from identification.fit import dense
from identification.fit.checks import check_identifiability, check_plausible
from identification.fit.factor import estimate_covariances
from identification.fit.ipopt_solver import IpoptResult
from identification.fit.record import FitRecord
from identification.fit.refinement import ReducedPoint, Refinement
from identification.fit.settings import IdentifySettings
from identification.fit.start import Start, decrement_unit

__all__ = ["PhaseClock", "assemble_estimate", "FullSpaceSolution", "sigma_rescaling"]


def sigma_rescaling(rss, dof, sig0) -> tuple:
    """(s^2, s^2 / sigma_0^2) with s^2 = RSS / (n - n_p): the estimated sigma (unknown sigma) and the factor
    that rescales information, objective and covariance from the objective's sigma_0 (scalars or arrays)."""
    s2 = rss / dof
    return s2, s2 / sig0 ** 2


@dataclass(frozen=True)
class FullSpaceSolution:
    """Ipopt's solution of the full-space NLP: its result, the number of passes (1: the
    unbounded pass was kept, 2: the bounded problem was solved), p clipped to the bounds, the
    states, the parameters found at a bound and, when the reduced-space Newton solved it, its
    reduced point at p and the second-order term S there (None when not evaluated)."""

    result: IpoptResult
    passes: int
    p: np.ndarray
    states: np.ndarray | None
    at_bound: np.ndarray
    point: ReducedPoint | None = None
    S: np.ndarray | None = None




class PhaseClock:
    """Wall and CPU seconds (``time.perf_counter``, ``time.process_time``) of the phases of one
    :func:`identify`, recorded in ``Estimate.diagnostics.timing`` as {phase: (wall s, CPU s)}."""

    def __init__(self):
        self._wall, self._cpu = time.perf_counter(), time.process_time()
        self.phases: dict = {}

    def lap(self, name: str) -> None:
        """Charge the time since the previous lap (or the start) to phase ``name``."""
        w, c = time.perf_counter(), time.process_time()
        old = self.phases.get(name, (0.0, 0.0))
        self.phases[name] = (old[0] + w - self._wall, old[1] + c - self._cpu)
        self._wall, self._cpu = w, c



def assemble_estimate(st: Start, sol: FullSpaceSolution, ref: Refinement, settings: IdentifySettings,
              t_start: float, clock: PhaseClock | None = None, escaped: tuple = ()) -> FitRecord:
    """Step 4 of :func:`identify`: identifiability, covariance (eq. 7) and the result.

    With sigma unknown the covariance, information and objective are rescaled by
    s^2 / sigma_0^2 with s^2 = RSS / (n - n_p).
    """
    model, data, point = st.model, st.data, ref.point
    sens = point.sens
    cond = check_identifiability(model, sens.G, st.problem.cw, st.sig, st.s_p, settings.rank_rtol, st.selected,
                                 None if ref.factor is None else ref.factor.sv[0])
    F = ref.information
    resid = data.z - sens.h[None]
    rss = float(np.nansum(resid[:, :, st.selected] ** 2))
    dof = st.n - model.n_p
    if data.sigma is None:
        s2, factor = sigma_rescaling(rss, dof, st.sig[0])
        sig_used = np.full(model.n_S, math.sqrt(s2))
    else:
        factor = 1.0
        sig_used = st.sig
    # from the QR factor of sqrt(Omega) J (not the normal equations): issue 20
    cov, cov_gn, H_ok, sv, K_eig = estimate_covariances(sens.G, st.problem.cw, st.w, st.sig, ref.S, ref.factor)
    H = F + ref.S
    cov, cov_gn = cov * factor, cov_gn * factor
    check_plausible(model.param_names, st.s_p, point.p, cov, cov_gn, sol.result.status)
    objective = point.objective / factor if data.sigma is None else point.objective
    notes = _notes(st, sol, ref, settings, cond, H, H_ok, objective, rss, dof)
    for e in escaped:
        notes += (f"the solver first stopped at a saddle point (RSS {e['rss']:.6g}, Hessian "
                  f"eigenvalue {e['eigenvalue']:.3g} in Gauss-Newton units); restarted from a lower point along "
                  "its direction of negative curvature",)
    res = sol.result
    extra = {"newton_decrement": ref.decrement / factor, "solver": res.stats.get("solver", "ipopt"),
             "ipopt_iterations": 0 if "solver" in res.stats else res.iterations, "ipopt_passes": sol.passes,
             "singular_values": sv, "hessian_eigenvalues": K_eig, "refinement_stop": ref.stop_reason,
             "saddle_escapes": escaped}
    if "t_wall_callbacks" in res.stats:
        extra["ipopt_timing"] = {"build": res.stats["t_build"], "nlpsol": res.stats["t_nlpsol"],
                                 "solve": res.wall_time, "callbacks": dict(res.stats["t_wall_callbacks"])}
    if clock is not None:
        clock.lap("identifiability, covariance, notes")
        extra["timing"] = dict(clock.phases)
    return FitRecord(
        p=point.p, param_names=model.param_names, param_units=tuple(par.unit for par in model.params),
        sensors=model.sensors, states=point.states, fitted=sens.h, residuals=resid, weights=st.w, sigma=sig_used,
        sigma_estimated=data.sigma is None, n_data=st.n, dof=dof, rss=rss, objective=objective,
        information=F / factor, S=ref.S / factor, H=H / factor, cov=cov, cov_gn=cov_gn, G=sens.G,
        status=res.status, message=res.message, iterations=res.iterations,
        solve_time=time.perf_counter() - t_start, refinement_steps=ref.steps,
        grad_norm=float(np.linalg.norm(point.gradient * st.s_p)), notes=notes, model_name=model.name,
        extra=extra, model=model, data=data)



def _notes(st, sol, ref, settings, cond, H, H_ok, objective, rss, dof) -> tuple:
    """The diagnostic notes of an estimate: solver status, unknown sigma, bounds, conditioning,
    size of the second-order term, definiteness of H and the chi^2 test of the residuals."""
    model, data, res = st.model, st.data, sol.result
    notes = []
    if res.accepted is None:
        dec = ref.decrement / decrement_unit(st, ref.point.objective)
        notes.append(f"Ipopt stalled ({res.status}); the exact Newton refinement verified the optimum "
                     f"(Newton decrement {dec:.1e}, i.e. within {math.sqrt(max(dec, 0)):.1e} "
                     "standard errors)")
    elif res.status != "Solve_Succeeded":
        notes.append(f"not converged to full tolerance: Ipopt status {res.status} ({res.message})")
    if data.sigma is None:
        s2 = rss / dof
        notes.append(f"sigma unknown: estimated s = {math.sqrt(s2):.4g} from RSS / (n - n_p) with {dof} dof; "
                     "intervals use Student t, the ellipsoid n_p F(n_p, dof) quantiles")
    for i in np.flatnonzero(sol.at_bound):
        notes.append(f"parameter {model.param_names[i]} is at a bound ({ref.point.p[i]:g}): the covariance assumes "
                     "an interior optimum and is not valid for it")
    F, S = ref.information, ref.S
    Dn = 1.0 / np.sqrt(np.diag(F))
    Fn = F * np.outer(Dn, Dn)
    Sn = S * np.outer(Dn, Dn)
    if cond ** 2 > settings.ill_conditioned:
        notes.append(f"ill-conditioned: the normalised information J^T Omega J has condition number "
                     f"{cond ** 2:.2e}; parameters are strongly correlated and their errors large")
    s_ratio = dense.singular_values(Sn)[0] / dense.singular_values(Fn)[0]     # ||Sn||_2 / ||Fn||_2
    if s_ratio > settings.s_ratio_note:
        notes.append(f"second-order term large: ||S|| is {100 * s_ratio:.3g} % of ||J^T Omega J|| (normalised); "
                     "the model fits poorly or is strongly nonlinear, so cov and cov_gn differ")
    if H_ok and dense.sym_eigenvalues(H * np.outer(Dn, Dn))[0] <= 0:
        notes.append("H = J^T Omega J + S is not positive definite: the estimate is not a strict local "
                     "minimum in the reduced space; treat cov with caution")
    if data.sigma is not None and dof > 0:
        chi2 = 2.0 * objective
        pval = float(special.chdtrc(dof, chi2))           # = stats.chi2.sf(chi2, dof), without its overhead
        if pval < 1e-3:
            notes.append(f"residuals exceed the sensor sigmas: reduced chi2 = {chi2 / dof:.3g} "
                         f"(chi2 test p = {pval:.2g}); the model or the sigmas are inadequate and cov "
                         "understates the uncertainty")
    return tuple(notes)
