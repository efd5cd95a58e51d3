"""Run the benchmarks: ``python -m bench [name ...]`` (``make bench`` runs all).

Every module ``bench/bench_<name>.py`` exposes ``main(argv: list[str] | None) -> None``;
results are printed and recorded by hand (with machine and date) in bench/RESULTS.md.
"""
import importlib
import pkgutil
import sys
from pathlib import Path


def available() -> list[str]:
    here = Path(__file__).parent
    return sorted(m.name[len("bench_"):] for m in pkgutil.iter_modules([str(here)]) if m.name.startswith("bench_"))


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    names = [a for a in argv if not a.startswith("-")] or available()
    unknown = [n for n in names if n not in available()]
    if unknown:
        print(f"bench: unknown benchmark {unknown[0]!r}; available: {', '.join(available())}", file=sys.stderr)
        return 2
    for n in names:
        print(f"=== bench {n} ===", flush=True)
        importlib.import_module(f"bench.bench_{n}").main([a for a in argv if a.startswith("-")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
