"""Comparing an estimate with a peer optimiser in units that hold on any machine.

A peer (scipy ``least_squares``, lmfit, R) stops when its own tolerances are met; where it stops
depends on the CPU's floating-point kernels, so agreement in raw digits beyond the peer's own
accuracy is not a property of mudoe.  What is true on any machine:

1. the two points agree to a small fraction of a standard error, and
2. mudoe's point is an optimum: the Gauss-Newton step from it is a negligible fraction of a
   standard error (no better point is within reach).

Both are measured in standard errors from the weighted Jacobian J at mudoe's point (QR, not the
normal equations): sd_i = sqrt(s2 * [(J^T J)^-1]_ii).
"""
from __future__ import annotations

import numpy as np

#: The two points may differ by this many standard errors: statistically nothing, and far above
#: where a peer stops.  scipy ``least_squares`` (ftol = xtol = gtol = 1e-15) on the 40 000-point
#: test stops 7e-10 sd short of the optimum with multi-threaded OpenBLAS and 1.9e-6 sd short with
#: OPENBLAS_NUM_THREADS=1 on the same machine (its ftol test fires at another iteration).
AGREE_SD = 1e-4
#: mudoe's Gauss-Newton step, in standard errors, must be below this at its estimate.
STEP_SD = 1e-8


def newton_step_sd(p, resid, jac, s2: float = 1.0) -> np.ndarray:
    """The Gauss-Newton step delta = -J^+ r at ``p`` in standard errors, |delta_i| / sd_i.

    ``resid(p)`` returns the weighted residuals, ``jac(p)`` their Jacobian; ``s2`` scales the
    covariance (1 when sigma is known, RSS / (n - n_p) when it is estimated).
    """
    p = np.asarray(p, float)
    Q, R = np.linalg.qr(np.asarray(jac(p), float))
    r = np.asarray(resid(p), float)
    step = -np.linalg.solve(R, Q.T @ r)
    Rinv = np.linalg.inv(R)
    sd = np.sqrt(s2 * np.sum(Rinv ** 2, axis=1))
    return np.abs(step) / sd


def stderr_at(p, jac, s2: float = 1.0) -> np.ndarray:
    """Standard errors sqrt(s2 [(J^T J)^-1]_ii) from the QR factor of J at ``p``."""
    R = np.linalg.qr(np.asarray(jac(np.asarray(p, float)), float), mode="r")
    return np.sqrt(s2 * np.sum(np.linalg.inv(R) ** 2, axis=1))


def assert_same_optimum(p, p_peer, resid, jac, s2: float = 1.0, agree_sd: float = AGREE_SD,
                        step_sd: float = STEP_SD):
    """Assert that mudoe's ``p`` and a peer's ``p_peer`` agree within ``agree_sd`` standard
    errors and that ``p`` is an optimum (its Gauss-Newton step is below ``step_sd`` sd)."""
    p, p_peer = np.asarray(p, float), np.asarray(p_peer, float)
    sd = stderr_at(p, jac, s2)
    gap = np.abs(p - p_peer) / sd
    assert np.all(gap < agree_sd), f"estimates differ by {gap.max():.3g} sd (allowed {agree_sd:g})"
    step = newton_step_sd(p, resid, jac, s2)
    assert np.all(step < step_sd), f"mudoe's Newton step is {step.max():.3g} sd (allowed {step_sd:g})"



def assert_agree_in_sd(est, p_peer, agree_sd: float = AGREE_SD, step_sd: float = STEP_SD):
    """For peers without an exact Jacobian: ``est.p`` and ``p_peer`` agree within ``agree_sd`` of
    the estimate's Gauss-Newton standard errors, and the estimate's own Newton decrement (its
    distance to the optimum in standard errors, exact AD) is below ``step_sd``."""
    gap = np.abs(np.asarray(est.p) - np.asarray(p_peer, float)) / est.stderr_gn
    assert np.all(gap < agree_sd), f"estimates differ by {gap.max():.3g} sd (allowed {agree_sd:g})"
    dec = est.diagnostics.newton_decrement
    assert dec < step_sd, f"mudoe's Newton decrement is {dec:.3g} sd (allowed {step_sd:g})"
