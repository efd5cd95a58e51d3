r"""The split tests of many campaigns of one design, fitted together or one by one.

:func:`batched_split_tests` gives ``run_split_tests(model, d, splits, ...)`` of
:func:`identification.studies.detect.run_split_tests` for every campaign d, with the fits of all
campaigns done together: every calibration, validation and pooled fit of a split is one
:func:`identification.fit.batch.fit_batch` call over the campaigns (same estimates as
:func:`identification.identify` to ~1e-10, identify as recorded per-member fallback), and the
statistics (Wald distances and the likelihood ratio or F statistic) are computed for all
campaigns at once with the same formulas.  :func:`shapiro_pvalues` gives the normality-gate
p-values of many campaigns at once.

How a study fits its campaigns is a :class:`SplitFits` strategy chosen once: :data:`BATCHED`
(the functions above) or :data:`ONE_BY_ONE` (one run_split_tests, i.e. identify per fit, per
campaign).  The Monte Carlo studies (:mod:`identification.studies.montecarlo`) and bootstrap
detection (:mod:`identification.studies.detect_bootstrap`) take one.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Callable, Sequence

import numpy as np
from scipy import special, stats

from models.contract import Model
from identification.errors import DataError, IdentificationError
from identification.fit.batch import BatchData, BatchFit, fit_batch
from identification.fit.measurements import Measurements
from identification.fit.unbounded import not_bounded_reason
from identification.studies.detect import DetectSettings, SplitTest, normality_check, run_split_tests
from identification.studies.split_tests import FitFailure
from identification.studies.splits import Split, SplitError

__all__ = ["BATCHED", "ONE_BY_ONE", "BatchedSplitFits", "OneByOneSplitFits", "SplitFits",
           "batched_split_tests", "shapiro_pvalues"]


def _given(fit: BatchFit, member: int):
    """A member's estimate for run_split_tests(fits=...): the estimate, or the exception of its fit."""
    try:
        return fit.result(member)
    except (IdentificationError, DataError) as exc:
        return exc


def _pooled_starts(model: Model, split: Split, fits: list, n_q_u: int) -> tuple:
    """Start values of the pooled fits: the precision-weighted mean (F_c + F_v)^{-1} (F_c p_c + F_v p_v)
    of each member's two estimates with their states (as detect's pooled Newton; moved to p by the
    tangent y' (p - p_est) when the fit is a batch member); NaN (start at p0)
    where it is singular or outside the bounds."""
    qs_c, qs_v = list(split.cal_inputs), list(split.val_inputs)
    qs = sorted(set(qs_c) | set(qs_v))
    P = np.full((len(fits), model.n_p), np.nan)
    Y = np.zeros((len(fits), n_q_u, model.n_y))
    for k, (ec, ev) in enumerate(fits):
        Fc, Fv = ec.information, ev.information
        try:
            p = np.linalg.solve(Fc + Fv, Fc @ ec.p + Fv @ ev.p)
        except np.linalg.LinAlgError:
            continue
        if not (np.all(p > model.lower) and np.all(p < model.upper)):
            continue
        if model.n_y:
            for j_list, est in ((qs_c, ec), (qs_v, ev)):
                rows = [qs.index(j) for j in j_list]
                Y[k, rows] = est.states
                yp = getattr(est, "state_derivatives", None)       # tangent predictor y(p) ~ y + y' (p - p_est)
                if yp is not None:
                    Y[k, rows] += yp @ (p - est.p)
        P[k] = p
    return P, Y


class _Subsets:
    """Picklable member -> Measurements of a split's subset (the data of a fallback fit)."""

    def __init__(self, ds: list, subset: Callable):
        self.ds, self.subset = ds, subset

    def __call__(self, r: int) -> Measurements:
        return self.subset(self.ds[r])


