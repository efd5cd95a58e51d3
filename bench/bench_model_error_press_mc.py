"""Issue 29's press coverage target over fresh campaigns of the virtual prototype (issue 29 item 5, session 13).

The target: "Press, every variant and every split: held-out coverage of the 95 % new-reading bands in [90, 99] %,
with bands no wider than the error requires (median widening per variant)".  One campaign gives one coverage per
split, and with 28 or 56 held-out readings a band of exactly 95 % lands in [90, 99] % only part of the time
(:func:`binomial_fact`); so the bands are judged over ``--n`` fresh campaigns:

* each campaign is :func:`models.prototype.generate_campaign` with its own seed (``[data] source = "prototype"``
  in configs/press.toml: its own gauge linearity error, drawn once per campaign, its own repeatability noise and
  force scatter; 6 series, the study on series 4 and 5 as shipped); the study is :func:`mudoe.study.prepare` of
  that config, sigma composed from the campaign's own sigma_rep;
* the model error is the product's: :func:`mudoe.model_error_runs.run_model_error` (kind auto, the study's four
  split scenarios, the noise :func:`mudoe.model_error_runs.error_noise`: sigma_rep of the composed sigma) on the
  sensors F_x and B0_y of the shipped study's E-optimal design (``[detect] sensors``; ``--sensors=oed`` lets
  each campaign design its own, which picks D_y and F_x on some campaigns);
* per variant M1/M2/M3 and split: the held-out coverage of the 95 % new-reading bands of the chosen error model
  (``HeldOut.coverage(kind)``), the discrepancy's and the plain ones, and the median widening (band width over the
  plain band of the same noise).  ``--compare`` also runs ``model_error`` with the study's composed sigma (the
  behaviour before session 13) on the same campaigns and sensors.

Reported per variant and split: mean coverage over campaigns +- its standard error, the fraction of campaigns in
[90, 99] % (Clopper-Pearson 95 %), the coverage pooled over campaigns; per variant the pooled coverage over splits
and the median widening; and the same numbers for the shipped campaign (data/press_campaign).  The campaigns run
on the replication engine (:func:`identification.replicate.replicate`, serial by default; replication r draws its
prototype seed from ``SeedSequence(--seed).spawn(n)[r]``).  M2 and M3 use the shipped friction constants
(data/press_friction.json, trained on the shipped campaign's series 1-4) on every campaign, as a study of a
prototype campaign does; the prototype's friction is the same in every campaign.

Run ``python -m bench model_error_press_mc --n=60 --compare`` (``--timing`` times one campaign first;
``--save=FILE.json`` keeps every campaign's rows; ``--need --n=0 --skip-shipped``: on the shipped campaign the
factor the discrepancy's bands could shrink by and still hold 95 %, and their width, with either noise).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from identification import model_error
from identification.cluster import seed_chunks
from identification.replicate import ReplicationTask, replicate
from identification.studies.montecarlo import clopper_pearson
from mudoe.config import load_config
from mudoe.model_error_runs import error_noise, run_model_error
from mudoe.study import StudyResults, prepare

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"
#: the sensors of the model error: the shipped study's E-optimal design (``[detect] sensors``; "oed" designs
#: them on each campaign, where the design sometimes picks D_y and F_x)
SENSORS = ("F_x", "B0_y")
#: the target's interval of held-out coverage
TARGET = (0.90, 0.99)
#: a record's row: variant, split and what was measured (the composed-sigma columns NaN without ``--compare``)
ROW_KEYS = ("variant", "split", "n", "unseen", "kind", "cover", "plain", "discrepancy", "widening",
            "cover_composed", "widening_composed", "kind_composed")


@dataclass(frozen=True, eq=False)
class CampaignRecord:
    """One campaign: its prototype seed (None: the shipped campaign), the design's sensors, the rows (dicts of
    :data:`ROW_KEYS`), the variants whose model error failed with the reason, the CPU seconds it took."""

    index: int
    seed: int | None
    sensors: tuple
    rows: tuple
    failed: dict
    cpu: float


def _study(seed: int | None, sensors):
    """The press study of configs/press.toml on the prototype campaign of ``seed`` (None: the shipped CSV), its
    ``[detect] sensors`` = ``sensors`` ("oed": the E-optimal design at the M3 estimate of each campaign)."""
    cfg = load_config(CONFIG)
    if seed is not None:
        cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, source="prototype", seed=int(seed)))
    return prepare(dataclasses.replace(cfg, detect=dataclasses.replace(cfg.detect, sensors=sensors)))


def campaign_record(index: int, seed: int | None, compare: bool = False, sensors=SENSORS) -> CampaignRecord:
    """The held-out coverage of every variant and split on one campaign (:func:`_study`), the product's way
    (:func:`run_model_error`); with ``compare`` also ``model_error`` with the study's composed sigma."""
    c0 = time.process_time()
    study = _study(seed, sensors)
    results = run_model_error(study, StudyResults(study), embedded=False)
    used = set(results.design_sensors)
    w = np.array([1.0 if s in used else 0.0 for s in study.sensors])
    rows = []
    for v, r in results.model_error.items():
        old = (model_error(study.models[v], study.data[v], study.start_values(v), splits=study.splits, weights=w,
                           alpha=r.alpha) if compare else None)
        for j, h in enumerate(r.heldout):
            ho = old.heldout[j] if old is not None else None
            rows.append(dict(variant=v, split=h.split, n=h.n_values, unseen=h.n_unseen, kind=r.kind,
                             cover=h.coverage(r.kind), plain=h.coverage_plain, discrepancy=h.coverage_discrepancy,
                             widening=h.widening(r.kind),
                             cover_composed=np.nan if ho is None else ho.coverage(old.kind),
                             widening_composed=np.nan if ho is None else ho.widening(old.kind),
                             kind_composed="" if old is None else old.kind))
    return CampaignRecord(index, seed, tuple(results.design_sensors), tuple(rows), dict(results.model_error_errors),
                          time.process_time() - c0)


