"""Errors of a study config that name the file, the line and the key.

The lowest module of the config code (it imports nothing of :mod:`mudoe`): the config reader
(:mod:`mudoe.config`), the cross-key checks (:mod:`mudoe.checks`), the data reader
(:mod:`mudoe.data_io`), the size limits (:mod:`mudoe.limits`) and the study modules all make their
:class:`ConfigError` here.  The line of a key is found in the TOML text by a best-effort search:
the key inside its ``[section]`` (or ``[[section]]``), else the file alone is named.
"""
from __future__ import annotations

import re

__all__ = ["ConfigError", "ConfigContext", "EntryContext", "config_error", "entry_error", "table_line"]


class ConfigError(ValueError):
    """The study configuration is invalid; the message names the file, the key and (if known) the line."""


class ConfigContext:
    """Where we are: file name and text (for line numbers)."""

    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = text.splitlines()

    def _section_start(self, section: str) -> int:
        """0-based line of the header of ``[section]`` (0 if not found)."""
        last = section.split(".")[-1].split("[")[0]
        hdr = re.compile(r"^\s*\[\[?\s*" + re.escape(section.split("[")[0]) + r"\s*\]\]?\s*(#.*)?$")
        hdr2 = re.compile(r"^\s*\[\[?.*\b" + re.escape(last) + r"\s*\]\]?")
        for pattern in (hdr, hdr2):
            for i, ln in enumerate(self.lines):
                if pattern.match(ln):
                    return i
        return 0

    def line_of(self, section: str, key: str) -> int | None:
        """Best-effort 1-based line of ``key`` inside ``[section]`` (None if not found)."""
        start = self._section_start(section) if section else 0
        pat = re.compile(r'^\s*["\']?' + re.escape(key) + r'["\']?\s*=|^\s*\[\[?[^\]]*\b' + re.escape(key)
                         + r'\s*\]\]?|[{,]\s*["\']?' + re.escape(key) + r'["\']?\s*=')
        for i in range(start, len(self.lines)):
            if pat.search(self.lines[i]):
                return i + 1
        return None

    def error(self, section: str, key: str, msg: str) -> ConfigError:
        where = f"[{section}] " if section else ""
        line = self.line_of(section, key) if key else None
        loc = f"{self.path}:{line}" if line else self.path
        return ConfigError(f"{loc}: {where}{key + ': ' if key else ''}{msg}")


class EntryContext:
    """The context of the ``k``-th (0-based) ``[[table]]`` entry: its errors name that entry's line (of ``key``,
    else of its header), not the first entry's; errors of other sections go to ``ctx``."""

    def __init__(self, ctx: ConfigContext, table: str, k: int):
        self.ctx, self.table, self.k = ctx, table, k
        self.path, self.lines = ctx.path, ctx.lines

    def error(self, section: str, key: str, msg: str) -> ConfigError:
        if section != self.table:
            return self.ctx.error(section, key, msg)
        return entry_error(self.path, "\n".join(self.lines), self.table, self.k, key, msg)


def entry_error(path, text: str, table: str, k: int, key: str, msg: str) -> ConfigError:
    """A :class:`ConfigError` naming the line of ``key`` in the ``k``-th (0-based) ``[[table]]`` of ``text``
    (the entry's header when the key is not in it)."""
    line = (table_line(text, table, k, key) if key else None) or table_line(text, table, k, "")
    loc = f"{path}:{line}" if line else str(path)
    return ConfigError(f"{loc}: [{table}] {key + ': ' if key else ''}{msg}")


def config_error(cfg, section: str, key: str, msg: str) -> ConfigError:
    """A :class:`ConfigError` for a check made after parsing: names ``cfg``'s file (a
    :class:`mudoe.config.StudyConfig`), the line of ``key`` in ``[section]`` (when the key is in the file)
    and the key."""
    return ConfigContext(cfg.path, cfg.text).error(section, key, msg)


def table_line(text: str, table: str, k: int, key: str) -> int | None:
    """1-based line of ``key`` in the ``k``-th (0-based) ``[[table]]`` of the TOML ``text`` (None: not found)."""
    head = re.compile(r"^\s*\[\[\s*" + re.escape(table) + r"\s*\]\]")
    other = re.compile(r"^\s*\[")
    pat = re.compile(r"^\s*" + re.escape(key) + r"\s*=")
    seen, inside = -1, False
    for i, ln in enumerate(text.splitlines()):
        if head.match(ln):
            seen += 1
            inside = seen == k
            if inside and not key:
                return i + 1
        elif other.match(ln):
            inside = False
        elif inside and pat.match(ln):
            return i + 1
    return None