def _split_batch(ds: list, Z: np.ndarray, sig, inputs, series, subset: Callable, sensors=None) -> BatchData:
    """The stacked data of one subset (inputs, series[, sensors]) of every replication (as Split.calibration
    etc.: the values of the other sensors missing)."""
    ser = list(range(Z.shape[1])) if series is None else list(series)
    rows = list(inputs)
    z = Z[:, ser][:, :, rows]
    if sensors is not None:
        z = z.copy()
        z[..., [k for k in range(Z.shape[3]) if k not in set(sensors)]] = np.nan
    return BatchData(ds[0].inputs[rows], z, sig, _Subsets(ds, subset))


def _pooled_batch(ds: list, Z: np.ndarray, sig, split: Split, members: list) -> BatchData:
    """The stacked pooled data of a split for ``members`` (as Split.pooled: NaN outside the pooled values)."""
    pts = split.pooled_points(Z.shape[1])
    qs = sorted({j for j, _ in pts})
    series = sorted({i for _, i in pts})
    mask = split.pooled_mask(Z.shape[1], Z.shape[2], Z.shape[3])[np.ix_(series, qs, range(Z.shape[3]))]
    zp = np.where(mask[None], Z[members][:, series][:, :, qs], np.nan)
    return BatchData(ds[0].inputs[qs], zp, None if sig is None else sig[members],
                     _Subsets([ds[r] for r in members], split.pooled))


def _batched_fits(model: Model, splits: tuple, p0: np.ndarray, weights, det: DetectSettings, ds: list,
                  st0) -> tuple:
    """The fits of run_split_tests for R data sets of one model with the same inputs: every
    calibration, validation and pooled fit of a split is one :func:`identification.fit.batch.fit_batch`
    call over the data sets.  Returns (fits, pooled, ok_split): per data set the (calibration,
    validation) estimates of every split and {pooled points: pooled estimate or FitFailure} (the
    ``fits`` and ``pooled`` arguments of run_split_tests), and per split whether it fits the data.

    A fit_batch call that raises LinAlgError (a singular system for the batch as a whole, e.g. a
    subset that cannot identify the parameters) leaves its fits out (None): run_split_tests then
    runs identify on each of them, which names the failure as it does without the batch engine."""
    R, n_q, n_M = len(ds), ds[0].n_q, ds[0].n_M
    n_sel = int(np.count_nonzero(ds[0].sensor_weights(weights) > 0))
    fits = [[(None, None)] * len(splits) for _ in range(R)]
    Z = np.stack([d.z for d in ds])
    sig = None if ds[0].sigma is None else np.stack([np.asarray(d.sigma, float) for d in ds])
    ok_split = []
    for js, split in enumerate(splits):
        try:
            split.check(n_q, n_M, model.n_p, n_sel)
        except SplitError:
            ok_split.append(False)
            continue
        ok_split.append(True)
        got = []
        for sub, rows, series, sens in ((split.calibration, split.cal_inputs, split.cal_series, split.cal_sensors),
                                        (split.validation, split.val_inputs, split.val_series, split.val_sensors)):
            try:
                bf = fit_batch(model, _split_batch(ds, Z, sig, rows, series, sub, sens), p0, weights, det.identify,
                               Y0=None if st0 is None else st0[list(rows)])
            except np.linalg.LinAlgError:
                got.append([None] * R)         # singular batch (e.g. rank-deficient subset): identify per member
                continue
            got.append([_given(bf, r) for r in range(R)])
        for r in range(R):
            fits[r][js] = (got[0][r], got[1][r])
    pooled = [{} for _ in range(R)]
    done_keys = {}
    for js, split in enumerate(splits):
        if not ok_split[js]:
            continue
        key = split.pooled_key(n_M)
        have = done_keys.setdefault(key, set())
        members = [r for r in range(R)
                   if r not in have and not any(e is None or isinstance(e, Exception) or not_bounded_reason(e)
                                                for e in fits[r][js])]
        if not members:
            continue
        have.update(members)
        qs = sorted({j for j, _ in split.pooled_points(n_M)})
        P, Y = _pooled_starts(model, split, [fits[r][js] for r in members], len(qs))
        try:
            bf = fit_batch(model, _pooled_batch(ds, Z, sig, split, members), p0, weights, det.identify,
                           Y0=None if st0 is None else st0[qs], starts=P, start_states=Y if model.n_y else None)
        except np.linalg.LinAlgError:
            continue                           # run_split_tests fits these pooled data itself
        for k, r in enumerate(members):
            e = _given(bf, k)
            if isinstance(e, Exception):
                pooled[r][key] = FitFailure.from_error(e, "pooled fit failed: ")
            else:
                pooled[r][key] = FitFailure(f"pooled fit {not_bounded_reason(e)}", "not bounded") if not_bounded_reason(e) else e
    return fits, pooled, ok_split


