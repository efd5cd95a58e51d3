"""Behaviour-unchanged harness (issue 21): save full-precision results of one tree, compare two saves, time workloads.

Only the public API is used (``from identification import identify, ...``, :class:`Estimate` attributes,
``mudoe.config`` / ``mudoe.study.prepare`` and the ``mudoe`` CLI), so the same file runs against the tree
before and after identification/ is split into sub-packages.

``--save DIR`` writes (``--part static`` the first four items, ``--part dynamic`` the rest, ``--part all`` the
default; ``--items`` a subset by name: fits, mc, report, dynfits, dyndesigns, dyndetect, dyncli)

* ``DIR/fits.npz`` (float64, bitwise) and ``DIR/fits.json`` (status, message, notes, summary text) of the
  fits: the press variants M1, M2, M3 on the shipped campaign (configs/press.toml, series 4 and 5),
  spring chains with 30 states (k, c) and 80 states (k1, k2, c), a small two-state model stated in SX and
  the same in MX.  Per fit: p, cov, cov_gn, information, S, H, objective, rss, grad_norm, iterations, status,
  the 95 % Wald intervals and ``summary()`` (its solve time, the only run-dependent number in it, is masked).
  For the SX fit also ``conf_int`` by every method (wald, profile, bootstrap with n = 20 and seed 7),
  converted to (n_p, 2) arrays whatever type ``conf_int`` returns, and the bootstrap replicates;
* ``DIR/mc.npz``: 100 Monte Carlo replications of the press size study (M1 on campaigns simulated from
  itself, the paper's four splits, TOL 5 %, serial in this process, seed 20261121, chunks of 50):
  per replication alpha_paper, alpha_two_sample, alpha_lr, covered, shapiro and the failed splits;
* ``DIR/press_report/results.json``: ``python -m mudoe report configs/press.toml --out DIR/press_report``;
* the dynamic part (issue 28 item 11), numbers in ``DIR/dynamic.npz`` (bitwise), strings in
  ``DIR/dynamic.json`` (exact), one key per field ``NAME/field``:

  - ``dynfits``: the batch reactor (collocation with discretisation error control) on solve_ivp data
    from P0 = (1.5, 50, 1, 70) (key ``reactor``; in fits.npz before issue 28), and every variant of the shipped reactor and oscillator
    studies (``reactor_isothermal``, ``oscillator_cubic``, ``oscillator_linear``) on their shipped campaigns
    from the configs' starts, read by ``mudoe.config.load_config`` + ``mudoe.study.prepare``: the Estimate
    fields of the static fits plus the discretisation record's fields;
  - ``dyndesigns``: ``oed.select_times`` (reactor: D with 4 times, A with 5 time x sensor pairs;
    oscillator: D with 3 of 50 times) and ``oed.select_inputs(..., times=...)`` (2 of 12 (cA0, T) rows of
    the isothermal reactor; 1 of 4 temperature profiles of Pyomo.DoE's reactor, bench.bench_dynamic_doe;
    its nominal experiment refined continuously, one start): chosen, indices, weights, value, lower bound,
    gap, proven_optimal, method, status, message, notes, candidates, information share, and for input
    designs the chosen inputs, the (row, sensor) pairs, the design and the refined levels;
  - ``dyndetect``: ``identification.detect`` and ``identification.validate`` (size study, 8 replications,
    seed 20261127, serial, no JIT) on the shipped reactor campaign split by experiment ("cool vs hot") and
    the oscillator's (cubic and linear; validate only for cubic) ("small vs large steps"): per test every
    SplitTest field (p_cal, p_val, alpha_paper, alpha_two_sample, alpha_lr, lr, ok, stage, labels, notes),
    the verdicts, and per replication the Monte Carlo arrays.  The same on the early/late split alone under
    ``early_late/...`` keys;
  - ``dyncli``: ``python -m mudoe report | detect | validate --runs 5 configs/{reactor,oscillator}.toml
    --out DIR/cli_{config}_{verb}`` in the tree's root: their ``results.json``, ``detect.json``,
    ``validate.json`` (the report's PNGs and PDF are kept but not compared);
* ``DIR/meta.json``: machine, date, tree, CPU seconds per item (never compared).

Robust to the refactoring of issue 28: only package-level names (``from identification import identify,
detect, validate, Split, MonteCarloSettings``, ``from oed import select_times, select_inputs``), the config
route and the CLI are used, with these fallbacks for fields that may be renamed or moved:
``DesignResult.chosen`` is read from ``sensors`` when absent (item 3); a dynamic fit's discretisation
record from ``est.discretisation``, else ``est.extra["discretisation"]`` (item 7); a dynamic study's start
from ``study.p0s[variant]`` (or ``start_values``), else ``study.p0``; the early/late split from the first of
``identification.early_late_split``, ``early_late_dynamic_split`` of ``identification.studies.splits`` or
``identification.studies.dynamic_detect``, ``identification.studies.splits.early_late_split`` that takes the campaign (none: the ``early_late/`` keys
hold a note and the comparison shows them missing).  A field absent from a tree is "only in A/B".

Known intended change (issue 28 item 2): the early/late split rule is unified.  Static cut at
``t <= t[(n-1)//2]``, dynamic at ``t < t[n//2]``: they differ only for an odd number of sampling times
(the oscillator's 25; the reactor's 10 give the same partition), so detection and validation numbers on
early/late splits may change.  ``--compare`` shows them apart: keys under ``early_late/`` and, in the JSON
files, every leaf under a record that names an early/late split ("early (t < 0.52) vs late") or whose key
or value names one; ``--allow-early-late`` accepts them (exit 0 when nothing else differs).  Numbers over
all splits (a verdict, a family-wise rate) that move with them show among the other differences.

``--compare A B`` compares the files either folder holds: per array the largest absolute and relative
difference and whether it is bitwise identical, the differing strings, and for every JSON file each
differing leaf; keys that are timings (``solve_time``, ``wall_time``, ``timing_s``), timestamps, versions,
hosts or paths (and string leaves holding absolute paths) are ignored and listed; date-times in text and
the wall time a Monte Carlo table prints ("serial (this process), 0.6 s") are masked.  Exit code 0 when
everything else is bitwise equal, 1 otherwise.

``--timing`` prints the CPU seconds (time.process_time, this process) of: the press M1 warm fit (median
of 30), 30 Monte Carlo replications serial (bench_detect --study timing --n-rep 30 --workers 1, batch
engine), the branch-and-bound D-optimal 50 x 10 with m = 10 (bench oed --sizes=50x10 --ms=10 --crits=D),
a profile conf_int of the SX fit and a bootstrap conf_int of it with n = 200.  Run it with
OPENBLAS_NUM_THREADS=1 (set here when unset) on an otherwise idle machine, A and B in turn.

CPU on 0b6c053 (2 cores shared with other jobs; this process plus its children): the static part about
27 s (fits 2.2, mc 0.8, press report 23.6), the dynamic part about 57 s (dynfits 1.4, dyndesigns 1.6,
dyndetect 8.1, dyncli 46: reports 11 + 17, detect 3 + 7, validate 3 + 5), 85 s in all with the imports.
DIR is resolved before the CLI runs in the tree's root, and nothing is written elsewhere; run with
PYTHONDONTWRITEBYTECODE=1 to keep __pycache__ out of a tree that must stay untouched.

Run (the tree under test first on the path; the file itself may come from another tree)::

    cd TREE && PYTHONPATH=TREE python bench/bench_unchanged.py --save DIR [--part static|dynamic|all]
    python bench/bench_unchanged.py --compare DIR_A DIR_B          # exit code 0: unchanged
    python bench/bench_unchanged.py --compare DIR_A DIR_B --allow-early-late   # accept issue 28 item 2
    cd TREE && PYTHONPATH=TREE OPENBLAS_NUM_THREADS=1 python bench/bench_unchanged.py --timing

``python -m bench unchanged --save=DIR`` and ``python -m bench unchanged`` (timing, the default) work too;
``python -m bench`` passes only ``--opt=value`` options and drops the exit code, so compare directly.
"""
from __future__ import annotations

