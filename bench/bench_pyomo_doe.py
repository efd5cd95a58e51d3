"""Benchmark (issue 22): the live peer Pyomo.DoE on its reactor example, beside the ODE's exact FIM.

The peer runs in its own Python environment (Pyomo 6.10 with an Ipopt AMPL executable built
from Debian packages, see ``shared/peers/README.md``), in a subprocess that runs this same file
with ``--worker`` (only the standard library and Pyomo are imported there). It measures, on the
example of pyomo/contrib/doe/examples (``ReactorExperiment``, nfe = 10, ncp = 3, central
differences with step 1e-3, determinant objective, parameters scaled by their nominal values,
Ipopt with MUMPS since HSL's ma57 is not available):

* ``compute_FIM`` (sequential) at the nominal design: the first call (building and discretising
  the model) and ``--rep`` warm calls (median, min, max);
* ``run_doe`` (a fresh ``DesignOfExperiments`` on the same experiment each time; the first run
  reported apart, then ``--doe-rep`` runs);
* the 9 x 9 full factorial of (CA[0], T[0]) over [1, 5] x [300, 700] (``--factorial-rep`` runs);
* with ``--grid``, ``compute_FIM`` on finer grids (nfe = 20, 40, 80), approaching the ODE.

In this process: the ODE's own FIM (bench.dynamic_reference, exact sensitivities by CVODES,
scipy and the closed form), timed. Everything is printed as one JSON document.

Where the peer is found (environment variables, else defaults):
``MUDOE_PEER_PYTHON`` (default /work/peers/venv/bin/python), ``MUDOE_PEER_IPOPT`` (default
``ipopt`` on PATH, then /work/peers/ipopt-ampl/bin/ipopt, /tmp/ipopt-ampl/bin/ipopt) and
``MUDOE_PEER_DATA`` (default shared/peers/pyomo_doe_reactor_result.json in a parent directory of
this file). Without a peer the reference part still runs and the JSON says how to build it.
Run: ``python -m bench pyomo_doe [--rep=20] [--doe-rep=3] [--factorial-rep=2] [--grid]``
(``--doe-rep=-1`` skips run_doe, ``--factorial-rep=0`` the factorial).
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

MARK = "PYOMO_DOE_RESULT_JSON:"
BUILD_HINT = (
    "build the peer with: bash shared/peers/build_ipopt_ampl.sh /work/peers/ipopt-ampl && "
    "python3 -m venv /work/peers/venv && /work/peers/venv/bin/pip install 'pyomo==6.10.*' pandas packaging "
    "(or point MUDOE_PEER_PYTHON / MUDOE_PEER_IPOPT / MUDOE_PEER_DATA at an existing one)")


def _clock():
    """(wall, CPU) seconds now; CPU counts this process and its waited-for children (Ipopt runs as one)."""
    t = os.times()
    return time.perf_counter(), time.process_time() + t.children_user + t.children_system


def _since(start):
    """(wall, CPU) seconds since ``start = _clock()``."""
    now = _clock()
    return now[0] - start[0], now[1] - start[1]


def _stats(pairs):
    """Median, min, max and count of (wall, CPU) seconds: the CPU time is the one a loaded machine disturbs less."""
    wall, cpu = [p[0] for p in pairs], [p[1] for p in pairs]
    return {"median_s": statistics.median(wall), "min_s": min(wall), "max_s": max(wall), "n": len(wall),
            "all_s": wall, "cpu_median_s": statistics.median(cpu), "cpu_min_s": min(cpu), "cpu_max_s": max(cpu)}


# ----------------------------------------------------------------------------------------------
# The worker: runs in the peer's environment (stdlib + Pyomo only)
# ----------------------------------------------------------------------------------------------

def _worker_setup(ipopt, data_file):
    """The example's data (control points as float keys) and an Ipopt (MUMPS) solver."""
    import pyomo.environ as pyo

    with open(data_file) as f:
        data = json.load(f)
    data["control_points"] = {float(k): v for k, v in data["control_points"].items()}
    solver = pyo.SolverFactory("ipopt", executable=ipopt)
    solver.options["linear_solver"] = "mumps"
    solver.options["halt_on_ampl_error"] = "yes"
    solver.options["max_iter"] = 3000
    return data, solver


def _doe(experiment, solver):
    """The example's DesignOfExperiments (reactor_example.py's settings, our solver)."""
    from pyomo.contrib.doe import DesignOfExperiments

    return DesignOfExperiments(
        experiment, fd_formula="central", step=1e-3, objective_option="determinant", scale_constant_value=1,
        scale_nominal_param_value=True, prior_FIM=None, jac_initial=None, fim_initial=None,
        L_diagonal_lower_bound=1e-7, solver=solver, tee=False, get_labeled_model_args=None,
        _Cholesky_option=True, _only_compute_fim_lower=True)


def _log10det(F):
    import numpy as np

    sign, logdet = np.linalg.slogdet(np.asarray(F, dtype=float))
    return float(logdet / np.log(10)) if sign > 0 else None