def _covariances(fits: list, det: DetectSettings, n_p: int) -> tuple:
    """(p (R, 2, n_p), C (R, 2, n_p, n_p), regular (R,)) of the calibration and validation fits of one
    split; regular False where a fit failed."""
    R = len(fits)
    P = np.full((R, 2, n_p), np.nan)
    C = np.full((R, 2, n_p, n_p), np.nan)
    regular = np.ones(R, bool)
    second = det.covariance == "second_order"
    for r, pair in enumerate(fits):
        for i, est in enumerate(pair):
            if isinstance(est, Exception) or est is None:
                regular[r] = False
                continue
            P[r, i] = est.p
            C[r, i] = est.cov if second else est.cov_gn
    return P, C, regular


def _batched_cholesky(C: np.ndarray) -> tuple:
    """(L, ok): the lower Cholesky factors of a stack (m, n, n) (numpy.linalg.cholesky), ok False (L the
    identity) where a matrix is not finite or not positive definite."""
    n = C.shape[-1]
    ok = np.all(np.isfinite(C), axis=(1, 2))
    A = np.where(ok[:, None, None], C, np.eye(n))
    try:
        return np.linalg.cholesky(A), ok
    except np.linalg.LinAlgError:
        L = np.broadcast_to(np.eye(n), A.shape).copy()
        for i in np.flatnonzero(ok):
            try:
                L[i] = np.linalg.cholesky(A[i])
            except np.linalg.LinAlgError:
                ok[i] = False
        return L, ok


def _wald_d2(D: np.ndarray, C: np.ndarray) -> tuple:
    """(d2, ok) with d2 = D^T C^{-1} D for stacks D (m, n), C (m, n, n), as
    :func:`identification.inference.regions.mahalanobis2` (Cholesky of (C + C^T)/2); ok False where it would raise
    CovarianceError (C not finite, not symmetric to rtol 1e-8 / atol 1e-14 max|C|, not positive definite)."""
    Ct = C.swapaxes(1, 2)
    with np.errstate(invalid="ignore"):
        atol = 1e-14 * np.abs(C).max(axis=(1, 2))
        sym = np.all(np.abs(C - Ct) <= atol[:, None, None] + 1e-8 * np.abs(Ct), axis=(1, 2))
    L, ok = _batched_cholesky(0.5 * (C + Ct))
    ok &= sym
    v = np.linalg.solve(L, np.where(ok[:, None], D, 0.0)[:, :, None])[:, :, 0]
    return np.einsum("mi,mi->m", v, v), ok