@dataclass(frozen=True, eq=False)
class PressCampaignTask(ReplicationTask):
    """Replication r: a fresh prototype campaign of seed ``SeedSequence(seed).spawn(n)[r].generate_state(1)[0]``
    and :func:`campaign_record` on it."""

    compare: bool = False
    sensors: tuple | str = SENSORS
    jit: bool = False

    def run_chunk(self, chunk: list) -> list:
        out = []
        for index, ss in chunk:
            rec = campaign_record(index, int(ss.generate_state(1)[0]), self.compare, self.sensors)
            print(f"  campaign {index + 1} (seed {rec.seed}): {rec.cpu:.1f} s CPU, sensors {', '.join(rec.sensors)}; "
                  + ", ".join(f"{r['variant']} {100 * r['cover']:.0f}" for r in rec.rows)
                  + (f"; FAILED {rec.failed}" if rec.failed else ""), file=sys.stderr, flush=True)
            out.append(rec)
        return out


def shipped_need(sensors, alpha: float = 0.05) -> None:
    """On the shipped campaign, per variant and split, for each noise (sigma_rep, the composed sigma): the factor
    the discrepancy's held-out new-reading bands could shrink by and still hold (1 - alpha) of the validation
    readings (the (1 - alpha) quantile of |z - mean| / half-width; < 1 wider than the error requires) and their
    median full width (um); readings in a condition not seen are predicted as a new draw, as the held-out table."""
    from identification.studies.discrepancy_gp import InputScaling
    from identification.studies.model_error import unseen_rows
    from identification.studies.model_error_fit import fit_model_error
    from mudoe.model_error_runs import error_data
    study = _study(None, sensors)
    w = np.array([1.0 if s in sensors else 0.0 for s in study.sensors])
    noise = error_noise(study, sensors)
    print("shipped campaign: need (width um) of the discrepancy's held-out bands, noise sigma_rep | composed sigma")
    for v, m in study.models.items():
        for sp in study.splits:
            out = []
            for d in (error_data(study, v, noise), study.data[v]):
                scaling = InputScaling.of(d.inputs, {}, tuple(m.inputs))
                cal, val = sp.calibration(d), sp.validation(d)
                f = fit_model_error(m, cal, study.p0, w, scaling, "discrepancy")
                b = f.predict(val.inputs, alpha, True, conditions=np.where(unseen_rows(sp, d), -1, 0))
                z = val.z[:, :, w > 0]
                ok = np.isfinite(z)
                e = np.abs(z - b.mean[None][:, :, w > 0]) / (b.upper - b.mean)[None][:, :, w > 0]
                width = np.broadcast_to((b.upper - b.lower)[None][:, :, w > 0], z.shape)[ok]
                out.append(f"{float(np.quantile(e[ok], 1 - alpha)):.2f} ({1e3 * float(np.median(width)):.1f})")
            print(f"  {v:<4} {sp.name:<32} {out[0]:>12} | {out[1]:>12}")


