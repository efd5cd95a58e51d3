"""A bar's line is open until the bar closes, and an interrupt message then starts a line of its own."""
from __future__ import annotations

import io

from identification.progress import Progress, bar_line_open


def test_a_bar_is_open_until_it_closes():
    stream = io.StringIO()
    bar = Progress(stream=stream).bar(10, "work")
    bar.update(3)
    assert bar_line_open() and not stream.getvalue().endswith("\n")
    bar.close()
    assert not bar_line_open()
    with Progress(enabled=False).bar(5, "quiet"):                 # a disabled bar draws no line
        assert not bar_line_open()


def test_the_interrupt_message_starts_its_own_line_after_an_open_bar(tmp_path):
    from mudoe.signals import Interrupt
    path = tmp_path / "err.txt"
    with open(path, "w") as f:
        bar = Progress(stream=f).bar(10, "work")
        bar.update(2)
        f.flush()
        stop = Interrupt()
        stop.stderr_fd = f.fileno()
        assert stop.announce() == stop.exit_code
        raw = path.read_bytes()                                  # bytes: the bar's \r stays a \r
        bar.close()
    bar_line, rest = raw.split(b"\n", 1)
    assert bar_line.startswith(b"\rwork:") and b"/10" in bar_line
    assert rest == b"mudoe: interrupted\n"


def test_without_an_open_bar_the_message_is_one_line(tmp_path):
    from mudoe.signals import Interrupt
    path = tmp_path / "err.txt"
    with open(path, "w") as f:
        stop = Interrupt()
        stop.stderr_fd = f.fileno()
        stop.announce()
    assert path.read_text() == "mudoe: interrupted\n"