def _split_statistics(model: Model, name: str, splits: tuple, det: DetectSettings, n_M: int, fits: list,
                      pooled: list, ok_split: list) -> list:
    """The split tests of R data sets from their batched fits, computed together: per data set the
    tuple of :class:`identification.studies.detect.SplitTest` that :func:`run_split_tests` gives with these
    fits (same formulas: Wald distances by Cholesky of the symmetrised covariance, the likelihood
    ratio 2 (Phi_pooled - Phi_cal - Phi_val) or, sigma estimated, the F (Chow) test).

    None for a data set that is not regular (a failed fit or pooled fit, a covariance that is not
    symmetric positive definite, a likelihood ratio that is not computable or clearly negative): the
    caller runs run_split_tests on it, which records the failures with their messages."""
    n_p, R = model.n_p, len(fits)
    regular = np.ones(R, bool)
    res = []
    for js, split in enumerate(splits):
        if not ok_split[js]:
            return [None] * R
        P, C, reg = _covariances([f[js] for f in fits], det, n_p)
        D = P[:, 1] - P[:, 0]
        d2p, okp = _wald_d2(D, C[:, 0])
        d2t, okt = _wald_d2(D, C[:, 0] + C[:, 1])
        reg &= okp & okt
        key = split.pooled_key(n_M)
        stat = np.full(R, np.nan)
        sig_est = np.zeros(R, bool)
        num, scale, dof = np.zeros(R), np.ones(R), np.zeros(R)
        for r in np.flatnonzero(reg):
            est_c, est_v = fits[r][js]
            est_u = pooled[r].get(key)
            if est_u is None or isinstance(est_u, FitFailure):
                reg[r] = False
                continue
            sig_est[r] = est_c.sigma_estimated
            if sig_est[r]:
                dof[r] = est_c.n_data + est_v.n_data - 2 * n_p
                rss_sep = est_c.rss + est_v.rss
                if dof[r] <= 0 or not rss_sep > 0:
                    reg[r] = False
                    continue
                num[r], scale[r] = est_u.rss - rss_sep, rss_sep
                stat[r] = (num[r] / n_p) / (rss_sep / dof[r])
            else:
                num[r] = 2.0 * (est_u.objective - est_c.objective - est_v.objective)
                scale[r] = 2.0 * max(est_u.objective, 1.0)
                stat[r] = num[r]
        reg &= ~(num < -1e-7 * scale)
        stat = np.maximum(stat, 0.0)
        a_lr = np.where(sig_est, stats.f.sf(stat, n_p, np.maximum(dof, 1)), special.chdtrc(n_p, stat))
        regular &= reg
        res.append((P, C, d2p, d2t, special.chdtrc(n_p, d2p), special.chdtrc(n_p, d2t), stat, a_lr))
    out = [None] * R
    for r in np.flatnonzero(regular):
        tests = []
        for js, (split, (P, C, d2p, d2t, a_p, a_t, stat, a_lr)) in enumerate(zip(splits, res)):
            est_c, est_v = fits[r][js]
            notes = (tuple(f"calibration fit: {n}" for n in est_c.notes)
                     + tuple(f"validation fit: {n}" for n in est_v.notes))
            c, v = split.label()
            tests.append(SplitTest(name, split.name, c, v, True, "", "", P[r, 0], P[r, 1], C[r, 0], C[r, 1],
                                   float(d2p[r]), float(d2t[r]), float(a_p[r]), float(a_t[r]), est_c.n_data,
                                   est_v.n_data, notes, float(stat[r]), float(a_lr[r]), ""))
        out[r] = tuple(tests)
    return out


def _same_design(datasets) -> list:
    """``datasets`` as a list of Measurements with the same inputs, series count and kind of sigma
    (DataError naming the argument otherwise)."""
    if isinstance(datasets, Measurements):
        raise TypeError("datasets: expected a sequence of Measurements, got one Measurements (wrap it in a list)")
    ds = list(datasets)
    if not ds:
        raise DataError("datasets: give at least one data set")
    bad = [type(d).__name__ for d in ds if not isinstance(d, Measurements)]
    if bad:
        raise TypeError(f"datasets: expected identification.Measurements, got {bad[0]}")
    d0 = ds[0]
    for r, d in enumerate(ds[1:], 1):
        if d.inputs.shape != d0.inputs.shape or not np.array_equal(d.inputs, d0.inputs):
            raise DataError(f"datasets: data set {r} has other inputs than data set 0; group the data sets by their "
                            "inputs and call once per group")
        if d.n_M != d0.n_M or d.z.shape != d0.z.shape:
            raise DataError(f"datasets: data set {r} has values of shape {d.z.shape}, data set 0 {d0.z.shape}; "
                            "give data sets of one shape")
        if (d.sigma is None) != (d0.sigma is None):
            raise DataError(f"datasets: data set {r} and data set 0 differ in whether sigma is known; give "
                            "sigma for all or for none")
    return ds


