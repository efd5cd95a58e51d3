"""Before/after check of Algorithm 1 (detect) for behaviour-unchanged refactors: every field of every split
test, decision and normality check, and the summary text, of detect on the shipped studies (configs/*.toml,
as ``mudoe detect`` runs it) and on failure paths (a degenerate split, sigma unknown, normality override,
sensor weights, fits the data do not bound, an untrustworthy linearisation, a dynamic campaign with and
without a bounded discretisation error).

    PYTHONPATH=TREE python bench/detect_unchanged.py --save OUT.pkl      (run from TREE; works on the flat
                                                                          pre-issue-21 layout too)
    python bench/detect_unchanged.py --compare A.pkl B.pkl             (np.array_equal on every number)
"""
import dataclasses
import os
import pickle
import sys
import time

import numpy as np

CONFIGS = ("configs/press.toml", "configs/truss_one_sensor.toml", "configs/reactor.toml", "configs/cstr.toml",
           "configs/oscillator.toml")

def dump(res):
    out = {"summary": res.summary(), "repr": repr(res), "tests": [], "decisions": [], "normality": []}
    for t in res.tests:
        out["tests"].append({f.name: getattr(t, f.name) for f in dataclasses.fields(t)})
    for d in res.all_decisions + res.decisions:
        out["decisions"].append(dataclasses.asdict(d))
    for m, c in res.normality:
        out["normality"].append((m, {f.name: getattr(c, f.name) for f in dataclasses.fields(c)}))
    out["design"] = res.design; out["notes"] = res.notes
    return out

def run(cfgs):
    from mudoe.config import load_config
    from mudoe.study import prepare, run_detect, StudyResults
    res = {}
    for c in cfgs:
        t0 = time.time()
        cfg = load_config(c)
        try:
            study = prepare(cfg)
            r = run_detect(study, StudyResults(study))
            res[c] = dump(r.detection)
        except Exception as e:
            res[c] = f"{type(e).__name__}: {e}"
        print(c, round(time.time() - t0, 1), "s", type(res[c]).__name__, flush=True)
    return res

def eq(a, b, path):
    if isinstance(a, dict):
        ok = a.keys() == b.keys()
        if not ok: print("keys differ", path)
        return all([eq(a[k], b[k], path + (k,)) for k in a if k in b]) and ok
    if isinstance(a, (list, tuple)):
        if len(a) != len(b): print("len differs", path); return False
        return all([eq(x, y, path + (i,)) for i, (x, y) in enumerate(zip(a, b))])
    if isinstance(a, (np.ndarray, float, np.floating)):
        same = np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
        if not same: print("DIFF", path, a, b)
        return same
    same = a == b
    if not same: print("DIFF", path, repr(a)[:300], repr(b)[:300])
    return same


