"""Wall time of `mudoe oed`'s design of a time-series study's next experiment (issue 30 item 8) against the library
call it makes, and of its approximate sampling times (issue 31), both planned at the start values (no fit).

    PYTHONPATH=. python bench/bench_oed_product.py [--rep=3]

Motor (configs/motor.toml, planned, mode = "inputs", n_candidates = 6, exact): ``mudoe.dynamic_plans.input_design``
on one model object (the design, then the values of the design, of the current experiments, of both and of each
alone) against ``oed.select_inputs`` on the same candidates (the exact choice alone).  Reactor (configs/reactor.toml, planned,
approximate = true): local, and pseudo-Bayesian over E1 ~ U(45, 55) (5 Gauss points) with the local design's
efficiencies (``plan_without_data``: the models built anew each run).  Median of ``--rep`` runs after one warm-up;
wall and CPU time of this process.
"""
from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def _cfg(name: str, extra: str):
    from mudoe.config import parse_config
    text = (REPO / "configs" / f"{name}.toml").read_text()
    text = re.sub(r"^\[oed\]\n", "[oed]\nplanned = true\n" + extra, text, flags=re.M)
    return parse_config(text, str(REPO / "configs" / f"{name}.toml"))


def _median(fn, rep: int) -> tuple:
    """(median wall s, median CPU s of this process, the last result) of ``rep`` calls after one warm-up."""
    fn()
    wall, cpu, out = [], [], None
    for _ in range(rep):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return float(np.median(wall)), float(np.median(cpu)), out


def main(argv=None) -> None:
    from mudoe.dynamic_plans import candidate_experiments, input_bounds, input_design
    from mudoe.study_base import Progress
    from mudoe.kind.time_series import build_dynamic, config_sigma
    from mudoe.study import plan_without_data
    from mudoe.study_models import build_models
    from oed.inputs import select_inputs
    rep = next((int(a.split("=")[1]) for a in (argv or []) if a.startswith("--rep=")), 3)
    cfg = _cfg("motor", 'mode = "inputs"\nbounds = { TL = [0.0, 0.03], u = [-12.0, 12.0] }\nn_candidates = 6\n')
    models, p0s, Q = build_dynamic(cfg, {k: b.model for k, b in build_models(cfg).items()})
    m, p = models["coulomb"], p0s["coulomb"]
    lo, hi = input_bounds(cfg, m, Q)
    C, _, _ = candidate_experiments(cfg, Q, lo, hi)
    sig, times = config_sigma(cfg, m), np.asarray(cfg.dynamic.times)
    w_cli, c_cli, plan = _median(lambda: input_design(cfg, "coulomb", m, p, Q, sig, True, Progress(False)), rep)
    w_lib, c_lib, res = _median(lambda: select_inputs(m, p, candidates=C, sigma=sig, n_points=1, times=times), rep)
    print(f"motor next experiment, 10 candidates of 11 inputs: mudoe.dynamic_plans.input_design {w_cli:.2f} s wall "
          f"({c_cli:.2f} s CPU), oed.select_inputs alone {w_lib:.2f} s ({c_lib:.2f} s CPU), ratio {w_cli / w_lib:.2f} "
          f"(CPU {c_cli / c_lib:.2f}); chosen {plan.chosen}, same as the library: "
          f"{list(plan.result.indices) == list(res.indices)}; log det C design {plan.values['design']:.4f}, "
          f"current {plan.values['current']:.4f}, both {plan.values['current + design']:.4f}, efficiency per "
          f"experiment {plan.efficiency:.4f}")
    for extra in ("approximate = true\n", 'approximate = true\nprior = { E1 = ["uniform", 45.0, 55.0] }\n'):
        cfg = _cfg("reactor", extra)
        w, c, plan = _median(lambda: plan_without_data(cfg), rep)
        d = plan.design
        print(f"reactor approximate times ({d.robust}, {d.prior.n} vectors): {w:.2f} s wall ({c:.2f} s CPU); support "
              f"{', '.join(f'{x[0]:.4g}' for x in d.points)} weights {', '.join(f'{w:.4f}' for w in d.weights)}; "
              f"sensitivity max {d.sensitivity_max:.8g} (n_p = 4, gap {d.gap:.2g})")


if __name__ == "__main__":
    main(sys.argv[1:])
