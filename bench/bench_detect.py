"""Monte Carlo size, coverage, power and timing of Algorithm 1 on the press (issue 5).

Studies (``--study``):

* ``size``: campaigns simulated by the press model M1 itself (k5 = k7 = 500 N/mm, the
  paper's 29 loads, n_M = 2 series, sensors D_y and F_x as chosen by the paper's E-optimal
  design, sigma = the paper's (15.18, 4.895, 3.904) um written in mm), tested on the paper's
  four scenarios at TOL = 5 % with Bonferroni.  Reports the family-wise rejection rate of
  the paper's statistic and of the two-sample statistic with Clopper-Pearson 95 %
  intervals, and the coverage of the 95 % ellipsoids of every fit.
* ``timing``: the same four-scenario test, ``--n-rep`` replications on ``--workers``
  processes with the batch engine (:func:`identification.fit.batch.fit_batch`, a chunk of
  replications fitted together), then ``--compare-rep`` replications (default min(n_rep, 200))
  on the same workers with one :func:`identification.identify` call per fit (the per-fit
  path); prints wall and CPU time (this process and its workers) per replication, the ratio,
  and whether the decisions of the common replications are identical (alpha to 1e-6);
  ``--serial-rep`` adds a run in this process.
* ``power``: campaigns from the virtual prototype (:mod:`models.prototype`) if it exposes
  a generator, M1 (and M2/M3 when :mod:`models.friction` provides them) tested on them;
  then the CPU split between campaign generation (timed in this process on the first
  replications' streams, JIT on as in the workers) and the rest (fits, tests, start-up).

Run ``python -m bench.bench_detect --study size --n-rep 2000`` (or via ``python -m bench detect``
with ``--study=size --n-rep=2000``).
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from identification.studies.detect import DetectSettings  # noqa: E402
from identification.studies.montecarlo import MonteCarloSettings, size_study  # noqa: E402
from identification.studies.splits import splits_from_scenarios  # noqa: E402
from models.press import PRESS_SCENARIOS, Q_PAPER, press_model  # noqa: E402

#: the paper's sensor sigmas (section 5), m -> mm
SIGMA_PAPER_MM = np.array([1.518e-05, 4.895e-06, 3.904e-06]) * 1e3
WEIGHTS_110 = np.array([1.0, 1.0, 0.0])      # D_y, F_x (the paper's E-optimal pair)
P0 = np.array([450.0, 550.0])                 # start values of every fit (N/mm)
PAPER_SPLITS = splits_from_scenarios(PRESS_SCENARIOS, len(Q_PAPER))   # the paper's four scenarios


def _machine() -> str:
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    return (f"{platform.processor() or platform.machine()}, nproc {os.cpu_count()}, "
            f"load average {load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f}, python {platform.python_version()}")


def _cpu() -> float:
    """CPU seconds (user + system) of this process and its finished child processes (the workers)."""
    import resource
    t = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        r = resource.getrusage(who)
        t += r.ru_utime + r.ru_stime
    return t


def run_size(n_rep: int, workers: int | None, seed: int, scheduler=None, progress=True, batch=True):
    from identification.studies.split_fits import BATCHED, ONE_BY_ONE
    model = press_model()
    settings = MonteCarloSettings(n_rep=n_rep, seed=seed, workers=workers, scheduler=scheduler, progress=progress,
                                  detect=DetectSettings(tol=0.05, normality="override"),
                                  fits=BATCHED if batch else ONE_BY_ONE)
    return size_study(model, model.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_PAPER_MM, PAPER_SPLITS,
                      p0=P0, n_series=2, weights=WEIGHTS_110, settings=settings, name="M1")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench detect")
    ap.add_argument("--study", choices=("size", "timing", "power", "press"), default="size")
    ap.add_argument("--n-rep", type=int, default=2000)
    ap.add_argument("--serial-rep", type=int, default=0, help="replications of a serial run (timing; 0: none)")
    ap.add_argument("--compare-rep", type=int, default=None,
                    help="replications of the per-fit comparison run (timing; default min(n_rep, 200); 0: none)")
    ap.add_argument("--per-fit", action="store_true", help="one identify call per fit (no batch engine)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--seed", type=int, default=20261121)
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--save", default=None, help="write the per-replication arrays to this .npz file")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}", flush=True)
    c0 = _cpu()
    if args.study == "size":
        res = run_size(args.n_rep, args.workers, args.seed, args.scheduler, not args.no_progress, not args.per_fit)
        _save(args.save, res)
        print(res.description)
        print(res.summary())
        for st in ("paper", "two_sample", "likelihood_ratio"):
            r = res.rejection_rate("M1", st)
            print(f"size {st}: {r}")
        print(f"wall {res.wall_time:.1f} s on {res.backend}: {res.wall_time / res.n_rep * 1e3:.0f} ms per replication; "
              f"CPU of all processes {_cpu() - c0:.1f} s ({'per-fit identify' if args.per_fit else 'batch engine'})")
    elif args.study == "timing":
        run_timing(args)
    elif args.study == "power":
        res = run_power(args.n_rep, args.workers, args.seed, args.scheduler, not args.no_progress, not args.per_fit)
        _save(args.save, res)
        print(res.description)
        print(res.summary())
        for m in res.models:
            for st in ("paper", "two_sample", "likelihood_ratio"):
                print(f"rejection rate {m} {st}: {res.rejection_rate(m, st)}")
        cpu_all = _cpu() - c0
        print(f"wall {res.wall_time:.1f} s on {res.backend}; CPU of all processes {cpu_all:.1f} s "
              f"({'per-fit identify' if args.per_fit else 'batch engine'})")
        report_power_split(res, cpu_all, 21, args.seed)
    else:
        run_press()


def run_timing(args):
    """Batch engine vs per-fit path on the same replications (see the module docstring)."""
    runs = []
    c0 = _cpu()
    par = run_size(args.n_rep, args.workers, args.seed, args.scheduler, not args.no_progress, batch=True)
    runs.append(("batch engine", par, _cpu() - c0))
    _save(args.save, par)
    print(par.summary())
    n_cmp = min(args.n_rep, 200) if args.compare_rep is None else args.compare_rep
    if n_cmp:
        c0 = _cpu()
        old = run_size(n_cmp, args.workers, args.seed, args.scheduler, not args.no_progress, batch=False)
        runs.append(("per-fit identify", old, _cpu() - c0))
    if args.serial_rep:
        c0 = _cpu()
        ser = run_size(args.serial_rep, 1, args.seed, None, not args.no_progress, batch=True)
        runs.append(("batch engine, serial", ser, _cpu() - c0))
    print("\n| path | backend | replications | wall | per replication | CPU (all processes) | CPU per replication |")
    print("|---|---|---|---|---|---|---|")
    for name, res, cpu in runs:
        per = res.wall_time / res.n_rep * 1e3
        print(f"| {name} | {res.backend} | {res.n_rep} | {res.wall_time:.1f} s | {per:.1f} ms "
              f"| {cpu:.1f} s | {cpu / res.n_rep * 1e3:.1f} ms |")
    if n_cmp:
        old, cpu_old = runs[1][1], runs[1][2]
        k = min(n_cmp, par.n_rep)
        diff = max(float(np.nanmax(np.abs(getattr(par, f)[:k] - getattr(old, f)[:k]))) for f in
                   ("alpha_lr", "alpha_two_sample", "alpha_paper"))
        nan_same = all(np.array_equal(np.isnan(getattr(par, f)[:k]), np.isnan(getattr(old, f)[:k])) for f in
                       ("alpha_lr", "alpha_two_sample", "alpha_paper"))
        same = all(np.array_equal(par.decisions(statistic=st)[:k], old.decisions(statistic=st)[:k], equal_nan=True)
                   for st in ("likelihood_ratio", "two_sample", "paper"))
        print(f"\nfirst {k} replications: decisions identical (all three statistics): {same}; "
              f"largest |alpha difference| {diff:.1e} (target 1e-6); same failed splits: {nan_same}")
        print(f"CPU per replication, per-fit / batch: {cpu_old / old.n_rep / (runs[0][2] / par.n_rep):.2f}; "
              f"wall per replication, per-fit / batch: {old.wall_time / old.n_rep / (par.wall_time / par.n_rep):.2f}")


def _save(path, res):
    if path:
        np.savez(path, alpha_paper=res.alpha_paper, alpha_two_sample=res.alpha_two_sample, alpha_lr=res.alpha_lr,
                 covered=res.covered,
                 shapiro=res.shapiro, models=np.array(res.models), splits=np.array([s.name for s in res.splits]))
        print(f"saved per-replication arrays to {path}")


class PrototypeCampaign:
    """Picklable generator rng -> Measurements: a fresh virtual-prototype campaign of n_series series.

    Each replication draws the campaign seed from its own stream; the prototype (CasADi
    functions, JIT-compiled when the worker has models.state.set_jit on, and its noise-free first
    cycle) is built once per worker copy and not pickled: the Monte Carlo workers keep their copy
    of the task, so once per worker.  sigma: the paper's fixed values (mm).  ``cpu_campaign`` and
    ``cpu_total`` add up the CPU seconds this copy spent in generate_campaign and in whole calls
    (with building the Measurements), ``n_calls`` the calls, ``n_builds`` the prototypes built.
    """

    def __init__(self, n_series: int = 2, sigma_mm=SIGMA_PAPER_MM, names=("M1",)):
        self.n_series = int(n_series)
        self.names = tuple(names)
        self.sigma = np.asarray(sigma_mm, float)
        self._proto = None
        self.cpu_campaign = self.cpu_total = 0.0
        self.n_calls = self.n_builds = 0

    def __getstate__(self):
        d = dict(self.__dict__)
        d.update(_proto=None, cpu_campaign=0.0, cpu_total=0.0, n_calls=0, n_builds=0)   # counters per copy
        return d

    def __call__(self, rng):
        from models.prototype import PrototypeConfig, VirtualPrototype, generate_campaign
        t0 = time.process_time()
        if self._proto is None:
            self._proto = VirtualPrototype(PrototypeConfig())
            self.n_builds += 1
        c = generate_campaign(seed=int(rng.integers(2 ** 32)), n_series=self.n_series, prototype=self._proto)
        self.cpu_campaign += time.process_time() - t0
        from mudoe.press import campaign_measurements
        if self.names == ("M1",):
            out = campaign_measurements(c, sigma=self.sigma)
        else:
            from models.friction import model_inputs
            out = {n: campaign_measurements(c, inputs=model_inputs(n, c.q_set), sigma=self.sigma) for n in self.names}
        self.cpu_total += time.process_time() - t0
        self.n_calls += 1
        return out


def generation_cost(generator: PrototypeCampaign, n: int, seed: int, jit: bool) -> dict:
    """CPU seconds per campaign of ``generator`` in this process, on the first n replications' streams.

    The first call (prototype build, JIT compilation when ``jit``, and the noise-free first
    cycle) is timed apart; ``campaign`` and ``total`` are medians over the n - 1 later calls
    (generate_campaign alone, and with building the Measurements).  JIT as the workers use it.
    """
    from models.state import set_jit
    children = np.random.SeedSequence(seed).spawn(max(n, 2))
    prev = set_jit(jit)
    try:
        w0 = time.perf_counter()
        generator(np.random.default_rng(children[0]))
        first = (time.perf_counter() - w0, generator.cpu_total)
        camp, tot = [], []
        for ch in children[1:]:
            c0, t0 = generator.cpu_campaign, generator.cpu_total
            generator(np.random.default_rng(ch))
            camp.append(generator.cpu_campaign - c0)
            tot.append(generator.cpu_total - t0)
    finally:
        set_jit(prev)
    return dict(first_wall=first[0], first_cpu=first[1], campaign=float(np.median(camp)), total=float(np.median(tot)),
                n=len(camp))


def run_power(n_rep: int, workers, seed: int, scheduler=None, progress=True, batch=True):
    from identification.studies.split_fits import BATCHED, ONE_BY_ONE
    from identification.studies.montecarlo import power_study
    try:
        from models.friction import candidate_models
        models = candidate_models()
    except ImportError:
        models = {"M1": press_model()}
    settings = MonteCarloSettings(n_rep=n_rep, seed=seed, workers=workers, scheduler=scheduler, progress=progress,
                                  detect=DetectSettings(tol=0.05, normality="override"),
                                  fits=BATCHED if batch else ONE_BY_ONE)
    return power_study(models, PrototypeCampaign(names=tuple(models)), PAPER_SPLITS, P0, WEIGHTS_110, settings,
                       description="data: virtual prototype campaigns (models.prototype.generate_campaign, 2 series "
                                   "after a run-in cycle, seed per replication), sigma = the paper's fixed values")


def report_power_split(res, cpu_all: float, n_gen: int, seed: int) -> None:
    """Print where the power study's CPU went: campaign generation (measured in this process on the
    first replications' streams, JIT on as in the workers) and the rest (fits, tests, worker start-up)."""
    names = tuple(res.models)
    g = generation_cost(PrototypeCampaign(names=names), min(n_gen, res.n_rep + 1), seed, jit=True)
    gen = g["total"] * res.n_rep
    print(f"\ngeneration (this process, JIT on, median of {g['n']} campaigns after the first): "
          f"generate_campaign {g['campaign'] * 1e3:.1f} ms CPU, with the Measurements of {len(names)} models "
          f"{g['total'] * 1e3:.1f} ms CPU per campaign; first call (prototype build, compilation, first cycle) "
          f"{g['first_wall']:.2f} s wall, {g['first_cpu']:.2f} s CPU in this process")
    print("| part | CPU s | share |\n|---|---|---|")
    print(f"| generation ({res.n_rep} campaigns x {g['total'] * 1e3:.1f} ms) | {gen:.1f} | {gen / cpu_all:.0%} |")
    print(f"| the rest: fits and tests, worker start-up and compilation, the probe | {cpu_all - gen:.1f} | "
          f"{(cpu_all - gen) / cpu_all:.0%} |")
    print(f"| all processes | {cpu_all:.1f} | 100% |")