import argparse
import difflib
import json
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

#: the fields of an Estimate saved for every fit (arrays and scalars, compared bitwise)
ARRAY_FIELDS = ("p", "cov", "cov_gn", "information", "S", "H", "objective", "rss", "grad_norm", "iterations",
                "sigma", "n_data", "dof")
#: the Monte Carlo arrays of a MonteCarloResult saved per replication
MC_FIELDS = ("alpha_paper", "alpha_two_sample", "alpha_lr", "covered", "shapiro")
MC_SEED, MC_REP, MC_CHUNK = 20261121, 100, 50
BOOT_N, BOOT_SEED = 20, 7
#: results.json keys never compared (run-dependent): a key of a leaf's path holding one of these words
#: (split at "_" and non-letters: "timing_s", "versions", "base_dir"; not "validate"), or ending in the word
#: "time" after another ("solve_time", "wall_time"; not "time_design", "time_windows", "chosen_times")
IGNORED_WORDS = frozenset({"timing", "created", "timestamp", "date", "duration", "elapsed", "wall", "cpu",
                           "version", "versions", "host", "hostname", "machine", "platform", "path", "dir", "pid"})
#: date-times inside text leaves (the report's "Built 2026-11-25 18:19 UTC" line) are masked before comparing
TIMESTAMP = re.compile(r"\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}(:\d{2}(\.\d+)?)?( ?UTC|Z|[+-]\d{2}:?\d{2})?")
#: the wall time a Monte Carlo table prints after its backend ("serial (this process), 0.6 s"), masked too
WALL_IN_TEXT = re.compile(r"(serial \(this process\)|local process(?:es)?|[Dd]ask[^,\n]*), \d+(?:\.\d+)? s")
#: press study (the paper's setting, bench_detect): sensor sigmas (mm), D_y + F_x, start values (N/mm)
SIGMA_PAPER_MM = np.array([1.518e-05, 4.895e-06, 3.904e-06]) * 1e3
WEIGHTS_110 = np.array([1.0, 1.0, 0.0])
P0_PRESS = np.array([450.0, 550.0])


# ---------------------------------------------------------------------------- conversions
def intervals_array(ci) -> np.ndarray:
    """(n_p, 2) float array [lower, upper] of a conf_int result: an ndarray as is, else its lower/upper
    (a ConfidenceIntervals), else ``np.asarray`` of it."""
    if isinstance(ci, np.ndarray):
        return np.array(ci, dtype=float)
    if hasattr(ci, "lower") and hasattr(ci, "upper"):
        return np.column_stack([np.asarray(ci.lower, float), np.asarray(ci.upper, float)])
    return np.array(np.asarray(ci), dtype=float)


def masked_summary(est) -> str:
    """``est.summary()`` with its solve time (wall clock, run-dependent) replaced by ``<time>``."""
    return re.sub(r"(iterations \d+, )\S+ s", r"\1<time> s", est.summary())


def _estimate_record(name: str, est, arrays: dict, texts: dict) -> None:
    """Store an Estimate's fields under ``name/``: numbers into ``arrays``, strings into ``texts``."""
    for f in ARRAY_FIELDS:
        arrays[f"{name}/{f}"] = np.asarray(getattr(est, f))
    arrays[f"{name}/ci_wald"] = intervals_array(est.conf_int(0.05))
    texts[name] = dict(status=est.status, message=est.message, notes=list(est.notes),
                       param_names=list(est.param_names), summary=masked_summary(est))


# ---------------------------------------------------------------------------- the fits
def press_fits(arrays: dict, texts: dict) -> None:
    """M1, M2, M3 on the shipped campaign as ``mudoe identify configs/press.toml`` fits them."""
    from identification import identify
    from mudoe.config import DEFAULT_CONFIG, load_config
    from mudoe.study import prepare
    study = prepare(load_config(DEFAULT_CONFIG))
    for v, m in study.models.items():
        _estimate_record(f"press_{v}", identify(m, study.data[v], study.p0), arrays, texts)


