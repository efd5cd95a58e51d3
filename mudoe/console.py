"""The command line's console: the output folder check, solver chatter capture and Ctrl-C.

* :func:`check_out_dir`: ``--out`` exists as a writable folder or can be created (checked
  before any work, nothing is created).
* :class:`Chatter`: during a run, CasADi's and Ipopt's messages (CasADi writes its warnings,
  e.g. ``nlp_g failed: Inf detected``, through Python's ``sys.stderr`` in many pieces, and
  Ipopt's banner through ``sys.stdout``; C code and worker processes write to the file
  descriptors 1 and 2) go to a temporary file; mudoe's own progress lines and bars pass
  through to the terminal.  The captured text is shown only with ``--debug``.
* :class:`Interrupt` (:mod:`mudoe.signals`, re-exported here): Ctrl-C and SIGTERM set a flag,
  kill the worker processes this process started and raise :class:`KeyboardInterrupt`; a
  solver that turns the interrupt into a failed fit cannot hide it (the flag is checked at
  every step and before any output is written); the run ends with 130 (143 for SIGTERM)
  within :data:`mudoe.signals.GRACE_S` seconds at the latest.
"""
from __future__ import annotations

import os
import sys
import tempfile
import warnings
from pathlib import Path

from .signals import EXIT_INTERRUPTED, INTERRUPT, Interrupt

__all__ = ["OutDirError", "check_out_dir", "Chatter", "Interrupt", "INTERRUPT", "EXIT_INTERRUPTED"]


class OutDirError(ValueError):
    """``--out`` cannot be used as the output folder; the message says why."""


def check_out_dir(out) -> Path:
    """The output folder ``out`` once it is known to be usable; nothing is created.

    Usable: an existing writable folder, or a path whose nearest existing ancestor is a
    writable folder (the folder is created when the first output is written).

    Raises
    ------
    OutDirError
        ``out`` is a file, or a folder (or the ancestor that would hold it) is not writable.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutDirError(f"--out: {out} exists and is not a folder; give a folder")
    where = out.absolute()
    while not where.exists():
        where = where.parent
    if not where.is_dir():
        raise OutDirError(f"--out: cannot create {out}: {where} is not a folder")
    try:                                  # a real test (os.access says yes to root, even on /proc)
        with tempfile.TemporaryDirectory(prefix=".mudoe-out-check-", dir=where):
            pass
    except OSError as exc:
        what = "folder" if where == out.absolute() else f"{out}: its parent"
        raise OutDirError(f"--out: cannot write into {what} {where} ({exc.strerror}); choose another --out") \
            from None
    return out


class _Diverter:
    """A text stream in place of ``sys.stderr``: CasADi messages to ``capture``, the rest to ``target``.

    A CasADi message starts with a write of ``"CasADi - "`` and ends with the write ending in a
    newline; everything outside such a message (mudoe's progress lines, tqdm bars) passes through.
    """

    def __init__(self, target, capture):
        self.target, self.capture, self.inside = target, capture, False

    def write(self, text: str) -> int:
        if not self.inside and text.startswith("CasADi - "):
            self.inside = True
        if self.inside:
            self.capture.write(text)
            self.inside = not text.endswith("\n")
        else:
            self.target.write(text)
        return len(text)

    def flush(self) -> None:
        self.target.flush()
        self.capture.flush()

    def isatty(self) -> bool:
        return bool(getattr(self.target, "isatty", lambda: False)())

    @property
    def encoding(self) -> str:
        return getattr(self.target, "encoding", "utf-8")


def _real_fd(stream, fd: int) -> bool:
    """``stream`` writes to the file descriptor ``fd`` (not a pytest capture or a StringIO)."""
    try:
        return stream.fileno() == fd
    except (AttributeError, OSError, ValueError):
        return False


class Chatter:
    """Context manager capturing solver chatter (see the module docstring); ``text`` holds it afterwards.

    Inside the block ``self.stdout`` is the terminal's standard output for mudoe's own results.
    """

    def __init__(self):
        self.text = ""
        self.stdout = sys.stdout

    def __enter__(self) -> "Chatter":
        sys.stdout.flush()
        sys.stderr.flush()
        self._file = tempfile.TemporaryFile(mode="w+", encoding="utf-8", errors="replace")
        self._py = (sys.stdout, sys.stderr)
        self._saved, self._opened = {}, []
        streams = {}
        for fd, stream in ((1, sys.stdout), (2, sys.stderr)):
            self._saved[fd] = os.dup(fd)
            if _real_fd(stream, fd):
                stream = open(self._saved[fd], "w", buffering=1, encoding=getattr(stream, "encoding", "utf-8"),
                              closefd=False)
                self._opened.append(stream)
            streams[fd] = stream
            os.dup2(self._file.fileno(), fd)
        self.stdout = streams[1]
        INTERRUPT.stderr_fd = self._saved[2]
        sys.stdout = self._file
        sys.stderr = _Diverter(streams[2], self._file)
        self._warnings = warnings.catch_warnings(record=True)
        self._caught = self._warnings.__enter__()
        warnings.simplefilter("default")
        return self

    def __exit__(self, *exc) -> None:
        try:
            self._warnings.__exit__(*exc)
            for s in self._opened:
                s.flush()
            self._file.flush()
            INTERRUPT.stderr_fd = 2
            for fd, saved in self._saved.items():
                os.dup2(saved, fd)
                os.close(saved)
        finally:
            sys.stdout, sys.stderr = self._py
            for s in self._opened:
                s.close()
            self._file.seek(0)
            self.text = self._file.read() + "".join(
                f"{w.filename}:{w.lineno}: {w.category.__name__}: {w.message}\n" for w in self._caught)
            self._file.close()