def run_press():
    """Algorithm 1 on the press campaign: the two held-out series, M1 (and M2/M3 when available)."""
    from identification.studies.detect import detect, normality_check
    from models import prototype as pt
    files = sorted(pt.CAMPAIGN_DIR.glob("*")) if pt.CAMPAIGN_DIR.exists() else []
    if files:
        camp = pt.read_campaign()
        origin = f"read from {pt.CAMPAIGN_DIR}"
    else:
        camp = pt.generate_campaign(pt.CAMPAIGN_SEED)
        origin = (f"{pt.CAMPAIGN_DIR} not shipped yet: regenerated in memory by generate_campaign(seed="
                  f"{pt.CAMPAIGN_SEED}), the campaign ship_campaign() would write")
    print(f"campaign: {origin}; {camp.n_M} series")
    from mudoe.press import campaign_measurements
    full = campaign_measurements(camp, sigma="composed")
    print("normality gate on all series (pairs 2-1, 4-3, 6-5), as the paper's table 'Analysis of the measurement "
          "data':")
    print(normality_check(full).table())
    try:
        from models.friction import candidate_models, model_inputs
        models = candidate_models()
        inputs = {n: model_inputs(n, camp.q_set) for n in models}
    except ImportError as exc:
        print(f"models.friction not available ({exc}): M2 and M3 not tested")
        models = {"M1": press_model()}
        inputs = {"M1": camp.q_set[:, None]}
    datas = {n: campaign_measurements(camp, series=pt.TEST_SERIES, inputs=inputs[n], sigma="composed")
             for n in models}
    d1 = next(iter(datas.values()))
    print(f"held-out series {[i + 1 for i in pt.TEST_SERIES]}, composed sigma (mm): {np.round(d1.sigma, 6).tolist()}")
    res = detect(models, datas, PAPER_SPLITS, P0, design=["D_y", "F_x"], normality="check")
    print(res.summary())


if __name__ == "__main__":
    main()
