"""Atomic file writing shared by the data writers (prototype, friction constants, CLI outputs, the report).

Outputs are written under a temporary name and moved into place by ``os.replace`` once complete.
For a process that must end at once (Ctrl-C, SIGTERM: ``mudoe.signals``) this module also keeps

* the temporary files and folders being written (:func:`scratch`), which :func:`abandon_outputs`
  removes, and
* the moves into place (:func:`publishing`): :func:`close_outputs` waits for one in progress and
  refuses any later one, so that a set of outputs is published whole or not at all.
"""
from __future__ import annotations

import os
import secrets
import shutil
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_write_text", "atomic_write_texts", "create_text", "register_scratch", "release_scratch", "scratch", "publishing", "close_outputs", "reopen_outputs", "abandon_outputs"]

_LOCK = threading.Lock()        # held while outputs are moved into place (publishing)
_SCRATCH: set = set()           # temporary paths being written
_STATE = {"closed": False}


def register_scratch(path) -> None:
    """Register ``path``, a temporary file or folder about to be written, for :func:`abandon_outputs`."""
    _SCRATCH.add(os.fspath(path))


def release_scratch(path) -> None:
    """Forget ``path`` (moved into place or removed)."""
    _SCRATCH.discard(os.fspath(path))


@contextmanager
def scratch(path):
    """:func:`register_scratch` ``path`` for the block (see the module docstring)."""
    register_scratch(path)
    try:
        yield Path(path)
    finally:
        release_scratch(path)


@contextmanager
def publishing():
    """The block moves finished outputs into place; it is not cut by an interrupt (see :func:`close_outputs`).

    Raises
    ------
    KeyboardInterrupt
        The outputs are closed (the process is being interrupted): nothing is moved.
    """
    with _LOCK:
        if _STATE["closed"]:
            raise KeyboardInterrupt("outputs closed: the process is being interrupted")
        yield


def close_outputs() -> None:
    """Let a :func:`publishing` block in progress finish, then refuse every later one."""
    with _LOCK:
        _STATE["closed"] = True


def reopen_outputs() -> None:
    """Allow publishing again (a new run in the same process)."""
    with _LOCK:
        _STATE["closed"] = False


def abandon_outputs() -> int:
    """Close the outputs and remove every registered temporary path (the process is about to end at once).

    Returns the number of paths removed.
    """
    close_outputs()
    removed = 0
    for path in list(_SCRATCH):
        try:
            if os.path.isdir(path) and not os.path.islink(path):
                shutil.rmtree(path)
            else:
                os.remove(path)
            removed += 1
        except FileNotFoundError:
            continue
        except OSError:
            continue                    # best effort: the process is ending
    return removed


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` via a temporary file and ``os.replace``.

    The temporary file lives in the target folder, gets the permissions a plain ``open`` would
    give (0o666 less the umask) and is removed if anything fails (or by :func:`abandon_outputs`),
    so a reader sees either the old file or the complete new one, never a half-written file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = os.path.join(path.parent, f".{path.name}.{secrets.token_hex(6)}.tmp")
    with scratch(tmp):                  # registered before it exists: an abrupt end never leaves it behind
        try:
            umask = os.umask(0)
            os.umask(umask)
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 & ~umask)
            with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
                fh.write(text)
            with publishing():
                os.replace(tmp, path)
        except OSError as exc:
            if os.path.exists(tmp):
                os.unlink(tmp)
            if exc.filename is None:         # e.g. [Errno 28] No space left on device: name the file
                raise OSError(exc.errno, f"{exc.strerror} (writing {path})", str(path)) from None
            raise
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise
    return path


def atomic_write_texts(files: dict) -> list:
    """Write several files as one: ``{path: text}``, each via a temporary file, all moved into place by
    ``os.replace`` in one :func:`publishing` block once every one is complete.

    A failure or an interrupt leaves none of them changed (or, for an interrupt during the moves,
    which the block waits for, all of them written): never the first of a pair without the second.
    Returns the paths in the order given.
    """
    for path in files:
        if Path(path).is_dir():            # the moves below could then fail half-way: refuse before writing
            raise IsADirectoryError(21, "Is a directory (cannot write a file there)", str(path))
    pending = []
    try:
        for path, text in files.items():
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = os.path.join(path.parent, f".{path.name}.{secrets.token_hex(6)}.tmp")
            register_scratch(tmp)
            pending.append((tmp, path))
            umask = os.umask(0)
            os.umask(umask)
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 & ~umask)
            try:
                with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
                    fh.write(text)
            except OSError as exc:
                if exc.filename is None:     # e.g. [Errno 28] No space left on device: name the file
                    raise OSError(exc.errno, f"{exc.strerror} (writing {path})", str(path)) from None
                raise
        with publishing():
            for tmp, path in pending:
                os.replace(tmp, path)
    finally:
        for tmp, _ in pending:
            if os.path.exists(tmp):
                os.unlink(tmp)
            release_scratch(tmp)
    return [path for _, path in pending]


def create_text(path, text: str) -> Path:
    """Create the new file ``path`` holding ``text``, complete or not at all, never replacing a file.

    The text goes to a temporary file in the target folder, which is then hard-linked to ``path``
    (``os.link`` fails if ``path`` exists, so of two concurrent writers exactly one succeeds and a
    reader never sees a partial file); where hard links are not supported the file is opened with
    mode ``"x"`` (exclusive creation).

    Raises
    ------
    FileExistsError
        ``path`` exists.
    """
    path = Path(path)
    if path.exists():
        raise FileExistsError(17, "File exists", str(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    register_scratch(tmp)               # an abrupt end (mudoe.signals) removes it
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
            fh.write(text)
        try:
            os.link(tmp, path)
        except FileExistsError:
            raise
        except OSError:                  # no hard links on this file system
            with open(path, "x", newline="", encoding="utf-8") as fh:
                fh.write(text)
    except OSError as exc:
        if exc.filename is None:         # e.g. [Errno 28] No space left on device: name the file
            raise OSError(exc.errno, f"{exc.strerror} (writing {path})", str(path)) from None
        raise
    finally:
        os.unlink(tmp)
        release_scratch(tmp)
    return path
