"""The ``--out`` folder: a folder mudoe owns, holding the outputs of one study.

* :func:`check_out` (before any work): ``--out`` is not empty text, is a folder or can be created
  (:func:`mudoe.console.check_out_dir`), and is either new, empty, marked as mudoe's (the marker
  file :data:`MARKER`) or holds only names mudoe writes (an output folder of an older mudoe);
  a folder holding other files is refused, so a run never mixes its outputs with someone else's.
* :func:`claim` (just before the first output is written, after the computation succeeded): when
  the marker names another study (another config file), the files it lists are removed first, so
  that no page of the other study stays beside the new ones; the marker then names this study.
* :func:`record`: the files a run wrote are added to the marker.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

from .console import OutDirError, check_out_dir
from .data_io import atomic_write_text

__all__ = ["MARKER", "check_out", "begin", "claim", "record"]

#: the marker file mudoe writes into every output folder (JSON: study, files written)
MARKER = ".mudoe-out.json"
#: names mudoe writes (an output folder of a mudoe without the marker is taken over)
_OUTPUT_NAMES = re.compile(r"(identify|oed|detect|validate|quantify)\.(json|txt)|report\.pdf|results\.json"
                           r"|page\d+_[\w.-]+\.png|measurements_[\w.-]+\.csv|campaign_long\.csv|campaign\.json"
                           r"|simulate\.json|\.report-\w+|\.[\w.-]+\.tmp")
#: {resolved folder: resolved config path} of the runs of this process (set by :func:`begin`)
_STUDY: dict = {}


def check_out(out: str) -> Path:
    """The ``--out`` folder once it is usable (nothing is created or removed).

    Raises
    ------
    OutDirError
        Empty text, a file, a folder that cannot be written, or a folder holding files that
        mudoe did not write.
    """
    if not str(out).strip():
        raise OutDirError("--out: empty; give a folder, e.g. --out results (\"\" would write into the current "
                          "folder)")
    path = check_out_dir(out)
    if not path.is_dir() or (path / MARKER).is_file():
        return path
    foreign = sorted(e.name for e in path.iterdir() if not _OUTPUT_NAMES.fullmatch(e.name))
    if foreign:
        more = f" and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        raise OutDirError(f"--out: {path} holds files mudoe did not write ({', '.join(foreign[:3])}{more}); give a "
                          "new or empty folder for the outputs")
    return path


def _read(out: Path) -> dict:
    try:
        d = json.loads((out / MARKER).read_text(encoding="utf-8"))
        return d if isinstance(d, dict) else {}
    except (OSError, ValueError):
        return {}


def begin(out: Path, config_path: str) -> None:
    """Remember which study a run writes into ``out`` (nothing is written yet)."""
    _STUDY[str(Path(out).absolute())] = str(Path(config_path).resolve())


def claim(out: Path) -> None:
    """Make ``out`` this run's study's folder: remove the files of another study, write the marker."""
    out = Path(out)
    study = _STUDY.get(str(out.absolute()), "")
    old = _read(out)
    files = list(old.get("files", [])) if isinstance(old.get("files"), list) else []
    if old.get("study") != study:
        for name in files:
            p = out / str(name)
            if p.parent == out and p.is_file():
                p.unlink()
        files = []
    if old.get("study") != study or not (out / MARKER).is_file():
        atomic_write_text(out / MARKER, json.dumps(dict(written_by="mudoe", study=study, files=files), indent=1)
                          + "\n")


def record(out: Path, paths) -> None:
    """Add the files ``paths`` (inside ``out``) to the marker of ``out``."""
    out = Path(out)
    d = _read(out)
    files = list(d.get("files", [])) if isinstance(d.get("files"), list) else []
    files += [Path(p).name for p in paths if Path(p).name not in files]
    d.update(written_by="mudoe", files=files)
    d.setdefault("study", _STUDY.get(str(out.absolute()), ""))
    atomic_write_text(out / MARKER, json.dumps(d, indent=1) + "\n")