def synthetic():
    """Failure paths of detect and run_split_tests (see the module docstring), every field dumped."""
    from identification import Measurements, simulate
    if os.path.isdir(os.path.join(os.environ.get("PYTHONPATH", "."), "identification", "studies")):
        from identification.studies.detect import detect, run_split_tests, DetectSettings
        from identification.studies.splits import Split, splits_from_scenarios, series_split
        from identification.studies.dynamic_detect import detect_dynamic, early_late_dynamic_split, time_window_splits
    else:
        from identification.detect import detect, run_split_tests, DetectSettings
        from identification.splits import Split, splits_from_scenarios, series_split
        from identification.dynamic_detect import detect_dynamic, early_late_dynamic_split, time_window_splits
    from models.library import linear_model
    from models.press import PRESS_SCENARIOS
    from models import Model

    out = {}
    Q = np.r_[np.linspace(0.0, 1.6, 15), np.linspace(1.6, 0.0, 15)[1:]][:, None]
    m = linear_model(np.array([[1.0, 0.3], [0.2, 1.0]]))
    H = simulate(m, [1.0, 2.0], Q)
    rng = np.random.default_rng(4)
    z = H[None] + np.array([0.01, 0.02]) * rng.standard_normal((3,) + H.shape)
    z[:, 15:, 0] += 0.03
    data = Measurements(Q, z, [0.01, 0.02], sensors=m.sensors)
    splits = tuple(splits_from_scenarios(PRESS_SCENARIOS, len(Q))) + (Split("degenerate", [0, 28], [1, 2, 3]),)
    out["linear"] = dump(detect(m, data, splits, [0.5, 1.5], normality="override"))
    out["linear_holm_paper"] = dump(detect(m, data, splits, [0.5, 1.5], normality="override", statistic="paper", correction="holm", design=["s1"] if "s1" in m.sensors else None))
    d2 = Measurements(Q, z, None, sensors=m.sensors)
    out["sigma_unknown"] = dump(detect(m, d2, splits, [0.5, 1.5], normality="override"))
    out["weights"] = dump(detect(m, data, splits[:2], [0.5, 1.5], normality="override", weights=[1.0, 0.0]))
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))
    X = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    for seed in (3, 5):
        zz = (10.0 * X / (20.0 + X))[None, :, None] + 0.1 * np.random.default_rng(seed).standard_normal((2, X.size, 1))
        dd = Measurements(inputs=X[:, None], z=zz, sigma=[0.1])
        t = run_split_tests(mm, dd, [series_split(X.size, [0], [1], name="s"), Split("a", [0, 1, 2], [3, 4])], [10.0, 20.0],
                            settings=DetectSettings(normality="override"), curvature=True)
        out[f"mm{seed}"] = [{f.name: getattr(x, f.name) for f in dataclasses.fields(x)} for x in t]
    x = np.linspace(0.2, 1.0, 8)[:, None]
    zz = simulate(mm, [1.0, 5.0], x)[None] + 0.01 * np.random.default_rng(1).standard_normal((2, 8, 1))
    out["mm_weak"] = dump(detect(mm, Measurements(x, zz, [0.01], sensors=mm.sensors), [Split("lo", [0, 1, 2, 3], [4, 5, 6, 7]), Split("eo", [0, 2, 4, 6], [1, 3, 5, 7])], [1.0, 5.0], normality="override"))
    if "studies" in detect.__module__:
        from identification.fit.dynamic_fit import simulate_campaign, DiscretisationSettings
    else:
        from identification.dynamic_fit import simulate_campaign, DiscretisationSettings
    from mudoe import example_reactor as R
    Qd = np.array([[1.0, 330.0], [2.0, 345.0], [1.5, 360.0], [1.0, 370.0]])
    dd = simulate_campaign(R.build(), R.P_TRUE, Qd, np.array([0.25, 0.5, 1.0, 1.5, 2.0]), [0.01, 0.01], n_series=2, seed=3)
    sp = [Split("exp 1-2 vs 3-4", [0, 1], [2, 3]), early_late_dynamic_split(dd)] + list(time_window_splits([0.75]))
    out["dyn"] = dump(detect(R.build(), dd, sp, R.P_TRUE * 1.1))
    out["dyn_unbounded"] = dump(detect_dynamic(R.build(), dd, sp[:1], R.P_TRUE, settings=DetectSettings(),
                                discretisation=DiscretisationSettings(tol_sigma=1e-12, max_refinements=0)))
    return out


if __name__ == "__main__":
    if len(sys.argv) != 4 and not (len(sys.argv) == 3 and sys.argv[1] == "--save"):
        sys.exit(__doc__)
    if sys.argv[1] == "--compare":
        A, B = (pickle.load(open(p, "rb")) for p in sys.argv[2:4])
        ok = eq(A, B, ())
        n = sum(len(v["tests"]) if isinstance(v, dict) else len(v) for v in A.values())
        print(f"{len(A)} runs, {n} split tests:", "ALL IDENTICAL (np.array_equal, equal texts)" if ok else "DIFFERENCES")
        sys.exit(0 if ok else 1)
    res = run(CONFIGS)
    res.update(synthetic())
    with open(sys.argv[2], "wb") as f:
        pickle.dump(res, f)