def batched_split_tests(model: Model, name: str | None, datasets, splits: Sequence[Split], p0, weights=None,
                        detect_settings: DetectSettings | None = None, start_states=None) -> list:
    """``run_split_tests(model, d, splits, p0, weights, detect_settings, name, start_states)`` for every
    data set d of ``datasets``, the fits of all data sets done together by the batch engine.

    Every calibration, validation and pooled fit of a split is one
    :func:`identification.fit.batch.fit_batch` call over the data sets (same estimates as
    :func:`identification.identify` to ~1e-10; identify as recorded per-member fallback), and the
    statistics (Wald distances d2 and the likelihood ratio or F statistic, chi^2 / F units, with
    their p-values alpha_min) are computed for all data sets at once with the formulas of
    :func:`identification.studies.detect.run_split_tests`.  A data set with a failed fit, a covariance that
    is not symmetric positive definite or a likelihood ratio that cannot be computed goes through
    run_split_tests itself (with the batch's fits), which records each failure with its stage and
    message, so failures are named exactly as there.

    Parameters
    ----------
    model : Model
    name : str or None               model label in the SplitTest records (None: the model's name)
    datasets : sequence of Measurements
        The R data sets: the same inputs, the same shape of values (n_M, n_q, n_S) and sigma known
        for all or for none (missing values may differ).  Group data sets by their inputs first.
    splits : sequence of Split
    p0 : array_like (n_p,)           start of every fit
    weights : array_like (n_S,), optional   sensor weights (0/1 selects sensors)
    detect_settings : DetectSettings, optional   covariance kind and identify settings
    start_states : array (n_q, n_y), optional   states at p0 for every input (warm start)

    Returns
    -------
    list of tuple of SplitTest
        One tuple (one SplitTest per split) per data set, in the order of ``datasets``.

    Raises
    ------
    TypeError, DataError, SplitError
        A bad argument (the message names it).
    """
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    ds = _same_design(datasets)
    splits = tuple(splits)
    if not splits or not all(isinstance(sp, Split) for sp in splits):
        raise SplitError("splits: give at least one identification.studies.splits.Split")
    det = detect_settings or DetectSettings()
    if not isinstance(det, DetectSettings):
        raise TypeError(f"detect_settings: expected DetectSettings, got {type(det).__name__}")
    p0 = np.asarray(p0, float).ravel()
    if p0.shape != (model.n_p,):
        raise DataError(f"p0: expected {model.n_p} values ({', '.join(model.param_names)}), got {p0.size}")
    if start_states is not None:
        start_states = np.asarray(start_states, float)
        if start_states.shape != (ds[0].n_q, model.n_y):
            raise DataError(f"start_states: expected the states at p0 of shape {(ds[0].n_q, model.n_y)}, got "
                            f"{start_states.shape}")
    name = name or model.name
    fits, pooled, ok_split = _batched_fits(model, splits, p0, weights, det, ds, start_states)
    out = _split_statistics(model, name, splits, det, ds[0].n_M, fits, pooled, ok_split)
    for r, tests in enumerate(out):
        if tests is None:
            out[r] = run_split_tests(model, ds[r], splits, p0, weights, det, name, start_states, fits=fits[r],
                                     pooled=pooled[r])
    return out


