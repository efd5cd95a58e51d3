"""Streaming CSV reading: blocks of lines parsed by pandas, memory bounded by one block plus the data kept.

A file is read in blocks of about :data:`BLOCK_BYTES` bytes that end at a line end.  A first pass
numbers the lines and counts their fields (separators outside quotes) without parsing anything,
so a ragged line anywhere in the file is refused with its line number at once; the second pass
drops blank lines and parses the rest with pandas' C reader (numeric columns as float64, the others
as text).  A cell pandas cannot read as a number sends only its block to a cell-by-cell path that
names the line and the column (the caller's ``cell`` function gives the message).

Peak memory is one block's text and frame plus what the caller keeps of each block (compact
numpy arrays), never the whole file as Python objects.
"""
from __future__ import annotations

import csv
import io
import itertools
import math
from pathlib import Path
from typing import Callable, Iterator, NamedTuple

import numpy as np

__all__ = ["DataFileError", "Block", "read_header", "blocks", "numbers", "texts", "MISSING_MARKERS", "BLOCK_BYTES"]

#: bytes of the file read at a time (the block then ends at the last line end inside it)
BLOCK_BYTES = 1 << 23
#: cells that mark a missing reading (compared after stripping blanks, case-insensitive)
MISSING_MARKERS = ("", "nan", "na", "n/a", "null", "none")
#: every upper/lower-case spelling of the markers (pandas compares exactly)
_NA_VALUES = sorted({"".join(p) for m in MISSING_MARKERS for p in itertools.product(*({c.lower(), c.upper()} for c in m))})


class DataFileError(ValueError):
    """A data file is missing or malformed; the message names the file and the line."""


class Block(NamedTuple):
    """Rows of one block: ``lines`` (1-based file line of each row) and ``frame`` (pandas, columns 0..n-1:
    float64 for the numeric columns, text for the others)."""

    lines: np.ndarray
    frame: object


def _open(path: Path):
    if not path.exists():
        raise DataFileError(f"{path}: data file not found; check [data] directory/files in the config")
    if not path.is_file():
        raise DataFileError(f"{path}: is not a file")
    try:
        return path.open("rb")
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc})") from None


def read_header(path: Path) -> tuple[list, int]:
    """The header fields (stripped) and the byte offset of the first data line."""
    with _open(path) as fh:
        first = fh.readline()
    try:
        text = first.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataFileError(f"{path}:1: cannot read ({exc})") from None
    fields = next(csv.reader([text]), [])
    if not any(c.strip() for c in fields):
        raise DataFileError(f"{path}:1: empty file; expected a header line")
    return [h.strip() for h in fields], len(first)


def _raw_blocks(path: Path, offset: int) -> Iterator[bytes]:
    """The file's bytes after ``offset`` in pieces that end at a line end (the last one at the end of file)."""
    with _open(path) as fh:
        fh.seek(offset)
        rest = b""
        while True:
            chunk = fh.read(BLOCK_BYTES)
            if not chunk:
                if rest:
                    yield rest + b"\n"
                return
            chunk = rest + chunk
            cut = chunk.rfind(b"\n") + 1
            if cut == 0:
                rest = chunk
                continue
            rest = chunk[cut:]
            yield chunk[:cut]


def _line_table(raw: bytes, path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, field count) of every line of ``raw`` (a block ending with a line end)."""
    a = np.frombuffer(raw, np.uint8)
    ends = np.flatnonzero(a == 10)
    starts = np.r_[0, ends[:-1] + 1]
    if b'"' not in raw:
        seps = np.flatnonzero(a == 44)
        counts = np.diff(np.searchsorted(seps, np.r_[starts, ends[-1] + 1]))[:len(starts)] + 1
        return starts, ends, counts
    try:                                   # quoted fields: count with the csv module (slow path)
        text_lines = raw.decode("utf-8").split("\n")[:-1]
    except UnicodeDecodeError as exc:
        raise DataFileError(f"{path}: cannot read ({exc})") from None
    try:
        counts = np.array([len(next(csv.reader([ln.rstrip("\r")]), [])) or 1 for ln in text_lines])
    except csv.Error as exc:
        raise DataFileError(f"{path}: malformed quoting ({exc})") from None
    return starts, ends, counts


def _rows(raw: bytes, line0: int, n_fields: int, path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, index) of the non-blank lines of a block whose first line is file line ``line0``;
    a line with another field count than ``n_fields`` raises naming its line."""
    starts, ends, counts = _line_table(raw, path)
    length = ends - starts
    blank = length == 0
    for i in np.flatnonzero(~blank & (length <= 8) & (counts == 1)):   # only white space ("\r", " ")
        blank[i] = not raw[starts[i]:ends[i]].strip()
    bad = np.flatnonzero(~blank & (counts != n_fields))
    if bad.size:
        i = int(bad[0])
        raise DataFileError(f"{path}:{line0 + i}: ragged row: {int(counts[i])} fields but the header has {n_fields}")
    keep = np.flatnonzero(~blank)
    return starts, ends, keep