def chain_problem(n_y: int, n_groups: int, n_q: int = 5, seed: int = 0):
    """Spring chain with n_y states, 2 noisy series at n_q load cases, 1 % noise (bench_identify's problem)."""
    from identification import Measurements, simulate
    from models.library import spring_chain
    model = spring_chain(n_y, n_sensors=max(4, n_groups + 2), n_groups=n_groups)
    p_true = np.concatenate([2.0 + 0.2 * np.arange(n_groups), [0.5]])
    Q = np.array([[f, 0.3 * f] for f in np.linspace(0.2, 3.0, n_q)])
    H = simulate(model, p_true, Q)
    sig = 0.01 * np.abs(H).max(axis=0)
    z = H[None] + sig * np.random.default_rng(seed).standard_normal((2,) + H.shape)
    return model, Measurements(Q, z, sig, sensors=model.sensors), np.concatenate([np.ones(n_groups), [0.1]])


def chain_fits(arrays: dict, texts: dict) -> None:
    """Spring chains: 30 states (dense, k and c) and 80 states (sparse, k1, k2, c)."""
    from identification import identify
    for n_y, n_groups in ((30, 1), (80, 2)):
        model, data, p0 = chain_problem(n_y, n_groups)
        _estimate_record(f"chain{n_y}", identify(model, data, p0), arrays, texts)


def small_problem(symbolic: str):
    """Two states, two parameters, 8 inputs, 2 series: the model of test_estimator's SX/MX test."""
    import casadi as ca
    from identification import Measurements, simulate
    from models import Model

    def E(y, p, q):
        return ca.vertcat(p[0] * y[0] + y[0] ** 3 - q[0], y[1] - p[1] * ca.sin(y[0]) - q[1])

    def h(y, p, q):
        return ca.vertcat(y[0], y[1] + 0.1 * p[0])

    Q = np.column_stack([np.linspace(0.5, 3, 8), np.linspace(0.1, 0.5, 8)])
    sig = np.array([0.01, 0.01])
    m = Model(["a", "b"], ["u", "v"], ["s1", "s2"], n_y=2, E=E, h=h, symbolic=symbolic)
    H = simulate(m, [2.0, 0.7], Q)
    data = Measurements(Q, H[None] + sig * np.random.default_rng(1).standard_normal((2,) + H.shape), sig)
    return m, data, np.array([1.5, 0.5])


def sx_mx_fits(arrays: dict, texts: dict) -> None:
    """The small model stated in SX and in MX; the SX fit's intervals by every method."""
    from identification import identify
    for sym in ("SX", "MX"):
        model, data, p0 = small_problem(sym)
        est = identify(model, data, p0)
        _estimate_record(sym, est, arrays, texts)
        if sym == "SX":
            arrays["SX/ci_profile"] = intervals_array(est.conf_int(0.05, method="profile"))
            boot = est.conf_int(0.05, method="bootstrap", n=BOOT_N, seed=BOOT_SEED, workers=1)
            arrays["SX/ci_bootstrap"] = intervals_array(boot)
            arrays["SX/bootstrap_replicates"] = np.asarray(boot.replicates, float)
            texts["SX"]["bootstrap_notes"] = list(boot.notes)


def reactor_data(seed: int = 0):
    """The batch reactor's six experiments (test_dynamic_fit): solve_ivp (LSODA, rtol 1e-10) plus noise."""
    from scipy.integrate import solve_ivp
    from identification import DynamicMeasurements
    from mudoe.example_reactor import P_TRUE, R_KJ, T_REF, TIMES
    Q = np.array([[1.0, 330.0], [1.0, 340.0], [1.0, 350.0], [2.0, 350.0], [2.0, 360.0], [2.0, 370.0]])
    sigma = np.array([0.01, 0.008])

    def ivp(q):
        k1, k2 = (P_TRUE[2 * i] * np.exp(-P_TRUE[2 * i + 1] / R_KJ * (1 / q[1] - 1 / T_REF)) for i in range(2))
        r = solve_ivp(lambda _, x: [-k1 * x[0], k1 * x[0] - k2 * x[1], k2 * x[1]], (0, TIMES[-1]), [q[0], 0, 0],
                      t_eval=TIMES, rtol=1e-10, atol=1e-13, method="LSODA")
        return r.y[:2].T

    rng = np.random.default_rng(seed)
    z = np.array([ivp(q) + sigma * rng.standard_normal((len(TIMES), 2)) for q in Q])[None]
    return DynamicMeasurements(Q, TIMES, z, sigma, sensors=["cA", "cB"])


# ---------------------------------------------------------------------------- Monte Carlo, report
def press_size_study(n_rep: int, chunk_size: int | None = MC_CHUNK):
    """The press size study of bench_detect (M1 on its own campaigns, the paper's four splits), serial."""
    from identification import DetectSettings, MonteCarloSettings, size_study, splits_from_scenarios
    from models.press import PRESS_SCENARIOS, Q_PAPER, press_model
    model = press_model()
    settings = MonteCarloSettings(n_rep=n_rep, seed=MC_SEED, workers=1, progress=False, chunk_size=chunk_size,
                                  detect=DetectSettings(tol=0.05, normality="override"))
    splits = splits_from_scenarios(PRESS_SCENARIOS, len(Q_PAPER))
    return size_study(model, model.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_PAPER_MM, splits,
                      p0=P0_PRESS, n_M=2, weights=WEIGHTS_110, settings=settings, name="M1")


def save_mc(out: Path) -> None:
    res = press_size_study(MC_REP)
    errors = np.array([repr(tuple(e)) for e in res.errors], dtype=str)
    np.savez(out / "mc.npz", errors=errors, **{f: np.asarray(getattr(res, f)) for f in MC_FIELDS})


def save_report(out: Path) -> None:
    """``python -m mudoe report configs/press.toml --out OUT/press_report`` with this interpreter and path."""
    import mudoe.config
    root = Path(mudoe.config.DEFAULT_CONFIG).parent.parent
    cmd = [sys.executable, "-m", "mudoe", "report", "configs/press.toml", "--out", str(out / "press_report"),
           "--quiet"]
    r = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} (in {root}) exited {r.returncode}: {r.stderr.strip()[-2000:]}")


STATIC_ITEMS = ("fits", "mc", "report")
DYNAMIC_ITEMS = ("dynfits", "dyndesigns", "dyndetect", "dyncli")


