"""Start-up of one Monte Carlo worker process, stage by stage (issue 15: the fixed costs of a parallel run).

Each measurement is a fresh Python process started as a spawned pool worker is (``python -c``), which
runs the worker's stages one after the other and records wall and CPU time (``resource.getrusage``:
this process plus its finished children, i.e. the C compiler) of each:

1. **interpreter**: from the parent's ``Popen`` to the child's first statement;
2. **imports**: what a worker imports to unpickle its task (``identification.studies.montecarlo``,
   ``models.press``, ``bench.bench_detect``);
3. **model build**: unpickling the press model and building its CasADi functions (``numerics``);
4. **compile/load**: the JIT work of the first chunk (``models.state.JIT.stats``: compilation with
   ``gcc``, or loading from the on-disk cache ``models.jit_cache``); its CPU is the compiler's (child
   processes) plus the wall time of the loads;
5. **first chunk**: the rest of a first chunk of ``--reps`` replications of the press timing study
   (batch engine, JIT on), i.e. the first fits.

Modes: ``cold`` (an empty cache directory: the worker compiles), ``warm`` (the cache filled by the
cold run: the worker only loads), ``nocache`` (``JIT.cache = False``: compiled in a private temporary
directory, the behaviour before the cache).  Run ``python -m bench.bench_startup`` (``--repeat 3``
medians) and read the markdown table.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

_CHILD = r"""
import json, os, resource, sys, time
T0 = float(sys.argv[1]); MODE = sys.argv[2]; REPS = int(sys.argv[3])
def clock():
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.time(), s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime
marks = [("interpreter",) + clock()]
import pickle
import identification.studies.montecarlo, models.press, bench.bench_detect as bd
marks.append(("imports",) + clock())
from models.state import JIT, numerics
JIT.cache = MODE != "nocache"
m = pickle.loads(pickle.dumps(models.press.press_model()))
numerics(m)
marks.append(("model build",) + clock())
w1, c1 = clock()
k1 = resource.getrusage(resource.RUSAGE_CHILDREN)
bd.run_size(REPS, 1, 20261121, progress=False)
w2, c2 = clock()
k2 = resource.getrusage(resource.RUSAGE_CHILDREN)
st = JIT.stats
gcc = k2.ru_utime + k2.ru_stime - k1.ru_utime - k1.ru_stime
marks.append(("compile/load", w1 + st.compile_s + st.load_s, c1 + gcc + st.load_s))
marks.append(("first chunk", w2, c2))
print(json.dumps({"marks": marks, "T0": T0, "compiled": st.compiled, "loaded": st.loaded}))
"""

STAGES = ("interpreter", "imports", "model build", "compile/load", "first chunk")


def worker_startup(mode: str, reps: int, cache_dir: str) -> dict:
    """Stage -> (wall s, CPU s) of one fresh worker process in ``mode`` (see the module docstring)."""
    env = dict(os.environ, MUDOE_JIT_CACHE=cache_dir, OPENBLAS_NUM_THREADS="1")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "")
    t0 = time.time()
    out = subprocess.run([sys.executable, "-c", _CHILD, repr(t0), mode, str(reps)], capture_output=True, text=True,
                         env=env, cwd=root, check=True).stdout
    got = json.loads(out.strip().splitlines()[-1])
    res, prev_w, prev_c = {}, got["T0"], 0.0
    for name, w, c in got["marks"]:
        res[name] = (w - prev_w, c - prev_c)
        prev_w, prev_c = w, c
    res["total"] = (got["marks"][-1][1] - got["T0"], got["marks"][-1][2])
    res["compiled/loaded"] = (got["compiled"], got["loaded"])
    return res


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=2, help="replications of the first chunk")
    ap.add_argument("--repeat", type=int, default=1, help="measurements per mode (the table gives medians)")
    ap.add_argument("--modes", nargs="+", choices=("nocache", "cold", "warm"), default=["nocache", "cold", "warm"])
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    import numpy as np
    from bench.bench_workers import _machine
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}", flush=True)
    runs = {m: [] for m in args.modes}
    for _ in range(args.repeat):
        with tempfile.TemporaryDirectory(prefix="mudoe-jit-bench-") as cache:
            for mode in ("nocache", "cold", "warm"):       # warm reads what cold wrote
                if mode in args.modes or (mode == "cold" and "warm" in args.modes):
                    r = worker_startup(mode, args.reps, cache)
                    if mode in args.modes:
                        runs[mode].append(r)
                        print(mode, {k: tuple(round(float(x), 3) for x in v) for k, v in r.items()}, flush=True)
    print(f"\nOne worker's start-up, stage by stage (median of {args.repeat}; first chunk = {args.reps} replications)\n")
    print("| stage | " + " | ".join(f"{m} wall s (CPU s)" for m in args.modes) + " |")
    print("|---|" + "---|" * len(args.modes))
    for stage in STAGES + ("total",):
        cells = []
        for m in args.modes:
            w = float(np.median([r[stage][0] for r in runs[m]]))
            c = float(np.median([r[stage][1] for r in runs[m]]))
            cells.append(f"{w:.2f} ({c:.2f})")
        print(f"| {stage} | " + " | ".join(cells) + " |")
    print("| functions compiled / loaded | " + " | ".join(
        "{} / {}".format(*runs[m][0]["compiled/loaded"]) for m in args.modes) + " |")


if __name__ == "__main__":
    main()
