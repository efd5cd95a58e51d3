"""Interrupts and termination of the CLI: exit code and seconds from the signal to the exit.

``python -m bench signals [--rounds=N]`` runs the CLI as a process (the harness of
tests/mudoe/test_signals.py) and signals it at four moments: while CasADi's JIT compiler runs
(empty JIT cache, press, 2 workers; ``kill -INT`` and a terminal's Ctrl-C to the process group),
while 2 worker processes fit (cstr, SIGTERM), and while the report's pages are written (Ctrl-C).
The requirement (issue 20): exit 130 / 143 within a second, no process and no output left.
"""
from __future__ import annotations

import collections
import signal
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _harness():
    sys.path.insert(0, str(HERE.parent / "tests" / "mudoe"))
    import test_signals
    return test_signals


def _one(T, kind: str):
    tmp = Path(tempfile.mkdtemp(prefix="bench_signals"))
    out = tmp / "out"
    group = "group" in kind
    if kind.startswith("compile"):
        run = T._Run(["validate", "configs/press.toml", "--runs", "40", "--workers", "2", "--out", str(out)],
                     dict(T.ENV, MUDOE_JIT_CACHE=str(tmp / "jit")), group)
        run.wait_for(lambda kids: any(T._is_compiler(k) for k in kids))
        sig, want = signal.SIGINT, 130
    elif kind.startswith("fitting"):
        run = T._Run(["validate", "configs/cstr.toml", "--runs", "2000", "--workers", "2", "--out", str(out)], T.ENV)
        run.wait_for(lambda kids: any(T._is_worker(k) for k in kids)
                     and any("rep/s" in ln and " 0/" not in ln for ln in run.lines))
        sig, want = signal.SIGTERM, 143
    else:
        run = T._Run(["report", "configs/cstr.toml", "--out", str(out)], T.ENV)
        run.wait_for(lambda kids: out.is_dir() and any(any(d.iterdir()) for d in out.glob(".report-*")))
        sig, want = signal.SIGINT, 130
    dt = run.signal(sig, group)
    run.reader.join(10)
    left = run.left_over()
    files = sorted(p.name for p in out.iterdir() if p.name != T.MARKER) if out.exists() else []
    return run.p.returncode == want, dt, bool(left), bool(files)


def main(argv=None) -> None:
    rounds = 3
    for a in argv or []:
        if a.startswith("--rounds="):
            rounds = int(a.split("=", 1)[1])
    T = _harness()
    kinds = ["compile kill -INT", "compile group Ctrl-C", "fitting SIGTERM", "writing Ctrl-C"]
    rows = collections.defaultdict(list)
    for _ in range(rounds):
        for kind in kinds:
            rows[kind].append(_one(T, kind))
    print(f"{'moment':<22} {'n':>3} {'right code':>10} {'exit s: median':>15} {'max':>6} {'procs left':>10} {'files left':>10}")
    for kind in kinds:
        r = rows[kind]
        dts = sorted(x[1] for x in r)
        print(f"{kind:<22} {len(r):>3} {sum(x[0] for x in r):>10} {dts[len(dts) // 2]:>15.2f} {dts[-1]:>6.2f} "
              f"{sum(x[2] for x in r):>10} {sum(x[3] for x in r):>10}")


if __name__ == "__main__":
    main(sys.argv[1:])