def _run_fits(fns, arrays: dict, texts: dict, cpu: dict) -> None:
    for fn in fns:
        c0 = time.process_time()
        fn(arrays, texts)
        cpu[fn.__name__] = time.process_time() - c0
        print(f"  {fn.__name__}: {cpu[fn.__name__]:.1f} s CPU", flush=True)


def save(out: Path, items) -> dict:
    """Run the items (static: "fits", "mc", "report"; dynamic: "dynfits", "dyndesigns", "dyndetect",
    "dyncli") and write their files into ``out``; CPU seconds per item."""
    out.mkdir(parents=True, exist_ok=True)
    cpu = {}
    if "fits" in items:
        arrays, texts = {}, {}
        _run_fits((press_fits, chain_fits, sx_mx_fits), arrays, texts, cpu)
        np.savez(out / "fits.npz", **arrays)
        (out / "fits.json").write_text(json.dumps(texts, indent=1, sort_keys=True))
    for name, fn in (("mc", save_mc), ("report", save_report)):
        if name in items:
            cpu[name] = _cpu(lambda: fn(out))
            print(f"  {name}: {cpu[name]:.1f} s CPU (this process and its children)", flush=True)
    fns = [fn for item, fn in (("dynfits", dynamic_fits), ("dyndesigns", dynamic_designs),
                               ("dyndetect", dynamic_detect_validate)) if item in items]
    if fns:
        arrays, texts = {}, {}
        _run_fits(fns, arrays, texts, cpu)
        np.savez(out / "dynamic.npz", **arrays)
        (out / "dynamic.json").write_text(json.dumps(texts, indent=1, sort_keys=True))
    if "dyncli" in items:
        cpu.update(save_dynamic_cli(out))
    return cpu


# ---------------------------------------------------------------------------- the dynamic part
def _first_attr(obj, names, default=None):
    """The first of the attributes ``names`` that ``obj`` has (renamed fields: the new name first)."""
    for n in names:
        if hasattr(obj, n):
            return getattr(obj, n)
    return default


def _put(key: str, value, arrays: dict, texts: dict) -> None:
    """Store one field: strings (and sequences of them) and None into ``texts``, numbers into ``arrays``."""
    if value is None or isinstance(value, str):
        texts[key] = value
        return
    if isinstance(value, dict):
        for k, v in value.items():
            _put(f"{key}/{k}", v, arrays, texts)
        return
    if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        texts[key] = list(value)                      # notes, names (an empty one too: never a float array)
        return
    a = np.asarray(value)
    if a.dtype.kind in "fiub":
        arrays[key] = a
    elif a.dtype.kind == "U" or (a.dtype.kind == "O" and all(isinstance(v, str) for v in a.ravel())):
        texts[key] = [str(v) for v in a.ravel()] if a.ndim else str(a)
    else:
        texts[key] = repr(value)


def _record_fields(prefix: str, obj, fields, arrays: dict, texts: dict) -> None:
    """``obj``'s ``fields`` (a name, or a tuple of names tried in turn) under ``prefix/first name``."""
    for f in fields:
        names = (f,) if isinstance(f, str) else f
        v = _first_attr(obj, names, _MISSING)
        if v is not _MISSING:
            _put(f"{prefix}/{names[0]}", list(v) if isinstance(v, tuple) else v, arrays, texts)


_MISSING = object()
#: DesignResult fields saved (``chosen`` is read from ``sensors`` on trees before issue 28 item 3)
DESIGN_FIELDS = (("chosen", "sensors"), "indices", "weights", "criterion", "kind", "value", "det", "lower_bound", "gap",
                 "proven_optimal", "method", "status", "message", "near_singular", "notes", "candidates",
                 "information_share")
#: InputDesignResult fields saved (its ``design`` and ``refined`` below them)
INPUT_DESIGN_FIELDS = ("indices", "pairs", "inputs", "value", "lower_bound", "gap", "proven_optimal", "criterion",
                       "method", "status", "notes")
#: SplitTest fields saved per (model, split) of a DetectionResult
TEST_FIELDS = ("model", "split", "cal_label", "val_label", "ok", "stage", "error", "p_cal", "p_val", "alpha_paper",
               "alpha_two_sample", "n_cal", "n_val", "notes", "lr", "alpha_lr", "lr_error", "trustworthy")
#: the dynamic configs shipped (configs/NAME.toml) and the CLI verbs run on each
DYN_CONFIGS = ("reactor", "oscillator")
DYN_VERBS = (("report", "results.json", ()), ("detect", "detect.json", ()),
             ("validate", "validate.json", ("--runs", "5")))
DYN_MC_REP, DYN_MC_SEED = 8, 20261127


def _root() -> Path:
    import mudoe.config
    return Path(mudoe.config.DEFAULT_CONFIG).resolve().parent.parent


def dynamic_study(name: str):
    """The study of ``configs/NAME.toml`` as ``mudoe`` prepares it (the shipped campaign read)."""
    from mudoe.config import load_config
    from mudoe.study import prepare
    return prepare(load_config(_root() / "configs" / f"{name}.toml"))


def study_start(study, variant: str):
    """The start of a variant: ``study.p0s[variant]`` (dynamic studies of 0b6c053), else ``study.p0``."""
    starts = _first_attr(study, ("p0s", "start_values"))
    if isinstance(starts, dict) and variant in starts:
        return starts[variant]
    return study.p0


def _discretisation_record(name: str, est, arrays: dict, texts: dict) -> None:
    """The discretisation record of a dynamic fit: ``est.discretisation`` (typed diagnostics, issue 28 item 7)
    or else ``est.extra["discretisation"]``; its dataclass fields, or n_elements and error_sigma."""
    import dataclasses
    rec = getattr(est, "discretisation", None)
    if rec is None:
        extra = getattr(est, "extra", None) or {}
        rec = extra.get("discretisation") if isinstance(extra, dict) else None
    if rec is None:
        texts[f"{name}/discretisation"] = None
        return
    fields = [f.name for f in dataclasses.fields(rec)] if dataclasses.is_dataclass(rec) else ["n_elements",
                                                                                             "error_sigma"]
    for f in fields:
        v = getattr(rec, f, None)
        if v is None or isinstance(v, (str, bool, int, float, np.ndarray, tuple, list, np.generic)):
            _put(f"{name}/discretisation/{f}", list(v) if isinstance(v, tuple) else v, arrays, texts)


