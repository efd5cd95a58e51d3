"""CPU time of a virtual-prototype campaign (models.prototype.generate_campaign) and its numbers.

Times ``generate_campaign(seed, n_series, prototype=VirtualPrototype(PrototypeConfig()))`` for
``--n-seeds`` seeds (the prototype built once, as a Monte Carlo worker does), with the CasADi
virtual machine and with the JIT-compiled functions (models.state.set_jit), and prints a
markdown table: build time, CPU of the first campaign (it computes the noise-free first cycle
that later campaigns reuse) and the median CPU per later campaign.

``--save FILE.npz`` stores the campaigns (z, z_raw, q_actual per seed); ``--compare FILE.npz``
prints the largest relative difference to stored campaigns.  Before/after in one session: run
this file with an older tree first on the path, e.g.
``PYTHONPATH=/path/to/old/tree python bench/bench_prototype.py --modes vm --save /tmp/old.npz``,
then ``python -m bench.bench_prototype --compare /tmp/old.npz`` from this tree.
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def _cpu() -> float:
    """CPU seconds (user + system) of this process."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _machine() -> str:
    load = os.getloadavg()
    return (f"{platform.processor() or platform.machine()}, nproc {os.cpu_count()}, load average "
            f"{load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f}, python {platform.python_version()}")


def time_campaigns(jit: bool, seeds, n_series: int) -> dict:
    """Build one prototype (JIT on or off) and generate a campaign per seed; returns times and campaigns."""
    from models import prototype as pt
    from models.state import JIT, set_jit
    prev = set_jit(jit)
    try:
        w0, c0 = time.perf_counter(), _cpu()
        proto = pt.VirtualPrototype(pt.PrototypeConfig())
        build = (time.perf_counter() - w0, _cpu() - c0)
        cpu, camps = [], {}
        for s in seeds:
            c0 = _cpu()
            c = pt.generate_campaign(seed=int(s), n_series=n_series, prototype=proto)
            cpu.append(_cpu() - c0)
            camps[int(s)] = c
    finally:
        set_jit(prev)
    return dict(build=build, cpu=np.array(cpu), campaigns=camps, compiled=jit and not JIT.failed)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench prototype")
    ap.add_argument("--n-seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--n-series", type=int, default=2)
    ap.add_argument("--modes", default="vm,jit", help="comma-separated: vm (CasADi virtual machine), jit (compiled)")
    ap.add_argument("--save", default=None, help="store the campaigns of the first mode in this .npz file")
    ap.add_argument("--compare", default=None, help="largest relative difference to the campaigns in this .npz file")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    if args.n_seeds < 2:
        raise SystemExit("--n-seeds: need at least 2 (the first campaign also computes the first cycle)")
    modes = [m.strip() for m in args.modes.split(",") if m.strip()]
    if not modes or any(m not in ("vm", "jit") for m in modes):
        raise SystemExit(f"--modes: expected a comma-separated list of vm and jit, got {args.modes!r}")
    import models.prototype as pt
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}; models from {pt.__file__}")
    seeds = range(args.first_seed, args.first_seed + args.n_seeds)
    ref = np.load(args.compare) if args.compare else None
    rows = []
    for m in modes:
        r = time_campaigns(m == "jit", seeds, args.n_series)
        diff = float("nan")
        if ref is not None:
            diff = 0.0
            for s, c in r["campaigns"].items():
                for name, a in (("z", c.z), ("z_raw", c.z_raw), ("q_actual", c.q_actual)):
                    b = ref[f"{name}_{s}"]
                    diff = max(diff, float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300))))
        rows.append((m + (" (compiled)" if r["compiled"] else ""), r, diff))
        if args.save and len(rows) == 1:
            np.savez(args.save, **{f"{name}_{s}": getattr(c, name) for s, c in r["campaigns"].items()
                                   for name in ("z", "z_raw", "q_actual")})
            print(f"saved {len(r['campaigns'])} campaigns to {args.save}")
    print(f"\n{args.n_seeds} campaigns of {args.n_series} series (seeds {seeds.start}..{seeds.stop - 1}), "
          "one prototype per mode\n")
    print("| functions | build wall s (CPU s) | first campaign CPU s | median CPU s per campaign (later ones) "
          "| max rel diff to --compare |")
    print("|---|---|---|---|---|")
    for name, r, diff in rows:
        print(f"| {name} | {r['build'][0]:.2f} ({r['build'][1]:.2f}) | {r['cpu'][0]:.3f} | "
              f"{np.median(r['cpu'][1:]):.4f} | {diff:.1e} |")


if __name__ == "__main__":
    main()
