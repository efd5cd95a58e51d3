"""NIST StRD nonlinear regression: correct digits of ``identify`` on all 27 problems x 2 starts (issue 20).

For every data set in ``tests/data/nist`` (the 27 NIST/ITL StRD nonlinear least-squares problems)
and both published starts, the model is fitted with sigma unknown by
:func:`identification.identify` and compared with NIST's certified values (11 digits) by the log
relative error LRE = -log10(|estimate - certified| / |certified|) (capped at 11, the certified
digits): the parameters (min over them), the Gauss-Newton standard errors ``stderr_gn`` (min over
them; NIST's standard deviations are Gauss-Newton ones with s^2 = RSS / (n - n_p)) and the RSS.
Then MGH10 from start 1 with the parameter scales a user would declare (1e-2, 1e4, 1e3): the
certified optimum or an exception.

``attainable``: the digits the certified values themselves allow in double precision (see
``tests/identification/fit/nist.py``, :func:`attainable_digits`): Lanczos1's RSS (1.4e-25) lies below
the round-off of its residuals, so its RSS and standard errors cannot be reproduced in double.

Run ``python -m bench.bench_nist`` (``--markdown`` prints the table for bench/RESULTS.md).  With
``PYTHONPATH`` pointing at another tree the same script measures that tree's estimator (the data
and helper are this tree's).
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

CERTIFIED_DIGITS = 11.0


def nist_module():
    """tests/identification/fit/nist.py of this tree, loaded by path."""
    name = "_mudoe_tests_nist_strd"
    if name not in sys.modules:
        path = Path(__file__).resolve().parents[1] / "tests" / "identification" / "fit" / "nist.py"
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def lre(estimate, certified) -> np.ndarray:
    """Elementwise log relative error, capped at the certified digits; 0 when not finite."""
    est = np.atleast_1d(np.asarray(estimate, dtype=float))
    cert = np.atleast_1d(np.asarray(certified, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        out = -np.log10(np.abs(est - cert) / np.abs(cert))
    return np.where(np.isnan(out), 0.0, np.minimum(out, CERTIFIED_DIGITS))


def fit(name: str, start: str, scales=None) -> dict:
    """One fit: LREs of p, stderr_gn and RSS, or the exception's type and message."""
    from identification import Measurements, identify
    from models import Model
    from models.contract import Parameter
    nist = nist_module()
    d = nist.load(name)
    params = [Parameter(f"b{i + 1}", scale=None if scales is None else scales[i]) for i in range(d.n_p)]
    inputs = ["x"] if d.n_x == 1 else [f"x{i + 1}" for i in range(d.n_x)]
    model = Model.explicit(params=params, inputs=inputs, sensors=["y"], h=nist.h_of(name, d.n_x), name=name)
    data = Measurements(inputs=d.x.reshape(d.n, d.n_x), z=d.y.reshape(1, -1, 1), sigma=None)
    t = time.perf_counter()
    try:
        est = identify(model, data, p0=getattr(d, start).copy())
    except Exception as exc:                       # noqa: BLE001 - the table records any failure
        return {"name": name, "start": start, "error": f"{type(exc).__name__}: {str(exc)[:160]}",
                "time": time.perf_counter() - t}
    return {"name": name, "start": start, "time": time.perf_counter() - t,
            "p": float(lre(est.p, d.certified).min()), "se": float(lre(est.stderr_gn, d.certified_stdev).min()),
            "rss": float(lre(est.rss, d.certified_rss)[0]), "solver": est.diagnostics.solver,
            "attainable": nist.attainable_digits(d) if hasattr(nist, "attainable_digits") else None}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="store_true", help="print a markdown table")
    ap.add_argument("--only", nargs="*", help="data set names (default: all)")
    args = ap.parse_args(argv)
    nist = nist_module()
    names = args.only or nist.available()
    rows = [fit(n, s) for n in names for s in ("start1", "start2")]
    if not args.only or "MGH10" in args.only:
        row = fit("MGH10", "start1", scales=(1e-2, 1e4, 1e3))
        row["start"] = "start1, scales (1e-2, 1e4, 1e3)"
        rows.append(row)
    if args.markdown:
        print("| problem | start | LRE p (min) | LRE stderr_gn (min) | LRE RSS | s |")
        print("| --- | --- | ---: | ---: | ---: | ---: |")
    for r in rows:
        if "error" in r:
            line = (f"| {r['name']} | {r['start']} | raised: {r['error']} | | | {r['time']:.2f} |" if args.markdown
                    else f"{r['name']:9s} {r['start']:9s} raised {r['error']}")
        elif args.markdown:
            line = f"| {r['name']} | {r['start']} | {r['p']:.1f} | {r['se']:.1f} | {r['rss']:.1f} | {r['time']:.2f} |"
        else:
            line = f"{r['name']:9s} {r['start']:9s} p {r['p']:5.1f}  se {r['se']:5.1f}  rss {r['rss']:5.1f}  {r['time']:.2f} s"
        print(line, flush=True)
    ok = [r for r in rows if "error" not in r]
    print(f"# {len(ok)}/{len(rows)} fits returned; p >= 9 digits: {sum(r['p'] >= 9 for r in ok)}; "
          f"stderr_gn >= 9 digits: {sum(r['se'] >= 9 for r in ok)}; total {sum(r['time'] for r in rows):.1f} s")


if __name__ == "__main__":
    main()
