"""Benchmark (issue 30 item 2, flat valleys): what merging the minima along one flat valley costs and changes.

The README truss measured by P_x only (``configs/truss_one_sensor.toml``'s campaign, um -> mm, sigma 4 um), fitted
by ``identify(..., starts=N)`` for N = 8 and 32 from (200, 300) N/mm: prints the wall time of the multi-start fit,
the distinct minima of the point rule alone (objectives within the tolerance and parameters within 0.01 standard
errors: what the page listed before) and with the valley rule
(:func:`identification.fit.multistart.distinct_minima`: objectives within the valley tolerance and no barrier on the
segment between neighbouring starts), the time of the valley check and how many objective evaluations it took.

    PYTHONPATH=. python bench/bench_multistart_valley.py
"""
import pathlib
import time

import numpy as np

from identification import Measurements, identify
from identification.fit.multistart import StartFit, distinct_minima, static_objective
from identification.fit.problem import Problem
from models.library import two_bar_truss

DATA = pathlib.Path(__file__).resolve().parents[1] / "data" / "truss_one_sensor" / "measurements_P_x.csv"


def main() -> None:
    raw = np.loadtxt(DATA, delimiter=",", skiprows=1)
    data = Measurements(raw[:, :1], (raw[:, 1:].T / 1000.0)[:, :, None], [0.004])
    model = two_bar_truss(sensors=("P_x",))
    for n in (8, 32):
        t = time.perf_counter()
        est = identify(model, data, [200.0, 300.0], starts=n)
        wall = time.perf_counter() - t
        ms = est.diagnostics.starts
        fits = [StartFit(index=i, outcome=o, p=ms.p[i], objective=ms.objective[i], sigma0=1.0, status="", error="",
                         warnings=(), fit_time=0.0) for i, o in enumerate(ms.outcome)]
        calls = [0]
        phi0 = static_objective(Problem(model, data), est.weights, est.sigma)

        def phi(p):
            calls[0] += 1
            return phi0(p)
        t = time.perf_counter()
        merged = distinct_minima(fits, ms.objective, ms.objective_tol, est.stderr, ms.best, vtol=ms.valley_tol,
                                 phi=phi, names=ms.param_names, model=model)
        dt = time.perf_counter() - t
        point = distinct_minima(fits, ms.objective, ms.objective_tol, est.stderr, ms.best, vtol=-1.0,
                                names=ms.param_names)
        print(f"starts={n}: identify {wall:.2f} s; minima by the point rule {len(point)}, with the valley rule "
              f"{len(merged)} {[(m.count, m.flat, round(m.objective, 4)) for m in merged]}; valley check "
              f"{dt * 1e3:.0f} ms, {calls[0]} objective evaluations")


if __name__ == "__main__":
    main()
