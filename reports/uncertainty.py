"""What the report shows of a fit whose linearisation cannot be trusted (issue 12).

For one model's fit on all study data: the (1 - alpha) profile-likelihood intervals next to
the Wald ones, the likelihood-ratio region of every parameter pair (the other parameters
re-optimised) next to the linearised ellipse, the sloppiest direction of the information
matrix, and the sentence that tells the engineer which picture to believe.  Everything is
computed once per model by the study (:mod:`mudoe.uncertainty_runs`) into a :class:`ModelUncertainty`;
this module words it and the builder draws it.

Which models get these pages (:data:`UNCERTAINTY_CHOICES`): ``"untrusted"`` (default) the
models whose Bates-Watts curvature says the linearisation is NOT trustworthy
(:func:`mudoe.fit_assessment.linearisation_trust`), ``"all"`` every fitted model, ``"none"`` none.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from identification.inference.profile import ConfidenceIntervals, LikelihoodRegion
from .view import fmt_value, unit_suffix

__all__ = ["UNCERTAINTY_CHOICES", "UNTRUSTED", "PairRegion", "ModelUncertainty", "uncertainty_models"]

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
    """The variants that get uncertainty pages: those of ``results.uncertainty`` (computed by the study,
    :mod:`mudoe.uncertainty_runs`) that ``which`` (one of :data:`UNCERTAINTY_CHOICES`) selects --
    "untrusted" the ones whose linearisation is NOT trustworthy, "all" every one, "none" none."""
    if which not in UNCERTAINTY_CHOICES:
        raise ValueError(f"uncertainty: expected one of {', '.join(repr(c) for c in UNCERTAINTY_CHOICES)}, "
                         f"got {which!r}")
    if which == "none":
        return []
    return [v for v, mu in results.uncertainty.items() if which == "all" or mu.trust == UNTRUSTED]
