"""Behaviour-unchanged harness (issue 21): save full-precision results of one tree, compare two saves, time workloads.

Only the public API is used (``from identification import identify, ...``, :class:`Estimate` attributes,
``mudoe.config`` / ``mudoe.study.prepare`` and the ``mudoe`` CLI), so the same file runs against the tree
before and after identification/ is split into sub-packages.

``--save DIR`` writes

* ``DIR/fits.npz`` (float64, bitwise) and ``DIR/fits.json`` (status, message, notes, summary text) of the
  fits: the press variants M1, M2, M3 on the shipped campaign (configs/press.toml, series 4 and 5),
  spring chains with 30 states (k, c) and 80 states (k1, k2, c), a small two-state model stated in SX and
  the same in MX, and the batch reactor (a dynamic model, collocated).  Per fit: p, cov, cov_gn,
  information, S, H, objective, rss, grad_norm, iterations, status, the 95 % Wald intervals and
  ``summary()`` (its solve time, the only run-dependent number in it, is masked).  For the SX fit also
  ``conf_int`` by every method (wald, profile, bootstrap with n = 20 and seed 7), converted to (n_p, 2)
  arrays whatever type ``conf_int`` returns, and the bootstrap replicates;
* ``DIR/mc.npz``: 100 Monte Carlo replications of the press size study (M1 on campaigns simulated from
  itself, the paper's four splits, TOL 5 %, serial in this process, seed 20261121, chunks of 50):
  per replication alpha_paper, alpha_two_sample, alpha_lr, covered, shapiro and the failed splits;
* ``DIR/press_report/results.json``: ``python -m mudoe report configs/press.toml --out DIR/press_report``;
* ``DIR/meta.json``: machine, date, tree, CPU seconds per item (never compared).

``--compare A B`` prints per array the largest absolute and relative difference and whether it is
bitwise identical, the differing strings, and for results.json every differing leaf; keys that are
timings, timestamps, versions, hosts or paths (and string leaves holding absolute paths) are ignored and
listed.  Exit code 0 when everything else is bitwise equal, 1 otherwise.

``--timing`` prints the CPU seconds (time.process_time, this process) of: the press M1 warm fit (median
of 30), 30 Monte Carlo replications serial (bench_detect --study timing --n-rep 30 --workers 1, batch
engine), the branch-and-bound D-optimal 50 x 10 with m = 10 (bench oed --sizes=50x10 --ms=10 --crits=D),
a profile conf_int of the SX fit and a bootstrap conf_int of it with n = 200.  Run it with
OPENBLAS_NUM_THREADS=1 (set here when unset) on an otherwise idle machine, A and B in turn.

Run (the tree under test first on the path; the file itself may come from another tree)::

    cd TREE && PYTHONPATH=TREE python bench/bench_unchanged.py --save DIR
    python bench/bench_unchanged.py --compare DIR_A DIR_B          # exit code 0: unchanged
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
#: (split at "_" and non-letters: "solve_time", "timing_s", "versions", "base_dir"; not "validate", "times")
IGNORED_WORDS = frozenset({"time", "timing", "created", "timestamp", "date", "duration", "elapsed", "wall", "cpu",
                           "version", "versions", "host", "hostname", "machine", "platform", "path", "dir", "pid"})
#: date-times inside text leaves (the report's "Built 2026-11-25 18:19 UTC" line) are masked before comparing
TIMESTAMP = re.compile(r"\d{4}-\d{2}-\d{2}[ T]\d{2}:\d{2}(:\d{2}(\.\d+)?)?( ?UTC|Z|[+-]\d{2}:?\d{2})?")
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


def dynamic_fit(arrays: dict, texts: dict) -> None:
    """The batch reactor (collocation with discretisation error control) from P0 = (1.5, 50, 1, 70)."""
    from identification import identify
    from mudoe.example_reactor import build
    est = identify(build(), reactor_data(), [1.5, 50.0, 1.0, 70.0])
    _estimate_record("reactor", est, arrays, texts)
    rec = est.extra.get("discretisation")
    if rec is not None:
        arrays["reactor/n_elements"] = np.asarray(rec.n_elements)
        arrays["reactor/error_sigma"] = np.asarray(rec.error_sigma)


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


def save(out: Path, items) -> dict:
    """Run the items ("fits", "mc", "report") and write their files into ``out``; CPU seconds per item."""
    out.mkdir(parents=True, exist_ok=True)
    cpu = {}
    if "fits" in items:
        arrays, texts = {}, {}
        for fn in (press_fits, chain_fits, sx_mx_fits, dynamic_fit):
            c0 = time.process_time()
            fn(arrays, texts)
            cpu[fn.__name__] = time.process_time() - c0
            print(f"  {fn.__name__}: {cpu[fn.__name__]:.1f} s CPU", flush=True)
        np.savez(out / "fits.npz", **arrays)
        (out / "fits.json").write_text(json.dumps(texts, indent=1, sort_keys=True))
    for name, fn in (("mc", save_mc), ("report", save_report)):
        if name in items:
            c0 = time.process_time()
            fn(out)
            cpu[name] = time.process_time() - c0
            print(f"  {name}: {cpu[name]:.1f} s CPU (this process)", flush=True)
    return cpu


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


def compare_npz(pa: Path, pb: Path) -> bool:
    """Print one line per array of two .npz files; True when all are bitwise identical."""
    if not (pa.exists() and pb.exists()):
        print(f"{pa.name}: missing in {'A' if not pa.exists() else 'B'}")
        return False
    a, b = np.load(pa), np.load(pb)
    same = True
    for k in sorted(set(a.files) | set(b.files)):
        if k not in a.files or k not in b.files:
            print(f"{pa.name} {k}: only in {'A' if k in a.files else 'B'}")
            same = False
            continue
        x, y = a[k], b[k]
        bit = bitwise_equal(x, y)
        same &= bit
        if x.dtype.kind in "fiub" and y.dtype.kind in "fiub" and x.shape == y.shape:
            dabs, drel, nan_same = array_diff(x, y)
            print(f"{pa.name} {k}: max abs {dabs:.3e}, max rel {drel:.3e}, same NaN {nan_same}: "
                  f"{'BITWISE identical' if bit else 'DIFFERENT'}")
        else:
            n_diff = "shape/dtype differ" if x.shape != y.shape else f"{int(np.sum(x != y))} entries differ"
            print(f"{pa.name} {k}: {'BITWISE identical' if bit else 'DIFFERENT (' + n_diff + ')'}")
    return same


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
    if any(isinstance(k, str) and IGNORED_WORDS.intersection(re.split(r"[^a-z0-9]+|_", k.lower())) for k in path):
        return "key"
    return "absolute path" if isinstance(value, str) and os.path.isabs(value) else ""


def _pattern(path: tuple) -> str:
    return "/".join("#" if isinstance(k, int) else k for k in path)


def _same_leaf(x, y) -> bool:
    if isinstance(x, float) and isinstance(y, float):
        return np.float64(x).tobytes() == np.float64(y).tobytes()
    return type(x) is type(y) and x == y


def compare_json_leaves(name: str, pa: Path, pb: Path) -> bool:
    """Print the differing leaves of two JSON files (ignored keys listed); True when none differs."""
    if not (pa.exists() and pb.exists()):
        print(f"{name}: missing in {'A' if not pa.exists() else 'B'}")
        return False
    la = dict(leaves(json.loads(pa.read_text())))
    lb = dict(leaves(json.loads(pb.read_text())))
    ignored, masked, differing, n = set(), set(), [], 0
    for path in sorted(set(la) | set(lb), key=lambda p: tuple(map(str, p))):
        x, y = la.get(path, "<absent>"), lb.get(path, "<absent>")
        why = _ignored(path, x) or _ignored(path, y)
        if why:
            ignored.add(_pattern(path) + (" (absolute path)" if why == "absolute path" else ""))
            continue
        n += 1
        if isinstance(x, str) and isinstance(y, str) and (TIMESTAMP.search(x) or TIMESTAMP.search(y)):
            masked.add(_pattern(path))
            x, y = TIMESTAMP.sub("<date-time>", x), TIMESTAMP.sub("<date-time>", y)
        if not _same_leaf(x, y):
            differing.append((path, x, y))
    print(f"{name}: {n} leaves compared, {len(differing)} differ; ignored keys: "
          f"{', '.join(sorted(ignored)) or 'none'}; date-times masked in: {', '.join(sorted(masked)) or 'none'}")
    for path, x, y in differing[:200]:
        extra = ""
        if isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
            d = abs(x - y)
            extra = f" (abs {d:.3e}, rel {d / max(abs(x), abs(y)):.3e})" if d else ""
        if isinstance(x, str) and isinstance(y, str) and "\n" in x + y:
            lines = difflib.unified_diff(x.splitlines(), y.splitlines(), "A", "B", lineterm="", n=0)
            print(f"  {'/'.join(map(str, path))}: text differs\n    " + "\n    ".join(lines))
        else:
            print(f"  {'/'.join(map(str, path))}: A {x!r} B {y!r}{extra}")
    if len(differing) > 200:
        print(f"  ... and {len(differing) - 200} more")
    return not differing


def compare(a: Path, b: Path) -> int:
    """Compare two --save folders; 0 when everything compared is bitwise equal, else 1."""
    ok = True
    for f in ("fits.npz", "mc.npz"):
        ok &= compare_npz(a / f, b / f)
    ok &= compare_json_leaves("fits.json", a / "fits.json", b / "fits.json")
    rj = Path("press_report") / "results.json"
    ok &= compare_json_leaves("press_report/results.json", a / rj, b / rj)
    print("RESULT: everything compared is bitwise identical" if ok else "RESULT: DIFFERENCES (see above)")
    return 0 if ok else 1


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
    g.add_argument("--save", metavar="DIR", help="write fits.npz, fits.json, mc.npz, press_report/ into DIR")
    g.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two --save folders")
    g.add_argument("--timing", action="store_true", help="CPU seconds of the A/B workloads (the default)")
    g.add_argument("--ab", nargs=2, metavar=("TREE_A", "TREE_B"),
                   help="--timing on two source trees in turn, in fresh processes; medians and B / A")
    ap.add_argument("--rounds", type=int, default=3, help="with --ab: runs per tree (default 3)")
    ap.add_argument("--json", action="store_true", help="with --timing: end with one JSON line of the times")
    ap.add_argument("--items", default="fits,mc,report", help="with --save: a subset of fits,mc,report")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    if args.compare:
        return compare(Path(args.compare[0]), Path(args.compare[1]))
    if args.ab:
        return timing_ab(Path(args.ab[0]).resolve(), Path(args.ab[1]).resolve(), args.rounds)
    if not args.save:
        times = timing()
        if args.json:
            print(json.dumps(times))
        return 0
    items = set(args.items.split(","))
    unknown = items - {"fits", "mc", "report"}
    if unknown:
        ap.error(f"--items: unknown {sorted(unknown)}; choose from fits, mc, report")
    out = Path(args.save)
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
