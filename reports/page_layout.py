"""The page layout every report page shares: A4 landscape, a bold title, wrapped text, parts of long lists."""
from __future__ import annotations

import textwrap

__all__ = ["PAGE_SIZE", "TEXT_LINE_HEIGHT", "ROWS_PER_PAGE", "new_page", "draw_text", "chunks", "part_label"]

#: A4 landscape (inches)
PAGE_SIZE = (11.69, 8.27)

#: height of one line of 9-point text as a fraction of the page height (1.2 x 9 pt on an 8.27 in page)
TEXT_LINE_HEIGHT = 0.019

#: table rows per page
ROWS_PER_PAGE = 25


def new_page(title=None):
    """A new A4-landscape figure with ``title`` at its top left."""
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=PAGE_SIZE)
    if title:
        fig.suptitle(title, x=0.04, y=0.97, ha="left", fontsize=14, weight="bold")
    return fig


def draw_text(fig, x, y, text, width=150, size=9, **kw):
    """``text`` wrapped at ``width`` characters (paragraphs kept), drawn from (x, y) down; returns its lines."""
    wrapped = "\n".join("\n".join(textwrap.wrap(par, width)) if par else "" for par in text.split("\n"))
    fig.text(x, y, wrapped, va="top", ha="left", fontsize=size, family=kw.pop("family", "sans-serif"), **kw)
    return wrapped.count("\n") + 1


def chunks(n: int, size: int) -> list[range]:
    """range(0, n) in the fewest, most even pieces of at most ``size`` (27 by 25: 14 + 13); [range(0)] if n = 0."""
    k = -(-n // size)
    edges = [round(i * n / k) for i in range(k + 1)] if k else []
    return [range(a, b) for a, b in zip(edges, edges[1:])] or [range(0)]


def part_label(k: int, n: int) -> str:
    """" (k+1/n)" after a title when a list takes n > 1 pages."""
    return f" ({k + 1}/{n})" if n > 1 else ""