def dynamic_fits(arrays: dict, texts: dict) -> None:
    """The batch reactor on solve_ivp data from P0 = (1.5, 50, 1, 70), and every variant of the shipped
    reactor and oscillator studies on their shipped campaigns from the configs' starts."""
    from identification import identify
    from mudoe.example_reactor import build
    est = identify(build(), reactor_data(), [1.5, 50.0, 1.0, 70.0])
    _estimate_record("reactor", est, arrays, texts)
    _discretisation_record("reactor", est, arrays, texts)
    for cfg in DYN_CONFIGS:
        study = dynamic_study(cfg)
        for v, m in study.models.items():
            est = identify(m, study.data[v], study_start(study, v))
            _estimate_record(f"{cfg}_{v}", est, arrays, texts)
            _discretisation_record(f"{cfg}_{v}", est, arrays, texts)


def _design_record(name: str, res, arrays: dict, texts: dict) -> None:
    _record_fields(name, res, DESIGN_FIELDS, arrays, texts)


def dynamic_designs(arrays: dict, texts: dict) -> None:
    """Sampling-time designs (oed.select_times) of the reactor (D, 4 times; A, 5 time x sensor pairs) and of
    the oscillator (D, 3 of 50 times); input designs (oed.select_inputs with times=): 2 of 12 (cA0, T) rows of
    the isothermal reactor (D), and on Pyomo.DoE's reactor with a temperature profile (bench.bench_dynamic_doe)
    1 of 4 profiles and the nominal experiment refined continuously (one start)."""
    from oed import RefineSettings, select_inputs, select_times
    from mudoe import example_oscillator as O, example_reactor as R
    Q = np.array([[1.0, 330.0], [1.0, 340.0], [1.0, 350.0], [2.0, 350.0], [2.0, 360.0], [2.0, 370.0]])
    sig = np.array([0.01, 0.008])
    _design_record("times_reactor_D4", select_times(R.build(), R.P_TRUE, R.TIMES, Q, sig, n_times=4, criterion="D"),
                   arrays, texts)
    _design_record("times_reactor_pairs_A5", select_times(R.build(), R.P_TRUE, R.TIMES, Q, sig, n_times=5,
                                                          pairs=True, criterion="A"), arrays, texts)
    _design_record("times_oscillator_D3", select_times(O.build(), O.P_TRUE, O.TIMES, np.array([[2.0], [4.0], [6.0],
                                                       [8.0]]), np.array([0.02, 0.05]), n_times=3, criterion="D"),
                   arrays, texts)
    C = np.array([[c, t] for c in (1.0, 1.5, 2.0) for t in (330.0, 345.0, 360.0, 375.0)])
    _input_design_record("inputs_reactor_D2", select_inputs(R.build(), R.P_TRUE, times=R.TIMES, candidates=C,
                                                            sigma=sig, n_points=2, criterion="D", time_limit=1e9),
                         arrays, texts)
    from bench.bench_dynamic_doe import GRID, LOWER, NOMINAL, P, UPPER, reactor
    profiles = np.array([NOMINAL, np.r_[5.0, np.linspace(650, 350, 8), 300.0], np.r_[2.0, [450.0] * 4, [300.0] * 5],
                         np.r_[4.0, 600.0, [300.0] * 8]])
    _input_design_record("inputs_profiles_D1", select_inputs(reactor(), P, times=GRID, candidates=profiles,
                                                             sigma=0.01, n_points=1, time_limit=1e9), arrays, texts)
    _input_design_record("inputs_profiles_refined", select_inputs(
        reactor(), P, times=GRID, candidates=[NOMINAL], sigma=0.01, n_points=1, refine=True, bounds=(LOWER, UPPER),
        refine_settings=RefineSettings(n_starts=1), time_limit=1e9), arrays, texts)


def _input_design_record(name: str, res, arrays: dict, texts: dict) -> None:
    """An InputDesignResult: its fields, its ``design`` (a DesignResult) and its ``refined`` levels."""
    _record_fields(name, res, INPUT_DESIGN_FIELDS, arrays, texts)
    if getattr(res, "design", None) is not None:
        _design_record(f"{name}/design", res.design, arrays, texts)
    ref = getattr(res, "refined", None)
    if ref is not None:
        _record_fields(f"{name}/refined", ref, ("inputs", "value", "n_failed", "messages", "notes"), arrays, texts)


def early_late_split(data):
    """The early/late split of a dynamic campaign from the first function found (issue 28 item 2 unifies
    the rule): ``identification.early_late_split(data)``, ``early_late_dynamic_split(data)`` from
    ``identification.studies.splits`` or ``identification.studies.dynamic_detect`` (0b6c053),
    ``identification.studies.splits.early_late_split(data)``;
    None when none takes the campaign."""
    import importlib
    for mod, fn in (("identification", "early_late_split"),
                    ("identification.studies.splits", "early_late_dynamic_split"),
                    ("identification.studies.dynamic_detect", "early_late_dynamic_split"),
                    ("identification.studies.splits", "early_late_split")):
        try:
            f = getattr(importlib.import_module(mod), fn)
        except (ImportError, AttributeError):
            continue
        try:
            return f(data)
        except TypeError:
            continue
    return None


def _detection_record(name: str, res, arrays: dict, texts: dict) -> None:
    for i, t in enumerate(res.tests):
        _record_fields(f"{name}/test{i}", t, TEST_FIELDS, arrays, texts)
    texts[f"{name}/verdicts"] = {str(k): str(v) for k, v in dict(res.verdicts).items()}
    texts[f"{name}/notes"] = [str(n) for n in getattr(res, "notes", ())]


def _mc_record(name: str, res, arrays: dict, texts: dict) -> None:
    for f in MC_FIELDS:
        arrays[f"{name}/{f}"] = np.asarray(getattr(res, f))
    texts[f"{name}/errors"] = [repr(tuple(e)) for e in res.errors]