# ---------------------------------------------------------------------------- the numbers
def binomial_fact() -> None:
    """P(one split's coverage in [90, 99] %) for a band of exactly 95 % on n independent readings."""
    print("one split, a band of exactly 95 % coverage, n independent readings (X ~ Binomial(n, 0.95)):")
    for n in (28, 56):
        lo, hi = int(np.ceil(TARGET[0] * n - 1e-9)), int(np.floor(TARGET[1] * n + 1e-9))
        p = stats.binom.cdf(hi, n, 0.95) - stats.binom.cdf(lo - 1, n, 0.95)
        print(f"  n = {n}: coverage in [90, 99] % means {lo} <= X <= {hi} ({100 * lo / n:.1f}-{100 * hi / n:.1f} %): "
              f"P = {100 * p:.1f} %; P(X = n, 100 %) = {100 * 0.95 ** n:.1f} %, P(below 90 %) = "
              f"{100 * stats.binom.cdf(lo - 1, n, 0.95):.1f} %")
    p28 = [stats.binom.cdf(int(np.floor(TARGET[1] * n + 1e-9)), n, 0.95)
           - stats.binom.cdf(int(np.ceil(TARGET[0] * n - 1e-9)) - 1, n, 0.95) for n in (28, 56)]
    four = p28[0] ** 2 * p28[1] ** 2
    print(f"  all four splits of one variant (28, 28, 56, 56 readings, independent): {100 * four:.1f} %; all 12 "
          f"splits: {100 * four ** 3:.2f} %")


def _inside(c: np.ndarray) -> np.ndarray:
    return (c >= TARGET[0] - 1e-12) & (c <= TARGET[1] + 1e-12)


