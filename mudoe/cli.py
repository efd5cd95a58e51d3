"""The ``mudoe`` command line: identify | oed | detect | quantify | report | validate | simulate.

Every subcommand reads a study config (TOML, see ``configs/press.toml``), runs a thin layer
over the library and writes its outputs atomically into ``--out`` (default ``results/``).
Summaries go to stdout (JSON with ``--json``), progress to stderr.

Exit codes: 0 success; 2 bad input (config, data, arguments: one line on stderr, no
traceback); 3 a library piece the command needs is not available yet; 1 a computation
failed (one line; ``--debug`` shows the traceback); 130 interrupted (Ctrl-C), 143 terminated
(SIGTERM): within a second, worker processes ended, nothing half-written (:mod:`mudoe.signals`).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_FAILED", "EXIT_BAD_INPUT", "EXIT_MISSING"]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_MISSING = 0, 1, 2, 3

_COMMANDS = {
    "identify": "identify the parameters of every model variant on the study's data",
    "oed": "optimal sensor selection: criteria of every sensor combination and the chosen design",
    "detect": "Algorithm 1: calibration/validation tests, alpha_min for the three statistics, verdict per model",
    "quantify": "size of the model error of every variant (static and dynamic models): test, error model, held-out coverage",
    "report": "run identify, oed and detect and build report.pdf, PNGs and results.json",
    "validate": "Monte Carlo size study of the test (data simulated from the fitted model), then the held-out "
                "coverage of the variant's bands with and without its model error",
    "simulate": "simulate a campaign of the study ([simulate] section; the press: its virtual prototype) as CSV",
}
_THREADS_HELP = ("Threads: every command runs its linear algebra on one BLAS thread per process (itself and its "
                 "--workers), faster for a study's many small matrices; set OPENBLAS_NUM_THREADS (or "
                 "OMP_NUM_THREADS, MKL_NUM_THREADS) to choose another number, mudoe then keeps it.")
_INIT_HELP = "write a commented study config template for your own model factory (never overwrites)"


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of exiting, so that main() controls the one-line message."""

    def error(self, message):
        raise _UsageError(f"{self.prog}: {message}")


class _UsageError(Exception):
    pass


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (``--help`` on every subcommand)."""
    p = _Parser(prog="mudoe", description="Model uncertainty via optimal design of experiments. "
                "Each command takes a study config (TOML); see README 'Commands' and 'Config reference'.",
                epilog=_THREADS_HELP)
    p.add_argument("--version", action="version", version=f"mudoe {_version()}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, help_ in _COMMANDS.items():
        sp = sub.add_parser(name, help=help_, description=help_ + ".", epilog=_THREADS_HELP)
        sp.add_argument("config", metavar="CONFIG", help="study config file (TOML), e.g. configs/press.toml")
        sp.add_argument("--out", metavar="DIR", default="results",
                        help="output folder (default: results/); files are written atomically")
        sp.add_argument("--json", action="store_true", help="print the result as JSON on stdout")
        sp.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
        sp.add_argument("--debug", action="store_true", help="show the traceback of an unexpected failure")
        if name == "validate":
            sp.add_argument("--runs", type=int, default=None, metavar="N",
                            help="replications (default: [validate] n_runs of the config)")
            sp.add_argument("--workers", type=int, default=1, metavar="N",
                            help="local worker processes (default 1)")
            sp.add_argument("--scheduler", default=None, metavar="ADDRESS",
                            help="run the replications on a Dask cluster: the scheduler address printed "
                                 "by `dask scheduler`, e.g. tcp://10.0.0.5:8786 (default: [validate] "
                                 "scheduler of the config, absent: local processes)")
            sp.add_argument("--no-model-error", action="store_true",
                            help="skip the held-out coverage of the variant's bands with its model error "
                                 "(default: [validate] model_error of the config, true)")
        if name == "simulate":
            sp.add_argument("--seed", type=int, default=None,
                            help="random seed (default: [simulate] seed, the press: [data] seed)")
    sp = sub.add_parser("init", help=_INIT_HELP, description=_INIT_HELP + ".")
    sp.add_argument("path", metavar="PATH", help="the config file to write, e.g. my_study.toml")
    sp.add_argument("--model", metavar="MODULE:FUNCTION", default=None,
                    help="your model factory; its parameters, inputs and sensors fill the template")
    sp.add_argument("--debug", action="store_true", help="show the traceback of an unexpected failure")
    return p


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("mudoe")
    except PackageNotFoundError:
        return "(not installed)"


def _bad_input_types():
    from identification.errors import BadStartError, DataError
    from identification.studies.splits import SplitError
    from models.contract import ModelError
    from .config import ConfigError
    from .console import OutDirError
    from .data_io import DataFileError
    return (ConfigError, DataFileError, DataError, SplitError, ModelError, OutDirError, BadStartError)


def _located(exc: Exception, args) -> str:
    """The message of a bad-input error; a library error that names no file gets the study's config file."""
    from identification.errors import DataError
    from identification.studies.splits import SplitError
    msg, config = str(exc), getattr(args, "config", None)
    if isinstance(exc, (DataError, SplitError)) and config and Path(config).name not in msg:
        return f"{config}: {msg}"
    return msg


