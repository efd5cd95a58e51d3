"""What the report shows of a fit whose linearisation cannot be trusted (issue 12).

For one model's fit on all study data: the (1 - alpha) profile-likelihood intervals next to
the Wald ones, the likelihood-ratio region of every parameter pair (the other parameters
re-optimised) next to the linearised ellipse, the sloppiest direction of the information
matrix, and the sentence that tells the engineer which picture to believe.  Everything is
computed once per model (:func:`model_uncertainty`); the builder only draws it.

Which models get these pages (:data:`UNCERTAINTY_CHOICES`): ``"untrusted"`` (default) the
models whose Bates-Watts curvature says the linearisation is NOT trustworthy
(:func:`reports.view.linearisation_trust`), ``"all"`` every fitted model, ``"none"`` none.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from identification.errors import IdentificationError
from identification.inference.profile import ConfidenceIntervals, LikelihoodRegion, lr_region
from .view import fmt_value, linearisation_trust, unit_suffix

__all__ = ["UNCERTAINTY_CHOICES", "PairRegion", "ModelUncertainty", "uncertainty_models", "model_uncertainty",
           "region_limits", "region_alpha"]

#: which models get the uncertainty pages
UNCERTAINTY_CHOICES = ("untrusted", "all", "none")

#: the words of linearisation_trust for a fit that must not be read through its ellipse
UNTRUSTED = "NOT trustworthy"


@dataclass(frozen=True)
class PairRegion:
    """The likelihood-ratio region of one parameter pair, or why it could not be computed."""

    pair: tuple
    region: LikelihoodRegion | None
    error: str = ""


def _fmt_end(x: float, se: float) -> str:
    if math.isinf(x):
        return "+inf" if x > 0 else "-inf"
    return fmt_value(x, se)[0]


@dataclass(frozen=True)
class ModelUncertainty:
    """Profile and Wald intervals, pair regions and identifiability of one model's fit.

    Attributes
    ----------
    variant : str                  the model (variant) name
    estimate : identification.Estimate
    trust : str                    "trustworthy", "NOT trustworthy" or "not assessed"
    wald : ndarray (n_p, 2)        (1 - alpha) Wald intervals p -+ q se
    profile : ConfidenceIntervals or None   the profile-likelihood intervals (None: failed, see profile_error)
    profile_error : str
    regions : tuple of PairRegion  every parameter pair (i < j)
    alpha : float
    seconds : float                wall time of the computation
    extent : ConfidenceIntervals or None   the profiles at the pair regions' threshold (:func:`region_alpha`):
                                   the extent of every region along each parameter, and the traces drawn
    extent_error : str
    """

    variant: str
    estimate: object
    trust: str
    wald: np.ndarray
    profile: ConfidenceIntervals | None
    profile_error: str
    regions: tuple
    alpha: float
    seconds: float
    extent: ConfidenceIntervals | None = None
    extent_error: str = ""

    @property
    def pct(self) -> str:
        return f"{100 * (1 - self.alpha):g} %"

    def warning(self) -> str:
        """The sentence telling the engineer which picture to believe (plain text)."""
        e, v = self.estimate, self.variant
        if self.trust == UNTRUSTED:
            c = e.curvature
            return (f"Do NOT trust the confidence ellipses and the +- standard errors of {v}: its linearisation is "
                    f"NOT trustworthy (Bates-Watts maximum relative curvature: intrinsic {c.intrinsic:.3g}, "
                    f"parameter-effects {c.parameter_effects:.3g}; critical value 1/sqrt(F(p, n - p; 0.05)) = "
                    f"{c.critical:.3g}). Use the {self.pct} profile-likelihood intervals of the table below and the "
                    "likelihood-ratio regions (solid red contours), not the Wald intervals and the dashed ellipses.")
        if self.trust == "trustworthy":
            c = e.curvature
            return (f"The linearisation of {v} is trustworthy (Bates-Watts maximum relative curvature: intrinsic "
                    f"{c.intrinsic:.3g}, parameter-effects {c.parameter_effects:.3g}, both below the critical value "
                    f"{c.critical:.3g}): its ellipses and Wald intervals may be used; the profile-likelihood "
                    "intervals and likelihood-ratio regions below show how closely they agree.")
        return (f"The linearisation of {v} was not assessed (no residual degrees of freedom or no curvature): "
                f"prefer the {self.pct} profile-likelihood intervals below to the Wald intervals.")

    def sloppy_text(self) -> str:
        """The weakest direction of the information matrix in words ('' for one parameter)."""
        sd = self.estimate.sloppy_direction
        if sd is None:
            return ""
        return (f"Identifiability: {sd}. The data determine that combination of the parameters poorly; the "
                "regions are long along it.")

    def interval_rows(self) -> tuple:
        """(head, rows, flags) of the interval table: parameter (unit), estimate +- se, Wald and profile
        intervals with the digits of the standard error, and the profile ends relative to the Wald ones."""
        e = self.estimate
        head = ["parameter", "estimate +- std. error", f"{self.pct} Wald interval",
                f"{self.pct} profile-likelihood interval", "profile vs Wald end"]
        rows, flags = [], []
        for i, (name, unit) in enumerate(zip(e.param_names, e.param_units)):
            p, se = float(e.p[i]), float(e.stderr[i])
            v, s = fmt_value(p, se)
            wl, wu = self.wald[i]
            row = [f"{name}{unit_suffix(unit)}", f"{v} +- {s}", f"[{_fmt_end(wl, se)}, {_fmt_end(wu, se)}]"]
            if self.profile is None:
                row += ["failed", self.profile_error[:60]]
                flag = True
            else:
                lo, up = float(self.profile.lower[i]), float(self.profile.upper[i])
                row.append(f"[{_fmt_end(lo, se)}, {_fmt_end(up, se)}]")
                ratio = []
                for side, end, wend in (("lower", lo, wl), ("upper", up, wu)):
                    if math.isinf(end):
                        ratio.append(f"{side} unbounded")
                    else:
                        ratio.append(f"{side} {abs(end - p) / max(abs(wend - p), 1e-300):.2g}x")
                row.append(", ".join(ratio))
                flag = any(math.isinf(x) for x in (lo, up)) or any(
                    abs(abs(end - p) / max(abs(wend - p), 1e-300) - 1) > 0.2
                    for end, wend in ((lo, wl), (up, wu)) if math.isfinite(end))
            rows.append(row)
            flags.append([False, False, flag, flag, flag])
        return head, rows, flags

    def notes(self) -> tuple:
        """Notes of the profile computation and of the regions (unbounded sides, unsolved points)."""
        out = list(self.profile.notes) if self.profile is not None else [f"profile: {self.profile_error}"]
        if self.extent_error:
            out.append(f"extent of the regions (profiles at the pair level): {self.extent_error}")
        for r in self.regions:
            if r.region is None:
                a, b = (self.estimate.param_names[k] for k in r.pair)
                out.append(f"region of ({a}, {b}) not computed: {r.error}")
        return tuple(out)


def uncertainty_models(results, which: str = "untrusted") -> list:
    """The fitted models that get uncertainty pages (``which`` one of :data:`UNCERTAINTY_CHOICES`)."""
    if which not in UNCERTAINTY_CHOICES:
        raise ValueError(f"uncertainty: expected one of {', '.join(repr(c) for c in UNCERTAINTY_CHOICES)}, "
                         f"got {which!r}")
    if which == "none":
        return []
    out = []
    for v, e in results.estimates.items():
        if e.n_p < 1 or e.model is None or e.data is None:
            continue
        if which == "all" or linearisation_trust(e) == UNTRUSTED:
            out.append(v)
    return out


def region_alpha(alpha: float, sigma_estimated: bool, dof: int) -> float:
    """The miss probability alpha' whose single-parameter profile threshold equals the pair-region one.

    The projection of the pair region {D_ij <= c_2} on p_i is {a : D_i(a) <= c_2} exactly (D_i is
    the minimum of D_ij over p_j), i.e. the profile interval at the level whose threshold is c_2:
    alpha' = P(chi2_1 > chi2_2(1 - alpha)) (sigma known) or P(F(1, dof) > 2 F(2, dof; 1 - alpha)).
    """
    from scipy import stats
    from identification.inference.profile import region_threshold
    c2 = region_threshold(alpha, sigma_estimated, dof)
    return float(stats.f.sf(c2, 1, dof) if sigma_estimated else stats.chi2.sf(c2, 1))


def region_limits(estimate, extent, pair, span: float = 1.3, cap: float = 8.0) -> tuple:
    """Grid rectangle of a pair region: the linearised ellipse's extent (``span`` x its half-widths)
    joined with the extent of the likelihood-ratio region (``extent``: the profile intervals at
    :func:`region_alpha`, and their traces), 10 % margin, each side capped at ``cap`` ellipse
    half-widths from the estimate (an unbounded region reaches the cap)."""
    from scipy import stats
    p = np.asarray(estimate.p, float)
    se = np.asarray(estimate.stderr, float)
    half = math.sqrt(stats.chi2.ppf(0.95, 2)) * se
    names = (estimate.param_names[pair[0]], estimate.param_names[pair[1]])
    lim = []
    for k in pair:
        lo, hi = p[k] - span * half[k], p[k] + span * half[k]
        if extent is not None:
            if estimate.param_names[k] in extent.param_names:
                e_lo, e_hi = extent[estimate.param_names[k]]
                lo, hi = min(lo, e_lo), max(hi, e_hi)
            for pr in extent.profiles:
                if pr.name in names:
                    col = pr.params[:, k]
                    lo, hi = min(lo, float(np.min(col))), max(hi, float(np.max(col)))
        lo, hi = max(lo, p[k] - cap * half[k]), min(hi, p[k] + cap * half[k])
        width = hi - lo
        lim.append((lo - 0.1 * width, hi + 0.1 * width))
    return tuple(lim)


def model_uncertainty(results, variant: str, alpha: float = 0.05, n_grid: int | None = None,
                      progress=None) -> ModelUncertainty:
    """Profile intervals, Wald intervals and the likelihood-ratio region of every pair of one model.

    Parameters
    ----------
    results : mudoe.study.StudyResults     (``results.estimates[variant]`` carries model and data)
    variant : str
    alpha : float                           miss probability (0.05: 95 %)
    n_grid : int, optional                  grid points per axis of the pair regions (default 21, 15
                                            beyond 6 pairs)
    progress : identification.progress.Progress, optional   a bar over the profiles and pairs

    A failed profile or region is recorded with its reason (shown on the page), never dropped.
    """
    from identification.inference.profile import ProfileError
    t0 = time.perf_counter()
    e = results.estimates[variant]
    n = e.n_p
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if n_grid is None:
        n_grid = 21 if len(pairs) <= 6 else 15
    bar = progress.bar(len(pairs) + 1, f"uncertainty of {variant}", unit="step") if progress is not None else None
    wald = np.asarray(e.conf_int(alpha), float)
    try:
        prof, perr = e.conf_int(alpha, method="profile"), ""
    except (ProfileError, IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
        prof, perr = None, str(exc).splitlines()[0]
    extent, eerr = None, ""
    if pairs:
        try:
            extent = e.conf_int(region_alpha(alpha, e.sigma_estimated, e.dof), method="profile")
        except (ProfileError, IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            eerr = str(exc).splitlines()[0]
    if bar is not None:
        bar.update(1)
    regions = []
    for pair in pairs:
        try:
            reg = lr_region(e.model, e.data, e, pair, alpha, n_grid=n_grid, grid="valley",
                            limits=region_limits(e, extent, pair))
            regions.append(PairRegion(pair, reg))
        except (IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            regions.append(PairRegion(pair, None, str(exc).splitlines()[0]))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return ModelUncertainty(variant, e, linearisation_trust(e), wald, prof, perr, tuple(regions), alpha,
                            time.perf_counter() - t0, extent, eerr)
