"""Test configuration: single-threaded BLAS (tiny matrices; threads only add contention).

``MUDOE_TEST_SLOW_CLOCK=K`` (a number > 1) makes this process's clocks (``time.time``, ``time.monotonic``,
``time.perf_counter`` and their ``_ns`` forms) run K times fast, as if the machine were K times slower: a test
whose result depends on a time limit or a measured speed then fails at once instead of once in a while under
load (issue 27; ``make test-slow-clock``).  Clocks of other processes and of the solvers' C code (SCIP's,
Ipopt's) are not affected.
"""
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")


def _dilate(clock, factor: float):
    origin = clock()

    def dilated():
        return origin + (clock() - origin) * factor
    return dilated


def _dilate_ns(clock, factor: float):
    origin = clock()

    def dilated():
        return origin + int((clock() - origin) * factor)
    return dilated


_SLOW = os.environ.get("MUDOE_TEST_SLOW_CLOCK")
if _SLOW:
    _factor = float(_SLOW)
    if not _factor > 1:
        raise ValueError(f"MUDOE_TEST_SLOW_CLOCK: expected a number > 1, got {_SLOW!r}")
    for _name in ("time", "monotonic", "perf_counter"):
        setattr(time, _name, _dilate(getattr(time, _name), _factor))
        setattr(time, _name + "_ns", _dilate_ns(getattr(time, _name + "_ns"), _factor))