def dynamic_detect_validate(arrays: dict, texts: dict) -> None:
    """identification.detect and identification.validate (size study, 8 replications, serial, no JIT) on
    the shipped reactor campaign (split by experiment: cool vs hot) and oscillator campaign (cubic and
    linear, small vs large steps), each at the config's start; the early/late split alone under
    ``early_late/`` (the intended change of issue 28 item 2)."""
    from identification import MonteCarloSettings, Split, detect, validate
    mc = MonteCarloSettings(n_rep=DYN_MC_REP, seed=DYN_MC_SEED, workers=1, progress=False, jit=False)
    for cfg, split in (("reactor", Split("cool vs hot", [0, 1, 5], [2, 3, 4])),
                       ("oscillator", Split("small vs large steps", [0, 1], [2, 3]))):
        study = dynamic_study(cfg)
        for v, m in study.models.items():
            data, p0 = study.data[v], study_start(study, v)
            el = early_late_split(data)
            for prefix, splits in (("", [split]), ("early_late/", [el] if el is not None else [])):
                if not splits:
                    texts[f"{prefix}detect_{cfg}_{v}"] = "no early/late split function found"
                    continue
                _detection_record(f"{prefix}detect_{cfg}_{v}", detect(m, data, splits, p0), arrays, texts)
                if v == "linear":
                    continue                         # the wrong model: a size study of it says nothing new
                res = validate(m, splits, p0, p_true=p0, data=data, n_M=2, settings=mc)
                _mc_record(f"{prefix}validate_{cfg}_{v}", res, arrays, texts)


def save_dynamic_cli(out: Path) -> dict:
    """``python -m mudoe VERB configs/NAME.toml --out OUT/cli_NAME_VERB --quiet`` (report, detect, validate
    --runs 5) for the shipped dynamic configs, in the tree's root; CPU seconds of the children per run."""
    import resource
    root, cpu = _root(), {}
    for cfg in DYN_CONFIGS:
        for verb, _, extra in DYN_VERBS:
            k0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cmd = [sys.executable, "-m", "mudoe", verb, f"configs/{cfg}.toml", "--out",
                   str(out / f"cli_{cfg}_{verb}"), "--quiet", *extra]
            r = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
            if r.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)} (in {root}) exited {r.returncode}: {r.stderr.strip()[-2000:]}")
            k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu[f"cli {verb} {cfg}"] = (k1.ru_utime + k1.ru_stime) - (k0.ru_utime + k0.ru_stime)
            print(f"  cli {verb} {cfg}: {cpu[f'cli {verb} {cfg}']:.1f} s CPU (child)", flush=True)
    return cpu


def dynamic_json_files() -> list:
    """The results.json / detect.json / validate.json files of the dynamic CLI runs (relative paths)."""
    return [Path(f"cli_{cfg}_{verb}") / f for cfg in DYN_CONFIGS for verb, f, _ in DYN_VERBS]


# ---------------------------------------------------------------------------- compare
def bitwise_equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Same dtype, shape and bytes (NaN payloads and signed zeros included)."""
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def array_diff(a: np.ndarray, b: np.ndarray) -> tuple:
    """(largest |a - b|, largest |a - b| / max(|a|, |b|), same NaN pattern) of two float arrays."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    ok = ~(nan_a | nan_b)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.abs(a[ok] - b[ok])
        scale = np.maximum(np.abs(a[ok]), np.abs(b[ok]))
        rel = np.where(d == 0, 0.0, d / scale)
    return (float(d.max()) if d.size else 0.0, float(np.nanmax(rel)) if rel.size else 0.0,
            bool(np.array_equal(nan_a, nan_b)))


def early_late_key(key: str) -> bool:
    """A saved array or text of an early/late split (kept apart: the intended change of issue 28 item 2)."""
    return key.startswith("early_late/")


def compare_npz(pa: Path, pb: Path) -> tuple:
    """Print one line per array of two .npz files; (others all bitwise identical, early/late ones all identical)."""
    if not (pa.exists() and pb.exists()):
        print(f"{pa.name}: missing in {'A' if not pa.exists() else 'B'}")
        return False, True
    a, b = np.load(pa), np.load(pb)
    same = {False: True, True: True}
    lines = {False: [], True: []}
    for k in sorted(set(a.files) | set(b.files)):
        el = early_late_key(k)
        if k not in a.files or k not in b.files:
            lines[el].append(f"{pa.name} {k}: only in {'A' if k in a.files else 'B'}")
            same[el] = False
            continue
        x, y = a[k], b[k]
        bit = bitwise_equal(x, y)
        same[el] &= bit
        if x.dtype.kind in "fiub" and y.dtype.kind in "fiub" and x.shape == y.shape:
            dabs, drel, nan_same = array_diff(x, y)
            lines[el].append(f"{pa.name} {k}: max abs {dabs:.3e}, max rel {drel:.3e}, same NaN {nan_same}: "
                             f"{'BITWISE identical' if bit else 'DIFFERENT'}")
        else:
            n_diff = "shape/dtype differ" if x.shape != y.shape else f"{int(np.sum(x != y))} entries differ"
            lines[el].append(f"{pa.name} {k}: {'BITWISE identical' if bit else 'DIFFERENT (' + n_diff + ')'}")
    print("\n".join(lines[False]))
    if lines[True]:
        print(f"{pa.name}, early/late splits (intended change, issue 28 item 2):\n  " + "\n  ".join(lines[True]))
    return same[False], same[True]


def leaves(x, path=()):
    """(path tuple, value) of every leaf of a JSON value."""
    if isinstance(x, dict):
        for k, v in x.items():
            yield from leaves(v, path + (str(k),))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from leaves(v, path + (i,))
    else:
        yield path, x


def _ignored(path: tuple, value) -> str:
    """Why a results.json leaf is not compared ("" when it is)."""
    for k in path:
        words = [w for w in re.split(r"[^a-z0-9]+|_", k.lower()) if w] if isinstance(k, str) else []
        if IGNORED_WORDS.intersection(words) or (len(words) > 1 and words[-1] == "time"):
            return "key"
    return "absolute path" if isinstance(value, str) and os.path.isabs(value) else ""


def _pattern(path: tuple) -> str:
    return "/".join("#" if isinstance(k, int) else k for k in path)


def _same_leaf(x, y) -> bool:
    if isinstance(x, float) and isinstance(y, float):
        return np.float64(x).tobytes() == np.float64(y).tobytes()
    return type(x) is type(y) and x == y