def _print_line(msg: str) -> None:
    print(" ".join(str(msg).split()), file=sys.stderr)


def main(argv=None) -> int:
    """Run the CLI; returns the exit code (never raises for bad input).

    The run has one BLAS thread, in this process and in the workers it starts, unless the user set
    OPENBLAS_NUM_THREADS, OMP_NUM_THREADS or the like (:mod:`mudoe.blas_threads`); entered first, before
    anything imports numpy.
    """
    from .blas_threads import one_blas_thread
    with one_blas_thread():
        from .signals import INTERRUPT
        INTERRUPT.install()
        try:
            return _main(argv)
        except KeyboardInterrupt:
            return INTERRUPT.announce(_print_line)
        finally:
            INTERRUPT.finish()               # after SIGINT / SIGTERM: ends the process with 130 / 143


def _main(argv) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except _UsageError as exc:
        _print_line(f"{exc} (see mudoe --help)")
        return EXIT_BAD_INPUT
    except SystemExit as exc:          # --help
        return int(exc.code or 0)
    if not args.command:
        parser.print_help(sys.stderr)
        return EXIT_BAD_INPUT
    from .signals import INTERRUPT
    try:
        code = _run(args)
        INTERRUPT.check()
        return code
    except KeyboardInterrupt:
        return INTERRUPT.announce(_print_line)
    except Exception as exc:  # noqa: BLE001 -- the CLI boundary turns every failure into one line
        if INTERRUPT.flag:               # e.g. a worker pool broken by Ctrl-C or SIGTERM
            return INTERRUPT.announce(_print_line)
        from .study import MissingPieceError
        bad = _bad_input_types()
        if isinstance(exc, bad):
            _print_line(f"mudoe {args.command}: error: {_located(exc, args)}")
            return EXIT_BAD_INPUT
        if isinstance(exc, MissingPieceError):
            _print_line(f"mudoe {args.command}: not available: {exc}")
            return EXIT_MISSING
        if isinstance(exc, OSError):
            _print_line(f"mudoe {args.command}: error: {exc}")
            return EXIT_BAD_INPUT
        if args.debug:
            raise
        _print_line(f"mudoe {args.command}: failed: {type(exc).__name__}: {exc} (rerun with --debug for details)")
        return EXIT_FAILED


def _run(args) -> int:
    from .config import load_config
    from .console import Chatter
    if args.command == "init":
        return _init(args)
    from .outdir import begin, check_out
    out = check_out(args.out)
    cfg = load_config(args.config)
    begin(out, cfg.path)
    from .limits import check_sizes
    check_sizes(cfg, args.command, runs=getattr(args, "runs", None))
    chatter = Chatter()
    try:
        with chatter:
            args.stdout = chatter.stdout
            return _run_study(args, cfg, out)
    finally:
        if args.debug and chatter.text.strip():
            sys.stderr.write("mudoe: solver messages captured during the run:\n" + chatter.text)


