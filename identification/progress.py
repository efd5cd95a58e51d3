"""Progress on a stream (stderr by default): counted bars (tqdm) and timed steps.

One helper for every long-running loop or step: :meth:`Progress.bar` is a tqdm bar over a
known number of items (e.g. Monte Carlo replications), :meth:`Progress.step` times a step
(seconds, wall clock) and prints ``<prefix><label> ...`` / ``<prefix><label> done in 1.2 s``.
A disabled helper prints nothing; its bar is a disabled tqdm (same calls, no output).
:func:`bar_line_open` says whether a bar drawn here is still open (its line on the stream has no end yet), so
that a last message written around the stream (an interrupt) starts on a line of its own.
"""
from __future__ import annotations

import sys
import time
import weakref
from contextlib import contextmanager

from tqdm import tqdm

__all__ = ["Progress", "bar_line_open"]

#: the bars :meth:`Progress.bar` made (weak: a bar that is gone is not open)
_BARS: "weakref.WeakSet[tqdm]" = weakref.WeakSet()


def bar_line_open() -> bool:
    """Whether a bar of :meth:`Progress.bar` is drawn and not closed: its line (``\\r`` updates) has no
    newline yet (tqdm sets ``disable`` when a bar closes)."""
    return any(not b.disable for b in list(_BARS))


class Progress:
    """Progress lines and bars on a stream, with the wall time of every step.

    Parameters
    ----------
    enabled : bool
        False: print nothing (bars are disabled, steps are still timed).
    stream : file-like, optional
        Where to write (default ``sys.stderr`` at call time).
    prefix : str
        Text before every step line (e.g. "mudoe: ").

    Attributes
    ----------
    timing : dict {label: seconds}
        Accumulated wall time of every step.
    """

    def __init__(self, enabled: bool = True, stream=None, prefix: str = ""):
        self.enabled = bool(enabled)
        self.stream = stream
        self.prefix = prefix
        self.timing: dict = {}

    def _out(self, text: str) -> None:
        if self.enabled:
            print(text, file=self.stream or sys.stderr, flush=True)

    def bar(self, total: int, desc: str, unit: str = "rep") -> tqdm:
        """A tqdm bar over ``total`` items (call ``update(n)`` and ``close()``, or use it in ``with``)."""
        b = tqdm(total=total, desc=desc, unit=unit, file=self.stream or sys.stderr, smoothing=0.1,
                 disable=not self.enabled)
        _BARS.add(b)
        return b

    @contextmanager
    def step(self, label: str, announce: bool = True):
        """Print ``label ...`` and, when done, the elapsed time (s); add it to ``timing[label]``.

        With ``announce=False`` (quick steps, e.g. reading the data) nothing is printed unless the
        step took over a second, so that a bad-input error stays the only line on the stream.
        """
        if announce:
            self._out(f"{self.prefix}{label} ...")
        t0 = time.perf_counter()
        yield
        dt = time.perf_counter() - t0
        self.timing[label] = self.timing.get(label, 0.0) + dt
        if announce or dt > 1.0:
            self._out(f"{self.prefix}{label} done in {dt:.1f} s")
