"""Deprecated (issue 28): the long-format CSV of time-series campaigns is read and written by the time-series
study kind, :mod:`mudoe.kind.long_csv` (``read_long_csv``, ``write_long_csv``, ``LONG_COLUMNS``)."""
from __future__ import annotations

import mudoe.kind.long_csv as _home
from reports.moved import moved

__all__ = ["read_long_csv", "write_long_csv", "LONG_COLUMNS"]

__getattr__ = moved(__name__, _home, __all__)