def _run_study(args, cfg, out: Path) -> int:
    from .study import Progress, StudyResults, prepare
    t0 = time.perf_counter()
    progress = Progress(enabled=not args.quiet)
    if args.command == "simulate":
        return _simulate(cfg, args, progress, out)
    if args.command == "oed" and cfg.oed.planned:
        return _oed_planned(cfg, args, progress, out, t0)
    study = prepare(cfg, progress, command=args.command)
    results = StudyResults(study)
    handler = {"identify": _identify, "oed": _oed, "detect": _detect, "validate": _validate,
               "report": _report, "quantify": _quantify}[args.command]
    code = handler(study, results, args, progress, out)
    if not args.quiet:
        print(f"mudoe: {args.command} finished in {time.perf_counter() - t0:.1f} s; outputs in {out}/",
              file=sys.stderr)
    return code


def _emit(args, text: str, obj) -> None:
    from reports.serialize import dumps
    stdout = getattr(args, "stdout", sys.stdout)
    stdout.write(dumps(obj) if args.json else text.rstrip() + "\n")
    stdout.flush()


def _write(out: Path, files: dict) -> list:
    """Write a command's outputs ``{name: text}`` into ``out`` as one (all or none, models.fileio)."""
    from models.fileio import atomic_write_texts
    from .console import INTERRUPT
    from .outdir import claim, record
    INTERRUPT.check()
    claim(out)
    paths = atomic_write_texts({out / name: text for name, text in files.items()})
    record(out, paths)
    return paths


def _identify_diagnostics(est) -> dict:
    """Curvature (Bates-Watts), weakest direction and (``[identify] starts`` > 1) every start of an estimate for
    identify's JSON output."""
    import numpy as np
    out = {}
    if est.diagnostics.starts is not None:
        out["multistart"] = est.diagnostics.starts.to_dict()
    sd = est.sloppy_direction
    if sd is not None:
        out["weakest_direction"] = dict(text=str(sd), sloppy=sd.sloppy.tolist(), stiff=sd.stiff.tolist(),
                                        stderr_ratio=sd.ratio)
    if est.model is not None and est.dof >= 1:
        try:
            c = est.curvature
        except np.linalg.LinAlgError as exc:
            out["curvature"] = dict(error=str(exc))
        else:
            out["curvature"] = dict(intrinsic=c.intrinsic, parameter_effects=c.parameter_effects,
                                    critical=c.critical, alpha=c.alpha, trustworthy=c.trustworthy)
    return out


def _identify(study, results, args, progress, out) -> int:
    from reports.serialize import dumps, estimate_dict
    from .study import FitFailedError, run_identify
    from .uncertainty_runs import summary_intervals
    results = run_identify(study, results, progress)
    failed = "; ".join(f"the fit of {v} failed ({e})" for v, e in results.estimate_errors.items())
    if not results.estimates:
        raise FitFailedError(failed)
    obj = {v: dict(estimate_dict(e), **_identify_diagnostics(e)) for v, e in results.estimates.items()}
    obj.update({v: dict(error=e) for v, e in results.estimate_errors.items()})
    text = "\n\n".join([e.summary(intervals=summary_intervals(e)) for e in results.estimates.values()]
                       + [f"{v}: identification failed: {e}" for v, e in results.estimate_errors.items()])
    _write(out, {"identify.json": dumps(obj), "identify.txt": text + "\n"})
    _emit(args, text, obj)
    if failed:
        _print_line(f"mudoe identify: failed: {failed}; the other fits are in {out}/identify.json")
        return EXIT_FAILED
    return EXIT_OK


def _oed_planned(cfg, args, progress, out, t0) -> int:
    """``[oed] planned = true``: the design before data (no data read), oed.json / oed.txt."""
    from reports.serialize import dumps
    from .study import plan_without_data
    plan = plan_without_data(cfg, progress)
    text = plan.summary()
    _write(out, {"oed.json": dumps(plan.to_dict()), "oed.txt": text + "\n"})
    _emit(args, text, plan.to_dict())
    if not args.quiet:
        print(f"mudoe: oed finished in {time.perf_counter() - t0:.1f} s; outputs in {out}/", file=sys.stderr)
    return 0