def table(records, title: str, key: str = "cover", widen: str = "widening") -> None:
    """Per variant and split: mean coverage +- SE over campaigns, fraction in [90, 99] % (Clopper-Pearson 95 %),
    pooled coverage, median widening; per variant the pooled coverage over its splits and campaigns (SE over the
    campaigns' pooled coverage) and the fraction of campaigns with every split in [90, 99] %."""
    rows = [r for rec in records for r in rec.rows]
    n_c = len(records)
    print(f"{title}: {n_c} campaign(s)")
    print(f"  {'variant':<7} {'split':<32} {'n':>3} {'mean %':>7} {'+- SE':>6} {'in [90,99]':>10} {'CP 95 %':>14} "
          f"{'pooled %':>8} {'100 %':>6} {'<90 %':>6} {'widen':>6}")
    for v in dict.fromkeys(r["variant"] for r in rows):
        mine = [r for r in rows if r["variant"] == v]
        splits = list(dict.fromkeys(r["split"] for r in mine))
        for sp in splits:
            c = np.array([r[key] for r in mine if r["split"] == sp], float)
            n = np.array([r["n"] for r in mine if r["split"] == sp], float)
            k = int(_inside(c).sum())
            ci = clopper_pearson(k, len(c))
            se = c.std(ddof=1) / np.sqrt(len(c)) if len(c) > 1 else np.nan
            wid = np.median([r[widen] for r in mine if r["split"] == sp])
            print(f"  {v:<7} {sp:<32} {int(n[0]):>3} {100 * c.mean():>7.1f} {100 * se:>6.1f} {100 * k / len(c):>9.0f}% "
                  f"{f'[{100 * ci.lo:.0f}, {100 * ci.hi:.0f}]':>14} {100 * (c * n).sum() / n.sum():>8.1f} "
                  f"{100 * np.mean(c >= 1 - 1e-12):>5.0f}% {100 * np.mean(c < TARGET[0] - 1e-12):>5.0f}% {wid:>6.2f}")
        per = {}                                          # campaign -> (covered, readings) over the variant's splits
        for rec in records:
            rr = [r for r in rec.rows if r["variant"] == v]
            if rr:
                per[rec.index] = (sum(r[key] * r["n"] for r in rr), sum(r["n"] for r in rr),
                                  all(_inside(np.array([r[key]])).all() for r in rr) and len(rr) == len(splits))
        pooled = np.array([a / b for a, b, _ in per.values()])
        se = pooled.std(ddof=1) / np.sqrt(len(pooled)) if len(pooled) > 1 else np.nan
        every = sum(x for _, _, x in per.values())
        kinds = {}
        for rec in records:
            kk = next((r["kind" if key == "cover" else "kind_composed"] for r in rec.rows if r["variant"] == v), None)
            kinds[kk] = kinds.get(kk, 0) + 1
        total = sum(a for a, _, _ in per.values()) / sum(b for _, b, _ in per.values())
        print(f"  {v:<7} {'pooled over splits':<32} {'':>3} {100 * pooled.mean():>7.1f} {100 * se:>6.1f} "
              f"{'':>10} {'':>14} {100 * total:>8.1f} "
              f"{'':>6} {'':>6} {np.median([r[widen] for r in mine]):>6.2f}   every split in [90, 99] %: "
              f"{every} of {len(per)} campaigns; kind {kinds}")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench model_error_press_mc")
    ap.add_argument("--n", type=int, default=60, help="fresh prototype campaigns")
    ap.add_argument("--seed", type=int, default=2913, help="SeedSequence of the campaigns' prototype seeds")
    ap.add_argument("--workers", type=int, default=1, help="local processes of the replication engine (1: serial)")
    ap.add_argument("--compare", action="store_true", help="also model_error with the composed sigma (before)")
    ap.add_argument("--timing", action="store_true", help="time one prototype campaign and one study first")
    ap.add_argument("--sensors", default=",".join(SENSORS),
                    help='sensors of the model error, comma list, or "oed" (each campaign\'s E-optimal design)')
    ap.add_argument("--skip-shipped", action="store_true", help="no table of the shipped campaign")
    ap.add_argument("--need", action="store_true", help="the shipped campaign's need and band widths per split")
    ap.add_argument("--save", default="", help="write every campaign's rows to this JSON file")
    args = ap.parse_args(argv or [])
    sensors = args.sensors if args.sensors in ("oed", "all") else tuple(args.sensors.split(","))
    print(f"sensors of the model error: {sensors}")
    binomial_fact()
    if args.timing:
        from models.prototype import generate_campaign
        c0, t0 = time.process_time(), time.perf_counter()
        generate_campaign(seed=1)
        print(f"one prototype campaign (6 series x 29 set points): {time.process_time() - c0:.2f} s CPU, "
              f"{time.perf_counter() - t0:.2f} s wall")
    if args.need:
        shipped_need(sensors if isinstance(sensors, tuple) else SENSORS)
    if not args.skip_shipped:
        shipped = campaign_record(0, None, compare=True, sensors=sensors)
        print(f"shipped campaign: {shipped.cpu:.1f} s CPU (with the composed-sigma run), sensors "
              f"{', '.join(shipped.sensors)}" + (f"; FAILED {shipped.failed}" if shipped.failed else ""))
        table([shipped], "shipped campaign, noise sigma_rep (as of session 13)")
        table([shipped], "shipped campaign, noise the composed sigma (before)", "cover_composed", "widening_composed")
    if args.n:
        t0, c0 = time.perf_counter(), time.process_time()
        reps = replicate(PressCampaignTask(compare=args.compare, sensors=sensors), args.n,
                         lambda w: seed_chunks(args.n, args.seed, w), workers=args.workers)
        recs = reps.records
        cpu = sum(r.cpu for r in recs)
        failed = [(r.index, r.failed) for r in recs if r.failed]
        designs = {}
        for r in recs:
            designs[r.sensors] = designs.get(r.sensors, 0) + 1
        print(f"{args.n} prototype campaigns (seed {args.seed}): {time.perf_counter() - t0:.0f} s wall, "
              f"{cpu:.0f} s CPU in the campaigns ({cpu / args.n:.1f} s each), {time.process_time() - c0:.0f} s "
              "CPU here; "
              f"designs {designs}; failed {failed or 'none'}")
        table(recs, "prototype campaigns, noise sigma_rep (as of session 13)")
        if args.compare:
            table(recs, "prototype campaigns, noise the composed sigma (before)", "cover_composed",
                  "widening_composed")
        if args.save:
            Path(args.save).write_text(json.dumps([dict(index=r.index, seed=r.seed, sensors=list(r.sensors),
                                                        rows=list(r.rows), failed=r.failed, cpu=r.cpu) for r in recs],
                                                  indent=1, default=float))


if __name__ == "__main__":
    main(sys.argv[1:])