def _worker_fim(data, solver, rep, nfe=10):
    """compute_FIM at the nominal design: the first call and ``rep`` warm calls."""
    from pyomo.contrib.doe.examples.reactor_experiment import ReactorExperiment

    doe = _doe(ReactorExperiment(data=data, nfe=nfe, ncp=3), solver)
    t0 = _clock()
    F = doe.compute_FIM(method="sequential")
    first = _since(t0)[0]
    warm = []
    for _ in range(rep):
        t0 = _clock()
        F = doe.compute_FIM(method="sequential")
        warm.append(_since(t0))
    return {"nfe": nfe, "first_s": first, "warm": _stats(warm) if warm else None, "log10_det": _log10det(F),
            "FIM": [list(map(float, r)) for r in F]}


def _worker_run_doe(data, solver, rep):
    """run_doe from a fresh DesignOfExperiments on one experiment: the first run apart, then ``rep``."""
    from pyomo.contrib.doe.examples.reactor_experiment import ReactorExperiment

    experiment = ReactorExperiment(data=data, nfe=10, ncp=3)
    times, res = [], None
    for _ in range(rep + 1):
        doe = _doe(experiment, solver)
        t0 = _clock()
        doe.run_doe()
        times.append(_since(t0))
        res = doe.results
    return {"first_s": times[0][0], "warm": _stats(times[1:]) if rep else None,
            "termination": str(res["Termination Condition"]), "log10_det": float(res["log10 D-opt"]),
            "design": dict(zip(res["Experiment Design Names"], map(float, res["Experiment Design"]))),
            "FIM": [list(map(float, r)) for r in res["FIM"]]}


def _worker_factorial(data, solver, rep):
    """The 9 x 9 full factorial of (CA[0], T[0]) in [1, 5] x [300, 700], ``rep`` times."""
    from pyomo.contrib.doe.examples.reactor_experiment import ReactorExperiment

    experiment = ReactorExperiment(data=data, nfe=10, ncp=3)
    times, res = [], None
    for _ in range(rep):
        doe = _doe(experiment, solver)
        t0 = _clock()
        res = doe.compute_FIM_full_factorial(design_ranges={"CA[0]": [1, 5, 9], "T[0]": [300, 700, 9]},
                                             method="sequential")
        times.append(_since(t0))
    d = res["log10 D-opt"]
    best = max(range(len(d)), key=lambda i: d[i])
    return {"timing": _stats(times), "points": len(d), "failed": sum(1 for v in res["det_FIM"] if v == 0),
            "CA0": list(map(float, res["CA[0]"])), "T0": list(map(float, res["T[0]"])),
            "log10_det": list(map(float, d)),
            "best": {"CA0": float(res["CA[0]"][best]), "T0": float(res["T[0]"][best]), "log10_det": float(d[best])}}


def _worker(argv):
    """Entry point in the peer's environment: measure, print one JSON line after MARK."""
    opts = dict(a[2:].split("=", 1) for a in argv if a.startswith("--") and "=" in a)
    import pyomo

    data, solver = _worker_setup(opts["ipopt"], opts["data"])
    if not solver.available(exception_flag=False):
        raise SystemExit(f"peer: the Ipopt executable {opts['ipopt']} is not usable")
    out = {"pyomo": pyomo.__version__, "ipopt": str(solver.version()), "python": sys.version.split()[0]}
    out["compute_FIM"] = _worker_fim(data, solver, int(opts["rep"]))
    if int(opts["doe_rep"]) >= 0:
        out["run_doe"] = _worker_run_doe(data, solver, int(opts["doe_rep"]))
    if int(opts["factorial_rep"]) > 0:
        out["factorial"] = _worker_factorial(data, solver, int(opts["factorial_rep"]))
    if opts.get("grid"):
        out["grid"] = [_worker_fim(data, solver, 0, nfe=int(n)) for n in opts["grid"].split(",")]
    print(MARK + json.dumps(out), flush=True)


# ----------------------------------------------------------------------------------------------
# The driver: runs in mudoe's environment
# ----------------------------------------------------------------------------------------------

def find_peer():
    """(python, ipopt, data file) of the Pyomo.DoE peer; raises FileNotFoundError saying how to build it."""
    py = Path(os.environ.get("MUDOE_PEER_PYTHON", "/work/peers/venv/bin/python"))
    candidates = [os.environ.get("MUDOE_PEER_IPOPT"), shutil.which("ipopt"), "/work/peers/ipopt-ampl/bin/ipopt",
                  "/tmp/ipopt-ampl/bin/ipopt"]
    ipopt = next((Path(c) for c in candidates if c and Path(c).is_file()), None)
    data = os.environ.get("MUDOE_PEER_DATA")
    if data is None:
        here = Path(__file__).resolve()
        found = [d / "shared" / "peers" / "pyomo_doe_reactor_result.json" for d in here.parents]
        data = next((f for f in found if f.is_file()), None)
    missing = [what for what, ok in (("the peer Python MUDOE_PEER_PYTHON=" + str(py), py.is_file()),
                                     ("an Ipopt AMPL executable (MUDOE_PEER_IPOPT)", ipopt is not None),
                                     ("the example's data file (MUDOE_PEER_DATA)", data and Path(data).is_file()))
               if not ok]
    if missing:
        raise FileNotFoundError("Pyomo.DoE peer not found: missing " + "; ".join(missing) + "; " + BUILD_HINT)
    return py, ipopt, Path(data)


