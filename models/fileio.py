"""Atomic file writing shared by the data writers (prototype, friction constants, CLI outputs)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write_text", "create_text"]


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8, newlines as given) to ``path`` via a temporary file and ``os.replace``.

    The temporary file lives in the target folder, gets the permissions a plain ``open`` would
    give (0o666 less the umask) and is removed if anything fails, so a reader sees either the
    old file or the complete new one, never a half-written file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as fh:
            fh.write(text)
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
    return path
