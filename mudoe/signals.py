"""Ctrl-C (SIGINT) and SIGTERM for the command line: exit 130 / 143 at once, no process left, nothing half-written.

The two signals are blocked in every thread of the process (:meth:`Interrupt.install` runs before
the heavy imports, so every thread started later inherits the mask) and taken by one daemon
thread with ``sigwait``:

* C code running ``system()`` sets SIGINT to "ignore" while its command runs: CasADi's JIT
  compiler runs ``gcc`` so, and a SIGINT that a thread could take then was discarded (issue 20:
  Ctrl-C during the compilation was lost 8 of 8 times).  A blocked signal stays pending and
  ``sigwait`` takes it whatever the handler;
* Ipopt installs its own SIGINT handler during every solve; no handler sees a blocked signal;
* worker processes (:func:`identification.cluster.worker_start`) ignore SIGINT: a terminal's
  Ctrl-C reaches the whole process group, and this process decides for all of them.

On the first signal (:meth:`Interrupt.signalled`) that thread records it (exit code 128 +
signal number: 130 for SIGINT, 143 for SIGTERM), kills every process this one started (worker
processes and the compilers they run; not multiprocessing's resource tracker, which ends by
itself once they are gone and cleans up what they left), closes the outputs
(:func:`models.fileio.close_outputs`: a report being moved into place is moved whole, nothing
is moved after), interrupts the main thread (``KeyboardInterrupt``: the command unwinds, the
temporary files are removed and ``main`` ends the process with the code, :meth:`Interrupt.finish`)
and starts a watchdog: when the
process still runs :data:`GRACE_S` seconds later (the main thread inside a long C call), the
temporary outputs are removed and the process ends with the code (``os._exit``).  A second
signal ends it the same way at once.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

__all__ = ["Interrupt", "INTERRUPT", "EXIT_INTERRUPTED", "EXIT_TERMINATED", "GRACE_S"]

#: exit code of an interrupted run (128 + SIGINT)
EXIT_INTERRUPTED = 128 + int(signal.SIGINT)
#: exit code of a terminated run (128 + SIGTERM)
EXIT_TERMINATED = 128 + int(signal.SIGTERM)
#: seconds after the first signal before the watchdog ends a run that did not stop by itself (s); the
#: watchdog itself takes 0.1-0.2 s on a loaded machine (it looks for the processes started meanwhile)
GRACE_S = 0.3

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_WORDS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated"}


class Interrupt:
    """SIGINT and SIGTERM handling of one CLI run (see the module docstring).

    Attributes
    ----------
    flag : bool         a signal arrived
    signum : int or None  the first signal
    stderr_fd : int     where the one-line message goes (a saved copy of 2 while ``Chatter`` captures 2)
    """

    def __init__(self):
        self.flag = False
        self.signum = None
        self.stderr_fd = 2
        self._previous = {}
        self._waiter = None         # the sigwait thread, started once per process
        self._said = threading.Lock()
        self._told = False

    @property
    def exit_code(self) -> int:
        """128 + the signal's number (130 for Ctrl-C, 143 for SIGTERM)."""
        return EXIT_TERMINATED if self.signum == signal.SIGTERM else EXIT_INTERRUPTED

    # ------------------------------------------------------------------ set up
    def install(self) -> None:
        """Take SIGINT and SIGTERM (main thread only; elsewhere nothing happens): see the module docstring."""
        self.flag, self.signum, self._told = False, None, False
        try:
            self._previous = {s: signal.signal(s, self._handler) for s in _SIGNALS}
        except ValueError:          # not the main thread
            self._previous = {}
            return
        if hasattr(signal, "pthread_sigmask") and hasattr(signal, "sigwait"):
            self.block()            # before any import starts a thread (numpy's BLAS): they all inherit it
            if self._waiter is None:     # one waiting thread per process (main() may run many times)
                self._waiter = threading.Thread(target=self._wait, daemon=True, name="mudoe-signals")
                self._waiter.start()
        from models.fileio import reopen_outputs
        reopen_outputs()

    @staticmethod
    def block() -> None:
        """Block SIGINT and SIGTERM in the calling thread (threads started later inherit it)."""
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_BLOCK, set(_SIGNALS))

    def uninstall(self) -> None:
        """Restore the previous handlers and unblock the signals in the main thread."""
        if self._previous:
            for s, h in self._previous.items():
                signal.signal(s, h)
            self._previous = {}
            if hasattr(signal, "pthread_sigmask"):
                signal.pthread_sigmask(signal.SIG_UNBLOCK, set(_SIGNALS))

    def finish(self) -> None:
        """End of a CLI run: :meth:`uninstall`; after a signal, end the process now with :attr:`exit_code`.

        The run has unwound (outputs cleaned, workers gone); the interpreter's own teardown of the
        loaded libraries takes about a second on a loaded machine, which a signalled process skips.
        """
        self.uninstall()
        if self.signum is not None:
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (OSError, ValueError, AttributeError):
                    continue
            os._exit(self.exit_code)

    # ------------------------------------------------------------------ the signal
    def _wait(self) -> None:
        """Daemon thread: every SIGINT and SIGTERM is taken here (they are blocked, so no handler sees them)."""
        import _thread
        while True:
            signum = signal.sigwait(set(_SIGNALS))
            if not self._previous:          # no CLI run (main() returned): Python's own behaviour
                self._default(signum)
                continue
            if self.flag:
                self.exit_now()
            self.signalled(signum)
            _thread.interrupt_main()

    @staticmethod
    def _default(signum: int) -> None:
        """Outside a CLI run: SIGINT raises KeyboardInterrupt in the main thread, SIGTERM ends the process."""
        import _thread
        if signum == signal.SIGINT:
            _thread.interrupt_main()
        else:
            os._exit(EXIT_TERMINATED)

    def _handler(self, signum, frame):
        """Python-level handler (platforms without ``sigwait``; and ``interrupt_main`` from the waiting thread)."""
        if not self.flag:
            self.signalled(signum)
        raise KeyboardInterrupt

    def signalled(self, signum: int) -> None:
        """First signal: record it, kill the processes this one started, close the outputs, start the watchdog."""
        from models.fileio import close_outputs
        self.flag, self.signum = True, int(signum)
        watchdog = threading.Timer(GRACE_S, self.exit_now)
        watchdog.daemon = True
        watchdog.start()
        kill_children()
        close_outputs()

    def exit_now(self) -> None:
        """End the process with :attr:`exit_code` now: temporary outputs removed, child processes killed."""
        from models.fileio import abandon_outputs
        abandon_outputs()
        kill_children()
        self.announce()
        os._exit(self.exit_code)

    @property
    def message(self) -> str:
        """``mudoe: interrupted`` (SIGINT, or a KeyboardInterrupt without a signal) or ``mudoe: terminated``."""
        return f"mudoe: {_WORDS.get(self.signum, 'interrupted')}"

    def announce(self, write=None) -> int:
        """Write :attr:`message` once per run (``write(text)``, default: to the terminal's stderr descriptor);
        returns :attr:`exit_code`."""
        with self._said:
            if not self._told:
                self._told = True
                from identification.progress import bar_line_open
                if bar_line_open():         # a progress bar's line has no end yet: the message gets its own line
                    with contextlib.suppress(OSError, ValueError):
                        sys.stderr.flush()
                    os.write(self.stderr_fd, b"\n")
                if write is not None:
                    write(self.message)
                else:
                    os.write(self.stderr_fd, (self.message + "\n").encode())
        return self.exit_code

    def check(self) -> None:
        """Raise :class:`KeyboardInterrupt` if a signal arrived (e.g. swallowed by a solver); re-block the
        signals in the calling thread (a library may have unblocked them)."""
        if self._previous:
            self.block()
        if self.flag:
            raise KeyboardInterrupt


def _is_resource_tracker(proc) -> bool:
    """Whether ``proc`` (psutil) is multiprocessing's resource tracker (it ends by itself and cleans up)."""
    import psutil
    try:
        return any("resource_tracker" in part for part in proc.cmdline())
    except psutil.Error:
        return False


def kill_children() -> int:
    """Kill (SIGKILL) every process this one started, and theirs, except the resource tracker; returns how many.

    The worker processes (multiprocessing's) first, at once; then whatever else runs below this
    process (the compilers they or this process started).
    """
    import multiprocessing

    import psutil
    for child in multiprocessing.active_children():
        try:
            os.kill(child.pid, signal.SIGKILL)
        except OSError:
            continue
    try:
        procs = psutil.Process().children(recursive=True)
    except psutil.Error:
        return 0
    procs = [p for p in procs if not _is_resource_tracker(p)]
    for p in procs:                 # not reaped here: multiprocessing waits for its own processes
        try:
            p.kill()
        except psutil.Error:
            continue
    return len(procs)


#: the process-wide signal state of the CLI
INTERRUPT = Interrupt()