def _mentions_early(x) -> bool:
    return isinstance(x, str) and "early" in x.lower()


def early_late_paths(x, path=()) -> set:
    """Paths of the JSON dicts that belong to an early/late split: a dict with a string child naming it
    ("early (t < 1.2) vs late"), or a key naming it; a leaf under one of them, a leaf whose key names the
    split, or a string leaf naming it is an early/late leaf."""
    out = set()
    if isinstance(x, dict):                 # a name or label (one short line), not a text that lists every split
        if any(_mentions_early(v) and "\n" not in v and len(v) < 100 for v in x.values()):
            out.add(path)
        for k, v in x.items():
            out |= early_late_paths(v, path + (str(k),))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out |= early_late_paths(v, path + (i,))
    return out


def _is_early_late(path: tuple, value, tagged: set) -> bool:
    return (_mentions_early(value) or any(_mentions_early(k) or early_late_key(str(k)) for k in path)
            or any(path[:i] in tagged for i in range(len(path) + 1)))


def _mask_text(x: str) -> str:
    """A text leaf with its date-times and the wall times of Monte Carlo tables masked."""
    return WALL_IN_TEXT.sub(r"\1, <wall> s", TIMESTAMP.sub("<date-time>", x))


def _print_leaf_diff(path, x, y) -> None:
    extra = ""
    if isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
        d = abs(x - y)
        extra = f" (abs {d:.3e}, rel {d / max(abs(x), abs(y)):.3e})" if d else ""
    if isinstance(x, str) and isinstance(y, str) and "\n" in x + y:
        lines = difflib.unified_diff(x.splitlines(), y.splitlines(), "A", "B", lineterm="", n=0)
        print(f"  {'/'.join(map(str, path))}: text differs\n    " + "\n    ".join(lines))
    else:
        print(f"  {'/'.join(map(str, path))}: A {x!r} B {y!r}{extra}")


def compare_json_leaves(name: str, pa: Path, pb: Path) -> tuple:
    """Print the differing leaves of two JSON files (ignored keys listed; those of early/late splits apart);
    (no other leaf differs, no early/late leaf differs)."""
    if not (pa.exists() and pb.exists()):
        print(f"{name}: missing in {'A' if not pa.exists() else 'B'}")
        return False, True
    ja, jb = json.loads(pa.read_text()), json.loads(pb.read_text())
    la, lb = dict(leaves(ja)), dict(leaves(jb))
    tagged = early_late_paths(ja) | early_late_paths(jb)
    ignored, masked, differing, n = set(), set(), {False: [], True: []}, 0
    for path in sorted(set(la) | set(lb), key=lambda p: tuple(map(str, p))):
        x, y = la.get(path, "<absent>"), lb.get(path, "<absent>")
        why = _ignored(path, x) or _ignored(path, y)
        if why:
            ignored.add(_pattern(path) + (" (absolute path)" if why == "absolute path" else ""))
            continue
        n += 1
        if isinstance(x, str) and isinstance(y, str) and (_mask_text(x) != x or _mask_text(y) != y):
            masked.add(_pattern(path))
            x, y = _mask_text(x), _mask_text(y)
        if not _same_leaf(x, y):
            differing[_is_early_late(path, x, tagged) or _is_early_late(path, y, tagged)].append((path, x, y))
    print(f"{name}: {n} leaves compared, {len(differing[False])} differ (+ {len(differing[True])} on early/late "
          f"splits); ignored keys: {', '.join(sorted(ignored)) or 'none'}; date-times and wall times masked in: "
          f"{', '.join(sorted(masked)) or 'none'}")
    for el in (False, True):
        if el and differing[True]:
            print(f"  -- {name}, early/late splits (intended change, issue 28 item 2):")
        for path, x, y in differing[el][:200]:
            _print_leaf_diff(path, x, y)
        if len(differing[el]) > 200:
            print(f"  ... and {len(differing[el]) - 200} more")
    return not differing[False], not differing[True]


def compare(a: Path, b: Path, allow_early_late: bool = False) -> int:
    """Compare two --save folders (the files either holds); 0 when everything compared is bitwise equal
    (early/late splits excepted with ``allow_early_late``), else 1."""
    ok, ok_el = True, True
    jsons = ["fits.json", "press_report/results.json", "dynamic.json"] + [str(p) for p in dynamic_json_files()]
    for f in ["fits.npz", "mc.npz", "dynamic.npz"] + jsons:
        if not ((a / f).exists() or (b / f).exists()):
            continue                                  # a part saved by neither
        o, e = (compare_npz if f.endswith(".npz") else lambda x, y: compare_json_leaves(f, x, y))(a / f, b / f)
        ok, ok_el = ok and o, ok_el and e
    print(f"early/late splits: {'identical' if ok_el else 'DIFFERENT (intended change, issue 28 item 2)'}")
    print("RESULT: everything compared is bitwise identical" if ok and ok_el else
          "RESULT: bitwise identical except the early/late splits" if ok else "RESULT: DIFFERENCES (see above)")
    return 0 if ok and (ok_el or allow_early_late) else 1


# ---------------------------------------------------------------------------- timing
def _cpu(fn) -> float:
    """CPU seconds (time.process_time) of this process and of its finished children (JIT compilers) in fn()."""
    import resource
    c0, k0 = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN)
    fn()
    k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() - c0 + (k1.ru_utime + k1.ru_stime) - (k0.ru_utime + k0.ru_stime)


def _median_cpu(fn, n: int) -> float:
    return float(np.median([_cpu(fn) for _ in range(n)]))


def _press_m1():
    """(model, data, p0) of the press M1 fit of ``mudoe identify configs/press.toml``."""
    from mudoe.config import DEFAULT_CONFIG, load_config
    from mudoe.study import prepare
    study = prepare(load_config(DEFAULT_CONFIG))
    return study.models["M1"], study.data["M1"], study.p0