def blocks(path: Path, n_fields: int, numeric: dict, first_line: int = 2, offset: int = 0) -> Iterator[Block]:
    """The data rows of ``path`` after the header, block by block.

    The whole file is first scanned for ragged rows (field counts by numpy, no parsing: a ragged last
    row of a 200 MB file is reported in about a second), then parsed block by block.

    Parameters
    ----------
    n_fields : int
        Fields per row (the header's); a row with another count is refused (ragged row).
    numeric : dict {column: bool}
        Columns parsed as float64 (their text is kept only for a block that fails to parse).
    first_line, offset : int
        File line number and byte offset of the first data line.
    """
    line0 = first_line
    for raw in _raw_blocks(path, offset):
        line0 += len(_rows(raw, line0, n_fields, path)[0])
    line0 = first_line
    names = list(range(n_fields))
    for raw in _raw_blocks(path, offset):
        starts, ends, keep = _rows(raw, line0, n_fields, path)
        lines = line0 + keep
        line0 += len(starts)
        if not keep.size:
            continue
        if keep.size != len(starts):       # drop blank lines before pandas sees them
            raw = b"".join(raw[starts[i]:ends[i] + 1] for i in keep)
        yield Block(lines.astype(np.int64), _parse(raw, names, numeric, path, lines))


def _parse(raw: bytes, names: list, numeric: dict, path: Path, lines: np.ndarray):
    """The block as a DataFrame: float64 numeric columns, or (a cell is not a plain number) all text."""
    import pandas as pd
    dtype = {c: ("float64" if numeric.get(c) else object) for c in names}
    kw = dict(header=None, names=names, keep_default_na=False, skip_blank_lines=False, engine="c",
              encoding="utf-8")
    try:
        return pd.read_csv(io.BytesIO(raw), dtype=dtype, na_values={c: _NA_VALUES for c in names if numeric.get(c)},
                           **kw)
    except ValueError:                     # text in a numeric column (or bad UTF-8): read it all as text
        pass
    try:
        return pd.read_csv(io.BytesIO(raw), dtype=object, na_filter=False, **kw)
    except UnicodeDecodeError as exc:
        raise DataFileError(f"{path}:{int(lines[0])}: cannot read ({exc})") from None


def numbers(block: Block, col: int, name: str, cell: Callable, allow_missing: bool = True,
            max_magnitude: float = math.inf) -> np.ndarray:
    """Column ``col`` of a block as float64; a bad cell raises through ``cell(line, name, text, allow_missing)``.

    Bad: text, infinite, above ``max_magnitude`` in magnitude, or missing when not ``allow_missing``.
    """
    s = block.frame[col]
    if s.dtype == np.float64:
        v = s.to_numpy()
        ok = np.isfinite(v) if not allow_missing else ~np.isinf(v)
        ok &= ~(np.abs(v) > max_magnitude)
        if ok.all():
            return v
        i = int(np.flatnonzero(~ok)[0])
        line = int(block.lines[i])
        cell(line, name, "nan" if math.isnan(v[i]) else repr(float(v[i])), allow_missing)
        raise DataFileError(f"line {line}: column {name!r}: value {v[i]!r} refused")
    return np.array([cell(int(ln), name, str(t), allow_missing) for ln, t in zip(block.lines, s.to_numpy())],
                    float)


def texts(block: Block, col: int) -> np.ndarray:
    """Column ``col`` of a block as stripped text (object array)."""
    s = block.frame[col]
    if s.dtype == np.float64:
        return np.array([repr(float(x)) for x in s.to_numpy()], object)
    return s.fillna("").astype(str).str.strip().to_numpy(object)