def run_peer(rep=20, doe_rep=3, factorial_rep=2, grid=None, timeout=3600):
    """Run the worker in the peer's environment; its measurements as a dict (see the module docstring)."""
    py, ipopt, data = find_peer()
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    env.pop("PYTHONPATH", None)
    cmd = [str(py), str(Path(__file__).resolve()), "--worker", f"--ipopt={ipopt}", f"--data={data}",
           f"--rep={rep}", f"--doe_rep={doe_rep}", f"--factorial_rep={factorial_rep}"]
    if grid:
        cmd.append("--grid=" + ",".join(map(str, grid)))
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout, cwd="/tmp")
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith(MARK)]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
        raise RuntimeError(f"Pyomo.DoE peer failed (exit {proc.returncode}): " + " | ".join(tail))
    out = json.loads(lines[-1][len(MARK):])
    out["ipopt_executable"] = str(ipopt)
    return out


def reference(rep=20):
    """The ODE's own FIM at the nominal design by the three methods, with timings (this process)."""
    from bench import dynamic_reference as dr

    out = {}
    for method in ("cvodes", "scipy", "closed"):
        dr.pyomo_doe_reactor_fim(method=method)          # imports and first-call costs out of the timing
        times = []
        for _ in range(rep):
            t0 = _clock()
            F = dr.pyomo_doe_reactor_fim(method=method)
            times.append(_since(t0))
        out[method] = {"log10_det": dr.log10_det(F), "timing": _stats(times), "FIM": F.tolist()}
    base = out["closed"]["log10_det"]
    out["max_abs_diff_log10_det"] = max(abs(v["log10_det"] - base) for v in out.values())
    t0 = time.perf_counter()
    C, T0, d = dr.pyomo_doe_reactor_factorial()
    out["factorial"] = {"seconds": time.perf_counter() - t0, "CA0": C.tolist(), "T0": T0.tolist(),
                        "log10_det": [v if v > -1e300 else None for v in d.tolist()]}
    t0 = time.perf_counter()
    x, v = dr.pyomo_doe_reactor_optimal_design()
    out["optimal_design"] = {"seconds": time.perf_counter() - t0, "CA0": x[0], "T": x[1:].tolist(), "log10_det": v,
                             "note": "local optimum (L-BFGS-B, closed form) from Pyomo.DoE's starts; T(t=1) has no effect"}
    return out


def _compare(out):
    """Peer minus ODE: log10 det at the nominal design, on finer grids, over the factorial; the ODE at run_doe's design."""
    from bench import dynamic_reference as dr

    ref, peer = out["reference"], out["peer"]
    base = ref["closed"]["log10_det"]
    peer["compute_FIM"]["log10_det_minus_ode"] = peer["compute_FIM"]["log10_det"] - base
    for g in peer.get("grid", []):
        g["log10_det_minus_ode"] = g["log10_det"] - base
    if "run_doe" in peer:
        design = peer["run_doe"]["design"]
        T = [design[f"T[{t:g}]"] for t in dr.PYOMO_DOE_REACTOR["times"]]
        peer["run_doe"]["ode_log10_det_at_design"] = dr.log10_det(dr.pyomo_doe_reactor_fim(design["CA[0]"], T))
    if "factorial" in peer:
        f, r = peer["factorial"], ref["factorial"]
        ode = {(round(c, 9), round(t, 9)): v for c, t, v in zip(r["CA0"], r["T0"], r["log10_det"])}
        pairs = [(v, ode[round(c, 9), round(t, 9)]) for c, t, v in zip(f["CA0"], f["T0"], f["log10_det"])]
        pairs = [(a, b) for a, b in pairs if b is not None]
        peer["factorial"]["max_abs_minus_ode"] = max(abs(a - b) for a, b in pairs)


def _machine():
    return {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(), "nproc": os.cpu_count(),
            "loadavg": os.getloadavg()}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    opts = dict(a[2:].split("=", 1) if "=" in a else (a[2:], "1") for a in argv if a.startswith("--"))
    rep, doe_rep = int(opts.get("rep", 20)), int(opts.get("doe-rep", 3))
    fact_rep = int(opts.get("factorial-rep", 2))
    grid = (20, 40, 80) if "grid" in opts else None
    out = {"machine_before": _machine(), "reference": reference(rep)}
    try:
        out["peer"] = run_peer(rep, doe_rep, fact_rep, grid)
    except FileNotFoundError as exc:
        print(f"bench pyomo_doe: {exc}", file=sys.stderr)
        out["peer"] = {"missing": str(exc)}
    else:
        _compare(out)
    out["machine_after"] = _machine()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    if "--worker" in sys.argv[1:]:
        _worker(sys.argv[1:])
    else:
        main()