def time_bnb() -> float:
    """CPU seconds of the branch-and-bound D-optimal 50 x 10, m = 10 (bench_oed's seeded instance)."""
    from oed.bnb import BnBSettings, branch_and_bound
    from oed.constraints import make_constraints
    from oed.criteria import validate_information
    n, p = 50, 10
    a = np.random.default_rng([0, n, p]).standard_normal((n, p))
    F, _ = validate_information(np.einsum("ki,kj->kij", a, a))
    cons = make_constraints(n, p, n_sensors=10)
    return _cpu(lambda: branch_and_bound(F, cons, "D", settings=BnBSettings(time_limit=30.0)))


def timing() -> dict:
    """CPU seconds per workload (this process plus its finished children), printed one line each."""
    from identification import identify
    print(f"machine: {_machine()}; OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}", flush=True)
    out = {}

    def record(name, seconds):
        out[name] = seconds
        print(f"{name}: {seconds:.4f} s CPU", flush=True)

    m, data, p0 = _press_m1()
    press = identify(m, data, p0)                        # builds and caches the solver: the fits below are warm
    record("press M1 warm fit (median of 30)", _median_cpu(lambda: identify(m, data, p0), 30))
    record("Monte Carlo 30 replications serial (bench_detect --study timing --n-rep 30 --workers 1)",
           _cpu(lambda: press_size_study(30, chunk_size=None)))
    record("branch-and-bound D 50x10 m=10", time_bnb())
    model, sdata, sp0 = small_problem("SX")
    small = identify(model, sdata, sp0)
    record("profile conf_int, SX small fit (median of 20)",
           _median_cpu(lambda: small.conf_int(0.05, method="profile"), 20))
    record("profile conf_int, press M1 (median of 5)", _median_cpu(lambda: press.conf_int(0.05, method="profile"), 5))
    record("bootstrap conf_int n=200 serial, SX small fit (median of 5)",
           _median_cpu(lambda: small.conf_int(0.05, method="bootstrap", n=200, seed=BOOT_SEED, workers=1), 5))
    record("bootstrap conf_int n=200 serial, press M1",
           _cpu(lambda: press.conf_int(0.05, method="bootstrap", n=200, seed=BOOT_SEED, workers=1)))
    return out


def timing_ab(tree_a: Path, tree_b: Path, rounds: int) -> int:
    """Run ``--timing`` in fresh processes on tree A and tree B in turn (A B A B ...) and print the medians
    and B / A per workload: both trees see the same machine load."""
    runs = {"A": [], "B": []}
    for r in range(rounds):
        for label, tree in (("A", tree_a), ("B", tree_b)):
            env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1")
            p = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--timing", "--json"], cwd=tree,
                               env=env, capture_output=True, text=True)
            if p.returncode != 0:
                print(f"timing on {tree} failed (exit {p.returncode}): {p.stderr.strip()[-2000:]}", file=sys.stderr)
                return 1
            runs[label].append(json.loads(p.stdout.strip().splitlines()[-1]))
            print(f"round {r + 1} {label} ({tree}) done; {_machine()}", flush=True)
    print(f"\n| workload | A CPU s (median of {rounds}) | B CPU s | B / A |\n|---|---|---|---|")
    for name in runs["A"][0]:
        a = float(np.median([x[name] for x in runs["A"]]))
        b = float(np.median([x[name] for x in runs["B"]]))
        print(f"| {name} | {a:.4f} | {b:.4f} | {b / a:.3f} |")
    return 0


# ---------------------------------------------------------------------------- command line
def _machine() -> str:
    load = os.getloadavg()
    return (f"{platform.processor() or platform.machine()}, nproc {os.cpu_count()}, load average "
            f"{load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f}, python {platform.python_version()}")


def _tree() -> str:
    import identification
    root = Path(identification.__file__).resolve().parent.parent
    r = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True)
    return f"{root} at {r.stdout.strip() or '(no git)'}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench unchanged", description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--save", metavar="DIR", help="write the saved results into DIR (see --part)")
    g.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two --save folders")
    g.add_argument("--timing", action="store_true", help="CPU seconds of the A/B workloads (the default)")
    g.add_argument("--ab", nargs=2, metavar=("TREE_A", "TREE_B"),
                   help="--timing on two source trees in turn, in fresh processes; medians and B / A")
    ap.add_argument("--rounds", type=int, default=3, help="with --ab: runs per tree (default 3)")
    ap.add_argument("--json", action="store_true", help="with --timing: end with one JSON line of the times")
    ap.add_argument("--part", choices=("static", "dynamic", "all"), default="all",
                    help="with --save: the static items (fits, mc, report), the dynamic ones (dynfits, dyndesigns, "
                         "dyndetect, dyncli) or all (default)")
    ap.add_argument("--items", default=None, help="with --save: a subset of the items (overrides --part)")
    ap.add_argument("--allow-early-late", action="store_true",
                    help="with --compare: differences on early/late splits (the intended change of issue 28 "
                         "item 2) are listed but do not make the exit code 1")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    if args.compare:
        return compare(Path(args.compare[0]), Path(args.compare[1]), allow_early_late=args.allow_early_late)
    if args.ab:
        return timing_ab(Path(args.ab[0]).resolve(), Path(args.ab[1]).resolve(), args.rounds)
    if not args.save:
        times = timing()
        if args.json:
            print(json.dumps(times))
        return 0
    part_items = dict(static=STATIC_ITEMS, dynamic=DYNAMIC_ITEMS, all=STATIC_ITEMS + DYNAMIC_ITEMS)[args.part]
    items = set(args.items.split(",")) if args.items else set(part_items)
    unknown = items - set(STATIC_ITEMS + DYNAMIC_ITEMS)
    if unknown:
        ap.error(f"--items: unknown {sorted(unknown)}; choose from {', '.join(STATIC_ITEMS + DYNAMIC_ITEMS)}")
    out = Path(args.save).resolve()          # the CLI runs below in the tree's root: never relative
    print(f"tree: {_tree()}; machine: {_machine()}", flush=True)
    w0 = time.perf_counter()
    cpu = save(out, items)
    wall = time.perf_counter() - w0
    meta = dict(tree=_tree(), machine=_machine(), date=time.strftime("%Y-%m-%dT%H:%M:%S%z"), cpu_s=cpu,
                wall_s=wall, items=sorted(items))
    (out / "meta.json").write_text(json.dumps(meta, indent=1))
    print(f"saved {sorted(items)} to {out} in {wall:.1f} s wall", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