def _oed(study, results, args, progress, out) -> int:
    from reports.serialize import dumps
    from .study import oed_files
    text, obj = oed_files(study, results, progress)
    _write(out, {"oed.json": dumps(obj), "oed.txt": text + "\n"})
    _emit(args, text, obj)
    return EXIT_OK


def _detect(study, results, args, progress, out) -> int:
    from reports.diagnosis import findings_text
    from reports.serialize import detection_dict, diagnosis_dict, dumps
    from reports.tables import normality_labels
    from .report_record import study_setup
    from .study import run_detect, run_diagnosis
    results = run_diagnosis(study, run_detect(study, results, progress), progress)
    labels = normality_labels(study_setup(study))
    diag = results.diagnosis               # None for a dynamic study (no diagnostic split family)
    obj = dict(detection_dict(results.detection, **labels), diagnosis=None if diag is None else diagnosis_dict(diag))
    text = results.detection.summary(**labels) + ("" if diag is None else "\n\n" + findings_text(
        diag, results.detection.models))
    _write(out, {"detect.json": dumps(obj), "detect.txt": text + "\n"})
    _emit(args, text, obj)
    return EXIT_OK


def _quantify(study, results, args, progress, out) -> int:
    from reports.serialize import dumps
    from .model_error_runs import error_summaries, quantify_dict, quantify_text, quantify_text_full, run_model_error
    results = run_model_error(study, results, progress)
    if not results.model_error:
        from .study import FitFailedError
        raise FitFailedError("; ".join(f"model error of {v}: {e}" for v, e in results.model_error_errors.items())
                             or "no model variant")
    with progress.step("model-error summaries and next runs"):
        summaries, failed = error_summaries(study, results)
    obj = quantify_dict(study, results, summaries, failed)
    _write(out, {"quantify.json": dumps(obj), "quantify.txt": quantify_text_full(study, results, summaries) + "\n"})
    _emit(args, quantify_text(study, results, summaries), obj)
    return EXIT_FAILED if results.model_error_errors else EXIT_OK


def _validate(study, results, args, progress, out) -> int:
    from reports.serialize import dumps, validation_dict
    from .study import run_validate
    if args.runs is not None:
        if args.runs < 1:
            from .config import ConfigError
            raise ConfigError(f"--runs: need at least one replication, got {args.runs}")
        cfg = dataclasses.replace(study.cfg, validate=dataclasses.replace(study.cfg.validate, n_runs=args.runs))
        study = dataclasses.replace(study, cfg=cfg)
        results = dataclasses.replace(results, study=study)
    if args.workers < 1:
        from .config import ConfigError
        raise ConfigError(f"--workers: need at least one worker, got {args.workers}")
    if args.scheduler is not None and not args.scheduler.strip():
        from .config import ConfigError
        raise ConfigError("--scheduler: give the Dask scheduler address printed by `dask scheduler`, "
                          "e.g. tcp://10.0.0.5:8786, or leave the option out for local processes")
    results = run_validate(study, results, progress, workers=args.workers, scheduler=args.scheduler)
    obj = validation_dict(results.validation)
    text = results.validation.summary()
    if study.cfg.validate.model_error and not args.no_model_error:
        from .model_error_runs import validate_model_error
        variant = study.cfg.validate.variant or next(iter(study.models))       # the one run_validate simulated
        lines, obj["model_error"] = validate_model_error(study, results, variant, progress)
        text += "\n\n" + lines
    _write(out, {"validate.json": dumps(obj), "validate.txt": text + "\n"})
    _emit(args, text, obj)
    return EXIT_OK