def shapiro_pvalues(ds: list) -> list:
    """``normality_check(d).pvalue`` of every data set: the Shapiro-Wilk p-values per sensor of the
    differences of pairs of series.  Data sets without missing values and of a common shape are
    tested in one ``scipy.stats.shapiro(..., axis=0)`` call (the same test per column); the others
    by :func:`identification.studies.detect.normality_check`."""
    out = [None] * len(ds)
    groups = {}
    for r, d in enumerate(ds):
        if d.n_M >= 2 and np.all(np.isfinite(d.z)):
            groups.setdefault(d.z.shape, []).append(r)
        else:
            out[r] = normality_check(d).pvalue
    for (n_M, n_q, n_S), rows in groups.items():
        n_pairs = n_M // 2
        Z = np.stack([ds[r].z for r in rows])                                   # (m, n_M, n_q, n_S)
        D = (Z[:, 1:2 * n_pairs:2] - Z[:, 0:2 * n_pairs:2]).reshape(len(rows), n_pairs * n_q, n_S)
        cols = D.transpose(1, 0, 2).reshape(n_pairs * n_q, -1)
        pv = np.full(cols.shape[1], np.nan)
        ok = np.ptp(cols, axis=0) > 0 if cols.shape[0] >= 3 else np.zeros(cols.shape[1], bool)
        if np.any(ok):
            pv[ok] = stats.shapiro(cols[:, ok], axis=0).pvalue
        for k, r in enumerate(pv.reshape(len(rows), n_S)):
            out[rows[k]] = r
    return out


# ---------------------------------------------------------------------------- strategies
class SplitFits(ABC):
    """How the split tests of the campaigns of one design are fitted (a strategy chosen once per study).

    Attributes
    ----------
    min_chunk, max_chunk : int
        Campaigns per chunk of a bootstrap detection without ``chunk_size``: about 4 chunks per
        worker, at least ``min(n, min_chunk)`` and at most ``max_chunk`` (a batch pays a per-call
        cost once per chunk).
    """

    min_chunk: int
    max_chunk: int

    @abstractmethod
    def split_tests(self, model: Model, name: str, datasets: list, splits: tuple, p0, weights,
                    detect_settings: DetectSettings, start_states) -> list:
        """``run_split_tests(model, d, splits, p0, weights, detect_settings, name, start_states)`` of every
        campaign d of ``datasets`` (same inputs): one tuple of SplitTest per campaign."""

    @abstractmethod
    def shapiro(self, datasets: list) -> list:
        """``normality_check(d).pvalue`` of every campaign d (the gate's p-values per sensor)."""


class BatchedSplitFits(SplitFits):
    """The campaigns' fits done together by the batch engine (:func:`batched_split_tests`, :func:`shapiro_pvalues`)."""

    min_chunk, max_chunk = 16, 50

    def split_tests(self, model, name, datasets, splits, p0, weights, detect_settings, start_states) -> list:
        return batched_split_tests(model, name, datasets, splits, p0, weights, detect_settings, start_states)

    def shapiro(self, datasets: list) -> list:
        return shapiro_pvalues(datasets)

    def __repr__(self) -> str:
        return "BATCHED"


class OneByOneSplitFits(SplitFits):
    """One :func:`identification.studies.detect.run_split_tests` (identify per fit) per campaign."""

    min_chunk, max_chunk = 1, 20

    def split_tests(self, model, name, datasets, splits, p0, weights, detect_settings, start_states) -> list:
        return [run_split_tests(model, d, splits, p0, weights, detect_settings, name, start_states)
                for d in datasets]

    def shapiro(self, datasets: list) -> list:
        return [normality_check(d).pvalue for d in datasets]

    def __repr__(self) -> str:
        return "ONE_BY_ONE"


#: the campaigns of a chunk fitted together by the batch engine (the default)
BATCHED = BatchedSplitFits()
#: one run_split_tests (identify per fit) per campaign
ONE_BY_ONE = OneByOneSplitFits()