def _report(study, results, args, progress, out) -> int:
    from reports.builder import build_report
    from reports.diagnosis import findings_text
    from .outdir import claim, record
    from .report_record import study_record
    t0 = time.perf_counter()
    results = _report_results(study, results, progress)
    timing = dict(progress.timing)
    timing["analysis_total"] = time.perf_counter() - t0
    results = dataclasses.replace(results, timing=timing)
    with progress.step("build report"):
        claim(out)
        paths = build_report(study_record(results), out, progress=progress)
        record(out, paths)
    text = "\n".join(str(p) for p in paths)
    obj = {"files": [str(p) for p in paths], "verdicts": {}}
    if results.detection is not None:
        diag = results.diagnosis
        text = ("\n".join(f"{m}: {d}" for m, d in results.detection.verdicts.items()) + "\n\n"
                + ("" if diag is None else findings_text(diag, results.detection.models) + "\n\n") + text)
        obj.update(verdicts=dict(results.detection.verdicts),
                   misses={} if diag is None else {m: diag.misses(m) for m in results.detection.models})
    _emit(args, text, obj)
    return EXIT_OK


def _report_results(study, results, progress):
    """Everything the report shows, computed by the study (the report only draws it)."""
    from .study import (FitFailedError, MissingPieceError, run_bands, run_detect, run_diagnosis, run_identify,
                        run_oed, run_report_pages, run_uncertainty)
    results = run_identify(study, results, progress)
    try:
        results = run_oed(study, results, progress)
    except (MissingPieceError, FitFailedError) as exc:
        results = results.with_note(f"optimal design not available: {exc}")
    if study.cfg.oed.mode != "sensors":
        results = dataclasses.replace(results, plan=study.kind.plan_at_estimate(study, results, progress))
    try:
        results = run_detect(study, results, progress)
    except (MissingPieceError, FitFailedError) as exc:
        results = results.with_note(f"detection not available: {exc}")
    except _bad_input_types() as exc:      # e.g. the normality gate failed: report it, do not hide it
        results = dataclasses.replace(results, detection_error=f"{type(exc).__name__}: {exc}")
        results = results.with_note(f"detection stopped: {exc}")
    results = run_report_pages(study, run_diagnosis(study, results, progress), progress)
    return run_uncertainty(study, run_bands(study, results), progress=progress)


def _init(args) -> int:
    from .template import write_template
    path = write_template(args.path, args.model)
    print(f"mudoe: wrote {path}; edit it, then run: mudoe identify {path}", file=sys.stderr)
    return EXIT_OK


def _simulate(cfg, args, progress, out) -> int:
    if args.seed is not None and args.seed < 0:
        from .config import ConfigError
        raise ConfigError(f"--seed: must be non-negative, got {args.seed}")
    from .registry import builtin_model
    builtin = builtin_model(cfg.model.name)
    if builtin is None or builtin.prototype is None:
        return _simulate_study(cfg, args, progress, out)
    seed = cfg.data.seed if args.seed is None else args.seed
    with progress.step(f"simulate the virtual prototype (seed {seed}, {cfg.data.n_series} series)"):
        camp = builtin.prototype.generate(seed=seed, n_series=cfg.data.n_series)
    _interrupt_check()
    from .outdir import claim, record
    claim(out)
    paths = builtin.prototype.write(camp, out)
    record(out, paths)
    text = "\n".join(str(p) for p in paths)
    _emit(args, text, {"files": [str(p) for p in paths], "seed": seed, "n_series": cfg.data.n_series})
    return EXIT_OK


def _interrupt_check() -> None:
    from .console import INTERRUPT
    INTERRUPT.check()


def _simulate_study(cfg, args, progress, out) -> int:
    """An own model's campaign in its kind's data format (the study's [data] layout, file names and units, or
    the long time-series CSV), plus simulate.json."""
    from .outdir import claim, record as record_files
    from .study import simulate
    with progress.step(f"simulate {cfg.model.name}", announce=False):
        sim = simulate(cfg, args.seed)
    _interrupt_check()
    claim(out)
    paths, record = sim.write(cfg, out)
    record_files(out, paths)
    _emit(args, "\n".join(str(p) for p in paths), record)
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
